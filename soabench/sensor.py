"""Synthetic range-bearing sensor: Recording -> Scans (docs/method.md §2.3, §3.1.1-3.1.2, §3.1.4, §5.1, §5.4).

The stage contract (:class:`Scan`, :class:`Scans`, :class:`Obstacles`) lives in :mod:`soabench.types`. Here:

* geometry of one scan: :func:`circle_tangents`, :func:`compute_obstacles` (O_k with tangent rays, T12-T15),
  :func:`line_of_sight` (touching or grazing an occluder is visible), :func:`fov_polygon`,
  :func:`shadow_polygons` and :func:`visible_region` (Omega_k, §3.1.4);
* the occluders present at a recording step: :func:`occluders_at`;
* the sensor itself: :func:`observe` (detections with p_D, Gaussian noise, Poisson clutter, source ids, flags).

Random streams: ``observe`` takes ``(detection_rng, clutter_rng)`` from ``TrialSeeds.sensor_rngs()``. Every
detection draw and noise draw of the run is taken from ``detection_rng`` up front, one per (scan, pedestrian), before
anything that depends on the clutter, so runs that differ only in ``lambda_c`` get identical target-originated
measurements (same values, same sources) and differ only in their clutter and in the order within a scan.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
import shapely
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

from soabench.config import Sensor, SensorConfig
from soabench.errors import SoabenchError, require, require_type
from soabench.geometry import fov_mask, range_bearing, wrap
from soabench.notice import announced
from soabench.scenario.scene import SceneMap
from soabench.types import (
    CLUTTER,
    DeferredRegion,
    Obstacles,
    Recording,
    Scan,
    Scans,
)

if TYPE_CHECKING:
    from soabench.scenario.scene import SceneMap

_FOV_ARC_STEP = np.radians(1.0)  #: vertex spacing of the FOV polygon arcs (chord error 2 mm at 50 m)
_SHADOW_ARC_POINTS = 16  #: far-arc vertices of each shadow polygon


# ----------------------------------------------------------------------------------------------------------------
# Tangent rays and obstacles O_k (§3.1.1, §3.1.2; T12-T15)


def circle_tangents(
    center: np.ndarray | Sequence[float], radius: float, ego_xy: np.ndarray | Sequence[float]
) -> tuple[float, float, float] | None:
    """Tangent rays of a circle seen from ``ego_xy`` (§3.1.2, circle form, T12).

    Returns ``(theta_min, theta_max, r_b)``: world-frame ray directions alpha_c -+ asin(rho/d), wrapped to
    (-pi, pi], and the tangent-point range sqrt(d^2 - rho^2); ``None`` when the sensor is inside or on the circle.
    """
    d_vec = np.asarray(center, dtype=float)[:2] - np.asarray(ego_xy, dtype=float)[:2]
    d = float(np.hypot(d_vec[0], d_vec[1]))
    if d <= radius:
        return None
    alpha_c = np.arctan2(d_vec[1], d_vec[0])
    half = np.arcsin(radius / d)
    return float(wrap(alpha_c - half)), float(wrap(alpha_c + half)), float(np.sqrt(d * d - radius * radius))


def compute_obstacles(polygons: list[np.ndarray], kinds: Sequence[str], ego_xy: np.ndarray, r_max: float) -> Obstacles:
    """O_k from occluder vertex arrays (§3.1.1-3.1.2): convex hull, centroid, tangent bearings and ranges.

    Occluders whose hull contains or touches the sensor are skipped, so are those farther than ``r_max`` (T15).
    """
    require(len(polygons) == len(kinds), f"got {len(polygons)} polygons but {len(kinds)} kinds")
    return obstacles_from_geoms(_polygons_from_arrays(polygons), np.asarray(kinds, dtype=str), ego_xy, r_max)


def obstacles_from_geoms(
    geoms: np.ndarray, kinds: np.ndarray, ego_xy: np.ndarray, r_max: float, hulls: np.ndarray | None = None
) -> Obstacles:
    """:func:`compute_obstacles` for an object array of shapely geometries (the fast path of :func:`observe`).

    ``hulls``: the counter-clockwise convex hulls of ``geoms`` (:func:`oriented_hulls`) when already known."""
    ego_xy = np.asarray(ego_xy, dtype=float)[:2]
    if len(geoms) == 0:
        return Obstacles.empty()
    ego_pt = shapely.points(ego_xy)
    hulls = oriented_hulls(geoms) if hulls is None else hulls
    keep = ~shapely.is_empty(hulls) & shapely.dwithin(hulls, ego_pt, r_max) & ~shapely.intersects(hulls, ego_pt)
    hulls, kinds = hulls[keep], np.asarray(kinds, dtype=str)[keep]
    if len(hulls) == 0:
        return Obstacles.empty()
    verts, owner = _hull_vertices(hulls)
    centroid = shapely.get_coordinates(shapely.centroid(hulls))
    d_c = centroid - ego_xy
    alpha_c = np.arctan2(d_c[:, 1], d_c[:, 0])
    d_v = verts - ego_xy
    r_v = np.hypot(d_v[:, 0], d_v[:, 1])
    delta = wrap(np.arctan2(d_v[:, 1], d_v[:, 0]) - alpha_c[owner])
    i_min = _group_first(owner, delta, r_v, len(hulls))
    i_max = _group_first(owner, -delta, r_v, len(hulls))
    return Obstacles(
        polygons=np.split(verts, np.flatnonzero(np.diff(owner)) + 1),
        kind=kinds.astype("<U8"),
        centroid_range=np.hypot(d_c[:, 0], d_c[:, 1]),
        centroid_bearing=alpha_c,
        theta_min=wrap(alpha_c + delta[i_min]),
        theta_max=wrap(alpha_c + delta[i_max]),
        r_min=r_v[i_min],
        r_max=r_v[i_max],
    )


def oriented_hulls(geoms: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull of each geometry (object array in, object array out)."""
    return shapely.orient_polygons(shapely.convex_hull(np.asarray(geoms, dtype=object)))


def _hull_vertices(hulls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 2) of each hull without the closing repeat, and the owning hull index (V,) (sorted)."""
    coords, owner = shapely.get_coordinates(hulls, return_index=True)
    is_last = np.r_[owner[1:] != owner[:-1], True]
    is_first = np.r_[True, owner[1:] != owner[:-1]]
    first_of = np.maximum.accumulate(np.where(is_first, np.arange(len(owner)), 0))
    closing = is_last & ~is_first & np.all(coords == coords[first_of], axis=1)
    return coords[~closing], owner[~closing]


def _group_first(owner: np.ndarray, key: np.ndarray, tie: np.ndarray, n: int) -> np.ndarray:
    """Index of the element with the smallest ``key`` (ties: smallest ``tie``) within each group of ``owner``."""
    order = np.lexsort((tie, key, owner))
    starts = np.searchsorted(owner[order], np.arange(n), side="left")
    return order[starts]


def _polygons_from_arrays(polygons: Sequence[np.ndarray]) -> np.ndarray:
    """Object array of shapely Polygons from (n_i, 2) vertex arrays (n_i >= 3), built in one vectorised call."""
    if len(polygons) == 0:
        return np.zeros(0, dtype=object)
    arrays = [np.asarray(p, dtype=float).reshape(-1, 2) for p in polygons]
    for i, a in enumerate(arrays):
        require(len(a) >= 3 and np.isfinite(a).all(), f"occluder polygon {i} needs >= 3 finite vertices, got {a!r}")
    owner = np.repeat(np.arange(len(arrays)), [len(a) for a in arrays])
    return shapely.polygons(shapely.linearrings(np.concatenate(arrays), indices=owner))


# ----------------------------------------------------------------------------------------------------------------
# Line of sight (§2.3 simulator-side detection, §4.4 occlusion_pd)


#: depth (m) by which a sight line must run inside an occluder to be blocked (docs/method.md §2.3, register row 34):
#: grazing a vertex or running along an edge is visible whatever the rounding of the sight line's end point
SIGHT_TOL = 1e-9


def line_of_sight(ego_xy: np.ndarray, targets: np.ndarray, occluders: Sequence[BaseGeometry]) -> np.ndarray:
    """(N,) bool: the segment sensor -> target does not run through an occluder (§2.3, §4.4).

    Blocked only where the segment passes through an occluder's core, the polygon eroded by :data:`SIGHT_TOL`:
    a segment that touches an occluder, grazes a vertex or runs along an edge is visible, also when rounding puts it
    a few ulps inside (S-OA's births on tangent rays, §3.1.2). Occluders that contain the sensor in their interior
    are ignored (the sensor cannot be occluded by what it sits in). The cores are GEOS's (``shapely.buffer``); the
    segments are tested against their rings in compiled code with certified signs, and GEOS decides the pairs those
    signs leave open (:class:`SightBlockers`): the same decisions as GEOS's ``intersects``, bit for bit.
    """
    ego_xy = np.asarray(ego_xy, dtype=float)[:2]
    targets = np.asarray(targets, dtype=float).reshape(-1, 2)
    if len(targets) == 0:
        return np.ones(0, dtype=bool)
    return line_of_sight_past(ego_xy, targets, sight_blockers(ego_xy, occluders))


#: below this many sight lines from a pose whose rings are not listed yet, GEOS alone decides them (listing the rings
#: and building the cores costs more than the few tests: the sensor's scans of a small crowd, benchmarks/README.md)
FEW_SIGHT_LINES = 16


class SightBlockers:
    """The occluders that can hide a point from one pose (those not containing the sensor in their interior),
    prepared, and their cores (each eroded by :data:`SIGHT_TOL`), built on first use for the occluders some sight
    line meets and kept for the next point set tested from the same pose (:func:`line_of_sight_past`).

    The sight lines are decided by compiled orientation tests against the rings of the occluders and of their cores
    (:func:`soabench.geometry_kernels.sight_blocked`); a (line, occluder) pair whose signs the floating-point test
    cannot certify, or whose occluder or core is not a valid polygon, goes to GEOS, as the whole test did before
    (``fallback_pairs`` counts them)."""

    def __init__(self, occ: np.ndarray) -> None:
        self.occ = occ
        self._core = np.full(len(occ), None, dtype=object)
        self._built = np.zeros(len(occ), dtype=bool)
        self._n_built = 0
        self._posed: dict[tuple[float, float], tuple] = {}  # per pose: the rings of the occluders and built cores
        self._invalid: np.ndarray | None = None  # occluders, then cores: not valid polygons (always decided by GEOS)
        self.fallback_pairs = 0

    def __len__(self) -> int:
        return len(self.occ)

    def cores(self, j: np.ndarray) -> np.ndarray:
        """The cores of occluders ``j`` (indices, repeats allowed)."""
        todo = np.unique(j[~self._built[j]])
        if len(todo):
            self._core[todo] = shapely.buffer(self.occ[todo], -SIGHT_TOL, join_style="mitre")
            self._built[todo] = True
            self._n_built += len(todo)
            if self._invalid is not None:
                self._invalid[len(self.occ) + todo] = ~shapely.is_valid(self._core[todo])
        return self._core[j]

    def blocked(self, ego_xy: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """(N,) bool: the segment ``ego_xy`` -> target runs through some occluder's core (:func:`line_of_sight`)."""
        # imported when called: numba would slow every start-up
        from soabench.geometry_kernels import BLOCKED, NEEDS_CORE

        ex, ey = float(ego_xy[0]), float(ego_xy[1])
        if len(targets) < FEW_SIGHT_LINES and (ex, ey) not in self._posed:  # GEOS alone costs less than the rings
            lines = shapely.linestrings(np.stack([np.broadcast_to(ego_xy, targets.shape), targets], axis=1))
            return _blocked_pairs(lines, self).any(axis=1)
        px, py = targets[:, 0].copy(), targets[:, 1].copy()
        status, pairs, need = self._decide(ex, ey, px, py)
        while need.any():  # the first lines that meet an occluder: build its core, decide those lines again
            self.cores(np.flatnonzero(need))
            redo = np.flatnonzero(status == NEEDS_CORE)
            again, more, need = self._decide(ex, ey, px[redo], py[redo])
            status[redo] = again
            pairs = np.concatenate([pairs, np.column_stack([redo[more[:, 0]], more[:, 1]])])
        out = status == BLOCKED
        if len(pairs):
            self.fallback_pairs += len(pairs)
            ii, jj = pairs[:, 0], pairs[:, 1]
            lines = shapely.linestrings(np.stack([np.broadcast_to(ego_xy, (len(ii), 2)), targets[ii]], axis=1))
            out[ii[_blocked_pair(lines, jj, self)]] = True
        return out

    def _decide(self, ex: float, ey: float, px: np.ndarray, py: np.ndarray) -> tuple:
        from soabench.geometry_kernels import sight_blocked

        posed = self._posed.get((ex, ey))
        if posed is None or posed[0] != self._n_built:  # the occluders, then the cores built so far
            if self._invalid is None:
                # GEOS's predicates on an invalid polygon (a buffer at large coordinates can return one) follow its
                # own rules, not the exact sets the signs decide: every line goes to GEOS there
                core = self._core[self._built]
                self._invalid = np.zeros(2 * len(self.occ), dtype=bool)
                self._invalid[: len(self.occ)] = ~shapely.is_valid(self.occ)
                self._invalid[len(self.occ) + np.flatnonzero(self._built)] = ~shapely.is_valid(core)
            rings = _ring_arrays(np.concatenate([self.occ, self._core]))
            posed = self._posed[(ex, ey)] = (self._n_built, _posed_rings(ex, ey, rings, self._invalid))
        return announced("geometry.sight", sight_blocked, ex, ey, px, py, *posed[1], self._built)


def _ring_arrays(geoms: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rings of ``geoms`` (polygons, multipolygons, empty or None) as :func:`soabench.geometry_kernels.
    sight_polygons` takes them: vertex x and y, each geometry's first ring, each ring's first vertex; and the
    geometries with a part that is not a polygon (never decided by the rings: every line goes to GEOS)."""
    odd = np.zeros(len(geoms), dtype=bool)
    kind = shapely.get_type_id(geoms)
    if ((kind == 3) | (kind == -1)).all() and not (shapely.get_num_interior_rings(geoms) > 0).any():
        xy, vertex_of = shapely.get_coordinates(geoms, return_index=True)  # polygons without holes: one ring each
        counts = np.bincount(vertex_of, minlength=len(geoms))
        rstart = np.zeros(len(geoms) + 1, dtype=np.int64)
        np.cumsum(counts > 0, out=rstart[1:])
        vstart = np.zeros(rstart[-1] + 1, dtype=np.int64)
        np.cumsum(counts[counts > 0], out=vstart[1:])
        return xy[:, 0].copy(), xy[:, 1].copy(), rstart, vstart, odd
    parts, part_of = shapely.get_parts(geoms, return_index=True)
    odd[part_of[shapely.get_type_id(parts) != 3]] = True
    rings, ring_of = shapely.get_rings(parts, return_index=True)
    xy, vertex_of = shapely.get_coordinates(rings, return_index=True)
    rstart = np.zeros(len(geoms) + 1, dtype=np.int64)
    np.cumsum(np.bincount(part_of[ring_of], minlength=len(geoms)), out=rstart[1:])
    vstart = np.zeros(len(rings) + 1, dtype=np.int64)
    np.cumsum(np.bincount(vertex_of, minlength=len(rings)), out=vstart[1:])
    return xy[:, 0].copy(), xy[:, 1].copy(), rstart, vstart, odd


def _posed_rings(ex: float, ey: float, rings: tuple, invalid: np.ndarray) -> tuple:
    """A ring set with what depends on the sensor's position (:func:`soabench.geometry_kernels.sight_polygons`); the
    polygons flagged ``invalid`` (or with a part that is not a polygon) are never decided by their rings."""
    from soabench.geometry_kernels import ODD, sight_polygons

    vx, vy, rstart, vstart, odd = rings
    odd = odd | invalid
    bb, side, inside = sight_polygons(ex, ey, vx, vy, rstart, vstart)
    if odd.any():
        bb[odd] = (-np.inf, -np.inf, np.inf, np.inf)
        inside[odd] = ODD
    return bb, rstart, vstart, vx, vy, side, inside


def sight_blockers(ego_xy: np.ndarray, occluders: Sequence[BaseGeometry]) -> SightBlockers:
    """What :func:`line_of_sight` tests against from ``ego_xy``, computed once per scan by a caller that tests many
    point sets from the same pose (:func:`line_of_sight_past`)."""
    ego_xy = np.asarray(ego_xy, dtype=float)[:2]
    occ = np.asarray(list(occluders), dtype=object).reshape(-1)
    if len(occ):
        occ = occ[~shapely.contains(occ, shapely.points(ego_xy))]
        shapely.prepare(occ)
    return SightBlockers(occ)


def line_of_sight_past(ego_xy: np.ndarray, targets: np.ndarray, blockers: SightBlockers) -> np.ndarray:
    """:func:`line_of_sight` given the scan's :func:`sight_blockers` (same result)."""
    ego_xy = np.asarray(ego_xy, dtype=float)[:2]
    targets = np.asarray(targets, dtype=float).reshape(-1, 2)
    if len(targets) == 0 or len(blockers) == 0:
        return np.ones(len(targets), dtype=bool)
    return ~blockers.blocked(ego_xy, targets)


def _line_of_sight_reference(ego_xy: np.ndarray, targets: np.ndarray, blockers: SightBlockers) -> np.ndarray:
    """:func:`line_of_sight_past` decided by GEOS alone, every line against every occluder: what the compiled test
    must equal in every case (the equivalence tests)."""
    ego_xy = np.asarray(ego_xy, dtype=float)[:2]
    targets = np.asarray(targets, dtype=float).reshape(-1, 2)
    if len(targets) == 0 or len(blockers) == 0:
        return np.ones(len(targets), dtype=bool)
    lines = shapely.linestrings(np.stack([np.broadcast_to(ego_xy, targets.shape), targets], axis=1))
    return ~_blocked_pairs(lines, blockers).any(axis=1)


def _blocked_pairs(lines: np.ndarray, blockers: SightBlockers) -> np.ndarray:
    """(N, O) bool: line i runs through the core of occluder j. Only pairs that meet the occluder itself (a prepared,
    cheap test) are tested against its core."""
    hit = shapely.intersects(lines[:, None], blockers.occ[None, :])
    ii, jj = np.nonzero(hit)
    if len(ii):
        hit[ii, jj] = shapely.intersects(lines[ii], blockers.cores(jj))
    return hit


def _blocked_pair(lines: np.ndarray, jj: np.ndarray, blockers: SightBlockers) -> np.ndarray:
    """(m,) bool: line k runs through the core of occluder jj[k], decided by GEOS as :func:`_blocked_pairs` does."""
    hit = shapely.intersects(lines, blockers.occ[jj])
    (k,) = np.nonzero(hit)
    if len(k):
        hit[k] = shapely.intersects(lines[k], blockers.cores(jj[k]))
    return hit


def target_visibility(
    ego_xy: np.ndarray,
    targets: np.ndarray,
    occluders: Sequence[BaseGeometry],
    visibility_points: int = 1,
    visibility_offset: float = 0.3,
) -> np.ndarray:
    """(N,) bool visibility of targets (§2.3): centre only, or any of centre and +-offset across the sight line."""
    targets = np.asarray(targets, dtype=float).reshape(-1, 2)
    if visibility_points == 1 or len(targets) == 0:
        return line_of_sight(ego_xy, targets, occluders)
    d = targets - np.asarray(ego_xy, dtype=float)[:2]
    norm = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]
    side = visibility_offset * np.column_stack([-d[:, 1], d[:, 0]]) / norm
    points = np.concatenate([targets, targets + side, targets - side])
    return line_of_sight(ego_xy, points, occluders).reshape(3, -1).any(axis=0)


# ----------------------------------------------------------------------------------------------------------------
# Field of view, shadows and the visible semantic region Omega_k (§2.3, §3.1.4)


def fov_polygon(ego: np.ndarray, cfg: SensorConfig) -> Polygon:
    """FOV_k as a polygon (§2.3): annulus [r_min, r_max] (360 deg) or annular sector centred on the ego heading."""
    x, y, theta = (float(v) for v in np.asarray(ego, dtype=float)[:3])
    shell, hole = _fov_template(float(cfg.r_min), float(cfg.r_max), float(cfg.fov_deg))
    if cfg.fov_deg < 360.0:
        c, s = np.cos(theta), np.sin(theta)
        shell = shell @ np.array([[c, s], [-s, c]])
    return Polygon(shell + (x, y), [hole + (x, y)] if hole is not None else None)


@lru_cache(maxsize=16)
def _fov_template(r_min: float, r_max: float, fov_deg: float) -> tuple[np.ndarray, np.ndarray | None]:
    """FOV outline about the origin with heading 0: (shell, hole or None); arcs sampled every _FOV_ARC_STEP."""
    full = fov_deg >= 360.0
    span = 2.0 * np.pi if full else np.radians(fov_deg)
    n = max(2, int(np.ceil(span / _FOV_ARC_STEP)) + 1)
    phi = np.linspace(-0.5 * span, 0.5 * span, n)
    if full:
        phi = phi[:-1]
    arc = np.column_stack([np.cos(phi), np.sin(phi)])
    if full:
        return r_max * arc, (r_min * arc[::-1] if r_min > 0 else None)
    inner = r_min * arc[::-1] if r_min > 0 else np.zeros((1, 2))
    return np.concatenate([r_max * arc, inner]), None


def shadow_polygons(ego_xy: np.ndarray, obstacles: Obstacles, r_far: float) -> np.ndarray:
    """(N,) object array: each obstacle together with its exact shadow, the set of points whose segment to the
    sensor meets the obstacle (the region between its tangent rays and beyond it), reaching at least ``r_far`` from
    the sensor (§3.1.2 cone C_j, §3.1.4, test T19b).

    For a convex obstacle not containing the sensor, obstacle plus shadow is convex: the convex hull of the obstacle's
    vertices and far points on the arc between theta_min and theta_max. The arc lies beyond every vertex of the
    obstacle (radius max(r_far, farthest vertex range)), so each far point is behind the supporting line of every
    edge facing the sensor and the hull adds nothing in front of the obstacle. (An arc at r_far alone would, when a
    tangent point lies beyond r_far, also cover visible ground in front of a large building.)
    """
    n_obs = len(obstacles)
    if n_obs == 0:
        return np.zeros(0, dtype=object)
    ego_xy = np.asarray(ego_xy, dtype=float)[:2]
    verts = _padded(obstacles.polygons)
    reach = np.maximum(r_far, np.hypot(*(verts - ego_xy).transpose(2, 0, 1)).max(axis=1))
    width = np.mod(obstacles.theta_max - obstacles.theta_min, 2.0 * np.pi)
    s = np.linspace(0.0, 1.0, _SHADOW_ARC_POINTS)
    phi = obstacles.theta_min[:, None] + width[:, None] * s[None, :]
    radius = (reach * (1.0 + 1e-9) + 1e-6) / np.cos(0.5 * width / (_SHADOW_ARC_POINTS - 1))
    far = ego_xy + radius[:, None, None] * np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    return shapely.convex_hull(shapely.multipoints(np.concatenate([verts, far], axis=1)))


def _padded(polygons: Sequence[np.ndarray]) -> np.ndarray:
    """(N, n_max, 2) vertex array, each polygon padded by repeating its first vertex (harmless for hulls)."""
    lens = np.fromiter((len(p) for p in polygons), dtype=np.intp, count=len(polygons))
    starts = np.concatenate([[0], np.cumsum(lens)[:-1]])
    j = np.arange(lens.max())
    return np.concatenate(polygons)[starts[:, None] + np.where(j < lens[:, None], j, 0)]


def visible_region(
    scene: SceneMap,
    ego: np.ndarray,
    obstacles: Obstacles,
    cfg: SensorConfig,
    region: BaseGeometry | None = None,
    occluders: Sequence[BaseGeometry] = (),
) -> BaseGeometry:
    """Omega_k (§3.1.4): the semantic region within FOV_k minus every obstacle and its shadow out to r_max.

    Args:
        region: the semantic region; ``scene.sidewalk`` when None (pass the union with crossings for
            ``birth.sem_include_crossings``).
        occluders: extra polygons to remove without a shadow (e.g. an occluder containing the sensor, which has no
            cone and is not in ``obstacles``).
    """
    return _omega(scene.sidewalk if region is None else region, ego, obstacles, cfg, occluders)


def _omega(
    region: BaseGeometry, ego: np.ndarray, obstacles: Obstacles, cfg: SensorConfig, occluders: Sequence[BaseGeometry]
) -> BaseGeometry:
    """(region within FOV_k) minus (obstacles with their shadows, and ``occluders``)."""
    fov = fov_polygon(ego, cfg)
    base = shapely.clip_by_rect(region, *fov.bounds).intersection(fov)
    if base.is_empty:
        return base
    cut = np.concatenate([shadow_polygons(ego, obstacles, cfg.r_max), np.asarray(list(occluders), dtype=object)])
    cut = cut[shapely.intersects(cut, base)] if len(cut) else cut
    return base.difference(shapely.union_all(cut)) if len(cut) else base


#: relative margin of the sure tests in :meth:`VisibleRegion.contains_xy` (far above rounding, far below any use)
_SURE = 1e-9


class VisibleRegion(DeferredRegion):
    """Omega_k of one scan (§3.1.4), built only when read (docs/method.md §3.1.4): what the sensor puts in
    ``Scan.visible_region``.

    :meth:`build` is :func:`visible_region` (the same polygon overlay, bit for bit). :meth:`contains_xy` answers
    which points lie in its interior from the overlay's inputs, without the overlay. A trial's birth models ask the
    second question of a few dozen points per scan; the overlay (a union of the shadow polygons and a set
    difference, the costly part) is then computed only for a scan whose geometry is read (a figure, an
    exported scans file, a birth model that samples in Omega_k itself).
    """

    def __init__(
        self,
        region: BaseGeometry,
        ego: np.ndarray,
        obstacles: Obstacles,
        cfg: SensorConfig,
        occluders: Sequence[BaseGeometry] = (),
    ) -> None:
        self.region, self.ego, self.obstacles, self.cfg = region, np.asarray(ego, dtype=float), obstacles, cfg
        self.occluders = np.asarray(list(occluders), dtype=object).reshape(-1)

    def build(self) -> BaseGeometry:
        return _omega(self.region, self.ego, self.obstacles, self.cfg, list(self.occluders))

    def contains_xy(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(n,) points (x_i, y_i) in the interior of Omega_k = (region within FOV_k) minus the obstacles with their
        shadows and the occluders containing the sensor:

        * in the interior of the semantic region (``shapely.contains_xy``, the region is prepared once per trial);
        * in the interior of FOV_k's polygon: decided from range and bearing where a point is farther than 1e-9
          (relative) from the polygon's outline (inside the inscribed annulus of its chords), else by the polygon;
        * not in any obstacle's closed shadow: the segment from the sensor to the point does not meet the obstacle's
          convex hull (:func:`segment_meets_convex`). Within r_max this is the shadow polygon of
          :func:`shadow_polygons` (its far arc lies beyond r_max, its other edges are the tangent rays and the
          obstacle's sides facing the sensor);
        * not in any occluder containing the sensor.
        """
        x = np.asarray(x, dtype=float).reshape(-1)
        y = np.asarray(y, dtype=float).reshape(-1)
        ok = shapely.contains_xy(self.region, x, y)
        idx = np.flatnonzero(ok)
        if len(idx):
            ok[idx[~self._in_fov(x[idx], y[idx])]] = False
            idx = np.flatnonzero(ok)
        if len(idx) and len(self.obstacles):
            hit = segment_meets_convex(self.ego[:2], np.column_stack([x[idx], y[idx]]), self.obstacles.polygons)
            ok[idx[hit]] = False
            idx = np.flatnonzero(ok)
        if len(idx) and len(self.occluders):
            hit = shapely.intersects_xy(self.occluders[:, None], x[idx][None, :], y[idx][None, :]).any(axis=0)
            ok[idx[hit]] = False
        return ok

    def _in_fov(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(n,) in the interior of :func:`fov_polygon`: sure from range and bearing, the polygon for the rest."""
        cfg = self.cfg
        span = 2.0 * np.pi if cfg.fov_deg >= 360.0 else np.radians(float(cfg.fov_deg))
        step = span / (max(2, int(np.ceil(span / _FOV_ARC_STEP)) + 1) - 1)  # the arcs' spacing (_fov_template)
        r_lo = float(cfg.r_min) * (1.0 + _SURE) + _SURE
        r_hi = float(cfg.r_max) * np.cos(0.5 * step) * (1.0 - _SURE) - _SURE
        dx, dy = x - self.ego[0], y - self.ego[1]
        r = np.hypot(dx, dy)
        sure = (r > r_lo) & (r < r_hi)
        if cfg.fov_deg < 360.0:
            sure &= np.abs(wrap(np.arctan2(dy, dx) - self.ego[2])) < 0.5 * span - _SURE
        out = sure.copy()
        rest = np.flatnonzero(~sure)
        if len(rest):
            out[rest] = shapely.contains_xy(fov_polygon(self.ego, cfg), x[rest], y[rest])
        return out


def segment_meets_convex(ego_xy: np.ndarray, points: np.ndarray, polygons: Sequence[np.ndarray]) -> np.ndarray:
    """(n,) True where the closed segment from ``ego_xy`` to a point meets any closed convex polygon (the
    counter-clockwise hulls of O_k): the point lies in that obstacle or in its shadow (§3.1.2, §3.1.4).

    Cyrus-Beck clipping of each segment against each polygon's edges, compiled
    (:func:`soabench.geometry_kernels.segments_meet_convex`): with the outward normal n_i of edge i, the segment
    e + t d (0 <= t <= 1) stays inside the edge's half-plane for t d.n_i <= (v_i - e).n_i; it meets the polygon
    where the largest entering t is at most the smallest leaving t."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) == 0 or len(polygons) == 0:
        return np.zeros(len(points), dtype=bool)
    # imported when called: numba would slow every start-up
    from soabench.geometry_kernels import flat_polygons, segments_meet_convex

    e = np.asarray(ego_xy, dtype=float)
    vx, vy, starts, counts = flat_polygons(polygons)
    px, py = points[:, 0].copy(), points[:, 1].copy()
    args = (float(e[0]), float(e[1]), px, py, vx, vy, starts, counts)
    return announced("geometry.segments", segments_meet_convex, *args)


# ----------------------------------------------------------------------------------------------------------------
# Occluders of a recording step (§3.1.1)


def occluders_at(recording: Recording, scene: SceneMap, step_index: int) -> tuple[list[np.ndarray], list[str]]:
    """Occluder vertex arrays and kinds at one recording step (§3.1.1): buildings, parked cars, other vehicles.

    Parked cars are the union of ``recording.static_occluders`` and ``scene.static_occluders`` with exact
    duplicates dropped. The ego's own footprint and pedestrians are never occluders.
    """
    polys, kinds = _static_occluder_arrays(recording, scene)
    vehicles = _vehicle_arrays(recording, step_index)
    return polys + list(vehicles), kinds + ["vehicle"] * len(vehicles)


def _static_occluder_arrays(recording: Recording, scene: SceneMap) -> tuple[list[np.ndarray], list[str]]:
    """Buildings (exterior rings of every part) and de-duplicated parked cars, as (n_i, 2) arrays."""
    polys: list[np.ndarray] = []
    kinds: list[str] = []
    for geom in scene.buildings:
        for part in shapely.get_parts(np.asarray([geom], dtype=object)):
            if isinstance(part, Polygon) and not part.is_empty:
                polys.append(np.asarray(part.exterior.coords)[:-1])
                kinds.append("building")
    seen: set[bytes] = set()
    parked = [np.asarray(p, dtype=float) for p in recording.static_occluders]
    parked += [np.asarray(p.exterior.coords)[:-1] for p in scene.static_occluders if not p.is_empty]
    for p in parked:
        key = shapely.normalize(shapely.polygons(p)).wkb
        if key not in seen:
            seen.add(key)
            polys.append(p)
            kinds.append("parked")
    return polys, kinds


def _vehicle_arrays(recording: Recording, step_index: int) -> np.ndarray:
    """(V_k, 4, 2) footprints of the other vehicles present (and finite) at ``step_index``."""
    foot = np.asarray(recording.veh_footprint, dtype=float).reshape(len(recording.t), -1, 4, 2)[step_index]
    present = np.asarray(recording.veh_present, dtype=bool).reshape(len(recording.t), -1)[step_index]
    return foot[present & np.isfinite(foot).all(axis=(1, 2))]


# ----------------------------------------------------------------------------------------------------------------
# The sensor (§2.3, §5.1, §5.4)


def scan_steps(t: np.ndarray, step_length: float, dt: float) -> np.ndarray:
    """Recording step index of each scan k = 0, 1, ... at time k*dt (scans start at t = 0, end at the recording's
    last sample). Each scan time must have a recording sample within half a SUMO step."""
    t = np.asarray(t, dtype=float)
    require(t.ndim == 1 and len(t) >= 1, "the recording has no time steps")
    tol = 0.5 * step_length + 1e-9
    require(abs(t[0]) <= tol, f"recording starts at t = {float(t[0])!r} s; the sensor samples k*dt from t = 0")
    n_scans = int(np.floor((t[-1] + tol) / dt)) + 1
    times = np.arange(n_scans) * dt
    idx = np.clip(np.searchsorted(t, times), 1, len(t) - 1) if len(t) > 1 else np.zeros(n_scans, dtype=int)
    if len(t) > 1:
        idx = np.where(np.abs(t[idx - 1] - times) <= np.abs(t[idx] - times), idx - 1, idx)
    bad = np.abs(t[idx] - times) > tol
    if bad.any():
        raise SoabenchError(f"the recording has no sample at scan time t = {float(times[bad][0])!r} s (dt = {dt!r} s)")
    return idx


def draw_clutter(rng: np.random.Generator, cfg: Sensor, n_scans: int) -> list[np.ndarray]:
    """Poisson clutter for ``n_scans`` scans (§2.3): (M_k, 2) (range, bearing) arrays, uniform over
    [r_min, r_max] x [-Theta/2, Theta/2] (``polar``) or uniform in area over the FOV (``cartesian``)."""
    counts = rng.poisson(cfg.lambda_c, n_scans)
    u = rng.random((int(counts.sum()), 2))
    if cfg.clutter_space == "polar":
        r = cfg.r_min + (cfg.r_max - cfg.r_min) * u[:, 0]
    else:
        r = np.sqrt(cfg.r_min**2 + (cfg.r_max**2 - cfg.r_min**2) * u[:, 0])
    b = wrap(cfg.fov * (u[:, 1] - 0.5))
    return np.split(np.column_stack([r, b]), np.cumsum(counts)[:-1])


@dataclass
class _Draws:
    """Every random number of one run, drawn before any scan is built (lambda-independent detections)."""

    u_detect: np.ndarray  #: (K, P) uniforms, detected iff u < p_D
    noise: np.ndarray  #: (K, P, 2) N(0, R) samples (range m, bearing rad)
    clutter: list[np.ndarray]  #: K (M_k, 2) clutter measurements


def _draw(rngs: tuple[np.random.Generator, np.random.Generator], cfg: Sensor, n_scans: int, n_peds: int) -> _Draws:
    """Detection uniforms and noise (detection rng, fixed shape) and clutter (clutter rng)."""
    det_rng, clutter_rng = rngs
    u_detect = det_rng.random((n_scans, n_peds))
    noise = det_rng.standard_normal((n_scans, n_peds, 2)) * np.array([cfg.sigma_r, cfg.sigma_b])
    return _Draws(u_detect, noise, draw_clutter(clutter_rng, cfg, n_scans))


def observe(
    recording: Recording,
    scene: SceneMap,
    cfg: SensorConfig,
    rngs: tuple[np.random.Generator, np.random.Generator],
    geometry: dict | None = None,
) -> Scans:
    """Recording -> Scans (§2.3): one scan every ``cfg.dt`` from t = 0, at the recording step with that time.

    Per scan: FOV test, line of sight through buildings, parked cars and other vehicles, detection with p_D,
    (range, bearing) + N(0, R) with the bearing relative to the ego heading and wrapped, Poisson clutter, source
    ids, a shuffle of the measurement order (detection rng), O_k and Omega_k. Pure given ``rngs``.

    ``geometry``: a dict that keeps each scan's geometry (ego, truth, FOV and line-of-sight tests, O_k, Omega_k),
    which does not depend on the clutter rate: the first call fills it, a later call with the same recording, scene
    and settings other than ``lambda_c`` reuses it (another recording, scene or setting starts it afresh). The scans
    are the same as without it (docs/method.md §5.8: the detection and clutter streams are drawn as before).
    """

    require_type(recording, Recording, "observe's recording", "simulate one with soabench.scenario.simulate")
    require_type(scene, SceneMap, "observe's scene", "load it with soabench.scenario.load(net)")
    require_type(
        cfg, Sensor, "observe's sensor", "pass config.sensor_at(rate): the [sensor] settings at a clutter rate"
    )
    require(
        isinstance(rngs, tuple) and len(rngs) == 2 and all(isinstance(g, np.random.Generator) for g in rngs),
        f"observe's rngs must be the pair (detection, clutter) of numpy Generators of TrialSeeds.sensor_rngs(), "
        f"got a {type(rngs).__name__}",
    )
    cfg.validate(recording.step_length)
    if geometry is not None:
        key = (id(recording), id(scene), repr(cfg.settings))
        if geometry.get("key") != key:
            geometry.clear()
            geometry.update(key=key, recording=recording, scene=scene, steps={})  # held: their ids stay unique
        geometry = geometry["steps"]
    steps = scan_steps(recording.t, recording.step_length, cfg.dt)
    n_peds = len(recording.ped_ids)
    draws = _draw(rngs, cfg, len(steps), n_peds)
    static = _StaticOccluders(*_prepared(*_static_occluder_arrays(recording, scene)))
    region = scene.sidewalk
    shapely.prepare(region)
    out = _empty_truth(len(steps), n_peds)
    scans: list[Scan] = []
    sources: list[np.ndarray] = []
    for k, idx in enumerate(steps):
        scan, source = _observe_step(recording, int(idx), k, cfg, draws, static, region, rngs[0], out, geometry)
        scans.append(scan)
        sources.append(source)
    return Scans(
        sensor=dataclasses.replace(cfg),
        scans=scans,
        dt=float(cfg.dt),
        source=sources,
        truth_xy=out["truth_xy"],
        present=out["present"],
        in_fov=out["in_fov"],
        visible=out["visible"],
        detected=out["detected"],
        ped_ids=np.asarray(recording.ped_ids, dtype=str),
    )


def _prepared(polys: list[np.ndarray], kinds: list[str]) -> tuple[np.ndarray, np.ndarray]:
    geoms = _polygons_from_arrays(polys)
    shapely.prepare(geoms)
    return geoms, np.asarray(kinds, dtype="<U8")


class _StaticOccluders:
    """The occluders fixed for a whole recording (buildings, parked cars): prepared geometries, kinds, and their
    oriented convex hulls, computed once per :func:`observe` instead of once per scan."""

    def __init__(self, geoms: np.ndarray, kinds: np.ndarray) -> None:
        self.geoms = geoms
        self.kinds = kinds
        self.hulls = oriented_hulls(geoms) if len(geoms) else geoms[:0]


def _empty_truth(n_scans: int, n_peds: int) -> dict[str, np.ndarray]:
    flags = {name: np.zeros((n_scans, n_peds), dtype=bool) for name in ("present", "in_fov", "visible", "detected")}
    return {"truth_xy": np.full((n_scans, n_peds, 2), np.nan), **flags}


def _observe_step(
    recording: Recording,
    idx: int,
    k: int,
    cfg: SensorConfig,
    draws: _Draws,
    static: _StaticOccluders,
    region: BaseGeometry,
    det_rng: np.random.Generator,
    out: dict[str, np.ndarray],
    geometry: dict | None = None,
) -> tuple[Scan, np.ndarray]:
    """One scan k at recording step ``idx``; fills row k of the truth arrays in ``out``. ``geometry``: the
    lambda-independent part of each scan by k, read if present, else computed and stored (:func:`observe`)."""
    if geometry is not None and k in geometry:
        ego, xy, present, in_fov, visible, obstacles, occ, omega = geometry[k]
    else:
        ego, xy, present, in_fov, visible, obstacles, occ, omega = _scan_geometry(recording, idx, cfg, static, region)
        if geometry is not None:
            geometry[k] = (ego, xy, present, in_fov, visible, obstacles, occ, omega)
    detected = visible & (draws.u_detect[k] < cfg.p_D)

    r, b = range_bearing(xy[detected], ego)
    z_targets = np.column_stack([r, b]) + draws.noise[k, detected]
    z_targets[:, 1] = wrap(z_targets[:, 1])
    Z = np.concatenate([z_targets, draws.clutter[k]]).reshape(-1, 2)
    source = np.concatenate([np.flatnonzero(detected), np.full(len(draws.clutter[k]), CLUTTER)]).astype(np.int64)
    perm = det_rng.permutation(len(Z))

    for name, value in (("truth_xy", xy), ("present", present), ("in_fov", in_fov), ("visible", visible)):
        out[name][k] = value
    out["detected"][k] = detected
    scan = Scan(k, k * float(cfg.dt), ego, Z[perm], obstacles, list(occ), omega)
    return scan, source[perm]


def _scan_geometry(
    recording: Recording,
    idx: int,
    cfg: SensorConfig,
    static: _StaticOccluders,
    region: BaseGeometry,
) -> tuple:
    """The part of a scan that does not depend on the clutter rate: ego pose, truth, FOV and line-of-sight tests,
    obstacles O_k, occluders and Omega_k (§2.3)."""
    ego = np.asarray(recording.ego_pose[idx], dtype=float)
    xy = np.asarray(recording.ped_xy[idx], dtype=float).reshape(-1, 2)
    present = np.asarray(recording.ped_present[idx], dtype=bool) & np.isfinite(xy).all(axis=1)
    xy = np.where(present[:, None], xy, np.nan)
    in_fov = present & fov_mask(xy, ego, cfg)

    vehicles = _vehicle_arrays(recording, idx)
    if len(vehicles):
        veh = shapely.polygons(vehicles)
        geoms = np.concatenate([static.geoms, veh])
        hulls = np.concatenate([static.hulls, oriented_hulls(veh)])
        kinds = np.concatenate([static.kinds, np.full(len(vehicles), "vehicle", dtype="<U8")])
    else:
        geoms, hulls, kinds = static.geoms, static.hulls, static.kinds
    ego_pt = shapely.points(ego[:2])
    near = shapely.dwithin(geoms, ego_pt, cfg.r_max)
    occ, occ_kinds, occ_hulls = geoms[near], kinds[near], hulls[near]

    visible = in_fov.copy()
    visible[in_fov] = target_visibility(ego, xy[in_fov], occ, cfg.visibility_points, cfg.visibility_offset)
    obstacles = obstacles_from_geoms(occ, occ_kinds, ego[:2], cfg.r_max, occ_hulls)
    inside = occ[shapely.intersects(occ_hulls, ego_pt)] if len(occ) else occ  # no cone: cut as is
    omega = VisibleRegion(region, ego, obstacles, cfg, list(inside))  # built only if read
    return ego, xy, present, in_fov, visible, obstacles, occ, omega
