"""Synthetic segmented LiDAR scans of SUMO scenes (``soabench export kitti --lidar``; docs/user-guide/kitti.md,
"Synthetic LiDAR scans").

A 2.5-D ray-cast from the Velodyne (the ego frame's origin, ``GROUND_Z`` = 1.73 m above the ground) in the KITTI
HDL-64E's pattern: ``BEAMS`` = 64 beams evenly spaced in elevation from -24.8 deg to +2 deg, azimuths every
0.17 deg x ``AZIMUTH_SUBSAMPLE`` (= 0.68 deg, which keeps a 10 Hz sequence's files about four times smaller than
KITTI's). Each ray returns its first hit within r_max:

* the ground plane z = GROUND_Z, labelled sidewalk (48) inside the scene's sidewalk and road (40) elsewhere;
* the walls of the buildings, extruded to ``BUILDING_H`` (50, building);
* the walls of the vehicle and parked-car boxes, ``CAR_H`` tall (10, car);
* pedestrians as vertical cylinders of radius ``PED_RADIUS`` and ``PED_HWL[0]`` tall (30, person).

Walls only (2.5-D): a ray that passes over an object's near wall goes on (roofs are not hit). Points are written in
the KITTI layout, ``velodyne/XXXX/NNNNNN.bin`` (float32 x y z intensity, intensity 0) and
``point_labels/XXXX/NNNNNN.label`` (uint32 SemanticKITTI class ids, instance 0).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import Point, Polygon

from soabench.config import SensorConfig
from soabench.kitti.lidar import SEMANTIC_KITTI_IDS
from soabench.kitti.velodyne import CAR_H, GROUND_Z, PED_HWL, ego_frame
from soabench.sensor import _static_occluder_arrays, scan_steps

VELODYNE_DIR, POINT_LABEL_DIR = "velodyne", "point_labels"
BEAMS = 64
ELEVATION_DEG = (-24.8, 2.0)  #: lowest and highest beam (deg)
AZIMUTH_STEP_DEG = 0.17  #: HDL-64E horizontal resolution at 10 Hz
AZIMUTH_SUBSAMPLE = 4  #: every 4th azimuth is cast
BUILDING_H = 10.0  #: building height above the ground (m)
PED_RADIUS = 0.3  #: pedestrian cylinder radius (m)
ROAD, SIDEWALK, BUILDING, CAR, PERSON = (
    SEMANTIC_KITTI_IDS[n][0] for n in ("road", "sidewalk", "building", "car", "person")
)


def beam_pattern() -> tuple[np.ndarray, np.ndarray]:
    """(A,) azimuths and (B,) elevations (rad) of the cast rays."""
    step = math.radians(AZIMUTH_STEP_DEG * AZIMUTH_SUBSAMPLE)
    az = -math.pi + step * np.arange(int(2 * math.pi / step))
    el = np.radians(np.linspace(ELEVATION_DEG[0], ELEVATION_DEG[1], BEAMS))
    return az, el


def _wall_distances(u: np.ndarray, rings: list[np.ndarray]) -> np.ndarray:
    """(A, n) horizontal distance along each direction ``u`` (A, 2) to the first wall of each closed ring (inf:
    missed)."""
    if not rings:
        return np.zeros((len(u), 0))
    p0 = np.concatenate(rings)
    p1 = np.concatenate([np.roll(r, -1, axis=0) for r in rings])
    e = p1 - p0
    den = u[:, None, 0] * e[None, :, 1] - u[:, None, 1] * e[None, :, 0]  # cross(u, e)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (p0[None, :, 0] * e[None, :, 1] - p0[None, :, 1] * e[None, :, 0]) / den  # cross(p0, e) / cross(u, e)
        s = (p0[None, :, 0] * u[:, None, 1] - p0[None, :, 1] * u[:, None, 0]) / den  # cross(p0, u) / cross(u, e)
    t = np.where((den != 0) & (t > 0) & (s >= 0) & (s <= 1), t, np.inf)
    starts = np.cumsum([0] + [len(r) for r in rings[:-1]])
    return np.minimum.reduceat(t, starts, axis=1)


def _cylinder_distances(u: np.ndarray, centres: np.ndarray, radius: float) -> np.ndarray:
    """(A, n) horizontal distance along each direction to the near side of each circle (inf: missed)."""
    if len(centres) == 0:
        return np.zeros((len(u), 0))
    proj = u @ centres.T
    disc = radius**2 - ((centres**2).sum(axis=1)[None, :] - proj**2)
    t = proj - np.sqrt(np.maximum(disc, 0.0))
    return np.where((disc >= 0) & (t > 0), t, np.inf)


def cast(
    rings: list[np.ndarray], tops: np.ndarray, ring_labels: np.ndarray, peds: np.ndarray, r_max: float
) -> tuple[np.ndarray, np.ndarray]:
    """One scan in the ego frame: (N, 3) points and (N,) class ids, ground hits labelled ROAD (the caller relabels
    the sidewalk). ``rings``: wall footprints (ego frame) with their top heights above the ground and labels."""
    az, el = beam_pattern()
    u = np.column_stack([np.cos(az), np.sin(az)])
    D = np.concatenate([_wall_distances(u, rings), _cylinder_distances(u, peds, PED_RADIUS)], axis=1)  # (A, n)
    top = np.concatenate([tops, np.full(len(peds), PED_HWL[0])]) + GROUND_Z
    lab = np.concatenate([ring_labels, np.full(len(peds), PERSON)]).astype(np.uint32)
    tan = np.tan(el)
    ground = np.where(tan < 0, GROUND_Z / np.where(tan < 0, tan, -1.0), np.inf)  # (B,)
    z = D[:, None, :] * tan[None, :, None]  # (A, B, n) height at each wall
    hit = (z <= top[None, None, :]) & (D[:, None, :] < ground[None, :, None])
    Dh = np.where(hit, D[:, None, :], np.inf)
    j = np.argmin(Dh, axis=2) if D.shape[1] else np.zeros((len(az), len(el)), dtype=int)
    d_obj = np.take_along_axis(Dh, j[..., None], axis=2)[..., 0] if D.shape[1] else np.full((len(az), len(el)), np.inf)
    d = np.minimum(d_obj, ground[None, :])
    label = np.where(d_obj <= ground[None, :], lab[j] if len(lab) else ROAD, ROAD)
    keep = d <= r_max
    a_i, b_i = np.nonzero(keep)
    r = d[keep]
    pts = np.column_stack([r * u[a_i, 0], r * u[a_i, 1], r * tan[b_i]])
    return pts, label[keep].astype(np.uint32)


def export_lidar(trial: int, recording, scans, scene, sensor: SensorConfig, out: Path) -> int:
    """Write the scans and labels of sequence ``trial``; returns the number of points written."""

    seq = f"{trial:04d}"
    steps = scan_steps(recording.t, recording.step_length, sensor.dt)
    statics, kinds = _static_occluder_arrays(recording, scene)
    static_geoms = [Polygon(p) for p in statics]
    static_tops = [BUILDING_H if kd == "building" else CAR_H for kd in kinds]
    static_labels = [BUILDING if kd == "building" else CAR for kd in kinds]
    sidewalk = scene.sidewalk
    shapely.prepare(sidewalk)
    folders = [out / VELODYNE_DIR / seq, out / POINT_LABEL_DIR / seq]
    for f in folders:
        f.mkdir(parents=True, exist_ok=True)
    n_points = 0
    reach = sensor.r_max + 1.0
    for k, scan in enumerate(scans.scans):
        ego, idx = scan.ego, int(steps[k])
        ego_pt = Point(ego[:2])
        rings, tops, labels = [], [], []
        for g, ring, top, lab in zip(static_geoms, statics, static_tops, static_labels, strict=True):
            if g.distance(ego_pt) <= reach:
                rings.append(ego_frame(ring, ego))
                tops.append(top)
                labels.append(lab)
        foot = np.asarray(recording.veh_footprint[idx], dtype=float).reshape(-1, 4, 2)
        pres = np.asarray(recording.veh_present[idx], dtype=bool).reshape(-1)
        for v in np.flatnonzero(pres & np.isfinite(foot).all(axis=(1, 2))):
            ring = ego_frame(foot[v], ego)
            if np.hypot(ring[:, 0], ring[:, 1]).min() <= reach:
                rings.append(ring)
                tops.append(CAR_H)
                labels.append(CAR)
        present = np.flatnonzero(scans.present[k])
        peds = ego_frame(scans.truth_xy[k, present], ego) if len(present) else np.zeros((0, 2))
        peds = peds[np.hypot(peds[:, 0], peds[:, 1]) <= reach]
        pts, lab = cast(rings, np.asarray(tops, dtype=float), np.asarray(labels, dtype=np.uint32), peds, sensor.r_max)
        ground = lab == ROAD
        c, s = math.cos(ego[2]), math.sin(ego[2])
        wx = ego[0] + c * pts[ground, 0] - s * pts[ground, 1]
        wy = ego[1] + s * pts[ground, 0] + c * pts[ground, 1]
        lab[np.flatnonzero(ground)[shapely.contains_xy(sidewalk, wx, wy)]] = SIDEWALK
        rows = np.column_stack([pts, np.zeros(len(pts))]).astype("<f4")
        _write(folders[0] / f"{k:06d}.bin", rows.tobytes())
        _write(folders[1] / f"{k:06d}.label", lab.astype("<u4").tobytes())
        n_points += len(pts)
    return n_points


def _write(path: Path, data: bytes) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)
