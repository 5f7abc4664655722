"""Fig. 7b: the posterior components of every model by origin over time (docs/method.md §5.7).

``steps.csv`` splits each scan's posterior component count J_k (after pruning and merging) by where the components
come from (:mod:`soabench.origins`): born at this scan, per birth source (occlusion, semantic, FOV boundary, uniform
grid, fixed GM, measurement-driven newborn), or surviving from an earlier scan. The figure stacks the mean over
trials of these counts against time, one panel per model (rows) and probability mode (columns), on one y-axis, so
the models' component counts and what they are made of compare at a glance.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from soabench.experiment.reports.tables import RunTables, select
from soabench.figures import style as ps
from soabench.origins import ORIGIN_KEYS
from soabench.types import SOURCE_NAMES

#: colour of each birth source (occl, sem, fov, grid, gm, meas): the paper's Fig. 2 for S-OA's three (occlusion
#: black, semantic green, FOV red, as :mod:`soabench.figures.births`), the baselines' sources in their own colours
SOURCE_COLORS = ("0.15", "tab:green", "tab:red", "tab:blue", "tab:purple", "tab:orange")
#: legend label of each birth source, in words
SOURCE_WORDS = ("occlusion", "semantic", "FOV boundary", "uniform grid", "fixed GM", "measurement-driven")
SURVIVING_COLOR = "0.78"
SURVIVING_LABEL = "surviving (born at an earlier scan)"
UNSOURCED_COLOR = "wheat"
UNSOURCED_LABEL = "no known birth source"

_BORN = [f"n_born_{s}" for s in SOURCE_NAMES]
_SURV = [f"n_surv_{s}" for s in SOURCE_NAMES]


def has_origins(tables: RunTables) -> bool:
    """True when the run's ``steps.csv`` carries the origin columns (runs written before them do not)."""
    return all(c in tables.steps for c in ORIGIN_KEYS)


def origins_over_time(tables: RunTables, clutter: float, model: str, mode: str) -> tuple[np.ndarray, dict]:
    """(k, {column: mean over trials per scan}) of every :data:`~soabench.origins.ORIGIN_KEYS` column; a scan that
    only some trials reached is averaged over those."""
    s = tables.steps
    m = select(s, clutter=clutter, model=model, mode=mode)
    if not m.any():
        return np.array([]), {c: np.array([]) for c in ORIGIN_KEYS}
    trials, k = s["trial"][m], s["k"][m]
    ks, tr = np.unique(k), np.unique(trials)
    rows, cols = np.searchsorted(tr, trials), np.searchsorted(ks, k)
    out = {}
    for c in ORIGIN_KEYS:
        grid = np.full((tr.size, ks.size), np.nan)
        grid[rows, cols] = s[c][m]
        with warnings.catch_warnings():  # a scan no trial reached is NaN, not a warning
            warnings.simplefilter("ignore", RuntimeWarning)
            out[c] = np.nanmean(grid, 0)
    return ks, out


def _layers(series: dict) -> list[tuple[str, str, np.ndarray]]:
    """(label, colour, values) of the stacked layers, bottom up: surviving, then born per source, then unsourced."""
    layers = [(SURVIVING_LABEL, SURVIVING_COLOR, sum(series[c] for c in _SURV))]
    layers += [(SOURCE_WORDS[i], SOURCE_COLORS[i], series[c]) for i, c in enumerate(_BORN)]
    layers.append((UNSOURCED_LABEL, UNSOURCED_COLOR, series["n_unsourced"]))
    return layers


def components_origin_figure(tables: RunTables, clutter: float) -> Figure:
    """Fig. 7b: stacked mean posterior components by origin vs time; rows = models, columns = modes, one y-axis."""
    models, modes = tables.models, tables.modes
    dt = float(tables.meta["config"]["sensor"]["dt"])
    n_trials = len(np.unique(tables.steps["trial"])) if len(tables.steps.get("trial", [])) else 0
    data = {(mo, p): origins_over_time(tables, clutter, mo, p) for mo in models for p in modes}
    present: dict[str, str] = {}  # label -> colour of every layer that is non-zero somewhere, in stacking order
    for _, series in data.values():
        for label, colour, v in _layers(series):
            if np.any(np.nan_to_num(v) > 0):
                present.setdefault(label, colour)
    order = [lab for lab, _, _ in _layers({c: np.zeros(1) for c in ORIGIN_KEYS})]
    with ps.style():
        fig = ps.figure("double", 0.95 * len(models) + 1.1)
        axes = fig.subplots(len(models), len(modes), squeeze=False, sharex=True, sharey=True)
        letters = ps.letters(len(models) * len(modes))
        for i, model in enumerate(models):
            for j, mode in enumerate(modes):
                ax = axes[i, j]
                k, series = data[(model, mode)]
                layers = [(lab, col, v) for lab, col, v in _layers(series) if lab in present]
                if k.size:
                    if layers:  # none when every count of the run is 0 (an empty posterior throughout)
                        ax.stackplot(
                            k * dt,
                            *[np.nan_to_num(v) for _, _, v in layers],
                            colors=[col for _, col, _ in layers],
                            edgecolor="0.3",
                            linewidth=0.2,
                        )
                    total = sum(np.nan_to_num(series[c]) for c in ORIGIN_KEYS)
                    born = sum(np.nan_to_num(series[c]) for c in _BORN)
                    unknown = np.mean(total) > 0 and np.mean(total) == np.mean(np.nan_to_num(series["n_unsourced"]))
                    note = " (origins unknown)" if unknown else f", born this scan {np.mean(born):.1f}"
                    ax.text(
                        0.99,
                        0.95,
                        f"mean J = {np.mean(total):.1f}{note}",
                        transform=ax.transAxes,
                        ha="right",
                        va="top",
                        fontsize=6.5,
                        bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 1.0},
                    )
                ps.panel_title(ax, letters[i * len(modes) + j], f"{ps.model_label(model)}, {mode}")
                ax.grid(axis="x", visible=False)
                if i == len(models) - 1:
                    ax.set_xlabel("time (s)")
            axes[i, 0].set_ylabel("components J")
        tops = [np.max(sum(np.nan_to_num(series[c]) for c in ORIGIN_KEYS)) for k, series in data.values() if k.size]
        axes[0, 0].set_ylim(0, 1.3 * max([*tops, 1.0]))  # headroom for the mean-J note
        axes[0, 0].set_xlim(0, None)

        handles = [Patch(facecolor=present[lab], edgecolor="0.3", linewidth=0.4) for lab in order if lab in present]
        labels = [f"born this scan: {lab}" if lab in SOURCE_WORDS else lab for lab in order if lab in present]
        ps.legend_below(fig, handles, labels, ncol=3)
        fig.suptitle(
            f"posterior components J after pruning and merging by origin, mean over {n_trials} trials, λ = {clutter:g}",
            x=0.0,
            ha="left",
        )
    return fig


def fig_components_origin(tables: RunTables, clutter: float, path: Path) -> Path | None:
    """Write Fig. 7b (:func:`components_origin_figure`); None (nothing written) for a run without origin columns."""
    if not has_origins(tables):
        return None
    return ps.save_png(components_origin_figure(tables, clutter), path)
