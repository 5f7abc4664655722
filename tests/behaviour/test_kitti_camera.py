"""The KITTI export read with the KITTI tracking devkit's conventions (docs/user-guide/outputs.md, "The KITTI
export"): label_02 field order and units, the camera frame (x right, y down, z forward), rotation_y and alpha, 2-D
boxes projected with P2 and clipped to the image, only what the camera sees; oxts packets whose velocities,
accelerations and yaw rate integrate back to the ego's motion; TrackEval's KITTI reader accepting the files."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from soabench.cli.main import main
from soabench.kitti.config import kitti_base_config
from soabench.kitti.export import GRAVITY, GROUND_Z, PED_HWL, export_calib, export_default_fov, oxts_text
from soabench.kitti.formats import lat_to_scale, latlon_to_mercator, parse_calib, parse_objects
from soabench.kitti.reader import centres_ego, footprints_ego

pytestmark = pytest.mark.slow  # a KITTI export from SUMO runs

DURATION = 30.0
W, H = 1242, 375


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("kitti_cam") / "export"
    assert main(["export", "kitti", "--trials", "1", "--duration", str(DURATION), "--out", str(out)]) == 0
    return out


def _rows(path):
    return [line.split() for line in path.read_text().splitlines() if line.strip()]


def test_label_rows_follow_the_devkit_field_order_and_units(exported):
    rows = _rows(exported / "label_02" / "0000.txt")
    r_max = kitti_base_config().sensor.r_max
    n_frames = len(_rows(exported / "oxts" / "0000.txt"))
    assert len(rows) > 100 and {r[2] for r in rows} == {"Pedestrian", "Car"}
    for r in rows:
        assert len(r) == 17
        frame, tid, trunc, occ = int(r[0]), int(r[1]), int(r[3]), int(r[4])  # integers, as the devkit writes them
        assert 0 <= frame < n_frames and tid >= 0 and trunc in (0, 1, 2) and occ in (0, 1, 2, 3)
        alpha, (left, top, right, bottom) = float(r[5]), map(float, r[6:10])
        h, w, length = map(float, r[10:13])
        x, y, z, ry = map(float, r[13:17])
        assert 0.0 <= left <= right <= W - 1 and 0.0 <= top <= bottom <= H - 1  # pixels, clipped to the image
        assert h > 0 and w > 0 and length > 0
        if r[2] == "Pedestrian":
            assert (h, w, length) == PED_HWL and math.hypot(x, z) <= r_max
        # bottom centre on the ground, 1.65 m below the camera (y down), in front of it (z forward)
        assert y == pytest.approx(-GROUND_Z - 0.08, abs=1e-9) and z > 0.0
        assert -math.pi <= ry <= math.pi and -math.pi <= alpha <= math.pi
        assert math.isclose(math.remainder(alpha - (ry - math.atan2(x, z)), 2 * math.pi), 0.0, abs_tol=1e-9)


def test_boxes_are_the_projection_of_the_3d_box_with_p2_in_the_camera_frame(exported):
    """The corners from the reader's own footprint (rotation_y as the reader reads it) and the box height, projected
    with the calib file's P2: their bounding box clipped to the image is the row's 2-D box."""
    calib = parse_calib(exported / "calib" / "0000.txt")
    lab, _ = parse_objects(exported / "label_02" / "0000.txt", "label")
    rows = _rows(exported / "label_02" / "0000.txt")
    box = np.array([[float(v) for v in r[6:10]] for r in rows])
    trunc = np.array([int(r[3]) for r in rows])
    feet = footprints_ego(lab, calib)  # (N, 4, 2) ego frame
    n_checked = 0
    for i in np.flatnonzero(trunc == 0):  # wholly in the image: nothing clipped
        ground = np.column_stack([feet[i], np.full(4, GROUND_Z)])
        top = ground + [0.0, 0.0, lab.hwl[i, 0]]
        X = calib.velo_to_rect_pts(np.vstack([ground, top]))
        assert (X[:, 2] > 0.1).all()
        uvw = np.column_stack([X, np.ones(8)]) @ calib.P2.T
        uv = uvw[:, :2] / uvw[:, 2:]
        np.testing.assert_allclose(box[i], [*uv.min(axis=0), *uv.max(axis=0)], atol=1e-6)
        n_checked += 1
    assert n_checked > 50
    # camera axes: x right = -y_ego (left), z forward = x_ego; a target on the left is left of the image centre
    ego = centres_ego(lab, calib)
    np.testing.assert_allclose(lab.xyz[:, 0], -ego[:, 1], atol=1e-9)
    np.testing.assert_allclose(lab.xyz[:, 2], ego[:, 0], atol=1e-9)
    u_centre = 0.5 * (box[:, 0] + box[:, 2])
    clear = (trunc == 0) & (np.abs(ego[:, 1]) > 1.0)
    assert clear.sum() > 20 and ((u_centre[clear] < calib.P2[0, 2]) == (ego[clear, 1] > 0)).all()


def test_only_what_the_camera_sees_is_labelled(exported):
    """The camera's horizontal FOV is the sensor's sector: a row whose centre lies outside it is a truncated box at the
    image border (occluded 3), every other row's centre projects into the image."""
    calib = parse_calib(exported / "calib" / "0000.txt")
    sensor = dataclasses.replace(kitti_base_config().sensor, fov_deg=export_default_fov(kitti_base_config().sensor))
    assert calib.fov_deg(W) == pytest.approx(sensor.fov_deg, abs=1e-9)
    rows = _rows(exported / "label_02" / "0000.txt")
    peds = [r for r in rows if r[2] == "Pedestrian"]
    x, z = (np.array([float(r[c]) for r in peds]) for c in (13, 15))
    in_sector = np.abs(np.arctan2(x, z)) <= 0.5 * sensor.fov
    trunc, occ = (np.array([int(r[c]) for r in peds]) for c in (3, 4))
    assert in_sector.sum() > 50
    assert (trunc[~in_sector] >= 1).all() and (occ[~in_sector] == 3).all() and (occ[in_sector] != 3).all()
    u = calib.P2[0, 0] * x / z + calib.P2[0, 2]
    assert ((u[in_sector] >= 0.0) & (u[in_sector] <= W)).all()
    # detections: every Pedestrian detection (measurement) the camera reports has a box in the image
    dets = [r for r in _rows(exported / "detections" / "0000.txt") if r[2] == "Pedestrian"]
    assert dets and all(len(r) == 18 and float(r[15]) > 0 and 0 <= float(r[6]) <= float(r[8]) <= W - 1 for r in dets)


# ---------------------------------------------------------------------------------------------------------------------
# oxts


def _integrates_back(oxts: np.ndarray, dt: float, tol_pos: float, tol_vel: float) -> None:
    """Velocities, accelerations and yaw rate of OXTS packets integrate (trapezoid rule) back to the packets' own
    positions (Mercator, devkit convention), velocities and headings."""
    scale = lat_to_scale(oxts[0, 0])
    mx, my = latlon_to_mercator(oxts[:, 0], oxts[:, 1], scale)
    yaw, vn, ve, vf, vl = oxts[:, 5], oxts[:, 6], oxts[:, 7], oxts[:, 8], oxts[:, 9]
    ax, ay, az, af, al, au, wz, wu = (oxts[:, c] for c in (11, 12, 13, 14, 15, 16, 19, 22))

    def integral(rate):
        return np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * dt)])

    np.testing.assert_allclose(integral(ve), mx - mx[0], atol=tol_pos)
    np.testing.assert_allclose(integral(vn), my - my[0], atol=tol_pos)
    heading = np.unwrap(yaw)
    np.testing.assert_allclose(integral(wz), heading - heading[0], atol=tol_pos)
    c, s = np.cos(yaw), np.sin(yaw)
    np.testing.assert_allclose(vf, c * ve + s * vn, atol=1e-9)  # vehicle frame: forward, left
    np.testing.assert_allclose(vl, -s * ve + c * vn, atol=1e-9)
    a_east, a_north = c * ax - s * ay, s * ax + c * ay
    np.testing.assert_allclose(integral(a_east), ve - ve[0], atol=tol_vel)
    np.testing.assert_allclose(integral(a_north), vn - vn[0], atol=tol_vel)
    np.testing.assert_array_equal(af, ax)  # a level ego: parallel to the earth's surface = vehicle frame
    np.testing.assert_array_equal(al, ay)
    np.testing.assert_array_equal(wu, wz)
    assert (az == GRAVITY).all() and (au == GRAVITY).all()  # specific force: the accelerometer at rest reads +g


def test_exported_oxts_integrate_back_to_the_ego_motion(exported):
    oxts = np.loadtxt(exported / "oxts" / "0000.txt")
    assert oxts.shape[1] == 30
    speed = np.hypot(oxts[:, 6], oxts[:, 7])
    assert speed.mean() > 1.0  # the ego moves, and the packets say so
    _integrates_back(oxts, 0.1, tol_pos=0.02, tol_vel=0.05)


def test_oxts_of_a_turning_accelerating_path_integrate_back():
    """A path with a turn and a changing speed: heading, speed and position all vary."""
    dt = 0.1
    t = np.arange(0.0, 30.0, dt)
    speed = 3.0 + 1.5 * np.sin(0.2 * t)
    theta = 0.6 * np.sin(0.15 * t)  # the Velodyne's heading
    x = np.concatenate([[0.0], np.cumsum(speed[:-1] * np.cos(theta[:-1]) * dt)])
    y = np.concatenate([[0.0], np.cumsum(speed[:-1] * np.sin(theta[:-1]) * dt)])
    calib = export_calib(dataclasses.replace(kitti_base_config().sensor, fov_deg=80.0))
    text = oxts_text(np.column_stack([x, y, theta]), calib, dt)
    oxts = np.array([[float(v) for v in line.split()] for line in text.splitlines()])
    assert np.ptp(oxts[:, 19]) > 0.1 and np.ptp(np.hypot(oxts[:, 6], oxts[:, 7])) > 1.0
    _integrates_back(oxts, dt, tol_pos=0.02, tol_vel=0.05)


# ---------------------------------------------------------------------------------------------------------------------
# TrackEval's KITTI 2-D box reader


def test_trackeval_reads_the_export(exported, tmp_path, trackeval_kitti):
    """TrackEval's KITTI 2-D box dataset reads label_02 as ground truth and a tracker file in the same format:
    the labels themselves score HOTA = MOTA = IDF1 = 1 for both classes; swapping two cars' ids halfway through the
    frames they share costs identity switches."""
    rows = _rows(exported / "label_02" / "0000.txt")
    n_frames = len(_rows(exported / "oxts" / "0000.txt"))
    gt = tmp_path / "gt"
    (gt / "label_02").mkdir(parents=True)
    (gt / "label_02" / "0000.txt").write_text((exported / "label_02" / "0000.txt").read_text())
    (gt / "evaluate_tracking.seqmap.training").write_text(f"0000 empty 000000 {n_frames:06d}\n")
    frames: dict[int, set[int]] = {}  # the frames of each evaluated (untruncated) car
    for r in rows:
        if r[2] == "Car" and int(r[3]) == 0:
            frames.setdefault(int(r[1]), set()).add(int(r[0]))
    cars = sorted(frames)
    common, a, b = max((len(frames[a] & frames[b]), a, b) for i, a in enumerate(cars) for b in cars[i + 1 :])
    assert common >= 10
    swap = {a: b, b: a}
    at = sorted(frames[a] & frames[b])[common // 2]  # the two cars swap ids from here on
    for name, ids in (("perfect", {}), ("swapped", swap)):
        folder = tmp_path / "trackers" / name / "data"
        folder.mkdir(parents=True)
        out = []
        for r in rows:
            tid = ids.get(int(r[1]), int(r[1])) if int(r[0]) >= at else int(r[1])
            out.append(" ".join([r[0], str(tid), *r[2:], "1.0"]))
        (folder / "0000.txt").write_text("\n".join(out) + "\n")
    res = trackeval_kitti(gt, tmp_path / "trackers", ["perfect", "swapped"], ["car", "pedestrian"])
    for cls in ("car", "pedestrian"):
        r = res["perfect"][cls]
        assert r["CLEAR"]["CLR_TP"] > 0
        assert np.allclose(r["HOTA"]["HOTA"], 1.0) and r["CLEAR"]["MOTA"] == 1.0 and r["Identity"]["IDF1"] == 1.0
    s = res["swapped"]["car"]
    assert s["CLEAR"]["IDSW"] > 0 and s["HOTA"]["HOTA"].mean() < 1.0
