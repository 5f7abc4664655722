"""The paper's headline numbers (docs/method.md §5.9) side by side with ours, with paired statistics.

For every comparison "S-OA vs X" this module reports the paper's number, ours, a paired Wilcoxon signed-rank test
over trials and a paired bootstrap confidence interval (percentile, trials resampled with replacement, fixed seed).
Inputs are the rows of a run's ``trials.csv`` (one row per trial x clutter x model x mode), so the comparison can be
re-made from committed results alone.
"""

from __future__ import annotations

import csv
import functools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from soabench.birth import BASELINES, LABEL

MODE_LABEL = {
    "static": "without dyn. p",
    "dynamic": "with dyn. p",
    "dynamic+occ": "dyn. p + occlusion",
    "static+occ": "static p + occlusion",
}

#: The paper's numbers; its UBM spreads the grid "uniformly across the workspace", so they stand beside our
#: ``ubm-ws``. Our ``ubm`` (the grid clipped to the field of view) has no paper counterpart: its paper cells are "-".
#: trials (of 100) in which S-OA has the lower mean delay than X (§5.9)
PAPER_WINS = {
    "static": {"pubm": 72, "ubm-ws": 100, "atbm": 5, "gmbm": 100},
    "dynamic": {"pubm": 68, "ubm-ws": 96, "atbm": 2, "gmbm": 100},
}
#: mean per-trial std of the delay, sigma-bar (s)
PAPER_SIGMA = {
    "static": {"pubm": 1.94, "ubm-ws": 2.93, "atbm": 0.96, "gmbm": 14.51, "soa": 1.65},
    "dynamic": {"pubm": 1.82, "ubm-ws": 2.98, "atbm": 0.56, "gmbm": 14.82, "soa": 1.71},
}
#: S-OA's percent reduction of the mean absolute cardinality error vs X
PAPER_CARD_REDUCTION = {
    "static": {"pubm": 9.03, "ubm-ws": 39.12, "atbm": 31.27, "gmbm": 82.41},
    "dynamic": {"pubm": 7.75, "ubm-ws": 35.18, "atbm": 60.94, "gmbm": 81.71},
}
#: S-OA's percent reduction of the mean OSPA (c = 100, p = 1) vs X
PAPER_OSPA_REDUCTION = {
    "static": {"pubm": 7.88, "ubm-ws": 35.43, "atbm": 14.86, "gmbm": 80.54},
    "dynamic": {"pubm": 6.15, "ubm-ws": 31.03, "atbm": 42.40, "gmbm": 79.72},
}

#: the clutter rate λ of the paper's numbers (§5.9): ours are compared at the same rate
PAPER_CLUTTER = 3.0

N_BOOT = 4000
BOOT_SEED = 20240501
CI_LEVEL = 0.95


def read_rows(path: str | Path) -> list[dict]:
    """Rows of a ``trials.csv`` with numbers parsed (empty or 'nan' -> NaN)."""
    out = []
    with open(path, newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            parsed: dict = {}
            for k, v in row.items():
                try:
                    parsed[k] = float(v) if v not in ("", None) else math.nan
                except ValueError:
                    parsed[k] = v
            out.append(parsed)
    return out


def paired(rows: Iterable[dict], metric: str, a: str, b: str, mode: str, clutter: float) -> tuple[np.ndarray, ...]:
    """Per-trial values of ``metric`` for models a and b (same trials, sorted by trial); NaN where missing."""
    table: dict[int, dict[str, float]] = {}
    for r in rows:
        if r["mode"] == mode and float(r["clutter"]) == float(clutter) and r["model"] in (a, b):
            table.setdefault(int(r["trial"]), {})[r["model"]] = float(r[metric])
    trials = sorted(table)
    xa = np.array([table[t].get(a, math.nan) for t in trials])
    xb = np.array([table[t].get(b, math.nan) for t in trials])
    return xa, xb


@dataclass
class Comparison:
    """One S-OA vs X comparison of one metric in one mode."""

    mode: str
    baseline: str
    metric: str
    paper: float
    ours: float
    ci_low: float
    ci_high: float
    p_value: float
    n: int


def _wilcoxon(x: np.ndarray, y: np.ndarray) -> float:
    d = x - y
    if len(d) < 2 or np.all(d == 0):
        return math.nan
    return float(stats.wilcoxon(x, y, zero_method="wilcox").pvalue)


def wilcoxon_p(x: np.ndarray, y: np.ndarray) -> float:
    """Two-sided Wilcoxon signed-rank p of paired values (NaN for fewer than 2 pairs or all differences 0)."""
    return _wilcoxon(np.asarray(x, dtype=float), np.asarray(y, dtype=float))


#: trial counts up to which the resamples are kept for the process (4,000 x 1,000 indices: 32 MB, and as much for
#: their counts); larger ones are drawn again at each call
KEPT_TRIALS = 1000


def resample_indices(n: int) -> np.ndarray:
    """(N_BOOT, n) trial indices drawn with replacement from the fixed seed: every bootstrap of this package (drawn
    once per n up to :data:`KEPT_TRIALS` in a process; read-only)."""
    return _kept_indices(n) if n <= KEPT_TRIALS else _indices(n)


def resample_counts(n: int) -> np.ndarray:
    """(N_BOOT, n): how often each trial is drawn in each resample of :func:`resample_indices` (float; read-only)."""
    return _kept_counts(n) if n <= KEPT_TRIALS else _counts(n)


def _indices(n: int) -> np.ndarray:
    idx = np.random.default_rng(BOOT_SEED).integers(0, n, size=(N_BOOT, n))
    idx.flags.writeable = False
    return idx


def _counts(n: int) -> np.ndarray:
    rows = np.arange(N_BOOT, dtype=np.int64)[:, None] * n
    counts = np.bincount((rows + resample_indices(n)).ravel(), minlength=N_BOOT * n).reshape(N_BOOT, n)
    out = counts.astype(float)
    out.flags.writeable = False
    return out


_kept_indices = functools.lru_cache(maxsize=4)(_indices)
_kept_counts = functools.lru_cache(maxsize=4)(_counts)


def resampled_sums(values: np.ndarray) -> np.ndarray:
    """(N_BOOT,): each resample's sum of the drawn trials' ``values`` (n,), ``values[resample_indices(n)].sum(-1)``.

    Non-negative whole numbers (counts of episodes) add up exactly in any order while every sum stays below 2^53
    (a resample may draw the largest value n times), so their sums are taken as one product with
    :func:`resample_counts`, which gives the same numbers as the gather; any other values are gathered and summed
    as numpy sums them."""
    values = np.asarray(values, dtype=float)
    n = len(values)
    whole = n and not np.signbit(values).any() and (values == np.round(values)).all()  # NaN is not whole
    if whole and n * values.max() < 2.0**53:
        return resample_counts(n) @ values
    return values[resample_indices(n)].sum(axis=-1)


def paired_interval(statistic, x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """The paired bootstrap percentile interval of ``statistic(x[idx], y[idx])`` over resampled trials."""
    return _bootstrap(statistic, np.asarray(x, dtype=float), np.asarray(y, dtype=float))


def _bootstrap(statistic, x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    if len(x) < 2:
        return math.nan, math.nan
    idx = resample_indices(len(x))
    values = statistic(x[idx], y[idx])
    lo, hi = np.nanquantile(values, [(1 - CI_LEVEL) / 2, (1 + CI_LEVEL) / 2])
    return float(lo), float(hi)


def percent_reduction(m_x, m_soa):
    """S-OA's percent reduction ``100 (M_X - M_SOA) / M_X`` of a metric's grand means (§5.8).

    Works on scalars and arrays; NaN where M_X is 0 or either mean is not finite.
    """
    m_x = np.asarray(m_x, dtype=float)
    m_soa = np.asarray(m_soa, dtype=float)
    ok = np.isfinite(m_x) & np.isfinite(m_soa) & (m_x != 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(ok, 100.0 * (m_x - m_soa) / np.where(ok, m_x, 1.0), np.nan)
    return float(out) if out.ndim == 0 else out


def _reduction(x_soa: np.ndarray, x_base: np.ndarray) -> np.ndarray:
    """:func:`percent_reduction` of the (resampled) per-trial values, means along the last axis."""
    return percent_reduction(np.mean(x_base, axis=-1), np.mean(x_soa, axis=-1))


def _win_fraction(x_soa: np.ndarray, x_base: np.ndarray) -> np.ndarray:
    return 100.0 * np.mean(x_soa < x_base, axis=-1)


def compare(rows: Sequence[dict], clutter: float = PAPER_CLUTTER) -> list[Comparison]:
    """Every headline comparison of §5.9 that the rows allow."""
    out: list[Comparison] = []
    present = {r["mode"] for r in rows}
    modes = [m for m in PAPER_WINS if m in present]
    models = {r["model"] for r in rows}
    for mode in modes:
        for base in BASELINES:
            if "soa" not in models or base not in models:
                continue
            # win counts on the mean delay: trials where both have a counted episode
            s, b = paired(rows, "delay_mean", "soa", base, mode, clutter)
            ok = np.isfinite(s) & np.isfinite(b)
            s, b = s[ok], b[ok]
            n = int(ok.sum())
            lo, hi = _bootstrap(_win_fraction, s, b)
            wins = float(np.sum(s < b))
            out.append(
                Comparison(
                    mode,
                    base,
                    "wins",
                    PAPER_WINS[mode].get(base, math.nan),
                    wins,
                    lo * n / 100,
                    hi * n / 100,
                    _wilcoxon(s, b),
                    n,
                )
            )
            for metric, paper in (("card_err", PAPER_CARD_REDUCTION), ("ospa", PAPER_OSPA_REDUCTION)):
                s, b = paired(rows, metric, "soa", base, mode, clutter)
                ok = np.isfinite(s) & np.isfinite(b)
                s, b = s[ok], b[ok]
                lo, hi = _bootstrap(_reduction, s, b)
                ours = float(_reduction(s, b)) if len(s) else math.nan
                out.append(
                    Comparison(
                        mode, base, metric, paper[mode].get(base, math.nan), ours, lo, hi, _wilcoxon(s, b), len(s)
                    )
                )
    return out


def sigma_bar(rows: Sequence[dict], mode: str, model: str, clutter: float = PAPER_CLUTTER) -> float:
    """Mean per-trial delay std over trials with a counted episode (the paper's sigma-bar)."""
    v = np.array(
        [
            float(r["delay_std"])
            for r in rows
            if r["mode"] == mode and r["model"] == model and float(r["clutter"]) == float(clutter)
        ]
    )
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else math.nan


def _fmt(x: float, nd: int = 1) -> str:
    return "n/a" if not np.isfinite(x) else f"{x:.{nd}f}"


def _pct(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.2f}%"


def _paper(x: float, nd: int) -> str:
    """A paper cell: "-" where the paper has no such number (e.g. for UBM clipped to the FOV)."""
    return "-" if not math.isfinite(x) else f"{x:.{nd}f}"


def _p(x: float) -> str:
    if not np.isfinite(x):
        return "n/a"
    return "< 1e-4" if x < 1e-4 else f"{x:.3g}"


#: a p-value as the tables print it
format_p = _p


def markdown(rows: Sequence[dict], clutter: float = PAPER_CLUTTER) -> str:
    """The side-by-side tables of results/README.md."""
    comps = compare(rows, clutter)
    lines: list[str] = []
    n_trials = len({int(r["trial"]) for r in rows})
    lines.append(
        f"Trials: {n_trials}; clutter lambda = {clutter:g}. CI: {int(CI_LEVEL * 100)}% paired bootstrap "
        f"({N_BOOT} resamples of trials); p: two-sided Wilcoxon signed-rank test on the paired per-trial values."
    )
    lines.append("")
    lines.append("### Tracking delay: trials in which S-OA has the lower mean delay")
    lines.append("")
    lines.append("| mode | vs | paper (of 100) | ours | 95% CI | trials compared | Wilcoxon p |")
    lines.append("|---|---|---:|---:|---|---:|---:|")
    for c in comps:
        if c.metric == "wins":
            lines.append(
                f"| {MODE_LABEL[c.mode]} | {LABEL[c.baseline]} | {_paper(c.paper, 0)} | {c.ours:.0f} of {c.n} "
                f"| [{_fmt(c.ci_low, 0)}, {_fmt(c.ci_high, 0)}] | {c.n} | {_p(c.p_value)} |"
            )
    lines.append("")
    lines.append("### Mean per-trial standard deviation of the delay, sigma-bar (s)")
    lines.append("")
    models = [m for m in ("soa", *BASELINES) if any(r["model"] == m for r in rows)]
    lines.append("| mode | " + " | ".join(f"{LABEL[m]} paper / ours" for m in models) + " |")
    lines.append("|---|" + "---:|" * len(models))
    for mode in [m for m in PAPER_SIGMA if any(r["mode"] == m for r in rows)]:
        cells = [
            f"{_paper(PAPER_SIGMA[mode].get(m, math.nan), 2)} / {_fmt(sigma_bar(rows, mode, m, clutter), 2)}"
            for m in models
        ]
        lines.append(f"| {MODE_LABEL[mode]} | " + " | ".join(cells) + " |")
    for metric, title in (("card_err", "mean absolute cardinality error"), ("ospa", "mean OSPA (c = 100, p = 1)")):
        lines.append("")
        lines.append(f"### S-OA's percent reduction of the {title}")
        lines.append("")
        lines.append("| mode | vs | paper | ours | 95% CI | Wilcoxon p |")
        lines.append("|---|---|---:|---:|---|---:|")
        for c in comps:
            if c.metric == metric:
                lines.append(
                    f"| {MODE_LABEL[c.mode]} | {LABEL[c.baseline]} | {_pct(c.paper)} | {_fmt(c.ours, 2)}% "
                    f"| [{_fmt(c.ci_low, 2)}, {_fmt(c.ci_high, 2)}]% | {_p(c.p_value)} |"
                )
    return "\n".join(lines)


def component_ratios(rows: Sequence[dict], clutter: float = PAPER_CLUTTER) -> dict[tuple[str, str], float]:
    """Mean posterior components of each model divided by S-OA's, per mode (paper: UBM ~ 5-6 x S-OA on KITTI)."""
    out = {}
    for mode in sorted({r["mode"] for r in rows}):
        means = {}
        for m in ("soa", *BASELINES):
            v = [
                float(r["mean_components"])
                for r in rows
                if r["mode"] == mode and r["model"] == m and float(r["clutter"]) == float(clutter)
            ]
            if v:
                means[m] = float(np.mean(v))
        for m, v in means.items():
            if "soa" in means and means["soa"] > 0:
                out[(mode, m)] = v / means["soa"]
    return out


def precision_by_clutter(rows: Sequence[dict]) -> dict[tuple[str, str, float], float]:
    """Mean per-trial precision per (mode, model, lambda) (paper Fig. 5h: ATBM falls with lambda, S-OA stays high)."""
    acc: dict[tuple[str, str, float], list[float]] = {}
    for r in rows:
        p = float(r["precision"])
        if np.isfinite(p):
            acc.setdefault((r["mode"], r["model"], float(r["clutter"])), []).append(p)
    return {k: float(np.mean(v)) for k, v in acc.items()}
