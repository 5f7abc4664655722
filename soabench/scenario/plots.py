"""Bird's-eye view of a scene like the paper's Fig. 3 (Section IV-A).

Roads grey, sidewalks / crossings / walking areas white on a light blue-grey background, buildings yellow, parked
cars black, other vehicles coloured, the ego red; pedestrian trajectories black dotted with a circle where each
presence episode starts and a triangle where it ends (or at ``time``). Other modules draw sensor and birth overlays
on the returned Axes.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.patches import Polygon as MplPolygon  # noqa: E402
from shapely.geometry.base import BaseGeometry  # noqa: E402

from soabench.scenario.recording import Recording  # noqa: E402
from soabench.scenario.scene import SceneMap  # noqa: E402

BACKGROUND = "#dde3ea"
ROAD = "#8c8c8c"
SIDEWALK = "#ffffff"
BUILDING = "#f5c518"
PARKED = "#000000"
EGO = "#e41a1c"
VEHICLE_COLOURS = ("#377eb8", "#4daf4a", "#984ea3", "#ff7f00", "#a65628", "#f781bf", "#17becf")


def _fill(ax: Axes, geom: BaseGeometry, **kw) -> None:
    """Fill every polygon part of ``geom`` (holes drawn in the background colour)."""
    if geom is None or geom.is_empty:
        return
    for g in getattr(geom, "geoms", [geom]):
        if g.geom_type == "Polygon":
            ax.add_patch(MplPolygon(np.asarray(g.exterior.coords), closed=True, **kw))
            for hole in g.interiors:
                ax.add_patch(MplPolygon(np.asarray(hole.coords), closed=True, facecolor=BACKGROUND, edgecolor="none",
                                        zorder=kw.get("zorder", 1)))  # fmt: skip
        elif hasattr(g, "geoms"):
            _fill(ax, g, **kw)


def _time_index(recording: Recording, time: float | None) -> int:
    if time is None:
        return len(recording.t) - 1
    return int(np.clip(np.searchsorted(recording.t, time + 1e-9, side="right") - 1, 0, len(recording.t) - 1))


def plot_scene(
    scene: SceneMap, recording: Recording | None = None, time: float | None = None, ax: Axes | None = None
) -> Axes:
    """Draw the map; with a recording, the vehicles and ego at ``time`` (default: the last sample) and the
    pedestrian trajectories up to ``time``. Returns the Axes (metres, limited to the world box)."""
    if ax is None:
        _, ax = plt.subplots(figsize=(10, 10 * scene.world_box.bounds[3] / max(scene.world_box.bounds[2], 1e-9)))
        x0, y0, x1, y1 = scene.bounds
        ax.figure.set_size_inches(10.0, max(3.0, 10.0 * (y1 - y0) / (x1 - x0)) + 0.6)
    ax.set_facecolor(BACKGROUND)
    _fill(ax, scene.roads, facecolor=ROAD, edgecolor="none", zorder=1)
    ped = scene.sidewalk.union(scene.walking_areas)
    _fill(ax, ped, facecolor=SIDEWALK, edgecolor="#b0b0b0", linewidth=0.5, zorder=2)
    _fill(ax, scene.crossings, facecolor=SIDEWALK, edgecolor="#b0b0b0", linewidth=0.5, hatch="||", zorder=2)
    for b in scene.buildings:
        _fill(ax, b, facecolor=BUILDING, edgecolor="#b8860b", linewidth=0.8, zorder=3)
    for o in scene.static_occluders:
        _fill(ax, o, facecolor=PARKED, edgecolor="none", zorder=4)
    if len(scene.doors):
        ax.plot(scene.doors[:, 0], scene.doors[:, 1], "s", color="#8b4513", markersize=4, zorder=5, label="doors")
    if recording is not None:
        _draw_recording(ax, recording, _time_index(recording, time))
    x0, y0, x1, y1 = scene.bounds
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    return ax


def _draw_recording(ax: Axes, rec: Recording, k: int) -> None:
    for j in range(len(rec.veh_ids)):
        if rec.veh_present[k, j]:
            colour = VEHICLE_COLOURS[j % len(VEHICLE_COLOURS)]
            ax.add_patch(MplPolygon(rec.veh_footprint[k, j], closed=True, facecolor=colour, edgecolor="k",
                                    linewidth=0.5, zorder=6))  # fmt: skip
    if not np.isnan(rec.ego_footprint[k]).any():
        ax.add_patch(MplPolygon(rec.ego_footprint[k], closed=True, facecolor=EGO, edgecolor="k", linewidth=0.5,
                                zorder=7))  # fmt: skip
    for j in range(len(rec.ped_ids)):
        present = rec.ped_present[: k + 1, j]
        if not present.any():
            continue
        # one dotted line per presence episode (a building exit starts a new one)
        edges = np.diff(np.concatenate([[0], present.astype(np.int8), [0]]))
        for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
            xy = rec.ped_xy[a:b, j]
            ax.plot(xy[:, 0], xy[:, 1], ":", color="k", linewidth=1.2, zorder=8)
            ax.plot(*xy[0], "o", markerfacecolor="none", markeredgecolor="k", markersize=6, zorder=9)
            ax.plot(*xy[-1], "^", markerfacecolor="none", markeredgecolor="k", markersize=6, zorder=9)
    who = (
        f"seed {rec.meta['base_seed']} trial {rec.meta['trial']}"
        if "base_seed" in rec.meta
        else f"SUMO seed {rec.seed}"
    )
    ax.set_title(f"{rec.net}  {who}  t = {rec.t[k]:.1f} s")
