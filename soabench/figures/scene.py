"""Bird's-eye view of a scene like the paper's Fig. 3 (Section IV-A), in the package style
(:mod:`soabench.figures.style`).

Roads grey, sidewalks / walking areas white and crossings hatched on a light blue-grey background, buildings yellow
with their doors as brown squares, parked cars and other static occluders black, other vehicles blue, the ego red;
pedestrian tracks black dotted with an open circle where each presence episode starts and an open triangle where it
ends (or at ``time``). A legend under the map explains every symbol drawn; the sensor and birth overlays add their
own entries to it (:func:`soabench.figures.style.extend_legend`).
"""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.patches import Polygon as MplPolygon

from soabench.figures import style as ps
from soabench.scenario.scene import SceneMap
from soabench.types import Recording

BACKGROUND = "#dde3ea"
ROAD = "#8c8c8c"
SIDEWALK = "#ffffff"
SIDEWALK_EDGE = "#b0b0b0"
BUILDING = "#f5c518"
BUILDING_EDGE = "#b8860b"
PARKED = "#000000"
DOOR = "#8b4513"
EGO = "#e41a1c"
VEHICLE = "#377eb8"


def scene_figure(scene: SceneMap, width: float | str = "double", legend_rows: int = 3) -> tuple[Figure, Axes]:
    """A figure sized to the scene's world box at paper width (room below the map for the legend)."""
    x0, y0, x1, y1 = scene.bounds
    w = {"single": ps.SINGLE, "double": ps.DOUBLE}.get(width, width) if isinstance(width, str) else float(width)
    h = float(w) * (y1 - y0) / max(x1 - x0, 1e-9)
    with ps.style():
        fig = ps.figure(w, min(h, 1.3 * float(w)) + 0.45 + 0.16 * legend_rows)
        ax = fig.add_subplot()
    return fig, ax


def _time_index(recording: Recording, time: float | None) -> int:
    if time is None:
        return len(recording.t) - 1
    return int(np.clip(np.searchsorted(recording.t, time + 1e-9, side="right") - 1, 0, len(recording.t) - 1))


def plot_scene(
    scene: SceneMap, recording: Recording | None = None, time: float | None = None, ax: Axes | None = None
) -> Axes:
    """Draw the map; with a recording, the vehicles and ego at ``time`` (default: the last sample) and the
    pedestrian tracks up to ``time``. Returns the Axes (metres, limited to the world box) with its legend."""
    if ax is None:
        _, ax = scene_figure(scene)
    with ps.style():
        ax.set_facecolor(BACKGROUND)
        handles: list = []
        if ps.fill_geometry(ax, scene.roads, facecolor=ROAD, edgecolor="none", zorder=1):
            handles.append(Patch(facecolor=ROAD, label="road"))
        ped = scene.sidewalk.union(scene.walking_areas)
        if ps.fill_geometry(ax, ped, facecolor=SIDEWALK, edgecolor=SIDEWALK_EDGE, linewidth=0.5, zorder=2):
            handles.append(Patch(facecolor=SIDEWALK, edgecolor=SIDEWALK_EDGE, label="sidewalk / walking area"))
        crossing = {"facecolor": SIDEWALK, "edgecolor": SIDEWALK_EDGE, "linewidth": 0.5, "hatch": "||||"}
        if ps.fill_geometry(ax, scene.crossings, zorder=2, **crossing):
            handles.append(Patch(label="crossing", **crossing))
        for b in scene.buildings:
            ps.fill_geometry(ax, b, facecolor=BUILDING, edgecolor=BUILDING_EDGE, linewidth=0.8, zorder=3)
        if scene.buildings:
            handles.append(Patch(facecolor=BUILDING, edgecolor=BUILDING_EDGE, label="building"))
        for o in scene.static_occluders:
            ps.fill_geometry(ax, o, facecolor=PARKED, edgecolor="none", zorder=4)
        if scene.static_occluders:
            handles.append(Patch(facecolor=PARKED, label="parked car / static occluder"))
        if len(scene.doors):
            ax.plot(scene.doors[:, 0], scene.doors[:, 1], "s", color=DOOR, ms=3.5, zorder=5)
            handles.append(Line2D([], [], color=DOOR, marker="s", ls="", ms=3.5, label="building door"))
        if recording is not None:
            handles += _draw_recording(ax, recording, _time_index(recording, time))
        x0, y0, x1, y1 = scene.bounds
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal")
        ax.grid(False)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ps.extend_legend(ax, handles)
    return ax


def _draw_recording(ax: Axes, rec: Recording, k: int) -> list:
    """Vehicles, ego and pedestrian tracks up to sample ``k``; returns the legend handles of what was drawn."""
    handles: list = []
    n_veh = 0
    for j in range(len(rec.veh_ids)):
        if rec.veh_present[k, j]:
            n_veh += 1
            ax.add_patch(MplPolygon(rec.veh_footprint[k, j], closed=True, facecolor=VEHICLE, edgecolor="k",
                                    linewidth=0.5, zorder=6))  # fmt: skip
    if not np.isnan(rec.ego_footprint[k]).any():
        ax.add_patch(MplPolygon(rec.ego_footprint[k], closed=True, facecolor=EGO, edgecolor="k", linewidth=0.5,
                                zorder=7))  # fmt: skip
        handles.append(Patch(facecolor=EGO, edgecolor="k", linewidth=0.5, label="ego vehicle (sensor)"))
    if n_veh:
        handles.append(Patch(facecolor=VEHICLE, edgecolor="k", linewidth=0.5, label="other vehicle"))
    n_tracks = 0
    for j in range(len(rec.ped_ids)):
        present = rec.ped_present[: k + 1, j]
        if not present.any():
            continue
        # one dotted line per presence episode (a building exit starts a new one)
        edges = np.diff(np.concatenate([[0], present.astype(np.int8), [0]]))
        for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
            xy = rec.ped_xy[a:b, j]
            n_tracks += 1
            ax.plot(xy[:, 0], xy[:, 1], ":", color="k", linewidth=1.0, zorder=8)
            ax.plot(*xy[0], "o", mfc="none", mec="k", ms=4.5, zorder=9)
            ax.plot(*xy[-1], "^", mfc="none", mec="k", ms=4.5, zorder=9)
    if n_tracks:
        handles += [
            Line2D([], [], color="k", ls=":", lw=1.0, label="pedestrian track"),
            Line2D([], [], color="k", marker="o", mfc="none", ls="", ms=4.5, label="track start (appears)"),
            Line2D([], [], color="k", marker="^", mfc="none", ls="", ms=4.5, label="track end (leaves / now)"),
        ]
    who = (
        f"seed {rec.meta['base_seed']} trial {rec.meta['trial']}"
        if "base_seed" in rec.meta
        else f"SUMO seed {rec.seed}"
    )
    ps.panel_title(ax, None, f"{rec.net}, {who}, t = {rec.t[k]:.1f} s")
    return handles
