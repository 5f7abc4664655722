"""SUMO trials written as a KITTI tracking layout (``soabench export kitti``), the mirror of the reader.

For trial n (sequence ``%04d`` % n) of a run with the config's seed, the very trial ``soabench run`` would simulate
and observe (same SUMO run, same sensor draws), with the sensor period set to the KITTI frame period and the sensor
sector set to the camera's horizontal FOV:

* ``label_02/XXXX.txt``: every present pedestrian (type ``Pedestrian``, track id = its index in the Recording,
  ``occluded`` 0 when in line of sight, 2 when in the FOV but hidden, 3 outside the FOV) and every vehicle and parked
  car within r_max (type ``Car``, track ids after the pedestrians);
* ``detections/XXXX.txt``: KITTI tracking result format (label columns + score): the synthetic sensor's measurements
  in scan order, target-originated ones with the target's track id, clutter with -1 (all typed ``Pedestrian``), plus
  the vehicle boxes as ``Car`` detections with score 1; scores are drawn from the export's own stream (targets
  U(0.5, 1), clutter U(0, 1)), so they never change the measurements;
* ``oxts/XXXX.txt``: 30-column packets whose devkit Mercator poses reproduce the ego path (first packet at
  49 N, 8.43 E);
* ``calib/XXXX.txt``: the nominal KITTI calibration, P2's focal length set so that the camera FOV equals the sensor's;
* ``semantics/XXXX.txt``: per frame, the sidewalk within r_max (hole-free pieces) and the buildings within r_max, in
  the ego frame;
* ``export.json``: provenance (net, seed, trials, duration, sensor).

Numbers are written with ``repr`` (shortest exact form), so the reader recovers measurements and truth to rounding.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon
from shapely.ops import split

from soabench.config import Config, SensorConfig
from soabench.errors import require
from soabench.experiment.files import write_json_atomic, write_text_atomic
from soabench.experiment.ownership import FolderLock, check_new_folder, resolve
from soabench.geometry import wrap
from soabench.kitti.formats import (
    NOMINAL,
    NOMINAL_IMAGE_WIDTH,
    calib_from_values,
    lat_to_scale,
    latlon_to_mercator,
    mercator_to_latlon,
)
from soabench.kitti.reader import CALIB_DIR, DETECTION_DIR, LABEL_DIR, OXTS_DIR, SEMANTICS_DIR

ORIGIN_LAT, ORIGIN_LON = 49.0, 8.43  #: geodetic position of the first IMU packet (Karlsruhe)
GROUND_Z = -1.73  #: ground height in the Velodyne frame (m; KITTI sensor setup)
PED_HWL = (1.75, 0.6, 0.8)  #: pedestrian box (m)
CAR_H = 1.5  #: vehicle box height (m)
SCORE_STREAM = 0x4B495454  #: "KITT": spawn key of the score stream
MAX_EXPORT_TRIALS = 10_000  #: trials of one export: KITTI sequence ids have four digits
EXPORT_FILE = "export.json"  #: written last: a folder holding it is a finished export


def _fmt(values) -> str:
    return " ".join(repr(float(v)) for v in np.asarray(values, dtype=float).ravel())


def export_calib(sensor: SensorConfig):
    """The nominal calibration with P2's focal length giving the sensor FOV: f_x = (W/2) / tan(Theta/2)."""
    P2 = NOMINAL["P2"].copy()
    f = 0.5 * NOMINAL_IMAGE_WIDTH / math.tan(0.5 * sensor.fov)
    P2[0] = P2[5] = f
    return calib_from_values({"P2": P2}, [])


def calib_text(calib) -> str:
    P2 = _fmt(calib.P2)
    lines = [f"P{i}: {P2}" for i in range(4)]
    lines.append(f"R_rect {_fmt(calib.R0_rect[:3, :3])}")
    lines.append(f"Tr_velo_cam {_fmt(calib.Tr_velo_cam[:3])}")
    lines.append(f"Tr_imu_velo {_fmt(calib.Tr_imu_velo[:3])}")
    return "\n".join(lines) + "\n"


def _pose4(ego: np.ndarray) -> np.ndarray:
    c, s = math.cos(ego[2]), math.sin(ego[2])
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = ego[:2]
    return T


def oxts_text(egos: np.ndarray, calib) -> str:
    """Packets whose devkit poses (:func:`~soabench.kitti.formats.poses_from_oxts`) give the Velodyne path ``egos``."""
    T_imu = np.array([_pose4(e) @ calib.Tr_imu_velo for e in egos])
    scale = lat_to_scale(ORIGIN_LAT)
    mx0, my0 = latlon_to_mercator(ORIGIN_LAT, ORIGIN_LON, scale)
    lat, lon = mercator_to_latlon(mx0 + T_imu[:, 0, 3] - T_imu[0, 0, 3], my0 + T_imu[:, 1, 3] - T_imu[0, 1, 3], scale)
    lat[0] = ORIGIN_LAT  # exactly: the reader takes the Mercator scale from it
    yaw = np.arctan2(T_imu[:, 1, 0], T_imu[:, 0, 0])
    rows = []
    for i in range(len(egos)):
        packet = np.zeros(30)
        packet[:6] = [lat[i], lon[i], T_imu[i, 2, 3], 0.0, 0.0, yaw[i]]
        packet[25:30] = [4, 10, 4, 4, 6]  # navstat numsats posmode velmode orimode (RTK-like)
        rows.append(_fmt(packet[:25]) + " " + " ".join(str(int(v)) for v in packet[25:]))
    return "\n".join(rows) + "\n"


def _ego_frame(xy: np.ndarray, ego: np.ndarray) -> np.ndarray:
    d = np.asarray(xy, dtype=float).reshape(-1, 2) - ego[:2]
    c, s = math.cos(ego[2]), math.sin(ego[2])
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])


def _object_row(frame, tid, typ, occluded, hwl, xyz, ry, score=None) -> str:
    alpha = float(wrap(ry - math.atan2(xyz[0], xyz[2])))
    row = f"{frame} {tid} {typ} 0 {occluded} {alpha!r} -1.0 -1.0 -1.0 -1.0 {_fmt(hwl)} {_fmt(xyz)} {float(ry)!r}"
    return row if score is None else f"{row} {float(score)!r}"


def _ry(calib, heading_ego: float) -> float:
    """rotation_y of a box whose length axis points along ``heading_ego`` in the Velodyne frame."""
    d = calib.velo_to_rect[:3, :3] @ np.array([math.cos(heading_ego), math.sin(heading_ego), 0.0])
    return math.atan2(-d[2], d[0])


def _box(corners: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """Centre, length, width and heading of the minimum rotated rectangle of a footprint (exact for rectangles)."""
    rect = np.asarray(shapely.minimum_rotated_rectangle(Polygon(corners)).exterior.coords)[:4]
    e1, e2 = rect[1] - rect[0], rect[2] - rect[1]
    if np.hypot(*e2) > np.hypot(*e1):
        e1, e2 = e2, e1
    return rect.mean(axis=0), float(np.hypot(*e1)), float(np.hypot(*e2)), float(math.atan2(e1[1], e1[0]))


def _hole_free(geom) -> list[Polygon]:
    """Polygons without holes covering ``geom``: each hole is cut by a vertical line through its interior."""
    todo = [p for p in shapely.get_parts(geom) if isinstance(p, Polygon) and not p.is_empty]
    out: list[Polygon] = []
    while todo:
        p = todo.pop()
        if not p.interiors:
            out.append(p)
            continue
        x = Polygon(p.interiors[0]).representative_point().x
        y0, y1 = p.bounds[1] - 1.0, p.bounds[3] + 1.0
        todo.extend(q for q in split(p, LineString([(x, y0), (x, y1)])).geoms if isinstance(q, Polygon))
    return out


def export_trial(trial: int, recording, scans, scene, sensor: SensorConfig, calib, out: Path, seed: int) -> dict:
    """Write sequence ``trial`` (all five files); returns counts."""
    from soabench.sensor import _static_occluder_arrays, scan_steps

    seq = f"{trial:04d}"
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(trial)], spawn_key=(SCORE_STREAM,)))
    steps = scan_steps(recording.t, recording.step_length, sensor.dt)
    P = len(recording.ped_ids)
    V = np.asarray(recording.veh_present).shape[1] if np.asarray(recording.veh_present).ndim == 2 else 0
    statics, kinds = _static_occluder_arrays(recording, scene)
    parked = [p for p, kd in zip(statics, kinds, strict=True) if kd == "parked"]
    parked_geoms = [Polygon(p) for p in parked]
    buildings = [p for p, kd in zip(statics, kinds, strict=True) if kd == "building"]
    building_geoms = [Polygon(p) for p in buildings]
    sidewalk = scene.sidewalk
    labels, dets, sem = [], [], []
    n_meas = 0
    for k, scan in enumerate(scans.scans):
        ego, idx = scan.ego, int(steps[k])
        ego_pt = Point(ego[:2])
        # pedestrians
        for i in np.flatnonzero(scans.present[k]):
            p = _ego_frame(scans.truth_xy[k, i], ego)[0]
            xyz = calib.velo_to_rect_pts([p[0], p[1], GROUND_Z])[0]
            occ = 0 if scans.visible[k, i] else (2 if scans.in_fov[k, i] else 3)
            heading = float(recording.ped_heading[idx, i]) - float(ego[2])
            ry = _ry(calib, heading) if math.isfinite(heading) else 0.0
            labels.append(_object_row(k, int(i), "Pedestrian", occ, PED_HWL, xyz, ry))
        # vehicles and parked cars within r_max
        boxes = []
        foot = np.asarray(recording.veh_footprint[idx], dtype=float).reshape(-1, 4, 2)
        pres = np.asarray(recording.veh_present[idx], dtype=bool).reshape(-1)
        for v in np.flatnonzero(pres & np.isfinite(foot).all(axis=(1, 2))):
            if Polygon(foot[v]).distance(ego_pt) <= sensor.r_max:
                boxes.append((P + int(v), foot[v]))
        for j, g in enumerate(parked_geoms):
            if g.distance(ego_pt) <= sensor.r_max:
                boxes.append((P + V + j, parked[j]))
        for tid, corners in boxes:
            centre, length, width, heading = _box(_ego_frame(corners, ego))
            xyz = calib.velo_to_rect_pts([centre[0], centre[1], GROUND_Z])[0]
            ry = _ry(calib, heading)
            labels.append(_object_row(k, tid, "Car", 0, (CAR_H, width, length), xyz, ry))
            dets.append(_object_row(k, tid, "Car", 0, (CAR_H, width, length), xyz, ry, 1.0))
        # measurements in scan order
        Z, src = scan.Z, scans.source[k]
        scores = np.where(src >= 0, rng.uniform(0.5, 1.0, len(Z)), rng.uniform(0.0, 1.0, len(Z)))
        for (r, b), s, sc in zip(Z, src, scores, strict=True):
            xyz = calib.velo_to_rect_pts([r * math.cos(b), r * math.sin(b), GROUND_Z])[0]
            dets.append(_object_row(k, int(s), "Pedestrian", 0, PED_HWL, xyz, 0.0, sc))
        n_meas += len(Z)
        # semantics: sidewalk within r_max (+1 m), buildings within r_max
        disk = ego_pt.buffer(sensor.r_max + 1.0, 64)
        for piece in _hole_free(shapely.intersection(sidewalk, disk)):
            xy = _ego_frame(np.asarray(piece.exterior.coords)[:-1], ego)
            sem.append(f"{k} sidewalk {_fmt(xy)}")
        for g, ring in zip(building_geoms, buildings, strict=True):
            if g.distance(ego_pt) <= sensor.r_max:
                sem.append(f"{k} building {_fmt(_ego_frame(ring, ego))}")
    egos = np.array([s.ego for s in scans.scans])
    for folder, text in (
        (LABEL_DIR, "\n".join(labels)), (DETECTION_DIR, "\n".join(dets)), (SEMANTICS_DIR, "\n".join(sem)),
        (OXTS_DIR, oxts_text(egos, calib).rstrip("\n")), (CALIB_DIR, calib_text(calib).rstrip("\n")),
    ):  # fmt: skip
        write_text_atomic(out / folder / f"{seq}.txt", text + "\n" if text else "")
    return {"sequence": seq, "frames": len(scans), "pedestrians": P, "measurements": n_meas}


def export_kitti(
    cfg: Config,
    net: str,
    polys: tuple[str, ...],
    scenario: str | None,
    trials: int,
    out: Path,
    duration: float | None = None,
    fov_deg: float | None = None,
    log: Callable[[str], None] = print,
) -> list[dict]:
    """Simulate, observe and write ``trials`` SUMO trials as KITTI sequences 0000, 0001, ... under ``out``."""
    from soabench.scenario import load

    require(
        isinstance(trials, int) and 1 <= trials <= MAX_EXPORT_TRIALS,
        f"--trials {trials!r} is out of range; allowed: integers in [1, {MAX_EXPORT_TRIALS}] (sequence ids 0000-9999)",
    )
    out = resolve(out)
    check_new_folder(out, EXPORT_FILE, "KITTI export", "remove it to export again")
    fov = float(fov_deg) if fov_deg is not None else export_default_fov(cfg.sensor)
    require(0.0 < fov < 180.0, f"--fov-deg {fov!r} must be in (0, 180): a camera's horizontal field of view")
    sensor = dataclasses.replace(cfg.sensor, fov_deg=fov)
    calib = export_calib(sensor)
    scene, scen = load(net, polys, scenario)
    sensor.validate(scen.step_length)
    dur = float(scen.duration) if duration is None else float(duration)
    require(dur > 0, f"--duration {dur!r} must be > 0")
    with FolderLock(out, "export folder"):
        check_new_folder(out, EXPORT_FILE, "KITTI export", "remove it to export again")  # again, under the lock
        return _export_trials(cfg, (net, polys, scenario), (scene, scen), trials, out, dur, sensor, calib, log)


def _export_trials(
    cfg: Config,
    source: tuple[str, tuple[str, ...], str | None],
    loaded: tuple,
    trials: int,
    out: Path,
    dur: float,
    sensor: SensorConfig,
    calib: dict,
    log: Callable[[str], None],
) -> list[dict]:
    """The trials of :func:`export_kitti` written into the checked and locked folder ``out``; ``export.json`` last."""
    from soabench.scenario import simulate
    from soabench.seeding import trial_seeds
    from soabench.sensor import observe

    (net, polys, scenario), (scene, scen) = source, loaded
    rows = []
    for n in range(trials):
        seeds = trial_seeds(cfg.experiment.seed, n)
        recording = simulate(scene, scen, seeds, duration=dur)
        scans = observe(recording, scene, sensor, seeds.sensor_rngs())
        rows.append(export_trial(n, recording, scans, scene, sensor, calib, out, cfg.experiment.seed))
        log(f"sequence {n:04d}: {rows[-1]['frames']} frames, {rows[-1]['measurements']} measurements")
    write_json_atomic(
        out / EXPORT_FILE,
        {
            "net": net, "polys": list(polys), "scenario": scenario, "seed": cfg.experiment.seed, "trials": trials,
            "duration": dur, "sensor": dataclasses.asdict(sensor), "sequences": rows,
        },
    )  # fmt: skip
    return rows


def export_default_fov(sensor: SensorConfig) -> float:
    """The sensor's sector if it is a camera-like one (< 180 deg), else the nominal KITTI camera FOV."""
    if sensor.fov_deg < 180.0:
        return float(sensor.fov_deg)
    return 2.0 * math.degrees(math.atan(0.5 * NOMINAL_IMAGE_WIDTH / NOMINAL["P2"][0]))
