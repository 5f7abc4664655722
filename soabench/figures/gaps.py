"""Identity kept against the length of the occlusion gap (docs/method.md §9.4): the figure a reader looks at first.

One panel per occluder kind that hid some pedestrian (all kinds together first, then parked car, moving vehicle,
building, other obstacle), titled once over its column; one row per probability mode (and filter family, when the
run has several), named once left of the row, so the figure reads at any number of rows. In a panel,
x is the gap length bin (``metrics.gap_bins``), y the share of re-emergences re-acquired under the label held before
the gap, pooled over the run's trials; one curve per model (colour, marker) with its 95 % bootstrap band over trials
(:func:`soabench.experiment.reports.occlusion.identity_curves`). The number of counted re-emergences is printed
under each bin (the most any model counted) and a point resting on fewer than :data:`FEW` is hollow, so a reader
sees where a point rests on few gaps.

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

#: points resting on fewer re-emergences than this are drawn hollow
FEW = 5
#: a kind's column title
TITLE = {"all": "every occluder", **OCCLUDER_LABEL}
#: the height of one row of panels (inches): the figure grows with the families and modes
ROW_HEIGHT = 1.45


def _bins(tables: RunTables) -> tuple[int, ...]:
    return tuple(tables.meta["config"].get("metrics", {}).get("gap_bins", MetricsConfig().gap_bins))


def identity_gaps_figure(tables: RunTables, clutter: float, families: Sequence[tuple[str, RunTables]] = ()) -> Figure:
    """The figure of one clutter rate; ``families``: (name, that family's tables) per filter family when the run
    names several (empty: the run's own tables). One row of panels per family and probability mode."""
    bins = _bins(tables)
    data = [(name, identity_curves(t, clutter, bins)) for name, t in (list(families) or [("", tables)])]
    kinds = [k for k in TITLE if any(k in curves for _, curves in data)]
    present = {key for _, c in data for cv in c.values() for key in cv}
    models = [m for m in tables.models if any(m == mo for mo, _ in present)]
    rows = [(name, curves, md) for name, curves in data for md in tables.modes
            if any((mo, md) in cv for cv in curves.values() for mo in models)]  # fmt: skip
    x = np.arange(len(bins), dtype=float)
    ncol = max(1, len(kinds))
    offsets = (np.arange(len(models)) - (len(models) - 1) / 2) * min(0.07, 0.45 / max(1, len(models)))
    with ps.style():
        fig = ps.figure("double", 1.0 + ROW_HEIGHT * max(1, len(rows)))
        axes = fig.subplots(max(1, len(rows)), ncol, sharey=True, squeeze=False)
        for r, (family, curves, mode) in enumerate(rows):
            for c, kind in enumerate(kinds):
                ax = axes[r, c]
                if r == 0:  # the occluder kind once, over its column
                    ax.set_title(TITLE[kind], loc="center", fontsize=ps.RC["axes.titlesize"], fontweight="bold")
                if c == 0:  # the family and mode once, left of their row
                    ax.set_ylabel(f"{', '.join(w for w in (family, mode) if w)}\nidentity kept")
                ax.set_xlim(-0.5, len(bins) - 0.5)
                ax.set_ylim(0, 1.02)
                if r == len(rows) - 1:
                    ax.set_xlabel("gap length (scans)")
                counts = np.zeros(len(bins))
                for i, model in enumerate(models):
                    arr = curves.get(kind, {}).get((model, mode))
                    if arr is None:
                        continue
                    st, xs = ps.model_style(model), x + offsets[i]
                    ok = np.isfinite(arr[:, 0])
                    counts = np.maximum(counts, np.nan_to_num(arr[:, 3]))
                    ax.plot(xs[ok], arr[ok, 0], color=st.color, lw=1.0)
                    few = ok & (arr[:, 3] < FEW)
                    ax.plot(xs[ok & ~few], arr[ok & ~few, 0], ls="", color=st.color, marker=st.marker, ms=3.2)
                    ax.plot(xs[few], arr[few, 0], ls="", color=st.color, marker=st.marker, ms=3.2, mfc="white")
                    band = ok & np.isfinite(arr[:, 1])
                    ax.fill_between(xs[band], arr[band, 1], arr[band, 2], color=st.color, alpha=0.08, lw=0)
                # the bins' labels carry the largest number of re-emergences any model had there
                ax.set_xticks(x, [f"{b}\nn≤{n:.0f}" for b, n in zip(bin_labels(bins), counts, strict=True)])
                if kind not in curves:
                    ax.text(0.5, 0.5, "no gap", ha="center", va="center", transform=ax.transAxes, color="0.4")
        if not rows:  # no labelled re-emergence after a gap in this run
            ax = axes[0, 0]
            ax.text(0.5, 0.5, f"no re-emergence after an occlusion gap counted at λ = {clutter:g}", ha="center",
                    va="center", transform=ax.transAxes)  # fmt: skip
            ax.set_axis_off()
            return fig
        ps.legend_below(fig, ps.model_handles(models), [ps.model_label(m) for m in models], ncol=len(models))
        fig.suptitle(
            f"Identity kept through an occlusion gap, λ = {clutter:g}: the share of re-emergences re-acquired under "
            "the label held before the gap\n(band: 95 % bootstrap interval over trials; hollow: fewer than "
            f"{FEW} re-emergences;\nn: the most re-emergences any model counted in the bin)",
            fontsize=ps.RC["axes.titlesize"],
        )
    return fig
