"""SUMO trials written as a KITTI tracking layout (``soabench export kitti``), the mirror of the reader.

For trial n (sequence ``%04d`` % n) of a run with the config's seed, the very trial ``soabench run`` would simulate
and observe (same SUMO run, same sensor draws), with the sensor period set to the KITTI frame period and the sensor
sector set to the camera's horizontal FOV:

* ``label_02/XXXX.txt``: what the camera sees (:mod:`soabench.kitti.camera`): every present pedestrian within
  r_max (type ``Pedestrian``, track id = its index in the Recording) and every vehicle and parked car within r_max
  (type ``Car``, track ids after the pedestrians) whose 3-D box lies in front of the camera and overlaps the image,
  with its 2-D box projected with P2 and clipped to the image, its truncation level, and ``occluded`` 0 when in
  line of sight, 2 when in the sensor's FOV but hidden, 3 when its centre is outside the FOV (a truncated box);
* ``detections/XXXX.txt``: KITTI tracking result format (label columns + score): the synthetic sensor's measurements
  in scan order whose pedestrian-sized box the camera sees, target-originated ones with the target's track id,
  clutter with -1 (all typed ``Pedestrian``), plus the labelled vehicle boxes as ``Car`` detections with score 1;
  scores are drawn from the export's own stream (targets U(0.5, 1), clutter U(0, 1)), so they never change the
  measurements;
* ``oxts/XXXX.txt``: 30-column packets whose devkit Mercator poses reproduce the ego path (first packet at
  49 N, 8.43 E), with the velocities, accelerations and yaw rate of that path (:func:`imu_motion`);
* ``calib/XXXX.txt``: the export's camera (:func:`export_calib`), whose horizontal FOV is the sensor's sector;
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
from shapely.geometry import Point, Polygon

from soabench import scenario as sumo_scenario
from soabench.atomic import write_json_atomic, write_text_atomic
from soabench.config import Config, SensorConfig, check_time
from soabench.errors import require
from soabench.folders import FolderLock, check_new_folder, resolve
from soabench.geometry import wrap
from soabench.kitti.camera import image_box
from soabench.kitti.formats import (
    NOMINAL,
    NOMINAL_IMAGE_WIDTH,
    calib_from_values,
    lat_to_scale,
    latlon_to_mercator,
    mercator_to_latlon,
)
from soabench.kitti.raycast import export_lidar
from soabench.kitti.reader import CALIB_DIR, DETECTION_DIR, LABEL_DIR, OXTS_DIR, SEMANTICS_DIR
from soabench.kitti.velodyne import CAR_H, GROUND_Z, PED_HWL, ego_frame, hole_free
from soabench.seeding import trial_seeds
from soabench.sensor import _static_occluder_arrays, observe, scan_steps

ORIGIN_LAT, ORIGIN_LON = 49.0, 8.43  #: geodetic position of the first IMU packet (Karlsruhe)
SCORE_STREAM = 0x4B495454  #: "KITT": spawn key of the score stream
GRAVITY = 9.80665  #: specific force (m/s^2) an accelerometer at rest reports upward: the OXTS az and au of a level ego
MAX_EXPORT_TRIALS = 10_000  #: trials of one export: KITTI sequence ids have four digits
EXPORT_FILE = "export.json"  #: written last: a folder holding it is a finished export


def _fmt(values) -> str:
    return " ".join(repr(float(v)) for v in np.asarray(values, dtype=float).ravel())


def export_calib(sensor: SensorConfig):
    """The export's camera: P2 = [[f, 0, W/2, 0], [0, f, c_y, 0], [0, 0, 1, 0]] with f = (W/2) / tan(Theta/2) (c_y
    nominal), at the Velodyne's position in the ground plane (Tr_velo_to_cam: KITTI's axes and 0.08 m height offset,
    without the 0.27 m forward offset). Its horizontal FOV is then the sensor's sector exactly: a point is in the
    image's width when its bearing from the sensor is within +-Theta/2, so every pedestrian the sensor can see is
    labelled, and the reader's FOV from P2 (:meth:`~soabench.kitti.formats.Calib.fov_deg`) is the sensor's."""
    f = 0.5 * NOMINAL_IMAGE_WIDTH / math.tan(0.5 * sensor.fov)
    P2 = np.array([f, 0.0, 0.5 * NOMINAL_IMAGE_WIDTH, 0.0, 0.0, f, NOMINAL["P2"][6], 0.0, 0.0, 0.0, 1.0, 0.0])
    Tr = NOMINAL["Tr_velo_to_cam"].copy()
    Tr[11] = 0.0  # z_cam = x_velo: the camera's optical centre above the Velodyne's
    return calib_from_values({"P2": P2, "Tr_velo_to_cam": Tr}, [])


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


def imu_motion(T_imu: np.ndarray, dt: float) -> dict[str, np.ndarray]:
    """Planar motion of the IMU path ``T_imu`` (F, 4, 4), sampled every ``dt`` s: world velocity (v_east, v_north),
    acceleration (a_east, a_north), yaw rate, and the velocity and acceleration in the vehicle frame (forward,
    left). Central differences of the positions and of the unwrapped heading (one-sided at the ends), so that
    integrating them (trapezoid rule) gives back the path to second order in dt."""
    F = len(T_imu)
    yaw = np.unwrap(np.arctan2(T_imu[:, 1, 0], T_imu[:, 0, 0]))
    if F < 2:
        z2 = np.zeros((F, 2))
        return {"v": z2, "a": z2.copy(), "yaw_rate": np.zeros(F), "v_body": z2.copy(), "a_body": z2.copy()}
    v = np.gradient(T_imu[:, :2, 3], dt, axis=0)
    a = np.gradient(v, dt, axis=0)
    c, s = np.cos(yaw), np.sin(yaw)

    def body(x: np.ndarray) -> np.ndarray:  # world (east, north) -> vehicle (forward, left)
        return np.column_stack([c * x[:, 0] + s * x[:, 1], -s * x[:, 0] + c * x[:, 1]])

    return {"v": v, "a": a, "yaw_rate": np.gradient(yaw, dt), "v_body": body(v), "a_body": body(a)}


def oxts_text(egos: np.ndarray, calib, dt: float) -> str:
    """Packets whose devkit poses (:func:`~soabench.kitti.formats.poses_from_oxts`) give the Velodyne path ``egos``,
    with the IMU's velocities, accelerations and yaw rate along it (:func:`imu_motion`; the ego stays level: roll,
    pitch, vertical velocity and the other angular rates are 0, az = au = g)."""
    T_imu = np.array([_pose4(e) @ calib.Tr_imu_velo for e in egos])
    scale = lat_to_scale(ORIGIN_LAT)
    mx0, my0 = latlon_to_mercator(ORIGIN_LAT, ORIGIN_LON, scale)
    lat, lon = mercator_to_latlon(mx0 + T_imu[:, 0, 3] - T_imu[0, 0, 3], my0 + T_imu[:, 1, 3] - T_imu[0, 1, 3], scale)
    lat[0] = ORIGIN_LAT  # exactly: the reader takes the Mercator scale from it
    yaw = np.arctan2(T_imu[:, 1, 0], T_imu[:, 0, 0])
    mo = imu_motion(T_imu, dt)
    (ve, vn), (vf, vl), (ax, ay), wz = mo["v"].T, mo["v_body"].T, mo["a_body"].T, mo["yaw_rate"]
    rows = []
    for i in range(len(egos)):
        packet = np.zeros(30)
        packet[:6] = [lat[i], lon[i], T_imu[i, 2, 3], 0.0, 0.0, yaw[i]]
        packet[6:11] = [vn[i], ve[i], vf[i], vl[i], 0.0]  # vn ve vf vl vu
        packet[11:17] = [ax[i], ay[i], GRAVITY, ax[i], ay[i], GRAVITY]  # ax ay az af al au
        packet[17:23] = [0.0, 0.0, wz[i], 0.0, 0.0, wz[i]]  # wx wy wz wf wl wu
        packet[25:30] = [4, 10, 4, 4, 6]  # navstat numsats posmode velmode orimode (RTK-like)
        rows.append(_fmt(packet[:25]) + " " + " ".join(str(int(v)) for v in packet[25:]))
    return "\n".join(rows) + "\n"


def _object_row(frame, tid, typ, truncated, occluded, bbox, hwl, xyz, ry, score=None) -> str:
    """One row in the devkit's field order: frame, track id, type, truncated, occluded, alpha, 2-D box (left, top,
    right, bottom; px), h w l (m), x y z (bottom centre, camera frame, m), rotation_y (rad)[, score]."""
    alpha = float(wrap(ry - math.atan2(xyz[0], xyz[2])))
    row = f"{frame} {tid} {typ} {truncated} {occluded} {alpha!r} {_fmt(bbox)} {_fmt(hwl)} {_fmt(xyz)} {float(ry)!r}"
    return row if score is None else f"{row} {float(score)!r}"


def _seen(calib, hwl, xyz, ry) -> tuple[np.ndarray, int] | None:
    """The 2-D box and truncation level of a box the camera sees with its centre in front of it, else None."""
    return image_box(calib.P2, hwl, xyz, ry) if xyz[2] > 0.0 else None


def pedestrian_row(
    frame: int,
    tid: int,
    xy: np.ndarray,
    heading: float,
    ego: np.ndarray,
    calib,
    r_max: float,
    occluded: int,
    score: float | None = None,
) -> str | None:
    """The row of a pedestrian box at world position ``xy`` walking along world ``heading`` (rad; NaN: unknown,
    written as rotation_y 0), if it is within ``r_max`` of the ego and the camera sees it; else None."""
    p = ego_frame(xy, ego)[0]
    if math.hypot(p[0], p[1]) > r_max:
        return None
    xyz = calib.velo_to_rect_pts([p[0], p[1], GROUND_Z])[0]
    heading_ego = float(heading) - float(ego[2])
    ry = _ry(calib, heading_ego) if math.isfinite(heading_ego) else 0.0
    seen = _seen(calib, PED_HWL, xyz, ry)
    if seen is None:
        return None
    return _object_row(frame, tid, "Pedestrian", seen[1], occluded, seen[0], PED_HWL, xyz, ry, score)


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


def export_trial(trial: int, recording, scans, scene, sensor: SensorConfig, calib, out: Path, seed: int) -> dict:
    """Write sequence ``trial`` (all five files); returns counts."""

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
            occ = 0 if scans.visible[k, i] else (2 if scans.in_fov[k, i] else 3)
            heading = float(recording.ped_heading[idx, i])
            row = pedestrian_row(k, int(i), scans.truth_xy[k, i], heading, ego, calib, sensor.r_max, occ)
            if row is not None:
                labels.append(row)
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
            centre, length, width, heading = _box(ego_frame(corners, ego))
            xyz = calib.velo_to_rect_pts([centre[0], centre[1], GROUND_Z])[0]
            ry = _ry(calib, heading)
            seen = _seen(calib, (CAR_H, width, length), xyz, ry)
            if seen is not None:
                row = (k, tid, "Car", seen[1], 0, seen[0], (CAR_H, width, length), xyz, ry)
                labels.append(_object_row(*row))
                dets.append(_object_row(*row, 1.0))
        # measurements in scan order
        Z, src = scan.Z, scans.source[k]
        scores = np.where(src >= 0, rng.uniform(0.5, 1.0, len(Z)), rng.uniform(0.0, 1.0, len(Z)))
        for (r, b), s, sc in zip(Z, src, scores, strict=True):
            xyz = calib.velo_to_rect_pts([r * math.cos(b), r * math.sin(b), GROUND_Z])[0]
            seen = _seen(calib, PED_HWL, xyz, 0.0)
            if seen is not None:
                dets.append(_object_row(k, int(s), "Pedestrian", seen[1], 0, seen[0], PED_HWL, xyz, 0.0, sc))
                n_meas += 1
        # semantics: sidewalk within r_max (+1 m), buildings within r_max
        disk = ego_pt.buffer(sensor.r_max + 1.0, 64)
        for piece in hole_free(shapely.intersection(sidewalk, disk)):
            xy = ego_frame(np.asarray(piece.exterior.coords)[:-1], ego)
            sem.append(f"{k} sidewalk {_fmt(xy)}")
        for g, ring in zip(building_geoms, buildings, strict=True):
            if g.distance(ego_pt) <= sensor.r_max:
                sem.append(f"{k} building {_fmt(ego_frame(ring, ego))}")
    egos = np.array([s.ego for s in scans.scans])
    for folder, text in (
        (LABEL_DIR, "\n".join(labels)), (DETECTION_DIR, "\n".join(dets)), (SEMANTICS_DIR, "\n".join(sem)),
        (OXTS_DIR, oxts_text(egos, calib, float(sensor.dt)).rstrip("\n")), (CALIB_DIR, calib_text(calib).rstrip("\n")),
    ):  # fmt: skip
        write_text_atomic(out / folder / f"{seq}.txt", text + "\n" if text else "")
    return {"sequence": seq, "frames": len(scans), "pedestrians": P, "measurements": n_meas}


def check_export_size(trials: int, duration: float | None) -> None:
    """``trials`` sequences (ids 0000-9999) of ``duration`` seconds each (None: the scenario's)."""
    require(
        isinstance(trials, int) and 1 <= trials <= MAX_EXPORT_TRIALS,
        f"--trials {trials!r} is out of range; allowed: integers in [1, {MAX_EXPORT_TRIALS}] (sequence ids 0000-9999)",
    )
    check_time("--duration", duration)


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
    lidar: bool = False,
) -> list[dict]:
    """Simulate, observe and write ``trials`` SUMO trials as KITTI sequences 0000, 0001, ... under ``out`` (with
    ``lidar``, also their synthetic segmented scans: :mod:`soabench.kitti.raycast`)."""

    check_export_size(trials, duration)
    out = resolve(out)
    check_new_folder(out, EXPORT_FILE, "KITTI export", "remove it to export again")
    fov = float(fov_deg) if fov_deg is not None else export_default_fov(cfg.sensor)
    require(0.0 < fov < 180.0, f"--fov-deg {fov!r} must be in (0, 180): a camera's horizontal field of view")
    sensor = dataclasses.replace(cfg.sensor_at(), fov_deg=fov)
    calib = export_calib(sensor)
    scene, scen = sumo_scenario.load(net, polys, scenario)
    sensor.validate(scen.step_length)
    dur = float(scen.duration) if duration is None else float(duration)
    require(dur > 0, f"--duration {dur!r} must be > 0")
    with FolderLock(out, "export folder"):
        check_new_folder(out, EXPORT_FILE, "KITTI export", "remove it to export again")  # again, under the lock
        return _export_trials(cfg, (net, polys, scenario), (scene, scen), trials, out, dur, sensor, calib, log, lidar)


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
    lidar: bool,
) -> list[dict]:
    """The trials of :func:`export_kitti` written into the checked and locked folder ``out``; ``export.json`` last."""

    (net, polys, scenario), (scene, scen) = source, loaded
    rows = []
    for n in range(trials):
        seeds = trial_seeds(cfg.experiment.seed, n)
        recording = sumo_scenario.simulate(scene, scen, seeds, duration=dur)
        scans = observe(recording, scene, sensor, seeds.sensor_rngs())
        rows.append(export_trial(n, recording, scans, scene, sensor, calib, out, cfg.experiment.seed))
        if lidar:
            rows[-1]["lidar_points"] = export_lidar(n, recording, scans, scene, sensor, out)
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
