"""Phase diagrams of an atlas (docs/method.md §5.10): S-OA's paired advantage over each baseline.

* :func:`pair_heatmaps`: one heatmap per baseline over two axes (the others pooled); the colour is the advantage
  (blue: S-OA better, red: worse, white: none), each cell carries its value, a framed cell is significant after the
  false-discovery correction, and the black line is the no-advantage contour;
* :func:`axis_curves`: the advantage along each axis, one line per baseline, with 95 % intervals; filled markers
  are significant.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from matplotlib.colors import TwoSlopeNorm
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from soabench.figures.style import DOUBLE, figure, letters, model_style, panel_title
from soabench.types import ATLAS_METRICS, ATLAS_NULL, AtlasCell


def _sorted_values(values) -> list:
    return sorted(set(values), key=lambda v: (isinstance(v, str), v))


def _tick(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def pair_heatmaps(
    cells: Sequence[AtlasCell],
    x: str,
    y: str,
    names: dict[str, str],
    baselines: Sequence[str],
    label: Callable[[str], str],
    metric: str,
) -> Figure:
    """Heatmaps of ``metric`` over axes ``x`` and ``y``, one panel per baseline (module docstring)."""
    bases = [b for b in baselines if any(c.baseline == b for c in cells)]
    xs = _sorted_values(c.values[0] for c in cells)
    ys = _sorted_values(c.values[1] for c in cells)
    null = ATLAS_NULL[metric]
    finite = [abs(c.estimate - null) for c in cells if math.isfinite(c.estimate)]
    span = max(finite) if finite and max(finite) > 0 else 1.0
    norm = TwoSlopeNorm(vcenter=null, vmin=null - span, vmax=null + span)
    ncol = len(bases)
    cell_w = 0.32 * len(xs) + 0.6
    width = min(DOUBLE, max(3.5, cell_w * ncol + 0.9))
    fig = figure(width, 0.32 * len(ys) + 1.35)
    axs = fig.subplots(1, ncol, squeeze=False, sharey=True)[0]
    digits = ".2f" if metric in ("delay_win", "dhota") else ".0f"
    im = None
    for ax, b, letter in zip(axs, bases, letters(ncol), strict=True):
        grid = np.full((len(ys), len(xs)), np.nan)
        sig = np.zeros_like(grid, dtype=bool)
        for c in cells:
            if c.baseline == b:
                i, j = ys.index(c.values[1]), xs.index(c.values[0])
                grid[i, j], sig[i, j] = c.estimate, c.significant
        im = ax.imshow(grid, cmap="RdBu", norm=norm, origin="lower", aspect="auto")
        ax.grid(False)
        for i in range(len(ys)):
            for j in range(len(xs)):
                if not math.isfinite(grid[i, j]):
                    continue
                dark = abs(grid[i, j] - null) > 0.6 * span
                ax.text(j, i, f"{grid[i, j]:{digits}}", ha="center", va="center", fontsize=5.5,
                        color="white" if dark else "black", fontweight="bold" if sig[i, j] else "normal")  # fmt: skip
                if sig[i, j]:
                    ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, lw=1.1, ec="black"))
        if len(xs) >= 2 and len(ys) >= 2 and np.isfinite(grid).all():
            above, below = (grid > null).any(), (grid < null).any()
            if above and below:
                ax.contour(np.arange(len(xs)), np.arange(len(ys)), grid, levels=[null], colors="black",
                           linewidths=1.0, linestyles="--")  # fmt: skip
        ax.set_xticks(range(len(xs)), [_tick(v) for v in xs])
        ax.set_yticks(range(len(ys)), [_tick(v) for v in ys])
        ax.set_xlabel(names[x])
        panel_title(ax, letter, f"vs {label(b)}".replace(" (", "\n("))  # "UBM (workspace)" on two lines
    axs[0].set_ylabel(names[y])
    cb = fig.colorbar(im, ax=list(axs), fraction=0.035 / max(1, ncol / 3), pad=0.02)
    cb.set_label(ATLAS_METRICS[metric], fontsize=6.5)
    fig.suptitle(
        f"S-OA's {ATLAS_METRICS[metric]} over each baseline (blue: S-OA better)\n"
        "framed: significant after BH-FDR (q = 0.05); dashed: no advantage",
        x=0.01, ha="left", fontsize=7.5,
    )  # fmt: skip
    return fig


def axis_curves(
    cells: Sequence[AtlasCell],
    axes: Sequence[str],
    names: dict[str, str],
    baselines: Sequence[str],
    label: Callable[[str], str],
    metric: str,
) -> Figure:
    """``metric`` along each axis (the others pooled), one line per baseline with 95 % intervals."""
    shown = [a for a in axes if any(c.axes == (a,) for c in cells)]
    n = len(shown)
    ncol = min(n, 4)
    nrow = math.ceil(n / ncol)
    fig = figure("double", 1.9 * nrow + 0.6)
    axs = fig.subplots(nrow, ncol, squeeze=False)
    null = ATLAS_NULL[metric]
    handles = {}
    for k, (a, letter) in enumerate(zip(shown, letters(n), strict=True)):
        ax = axs[k // ncol][k % ncol]
        vals = _sorted_values(c.values[0] for c in cells if c.axes == (a,))
        numeric = all(isinstance(v, (int, float)) for v in vals)
        nb = len(baselines)
        for bi, b in enumerate(baselines):
            sel = sorted(
                (c for c in cells if c.axes == (a,) and c.baseline == b), key=lambda c: vals.index(c.values[0])
            )
            if not sel:
                continue
            st = model_style(b)
            pos = np.array([vals.index(c.values[0]) for c in sel], float) + (bi - (nb - 1) / 2) * 0.06
            est = np.array([c.estimate for c in sel])
            err = np.array([[c.estimate - c.low, c.high - c.estimate] for c in sel]).T
            ax.errorbar(pos, est, yerr=err, color=st.color, marker=None, lw=1.0, elinewidth=0.7)
            for p, e, c in zip(pos, est, sel, strict=True):
                ax.plot(p, e, marker=st.marker, ms=4, color=st.color, mfc=st.color if c.significant else "white")
            handles[b] = Line2D([], [], color=st.color, marker=st.marker, ms=4, lw=1.0)
        ax.axhline(null, color="black", lw=0.7, ls="--")
        ax.set_xticks(range(len(vals)), [_tick(v) for v in vals])
        ax.set_xlim(-0.5, len(vals) - 0.5)
        ax.set_xlabel(names[a] if numeric else "")
        panel_title(ax, letter, names[a])
        if k % ncol == 0:
            ax.set_ylabel(ATLAS_METRICS[metric])
    for k in range(n, nrow * ncol):
        axs[k // ncol][k % ncol].set_visible(False)
    fig.legend(
        list(handles.values()), [f"vs {label(b)}" for b in handles], loc="outside lower center",
        ncol=min(5, len(handles)), frameon=False,
    )  # fmt: skip
    fig.suptitle(
        f"S-OA's {ATLAS_METRICS[metric]} (mean, 95 % CI over trials; filled = significant after BH-FDR; dashed = none)",
        x=0.01, ha="left", fontsize=7.5,
    )  # fmt: skip
    return fig
