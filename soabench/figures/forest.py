"""The forest plot of S-OA's paired differences (docs/method.md §5.8): one panel per metric, one row per model X,
the mean over trials of M(S-OA) - M(X) with its 95 % interval (one marker per probability mode), a line at 0 and
the side where S-OA is better shaded.

A run's ``figures/paired.png`` and the README's key figure (``soabench study``'s ``key_figure.png``) are this plot,
drawn from :class:`~soabench.experiment.reports.headline.Headline` data handed to it. An interval much wider than
the others (GMBM's delay) would squash every other row to a dot, so the axis is fitted to the rest and that row
ends in an arrow at the edge with its numbers written beside it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from soabench.experiment.reports.headline import Headline, Metric, headline
from soabench.experiment.reports.tables import RunTables
from soabench.figures import style as ps
from soabench.figures.families import FAMILY_LABEL, run_families

#: a row is drawn off scale when its widest bound exceeds this many times the median of the rows' widest bounds
_OFF_SCALE = 4.0


def _limit(bounds: Sequence[float]) -> float:
    """The half-width of a panel's symmetric x-axis: every bound fits unless it is an outlier (:data:`_OFF_SCALE`)."""
    b = np.array([x for x in bounds if math.isfinite(x)], dtype=float)
    if b.size == 0:
        return 1.0
    inside = b[b <= _OFF_SCALE * max(float(np.median(b)), 1e-12)]
    return 1.15 * float(inside.max() if inside.size else b.max()) or 1.0


def _sig2(x: float) -> str:
    """``x`` signed, to two significant digits with trailing zeros kept (+0.40, -29, +0.061)."""
    if not math.isfinite(x) or x == 0:
        return f"{x:+g}"
    return f"{x:+.{max(0, 1 - math.floor(math.log10(abs(x))))}f}"


def _panel(ax, head: Headline, metric: Metric, others: Sequence[str], show_labels: bool) -> None:
    modes = head.modes
    step = 0.7 / max(len(modes), 1)
    rows = [(i, j, head.pair(metric.key, mode, o)) for i, o in enumerate(others) for j, mode in enumerate(modes)]
    rows = [(i, j, p) for i, j, p in rows if p is not None and p.n > 0]
    lim = _limit([max(abs(p.low), abs(p.high)) if math.isfinite(p.low) else abs(p.diff) for _, _, p in rows])
    better = -1.0 if metric.lower_is_better else 1.0  # the side of 0 where S-OA is better
    ax.axvspan(0, better * lim, color="tab:green", alpha=0.07, lw=0)
    ax.axvline(0, color="0.3", lw=0.8)
    for i, j, p in rows:
        y = i + (j - (len(modes) - 1) / 2) * step
        color, mstyle = ps.model_style(p.other).color, ps.mode_style(modes[j])
        lo, hi = (p.low, p.high) if math.isfinite(p.low) else (p.diff, p.diff)
        face = color if j == 0 else "white"
        ax.plot([max(lo, -lim), min(hi, lim)], [y, y], color=color, lw=1.4, solid_capstyle="butt")
        if abs(p.diff) <= lim:
            ax.plot([p.diff], [y], marker=mstyle.marker, color=color, mfc=face, ms=4.5, mew=1.0, ls="none")
        for edge, toward in ((lim, hi > lim), (-lim, lo < -lim)):
            if toward:  # off scale: an arrow at the edge and the numbers beside it
                sign = 1 if edge > 0 else -1
                ax.annotate("", xy=(edge, y), xytext=(edge - sign * 0.12 * lim, y),
                            arrowprops={"arrowstyle": "-|>", "color": color, "lw": 1.2})  # fmt: skip
                ax.text(edge - sign * 0.15 * lim, y, f"{_sig2(p.diff)} [{_sig2(p.low)}, {_sig2(p.high)}]",
                        ha="right" if sign > 0 else "left", va="center", fontsize=6, color=color)  # fmt: skip
    ax.set_xlim(-lim, lim)
    ax.set_ylim(len(others) - 0.5, -0.5)
    ax.set_yticks(range(len(others)), [ps.model_label(o) for o in others] if show_labels else [])
    ax.grid(axis="y", visible=False)
    unit = f" ({metric.unit})" if metric.unit else ""
    ax.set_xlabel(f"S-OA − X{unit}\n" + ("S-OA better →" if better > 0 else "← S-OA better"))


def forest_figure(head: Headline, metrics: Sequence[str] | None = None) -> Figure:
    """The forest plot of ``head`` over ``metrics`` (keys of :data:`~soabench.experiment.reports.headline.METRICS`;
    default: every metric the headline has), one panel each, the models S-OA is paired with as rows."""
    chosen = [m for m in head.metrics if metrics is None or m.key in metrics]
    others = list(dict.fromkeys(p.other for p in head.paired))
    ncols = min(len(chosen), 4) or 1
    nrows = -(-len(chosen) // ncols) or 1
    with ps.style():
        fig = ps.figure("double", 0.5 + nrows * (0.55 + 0.34 * max(len(others), 1)))
        axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
        for k, (ax, metric, letter) in enumerate(zip(axes, chosen, ps.letters(len(chosen)), strict=False)):
            _panel(ax, head, metric, others, show_labels=k % ncols == 0)
            ps.panel_title(ax, letter, metric.label)
        for ax in axes[len(chosen) :]:
            ax.set_visible(False)
        if not chosen or not others:
            axes[0].text(0.5, 0.5, "no model paired with S-OA", ha="center", va="center", transform=axes[0].transAxes)

        handles = [Line2D([], [], color="0.2", marker=ps.mode_style(m).marker, mfc="0.2" if j == 0 else "white",
                          ls="-", label=m) for j, m in enumerate(head.modes)]  # fmt: skip
        family = f", {head.family}" if head.family else ""
        title = f"mean paired difference over trials ± 95 % interval, λ = {head.clutter:g}{family}"
        ps.legend_below(fig, handles, ncol=len(handles) or 1, title=title)
    return fig


def paired_figure(tables: RunTables, clutter: float) -> Figure:
    """A run's ``figures/paired.png``: the forest plot of every metric of its headline at ``clutter``; the title
    names the filter family when the tables hold one family's rows (a run of several draws it on its first's)."""
    fams = run_families(tables)
    family = FAMILY_LABEL.get(fams[0], fams[0]) if len(fams) == 1 else None
    return forest_figure(headline(tables, clutter, family))
