"""The cross-scene figure of ``soabench results`` (docs/method.md §3.1.4): S-OA's advantage over each baseline against
the occlusion density of each scene, in the package style."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure

from soabench.birth import BASELINES
from soabench.experiment.reports import paper
from soabench.figures import style as ps

#: (column, CI low, CI high, axis label, panel title) per column of the figure
PANELS = (
    ("delay_win_pct", "delay_win_ci_low", "delay_win_ci_high", "trials with lower delay (%)", "delay wins"),
    ("card_reduction", "card_ci_low", "card_ci_high", "reduction of card. error (%)", "cardinality error"),
    ("ospa_reduction", "ospa_ci_low", "ospa_ci_high", "reduction of OSPA (%)", "OSPA"),
)


def cross_scene_figure(rows: Sequence[Mapping], scenes: Sequence[str]) -> Figure:
    """S-OA's advantage vs occlusion density: one column per measure, one row per probability mode; per baseline
    one marker per scene with its 95% CI (small horizontal offsets keep the bars apart), ``scenes`` named on top in
    their order."""
    modes = list(dict.fromkeys(r["mode"] for r in rows))
    bases = [b for b in BASELINES if any(r["baseline"] == b for r in rows)]
    dens = {r["scene"]: 100.0 * float(r["occluded_sidewalk"]) for r in rows}
    xs = np.array([dens[s] for s in scenes])
    span = float(xs.max() - xs.min()) if len(xs) > 1 else 10.0
    step = 0.025 * span
    with ps.style():
        fig = ps.figure("double", 1.2 + 2.0 * len(modes))
        axes = np.atleast_2d(fig.subplots(len(modes), len(PANELS), sharex=True))
        letters = iter(ps.letters(axes.size))
        for i, mode in enumerate(modes):
            for j, (col, lo, hi, ylabel, title) in enumerate(PANELS):
                ax = axes[i, j]
                ax.axhline(50.0 if j == 0 else 0.0, color="0.3", lw=0.7, ls=":", zorder=0)
                for b_i, base in enumerate(bases):
                    sub = sorted(
                        (r for r in rows if r["mode"] == mode and r["baseline"] == base),
                        key=lambda r: dens[r["scene"]],
                    )
                    if not sub:
                        continue
                    st = ps.model_style(base)
                    x = np.array([dens[r["scene"]] for r in sub]) + (b_i - (len(bases) - 1) / 2) * step
                    y = np.array([float(r[col]) for r in sub])
                    err = np.array([[y_ - float(r[lo]), float(r[hi]) - y_] for y_, r in zip(y, sub, strict=True)]).T
                    ax.errorbar(
                        x, y, yerr=np.nan_to_num(np.clip(err, 0, None)), fmt=st.marker, color=st.color,
                        mfc=st.color if mode == "static" else "white", ms=3.5, lw=0.8, elinewidth=0.8,
                        ls=ps.mode_style(mode).linestyle, alpha=0.95,
                    )  # fmt: skip
                ax.set_ylabel(ylabel)
                if j == 0:
                    ax.set_ylim(-3, 103)
                if i == 0:
                    top = ax.secondary_xaxis("top")
                    top.set_xticks(xs, labels=scenes, rotation=30, ha="left", fontsize=6.5)
                    top.tick_params(length=2, pad=1)
                ps.panel_title(ax, next(letters), f"{title}, {paper.MODE_LABEL.get(mode, mode)}")
        xlabel = "occlusion density: occluded share of the sidewalk in the field of view (%)"
        axes[-1, len(PANELS) // 2].set_xlabel(xlabel)
        ps.legend_below(fig, ps.model_handles(bases) + ps.mode_handles(modes), ncol=len(bases) + len(modes))
    return fig
