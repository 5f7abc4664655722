"""Figure support: birth components over a scene, coloured like the paper's Fig. 2 (docs/method.md §3.1, §3.6).

Occlusion terms are black, semantic terms green and FOV-boundary terms red, as in the paper; the baselines' grid,
fixed GM and measurement-driven (newborn) components get their own colours. Each component is drawn as the 2-sigma
ellipse of its position block.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from matplotlib.collections import EllipseCollection, LineCollection
from matplotlib.lines import Line2D

from soabench.figures import style as ps
from soabench.figures.scene import plot_scene, scene_figure
from soabench.types import SOURCE_MEAS, SOURCE_NAMES, Births

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from soabench.types import Scan

#: colour per source code (occl, sem, fov, grid, gm, meas)
SOURCE_COLORS = ("black", "tab:green", "tab:red", "tab:blue", "tab:purple", "tab:orange")
#: legend label per source code
SOURCE_LABELS = ("occlusion", "semantic", "FOV boundary", "uniform grid", "fixed GM", "measurement newborn")


def ellipse_params(P: np.ndarray, n_sigma: float = 2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Full widths, heights and angles (deg) of the ``n_sigma`` ellipses of (J, 2, 2) position covariances."""
    P = np.asarray(P, dtype=float).reshape(-1, 2, 2)
    evals, evecs = np.linalg.eigh(0.5 * (P + np.swapaxes(P, -1, -2)))
    evals = np.maximum(evals, 0.0)
    width = 2.0 * n_sigma * np.sqrt(evals[:, 1])  # major axis
    height = 2.0 * n_sigma * np.sqrt(evals[:, 0])
    angle = np.degrees(np.arctan2(evecs[:, 1, 1], evecs[:, 0, 1]))
    return width, height, angle


def draw_births(ax: Axes, births: Births, scan: Scan | None = None) -> None:
    """Draw birth components as 2-sigma ellipses (position block) and their means on ``ax``.

    Appended components use their ``source`` colour; newborn terms (PUBM/ATBM, ``births.newborn``) are drawn from
    ``newborn.m`` / ``newborn.P`` as measurement newborns. With ``scan``, the ego pose and the obstacles' tangent
    rays (thin dotted lines from the sensor to r_max) are drawn too. The legend under the map lists the sources
    present.
    """
    m = [np.asarray(births.m, dtype=float).reshape(-1, 4)]
    P = [np.asarray(births.P, dtype=float).reshape(-1, 4, 4)]
    src = [np.asarray(births.source, dtype=int).reshape(-1)]
    if births.newborn is not None:
        nb_m = np.asarray(births.newborn.m, dtype=float).reshape(-1, 4)
        m.append(nb_m)
        P.append(np.asarray(births.newborn.P, dtype=float).reshape(-1, 4, 4))
        src.append(np.full(len(nb_m), SOURCE_MEAS))
    mm, PP, ss = np.concatenate(m), np.concatenate(P), np.concatenate(src)
    handles = []
    if scan is not None:
        handles += _draw_scan(ax, scan)
    for code in np.unique(ss):
        sel = ss == code
        colour = SOURCE_COLORS[code] if code < len(SOURCE_COLORS) else "tab:gray"
        w, h, a = ellipse_params(PP[sel, :2, :2])
        ax.add_collection(
            EllipseCollection(
                w,
                h,
                a,
                units="xy",
                offsets=mm[sel, :2],
                offset_transform=ax.transData,
                facecolors="none",
                edgecolors=colour,
                linewidths=0.8,
                zorder=4,
            )
        )
        ax.plot(mm[sel, 0], mm[sel, 1], ".", color=colour, ms=2.5, zorder=5)
        label = SOURCE_LABELS[code] if code < len(SOURCE_LABELS) else SOURCE_NAMES[code]
        handles.append(Line2D([], [], color=colour, marker="o", mfc="none", ls="", label=f"{label} ({sel.sum()})"))
    if handles:
        ps.extend_legend(ax, handles)  # one legend under the map, after the scene's own entries


def _draw_scan(ax: Axes, scan: Scan) -> list[Line2D]:
    """Ego pose and the tangent rays of every obstacle of the scan."""
    e = np.asarray(scan.ego, dtype=float)
    obs = scan.obstacles
    if len(obs):
        theta = np.concatenate([obs.theta_min, obs.theta_max])
        r_end = np.concatenate([obs.r_min, obs.r_max]) + 8.0  # a little past the occlusion layers
        ends = e[:2] + r_end[:, None] * np.column_stack([np.cos(theta), np.sin(theta)])
        segs = np.stack([np.broadcast_to(e[:2], ends.shape), ends], axis=1)
        ax.add_collection(LineCollection(segs, linestyles=":", linewidths=0.6, colors="0.35", zorder=3))
    ax.plot(e[0], e[1], marker=(3, 0, np.degrees(e[2]) - 90.0), color="tab:cyan", ms=10, mec="k", zorder=8)
    return [
        Line2D([], [], color="0.35", ls=":", label="tangent rays"),
        Line2D([], [], color="tab:cyan", marker=(3, 0, 0), mec="k", ls="", ms=7, label="sensor pose"),
    ]


def births_snapshot_figure(scene, recording, births: Births, scan: Scan, label: str) -> Figure:
    """The scene at ``scan``'s time with one model's birth components (paper Fig. 2 colours); the title names the
    model (``label``) and counts its components and newborn terms."""
    fig, ax = scene_figure(scene, legend_rows=5)
    plot_scene(scene, recording, time=scan.t, ax=ax)
    draw_births(ax, births, scan)
    n_new = 0 if births.newborn is None else len(births.newborn.m)
    ps.panel_title(
        ax, None, f"{ax.get_title(loc='left')}; {label}: {len(births)} birth components, {n_new} newborn terms"
    )
    return fig
