"""The "Tracks" table of a run's summary (docs/method.md §9.3, §9.4), from the per-trial columns of trials.csv.

Per (clutter rate, model, mode): HOTA, AssA, IDF1 and OSPA(2) as mean ± σ over trials, ID switches as the mean per
trial, the entry and re-emergence delay as the mean of the per-trial means with σ̄ (the mean of the per-trial
standard deviations, as §5.4), the coasted and identity-kept fractions pooled over the run's gaps and re-emergence
episodes with their counts. A tracker without labels shows "—" in every label column. Against S-OA: the trials in
which S-OA's HOTA is higher (ties, lower and n/a apart) and the mean paired HOTA and IDF1 differences.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np

#: shown for a measure a tracker cannot have (no labels)
ABSENT = "—"


def _finite(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return x[np.isfinite(x)]


def _mean_std(x: np.ndarray) -> tuple[float, float]:
    x = _finite(x)
    return (float(x.mean()), float(x.std(ddof=0))) if x.size else (math.nan, math.nan)


def _pooled(frac: np.ndarray, count: np.ndarray) -> tuple[float, int]:
    """Fraction pooled over the trials' items (per-trial fraction x its count), and the number of items."""
    frac, count = np.asarray(frac, dtype=float), np.asarray(count, dtype=float)
    ok = np.isfinite(frac) & np.isfinite(count) & (count > 0)
    n = int(count[ok].sum())
    return (float((frac[ok] * count[ok]).sum()) / n if n else math.nan), n


def track_stats(col: Callable[[str], np.ndarray]) -> dict:
    """The Tracks-table numbers of one (clutter, model, mode): ``col(name)`` is that selection's per-trial column
    (NaN where a trial has no value: an unlabelled tracker's label columns are empty)."""
    labelled = bool(_finite(col("hota")).size)
    out: dict = {"labelled": labelled}
    for key in ("hota", "assa", "idf1", "ospa2", "idsw"):
        out[f"{key}_mean"], out[f"{key}_std"] = _mean_std(col(key))
    for kind in ("entry", "reemergence"):
        out[f"delay_{kind}_mean"] = _mean_std(col(f"delay_{kind}_mean"))[0]
        out[f"delay_{kind}_sigma_bar"] = _mean_std(col(f"delay_{kind}_std"))[0]
        out[f"n_{kind}"] = int(np.nansum(col(f"n_{kind}")))
        out[f"n_{kind}_censored"] = int(np.nansum(col(f"n_{kind}_censored")))
    out["coasted"], out["n_gaps"] = _pooled(col("coasted"), col("n_gaps"))
    out["id_kept"], out["n_id"] = _pooled(col("id_kept"), col("n_id")) if labelled else (math.nan, 0)
    return out


def tracks_vs_soa(soa: Mapping[int, Mapping[str, float]], other: Mapping[int, Mapping[str, float]]) -> dict:
    """Paired comparison by trial (``{trial: {column: value}}`` of S-OA and of baseline X): trials with S-OA's HOTA
    higher, equal, lower, n/a (either side without a value), and the mean paired differences S-OA − X of HOTA and
    IDF1 over the trials where both have one."""
    higher = ties = lower = na = 0
    diffs: dict[str, list[float]] = {"hota": [], "idf1": []}
    for trial in sorted(set(soa) | set(other)):
        a, b = soa.get(trial, {}), other.get(trial, {})
        h_a, h_b = a.get("hota", math.nan), b.get("hota", math.nan)
        if not (math.isfinite(h_a) and math.isfinite(h_b)):
            na += 1
            continue
        higher, ties, lower = higher + (h_a > h_b), ties + (h_a == h_b), lower + (h_a < h_b)
        for key in diffs:
            if math.isfinite(a.get(key, math.nan)) and math.isfinite(b.get(key, math.nan)):
                diffs[key].append(a[key] - b[key])
    return {
        "hota_higher": higher, "hota_ties": ties, "hota_lower": lower, "na": na,
        "n_trials": higher + ties + lower + na,
        "hota_diff": float(np.mean(diffs["hota"])) if diffs["hota"] else math.nan,
        "idf1_diff": float(np.mean(diffs["idf1"])) if diffs["idf1"] else math.nan,
    }  # fmt: skip


def _num(x: float, nd: int = 3) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.{nd}f}"


def _label(s: Mapping, text: str) -> str:
    """``text`` for a labelled tracker, :data:`ABSENT` otherwise."""
    return text if s["labelled"] else ABSENT


def _pm(s: Mapping, key: str) -> str:
    """mean ± σ of a label column."""
    return _label(s, f"{_num(s[key + '_mean'])} ± {_num(s[key + '_std'])}")


def _delay(s: Mapping, kind: str) -> str:
    """k̄ (σ̄; censored / episodes) of one episode kind."""
    return (
        f"{_num(s[f'delay_{kind}_mean'])} (σ̄ {_num(s[f'delay_{kind}_sigma_bar'])}; "
        f"{s[f'n_{kind}_censored']} / {s[f'n_{kind}']} censored)"
    )


def render_tracks(rows: list[tuple[str, str, dict]], versus: list[tuple[str, str, dict]]) -> list[str]:
    """Markdown lines of the Tracks table (``rows``: (model label, mode, :func:`track_stats`)) and of the paired
    comparison against S-OA (``versus``: (mode, baseline label, :func:`tracks_vs_soa`))."""
    lines = [
        "| model | mode | HOTA | AssA | IDF1 | IDSW / trial | OSPA(2) (m) | entry delay (s) | re-emergence delay (s) "
        "| coasted | identity kept |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for model, mode, s in rows:
        kept = _label(s, f"{_num(s['id_kept'])} of {s['n_id']}")
        lines.append(
            f"| {model} | {mode} | {_pm(s, 'hota')} | {_pm(s, 'assa')} | {_pm(s, 'idf1')} "
            f"| {_label(s, _num(s['idsw_mean'], 2))} | {_pm(s, 'ospa2')} | {_delay(s, 'entry')} "
            f"| {_delay(s, 'reemergence')} | {_num(s['coasted'])} of {s['n_gaps']} "
            f"| {kept} |"
        )
    if versus:
        lines += [
            "",
            "S-OA against each baseline (trackers with labels): trials in which S-OA's HOTA is higher (ties, lower, "
            "n/a separately); mean paired differences S-OA − X.",
            "",
            "| mode | baseline | S-OA higher HOTA | ties | S-OA lower | n/a | ΔHOTA | ΔIDF1 |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for mode, baseline, c in versus:
            lines.append(
                f"| {mode} | {baseline} | {c['hota_higher']} / {c['n_trials']} | {c['hota_ties']} | {c['hota_lower']} "
                f"| {c['na']} | {_num(c['hota_diff'])} | {_num(c['idf1_diff'])} |"
            )
    return lines


def render_hota(head: str, rows: list[tuple[str, str, str, Mapping]]) -> list[str]:
    """Markdown lines of the short track table of a sweep or a study: per row (``head`` column value, model label,
    mode, :func:`track_stats`) HOTA and IDF1 (mean ± σ over trials) and ID switches per trial; nothing when no row
    is labelled."""
    if not any(st["labelled"] for *_, st in rows):
        return []
    lines = [f"| {head} | model | mode | HOTA | IDF1 | IDSW / trial |", "|---|---|---|---|---|---|"]
    for key, model, mode, st in rows:
        idsw = _label(st, _num(st["idsw_mean"], 2))
        lines.append(f"| {key} | {model} | {mode} | {_pm(st, 'hota')} | {_pm(st, 'idf1')} | {idsw} |")
    return lines


TRACKS_LEGEND = (
    "Legend (docs/method.md §9.3, §9.4): HOTA, AssA (association accuracy) and IDF1 are fractions (1 = perfect), "
    "mean ± σ over trials; IDSW counts identity switches; OSPA(2) is the OSPA distance between truth and estimated "
    "tracks over a sliding window. Entry and re-emergence delays are the §5.4 delay split by episode kind: a "
    "re-emergence episode starts when a pedestrian comes back into sight after an occlusion inside the field of "
    "view. **coasted**: the fraction of occlusion gaps covered by an estimate on every scan; **identity kept**: the "
    "fraction of re-emergences re-acquired under the label the pedestrian had before the gap. "
    f"{ABSENT}: no track metric: the tracker gives no labels, or its filter family defines no run in that mode."
)
