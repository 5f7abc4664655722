"""Summary of a finished run in the paper's terms, from its CSV files only (docs/method.md §5.8, §5.9).

``write_report(run_dir)`` reads ``run.json`` (config), ``trials.csv``, ``episodes.csv``, ``steps.csv``,
``timing.csv`` and the failure records, and writes ``summary.json``, ``summary.md`` and ``figures/*.png``, so a
finished or resumed run can be re-reported at any time.

Statistics (per clutter rate lambda, birth model and probability mode):

* mean delay k̄ = mean over trials of the per-trial mean delay (trials without a counted episode excluded);
  σ̄ = mean over trials of the per-trial delay std (§5.4 item 7);
* win counts: trials in which S-OA's k̄ is lower than baseline X's, with ties, losses and n/a (one side has no
  counted episode) separately (§5.8);
* percent reduction ``100 (M_X - M_SOA) / M_X`` of the cardinality error and OSPA on grand means (mean over
  trials of the per-trial means) (§5.8); mean ± σ over trials use the population std (ddof = 0);
* precision and recall: mean over trials of the per-trial values, NaN trials excluded (§5.5);
* components: mean over trials of the per-trial mean posterior component count (§5.7, Fig. 7);
* censored: censored episodes / all episodes with a detection (§5.4 item 5);
* "episodes S-OA ≤ X": the KITTI-style pairwise fraction over episodes counted for both (§5.8).

A run that names filter families (``experiment.filters``, a ``filter`` column in its tables) is summarised family
by family: every statistic and every paired comparison above is computed inside one family (S-OA in the LMB against
the baselines in the LMB), and a probability mode a family does not run reads "—".
The paper's figures and the comparison with the paper use the GM-PHD family; ``figures/families.png`` sets the
families side by side.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from soabench.atomic import write_json_atomic, write_text_atomic
from soabench.birth import BASELINES, LABEL
from soabench.config import FAMILIES, FAMILY_MODES, FILTER_FAMILIES, Config, MetricsConfig
from soabench.errors import SoabenchError
from soabench.experiment.reports import occlusion, paper, track_intervals
from soabench.experiment.reports.paper import percent_reduction
from soabench.experiment.reports.tables import RunTables, load_tables, select, tables_models  # noqa: F401 (shared)
from soabench.experiment.runs.failures import write_model_failures
from soabench.experiment.runs.provenance import REPRODUCTION_TOLERANCE
from soabench.experiment.runs.store import RunStore
from soabench.experiment.trial.observable import duration_hint
from soabench.experiment.trial.trial import FILTER_COLUMN
from soabench.tracks.evaluate import TRACK_KEYS
from soabench.tracks.report import TRACKS_LEGEND, render_tracks, track_stats, tracks_vs_soa

#: how the summary names a filter family
FAMILY_LABEL = {name: f.label for name, f in FAMILIES.items()}


def _nanmean(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=float)
    x = x[~np.isnan(x)]
    return float(x.mean()) if x.size else math.nan


def _nanstd(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=float)
    x = x[~np.isnan(x)]
    return float(x.std(ddof=0)) if x.size else math.nan


def _by_trial(tables: RunTables, col: str, clutter: float, model: str, mode: str) -> dict[int, float]:
    t = tables.trials
    m = select(t, clutter=clutter, model=model, mode=mode)
    return {int(k): float(v) for k, v in zip(t["trial"][m], t[col][m], strict=False)}


def model_stats(tables: RunTables, clutter: float, model: str, mode: str) -> dict:
    """The per-(lambda, model, mode) numbers of the summary table."""
    t = tables.trials
    m = select(t, clutter=clutter, model=model, mode=mode)
    col = lambda c: t[c][m] if c in t else np.full(int(m.sum()), math.nan)  # noqa: E731
    n_ep = float(np.nansum(col("n_episodes")))
    n_cens = float(np.nansum(col("n_censored")))
    return {
        "model": model,
        "mode": mode,
        "n_trials": int(m.sum()),
        "delay_mean": _nanmean(col("delay_mean")),
        "delay_sigma_bar": _nanmean(col("delay_std")),
        "delay_mean_lb": _nanmean(col("delay_mean_lb")),
        "card_err_mean": _nanmean(col("card_err")),
        "card_err_std": _nanstd(col("card_err")),
        "ospa_mean": _nanmean(col("ospa")),
        "ospa_std": _nanstd(col("ospa")),
        "gospa_mean": _nanmean(col("gospa")),
        "precision_mean": _nanmean(col("precision")),
        "recall_mean": _nanmean(col("recall")),
        "components_mean": _nanmean(col("mean_components")),
        "n_episodes": int(n_ep),
        "n_censored": int(n_cens),
    }


def episode_le_fraction(tables: RunTables, clutter: float, mode: str, baseline: str) -> float:
    """Fraction of episodes (counted for both) with delay_SOA <= delay_X (KITTI-style pairwise, §5.8)."""
    e = tables.episodes
    if not e or "delay" not in e or len(e["delay"]) == 0:
        return math.nan

    def delays(model: str) -> dict[tuple, float]:
        m = select(e, clutter=clutter, model=model, mode=mode) & (e["censored"] == 0) & ~np.isnan(e["delay"])
        keys = zip(e["trial"][m], e["target"][m], e["k0"][m], strict=False)
        return dict(zip(((int(a), str(b), float(c)) for a, b, c in keys), e["delay"][m], strict=False))

    a, b = delays("soa"), delays(baseline)
    common = sorted(set(a) & set(b))
    if not common:
        return math.nan
    return float(np.mean([a[k] <= b[k] for k in common]))


def compare(tables: RunTables, clutter: float, mode: str, baseline: str, stats: dict) -> dict:
    """Win counts (ties and n/a separately) and percent reductions of S-OA against ``baseline``."""
    soa = _by_trial(tables, "delay_mean", clutter, "soa", mode)
    other = _by_trial(tables, "delay_mean", clutter, baseline, mode)
    wins = ties = losses = na = 0
    for trial in sorted(set(soa) | set(other)):
        a, b = soa.get(trial, math.nan), other.get(trial, math.nan)
        if math.isnan(a) or math.isnan(b):
            na += 1
        elif a < b:
            wins += 1
        elif a == b:
            ties += 1
        else:
            losses += 1
    s, x = stats[("soa", mode)], stats[(baseline, mode)]
    return {
        "mode": mode,
        "baseline": baseline,
        "n_trials": wins + ties + losses + na,
        "wins": wins,
        "ties": ties,
        "losses": losses,
        "na": na,
        "card_reduction": percent_reduction(x["card_err_mean"], s["card_err_mean"]),
        "ospa_reduction": percent_reduction(x["ospa_mean"], s["ospa_mean"]),
        "episode_le_fraction": episode_le_fraction(tables, clutter, mode, baseline),
    }


def timing_summary(tables: RunTables, sessions: list[dict]) -> dict:
    """Wall time of the sessions and seconds per stage (SUMO, sensor, each filter model x mode)."""
    tm = tables.timing
    out: dict[str, Any] = {"wall_s": float(sum(s.get("wall_s", 0.0) for s in sessions)), "sessions": sessions}
    if not tm or "trial" not in tm or len(tm["trial"]) == 0:
        return out
    first = {}
    for i, trial in enumerate(tm["trial"]):
        first.setdefault(int(trial), i)
    idx = np.array(sorted(first.values()), dtype=int)
    for stage in ("sumo", "sensor"):
        col = tm.get(f"t_{stage}")
        out[f"{stage}_s"] = float(np.nansum(col[idx])) if col is not None else math.nan
    filt = {}
    fams = list(dict.fromkeys(tm[FILTER_COLUMN])) if FILTER_COLUMN in tm else [None]
    runs = [(a, b, f) for a in dict.fromkeys(tm["model"]) for b in dict.fromkeys(tm["mode"]) for f in fams]
    for model, mode, fam in runs:
        m = select(tm, model=model, mode=mode) & (tm[FILTER_COLUMN] == fam if fam is not None else True)
        if m.any():
            filt[f"{model}/{mode}" + (f"/{fam}" if fam is not None else "")] = {
                stage: float(np.nansum(tm[f"t_{stage}"][m]))
                for stage in ("birth", "predict", "update", "reduce", "metrics", "filter_total")
                if f"t_{stage}" in tm
            }
    out["filter_s"] = filt
    return out


def families(tables: RunTables) -> list[str | None]:
    """The filter families of a run's tables in the config's order ([None]: a run without a ``filter`` column)."""
    if FILTER_COLUMN not in tables.trials:
        return [None]
    present = set(tables.trials[FILTER_COLUMN])
    named = tables.meta["config"]["experiment"].get("filters", FILTER_FAMILIES[:1])
    return [f for f in named if f in present] + sorted(present - set(named))


def family_tables(tables: RunTables, family: str | None) -> RunTables:
    """The tables of one filter family (all of them for None): trials, episodes and timing rows of that family."""
    if family is None:
        return tables

    def only(table: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        if FILTER_COLUMN not in table:
            return table
        keep = table[FILTER_COLUMN] == family
        return {c: v[keep] for c, v in table.items()}

    return dataclasses.replace(tables, trials=only(tables.trials), episodes=only(tables.episodes),
                               timing=only(tables.timing))  # fmt: skip


def summarize(tables: RunTables, failures: list[dict] | None = None, sessions: list[dict] | None = None) -> dict:
    """Every number of the Markdown summary, as a JSON-able dict (also written to summary.json)."""
    meta = tables.meta
    exp = meta["config"]["experiment"]
    n_trials = int(meta.get("trials", exp["trials"]))
    ok_trials = sorted({int(t) for t in tables.trials.get("trial", [])})
    results = []
    for clutter, family in [(c, f) for c in tables.clutters for f in families(tables)]:
        results.append(_clutter_results(family_tables(tables, family), clutter, family))
    failures = failures or []
    return {
        "net": meta.get("net"),
        "net_name": meta.get("net_name"),
        "polys": meta.get("polys"),
        "scenario": meta.get("scenario"),
        "scenario_config": meta.get("scenario_config"),
        "config": meta["config"],
        "versions": meta.get("versions"),
        "platform": meta.get("platform"),
        "reproduction_tolerance": meta.get("reproduction_tolerance", REPRODUCTION_TOLERANCE),
        "warnings": [r["warning"] for r in results if r["warning"]],
        "n_trials": n_trials,
        "n_ok": len(ok_trials),
        "complete": len(ok_trials) == n_trials and not failures,
        "failures": [{k: f.get(k) for k in ("trial", "seed", "sumo_seed", "error", "worker")} for f in failures],
        "results": results,
        "timing": timing_summary(tables, sessions or []),
    }


def _clutter_results(tables: RunTables, clutter: float, family: str | None) -> dict:
    """The statistics and paired comparisons of one clutter rate (of one filter family, when not None)."""
    meta = tables.meta
    stats = {(mo, md): model_stats(tables, clutter, mo, md) for mo in tables.models for md in tables.modes}
    comps = []
    warning = unobserved_warning(tables, clutter)
    if warning:  # when, on this scene, somebody does become observable
        warning += duration_hint(meta)
    if "soa" in tables.models and not warning:  # paired against S-OA: the baselines, then every plugin
        others = [b for b in BASELINES if b in tables.models] + [
            m for m in tables.models if m != "soa" and m not in BASELINES
        ]
        for md in tables.modes:
            for b in others:
                comps.append(compare(tables, clutter, md, b, stats))
    out = {"clutter": clutter, "models": list(stats.values()), "vs_soa": comps, "warning": warning}
    baselines = [c["baseline"] for c in comps if c["mode"] == tables.modes[0]]
    out["tracks"] = _tracks(tables, clutter, baselines)
    bins = tuple(meta["config"].get("metrics", {}).get("gap_bins", MetricsConfig().gap_bins))
    # null, not NaN, where a number is undefined: summary.json stays strict JSON for the report page
    out["occlusion"] = _nan_to_none(occlusion.breakdown(tables, clutter, bins, baselines))
    out["track_intervals"] = _nan_to_none(_track_intervals(tables, clutter, baselines))
    if family is not None:
        out["filter"] = family
    return out


def _floats(values: Any) -> np.ndarray:
    """A trials.csv column as floats: an empty cell (a track column of an unlabelled tracker) is NaN."""
    return np.array([math.nan if v is None or v == "" else float(v) for v in np.asarray(values).tolist()], dtype=float)


def _tracks(tables: RunTables, clutter: float, baselines: list[str]) -> dict:
    """The Tracks table of one clutter rate (docs/method.md §9.3, §9.4): per model and mode
    :func:`soabench.tracks.report.track_stats`, and S-OA's paired HOTA comparison against ``baselines``."""
    t = tables.trials
    if "hota" not in t:
        return {}
    rows, versus = [], []
    by_trial: dict[tuple[str, str], dict[int, dict[str, float]]] = {}
    for mo in tables.models:
        for md in tables.modes:
            m = select(t, clutter=clutter, model=mo, mode=md)
            if not m.any():
                continue
            cols = {c: _floats(t[c][m]) if c in t else np.full(int(m.sum()), math.nan) for c in TRACK_KEYS}
            rows.append((mo, md, track_stats(cols.__getitem__)))
            trials = [int(v) for v in t["trial"][m]]
            by_trial[(mo, md)] = {
                n: {"hota": h, "idf1": f} for n, h, f in zip(trials, cols["hota"], cols["idf1"], strict=True)
            }
    for md in tables.modes:
        for b in baselines:
            if ("soa", md) in by_trial and (b, md) in by_trial:
                versus.append((md, b, tracks_vs_soa(by_trial[("soa", md)], by_trial[(b, md)])))
    return {"rows": rows, "versus": versus}


def _nan_to_none(obj: Any) -> Any:
    """``obj`` with every non-finite float (in nested dicts and lists) replaced by None."""
    if isinstance(obj, dict):
        return {k: _nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_nan_to_none(v) for v in obj]
    return None if isinstance(obj, float) and not math.isfinite(obj) else obj


def _track_intervals(tables: RunTables, clutter: float, baselines: list[str]) -> dict:
    """The intervals on the Tracks table of one clutter rate (:mod:`soabench.experiment.reports.track_intervals`):
    ``rows`` per labelled model and mode, ``vs_soa`` per mode and labelled baseline; {} without a labelled tracker."""
    t = tables.trials
    if "hota" not in t:
        return {}
    rows, by_trial = [], {}
    for mo in tables.models:
        for md in tables.modes:
            m = select(t, clutter=clutter, model=mo, mode=md)
            cols = {c: _floats(t[c][m]) if c in t else np.full(int(m.sum()), math.nan) for c in TRACK_KEYS}
            if not m.any() or not np.isfinite(cols["hota"]).any():
                continue
            rows.append({"model": mo, "mode": md, **track_intervals.row_intervals(cols.__getitem__)})
            by_trial[(mo, md)] = {
                int(n): {k: float(cols[k][i]) for k in track_intervals.PAIRED_KEYS} for i, n in enumerate(t["trial"][m])
            }
    versus = [
        {"mode": md, "baseline": b, **track_intervals.paired(by_trial[("soa", md)], by_trial[(b, md)])}
        for md in tables.modes
        for b in baselines
        if ("soa", md) in by_trial and (b, md) in by_trial
    ]
    return {"rows": rows, "vs_soa": versus} if rows else {}


def render_occlusion(summary: dict) -> str:
    """The occlusion section of summary.md (after every other section): per clutter rate (and filter family) the
    Tracks table's intervals and paired S-OA tests, then identity kept, coasted share and re-emergence delay by gap
    length and by occluder kind (docs/method.md §9.4)."""
    lines: list[str] = []
    for res in summary["results"]:
        iv, occ = res.get("track_intervals") or {}, res.get("occlusion") or {}
        occ = occ if occ.get("rows") else {}  # bins without a gap: nothing to tabulate
        if not iv and not occ:
            continue
        family = res.get("filter")
        where = f"λ = {res['clutter']:g}" + (f", {FAMILY_LABEL.get(family, family)}" if family else "")
        lines += ["", f"## Occlusion and identity, {where}"]
        if iv:
            stats = {(mo, md): st for mo, md, st in (res.get("tracks") or {}).get("rows", [])}
            rows = [(r["model"], r["mode"], stats[(r["model"], r["mode"])], r) for r in iv["rows"]]
            versus = [(c["mode"], c["baseline"], c) for c in iv["vs_soa"]]
            lines += ["", f"### Tracks with intervals, {where}", "", *track_intervals.render(rows, versus)]
        if occ:
            labelled = {mo: bool(st["labelled"]) for mo, _, st in (res.get("tracks") or {}).get("rows", [])}
            lines += ["", f"### Identity through occlusion gaps, {where}", *occlusion.render(occ, labelled)]
            lines += ["", occlusion.LEGEND]
    return "\n".join(lines) + "\n" if lines else ""


# ------------------------------------------------------------------------------------------------ Markdown
def fmt(x: float, nd: int = 3) -> str:
    """Fixed-point text of a number; 'n/a' for NaN."""
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.{nd}f}"


def fmt_pct(x: float) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.2f}%"


def render_markdown(summary: dict, figures: Sequence[str] = ()) -> str:
    """The summary tables in the paper's terms (Markdown)."""
    exp = summary["config"]["experiment"]
    lines = [f"# soabench run: {summary.get('net_name') or summary.get('net')}", ""]
    lines.append(
        f"{summary['n_trials']} trials x {exp['duration']:g} s, seed {exp['seed']}, "
        f"models {', '.join(LABEL.get(m, m) for m in tables_models(exp))}, modes {', '.join(exp['probabilities'])}, "
        f"clutter λ = {', '.join(f'{c:g}' for c in exp['clutter'])}. "
        f"{summary['n_ok']} of {summary['n_trials']} trials succeeded"
        + (f", {len(summary['failures'])} failed (listed below)." if summary["failures"] else ".")
    )
    for res in summary["results"]:
        family = res.get("filter")
        lines += ["", f"## λ = {res['clutter']:g}" + (f", {FAMILY_LABEL.get(family, family)}" if family else ""), ""]
        if res.get("warning"):
            lines += [f"**Warning:** {res['warning']}", ""]
        lines.append(
            "| model | mode | trials | k̄ delay (s) | σ̄ delay (s) | card. error | OSPA (m) | GOSPA (m) | precision "
            "| recall | components | censored |"
        )
        lines.append("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for s in res["models"]:
            lines.append(
                f"| {LABEL.get(s['model'], s['model'])} | {s['mode']} | {s['n_trials']} | {fmt(s['delay_mean'])} "
                f"| {fmt(s['delay_sigma_bar'])} | {fmt(s['card_err_mean'])} ± {fmt(s['card_err_std'])} "
                f"| {fmt(s['ospa_mean'])} ± {fmt(s['ospa_std'])} | {fmt(s['gospa_mean'])} "
                f"| {fmt(s['precision_mean'])} | {fmt(s['recall_mean'])} | {fmt(s['components_mean'], 1)} "
                f"| {s['n_censored']} / {s['n_episodes']} |"
            )
        if family in FAMILY_MODES:  # the modes this family does not run: one row of "—" per model
            skipped = [md for md in exp["probabilities"] if md not in FAMILY_MODES[family]]
            for model in dict.fromkeys(s["model"] for s in res["models"]):
                for md in skipped:
                    lines.append(f"| {LABEL.get(model, model)} | {md} |" + " — |" * 10)
        if res["vs_soa"]:
            lines += [
                "",
                "S-OA against each baseline: trials in which S-OA has the lower mean delay (ties, losses, n/a "
                "separately); episodes with delay_SOA ≤ delay_X; percent reduction 100·(M_X − M_SOA)/M_X of the "
                "grand means.",
                "",
                "| mode | baseline | S-OA lower k̄ | ties | S-OA higher | n/a | episodes S-OA ≤ X "
                "| card. error reduction | OSPA reduction |",
                "|---|---|---|---|---|---|---|---|---|",
            ]
            for c in res["vs_soa"]:
                frac = c["episode_le_fraction"]
                pct = fmt_pct(100 * frac if math.isfinite(frac) else frac)
                lines.append(
                    f"| {c['mode']} | {LABEL.get(c['baseline'], c['baseline'])} | {c['wins']} / {c['n_trials']} "
                    f"| {c['ties']} | {c['losses']} | {c['na']} | {pct} "
                    f"| {fmt_pct(c['card_reduction'])} | {fmt_pct(c['ospa_reduction'])} |"
                )
        if res.get("tracks"):
            tr = res["tracks"]
            rows = [(LABEL.get(mo, mo), md, st) for mo, md, st in tr["rows"]]
            versus = [(md, LABEL.get(b, b), c) for md, b, c in tr["versus"]]
            lines += ["", f"### Tracks, λ = {res['clutter']:g}", "", *render_tracks(rows, versus), "", TRACKS_LEGEND]
    if summary["results"]:
        lines += ["", table_legend(summary["config"].get("metrics", {}))]
    if summary["failures"]:
        lines += ["", f"## Failed trials ({len(summary['failures'])})", "", "| trial | seed | sumo_seed | error |"]
        lines.append("|---|---|---|---|")
        for f in summary["failures"]:
            err = str(f.get("error", "")).replace("|", "\\|").replace("\n", " ")
            lines.append(f"| {f['trial']} | {f['seed']} | {f['sumo_seed']} | {err} |")
    tm = summary.get("timing", {})
    if tm.get("wall_s"):
        lines += [
            "",
            f"Wall time {tm['wall_s']:.1f} s; SUMO {fmt(tm.get('sumo_s', math.nan), 1)} s and sensor "
            f"{fmt(tm.get('sensor_s', math.nan), 1)} s summed over trials (timing.csv has every filter stage).",
        ]
    if figures:
        lines += ["", "Figures: " + ", ".join(f"`{f}`" for f in figures)]
    return "\n".join(lines) + "\n"


def table_legend(metrics: dict) -> str:
    """What the summary table's terms mean, with the values this run used (docs/method.md §5.2-5.6)."""

    m = {**dataclasses.asdict(MetricsConfig()), **metrics}
    lower_bound = m["censored"] == "lower_bound"
    return (
        "Legend: k̄ delay is the mean over trials of each trial's mean tracking delay, σ̄ the mean of the per-trial "
        "standard deviations (docs/method.md §5.4); ± is the standard deviation over trials. **censored** counts "
        "detection episodes in which no estimate ever came within the "
        f"{m['d_gate']:g} m gate of the pedestrian (never initiated), out of all episodes; they are "
        + (
            'counted in k̄ with the episode\'s remaining length as a lower bound (metrics.censored = "lower_bound")'
            if lower_bound
            else 'left out of k̄ (metrics.censored = "exclude")'
        )
        + f". **OSPA** (§5.2): cut-off c = {m['ospa_c']:g} m, order p = {m['ospa_p']:g}; c is the distance charged "
        "for each missed or false target, and for an estimate farther than c from its pedestrian. **GOSPA** (§5.6): "
        f"cut-off c = {m['gospa_c']:g} m, order p = {m['gospa_p']:g}, α = 2; each missed or false target costs c^p / 2 "
        "and the total is not divided by the number of targets."
    )


def unobserved_warning(tables: RunTables, clutter: float) -> str:
    """A warning when no pedestrian was ever observed at ``clutter``: no detection episode (a visibility run with a
    detection, §5.4) for any model, or no target in the metrics' ground-truth set. Delays, win counts and percent
    reductions are then undefined: a "100 % lower cardinality error" would only say that S-OA made no false tracks
    where there was nothing to see. '' otherwise."""
    t = tables.trials
    m = select(t, clutter=clutter)
    total = lambda *cs: float(sum(np.nansum(t[c][m]) for c in cs)) if all(c in t for c in cs) else None  # noqa: E731
    n_episodes, n_truth = total("n_episodes"), total("tp", "fn")  # None: a table without the column
    if (n_episodes is None or n_episodes > 0) and (n_truth is None or n_truth > 0):
        return ""
    n_trials = len({int(x) for x in t["trial"][m]}) if "trial" in t else 0
    return (
        f"no pedestrian was observed at λ = {clutter:g} in {n_trials} trial(s): {int(n_episodes or 0)} detection "
        f"episodes (the ground-truth set held {int(n_truth or 0)} target-scans, none of them seen), so delays, win "
        "counts and percent reductions are undefined and not reported. Check that pedestrians walk into the "
        "sensor's field of view and line of sight (scenario, duration, sensor fov_deg and r_max)."
    )


#: what the paper's protocol fixes besides the network: every parameter section at its default (the paper's
#: values) and 100 s trials; trial count, seed, models and clutter rates may differ (λ = 3 is compared)
PAPER_SECTIONS = ("sensor", "filter", "birth", "metrics")
PAPER_DURATION_S = 100.0


def paper_protocol_mismatch(meta: dict) -> str:
    """Why the paper's numbers do not apply to a run ('' when they do): they hold only for the paper's protocol
    on the shipped intersection (its own scenario and polygons, default parameters, 100 s trials)."""

    if str(meta.get("net")) != "intersection":
        return f"the network is {meta.get('net_name') or meta.get('net')!r}, not the shipped intersection"
    if meta.get("scenario") is not None:
        return f"a user scenario file ({meta['scenario']}) replaces the shipped one"
    if meta.get("polys"):
        return "extra polygon files change the scene"
    try:
        cfg = Config.from_record(meta["config"]).to_dict()
    except SoabenchError as exc:
        return f"the run's configuration is not readable ({exc})"
    default = Config().to_dict()
    for sec in PAPER_SECTIONS:
        diff = sorted(k for k in default[sec] if cfg[sec].get(k) != default[sec][k])
        if diff:
            return f"[{sec}] {', '.join(diff)} differ from the paper's values"
    if float(cfg["experiment"]["duration"]) != PAPER_DURATION_S:
        return f"trials last {cfg['experiment']['duration']:g} s, not the paper's {PAPER_DURATION_S:g} s"
    return ""


def paper_section(run_dir: Path, tables: RunTables, clutter: float = paper.PAPER_CLUTTER) -> str:
    """The paper's headline numbers beside ours (:mod:`soabench.experiment.reports.paper`), when the run follows the
    paper's
    protocol on the shipped intersection (:func:`paper_protocol_mismatch`) and S-OA, a baseline and lambda = 3 were
    run; otherwise a line saying why there is no comparison."""
    mismatch = paper_protocol_mismatch(tables.meta)
    if mismatch:
        return (
            f"No comparison with the paper: {mismatch}; its numbers hold only for its own protocol on the shipped "
            "intersection.\n"
        )
    if "soa" not in tables.models or not set(BASELINES) & set(tables.models) or clutter not in tables.clutters:
        return ""
    if unobserved_warning(tables, clutter):
        return ""
    if not set(tables.modes) & {"static", "dynamic"}:
        return ""

    rows = [
        r
        for r in paper.read_rows(run_dir / "trials.csv")
        if r["mode"] in ("static", "dynamic") and r.get(FILTER_COLUMN, FILTER_FAMILIES[0]) == FILTER_FAMILIES[0]
    ]
    with np.errstate(invalid="ignore"):  # percentiles of all-NaN bootstrap samples (trials without episodes)
        body = paper.markdown(rows, clutter)
    return f"## Against the paper (docs/method.md §5.9), λ = {clutter:g}\n\n{body}\n"


def write_report(run_dir: Path, figures: bool = True, store: RunStore | None = None) -> str:
    """Write summary.json, summary.md and the figures of a run from its CSV files; return the Markdown.

    ``store``: the folder's :class:`RunStore` if the caller has one (the one that just merged it knows the model
    failures without reading every trial record again)."""
    run_dir = Path(run_dir)
    store = store if store is not None else RunStore(run_dir)
    tables = load_tables(run_dir, steps=store.step_columns())  # the columns its merge kept: no parse of steps.csv
    summary = summarize(tables, store.failures(), store.sessions())
    fig_paths: list[str] = []
    if figures:  # a run of several families: the GM-PHD family's figures, then the families side by side
        # imported when called: matplotlib would slow every start-up
        from soabench.figures.results import make_figures

        fig_paths = [str(p.relative_to(run_dir)) for p in make_figures(tables, run_dir / "figures")]
    if families(tables) != [None]:  # the paper's comparison: the GM-PHD family
        tables = family_tables(tables, FILTER_FAMILIES[0])
    summary["figures"] = fig_paths

    md = render_markdown(summary, fig_paths) + write_model_failures(run_dir, store.model_failures(), summary)
    paper_md = paper_section(run_dir, tables)
    if paper_md:
        md += "\n" + paper_md
    md += render_occlusion(summary)
    for warning in summary["warnings"]:
        print(f"soabench: warning: {warning}", file=sys.stderr)
    write_json_atomic(run_dir / "summary.json", summary)
    write_text_atomic(run_dir / "summary.md", md)
    return md
