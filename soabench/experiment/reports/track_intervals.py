"""Intervals on the Tracks table (docs/method.md §9.3, §9.4, statistics of §5.8): per model and mode the 95 %
interval of the mean over trials of HOTA, AssA, IDF1, OSPA(2) and ID switches (Student t), and of the pooled
identity kept (percentile bootstrap over trials); per S-OA comparison the mean paired difference S-OA − X of HOTA,
IDF1 and identity kept (per trial) with its paired bootstrap interval and the two-sided Wilcoxon signed-rank p,
as the paper's comparison (:mod:`soabench.experiment.reports.paper`) computes them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from scipy.stats import t as student_t

from soabench.birth import LABEL
from soabench.experiment.reports import paper

#: columns with a t-interval of the mean over trials
MEAN_KEYS = ("hota", "assa", "idf1", "ospa2", "idsw")
#: columns of the paired S-OA comparison
PAIRED_KEYS = ("hota", "idf1", "id_kept")


def mean_interval(x: np.ndarray) -> tuple[float, float, float, int]:
    """Mean of the finite values, the ends of its 95 % Student-t interval, and their count (NaN ends below 2)."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan, math.nan, math.nan, 0
    mean = float(x.mean())
    if x.size < 2:
        return mean, math.nan, math.nan, 1
    half = float(student_t.ppf((1 + paper.CI_LEVEL) / 2, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
    return mean, mean - half, mean + half, int(x.size)


def _pooled_interval(frac: np.ndarray, count: np.ndarray) -> tuple[float, float]:
    """Bootstrap interval over trials of a fraction pooled over the trials' items (fraction x count per trial)."""
    frac, count = np.asarray(frac, dtype=float), np.asarray(count, dtype=float)
    ok = np.isfinite(count)
    num, den = np.where(ok & np.isfinite(frac), frac * count, 0.0), np.where(ok & np.isfinite(frac), count, 0.0)
    if len(num) < 2 or den.sum() == 0:
        return math.nan, math.nan
    n, d = paper.resampled_sums(num), paper.resampled_sums(den)
    vals = n[d > 0] / d[d > 0]
    lo, hi = np.quantile(vals, [(1 - paper.CI_LEVEL) / 2, (1 + paper.CI_LEVEL) / 2])
    return float(lo), float(hi)


def row_intervals(col: Callable[[str], np.ndarray]) -> dict[str, Any]:
    """The intervals of one (model, mode): ``col(name)`` its per-trial column (NaN where a trial has none)."""
    out: dict[str, Any] = {}
    for key in MEAN_KEYS:
        out[key], out[f"{key}_lo"], out[f"{key}_hi"], out[f"n_{key}"] = mean_interval(col(key))
    out["id_kept_lo"], out["id_kept_hi"] = _pooled_interval(col("id_kept"), col("n_id"))
    return out


def _mean_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.mean(a - b, axis=-1)


def paired(soa: Mapping[int, Mapping[str, float]], other: Mapping[int, Mapping[str, float]]) -> dict[str, Any]:
    """Per :data:`PAIRED_KEYS` column the mean paired difference S-OA − X over the trials where both have a value,
    its paired bootstrap interval, the Wilcoxon p and the number of pairs (``{trial: {column: value}}`` each)."""
    out: dict[str, Any] = {}
    for key in PAIRED_KEYS:
        trials = [
            n for n in sorted(set(soa) & set(other))
            if math.isfinite(soa[n].get(key, math.nan)) and math.isfinite(other[n].get(key, math.nan))
        ]  # fmt: skip
        a = np.array([soa[n][key] for n in trials], dtype=float)
        b = np.array([other[n][key] for n in trials], dtype=float)
        out[f"{key}_diff"] = float(np.mean(a - b)) if trials else math.nan
        out[f"{key}_lo"], out[f"{key}_hi"] = paper.paired_interval(_mean_diff, a, b)
        out[f"{key}_p"] = paper.wilcoxon_p(a, b)
        out[f"{key}_n"] = len(trials)
    return out


def _num(x: float, nd: int = 3) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.{nd}f}"


def _p(x: float | None) -> str:
    return "n/a" if x is None else paper.format_p(x)


def _iv(s: Mapping, key: str, nd: int = 3, value: Any = KeyError) -> str:
    """value [lo, hi] of ``key`` (the value ``s[key]`` unless given; None reads n/a)."""
    value = s[key] if value is KeyError else value
    return f"{_num(value, nd)} [{_num(s[f'{key}_lo'], nd)}, {_num(s[f'{key}_hi'], nd)}]"


def render(rows: Sequence[tuple[str, str, dict, dict]], versus: Sequence[tuple[str, str, dict]]) -> list[str]:
    """Markdown lines: ``rows`` (model, mode, :func:`soabench.tracks.report.track_stats`, :func:`row_intervals`)
    of the labelled trackers and ``versus`` (mode, baseline, :func:`paired`)."""
    lines = [
        "Mean over trials [95 % interval of the mean, Student t]; identity kept pooled over the run's re-emergences "
        "[95 % bootstrap interval over trials].",
        "",
        "| model | mode | HOTA | AssA | IDF1 | OSPA(2) (m) | IDSW / trial | identity kept |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for model, mode, st, iv in rows:
        cells = [_iv(iv, k, 2 if k == "idsw" else 3) for k in ("hota", "assa", "idf1", "ospa2", "idsw")]
        kept = _iv(iv, "id_kept", value=st["id_kept"])
        lines.append(f"| {LABEL.get(model, model)} | {mode} | " + " | ".join(cells) + f" | {kept} |")
    if versus:
        lines += [
            "",
            "S-OA − X, mean over trials of the paired per-trial difference [95 % paired bootstrap interval]; p: "
            "two-sided Wilcoxon signed-rank test; n: trials where both have a value.",
            "",
            "| mode | baseline | ΔHOTA | p | ΔIDF1 | p | Δ identity kept | p | n |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for mode, b, c in versus:
            cells = [f"{_iv(c, k, value=c[f'{k}_diff'])} | {_p(c[f'{k}_p'])}" for k in PAIRED_KEYS]
            lines.append(f"| {mode} | {LABEL.get(b, b)} | " + " | ".join(cells) + f" | {c['hota_n']} |")
    return lines
