"""Outputs of ``soabench kitti``: Table I, the pairwise delay comparison, Figs. 6-8, summary.json and report.md
(paper §V; docs/method.md §5.2-5.4, §5.7-5.9).

* Table I: mean absolute cardinality error and mean OSPA (c and p from the metrics settings; the KITTI defaults are
  c = 10 m, p = 1), mean +- sigma over all time steps of all held-out sequences;
* pairwise: per target episode (§5.4, matched across models by sequence, target and episode start), the share in
  which S-OA's delay is <= the other model's; an episode censored for one model counts as an infinite delay for it,
  episodes censored for both are left out (their number is reported);
* Fig. 6: histogram of the per-episode delays; Fig. 7: mean posterior components per sequence; Fig. 8: mean delay
  over all episodes vs the N-hat offset, with the std of those means.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from soabench.atomic import write_json_atomic, write_text_atomic
from soabench.birth import LABEL
from soabench.config import family_label
from soabench.experiment.campaigns.kitti import trackeval_kitti
from soabench.experiment.reports.occlusion import bin_labels
from soabench.experiment.runs.files import write_csv
from soabench.figures import kitti as kitti_figures
from soabench.kitti.config import KittiSpec
from soabench.kitti.levels import LEVEL_NAMES, LEVELS

#: the paper's KITTI numbers (Table I, §V-A pairwise shares, §V-B std of the sweep means); its UBM spreads the grid
#: across the workspace, so its numbers stand beside ``ubm-ws`` (``ubm``, clipped to the FOV, has none)
PAPER = {
    "card_err": {"soa": (6.5565, 4.4513), "pubm": (6.7194, 4.5109), "ubm-ws": (6.7836, 4.4926)},
    "ospa": {"soa": (7.8666, 1.9936), "pubm": (8.0362, 1.9943), "ubm-ws": (8.1023, 1.9742)},
    "pairwise": {"pubm": 70.3, "ubm-ws": 72.2},
    "sweep_std": {"soa": 0.12, "pubm": 0.10, "ubm-ws": 0.15},
}


#: track measures kept per model and sequence (docs/method.md §9.3; truth ids are label_02's track ids, gate
#: d_gate; None for an unlabelled model), in sequences.csv after the §5 columns
TRACK_COLUMNS = ("hota", "deta", "assa", "idf1", "idsw", "mota")


def _label(m: str) -> str:
    return LABEL.get(m, m)


def levels_table(records: dict, models: list[str]) -> dict:
    """Per model and kind (``occluded``, ``truncated``) and level the truth-frames, those associated (and the recall
    they give) and the identity switches (None for an unlabelled model), summed over the CV sequences
    (:mod:`soabench.kitti.levels`); {} when no record holds the split."""
    out: dict = {}
    for m in models:
        runs = [r["models"][m]["levels"] for (st, _), r in sorted(records.items()) if st == "cv"
                and "levels" in r["models"][m]]  # fmt: skip
        if not runs:
            continue
        out[m] = {}
        for kind, values in LEVELS.items():
            rows = []
            for i, v in enumerate(values):
                frames = sum(run[kind][i]["frames"] for run in runs)
                assoc = sum(run[kind][i]["associated"] for run in runs)
                sw = [run[kind][i]["idsw"] for run in runs]
                idsw = None if any(x is None for x in sw) else int(sum(sw))
                recall = assoc / frames if frames else math.nan
                rows.append({"level": v, "frames": frames, "associated": assoc, "recall": recall, "idsw": idsw})
            out[m][kind] = rows
    return out


def undetected_gaps_table(records: dict, models: list[str], bins: Sequence[int]) -> dict:
    """Per model and gap-length bin (``bins`` as ``metrics.gap_bins``) the undetected gaps of the CV sequences
    (:mod:`soabench.kitti.levels`): their number, the coasted share, the identity re-emergences counted and the
    share kept (NaN when none)."""
    out: dict = {}
    labels = bin_labels(bins)
    for m in models:
        gaps = [g for (st, _), r in sorted(records.items()) if st == "cv" for g in r["models"][m].get("levels", {})
                .get("gaps", [])]  # fmt: skip
        rows = []
        for label, lo, hi in zip(labels, bins, [*bins[1:], math.inf], strict=True):
            here = [g for g in gaps if lo <= g["scans"] < hi]
            ids = [g["id_kept"] for g in here if g["id_kept"] is not None]
            rows.append({
                "bin": label, "gaps": len(here),
                "coasted": float(np.mean([g["coasted"] for g in here])) if here else math.nan,
                "n_id": len(ids), "id_kept": float(np.mean(ids)) if ids else math.nan,
            })  # fmt: skip
        out[m] = rows
    return out


def _trackeval_md(te: dict, tt: dict, lv: dict, models: list[str]) -> list[str]:
    """TrackEval's own KITTI evaluation beside our Tracks numbers (nothing when it did not run)."""
    if not te:
        return []
    L = ["## TrackEval's own KITTI evaluation beside ours", ""]
    if "error" in te:
        return [*L, f"TrackEval refused the inputs: {te['error']}", ""]
    L += [
        "TrackEval's KITTI reader scores 2-D image boxes (each estimate drawn as a pedestrian box at its position) "
        "matched by IoU, pooled over the sequences, and drops every pedestrian labelled occluded above 2 or "
        "truncated above 0 (and the estimates matched to them); ours scores every labelled pedestrian in the field "
        "of view in the ground plane (mean over sequences). Truth: the truth boxes TrackEval keeps, and our "
        "truth-frames.",
        "",
        "| model | HOTA, TrackEval | HOTA, ours | IDF1, TrackEval | IDF1, ours | MOTA, TrackEval | IDSW, TrackEval "
        "| IDSW, ours | truth, TrackEval | truth, ours |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for m in models:
        t, o = te.get(m), tt.get(m)
        if t is None or o is None:
            continue
        ours = sum(r["frames"] for r in lv.get(m, {}).get("occluded", []))
        L.append(
            f"| {_label(m)} | {_fmt(t['hota'])} | {_fmt(o['hota_mean'])} | {_fmt(t['idf1'])} | {_fmt(o['idf1_mean'])} "
            f"| {_fmt(t['mota'])} | {t['idsw']} | {o['idsw']} | {t['gt_dets']} | {ours} |"
        )
    return [*L, ""]


def _levels_md(lv: dict, gaps: dict, models: list[str]) -> list[str]:
    """The occlusion-level tables of the report (nothing without the split)."""
    if not lv:
        return []
    L = [
        "## Occlusion levels: KITTI's `occluded` and `truncated`, per truth-frame",
        "",
        "A target counts at the level its label row gives in each frame. Frames: truth-frames of the ground-truth "
        "set; recall: the share with an associated estimate; IDSW: identity switches at frames of that level.",
        "",
        "| model | level | frames | recall | IDSW |",
        "|---|---|---|---|---|",
    ]
    for m in models:
        for kind in LEVELS:
            for row in lv.get(m, {}).get(kind, []):
                idsw = "—" if row["idsw"] is None else str(row["idsw"])
                name = f"{kind} {row['level']} ({LEVEL_NAMES[kind][row['level']]})"
                L.append(f"| {_label(m)} | {name} | {row['frames']} | {_fmt(row['recall'])} | {idsw} |")
    L += [
        "",
        "## Identity through undetected gaps",
        "",
        "Gaps: frames in which a target is present and in the FOV but not detected, with a detection before and "
        "after. Coasted: covered by an associated estimate on every frame; identity kept: the label after the gap is "
        "the one before it (labelled models, associated on both sides; count in brackets).",
        "",
        "| model | gap length (frames) | gaps | coasted | identity kept |",
        "|---|---|---|---|---|",
    ]
    for m in models:
        labelled = any(r["idsw"] is not None for r in lv.get(m, {}).get("occluded", []))
        for row in gaps.get(m, []):
            kept = f"{_fmt(row['id_kept'])} ({row['n_id']})" if labelled else "—"
            L.append(f"| {_label(m)} | {row['bin']} | {row['gaps']} | {_fmt(row['coasted'])} | {kept} |")
    return [*L, ""]


# ---------------------------------------------------------------------------------------------------------------------
# numbers


def table1(records: dict, models: list[str]) -> dict:
    """Per model: mean and sigma (ddof 0) of the cardinality error and OSPA over all time steps of all CV sequences."""
    out = {}
    for m in models:
        card = np.concatenate([r["models"][m]["series"]["card_err"] for (st, _), r in records.items() if st == "cv"])
        osp = np.concatenate([r["models"][m]["series"]["ospa"] for (st, _), r in records.items() if st == "cv"])
        out[m] = {
            "card_err_mean": float(card.mean()),
            "card_err_std": float(card.std()),
            "ospa_mean": float(osp.mean()),
            "ospa_std": float(osp.std()),
            "steps": int(len(card)),
        }
    return out


def tracks_table(records: dict, models: list[str]) -> dict:
    """Per model, over the CV sequences (docs/method.md §9.3): mean and sigma (ddof 0) over sequences of HOTA and
    IDF1, IDSW summed, and the number of sequences with labels; empty when no model labels its estimates (or the
    records predate the track measures)."""
    out = {}
    for m in models:
        rows = [r["models"][m].get("tracks", {}) for (st, _), r in sorted(records.items()) if st == "cv"]
        rows = [t for t in rows if t.get("hota") is not None]
        if not rows:
            continue
        hota, idf1 = np.array([t["hota"] for t in rows]), np.array([t["idf1"] for t in rows])
        out[m] = {
            "hota_mean": float(hota.mean()),
            "hota_std": float(hota.std()),
            "idf1_mean": float(idf1.mean()),
            "idf1_std": float(idf1.std()),
            "idsw": int(sum(t["idsw"] for t in rows)),
            "sequences": len(rows),
        }
    return out


def _episodes(records: dict, setting: str, model: str) -> dict[tuple, float]:
    """{(sequence, target, k0): delay (inf if censored)} of one model in one setting."""
    out = {}
    for (st, s), r in records.items():
        if st != setting:
            continue
        for e in r["models"][model]["episodes"]:
            out[(s, e["target"], e["k0"])] = math.inf if e["censored"] else float(e["delay"])
    return out


def pairwise(records: dict, models: list[str], ref: str = "soa") -> dict:
    """Share (%) of target episodes in which ``ref``'s delay is <= each other model's (module docstring)."""
    if ref not in models:
        return {}
    a = _episodes(records, "cv", ref)
    out = {}
    for m in models:
        if m == ref:
            continue
        b = _episodes(records, "cv", m)
        keys = sorted(set(a) & set(b))
        both = [k for k in keys if math.isinf(a[k]) and math.isinf(b[k])]
        use = [k for k in keys if not (math.isinf(a[k]) and math.isinf(b[k]))]
        wins = sum(a[k] <= b[k] for k in use)
        out[m] = {
            "share": 100.0 * wins / len(use) if use else math.nan,
            "n": len(use),
            "both_censored": len(both),
        }
    return out


def delays(records: dict, setting: str, model: str) -> np.ndarray:
    """Finite per-episode delays (s) of one model in one setting."""
    d = np.array(list(_episodes(records, setting, model).values()), dtype=float)
    return d[np.isfinite(d)]


def sweep_table(records: dict, models: list[str], offsets: list[int]) -> dict:
    """Per model: mean delay over all episodes at each offset, and the std (ddof 0) of those means."""
    out = {}
    for m in models:
        means = []
        for o in offsets:
            d = delays(records, f"sweep{o:+d}", m)
            means.append(float(d.mean()) if len(d) else math.nan)
        arr = np.array(means)
        out[m] = {"offsets": list(offsets), "mean_delay": means, "std_of_means": float(np.nanstd(arr))}
    return out


# ---------------------------------------------------------------------------------------------------------------------
# files


def _fmt(v: float, nd: int = 3) -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{nd}f}"


def family_records(records: dict, family: str) -> dict:
    """The records of a run's other filter family ``family`` as the tables read a run's first family: its runs in
    place of ``models`` (:func:`.protocol.run_sequence` keeps them under ``families``)."""
    return {key: {**r, "models": r["families"][family]} for key, r in records.items()}


def _sequence_rows(records: dict, models: list[str], frames: dict, targets: dict) -> list[dict]:
    """One row of ``sequences.csv`` per (setting, sequence, model) of ``records``."""
    keys = ("card_err", "ospa", "delay_mean", "delay_std", "n_episodes", "n_censored", "mean_components",
            "precision", "recall")  # fmt: skip
    rows = []
    for (setting, s), r in sorted(records.items()):
        for m in models:
            run = r["models"][m]
            rows.append({
                "setting": setting, "sequence": s, "N_hat": r["N_hat"], "model": m, "frames": frames[s],
                "targets": targets[s], **{k: run["summary"][k] for k in keys},
                **{k: run.get("tracks", {}).get(k) for k in TRACK_COLUMNS},
            })  # fmt: skip
    return rows


def write_outputs(
    out: Path, spec: KittiSpec, folds: list, records: dict, skipped: list, targets: dict, frames: dict
) -> str:
    """Write summary.json, report.md, sequences.csv, episodes.csv and the figures; returns the Markdown report."""
    models = list(spec.config.experiment.models)
    t1 = table1(records, models)
    tt = tracks_table(records, models)
    lv = levels_table(records, models)
    cv_seqs = sorted(s for (st, s) in records if st == "cv")
    te = trackeval_kitti.evaluate(out, cv_seqs, frames, models)
    ug = undetected_gaps_table(records, models, spec.config.metrics.gap_bins)
    pw = pairwise(records, models)
    offsets = list(spec.nhat_sweep or [])
    sw = sweep_table(records, models, offsets) if offsets else {}
    fig_dir = out / "figures"
    censored = {m: sum(math.isinf(v) for v in _episodes(records, "cv", m).values()) for m in models}
    cv_delays = {m: delays(records, "cv", m) for m in models}
    figs = [kitti_figures.delay_histogram(cv_delays, censored, spec.config.sensor.dt, fig_dir / "fig6_delay_hist.png")]
    seqs = sorted(s for (st, s) in records if st == "cv")
    components = {m: [records[("cv", s)]["models"][m]["summary"]["mean_components"] for s in seqs] for m in models}
    figs.append(kitti_figures.components_per_sequence(seqs, components, fig_dir / "fig7_components.png"))
    if sw:
        figs.append(kitti_figures.nhat_sweep({m: sw[m] for m in models}, fig_dir / "fig8_nhat_sweep.png"))

    families = list(spec.config.experiment.filters)
    per_family = {f: family_records(records, f) for f in families[1:]}
    per_seq, ep_rows = [], []
    for family, recs in [(families[0], records), *per_family.items()]:
        rows = _sequence_rows(recs, models, frames, targets)
        if len(families) > 1:  # a run of several families: each row names its family, last
            rows = [{**row, "filter": family} for row in rows]
        per_seq += rows
    for (setting, s), r in sorted(records.items()):
        for m in models:
            for e in r["models"][m]["episodes"]:
                ep_rows.append({"setting": setting, "sequence": s, "model": m, **e})
    seq_cols = list(per_seq[0]) if per_seq else []
    write_csv(out / "sequences.csv", per_seq, seq_cols)
    ep_cols = ["setting", "sequence", "model", "target", "k0", "k_end", "k_d", "k_t", "delay", "delay_lb", "censored"]
    write_csv(out / "episodes.csv", ep_rows, ep_cols)
    infos = {s: r["info"] for (st, s), r in records.items() if st == "cv"}
    no_sem = sorted(s for s, i in infos.items() if not i["semantics"])
    stationary = sorted(s for s, i in infos.items() if i["stationary_ego"])
    summary = {
        "folds": folds,
        "models": models,
        "probability": spec.config.experiment.probabilities[0],
        "table1": t1,
        "tracks": tt,
        "pairwise": pw,
        "sweep": sw,
        "sequences": per_seq,
        "sequence_info": infos,
        "skipped": skipped,
        "semantics_missing": no_sem,
        "stationary_ego": stationary,
        "paper": PAPER,
        "figures": figs,
        "occlusion_levels": lv,
        "undetected_gaps": ug,
        "trackeval_kitti": te,
    }
    if len(families) > 1:  # every family's tables, each family's own S-OA comparison inside it
        summary["filters"] = families
        summary["families"] = {
            f: {"table1": table1(r, models), "tracks": tracks_table(r, models), "pairwise": pairwise(r, models)}
            for f, r in per_family.items()
        }
    write_json_atomic(out / "summary.json", summary)
    md = _markdown(spec, summary, records, out)
    levels_md = _levels_md(lv, ug, models) + _trackeval_md(te, tt, lv, models)
    if levels_md:
        md += "\n" + "\n".join(levels_md)
    for f, tables in summary.get("families", {}).items():
        md += "\n" + "\n".join(_family_md(f, tables, models, spec.config.metrics.ospa_c))
    write_text_atomic(out / "report.md", md)
    return md


def _shown(path, out: Path) -> str:
    """A data path as the report shows it: relative to the report's folder where it lies beside it (a report
    committed with its export reads the same on every machine), else as given."""
    try:
        return os.path.relpath(Path(path).resolve(), Path(out).resolve())
    except ValueError:  # another drive (Windows)
        return str(path)


def _lidar_source(spec, out: Path) -> str:
    """The report's words for the semantic region built from segmented scans, or for no semantics at all."""
    lid = spec.lidar
    if not lid:
        return ", no semantics"
    return (
        f", semantics from LiDAR point labels `{_shown(lid['point_labels'], out)}` on scans "
        f"`{_shown(lid['velodyne'], out)}` (grid {lid['grid']:g} m, closing {lid['closing']:g} m, "
        f"gap fill {lid['fill']:g} m along {lid['sector_deg']:g}° sectors)"
    )


def _tracks_md(tt: dict, models: list[str]) -> list[str]:
    """The Tracks table of the report (nothing when no model labels its estimates)."""
    if not tt:
        return []
    L = ["## Tracks: HOTA and IDF1 over the CV sequences (mean ± σ over sequences; IDSW summed)", ""]
    L += ["| | HOTA | IDF1 | IDSW | sequences |", "|---|---|---|---|---|"]
    for x in models:
        t = tt.get(x)
        if t is None:
            L.append(f"| {_label(x)} | — | — | — | 0 |")
            continue
        hota, idf1 = f"{t['hota_mean']:.3f} ± {t['hota_std']:.3f}", f"{t['idf1_mean']:.3f} ± {t['idf1_std']:.3f}"
        L.append(f"| {_label(x)} | {hota} | {idf1} | {t['idsw']} | {t['sequences']} |")
    return [*L, ""]


def _families_note(families: tuple[str, ...]) -> str:
    """The header's note on a run of several filter families: which family the first tables show."""
    others = ", ".join(family_label(f) for f in families[1:])
    return f" Filter families: the tables below are the {family_label(families[0])} filter's; {others} follow."


def _family_md(family: str, tables: dict, models: list[str], ospa_c: float) -> list[str]:
    """The section of another filter family: its Table I numbers, its Tracks table (identities on the sequences)
    and S-OA's pairwise delay comparison inside it."""
    t1, pw = tables["table1"], tables["pairwise"]
    L = [f"## The {family_label(family)} filter", "", "| | " + " | ".join(_label(x) for x in models) + " |"]
    L += ["|---|" + "---|" * len(models)]
    for key, name in (("card_err", "mean abs. cardinality error"), ("ospa", f"mean OSPA (m, c = {ospa_c:g})")):
        L.append(f"| {name} | " + " | ".join(f"{t1[x][key + '_mean']:.4f} ± {t1[x][key + '_std']:.4f}"
                                              for x in models) + " |")  # fmt: skip
    if pw:
        L += ["", "S-OA matches or outperforms X in n % of target episodes (tracking delay):", ""]
        L += ["| X | S-OA ≤ X | episodes compared |", "|---|---|---|"]
        L += [f"| {_label(x)} | {_fmt(v['share'], 1)} % | {v['n']} |" for x, v in pw.items()]
    tracks = _tracks_md(tables["tracks"], models)
    return [*L, "", *(t.replace("## Tracks", f"### Tracks, {family_label(family)}", 1) for t in tracks)]


def _markdown(spec: KittiSpec, summary: dict, records: dict, out: Path) -> str:
    """report.md's sections from the numbers of summary.json (and the per-sequence records for Fig. 7's means)."""
    folds, t1, tt, pw, sw = (summary[k] for k in ("folds", "table1", "tracks", "pairwise", "sweep"))
    models, infos = summary["models"], summary["sequence_info"]
    m = spec.config.metrics
    det = _shown(spec.detections, out) if spec.detections else "(root)/detections"
    L = [
        "# KITTI protocol (paper §V)",
        "",
        f"Data: `{_shown(spec.root, out)}`, detections `{det}`"
        + (f", semantics `{_shown(spec.semantics, out)}`" if spec.semantics else _lidar_source(spec, out))
        + ".",
        f"{len(infos)} sequences in {len(folds)} folds; probability mode `{spec.config.experiment.probabilities[0]}`; "
        f"OSPA c = {m.ospa_c:g} m, p = {m.ospa_p:g}; delay gate {m.d_gate:g} m; "
        f"frame period {spec.config.sensor.dt:g} s."
        + (_families_note(spec.config.experiment.filters) if len(spec.config.experiment.filters) > 1 else ""),
        "",
        "## Folds and N-hat (duration-weighted: training targets / training frames)",
        "",
        "| fold | held-out sequences | N-hat (births per frame) |",
        "|---|---|---|",
    ]
    L += [f"| {f['fold']} | {', '.join(f['sequences'])} | {f['N_hat']:.5f} |" for f in folds]
    L += ["", "## Table I: mean over all time steps (± σ)", "", "| | " + " | ".join(_label(x) for x in models) + " |"]
    L += ["|---|" + "---|" * len(models)]
    for key, name in (("card_err", "mean abs. cardinality error"), ("ospa", f"mean OSPA (m, c = {m.ospa_c:g})")):
        ours = [f"{t1[x][key + '_mean']:.4f} ± {t1[x][key + '_std']:.4f}" for x in models]
        paper = [f"{PAPER[key][x][0]:.4f} ± {PAPER[key][x][1]:.4f}" if x in PAPER[key] else "—" for x in models]
        L += [f"| {name}, ours | " + " | ".join(ours) + " |", f"| {name}, paper | " + " | ".join(paper) + " |"]
    if pw:
        L += ["", "## Pairwise tracking delay: S-OA matches or outperforms X in n % of target episodes", ""]
        L += ["| X | ours | episodes compared | censored for both (left out) | paper |", "|---|---|---|---|---|"]
        for x, v in pw.items():
            paper = f"{PAPER['pairwise'][x]:.1f} %" if x in PAPER["pairwise"] else "—"
            L.append(f"| {_label(x)} | {_fmt(v['share'], 1)} % | {v['n']} | {v['both_censored']} | {paper} |")
    comps = {x: np.mean([r["models"][x]["summary"]["mean_components"] for (st, _), r in records.items() if st == "cv"])
             for x in models}  # fmt: skip
    L += ["", "## Posterior components (Fig. 7)", ""]
    L += [f"- {_label(x)}: {comps[x]:.1f} on average over the sequences" for x in models]
    for x in ("ubm-ws", "ubm"):
        if "soa" in comps and x in comps and comps["soa"] > 0:
            paper = " (paper: about 5-6)" if x == "ubm-ws" else ""
            L.append(f"- {_label(x)} / S-OA = {comps[x] / comps['soa']:.2f}{paper}")
    if sw:
        L += ["", "## N-hat sweep (Fig. 8): std of the mean delays over the offsets", ""]
        L += ["| | ours (s) | paper (s) |", "|---|---|---|"]
        for x in models:
            paper = f"{PAPER['sweep_std'][x]:.2f}" if x in PAPER["sweep_std"] else "—"
            L.append(f"| {_label(x)} | {sw[x]['std_of_means']:.3f} | {paper} |")
    L += ["", *_tracks_md(tt, models), "## Notes", "", *_notes_md(spec, summary, out)]
    L += ["", "Figures: `figures/fig6_delay_hist.png`, `figures/fig7_components.png`"
          + (", `figures/fig8_nhat_sweep.png`" if sw else "") + "."]  # fmt: skip
    return "\n".join(L) + "\n"


def _notes_md(spec: KittiSpec, summary: dict, out: Path) -> list[str]:
    """The Notes of report.md: missing semantics or oxts, nominal calibrations, skipped sequences, GMBM on KITTI,
    dropped detections, data exported from SUMO."""
    models, infos, skipped = summary["models"], summary["sequence_info"], summary["skipped"]
    no_sem, stationary = summary["semantics_missing"], summary["stationary_ego"]
    L: list[str] = []
    if no_sem:
        L.append(
            f"- No semantics for {len(no_sem)} sequence(s) ({', '.join(no_sem)}): S-OA used its occlusion and FOV "
            "terms only there (no semantic births)."
        )
    if stationary:
        L.append(f"- No oxts for {', '.join(stationary)}: the ego was taken as stationary.")
    nominal = sorted(s for s, i in infos.items() if i["calib_nominal"])
    if nominal:
        L.append(f"- Nominal calibration values used for {', '.join(nominal)}.")
    for s in skipped:
        L.append(f"- Skipped sequence {s['sequence']}: {s['reason']}")
    if "gmbm" in models:
        L.append(
            "- GMBM's a-priori entry points come from a map (sidewalk exits, doors); KITTI sequences have none, "
            "so it places no births here."
        )
    dropped = sum(i["outside_fov"] for i in infos.values())
    below = sum(i["below_score"] for i in infos.values())
    L.append(f"- Detections dropped: {dropped} outside the FOV, {below} below the score threshold.")
    if (Path(spec.root) / "export.json").is_file():
        L.append("- These sequences were generated from SUMO by `soabench export kitti`; they are not KITTI data.")
    return L
