"""The key (legend) of a scene figure drawn by :func:`soabench.scenario.plots.plot_scene` (``soabench scene``)."""

from __future__ import annotations

from matplotlib.axes import Axes
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.transforms import ScaledTranslation

from soabench.scenario import plots


def add_scene_key(ax: Axes) -> None:
    """A one-row legend under the axes naming every layer of the scene figure."""
    handles = [
        Patch(facecolor=plots.ROAD, label="road"),
        Patch(facecolor=plots.SIDEWALK, edgecolor="#b0b0b0", label="sidewalk"),
        Patch(facecolor=plots.SIDEWALK, edgecolor="#b0b0b0", hatch="||", label="crossing"),
        Patch(facecolor=plots.BUILDING, edgecolor="#b8860b", label="building"),
        Patch(facecolor=plots.PARKED, label="static occluder"),
        Line2D([], [], ls="none", marker="s", color="#8b4513", markersize=5, label="door"),
        Patch(facecolor=plots.EGO, edgecolor="k", label="ego"),
        Patch(facecolor=plots.VEHICLE_COLOURS[0], edgecolor="k", label="other vehicle"),
        Line2D(
            [], [], ls=":", color="k", marker="^", markerfacecolor="none", label="pedestrian now (track since entry)"
        ),
        Line2D([], [], ls="none", marker="o", markerfacecolor="none", color="k", label="entry point"),
    ]
    # anchored 0.5 inch below the axes (under the tick labels and x label, whatever the axes' aspect)
    below = ax.transAxes + ScaledTranslation(0.0, -0.5, ax.figure.dpi_scale_trans)
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0.0), bbox_transform=below, ncol=5, fontsize=8)
