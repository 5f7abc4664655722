"""The data that flows between the stages: plain dataclasses in the bottom layer (DESIGN: "Where the house goes next").

Every stage and every plugin imports these without importing a stage: a scene source (SUMO, KITTI) produces a
:class:`Recording` and :class:`Scans`; a birth model turns a :class:`BirthContext` into :class:`Births` (optionally
with :class:`NewbornTerms`); our GM-PHD filter returns a :class:`StepResult` per scan; any tracker returns
:class:`Estimates` per scan. The public names are re-exported by :mod:`soabench.api`.

This module imports numpy, shapely (for the geometry a scan carries) and :mod:`soabench.errors` only. The ``.npz``
round trips of :class:`Recording` and :class:`Scans` live here with their classes (both formats:
docs/user-guide/outputs.md).
"""

from __future__ import annotations

import dataclasses
import json
import math
import operator
from collections.abc import Callable, Hashable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from soabench.errors import SoabenchError, require

if TYPE_CHECKING:  # soabench.config sits above this module; imported at run time only where a config is built
    from soabench.config import Sensor

CLUTTER = -1  #: source id of a clutter measurement
OCCLUDER_KINDS = ("building", "parked", "vehicle")  #: values of ``Obstacles.kind``
SCANS_FORMAT_VERSION = 1  #: version written by :meth:`Scans.save_npz` (docs/user-guide/outputs.md)


# ----------------------------------------------------------------------------------------------------------------
# Truth: one scenario run


@dataclass
class Recording:
    """Ground truth of one scenario run. T steps, P pedestrians (stable ids), V vehicle slots.

    Attributes:
        t: (T,) simulation time of each step (s).
        step_length: SUMO step (s).
        ego_pose: (T, 3) ego geometric centre x, y (m) and heading theta (rad).
        ego_footprint: (T, 4, 2) ego rectangle corners (m).
        ped_ids: (P,) stable pedestrian ids (str).
        ped_present: (T, P) bool, True while the pedestrian is in the scene (not inside a building).
        ped_xy: (T, P, 2) position (m), NaN while absent.
        ped_speed: (T, P) speed (m/s), NaN while absent.
        ped_heading: (T, P) heading (rad), NaN while absent.
        veh_ids: (V,) ids of the other (non-ego) vehicle slots.
        veh_present: (T, V) bool.
        veh_footprint: (T, V, 4, 2) corners of each other vehicle (m), NaN while absent.
        static_occluders: list of (n_i, 2) polygons (parked cars), constant over time.
        seed: trial seed used for SUMO and the scenario.
        net: network name.
        meta: free-form provenance (SUMO version, pedestrian model, ...).
    """

    t: np.ndarray
    step_length: float
    ego_pose: np.ndarray
    ego_footprint: np.ndarray
    ped_ids: np.ndarray
    ped_present: np.ndarray
    ped_xy: np.ndarray
    ped_speed: np.ndarray
    ped_heading: np.ndarray
    veh_ids: np.ndarray
    veh_present: np.ndarray
    veh_footprint: np.ndarray
    static_occluders: list[np.ndarray]
    seed: int
    net: str
    meta: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        T, P = np.shape(self.ped_present)[:2] if np.ndim(self.ped_present) == 2 else (len(self.t), 0)
        span = f"{float(self.t[0]):g}-{float(self.t[-1]):g} s" if len(self.t) else "empty"
        return (
            f"Recording(net={self.net!r}, seed={self.seed}, {T} steps of {self.step_length:g} s ({span}), "
            f"{P} pedestrians, {len(self.veh_ids)} vehicles, {len(self.static_occluders)} parked cars)"
        )

    def save_npz(self, path: str | Path) -> None:
        """Write the Recording as a compressed .npz (format: docs/user-guide/outputs.md); exact round trip."""
        occ = [np.asarray(o, dtype=float).reshape(-1, 2) for o in self.static_occluders]
        offsets = np.cumsum([0] + [len(o) for o in occ]).astype(np.int64)
        np.savez_compressed(
            Path(path),
            format_version=np.array(RECORDING_FORMAT_VERSION),
            t=np.asarray(self.t, dtype=float),
            step_length=np.array(float(self.step_length)),
            ego_pose=np.asarray(self.ego_pose, dtype=float),
            ego_footprint=np.asarray(self.ego_footprint, dtype=float),
            ped_ids=np.asarray(self.ped_ids, dtype=str),
            ped_present=np.asarray(self.ped_present, dtype=bool),
            ped_xy=np.asarray(self.ped_xy, dtype=float),
            ped_speed=np.asarray(self.ped_speed, dtype=float),
            ped_heading=np.asarray(self.ped_heading, dtype=float),
            veh_ids=np.asarray(self.veh_ids, dtype=str),
            veh_present=np.asarray(self.veh_present, dtype=bool),
            veh_footprint=np.asarray(self.veh_footprint, dtype=float),
            static_occluder_xy=np.concatenate(occ) if occ else np.zeros((0, 2)),
            static_occluder_offsets=offsets,
            seed=np.array(int(self.seed), dtype=np.int64),
            net=np.array(str(self.net)),
            meta_json=np.array(json.dumps(self.meta, sort_keys=True)),
        )

    @classmethod
    def load_npz(cls, path: str | Path) -> Recording:
        """Read a Recording written by :meth:`save_npz`; SoabenchError on a missing or foreign file."""
        p = Path(path)
        require(p.is_file(), f"recording file {str(path)!r} does not exist; give a .npz written by save_npz")
        try:
            with np.load(p, allow_pickle=False) as z:
                d = {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            raise SoabenchError(f"recording file {str(p)!r} is not a readable .npz ({exc})") from None
        require(
            "z_offsets" not in d,
            f"{str(p)!r} is a Scans file (written by Scans.save_npz), not a Recording; read it with "
            "soabench.api.Scans.load_npz",
        )
        missing = sorted(set(_RECORDING_KEYS) - set(d))
        require(not missing, f"recording file {str(p)!r} lacks arrays {missing}; it was not written by save_npz")
        xy, off = d["static_occluder_xy"], d["static_occluder_offsets"]
        return cls(
            t=d["t"],
            step_length=float(d["step_length"]),
            ego_pose=d["ego_pose"],
            ego_footprint=d["ego_footprint"],
            ped_ids=d["ped_ids"],
            ped_present=d["ped_present"],
            ped_xy=d["ped_xy"],
            ped_speed=d["ped_speed"],
            ped_heading=d["ped_heading"],
            veh_ids=d["veh_ids"],
            veh_present=d["veh_present"],
            veh_footprint=d["veh_footprint"],
            static_occluders=[xy[off[i] : off[i + 1]] for i in range(len(off) - 1)],
            seed=int(d["seed"]),
            net=str(d["net"]),
            meta=json.loads(str(d["meta_json"])),
        )


RECORDING_FORMAT_VERSION = 1  #: version written by :meth:`Recording.save_npz`
_RECORDING_KEYS = (
    "t", "step_length", "ego_pose", "ego_footprint", "ped_ids", "ped_present", "ped_xy", "ped_speed", "ped_heading",
    "veh_ids", "veh_present", "veh_footprint", "static_occluder_xy", "static_occluder_offsets", "seed", "net",
    "meta_json",
)  # fmt: skip


# ----------------------------------------------------------------------------------------------------------------
# Scans: what a tracker receives, plus the per-scan truth the metrics need


@dataclass
class Obstacles:
    """Occluders O_k seen from the sensor at one scan (§3.1.1-3.1.2), world frame. N obstacles.

    Attributes:
        polygons: list of N convex (n_i, 2) vertex arrays (convex hull of each occluder).
        kind: (N,) str, "building", "parked", or "vehicle".
        centroid_range: (N,) r'_j (m).
        centroid_bearing: (N,) alpha_c, world-frame direction of the centroid (rad).
        theta_min, theta_max: (N,) world-frame tangent ray directions (rad), wrap-safe (T14).
        r_min, r_max: (N,) tangent-point ranges r^b_min, r^b_max (m).
    Obstacles containing the sensor are left out (T15); only those intersecting the r_max disk are included.
    """

    polygons: list[np.ndarray]
    kind: np.ndarray
    centroid_range: np.ndarray
    centroid_bearing: np.ndarray
    theta_min: np.ndarray
    theta_max: np.ndarray
    r_min: np.ndarray
    r_max: np.ndarray

    def __len__(self) -> int:
        return len(self.polygons)

    @classmethod
    def empty(cls) -> Obstacles:
        """No obstacles."""
        z = np.zeros(0)
        return cls([], np.zeros(0, dtype="<U8"), z, z.copy(), z.copy(), z.copy(), z.copy(), z.copy())


class DeferredRegion:
    """A region computed only when read (docs/method.md §3.1.4): what a :class:`Scan` may hold as its
    ``visible_region`` instead of the geometry itself.

    :meth:`build` returns the geometry; :meth:`contains_xy` answers which points lie in its interior without
    building it (the sensor's Omega_k: birth models ask that of a few dozen points per scan, while the polygon
    overlay behind the geometry costs more than the rest of the scan). The sensor's subclass is
    :class:`soabench.sensor.VisibleRegion`.
    """

    def build(self) -> BaseGeometry:  # pragma: no cover - interface
        raise NotImplementedError

    def contains_xy(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def geometry(self) -> BaseGeometry:
        """:meth:`build`, computed on the first call and kept."""
        built = self.__dict__.get("_built")
        if built is None:
            built = self.__dict__["_built"] = self.build()
        return built


class _RegionField:
    """The ``visible_region`` field of :class:`Scan`: holds a geometry or a :class:`DeferredRegion`, and reads
    as the geometry either way (a deferred one is built on the first read and kept)."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.slot = "_" + name

    def __get__(self, obj: Any, objtype: type | None = None) -> BaseGeometry:
        if obj is None:  # class access: no default value for the dataclass field
            raise AttributeError(self.slot[1:])
        value = obj.__dict__[self.slot]
        return value.geometry() if isinstance(value, DeferredRegion) else value

    def __set__(self, obj: Any, value: BaseGeometry | DeferredRegion) -> None:
        obj.__dict__[self.slot] = value


@dataclass
class Scan:
    """What the filters receive at scan k (never the truth).

    Attributes:
        k: scan index; t: time (s).
        ego: (3,) sensor pose x, y, theta (ego geometric centre, heading).
        Z: (M, 2) measurements (range m, bearing rad relative to the ego heading, wrapped to (-pi, pi]).
        obstacles: O_k.
        occluders: shapely polygons of every occluder at k (buildings, parked cars, other vehicles) for
            line-of-sight tests (the ``occlusion_pd`` option). Exact shapes (not hulls); only those within r_max
            of the sensor, since no segment to a point in the FOV can meet any other.
        visible_region: Omega_k = sidewalk within the FOV minus occluders and their shadows (shapely). It may be
            given as a :class:`DeferredRegion` (the sensor does): it then reads as the geometry, built on the first
            read; :meth:`in_visible_region` tests points without building it.
    """

    k: int
    t: float
    ego: np.ndarray
    Z: np.ndarray
    obstacles: Obstacles
    occluders: list[BaseGeometry]
    visible_region: BaseGeometry = _RegionField()  # type: ignore[assignment]  # no default: see _RegionField

    def __repr__(self) -> str:
        x, y, th = (float(v) for v in np.asarray(self.ego, dtype=float).reshape(3))
        return (
            f"Scan(k={self.k}, t={self.t:g} s, ego=({x:.1f}, {y:.1f}, {th:.2f} rad), {len(self.Z)} measurements, "
            f"{len(self.obstacles)} obstacles, {len(self.occluders)} occluders)"
        )

    def in_visible_region(self, xy: np.ndarray) -> np.ndarray:
        """(J,) True where a point of ``xy`` (J, 2) lies in the interior of Omega_k (``shapely.contains_xy``).

        A deferred region answers without building its geometry (:meth:`DeferredRegion.contains_xy`): the same
        answer as the built polygon's except for points within rounding distance (about 1e-12 m) of its boundary,
        where the overlay's computed vertices and the exact inputs may disagree. Which of the two answers a scan
        gives depends only on how it was made, never on whether its geometry was read before (a copy made with
        ``dataclasses.replace`` holds the built geometry, read through the field)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        value = self.__dict__["_visible_region"]
        if isinstance(value, DeferredRegion):
            return np.asarray(value.contains_xy(xy[:, 0], xy[:, 1]), dtype=bool)
        return shapely.contains_xy(value, xy[:, 0], xy[:, 1])

    # Work done once per scan (docs/method.md §5.8): every filter run of a trial reads the same Scan, so what depends
    # on the scan alone is computed on first use and kept on the instance (not a field: equality, ``replace``, the
    # .npz format and pickles ignore it; an edited ``occluders`` list is indexed anew).

    def occluder_index(self) -> shapely.STRtree:
        """The STRtree of :attr:`occluders`, built on the first call (birth models ask which candidate means lie
        inside an occluder of the scan, :func:`soabench.birth.base.inside_any`)."""
        occ = self.occluders
        hit = self.__dict__.get("_occluder_index")
        if hit is not None and hit[0] is occ and len(hit[1]) == len(occ) and all(map(operator.is_, hit[1], occ)):
            return hit[2]
        snap = tuple(occ)
        tree = shapely.STRtree(list(snap))
        self.__dict__["_occluder_index"] = (occ, snap, tree)
        return tree

    def once(self, key: Hashable, make: Callable[[], Any]) -> Any:
        """``make()`` computed on the first call with ``key`` and kept on the scan (e.g. the filter's input check
        of Z_k and the ego pose, identical for every run over this scan). ``key`` must name every input besides
        the scan that the value depends on. A scan's arrays are read, never written, by every stage: a caller that
        edits them in place after a filter step must build a new Scan (``dataclasses.replace``)."""
        cache = self.__dict__.setdefault("_once", {})
        if key not in cache:
            cache[key] = make()
        return cache[key]

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k not in ("_occluder_index", "_once")}


def scan_once(scan: Any, key: Hashable, make: Callable[[], Any]) -> Any:
    """:meth:`Scan.once` of ``scan``, or ``make()`` now for a scan object that cannot keep it (a duck-typed scan of
    a plugin or a test): what every stage that shares per-scan work across runs calls (docs/method.md §5.8)."""
    once = getattr(scan, "once", None)
    return make() if once is None else once(key, make)


@dataclass
class Scans:
    """K scans plus the per-scan truth needed by the metrics. P pedestrians (same order as the Recording).

    Attributes:
        scans: list of K :class:`Scan` (filter inputs).
        dt: sensor period (s).
        source: list of K (M_k,) int arrays: pedestrian index of each measurement, or CLUTTER (-1).
        truth_xy: (K, P, 2) true positions (NaN while absent).
        present, in_fov, visible, detected: (K, P) bool flags (§5.1, §5.4).
        ped_ids: (P,) pedestrian ids.
        ped_labels: (P,) int64 truth track label of each pedestrian (read-only property, derived from ``ped_ids``
            by :func:`truth_labels`).
        sensor: the :class:`~soabench.config.Sensor` that produced the scans (written into every exported
            file).
    """

    scans: list[Scan]
    dt: float
    source: list[np.ndarray]
    truth_xy: np.ndarray
    present: np.ndarray
    in_fov: np.ndarray
    visible: np.ndarray
    detected: np.ndarray
    ped_ids: np.ndarray
    sensor: Sensor | None = None

    def __post_init__(self) -> None:
        """Checked when built, so a wrong argument fails here with one line naming it, not in the metrics later."""
        _check_scans(self)

    def __len__(self) -> int:
        return len(self.scans)

    @property
    def ped_labels(self) -> np.ndarray:
        """(P,) int64 truth track label of each pedestrian column (docs/method.md §2.13): :func:`truth_labels`."""
        return truth_labels(self.ped_ids)

    def __iter__(self) -> Iterator[Scan]:
        """The scans in order (``for scan in scans: tracker.step(scan)``)."""
        return iter(self.scans)

    def __getitem__(self, k: int) -> Scan:
        """Scan ``k``."""
        return self.scans[k]

    def __repr__(self) -> str:
        K, P = np.shape(self.present)[:2] if np.ndim(self.present) == 2 else (len(self.scans), 0)
        n_z = sum(len(sc.Z) for sc in self.scans)
        n_true = sum(int(np.count_nonzero(np.asarray(s) != CLUTTER)) for s in self.source)
        lam = "" if self.sensor is None else f", lambda_c={self.sensor.lambda_c:g}"
        return (
            f"Scans({K} scans every {self.dt:g} s, {P} pedestrians, {n_z} measurements ({n_true} from targets, "
            f"{n_z - n_true} clutter){lam})"
        )

    def save_npz(self, path: str | Path) -> None:
        """Write the Scans as a compressed .npz without pickles (format: docs/user-guide/outputs.md), with the sensor
        parameters and their units (:func:`sensor_arrays`): a tracker reading the file needs R, p_D and kappa."""
        require(
            self.sensor is not None,
            "these Scans carry no Sensor (Scans.sensor); set it before exporting: the file must say how it "
            "was measured",
        )
        np.savez_compressed(Path(path), **_scans_to_arrays(self), **sensor_arrays(self.sensor))

    @classmethod
    def load_npz(cls, path: str | Path) -> Scans:
        """Read Scans written by :meth:`save_npz`."""
        p = Path(path)
        require(p.is_file(), f"scans file {str(p)!r} does not exist")
        try:
            with np.load(p, allow_pickle=False) as data:
                arrays = {name: data[name] for name in data.files}
        except (OSError, ValueError) as exc:
            raise SoabenchError(f"scans file {str(p)!r} is not a readable .npz ({exc})") from None
        return _scans_from_arrays(arrays, str(p))


def _check_scans(s: Scans) -> None:
    """One line naming the first argument of :class:`Scans` that does not fit: K scans of P pedestrians, every
    per-scan array of length K, every source array as long as its scan's Z, finite truth wherever present."""
    require(s.scans is not None and not isinstance(s.scans, (str, bytes)), "Scans: scans must be a list of Scan")
    K = len(s.scans)
    require(
        isinstance(s.dt, (int, float, np.number)) and np.isfinite(s.dt) and s.dt > 0,
        f"Scans: dt = {s.dt!r}; give the sensor period in seconds, a finite number > 0",
    )
    ids = np.asarray(s.ped_ids)
    require(ids.ndim == 1, f"Scans: ped_ids has shape {ids.shape}; give (P,) pedestrian ids, one per truth column")
    P = len(ids)
    for name in ("present", "in_fov", "visible", "detected"):
        a = np.asarray(getattr(s, name))
        require(
            a.shape == (K, P) and a.dtype == np.bool_,
            f"Scans: {name} has shape {a.shape} and dtype {a.dtype}; give ({K}, {P}) booleans (K = len(scans), "
            "P = len(ped_ids))",
        )
    xy = np.asarray(s.truth_xy)
    require(
        xy.shape == (K, P, 2) and (xy.size == 0 or np.issubdtype(xy.dtype, np.floating)),
        f"Scans: truth_xy has shape {xy.shape} and dtype {xy.dtype}; give ({K}, {P}, 2) float positions "
        "(K = len(scans), P = len(ped_ids))",
    )
    bad = ~np.isfinite(xy).all(axis=2) & np.asarray(s.present)
    if bad.any():
        k, j = (int(v) for v in np.argwhere(bad)[0])
        raise SoabenchError(
            f"Scans: truth_xy[{k}, {j}] is {xy[k, j].tolist()} where present[{k}, {j}] is True; give finite "
            "positions wherever a pedestrian is present (NaN only while absent)"
        )
    require(
        isinstance(s.source, (list, tuple)) and len(s.source) == K,
        f"Scans: source holds {len(s.source) if isinstance(s.source, (list, tuple)) else type(s.source).__name__} "
        f"entries; give a list of {K} arrays, one per scan",
    )
    for k, (scan, src) in enumerate(zip(s.scans, s.source, strict=True)):
        Z = np.asarray(scan.Z)
        require(
            Z.ndim == 2 and Z.shape[1] == 2 and (Z.size == 0 or np.issubdtype(Z.dtype, np.number)),
            f"Scans: scans[{k}].Z has shape {Z.shape} and dtype {Z.dtype}; give (M, 2) range-bearing numbers",
        )
        require(bool(np.isfinite(Z).all()), f"Scans: scans[{k}].Z holds NaN or infinite values; give finite numbers")
        src = np.asarray(src)
        require(
            src.shape == (len(Z),) and (src.size == 0 or np.issubdtype(src.dtype, np.integer)),
            f"Scans: source[{k}] has shape {src.shape} and dtype {src.dtype}; give ({len(Z)},) integers, one per "
            f"measurement of scans[{k}].Z",
        )
        if src.size and not (int(src.min()) >= CLUTTER and int(src.max()) < P):
            raise SoabenchError(
                f"Scans: source[{k}] holds {int(src.min())}..{int(src.max())}; give pedestrian columns 0..{P - 1} "
                f"or CLUTTER ({CLUTTER})"
            )


def _check_offsets(a: dict[str, np.ndarray], name: str, n: int, total: int, where: str) -> None:
    """The (n+1,) offsets array ``name`` of a file: from 0 to ``total``, never decreasing."""
    o = np.asarray(a[name])
    ok = o.shape == (n + 1,) and np.issubdtype(o.dtype, np.integer) and o[0] == 0 and o[-1] == total
    require(
        bool(ok and (np.diff(o) >= 0).all()),
        f"{where}: {name} does not match its arrays (shape {o.shape}; expected {n + 1} non-decreasing offsets from "
        f"0 to {total}); the file is damaged or was not written by Scans.save_npz",
    )


def truth_labels(ped_ids: Sequence[str] | np.ndarray) -> np.ndarray:
    """(P,) int64 truth track labels from pedestrian ids, deterministically (docs/method.md §2.13).

    Ids that are all integers (KITTI's track ids) are those integers; ids that are one common prefix followed by
    distinct integers (SUMO's ``ped0``, ``ped1``, ...) are the integers; any other set of ids is numbered by column,
    0, 1, ... (the columns are in the recording's stable order).
    """
    ids = [str(i) for i in np.asarray(ped_ids).reshape(-1)]
    stems = [i.rstrip("0123456789") for i in ids]
    digits = [i[len(t) :] for i, t in zip(ids, stems, strict=True)]
    if ids and all(digits) and len(set(stems)) == 1:
        nums = [int(d) for d in digits]
        if len(set(nums)) == len(nums) and max(nums) < 2**62:
            return np.array(nums, dtype=np.int64)
    return np.arange(len(ids), dtype=np.int64)


# ----------------------------------------------------------------------------------------------------------------
# .npz round trip (docs/user-guide/outputs.md)


def _offsets(counts: Sequence[int]) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(np.asarray(counts, dtype=np.int64))]).astype(np.int64)


def _wkb_pack(geoms: Sequence[BaseGeometry]) -> tuple[np.ndarray, np.ndarray]:
    """Concatenated WKB bytes (uint8) and (n+1,) byte offsets."""
    blobs = [shapely.to_wkb(g) for g in geoms]
    data = np.frombuffer(b"".join(blobs), dtype=np.uint8) if blobs else np.zeros(0, dtype=np.uint8)
    return data.copy(), _offsets([len(b) for b in blobs])


def _wkb_unpack(data: np.ndarray, offsets: np.ndarray) -> list[BaseGeometry]:
    raw = data.tobytes()
    return [shapely.from_wkb(raw[a:b]) for a, b in zip(offsets[:-1], offsets[1:], strict=True)]


def _scans_to_arrays(scans: Scans) -> dict[str, np.ndarray]:
    s = scans.scans
    obstacles = [sc.obstacles for sc in s]
    all_polys = [p for o in obstacles for p in o.polygons]
    occluders = [g for sc in s for g in sc.occluders]
    occ_wkb, occ_wkb_off = _wkb_pack(occluders)
    reg_wkb, reg_wkb_off = _wkb_pack([sc.visible_region for sc in s])

    def cat(name: str) -> np.ndarray:
        parts = [getattr(o, name) for o in obstacles]
        return np.concatenate(parts).astype(float) if parts else np.zeros(0)

    return {
        "format_version": np.int64(SCANS_FORMAT_VERSION),
        "dt": np.float64(scans.dt),
        "k": np.array([sc.k for sc in s], dtype=np.int64),
        "t": np.array([sc.t for sc in s], dtype=float),
        "ego": np.array([sc.ego for sc in s], dtype=float).reshape(-1, 3),
        "z_offsets": _offsets([len(sc.Z) for sc in s]),
        "Z": np.concatenate([sc.Z for sc in s]).reshape(-1, 2) if s else np.zeros((0, 2)),
        "source": np.concatenate(scans.source).astype(np.int64) if s else np.zeros(0, dtype=np.int64),
        "ped_ids": np.asarray(scans.ped_ids, dtype=str),
        "truth_xy": np.asarray(scans.truth_xy, dtype=float),
        "present": np.asarray(scans.present, dtype=bool),
        "in_fov": np.asarray(scans.in_fov, dtype=bool),
        "visible": np.asarray(scans.visible, dtype=bool),
        "detected": np.asarray(scans.detected, dtype=bool),
        "obst_offsets": _offsets([len(o) for o in obstacles]),
        "obst_kind": np.concatenate([o.kind for o in obstacles]).astype("<U8") if s else np.zeros(0, "<U8"),
        "obst_centroid_range": cat("centroid_range"),
        "obst_centroid_bearing": cat("centroid_bearing"),
        "obst_theta_min": cat("theta_min"),
        "obst_theta_max": cat("theta_max"),
        "obst_r_min": cat("r_min"),
        "obst_r_max": cat("r_max"),
        "obst_vertex_offsets": _offsets([len(p) for p in all_polys]),
        "obst_vertices": np.concatenate(all_polys).reshape(-1, 2) if all_polys else np.zeros((0, 2)),
        "occluder_offsets": _offsets([len(sc.occluders) for sc in s]),
        "occluder_wkb": occ_wkb,
        "occluder_wkb_offsets": occ_wkb_off,
        "region_wkb": reg_wkb,
        "region_wkb_offsets": reg_wkb_off,
    }


#: the arrays of a Scans file (:meth:`Scans.save_npz`)
_SCANS_KEYS = (
    "dt", "k", "t", "ego", "z_offsets", "Z", "source", "ped_ids", "truth_xy", "present", "in_fov", "visible",
    "detected", "obst_offsets", "obst_kind", "obst_centroid_range", "obst_centroid_bearing", "obst_theta_min",
    "obst_theta_max", "obst_r_min", "obst_r_max", "obst_vertex_offsets", "obst_vertices", "occluder_offsets",
    "occluder_wkb", "occluder_wkb_offsets", "region_wkb", "region_wkb_offsets",
)  # fmt: skip


def _scans_from_arrays(a: dict[str, np.ndarray], where: str) -> Scans:
    require(
        not set(_RECORDING_KEYS) <= set(a),
        f"{where} is a Recording file (the truth, written by Recording.save_npz), not Scans; read it with "
        "soabench.api.Recording.load_npz",
    )
    missing = sorted(set(_SCANS_KEYS) - set(a))
    require(
        "format_version" in a and int(a["format_version"]) == SCANS_FORMAT_VERSION and not missing,
        f"{where} is not a soabench Scans file of format version {SCANS_FORMAT_VERSION}"
        + (f" (it lacks {', '.join(missing[:4])}{', ...' if len(missing) > 4 else ''})" if missing else "")
        + "; give a .npz written by Scans.save_npz or soabench export scans",
    )
    K = len(a["k"])
    for name, n, total in (
        ("z_offsets", K, len(a["Z"])),
        ("obst_offsets", K, len(a["obst_kind"])),
        ("obst_vertex_offsets", len(a["obst_kind"]), len(a["obst_vertices"])),
        ("occluder_offsets", K, len(a["occluder_wkb_offsets"]) - 1),
        ("occluder_wkb_offsets", len(a["occluder_wkb_offsets"]) - 1, len(a["occluder_wkb"])),
        ("region_wkb_offsets", K, len(a["region_wkb"])),
    ):
        _check_offsets(a, name, n, total, where)
    require(
        len(a["source"]) == len(a["Z"]) and len(a["t"]) == K and np.shape(a["ego"]) == (K, 3),
        f"{where}: source, t or ego do not match Z and k (lengths {len(a['source'])}/{len(a['Z'])}, "
        f"{len(a['t'])}/{K}, ego {np.shape(a['ego'])}); the file is damaged or was not written by Scans.save_npz",
    )
    zo, oo, vo, co = a["z_offsets"], a["obst_offsets"], a["obst_vertex_offsets"], a["occluder_offsets"]
    verts = [a["obst_vertices"][p:q] for p, q in zip(vo[:-1], vo[1:], strict=True)]
    occluders = _wkb_unpack(a["occluder_wkb"], a["occluder_wkb_offsets"])
    regions = _wkb_unpack(a["region_wkb"], a["region_wkb_offsets"])
    scans, sources = [], []
    for i in range(len(a["k"])):
        sl = slice(oo[i], oo[i + 1])
        obstacles = Obstacles(
            polygons=verts[sl],
            kind=a["obst_kind"][sl],
            centroid_range=a["obst_centroid_range"][sl],
            centroid_bearing=a["obst_centroid_bearing"][sl],
            theta_min=a["obst_theta_min"][sl],
            theta_max=a["obst_theta_max"][sl],
            r_min=a["obst_r_min"][sl],
            r_max=a["obst_r_max"][sl],
        )
        z_sl = slice(zo[i], zo[i + 1])
        scan = Scan(
            int(a["k"][i]),
            float(a["t"][i]),
            a["ego"][i],
            a["Z"][z_sl],
            obstacles,
            occluders[co[i] : co[i + 1]],
            regions[i],
        )
        scans.append(scan)
        sources.append(a["source"][z_sl])
    sensor = _sensor_from_arrays(a, where)
    try:
        return Scans(
            scans=scans,
            dt=float(a["dt"]),
            source=sources,
            truth_xy=a["truth_xy"],
            present=a["present"],
            in_fov=a["in_fov"],
            visible=a["visible"],
            detected=a["detected"],
            ped_ids=a["ped_ids"],
            sensor=sensor,
        )
    except SoabenchError as exc:
        raise SoabenchError(f"{where}: {exc}") from None


#: unit of each sensor parameter written into a scans file (docs/user-guide/outputs.md)
SENSOR_UNITS: dict[str, str] = {
    "dt": "s",
    "sigma_r": "m",
    "sigma_b": "rad",
    "p_D": "1",
    "lambda_c": "1/scan",
    "r_min": "m",
    "r_max": "m",
    "fov": "rad",
}


def sensor_arrays(cfg: Sensor) -> dict[str, np.ndarray]:
    """The sensor parameters of a scans file: one float64 scalar per parameter in SI units and radians
    (``sigma_r``, ``sigma_b``, ``p_D``, ``lambda_c``, ``r_min``, ``r_max``, ``fov``; ``dt`` is written with the
    scans) and ``sensor_json``: every :class:`Sensor` field as configured (degrees where the config uses them)
    plus the units of the scalars."""
    values = {
        "sigma_r": cfg.sigma_r,
        "sigma_b": cfg.sigma_b,
        "p_D": cfg.p_D,
        "lambda_c": cfg.lambda_c,
        "r_min": cfg.r_min,
        "r_max": cfg.r_max,
        "fov": cfg.fov,
    }
    meta = {"config": dataclasses.asdict(cfg), "units": SENSOR_UNITS}
    out = {k: np.float64(v) for k, v in values.items()}
    out["sensor_json"] = np.array(json.dumps(meta, sort_keys=True))
    return out


def _sensor_from_arrays(a: dict[str, np.ndarray], where: str) -> Sensor | None:
    from soabench.config import Sensor  # run time only: soabench.config sits above this bottom module

    if "sensor_json" not in a:
        return None
    try:
        return Sensor(**json.loads(str(a["sensor_json"]))["config"])
    except (ValueError, TypeError, KeyError) as exc:
        raise SoabenchError(f"{where}: sensor_json is not a soabench sensor configuration ({exc})") from None


# ----------------------------------------------------------------------------------------------------------------
# Births: what a birth model hands the GM-PHD filter (docs/method.md §2.11, §3.0)

# source codes of birth components (Births.source), for figures and diagnostics
SOURCE_OCCL, SOURCE_SEM, SOURCE_FOV, SOURCE_GRID, SOURCE_GM, SOURCE_MEAS = range(6)
SOURCE_NAMES = ("occl", "sem", "fov", "grid", "gm", "meas")


@dataclass
class NewbornTerms:
    """Measurement-driven newborn terms of scan k, one per measurement, in Z_k order (§3.2, §3.4).

    Attributes:
        m: (M, 4) newborn means (inverse measurement, zero velocity).
        P: (M, 4, 4) newborn covariances blkdiag(J R J^T, sigma_v^2 I).
        beta: callable ``beta(A, kappa) -> (M,)``: the additive term beta_l of each normaliser
            L_l = kappa_l + A_l + beta_l, given the persistent support A_l = sum_j p_D,j w_j q_jl and the clutter
            intensity kappa_l. The newborn posterior weight is beta_l / L_l, its mean/cov (m_l, P_l), and it gets
            no missed-detection term.
    """

    m: np.ndarray
    P: np.ndarray
    beta: Callable[[np.ndarray, np.ndarray], np.ndarray]
    #: True when beta allocates an expected number of births over the measurements (ATBM, §3.4): a labelled filter
    #: then gives the terms Reuter's adaptive birth; False (a birth intensity's terms, PUBM's §3.2) weighs each by
    #: beta / (kappa + beta) (docs/method.md "LMB filter", birth). The GM-PHD reads beta alone either way.
    adaptive: bool = False


@dataclass
class Births:
    """Birth of one scan: appended Gaussian components (J of them, J may be 0) and optional newborn terms."""

    w: np.ndarray  #: (J,) weights
    m: np.ndarray  #: (J, 4) means [p_x, p_y, v_x, v_y]
    P: np.ndarray  #: (J, 4, 4) covariances
    source: np.ndarray  #: (J,) int source codes (SOURCE_*)
    newborn: NewbornTerms | None = None

    def __repr__(self) -> str:
        n_new = 0 if self.newborn is None else len(self.newborn.m)
        return f"Births({len(self.w)} components of total weight {float(np.sum(self.w)):.3g}, {n_new} newborn terms)"

    @classmethod
    def empty(cls) -> Births:
        return cls(np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4, 4)), np.zeros(0, dtype=np.int8))

    def __len__(self) -> int:
        return len(self.w)


@dataclass
class BirthContext:
    """What a birth model may look at when scan k arrives (time alignment: everything is at k, §2.12 item 10)."""

    scan: Scan  #: ego pose, Z_k, obstacles O_k, occluders, visible semantic region at k
    prev: StepResult | None  #: the filter's result at k-1 (None at k = 0); ATBM prev-scan reads it
    p_D_b: float = 0.98  #: detection probability of a newborn (filter p_D; Beta prior mean in dynamic mode)


# ----------------------------------------------------------------------------------------------------------------
# What a tracker returns per scan


@dataclass
class Estimates:
    """What any tracker returns at scan k: its estimated target states and, optionally, cost figures.

    Attributes:
        X: (n, 2) positions [p_x, p_y] or (n, 4) states [p_x, p_y, v_x, v_y], world frame (m, m/s); n may be 0.
            The metrics read the positions only. One row per estimated target (repeat a row for two targets).
        w: optional (n,) non-negative confidence of each estimate (a PHD weight, a track score); stored with
            ``--save-estimates``, never used by the metrics.
        n_components: optional cost figure: hypotheses, components or tracks kept after the step. Without it the
            harness reports the number of estimates.
        cardinality: optional expected number of targets (a PHD's sum of weights); without it NaN.
        labels: optional (n,) int64 track label of each estimate (docs/method.md §2.13; the LMB filter labels its
            estimates too): equal labels across scans mean the same track. None: the tracker does not label its
            estimates (scored by position only).
    """

    X: np.ndarray
    w: np.ndarray | None = None
    n_components: int | None = None
    cardinality: float | None = None
    labels: np.ndarray | None = None

    def __post_init__(self) -> None:
        """Checked when built, so a wrong argument fails here with one line naming it, not scans later."""
        X = np.asarray(self.X)
        require(
            X.ndim == 2 and X.shape[1] in (2, 4) and (X.size == 0 or np.issubdtype(X.dtype, np.number)),
            f"Estimates: X has shape {X.shape} and dtype {X.dtype}; give (n, 2) positions or (n, 4) states "
            "[x, y, vx, vy] as numbers (np.zeros((0, 4)) for no target)",
        )
        n = len(X)
        if self.w is not None:
            w = np.asarray(self.w)
            require(
                w.shape == (n,) and (n == 0 or np.issubdtype(w.dtype, np.number)),
                f"Estimates: w has shape {w.shape}; give ({n},) numbers, one weight per row of X, or None",
            )
        if self.labels is not None:
            lab = np.asarray(self.labels)
            integer = np.issubdtype(lab.dtype, np.integer) and not np.issubdtype(lab.dtype, np.bool_)
            require(
                lab.shape == (n,) and (n == 0 or integer),
                f"Estimates: labels has shape {lab.shape} and dtype {lab.dtype}; give ({n},) integer track labels "
                "(np.int64), one per row of X, or None",
            )

    @classmethod
    def empty(cls) -> Estimates:
        """No target at this scan."""
        return cls(np.zeros((0, 4)))

    def __repr__(self) -> str:
        X = np.asarray(self.X)
        extra = "".join(
            f", {name}={value!r}"
            for name, value in (("n_components", self.n_components), ("cardinality", self.cardinality))
            if value is not None
        )
        w = "" if self.w is None else ", with weights"
        lab = "" if self.labels is None else ", labelled"
        return f"Estimates({len(X)} targets, X of shape {X.shape}{w}{lab}{extra})"

    def __len__(self) -> int:
        return len(self.X)


@dataclass
class StepResult:
    """Output and diagnostics of one GM-PHD filter cycle at scan k (§2.10, §5.7): a richer :class:`Estimates`.

    Attributes:
        k: scan index.
        X: (n, 4) extracted states, with multiplicity (floor(w + 0.5) copies).
        X_w: (n,) weight of the component each estimate came from.
        sum_w: posterior mass N_k|k after the update (before reduction).
        sum_w_reduced: mass after prune/merge/cap.
        n_predicted: components after prediction and birth (plus newborn terms, if any).
        n_updated: components after the update.
        n_reduced: components after prune/merge/cap (the paper's "posterior components").
        cap_hit: J_max was hit.
        t_predict, t_update, t_reduce: wall time of each stage (s).
        mean_pD: weight-averaged p_D estimate (dynamic mode; p_D otherwise).
        A: (M,) persistent support of each measurement, sum_j p_D,j w_j q_jl.
        kappa: (M,) clutter intensity of each measurement.
    """

    k: int
    X: np.ndarray
    X_w: np.ndarray
    sum_w: float
    sum_w_reduced: float
    n_predicted: int
    n_updated: int
    n_reduced: int
    cap_hit: bool
    t_predict: float
    t_update: float
    t_reduce: float
    mean_pD: float
    A: np.ndarray
    kappa: np.ndarray
    n_pruned: int = 0  #: components after pruning (before merging)
    n_merged: int = 0  #: components after merging (before the cap)
    n_pairs: int = 0  #: detection (j, l) pairs built in the update (q > 0)
    n_newborn: int = 0  #: measurement-driven newborn components built in the update
    n_dropped: int = 0  #: non-finite measurements dropped (``filter.nonfinite = "drop"``; all if the pose was)
    n_dropped_births: int = 0  #: birth components dropped for a non-finite or negative value
    #: posterior components (after reduction) by birth origin and age, in the order of
    #: :data:`soabench.origins.ORIGIN_KEYS` (docs/method.md §5.7); None: origins unknown (a foreign tracker)
    origin_counts: np.ndarray | None = None
    #: (n,) int64 track label of each row of X (docs/method.md §2.13, and the LMB filter); None: an unlabelled tracker
    labels: np.ndarray | None = None

    def __repr__(self) -> str:
        return f"StepResult(k={self.k}, {len(self.X)} estimates, mass {self.sum_w:.3g}, {self.n_reduced} components)"


#: the metrics of an atlas's phase diagrams (docs/method.md §5.10), column -> label; each is oriented so that a
#: positive advantage means S-OA is better
ATLAS_METRICS = {
    "delay_win": "delay win share",
    "card_red": "cardinality-error reduction (%)",
    "ospa_red": "OSPA reduction (%)",
    "dhota": "ΔHOTA",
}
#: each metric's value at no advantage
ATLAS_NULL = {"delay_win": 0.5, "card_red": 0.0, "ospa_red": 0.0, "dhota": 0.0}


@dataclass
class AtlasCell:
    """One cell of an atlas (one value of one axis, or a value pair of two; docs/method.md §5.10) for one metric and
    baseline: the estimate, its 95 % interval, its p-value and the FDR decision."""

    metric: str
    baseline: str
    mode: str
    family: str
    axes: tuple[str, ...]
    values: tuple
    n: int
    estimate: float
    low: float
    high: float
    p: float
    significant: bool = False
    adj_low: float = math.nan
    adj_high: float = math.nan

    def as_row(self) -> dict:
        d = {
            "metric": self.metric,
            "baseline": self.baseline,
            "mode": self.mode,
            "family": self.family,
            "axis_x": self.axes[0],
            "x": self.values[0],
            "axis_y": self.axes[1] if len(self.axes) > 1 else "",
            "y": self.values[1] if len(self.axes) > 1 else None,
        }
        d.update(
            n_trials=self.n, estimate=self.estimate, ci_low=self.low, ci_high=self.high, p=self.p,
            significant=self.significant, fcr_low=self.adj_low, fcr_high=self.adj_high,
        )  # fmt: skip
        return d
