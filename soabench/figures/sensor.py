"""Sensor overlay for the scene figure (``soabench scene ... --sensor``): FOV, Omega_k, obstacle cones, sight lines
and measurements of one scan (docs/method.md §2.3, §3.1.2, §3.1.4).

Colours: visible region light green; obstacle shadows grey with tangent rays dark grey; sight lines green (visible)
or red dashed (blocked); measurements from targets blue dots, clutter orange crosses; ego black triangle.
"""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from soabench.config import SensorConfig
from soabench.figures import style as ps
from soabench.figures.scene import plot_scene, scene_figure
from soabench.geometry import polar_to_world
from soabench.sensor import fov_polygon, shadow_polygons
from soabench.types import CLUTTER, Estimates, Scan, Scans, StepResult

_VISIBLE_REGION = "#7fd37f"
_SHADOW = "0.55"
_RAY = "0.3"
_LOS_OK = "tab:green"
_LOS_BLOCKED = "tab:red"
_Z_TARGET = "tab:blue"
_Z_CLUTTER = "tab:orange"


def draw_sensor_overlay(ax: Axes, scans: Scans, k: int, cfg: SensorConfig) -> None:
    """Draw scan ``k`` of ``scans`` on ``ax`` (which may already show the scene) and add its entries to the legend
    under the map.

    Layers sit above :func:`soabench.figures.scene.plot_scene` (zorder <= 9): Omega_k just above the sidewalks,
    shadows above buildings and cars, rays, sight lines and measurements on top.
    """
    scan = scans.scans[k]
    ego = np.asarray(scan.ego, dtype=float)
    ps.fill_geometry(ax, scan.visible_region, facecolor=_VISIBLE_REGION, edgecolor="none", alpha=0.45, zorder=2.5)
    for shadow in shadow_polygons(ego[:2], scan.obstacles, cfg.r_max):
        ps.fill_geometry(ax, shadow.intersection(fov_polygon(ego, cfg)), facecolor=_SHADOW, alpha=0.3, zorder=4.5)
    _draw_tangent_rays(ax, ego, scans, k, cfg)
    ps.fill_geometry(ax, fov_polygon(ego, cfg), facecolor="none", edgecolor="k", linestyle="--", lw=0.8, zorder=10)
    _draw_sight_lines(ax, ego, scans, k)
    _draw_measurements(ax, ego, scans, k)
    _draw_ego(ax, ego)
    ps.extend_legend(ax, _legend_handles())
    ax.set_aspect("equal")


def _draw_ego(ax: Axes, ego: np.ndarray) -> None:
    """Sensor origin (black dot) and heading (arrow, 6 m)."""
    ax.plot(*ego[:2], "o", color="k", ms=6, zorder=12)
    tip = ego[:2] + 6.0 * np.array([np.cos(ego[2]), np.sin(ego[2])])
    ax.annotate("", tip, ego[:2], arrowprops={"arrowstyle": "-|>", "color": "k", "lw": 1.5}, zorder=12)


def _draw_tangent_rays(ax: Axes, ego: np.ndarray, scans: Scans, k: int, cfg: SensorConfig) -> None:
    """Each obstacle's two tangent rays, from the tangent point out to r_max (§3.1.2)."""
    obs = scans.scans[k].obstacles
    segments = []
    for theta, r_b in ((obs.theta_min, obs.r_min), (obs.theta_max, obs.r_max)):
        u = np.column_stack([np.cos(theta), np.sin(theta)])
        start = ego[:2] + r_b[:, None] * u
        end = ego[:2] + np.maximum(r_b, cfg.r_max)[:, None] * u
        segments += list(np.stack([start, end], axis=1))
    for seg in segments:
        ax.plot(seg[:, 0], seg[:, 1], color=_RAY, lw=0.7, zorder=10)


def _draw_sight_lines(ax: Axes, ego: np.ndarray, scans: Scans, k: int) -> None:
    """Sensor -> pedestrian segments for present pedestrians in the FOV: visible solid green, blocked dashed red."""
    xy = scans.truth_xy[k]
    for i in np.flatnonzero(scans.in_fov[k]):
        ok = bool(scans.visible[k, i])
        style = {"color": _LOS_OK, "ls": "-"} if ok else {"color": _LOS_BLOCKED, "ls": "--"}
        ax.plot([ego[0], xy[i, 0]], [ego[1], xy[i, 1]], lw=1.2, zorder=11, **style)
    shown = scans.present[k]
    ax.plot(xy[shown, 0], xy[shown, 1], "o", mfc="none", mec="k", ms=7, zorder=11)


def _draw_measurements(ax: Axes, ego: np.ndarray, scans: Scans, k: int) -> None:
    """Z_k in the world frame: target-originated dots, clutter crosses."""
    world = polar_to_world(scans.scans[k].Z, ego)
    clutter = scans.source[k] == CLUTTER
    ax.plot(world[~clutter, 0], world[~clutter, 1], ".", color=_Z_TARGET, ms=9, zorder=12)
    ax.plot(world[clutter, 0], world[clutter, 1], "x", color=_Z_CLUTTER, ms=6, zorder=12)


def _legend_handles() -> list:
    return [
        Patch(facecolor=_VISIBLE_REGION, alpha=0.45, label="visible sidewalk $\\Omega_k$"),
        Patch(facecolor=_SHADOW, alpha=0.3, label="obstacle + shadow"),
        Line2D([], [], color=_RAY, lw=0.7, label="tangent rays"),
        Line2D([], [], color=_LOS_OK, label="line of sight: visible"),
        Line2D([], [], color=_LOS_BLOCKED, ls="--", label="line of sight: blocked"),
        Line2D([], [], color=_Z_TARGET, marker=".", ls="none", label="measurement (target)"),
        Line2D([], [], color=_Z_CLUTTER, marker="x", ls="none", label="measurement (clutter)"),
        Line2D([], [], color="k", ls="--", lw=0.8, label="field of view"),
        Line2D([], [], color="k", marker="o", ls="none", label="sensor origin (arrow: heading)"),
        Line2D([], [], color="k", marker="o", mfc="none", ls="none", ms=7, label="present pedestrian"),
    ]


_ESTIMATE = "tab:purple"


def draw_scan(ax: Axes, scan: Scan, estimates: Estimates | StepResult | None = None) -> None:
    """One scan on a scene drawn by :func:`soabench.figures.scene.plot_scene` (a notebook's view, without the
    truth a :class:`Scans` holds): Ω_k, the sensor pose, the measurements Z_k in the world frame and, given
    ``estimates``, the estimated positions (with their track labels when labelled); adds its entries to the legend."""
    ego = np.asarray(scan.ego, dtype=float)
    handles: list = [Patch(facecolor=_VISIBLE_REGION, alpha=0.45, label="visible sidewalk $\\Omega_k$")]
    ps.fill_geometry(ax, scan.visible_region, facecolor=_VISIBLE_REGION, edgecolor="none", alpha=0.45, zorder=2.5)
    world = polar_to_world(np.asarray(scan.Z, dtype=float).reshape(-1, 2), ego)
    ax.plot(world[:, 0], world[:, 1], ".", color=_Z_TARGET, ms=9, zorder=12)
    handles.append(Line2D([], [], color=_Z_TARGET, marker=".", ls="none", label=f"measurement ({len(world)})"))
    if estimates is not None:
        X = np.asarray(estimates.X, dtype=float)
        X = X.reshape(-1, X.shape[-1] if X.ndim == 2 else 2)
        ax.plot(X[:, 0], X[:, 1], "+", color=_ESTIMATE, ms=9, mew=1.6, zorder=13)
        if estimates.labels is not None:
            for (x, y), label in zip(X[:, :2], np.asarray(estimates.labels), strict=True):
                ax.annotate(str(label), (x, y), xytext=(4, 4), textcoords="offset points", fontsize=6,
                            color=_ESTIMATE, zorder=13)  # fmt: skip
        handles.append(Line2D([], [], color=_ESTIMATE, marker="+", ls="none", mew=1.6, label=f"estimate ({len(X)})"))
    _draw_ego(ax, ego)
    handles.append(Line2D([], [], color="k", marker="o", ls="none", label="sensor origin (arrow: heading)"))
    ps.extend_legend(ax, handles)
    ps.panel_title(ax, None, f"scan {scan.k}, t = {scan.t:.1f} s")
    ax.set_aspect("equal")


def scene_snapshot_figure(
    scene, recording, time: float, scans: Scans | None = None, sensor: SensorConfig | None = None
) -> Figure:
    """The bird's-eye view at ``time`` (paper Fig. 3); with ``scans`` and ``sensor``, the scene at the last scan's
    time under the sensor overlay of that scan (FOV, sight lines, measurements, obstacle cones)."""
    fig, ax = scene_figure(scene, legend_rows=6 if scans is not None else 3)
    if scans is None or sensor is None:
        plot_scene(scene, recording, time=time, ax=ax)
        return fig
    plot_scene(scene, recording, time=scans.scans[-1].t, ax=ax)  # the scene at the overlaid scan's time
    draw_sensor_overlay(ax, scans, len(scans) - 1, sensor)
    return fig
