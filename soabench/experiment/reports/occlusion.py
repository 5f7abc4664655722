"""What occlusion costs, from a run's episode rows (docs/method.md §9.4, "Breakdowns"): identity kept, coasted
share and re-emergence delay per gap-length bin and per occluder kind, with 95 % intervals, and S-OA's paired
differences per bin.

Per (clutter rate, model, mode) and group (a gap-length bin of ``metrics.gap_bins``, or an occluder kind):

* **identity kept**: kept / counted over the group's re-emergence episodes that count for it (``gap_id_kept``
  not empty), pooled over the trials; labelled trackers only;
* **coasted**: coasted gaps / gaps, over the gaps that start a re-emergence episode;
* **re-emergence delay**: the mean delay of the group's uncensored re-emergence episodes (s), pooled.

The intervals are percentile bootstrap intervals over trials (the trials are resampled with replacement and each
pooled ratio recomputed; the gaps of one trial share its scene and are not independent), with the seed and
resample count of the paired statistics of §5.8 (:mod:`soabench.experiment.reports.paper`), so they are the same on
every run of the same rows. S-OA against X: the difference of the pooled ratios, S-OA − X, with the paired
bootstrap interval (the same resampled trials for both).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from soabench.birth import LABEL
from soabench.experiment.reports import paper
from soabench.experiment.reports.tables import RunTables, select
from soabench.tracks.gaps import OCCLUDER_KINDS, OCCLUDER_LABEL

#: the measures of a group, each a pooled ratio (numerator column, denominator rule) over its episodes
MEASURES = ("id_kept", "coasted", "delay")
#: the bins' upper limit when the last bin is open
OPEN = math.inf


def bin_labels(bins: Sequence[int]) -> list[str]:
    """Names of the gap-length bins whose first scan counts are ``bins``: (1, 2, 4, 8) -> 1, 2-3, 4-7, 8+."""
    out = []
    for i, lo in enumerate(bins):
        hi = bins[i + 1] - 1 if i + 1 < len(bins) else OPEN
        out.append(f"{lo}+" if hi == OPEN else str(lo) if hi == lo else f"{lo}-{hi}")
    return out


def _floats(values: Any) -> np.ndarray:
    return np.array([math.nan if v is None or v == "" else float(v) for v in np.asarray(values).tolist()], dtype=float)


def _per_trial(
    trials: np.ndarray, ep_trial: np.ndarray, num: np.ndarray, den: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Sums of ``num`` and ``den`` per trial of ``trials`` (episodes tagged ``ep_trial``)."""
    pos = {int(t): i for i, t in enumerate(trials)}
    idx = np.array([pos[int(t)] for t in ep_trial], dtype=np.int64)
    return (np.bincount(idx, weights=num, minlength=len(trials)), np.bincount(idx, weights=den, minlength=len(trials)))


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """num.sum(-1) / den.sum(-1), NaN where the denominator is 0."""
    return _ratio_of(num.sum(axis=-1), den.sum(axis=-1))


def _ratio_of(n: np.ndarray, d: np.ndarray) -> np.ndarray:
    """n / d of sums, NaN where the denominator is 0."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(d > 0, n / np.where(d > 0, d, 1.0), np.nan)


def _boot_ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """The pooled ratio of every bootstrap resample of the trials (:func:`paper.resampled_sums`):
    ``_ratio(num[draws], den[draws])`` with the draws of :func:`paper.resample_indices`."""
    return _ratio_of(paper.resampled_sums(num), paper.resampled_sums(den))


def _interval(values: np.ndarray) -> tuple[float, float]:
    """The central :data:`paper.CI_LEVEL` percentile interval of bootstrap ``values`` (NaN when none is finite)."""
    values = values[np.isfinite(values)]
    if values.size == 0:
        return math.nan, math.nan
    lo, hi = np.quantile(values, [(1 - paper.CI_LEVEL) / 2, (1 + paper.CI_LEVEL) / 2])
    return float(lo), float(hi)


def _cells(e: dict[str, np.ndarray], mask: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per measure the per-episode numerator and denominator of the rows ``mask``."""
    kept = _floats(e["gap_id_kept"][mask])
    coasted = _floats(e["gap_coasted"][mask])
    delay = _floats(e["delay"][mask])
    ok_delay = np.isfinite(delay) & (_floats(e["censored"][mask]) == 0)
    return {
        "id_kept": (np.nan_to_num(kept), np.isfinite(kept).astype(float)),
        "coasted": (np.nan_to_num(coasted), np.isfinite(coasted).astype(float)),
        "delay": (np.where(ok_delay, delay, 0.0), ok_delay.astype(float)),
    }


def _groups(e: dict[str, np.ndarray], bins: Sequence[int]) -> list[tuple[str, str, np.ndarray]]:
    """(by, group, mask over the episode rows) of every gap-length bin and occluder kind."""
    n = _floats(e["gap_scans"])
    kinds = np.asarray(e["gap_occluder"]).astype(str)
    out = []
    for label, lo, hi in zip(bin_labels(bins), bins, [*bins[1:], OPEN], strict=True):
        out.append(("gap", label, (n >= lo) & (n < hi)))
    for kind in OCCLUDER_KINDS:
        out.append(("occluder", kind, kinds == kind))
    return out


def _has_gaps(e: dict[str, np.ndarray]) -> bool:
    return bool(e) and "gap_scans" in e and bool(np.isfinite(_floats(e["gap_scans"])).any())


def identity_curves(tables: RunTables, clutter: float, bins: Sequence[int]) -> dict[str, dict[tuple[str, str], Any]]:
    """Identity kept per gap-length bin for every occluder kind with a gap ("all" first: every kind together): per
    kind and (model, mode) an array (n_bins, 4) of the pooled value, its bootstrap interval and the count; {} for
    a run without gaps. Only labelled trackers (some identity counted) get a curve."""
    e, t = tables.episodes, tables.trials
    if not _has_gaps(e):
        return {}
    n = _floats(e["gap_scans"])
    kinds = np.asarray(e["gap_occluder"]).astype(str)
    bin_masks = [(n >= lo) & (n < hi) for lo, hi in zip(bins, [*bins[1:], OPEN], strict=True)]
    out: dict[str, dict[tuple[str, str], Any]] = {}
    for kind in ("all", *OCCLUDER_KINDS):
        kind_mask = np.isfinite(n) if kind == "all" else kinds == kind
        if not kind_mask.any():
            continue
        curves = {}
        for model in tables.models:
            for mode in tables.modes:
                trials = np.unique(t["trial"][select(t, clutter=clutter, model=model, mode=mode)]).astype(int)
                sel = select(e, clutter=clutter, model=model, mode=mode) & kind_mask
                if not len(trials) or not np.isfinite(_floats(e["gap_id_kept"][sel])).any():
                    continue
                arr = np.full((len(bins), 4), np.nan)
                for i, bm in enumerate(bin_masks):
                    num, den = _cells(e, sel & bm)["id_kept"]
                    s_num, s_den = _per_trial(trials, e["trial"][sel & bm], num, den)
                    if s_den.sum() > 0:
                        arr[i] = (
                            s_num.sum() / s_den.sum(),
                            *_interval(_boot_ratio(s_num, s_den)),
                            s_den.sum(),
                        )
                    else:
                        arr[i, 3] = 0
                curves[(model, mode)] = arr
        if curves:
            out[kind] = curves
    return out


def breakdown(tables: RunTables, clutter: float, bins: Sequence[int], baselines: Sequence[str]) -> dict:
    """The breakdowns of one clutter rate (module docstring): ``rows`` (one per model, mode and group) and
    ``vs_soa`` (one per mode, baseline and group), both empty for a run without a gap; {} for tables without the
    gap columns."""
    e, t = tables.episodes, tables.trials
    if not e or "gap_scans" not in e:
        return {}
    if not _has_gaps(e):
        return {"bins": list(bins), "bin_labels": bin_labels(bins), "rows": [], "vs_soa": []}
    groups = _groups(e, bins)
    per: dict[tuple[str, str], tuple[np.ndarray, dict]] = {}
    rows = []
    for model in tables.models:
        for mode in tables.modes:
            trials = np.unique(t["trial"][select(t, clutter=clutter, model=model, mode=mode)]).astype(int)
            if not len(trials):
                continue
            sel = select(e, clutter=clutter, model=model, mode=mode)
            sums = {}
            for by, group, mask in groups:
                m = sel & mask
                cells = _cells(e, m)
                row: dict[str, Any] = {"model": model, "mode": mode, "by": by, "group": group}
                for measure, (num, den) in cells.items():
                    s_num, s_den = _per_trial(trials, e["trial"][m], num, den)
                    sums[(by, group, measure)] = (s_num, s_den)
                    row[measure] = float(_ratio(s_num, s_den)) if s_den.sum() > 0 else math.nan
                    row[f"{measure}_lo"], row[f"{measure}_hi"] = _interval(_boot_ratio(s_num, s_den))
                    row[f"n_{measure}"] = int(s_den.sum())
                rows.append(row)
            per[(model, mode)] = (trials, sums)
    versus = []
    for mode in tables.modes:
        if ("soa", mode) not in per:
            continue
        for b in baselines:
            if (b, mode) not in per:
                continue
            (t_a, s_a), (t_b, s_b) = per[("soa", mode)], per[(b, mode)]
            common = np.intersect1d(t_a, t_b)
            ia, ib = np.searchsorted(t_a, common), np.searchsorted(t_b, common)
            for by, group, _ in groups:
                c: dict[str, Any] = {"mode": mode, "baseline": b, "by": by, "group": group, "n_trials": len(common)}
                for measure in MEASURES:
                    (na, da), (nb, db) = s_a[(by, group, measure)], s_b[(by, group, measure)]
                    na, da, nb, db = na[ia], da[ia], nb[ib], db[ib]
                    c[f"{measure}_diff"] = float(_ratio(na, da) - _ratio(nb, db))
                    boot = _boot_ratio(na, da) - _boot_ratio(nb, db)  # the same resamples for both
                    c[f"{measure}_diff_lo"], c[f"{measure}_diff_hi"] = _interval(boot)
                versus.append(c)
    return {"bins": list(bins), "bin_labels": bin_labels(bins), "rows": rows, "vs_soa": versus}


# ------------------------------------------------------------------------------------------------------ Markdown
def _num(x: float, nd: int = 3) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.{nd}f}"


def _ci(row: dict, key: str, nd: int = 3) -> str:
    """value [lo, hi] (n)."""
    if row[key] is None or not math.isfinite(row[key]):
        return "n/a (0)"
    return f"{_num(row[key], nd)} [{_num(row[key + '_lo'], nd)}, {_num(row[key + '_hi'], nd)}] ({row[f'n_{key}']})"


def _group_name(by: str, group: str) -> str:
    return (f"{group} scan" + ("" if group == "1" else "s")) if by == "gap" else OCCLUDER_LABEL.get(group, group)


def render(occ: dict, labelled: dict[str, bool]) -> list[str]:
    """Markdown lines of one clutter rate's breakdowns (``labelled``: model -> whether it labels its estimates)."""
    lines: list[str] = []
    for by, title in (("gap", "gap length"), ("occluder", "occluder kind")):
        lines += [
            "",
            f"By {title}: value [95 % bootstrap interval over trials] (count).",
            "",
            f"| model | mode | {title} | identity kept | coasted | re-emergence delay (s) |",
            "|---|---|---|---|---|---|",
        ]
        seen = {r["group"] for r in occ["rows"] if r["by"] == by and r["n_coasted"] > 0}
        for r in occ["rows"]:
            if r["by"] != by or (by == "occluder" and r["group"] not in seen):  # a kind that hid nobody: no row
                continue
            kept = _ci(r, "id_kept") if labelled.get(r["model"], False) else "—"
            lines.append(
                f"| {LABEL.get(r['model'], r['model'])} | {r['mode']} | {_group_name(by, r['group'])} | {kept} "
                f"| {_ci(r, 'coasted')} | {_ci(r, 'delay', 2)} |"
            )
    pairs = [c for c in occ["vs_soa"] if c["by"] == "gap" and labelled.get(c["baseline"], False)]
    if pairs and labelled.get("soa", False):
        lines += [
            "",
            "S-OA − X per gap length (pooled ratios; [95 % paired bootstrap interval over trials]).",
            "",
            "| mode | baseline | gap length | Δ identity kept | Δ coasted | Δ re-emergence delay (s) |",
            "|---|---|---|---|---|---|",
        ]
        for c in pairs:
            cells = [
                f"{_num(c[f'{m}_diff'], nd)} [{_num(c[f'{m}_diff_lo'], nd)}, {_num(c[f'{m}_diff_hi'], nd)}]"
                for m, nd in (("id_kept", 3), ("coasted", 3), ("delay", 2))
            ]
            lines.append(
                f"| {c['mode']} | {LABEL.get(c['baseline'], c['baseline'])} | {_group_name('gap', c['group'])} | "
                + " | ".join(cells)
                + " |"
            )
    return lines


LEGEND = (
    "Legend (docs/method.md §9.4): each occlusion gap is binned by its length in scans and by the occluder kind that "
    "hid the pedestrian longest (parked car, moving vehicle, building, other obstacle). **identity kept**: the "
    "share of re-emergences re-acquired under the label held before the gap (labelled trackers; — otherwise); "
    "**coasted**: the share of gaps covered by an estimate on every scan; **re-emergence delay**: mean delay of "
    "the re-emergence episodes after those gaps. Each is pooled over the run's gaps; the interval resamples trials."
)
