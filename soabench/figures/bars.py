"""What several figures draw alike: the mean with its confidence interval over trials, and grouped bars.

One model per slot (its colour), one bar per probability mode (its hatch), mean ± σ over trials with every
per-trial value as a dot (docs/method.md §5.8: the per-trial numbers the tables summarise).
"""

from __future__ import annotations

import math

import numpy as np

from soabench.figures import style as ps


def mean_ci(v: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """Mean of the finite values and the half-width of its Student-t confidence interval (NaN if undefined)."""
    from scipy.stats import t as student_t

    v = np.asarray(v, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return math.nan, math.nan
    if v.size == 1:
        return float(v[0]), math.nan
    half = student_t.ppf(0.5 + level / 2, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size)
    return float(v.mean()), float(half)


def pooled_mean_ci(values: np.ndarray, trials: np.ndarray, level: float = 0.95) -> float:
    """Half-width of the Student-t confidence interval, over trials, of the mean of ``values`` pooled over every
    trial (each value tagged with its trial): the ratio estimator sum / count with trials as the sampled units,
    variance T/(T-1) * sum_t (S_t - mean * n_t)^2 / (sum_t n_t)^2 over the T trials with a value. NaN for T < 2."""
    from scipy.stats import t as student_t

    values, trials = np.asarray(values, dtype=float), np.asarray(trials)
    keep = np.isfinite(values)
    values, trials = values[keep], trials[keep]
    ids, which = np.unique(trials, return_inverse=True)
    if ids.size < 2:
        return math.nan
    sums, counts = np.bincount(which, weights=values), np.bincount(which).astype(float)
    mean = sums.sum() / counts.sum()
    var = ids.size / (ids.size - 1) * float(np.sum((sums - mean * counts) ** 2)) / counts.sum() ** 2
    return float(student_t.ppf(0.5 + level / 2, ids.size - 1) * math.sqrt(var))


def offsets(n: int, width: float = 0.8) -> np.ndarray:
    """x offsets of ``n`` grouped bars / strips inside one slot of ``width``."""
    return (np.arange(n) - (n - 1) / 2) * (width / max(n, 1))


def grouped_bars(
    ax, slots: list[str], modes: list[str], values, models_for_color: list[str] | None = None, hatch=None
) -> None:
    """Grouped bars: one slot per model, one hatched/plain bar per mode, mean ± σ (lower bar clipped at 0) and
    every per-trial value as a small dot. ``values(slot, mode)`` gives the per-trial values; ``hatch(mode)`` the
    bar hatch of a group (default: the probability mode's)."""
    hatch = hatch or (lambda mode: ps.mode_style(mode).hatch)
    rng = np.random.default_rng(0)  # jitter only; fixed so the figure is reproducible
    width = 0.8 / max(len(modes), 1)
    for j, mode in enumerate(modes):
        off = offsets(len(modes))[j]
        for i, slot in enumerate(slots):
            v = np.asarray(values(slot, mode), dtype=float)
            v = v[np.isfinite(v)]
            mu, sd = (float(v.mean()), float(v.std())) if v.size else (math.nan, math.nan)
            st = ps.model_style(slot)
            ax.bar(
                i + off,
                mu,
                width * 0.92,
                yerr=[[min(sd, mu) if v.size else 0.0], [sd if v.size else 0.0]],
                color=st.color,
                alpha=0.55,
                hatch=hatch(mode),
                edgecolor="k",
                linewidth=0.5,
                error_kw={"elinewidth": 0.8, "capsize": 2},
                zorder=2,
            )
            if v.size:
                x = i + off + rng.uniform(-0.25, 0.25, v.size) * width
                ax.plot(x, v, ".", color=st.color, mec="k", mew=0.2, ms=2.5, alpha=0.8, zorder=3)
    ax.set_xticks(np.arange(len(slots)), [ps.tick_label(s) for s in slots])
    ax.grid(axis="x", visible=False)
