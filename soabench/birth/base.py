"""The shared birth builder and FOV rule (docs/method.md §3.0).

The data classes (:class:`~soabench.types.Births`, :class:`~soabench.types.NewbornTerms`,
:class:`~soabench.types.BirthContext`) live in :mod:`soabench.types` and the :class:`~soabench.protocols.BirthModel`
protocol in :mod:`soabench.protocols` (both public through :mod:`soabench.api`).

A birth model is built once per trial, ``Model(cfg, sensor, scene, rng)``, and called once per scan with a
:class:`BirthContext`. It returns :class:`Births`: Gaussian components appended to the predicted intensity before
the update (S-OA, UBM, GMBM, ATBM prev-scan), and/or measurement-driven newborn terms that the update handles
inside each measurement's normaliser with no missed-detection term (PUBM, ATBM same-scan).
"""

from __future__ import annotations

import weakref
from collections import OrderedDict
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import shapely
from shapely import STRtree
from shapely.geometry.base import BaseGeometry

from soabench.geometry import fov_mask
from soabench.types import (
    Births,
)

if TYPE_CHECKING:
    from soabench.config import BirthConfig, SensorConfig
    from soabench.scenario.scene import SceneMap
    from soabench.types import Scan

# ---------------------------------------------------------------------------------------------------------------------
# Shared builder and FOV-only rule (docs/method.md §3.0). Everything below is array code over all candidate means.
# ---------------------------------------------------------------------------------------------------------------------


def build_components(
    p: np.ndarray, P_p: np.ndarray, sigma_v: float, v: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Birth components from position means and covariances (§3.0, register row 26).

    ``m = [p; v]`` (``v`` = 0 unless given) and ``P = blkdiag(P_p, sigma_v^2 I_2)``: position and velocity get
    separate blocks instead of the paper's sigma^2 I over the whole state.

    Args:
        p: (J, 2) position means.
        P_p: (J, 2, 2) position covariances, or one (2, 2) covariance shared by all J.
        sigma_v: velocity prior std per axis (m/s).
        v: optional (J, 2) velocity means.

    Returns:
        ``(m, P)`` with shapes (J, 4) and (J, 4, 4).

    Example:
        >>> import numpy as np
        >>> from soabench.api import build_components
        >>> m, P = build_components(np.array([[1.0, 2.0]]), np.eye(2), sigma_v=0.5)
        >>> m.tolist(), P[0].diagonal().tolist()
        ([[1.0, 2.0, 0.0, 0.0]], [1.0, 1.0, 0.25, 0.25])
    """
    p = np.asarray(p, dtype=float).reshape(-1, 2)
    J = len(p)
    m = np.zeros((J, 4))
    m[:, :2] = p
    if v is not None:
        m[:, 2:] = np.asarray(v, dtype=float).reshape(-1, 2)
    P = np.zeros((J, 4, 4))
    P[:, :2, :2] = P_p
    P[:, 2, 2] = P[:, 3, 3] = sigma_v**2
    return m, P


def births_from(
    p: np.ndarray, P_p: np.ndarray, w: np.ndarray, source: np.ndarray, sigma_v: float, v: np.ndarray | None = None
) -> Births:
    """:class:`Births` of J appended components built with :func:`build_components`.

    Example:
        >>> import numpy as np
        >>> from soabench.api import SOURCE_OCCL, births_from, isotropic
        >>> b = births_from(np.array([[1.0, 2.0], [3.0, 4.0]]), isotropic(1.0, 2), w=[0.1, 0.1],
        ...                 source=[SOURCE_OCCL, SOURCE_OCCL], sigma_v=0.5)
        >>> b.m.shape, b.w.tolist()
        ((2, 4), [0.1, 0.1])
    """
    m, P = build_components(p, P_p, sigma_v, v)
    return Births(np.asarray(w, dtype=float).reshape(-1), m, P, np.asarray(source, dtype=np.int8).reshape(-1))


def isotropic(sigma: float | np.ndarray, n: int) -> np.ndarray:
    """(n, 2, 2) covariances sigma^2 I_2 (``sigma`` scalar or (n,)).

    Example:
        >>> from soabench.api import isotropic
        >>> isotropic(2.0, 3)[0].tolist()
        [[4.0, 0.0], [0.0, 4.0]]
    """
    s2 = np.broadcast_to(np.asarray(sigma, dtype=float) ** 2, (n,))
    return s2[:, None, None] * np.eye(2)[None]


_TREES: OrderedDict[int, tuple[Sequence[BaseGeometry], tuple[BaseGeometry, ...], STRtree]] = OrderedDict()
_N_TREES = 256  #: geometry lists kept indexed (least recently used dropped first)


def geometry_index(geoms: Sequence[BaseGeometry]) -> STRtree:
    """The STRtree of ``geoms``, built once per geometry list and reused while the list holds the same objects.

    A trial runs its 15 filters (birth model x probability mode) one after the other over the same scans, and each
    birth model asks which candidate means lie inside ``scan.occluders``; the tree of a scan's occluders is built
    on the first of those calls only. The cache keeps the ``_N_TREES`` most recently used lists (a trial's scans at
    one clutter rate fit); each entry holds a strong reference to its list, so the identity used as key cannot be
    reused, and a snapshot of the member objects, compared by identity on every hit, so an edited list is indexed
    anew.
    """
    hit = _TREES.get(id(geoms))
    if hit is not None:
        lst, snap, tree = hit
        if lst is geoms and len(snap) == len(geoms) and all(a is b for a, b in zip(snap, geoms, strict=True)):
            _TREES.move_to_end(id(geoms))
            return tree
    snap = tuple(geoms)
    tree = STRtree(list(snap))
    _TREES[id(geoms)] = (geoms, snap, tree)
    _TREES.move_to_end(id(geoms))
    while len(_TREES) > _N_TREES:
        _TREES.popitem(last=False)
    return tree


def inside_any(geoms: Sequence[BaseGeometry] | STRtree | None, xy: np.ndarray) -> np.ndarray:
    """(J,) True where a point of ``xy`` (J, 2) lies in the interior of any geometry.

    The tree of a geometry list is built once (:func:`geometry_index`). Candidate (point, geometry) pairs are those
    whose point lies in the geometry's bounding box (:func:`_box_pairs`); each pair is then decided by
    ``shapely.contains_xy`` on the prepared geometry, the predicate of a tree query with ``predicate="within"``
    without building a Point per candidate mean."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    out = np.zeros(len(xy), dtype=bool)
    if geoms is None or len(xy) == 0:
        return out
    if not isinstance(geoms, STRtree) and len(geoms) == 0:
        return out
    tree = geoms if isinstance(geoms, STRtree) else geometry_index(geoms)
    if len(tree.geometries) == 0:
        return out
    i, j, members = _box_pairs(tree, xy)
    if len(i):
        out[i[shapely.contains_xy(members[j], xy[i, 0], xy[i, 1])]] = True
    return out


#: per tree: its geometries (prepared) and their bounding boxes (G, 4), kept while the tree lives
_BOXES: weakref.WeakKeyDictionary[STRtree, tuple[np.ndarray, np.ndarray]] = weakref.WeakKeyDictionary()
_BOX_BRUTE = 200_000  #: up to this many (point, geometry) pairs the boxes are tested with numpy, beyond in the tree


def _box_pairs(tree: STRtree, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(i, j, geometries): the pairs of point i of ``xy`` and geometry j of ``tree`` with the point in the
    geometry's closed bounding box, in point-major order for the numpy test, in the tree's order otherwise."""
    hit = _BOXES.get(tree)
    if hit is None:
        members = np.asarray(tree.geometries, dtype=object)
        shapely.prepare(members)
        hit = _BOXES[tree] = (members, shapely.bounds(members))
    members, bounds = hit
    if len(xy) * len(members) > _BOX_BRUTE:
        i, j = tree.query(shapely.points(xy))
        return i, j, members
    x, y = xy[:, :1], xy[:, 1:]
    inbox = (x >= bounds[:, 0]) & (x <= bounds[:, 2]) & (y >= bounds[:, 1]) & (y <= bounds[:, 3])
    i, j = np.nonzero(inbox)
    return i, j, members


class FOVRule:
    """The FOV-only rule of §3.0 (pitfall 7 of §2.12): which candidate birth means may be instantiated at scan k.

    A mean passes if it is in FOV_k inset by ``delta_in`` from the range limits (:func:`soabench.geometry.fov_mask`),
    inside the workspace (closed world box), and not inside a building, a static occluder (both fixed per scene,
    indexed once) or any occluder of the scan (``scan.occluders``).
    """

    def __init__(self, cfg: BirthConfig, sensor: SensorConfig, scene: SceneMap) -> None:
        self.sensor = sensor
        self.delta_in = float(cfg.delta_in)
        self.box = np.asarray(scene.bounds, dtype=float)
        self.static_tree = STRtree(list(scene.buildings) + list(scene.static_occluders))

    def in_workspace(self, xy: np.ndarray) -> np.ndarray:
        """(J,) inside the closed world box."""
        x0, y0, x1, y1 = self.box
        return (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)

    def in_static(self, xy: np.ndarray) -> np.ndarray:
        """(J,) inside a building or static occluder of the scene."""
        return inside_any(self.static_tree, xy)

    @staticmethod
    def occluder_index(scan: Scan) -> STRtree:
        """The STRtree of ``scan.occluders``: the scan's own (built once per scan), or the LRU's for a duck-typed
        scan without :meth:`soabench.types.Scan.occluder_index`."""
        index = getattr(scan, "occluder_index", None)
        return index() if index is not None else geometry_index(scan.occluders)

    def in_occluder(self, xy: np.ndarray, scan: Scan) -> np.ndarray:
        """(J,) inside an occluder of scan k (vehicles, parked cars, buildings as the sensor lists them); the
        scan's occluder index is built once per scan and carried on it (:meth:`soabench.types.Scan.occluder_index`)."""
        if len(xy) == 0 or not scan.occluders:
            return inside_any(scan.occluders, xy)
        return inside_any(self.occluder_index(scan), xy)

    def in_fov(self, xy: np.ndarray, scan: Scan) -> np.ndarray:
        """(J,) in FOV_k inset by delta_in."""
        return fov_mask(xy, scan.ego, self.sensor, inset=self.delta_in)

    def mask(self, xy: np.ndarray, scan: Scan, static_ok: np.ndarray | None = None) -> np.ndarray:
        """(J,) the full rule. ``static_ok`` may carry a precomputed workspace-and-not-in-building mask."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        ok = self.in_fov(xy, scan)
        if static_ok is None:
            ok &= self.in_workspace(xy)
            ok[ok] &= ~self.in_static(xy[ok])
        else:
            ok &= static_ok
        ok[ok] &= ~self.in_occluder(xy[ok], scan)
        return ok

    def static_mask(self, xy: np.ndarray) -> np.ndarray:
        """(J,) the time-invariant part of the rule, for point sets fixed per trial (grid, Poisson-disk, GMBM)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        ok = self.in_workspace(xy)
        ok[ok] &= ~self.in_static(xy[ok])
        return ok
