"""Identity kept against the length of the occlusion gap (docs/method.md §9.4): the figure a reader looks at first.

One panel per occluder kind that hid some pedestrian (all kinds together first, then parked car, moving vehicle,
building, other obstacle), per filter family when the run has several (one row each). In a panel, x is the gap
length bin (``metrics.gap_bins``), y the share of re-emergences re-acquired under the label held before the gap,
pooled over the run's trials; one curve per model (colour, marker) and probability mode (line style) with its 95 %
bootstrap band over trials (:func:`soabench.experiment.reports.occlusion.identity_curves`). The number of counted
re-emergences of each point is printed under the axis per model, so a reader sees where a point rests on few gaps.

A run's report draws it per clutter rate as ``identity_gaps.png`` (``identity_gaps_lam<λ>.png`` with several rates)
when some tracker of the run labels its estimates.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from soabench.config import MetricsConfig
from soabench.experiment.reports.occlusion import bin_labels, identity_curves
from soabench.experiment.reports.tables import RunTables
from soabench.figures import style as ps
from soabench.tracks.gaps import OCCLUDER_LABEL

#: a kind's panel title
TITLE = {"all": "every occluder", **OCCLUDER_LABEL}


def _bins(tables: RunTables) -> tuple[int, ...]:
    return tuple(tables.meta["config"].get("metrics", {}).get("gap_bins", MetricsConfig().gap_bins))


def identity_gaps_figure(tables: RunTables, clutter: float, families: Sequence[tuple[str, RunTables]] = ()) -> Figure:
    """The figure of one clutter rate; ``families``: (name, that family's tables) per row when the run names
    several filter families (empty: one row of ``tables``)."""
    rows = list(families) or [("", tables)]
    bins = _bins(tables)
    data = [(name, identity_curves(t, clutter, bins)) for name, t in rows]
    kinds = [k for k in TITLE if any(k in curves for _, curves in data)]
    models = [m for m in tables.models if any(m == mo for _, c in data for cv in c.values() for mo, _ in cv)]
    modes = [md for md in tables.modes if any(md == m for _, c in data for cv in c.values() for _, m in cv)]
    labels = bin_labels(bins)
    x = np.arange(len(bins), dtype=float)
    ncol = max(1, len(kinds))
    with ps.style():
        fig = ps.figure("double", 0.4 + 2.3 * len(rows))
        axes = np.atleast_2d(fig.subplots(len(rows), ncol, sharey=True, squeeze=False))
        letters = iter(ps.letters(len(rows) * ncol))
        n_lines = max(1, len(models) * len(modes))
        offsets = (np.arange(n_lines) - (n_lines - 1) / 2) * min(0.08, 0.5 / n_lines)
        for r, (family, curves) in enumerate(data):
            for c, kind in enumerate(kinds):
                ax = axes[r, c]
                title = TITLE[kind] + (f", {family}" if family else "")
                ps.panel_title(ax, next(letters), title)
                ax.set_xticks(x, labels)
                ax.set_xlim(-0.5, len(bins) - 0.5)
                ax.set_ylim(0, 1.05)
                ax.set_xlabel("gap length (scans)")
                if c == 0:
                    ax.set_ylabel("identity kept (share of re-emergences)")
                if kind not in curves:
                    ax.text(0.5, 0.5, "no gap", ha="center", va="center", transform=ax.transAxes, color="0.4")
                    continue
                i = 0
                for model in models:
                    st = ps.model_style(model)
                    for mode in modes:
                        arr = curves[kind].get((model, mode))
                        if arr is None:
                            continue
                        xs = x + offsets[i]
                        i += 1
                        ok = np.isfinite(arr[:, 0])
                        ls = ps.mode_style(mode).linestyle
                        ax.plot(xs[ok], arr[ok, 0], color=st.color, ls=ls, marker=st.marker, ms=3, lw=1.1)
                        band = ok & np.isfinite(arr[:, 1])
                        ax.fill_between(xs[band], arr[band, 1], arr[band, 2], color=st.color, alpha=0.10, lw=0)
                        ax.vlines(xs[band], arr[band, 1], arr[band, 2], color=st.color, lw=0.6, alpha=0.7)
                counts = np.nansum([a[:, 3] for a in curves[kind].values()], axis=0) / max(1, len(curves[kind]))
                for xi, n in zip(x, counts, strict=True):
                    ax.text(xi, 0.02, f"n≈{n:.0f}", ha="center", va="bottom", fontsize=5.5, color="0.35")
        handles = ps.model_handles(models) + ps.mode_handles(modes)
        ps.legend_below(fig, handles, [ps.model_label(m) for m in models] + list(modes), ncol=len(handles))
        fig.suptitle(
            f"Identity kept through an occlusion, by gap length and occluder (λ = {clutter:g}; band: 95 % bootstrap "
            "interval over trials; n: re-emergences per model)",
            fontsize=7,
        )
    return fig
