"""S-OA's semantic region from segmented LiDAR scans (docs/method.md §3.1.4, "The semantic region from a point
cloud"; docs/user-guide/kitti.md, "From a KITTI download and a segmentation network").

Inputs, per sequence ``XXXX`` and frame ``NNNNNN``:

* ``VELODYNE/XXXX/NNNNNN.bin``: the KITTI scan, float32 rows (x, y, z, intensity) in the Velodyne (ego) frame;
* ``LABELS/XXXX/NNNNNN.label``: one uint32 per point in the SemanticKITTI format, the lower 16 bits the class id
  (:data:`SEMANTIC_KITTI_IDS`), the upper 16 bits an instance id (ignored).

Per frame and configured class (``kitti.semantic_classes``: birth region, ``kitti.occluder_classes``: occluders), the
bird's-eye points of that class within r_max and near the sensor's sector, with the ground between consecutive
returns of the class along a scan sector (gap fill, ``fill`` m at most), are rasterised on a grid of ``grid`` m
cells aligned with the ego frame; the occupancy is closed morphologically with a disc of radius ``closing`` m (it
fills the gaps between beams and azimuths), and the outline of the occupied cells is traced along the cell edges
(the union of the cells exactly), simplified within half a cell and cut into hole-free pieces: the same
``(class, vertices)`` rows a ``--semantics`` file gives. The loops over points and cells are compiled
(:mod:`soabench.kitti.lidar_raster`).

The regions of a sequence are cached in ``RUN/lidar/XXXX.npz`` with a key made of the input files' names, sizes and
modification times and the parameters, so a resumed or repeated run reads them back instead of rebuilding them.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import zipfile
from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import Polygon

from soabench.config import SensorConfig
from soabench.errors import require
from soabench.kitti.config import KittiConfig
from soabench.kitti.formats import ReadError
from soabench.kitti.lidar_raster import closed_raster, frame_cells, ring_polygons
from soabench.kitti.reader import KittiSequence, sensor_for
from soabench.kitti.velodyne import hole_free
from soabench.notice import first_use_notice

#: SemanticKITTI class ids (lower 16 bits of a .label value) by class name, as in the dataset's semantic-kitti.yaml
SEMANTIC_KITTI_IDS: dict[str, tuple[int, ...]] = {
    "unlabeled": (0,), "outlier": (1,), "car": (10, 252), "bicycle": (11,), "bus": (13, 257), "motorcycle": (15,),
    "on-rails": (16, 256), "truck": (18, 258), "other-vehicle": (20, 259), "person": (30, 254),
    "bicyclist": (31, 253), "motorcyclist": (32, 255), "road": (40,), "parking": (44,), "sidewalk": (48,),
    "other-ground": (49,), "building": (50,), "fence": (51,), "other-structure": (52,), "lane-marking": (60,),
    "vegetation": (70,), "trunk": (71,), "terrain": (72,), "pole": (80,), "traffic-sign": (81,),
    "other-object": (99,),
}  # fmt: skip
POINT_BYTES = 16  #: float32 x, y, z, intensity
CACHE_DIR = "lidar"
CACHE_FORMAT = "soabench-lidar-regions-2"
FOV_MARGIN_DEG = 5.0  #: points this far outside the sensor's sector still shape the region at its edges


@dataclass(frozen=True)
class LidarParams:
    """Region building parameters (docs/method.md §3.1.4)."""

    grid: float = 0.5  #: raster cell size (m)
    closing: float = 1.0  #: radius (m) of the disc of the morphological closing (0: none)
    fill: float = 8.0  #: longest gap (m) filled between consecutive returns of a class along a 1-deg sector (0: none)
    sector_deg: float = 1.0  #: azimuth sector (deg) of the gap fill

    def validate(self) -> LidarParams:
        require(0.05 <= self.grid <= 5.0, f"--lidar-grid {self.grid!r} must be in [0.05, 5] m")
        require(0.0 <= self.closing <= 10.0, f"--lidar-closing {self.closing!r} must be in [0, 10] m")
        require(0.0 <= self.fill <= 50.0, f"--lidar-fill {self.fill!r} must be in [0, 50] m")
        require(0.0 < self.sector_deg <= 10.0, f"lidar sector {self.sector_deg!r} must be in (0, 10] deg")
        return self


def class_ids(names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The SemanticKITTI ids of each configured class name; one line naming the allowed names otherwise."""
    bad = [n for n in names if n not in SEMANTIC_KITTI_IDS]
    require(
        not bad,
        f"semantic class(es) {', '.join(map(repr, bad))} have no SemanticKITTI id; allowed: "
        + ", ".join(SEMANTIC_KITTI_IDS),
    )
    return {n: np.asarray(SEMANTIC_KITTI_IDS[n], dtype=np.uint32) for n in names}


# ---------------------------------------------------------------------------------------------------------------------
# files


def frame_files(velodyne: Path, labels: Path, seq: str, n_frames: int) -> list[tuple[Path, Path, int]]:
    """``(scan, labels, n_points)`` of frames 0 .. n_frames-1, checked: both files exist, the scan is whole float32
    rows of 4 values and the label file holds one uint32 per point (:class:`ReadError` naming the file otherwise)."""
    out = []
    for d in (velodyne / seq, labels / seq):
        if not d.is_dir():
            raise ReadError(f"{d} is not a folder: sequence {seq} needs one file per frame there (NNNNNN.bin/.label)")
    for k in range(n_frames):
        scan, lab = velodyne / seq / f"{k:06d}.bin", labels / seq / f"{k:06d}.label"
        for p in (scan, lab):
            if not p.is_file():
                raise ReadError(f"{p} is missing: sequence {seq} has frames 0-{n_frames - 1} and each needs one")
        size = scan.stat().st_size
        if size % POINT_BYTES:
            raise ReadError(f"{scan}: {size} bytes is not a whole number of points (float32 x y z intensity, 16 bytes)")
        n = size // POINT_BYTES
        n_lab = lab.stat().st_size
        if n_lab != 4 * n:
            raise ReadError(f"{lab}: {n_lab} bytes = {n_lab / 4:g} labels, but {scan} has {n} points (one uint32 each)")
        out.append((scan, lab, n))
    return out


def read_frame(scan: Path, labels: Path) -> tuple[np.ndarray, np.ndarray]:
    """(N, 4) float32 points and (N,) uint32 class ids (lower 16 bits) of one frame; :class:`ReadError` naming the
    scan if a point's x, y or z is NaN or infinite (it would land in no cell, or in a wrong one)."""
    pts = np.fromfile(scan, dtype="<f4").reshape(-1, 4)
    bad = int(np.count_nonzero(~np.isfinite(pts[:, :3]).all(axis=1)))
    if bad:
        raise ReadError(
            f"{scan}: {bad} of {len(pts)} points have a NaN or infinite coordinate; a scan holds finite float32 "
            "x y z intensity"
        )
    lab = np.fromfile(labels, dtype="<u4") & np.uint32(0xFFFF)
    return pts, lab


# ---------------------------------------------------------------------------------------------------------------------
# points -> polygons


def _label_lut(ids: dict[str, np.ndarray]) -> np.ndarray:
    """Configured class index (0, 1, ... in the order of ``ids``; -1: none) of every 16-bit SemanticKITTI id."""
    lut = np.full(1 << 16, -1, dtype=np.int64)
    for c, cid in enumerate(ids.values()):
        lut[cid] = c
    return lut


def _polygons(occ: np.ndarray, i0: int, j0: int, grid: float) -> list[np.ndarray]:
    """The occupied cells of a raster whose cell (0, 0) is the ego frame's cell (i0, j0), as the (n, 2) vertices of
    hole-free polygons: each 4-connected set of cells is bounded by its traced outline (staircase corners only) and
    its holes, every ring simplified within half a cell (Douglas-Peucker from the ring's lowest vertex, as
    ``shapely.simplify`` does the outline of the union of the cells; :func:`.lidar_raster.ring_polygons`); a set
    with holes is cut into hole-free pieces, and the rare polygon the simplification leaves invalid (rings
    touching where cells meet at a corner) is made valid first."""
    xy, off, xy_h, off_h, comp_h, shell_h = ring_polygons(occ, i0, j0, grid, 0.5 * grid)
    plain = shapely.from_ragged_array(shapely.GeometryType.POLYGON, xy, (off, np.arange(len(off))))
    valid = shapely.is_valid(plain)
    out = [xy[a : b - 1] for a, b, ok in zip(off[:-1], off[1:], valid, strict=True) if ok]
    rest = list(shapely.make_valid(plain[~valid])) if not valid.all() else []
    rings = [xy_h[a:b] for a, b in zip(off_h[:-1], off_h[1:], strict=True)]
    for c in np.unique(comp_h):
        mine = np.flatnonzero(comp_h == c)
        if not shell_h[mine].any():  # its outline collapsed: no area
            continue
        g = Polygon(rings[mine[shell_h[mine]][0]], [rings[r] for r in mine[~shell_h[mine]]])
        rest.append(g if g.is_valid else shapely.make_valid(g))
    for g in rest:
        out.extend(np.asarray(p.exterior.coords)[:-1] for p in hole_free(g))
    return out


def _cells_region(ci: np.ndarray, cj: np.ndarray, params: LidarParams) -> list[np.ndarray]:
    """Hole-free polygons (vertex arrays) of the marked cells ``(ci, cj)`` after the closing (docs/method.md §3.1.4,
    steps 2 and 3)."""
    if len(ci) == 0:
        return []
    rad = int(np.ceil(params.closing / params.grid)) if params.closing > 0 else 0
    occ, i0, j0 = closed_raster(ci, cj, rad)
    return _polygons(occ, int(i0), int(j0), params.grid)


def region_from_points(xy: np.ndarray, params: LidarParams, r_max: float):
    """The bird's-eye region of the points ``xy`` (N, 2): grid occupancy within r_max, closed with a disc of radius
    ``params.closing``, as polygons of the occupied cells (a shapely geometry, empty without points)."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    xy = xy[(np.abs(xy) <= r_max).all(axis=1)]
    ij = np.floor(xy / params.grid).astype(np.int64)
    return shapely.union_all([Polygon(r) for r in _cells_region(ij[:, 0].copy(), ij[:, 1].copy(), params)])


def frame_regions(
    pts: np.ndarray,
    lab: np.ndarray,
    ids: dict[str, np.ndarray],
    params: LidarParams,
    r_max: float,
    fov_deg: float = 360.0,
    lut: np.ndarray | None = None,
) -> list[tuple[str, np.ndarray]]:
    """``(class, (n, 2) vertices)`` hole-free polygons of one frame, per configured class, from the points within
    r_max and within ``FOV_MARGIN_DEG`` of the sensor's sector (Omega_k never reaches beyond it); ``lut`` is
    :func:`_label_lut` of ``ids`` (made when not given)."""
    lut = _label_lut(ids) if lut is None else lut
    half = 0.5 * fov_deg + FOV_MARGIN_DEG if fov_deg + 2.0 * FOV_MARGIN_DEG < 360.0 else -1.0
    ci, cj, cc = frame_cells(
        pts, lab, lut, len(ids), float(r_max), half, params.grid, float(np.radians(params.sector_deg)), params.fill
    )
    out = []
    for c, name in enumerate(ids):
        mine = cc == c
        out.extend((name, xy) for xy in _cells_region(ci[mine], cj[mine], params))
    return out


# ---------------------------------------------------------------------------------------------------------------------
# a sequence, with the run folder's cache


def _key(
    files: list[tuple[Path, Path, int]], names: tuple[str, ...], params: LidarParams, r_max: float, fov: float
) -> str:
    h = hashlib.sha256(json.dumps([CACHE_FORMAT, list(names), asdict(params), r_max, fov, FOV_MARGIN_DEG]).encode())
    for scan, lab, _ in files:
        for p in (scan, lab):
            st = p.stat()
            h.update(f"{p.name} {st.st_size} {st.st_mtime_ns}\n".encode())
    return h.hexdigest()


def _save(path: Path, key: str, names: tuple[str, ...], sem: dict[int, list[tuple[str, np.ndarray]]]) -> None:
    rows = [(k, names.index(c), xy) for k, polys in sorted(sem.items()) for c, xy in polys]
    xy = np.concatenate([r[2] for r in rows]) if rows else np.zeros((0, 2))
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(
        tmp, key=np.array(key), names=np.array(names, dtype=str), frame=np.array([r[0] for r in rows], dtype=np.int32),
        cls=np.array([r[1] for r in rows], dtype=np.int32), n=np.array([len(r[2]) for r in rows], dtype=np.int64),
        xy=xy,
    )  # fmt: skip
    os.replace(tmp, path)


def _load(path: Path, key: str) -> dict[int, list[tuple[str, np.ndarray]]] | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["key"]) != key:
                return None
            names, frame, cls, n, xy = (z[k] for k in ("names", "frame", "cls", "n", "xy"))
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):  # unreadable: rebuilt
        return None
    out: dict[int, list[tuple[str, np.ndarray]]] = {}
    for f, c, part in zip(frame, cls, np.split(xy, np.cumsum(n)[:-1]) if len(n) else [], strict=True):
        out.setdefault(int(f), []).append((str(names[c]), part))
    return out


def sequence_regions(
    velodyne: Path,
    labels: Path,
    seq: str,
    n_frames: int,
    names: tuple[str, ...],
    params: LidarParams,
    r_max: float,
    cache: Path | None = None,
    fov_deg: float = 360.0,
) -> tuple[dict[int, list[tuple[str, np.ndarray]]], bool]:
    """Per-frame ``(class, vertices)`` polygons of a sequence (the shape of a parsed ``--semantics`` file) and
    whether they came from the cache ``cache/XXXX.npz`` (written when built)."""
    files = frame_files(Path(velodyne), Path(labels), seq, n_frames)
    ids = class_ids(names)
    key = _key(files, names, params, r_max, fov_deg)
    path = Path(cache) / f"{seq}.npz" if cache is not None else None
    if path is not None and path.is_file() and (hit := _load(path, key)) is not None:
        return hit, True
    sem = {}
    lut = _label_lut(ids)
    for k, (scan, lab, _) in enumerate(files):
        pts, cl = read_frame(scan, lab)
        # the first frame compiles the loops of lidar_raster after installation: one line if that takes a while
        with first_use_notice("lidar_raster") if k == 0 else nullcontext():
            polys = frame_regions(pts, cl, ids, params, r_max, fov_deg, lut)
        if polys:
            sem[k] = polys
    if path is not None:
        _save(path, key, names, sem)
    return sem, False


# ---------------------------------------------------------------------------------------------------------------------
# the protocol's hooks (``spec.lidar`` of :class:`~soabench.kitti.config.KittiSpec`)


def lidar_files(lidar: dict, seq: KittiSequence) -> None:
    """Check a sequence's scans and labels before anything is written (:class:`ReadError` on the first bad file)."""
    frame_files(Path(lidar["velodyne"]), Path(lidar["point_labels"]), seq.seq, seq.n_frames)


def lidar_semantics(
    lidar: dict, seq: KittiSequence, kcfg: KittiConfig, sensor: SensorConfig, run_dir: Path, log: Callable[[str], None]
) -> dict[int, list[tuple[str, np.ndarray]]]:
    """The sequence's per-frame regions of the birth and occluder classes, cached in ``run_dir/lidar/``."""
    t0 = time.perf_counter()
    names = tuple(dict.fromkeys(kcfg.semantic_classes + kcfg.occluder_classes))
    params = LidarParams(**{f.name: float(lidar[f.name]) for f in fields(LidarParams)})
    fov = float(sensor_for(seq, kcfg, sensor).fov_deg)
    sem, cached = sequence_regions(
        Path(lidar["velodyne"]), Path(lidar["point_labels"]), seq.seq, seq.n_frames, names, params,
        float(sensor.r_max), Path(run_dir) / CACHE_DIR, fov,
    )  # fmt: skip
    how = f"read from {CACHE_DIR}/{seq.seq}.npz" if cached else "built"
    log(
        f"sequence {seq.seq}: semantic regions from {seq.n_frames} LiDAR scans {how} ({time.perf_counter() - t0:.1f} s)"
    )
    return sem


def lidar_options(
    root: str,
    point_labels: str | None,
    velodyne: str | None = None,
    semantics: str | None = None,
    grid: float | None = None,
    closing: float | None = None,
    fill: float | None = None,
    classes: tuple[str, ...] = (),
) -> dict | None:
    """A KITTI run's ``spec.lidar`` from ``--point-labels DIR [--velodyne DIR] [--lidar-grid M] [--lidar-closing M]
    [--lidar-fill M]`` (None without ``point_labels``); one line naming the bad value otherwise. ``classes``: the
    semantic and occluder classes whose SemanticKITTI ids the region is made of."""
    given = {"grid": grid, "closing": closing, "fill": fill}
    if point_labels is None:
        flags = [
            f for f, v in (("velodyne", velodyne), *((f"lidar-{k}", v) for k, v in given.items())) if v is not None
        ]
        require(not flags, f"--{flags[0] if flags else ''} needs --point-labels DIR")
        return None
    require(semantics is None, "give either --semantics DIR or --point-labels DIR (two sources of one region)")
    velodyne_dir = Path(velodyne) if velodyne is not None else Path(root) / "velodyne"
    require(velodyne_dir.is_dir(), f"--velodyne {str(velodyne_dir)!r} is not a folder (KITTI scans XXXX/NNNNNN.bin)")
    labels = Path(point_labels)
    require(labels.is_dir(), f"--point-labels {str(labels)!r} is not a folder (SemanticKITTI XXXX/NNNNNN.label)")
    class_ids(classes)
    params = LidarParams(**{k: float(v) for k, v in given.items() if v is not None}).validate()
    return {"velodyne": str(velodyne_dir.resolve()), "point_labels": str(labels.resolve()), **asdict(params)}
