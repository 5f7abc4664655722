"""What an occlusion gap was (docs/method.md §9.4, "Gaps described"): how long, behind what, and what moved.

For a gap k_a..k_b of target i (:class:`~soabench.tracks.reemergence.Gap`):

* its length in scans (k_b − k_a + 1) and in seconds (that times the scan period);
* the **occluder kind** that hid i longest: on each scan of the gap, the hiding occluder is the first one the sight
  line from the sensor to i's true position runs through (the nearest to the sensor among those that block it, by
  the sensor's own rule, :func:`soabench.sensor.line_of_sight`); its kind is the scan's obstacle kind
  (:attr:`soabench.types.Obstacles.kind`: ``"parked"`` car, ``"vehicle"`` in traffic, ``"building"``), or
  ``"other"`` for any other occluder or none found. The kind with the most scans wins; a tie goes to the kind that
  hid i first;
* whether i **moved** more than ``d_gate`` while hidden: the distance between its true positions at k_a − 1 (last
  seen) and k_b + 1 (seen again);
* whether the **ego moved**: its position changed by more than :data:`EGO_MOVED_M` between those two scans.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import shapely

from soabench.sensor import SIGHT_TOL, oriented_hulls

if TYPE_CHECKING:
    from soabench.tracks.reemergence import Gap
    from soabench.types import Scan, Scans

#: occluder kinds of a gap, in the order tables and figures list them, with their names for a reader
OCCLUDER_KINDS = ("parked", "vehicle", "building", "other")
OCCLUDER_LABEL = {
    "parked": "parked car",
    "vehicle": "moving vehicle",
    "building": "building",
    "other": "other obstacle",
}
#: the ego "moved" during a gap when its position changed by more than this (m)
EGO_MOVED_M = 0.5
#: an occluder is the obstacle of O_k whose hull centroid lies this close to its own (m)
_SAME_CENTROID_M = 1e-6

#: the hiding kinds found for the last :class:`~soabench.types.Scans` described, per (scan, target): the runs of one
#: trial share its truth and occluders (a Scans is not changed once built), so each hidden scan of a target is
#: tested once per trial, not once per run
_hidden_memo: list = [None, None, {}]  # [weak reference to the Scans, its truth array, {(k, target): kind}]


@dataclass(frozen=True)
class GapDescription:
    """One gap described (module docstring): scans and seconds hidden, the occluder kind, the target's and the
    ego's displacement between the scans before and after the gap (m) and whether each counts as moved."""

    scans: int
    seconds: float
    occluder: str
    displacement: float
    moved: bool
    ego_displacement: float
    ego_moved: bool


def _obstacle_kind(scan: Scan, occluder: shapely.Geometry) -> str:
    """The kind of the obstacle of O_k that is ``occluder``'s hull (matched by hull centroid), else "other"."""
    obs = scan.obstacles
    if obs is None or not len(obs):
        return "other"
    ego = np.asarray(scan.ego, dtype=float)[:2]
    b = np.asarray(obs.centroid_bearing, dtype=float)
    centroids = ego + np.asarray(obs.centroid_range, dtype=float)[:, None] * np.column_stack([np.cos(b), np.sin(b)])
    c = shapely.get_coordinates(shapely.centroid(oriented_hulls(np.array([occluder], dtype=object))))[0]
    d = np.hypot(*(centroids - c).T)
    j = int(np.argmin(d))
    kind = str(obs.kind[j])
    return kind if d[j] <= _SAME_CENTROID_M and kind in OCCLUDER_KINDS else "other"


def hiding_kind(scan: Scan, xy: np.ndarray) -> str:
    """The kind of the occluder that hides the point ``xy`` from the sensor at ``scan``: the nearest to the sensor
    of the occluders whose core the sight line runs through (:func:`soabench.sensor.line_of_sight`'s rule), "other"
    when none does."""
    return hiding_kinds(scan, np.asarray(xy, dtype=float).reshape(1, -1))[0]


def hiding_kinds(scan: Scan, points: np.ndarray) -> list[str]:
    """:func:`hiding_kind` of each row of ``points`` (n, 2) at ``scan``, the sight lines tested against the scan's
    occluders together (each occluder's core eroded once for every line that crosses it)."""
    points = np.asarray(points, dtype=float).reshape(len(points), -1)[:, :2]
    kinds = ["other"] * len(points)
    ego = np.asarray(scan.ego, dtype=float)[:2]
    occ = np.asarray(list(scan.occluders), dtype=object).reshape(-1)
    finite = np.flatnonzero(np.isfinite(points).all(axis=1))
    if not len(occ) or not len(finite):
        return kinds
    ego_pt = shapely.points(ego)
    occ = occ[~shapely.contains(occ, ego_pt)]  # the sensor is never hidden by what it sits in
    ends = points[finite]
    lines = shapely.linestrings(np.stack([np.broadcast_to(ego, ends.shape), ends], axis=1))
    hit = shapely.intersects(lines[:, None], occ[None, :])  # (lines, occluders)
    crossed = np.flatnonzero(hit.any(axis=0))
    if not len(crossed):
        return kinds
    core = shapely.buffer(occ[crossed], -SIGHT_TOL, join_style="mitre")
    hit[:, crossed] &= shapely.intersects(lines[:, None], core[None, :])
    dist = np.full(len(occ), np.inf)
    dist[crossed] = shapely.distance(ego_pt, occ[crossed])
    kind_of: dict[int, str] = {}
    for q in np.flatnonzero(hit.any(axis=1)):
        on = np.flatnonzero(hit[q])
        j = int(on[np.argmin(dist[on])])  # the nearest; a tie goes to the first in the scan's order
        if j not in kind_of:
            kind_of[j] = _obstacle_kind(scan, occ[j])
        kinds[int(finite[q])] = kind_of[j]
    return kinds


def _hidden_by(scans: Scans) -> dict[tuple[int, int], str]:
    """The hiding kinds (:func:`hiding_kinds`) already found for ``scans``, per (scan, target); a new, empty memo
    when ``scans`` (or its truth) is not the one described last."""
    ref, truth, memo = _hidden_memo
    if ref is None or ref() is not scans or truth is not scans.truth_xy:
        memo = {}
        _hidden_memo[:] = [weakref.ref(scans), scans.truth_xy, memo]
    return memo


def describe_gaps(scans: Scans, gaps: Sequence[Gap], d_gate: float) -> list[GapDescription]:
    """:class:`GapDescription` of each gap of ``scans`` (the truth and the per-scan occluders of the sensor)."""
    xy, dt = np.asarray(scans.truth_xy, dtype=float), float(scans.dt)
    hidden_by = _hidden_by(scans)
    queries: dict[int, list[int]] = {}  # scan -> the targets hidden there by some gap not yet tested, in gap order
    for g in gaps:
        for k in range(g.k_a, g.k_b + 1):
            if (k, g.target) not in hidden_by:
                queries.setdefault(k, []).append(g.target)
    for k, targets in queries.items():
        unique = list(dict.fromkeys(targets))
        hidden_by.update(zip(((k, i) for i in unique), hiding_kinds(scans.scans[k], xy[k, unique]), strict=True))
    out = []
    for g in gaps:
        kinds = [hidden_by[(k, g.target)] for k in range(g.k_a, g.k_b + 1)]
        counts = {kd: kinds.count(kd) for kd in dict.fromkeys(kinds)}  # in order of first appearance: the tie rule
        kind = max(counts, key=counts.__getitem__)
        before, after = g.k_a - 1, g.k_b + 1
        moved = float(np.hypot(*(xy[after, g.target] - xy[before, g.target])))
        ego = [np.asarray(scans.scans[k].ego, dtype=float)[:2] for k in (before, after)]
        ego_moved = float(np.hypot(*(ego[1] - ego[0])))
        n = g.k_b - g.k_a + 1
        out.append(GapDescription(n, n * dt, kind, moved, moved > d_gate, ego_moved, ego_moved > EGO_MOVED_M))
    return out
