"""KITTI tracking sequences -> the same :class:`~soabench.types.Scans` the SUMO path makes (docs/method.md §2.3,
§3.1.1, §5.1, §5.4, §5.9).

Frames: the sensor (ego) frame is the Velodyne frame (x forward, y left); its pose comes from the oxts packets (devkit
Mercator convention, :func:`~soabench.kitti.formats.poses_from_oxts`) and ``Tr_imu_to_velo``, and is projected onto
the ground plane: ``ego = (x, y, theta)`` in the frame of the first IMU pose. Every object is mapped to the ego frame
with the calibration (``X_velo = (R0_rect Tr_velo_to_cam)^-1 X_rect``) and from there to the world frame with the
planar ego pose, so measurement model and truth agree exactly.

Per frame k:

* Z_k: the centres of the detections of the tracked classes (score >= ``score_min``) as (range, bearing) from the
  ego; detections outside FOV_k are dropped unless ``detections_in_fov = false`` (counted);
* truth: the labelled objects of the tracked classes with their track ids (present = labelled at k);
  ``visible`` = in FOV_k and KITTI ``occluded <= max_occluded``; ``detected`` from the measurement origin, which
  is the gated assignment of detections to the labelled objects in FOV_k (``source = "match"``) or the detection
  file's track-id column (``source = "track_id"``, data written by ``soabench export kitti``);
* O_k: the footprints of the vehicle boxes (labels or detections) and the semantic occluder polygons (buildings)
  within r_max, with their tangent rays; Omega_k: the semantic polygons of frame k (sidewalk) within FOV_k minus
  obstacles and shadows (empty without ``--semantics``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import MultiLineString, Polygon, box

from soabench.config import SensorConfig
from soabench.errors import SoabenchError, require
from soabench.geometry import wrap
from soabench.kitti.config import KittiConfig
from soabench.kitti.formats import (
    Calib,
    Objects,
    ReadError,
    nominal_calib,
    parse_calib,
    parse_objects,
    parse_oxts,
    parse_semantics,
    poses_from_oxts,
)
from soabench.metrics import gated_assignment
from soabench.scenario.scene import SceneMap
from soabench.sensor import obstacles_from_geoms, visible_region
from soabench.types import CLUTTER, Scan, Scans

LABEL_DIR, CALIB_DIR, OXTS_DIR = "label_02", "calib", "oxts"
DETECTION_DIR, SEMANTICS_DIR = "detections", "semantics"  #: folder names written by ``soabench export kitti``
_SEQ_FILE = re.compile(r"^(\d+)\.txt$")


# ---------------------------------------------------------------------------------------------------------------------
# the dataset: folders and sequence ids


def sequence_files(folder: Path) -> dict[str, Path]:
    """``{id: path}`` of the ``XXXX.txt`` files of a folder (ids as written, e.g. "0007")."""
    return {m.group(1): p for p in sorted(Path(folder).iterdir()) if (m := _SEQ_FILE.match(p.name)) and p.is_file()}


#: ``--sequences`` bounds: sequence numbers and how many one run may name
MAX_SEQUENCE_NUMBER = 999_999
MAX_SEQUENCES = 10_000


def parse_sequences(text: str) -> list[int]:
    """``0000-0020``, ``0,3,5`` or a mix (``0-3,7``): sorted unique sequence numbers, each in
    [0, :data:`MAX_SEQUENCE_NUMBER`], at most :data:`MAX_SEQUENCES` of them (checked before a range is expanded)."""
    shown = text if len(text) <= 60 else text[:57] + "..."
    spans: list[tuple[int, int]] = []
    try:
        for part in (s.strip() for s in text.split(",")):
            a, _, b = part.partition("-") if "-" in part else (part, "", part)
            lo, hi = int(a), int(b)
            require(hi >= lo >= 0, "")
            spans.append((lo, hi))
    except (ValueError, SoabenchError):
        raise SoabenchError(
            f"--sequences {shown!r} must be ranges LO-HI and/or numbers separated by commas, e.g. 0000-0020 or 0,3,5"
        ) from None
    top = max(hi for _, hi in spans)
    count = sum(hi - lo + 1 for lo, hi in spans)
    require(
        top <= MAX_SEQUENCE_NUMBER and count <= MAX_SEQUENCES,
        f"--sequences {shown!r} names sequence {top} ({count} numbers); allowed: numbers 0-{MAX_SEQUENCE_NUMBER}, "
        f"at most {MAX_SEQUENCES} of them",
    )
    return sorted({n for lo, hi in spans for n in range(lo, hi + 1)})


def _listed(items: list[str], limit: int = 5) -> str:
    """``a, b, c`` or ``a, b, c, d, e, ... (N in all)``: a list in one readable line."""
    return ", ".join(items[:limit]) + (f", ... ({len(items)} in all)" if len(items) > limit else "")


@dataclass
class Dataset:
    """A KITTI tracking root with its detection (and semantics) folders, checked for consistent sequence ids."""

    root: Path
    detections: Path
    semantics: Path | None
    ids: list[str]  #: the sequences to use, e.g. ["0000", "0001"]


def open_dataset(
    root: str | Path, detections: str | Path | None = None, semantics: str | Path | None = None, sequences=None
) -> Dataset:
    """Check the folders and the sequence ids (labels vs detections); :class:`SoabenchError` naming what is wrong."""
    root = Path(root)
    require(root.is_dir(), f"--root {str(root)!r} is not a folder")
    labels = root / LABEL_DIR
    require(labels.is_dir(), f"--root {str(root)!r} has no {LABEL_DIR}/ folder (KITTI tracking layout: XXXX.txt files)")
    det = Path(detections) if detections is not None else root / DETECTION_DIR
    require(
        det.is_dir(),
        f"--detections {str(det)!r} is not a folder"
        if detections is not None
        else f"no detections: give --detections DIR (none at {str(det)!r})",
    )
    sem = Path(semantics) if semantics is not None else None
    require(sem is None or sem.is_dir(), f"--semantics {str(sem)!r} is not a folder")
    label_ids = sequence_files(labels)
    require(bool(label_ids), f"{str(labels)!r} holds no sequence files XXXX.txt")
    det_ids = sequence_files(det)
    extra = sorted(set(det_ids) - set(label_ids))
    require(
        not extra,
        f"detections for sequence(s) {', '.join(extra)} in {str(det)!r} have no labels in {str(labels)!r}; "
        "the sequence ids of labels and detections must match",
    )
    if sequences is None:
        ids = sorted(label_ids)
    else:
        by_num = {int(s): s for s in label_ids}
        missing = [f"{n:04d}" for n in sequences if n not in by_num]
        require(not missing, f"--sequences: no labels for {_listed(missing)} in {str(labels)!r}")
        ids = [by_num[n] for n in sequences]
    no_det = [s for s in ids if s not in det_ids]
    require(
        not no_det,
        f"no detections for sequence(s) {', '.join(no_det)} in {str(det)!r}; "
        "the sequence ids of labels and detections must match",
    )
    return Dataset(root, det, sem, ids)


# ---------------------------------------------------------------------------------------------------------------------
# one sequence


@dataclass
class KittiSequence:
    """The files of one sequence, parsed."""

    seq: str
    n_frames: int
    labels: Objects
    detections: Objects
    det_format: str
    calib: Calib
    imu_poses: np.ndarray | None  #: (F, 4, 4) or None without oxts
    semantics: dict[int, list[tuple[str, np.ndarray]]] | None
    notes: list[str] = field(default_factory=list)


def read_sequence(ds: Dataset, seq: str) -> KittiSequence:
    """Parse the files of sequence ``seq``; :class:`ReadError` naming file and line on the first bad row."""
    notes: list[str] = []
    label_path = ds.root / LABEL_DIR / f"{seq}.txt"
    labels, _ = parse_objects(label_path, "label")
    detections, det_format = parse_objects(ds.detections / f"{seq}.txt", "detections")
    calib_path = ds.root / CALIB_DIR / f"{seq}.txt"
    if calib_path.is_file():
        calib = parse_calib(calib_path)
    else:
        calib = nominal_calib()
        notes.append(f"no {CALIB_DIR}/{seq}.txt: nominal KITTI calibration used")
    oxts_path = ds.root / OXTS_DIR / f"{seq}.txt"
    poses = None
    if oxts_path.is_file():
        oxts = parse_oxts(oxts_path)
        if len(oxts):
            poses = poses_from_oxts(oxts)
        n_frames = len(oxts)
        where = f"{oxts_path} has {n_frames} packets"
    else:
        notes.append(f"no {OXTS_DIR}/{seq}.txt: the ego is taken as stationary")
        n_frames = int(labels.frame.max()) + 1 if len(labels) else 0
        where = f"the last labelled frame of {label_path} is {n_frames - 1}"
    if n_frames == 0:
        raise ReadError(f"sequence {seq} is empty: {label_path} has no objects and there are no oxts packets")
    for obj, what in ((labels, "labels"), (detections, "detections")):
        bad = np.flatnonzero(obj.frame >= n_frames)
        if len(bad):
            i = bad[0]
            raise ReadError(
                f"{obj.path}:{obj.line[i]}: {what} in frame {obj.frame[i]}, a frame without labels "
                f"(the sequence has frames 0-{n_frames - 1}: {where})"
            )
    semantics = None
    if ds.semantics is not None:
        sem_path = ds.semantics / f"{seq}.txt"
        if sem_path.is_file():
            semantics = parse_semantics(sem_path)
            late = [f for f in semantics if f >= n_frames]
            if late:
                raise ReadError(f"{sem_path}: polygons for frame {min(late)}, beyond the last frame {n_frames - 1}")
        else:
            notes.append(f"no semantics/{seq}.txt: S-OA uses its occlusion and FOV terms only")
    return KittiSequence(seq, n_frames, labels, detections, det_format, calib, poses, semantics, notes)


# ---------------------------------------------------------------------------------------------------------------------
# geometry


def ego_poses(seq: KittiSequence) -> np.ndarray:
    """(F, 3) planar Velodyne poses (x, y, theta) in the first IMU frame; zeros without oxts (stationary ego)."""
    if seq.imu_poses is None:
        return np.zeros((seq.n_frames, 3))
    T = seq.imu_poses @ np.linalg.inv(seq.calib.Tr_imu_velo)
    return np.column_stack([T[:, 0, 3], T[:, 1, 3], np.arctan2(T[:, 1, 0], T[:, 0, 0])])


def to_world(xy: np.ndarray, ego: np.ndarray) -> np.ndarray:
    """Ego-frame points (..., 2) to the world with poses ``ego`` (..., 3) (broadcast)."""
    c, s = np.cos(ego[..., 2]), np.sin(ego[..., 2])
    return np.stack(
        [ego[..., 0] + c * xy[..., 0] - s * xy[..., 1], ego[..., 1] + s * xy[..., 0] + c * xy[..., 1]], axis=-1
    )


def centres_ego(obj: Objects, calib: Calib) -> np.ndarray:
    """(N, 2) bird's-eye box centres in the ego (Velodyne) frame."""
    return calib.rect_to_velo(obj.xyz)[:, :2]


def footprints_ego(obj: Objects, calib: Calib) -> np.ndarray:
    """(N, 4, 2) bird's-eye box corners in the ego frame (length along the box x axis rotated by rotation_y)."""
    sx = np.array([1.0, 1.0, -1.0, -1.0])
    sz = np.array([1.0, -1.0, -1.0, 1.0])
    xo = 0.5 * obj.hwl[:, 2:3] * sx  # (N, 4) along the length
    zo = 0.5 * obj.hwl[:, 1:2] * sz  # across
    c, s = np.cos(obj.ry)[:, None], np.sin(obj.ry)[:, None]
    x = obj.xyz[:, 0:1] + c * xo + s * zo
    z = obj.xyz[:, 2:3] - s * xo + c * zo
    y = np.broadcast_to(obj.xyz[:, 1:2], x.shape)
    pts = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    return calib.rect_to_velo(pts)[:, :2].reshape(-1, 4, 2)


def _fov_ego(xy: np.ndarray, sensor: SensorConfig) -> np.ndarray:
    r = np.hypot(xy[..., 0], xy[..., 1])
    ok = (r >= sensor.r_min) & (r <= sensor.r_max)
    if sensor.fov_deg < 360.0:
        ok &= np.abs(np.arctan2(xy[..., 1], xy[..., 0])) <= 0.5 * sensor.fov + 1e-12
    return ok


# ---------------------------------------------------------------------------------------------------------------------
# sequence -> Scans


@dataclass
class SequenceScans:
    """The Scans of a sequence, the scene map its birth models use, its sensor settings and what the reader did."""

    scans: Scans
    scene: SceneMap
    sensor: SensorConfig
    info: dict
    #: (F, P) int per frame and target the truth row's KITTI level, -1 where absent: ``"occluded"`` (0-3) and
    #: ``"truncated"`` (0 not, 1 partly, 2 fully truncated; a fraction in (0, 1] counts as 1)
    levels: dict[str, np.ndarray] | None = None


def sensor_for(seq: KittiSequence, kcfg: KittiConfig, sensor: SensorConfig) -> SensorConfig:
    """The sensor settings of a sequence: camera horizontal FOV (configured, or from P2) and the range limit."""

    fov = kcfg.fov_deg if kcfg.fov_deg > 0 else seq.calib.fov_deg(kcfg.image_width)
    return replace(sensor, fov_deg=float(fov))


def to_scans(seq: KittiSequence, kcfg: KittiConfig, sensor: SensorConfig) -> SequenceScans:
    """Build the Scans of one sequence (module docstring); ``sensor.dt`` is the frame period."""
    sensor = sensor_for(seq, kcfg, sensor)
    F = seq.n_frames
    ego = ego_poses(seq)

    # truth: tracked-class labels with their track ids
    lab = seq.labels.select(np.isin(seq.labels.type, kcfg.classes))
    ids = np.unique(lab.track_id)
    col = np.searchsorted(ids, lab.track_id)
    key = lab.frame * max(len(ids), 1) + col
    _, counts = np.unique(key, return_counts=True)
    if (counts > 1).any():
        dup = np.flatnonzero(np.isin(key, np.unique(key)[counts > 1]))[1]
        where = f"{lab.path}:{lab.line[dup]}"
        raise ReadError(f"{where}: track {lab.track_id[dup]} appears twice in frame {lab.frame[dup]}")
    P = len(ids)
    truth = np.full((F, P, 2), np.nan)
    present = np.zeros((F, P), dtype=bool)
    occ_ok = np.zeros((F, P), dtype=bool)
    truth[lab.frame, col] = to_world(centres_ego(lab, seq.calib), ego[lab.frame])
    present[lab.frame, col] = True
    occ_ok[lab.frame, col] = (lab.occluded >= 0) & (lab.occluded <= kcfg.max_occluded)
    levels = {name: np.full((F, P), -1, dtype=int) for name in ("occluded", "truncated")}
    levels["occluded"][lab.frame, col] = lab.occluded
    if lab.truncated is not None:
        trunc = np.asarray(lab.truncated, dtype=float)
        levels["truncated"][lab.frame, col] = np.where(trunc >= 0, np.clip(np.ceil(trunc), 0, 2), -1).astype(int)
    d = truth - ego[:, None, :2]
    r = np.hypot(d[..., 0], d[..., 1])
    in_fov = present & (r >= sensor.r_min) & (r <= sensor.r_max)
    if sensor.fov_deg < 360.0:
        b = wrap(np.arctan2(d[..., 1], d[..., 0]) - ego[:, None, 2])
        in_fov &= np.abs(np.where(present, b, 0.0)) <= 0.5 * sensor.fov + 1e-12
    visible = in_fov & occ_ok

    # measurements
    det = seq.detections
    is_cls = np.isin(det.type, kcfg.classes)
    passed = is_cls & (det.score >= kcfg.score_min)
    n_below = int((is_cls & ~passed).sum())
    meas = det.select(passed)
    z_ego = centres_ego(meas, seq.calib)
    keep = _fov_ego(z_ego, sensor) if kcfg.detections_in_fov else np.ones(len(meas), dtype=bool)
    n_outside = int((~keep).sum())
    meas, z_ego = meas.select(keep), z_ego[keep]
    Z_all = np.column_stack([np.hypot(z_ego[:, 0], z_ego[:, 1]), np.arctan2(z_ego[:, 1], z_ego[:, 0])])
    order = np.argsort(meas.frame, kind="stable")
    bounds = np.searchsorted(meas.frame[order], np.arange(F + 1))
    if kcfg.source == "track_id":
        known = {int(t): i for i, t in enumerate(ids)}
        bad = [i for i, t in enumerate(meas.track_id) if t >= 0 and int(t) not in known]
        if bad:
            i = bad[0]
            raise ReadError(
                f"{meas.path}:{meas.line[i]}: track id {meas.track_id[i]} is not a labelled target of the tracked "
                "classes (kitti.source = 'track_id' needs the truth ids in the detections, as the export writes them)"
            )
        src_all = np.array([known.get(int(t), CLUTTER) for t in meas.track_id], dtype=np.int64)

    # obstacles: vehicle boxes (labels or detections) and semantic occluders
    obs_src = seq.labels if kcfg.obstacles == "labels" else det.select(det.score >= kcfg.score_min)
    obs = obs_src.select(np.isin(obs_src.type, kcfg.obstacle_classes))
    feet = to_world(footprints_ego(obs, seq.calib), ego[obs.frame][:, None, :]) if len(obs) else np.zeros((0, 4, 2))
    obs_order = np.argsort(obs.frame, kind="stable")
    obs_bounds = np.searchsorted(obs.frame[obs_order], np.arange(F + 1))
    sem_regions, sem_occ, sem_notes = _semantic_world(seq, ego, kcfg)
    sidewalk = shapely.union_all([g for g in sem_regions if g is not None]) if seq.semantics else Polygon()

    scans: list[Scan] = []
    sources: list[np.ndarray] = []
    detected = np.zeros((F, P), dtype=bool)
    empty_region = Polygon()
    for k in range(F):
        rows = order[bounds[k] : bounds[k + 1]]
        Z = Z_all[rows]
        if kcfg.source == "track_id":
            src = src_all[rows]
        else:
            gt_idx = np.flatnonzero(in_fov[k])
            src = np.full(len(rows), CLUTTER, dtype=np.int64)
            pairs = gated_assignment(to_world(z_ego[rows], ego[k]), truth[k, gt_idx], kcfg.match_gate)
            src[pairs[:, 0]] = gt_idx[pairs[:, 1]]
        detected[k, src[src >= 0]] = True
        vehicles = feet[obs_order[obs_bounds[k] : obs_bounds[k + 1]]]
        geoms = np.concatenate([shapely.polygons(vehicles) if len(vehicles) else np.zeros(0, dtype=object), sem_occ[k]])
        kinds = np.array(["vehicle"] * len(vehicles) + ["building"] * len(sem_occ[k]), dtype="<U8")
        ego_pt = shapely.points(ego[k, :2])
        near = shapely.dwithin(geoms, ego_pt, sensor.r_max) if len(geoms) else np.zeros(0, dtype=bool)
        occ, occ_kinds = geoms[near], kinds[near]
        obstacles = obstacles_from_geoms(occ, occ_kinds, ego[k, :2], sensor.r_max)
        inside = occ[shapely.intersects(shapely.convex_hull(occ), ego_pt)] if len(occ) else occ
        region = sem_regions[k] if sem_regions[k] is not None else empty_region
        omega = visible_region(None, ego[k], obstacles, sensor, region=region, occluders=list(inside))  # type: ignore[arg-type]
        scans.append(Scan(k, k * float(sensor.dt), ego[k].copy(), Z, obstacles, list(occ), omega))
        sources.append(src)

    scene = _scene_map(seq, ego, sensor, sidewalk)
    info = {
        "sequence": seq.seq,
        "frames": F,
        "targets": P,
        "detections": int(len(det)),
        "measurements": int(len(Z_all)),
        "below_score": n_below,
        "outside_fov": n_outside,
        "format": seq.det_format,
        "fov_deg": float(sensor.fov_deg),
        "calib_nominal": list(seq.calib.nominal),
        "stationary_ego": seq.imu_poses is None,
        "semantics": seq.semantics is not None,
        "notes": list(seq.notes) + sem_notes,
    }
    out = Scans(
        scans=scans, dt=float(sensor.dt), source=sources, truth_xy=truth, present=present, in_fov=in_fov,
        visible=visible, detected=detected, ped_ids=np.array([str(i) for i in ids], dtype=str),
    )  # fmt: skip
    return SequenceScans(out, scene, sensor, info, levels)


def _semantic_world(seq: KittiSequence, ego: np.ndarray, kcfg: KittiConfig) -> tuple[list, list[np.ndarray], list]:
    """Per frame: the semantic region (world, or None) and the semantic occluder polygons (object array); notes on
    polygons left out (other classes, zero area)."""
    regions: list = [None] * seq.n_frames
    occluders = [np.zeros(0, dtype=object) for _ in range(seq.n_frames)]
    if not seq.semantics:
        return regions, occluders, []
    other: dict[str, int] = {}
    flat = 0
    for k, polys in seq.semantics.items():
        reg, occ = [], []
        for cls, xy in polys:
            if cls not in kcfg.semantic_classes and cls not in kcfg.occluder_classes:
                other[cls] = other.get(cls, 0) + 1
                continue
            g = shapely.make_valid(Polygon(to_world(xy, ego[k])))
            if g.is_empty or g.area <= 0:
                flat += 1
                continue
            (reg if cls in kcfg.semantic_classes else occ).append(g)
        regions[k] = shapely.union_all(reg) if reg else None
        parts = [p for g in occ for p in shapely.get_parts(g) if isinstance(p, Polygon)]
        occluders[k] = np.asarray(parts, dtype=object)
    notes = []
    if other:
        listed = ", ".join(f"{c} ({n})" for c, n in sorted(other.items()))
        notes.append(
            f"semantics/{seq.seq}.txt: polygons of classes {listed} not used (kitti.semantic_classes = "
            f"{list(kcfg.semantic_classes)}, kitti.occluder_classes = {list(kcfg.occluder_classes)})"
        )
    if flat:
        notes.append(f"semantics/{seq.seq}.txt: {flat} polygon(s) of zero area left out")
    return regions, occluders, notes


def _scene_map(seq: KittiSequence, ego: np.ndarray, sensor: SensorConfig, sidewalk) -> SceneMap:
    """The workspace of a sequence: the box around the ego path grown by r_max; Omega_sidewalk = all semantics."""
    pad = sensor.r_max + 5.0
    x0, y0 = ego[:, :2].min(axis=0) - pad
    x1, y1 = ego[:, :2].max(axis=0) + pad
    return SceneMap(
        name=f"kitti-{seq.seq}", world_box=box(x0, y0, x1, y1), sidewalk=sidewalk, crossings=Polygon(),
        walking_areas=Polygon(), roads=Polygon(), buildings=[], static_occluders=[], doors=np.zeros((0, 2)),
        sidewalk_lines=MultiLineString(),
    )  # fmt: skip
