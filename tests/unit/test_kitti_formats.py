"""KITTI file formats and the reader's geometry, on hand-made files (no SUMO)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from kitti_files import ab3dmot_rows, write_dataset, write_sequence

from soabench.config import Sensor
from soabench.experiment.campaigns.kitti.protocol import fold_partition, n_hat, sweep_n_hat
from soabench.kitti.config import KittiConfig, kitti_from_dict
from soabench.kitti.formats import (
    EARTH_RADIUS,
    latlon_to_mercator,
    mercator_to_latlon,
    nominal_calib,
    parse_calib,
    parse_objects,
    poses_from_oxts,
)
from soabench.kitti.reader import footprints_ego, open_dataset, parse_sequences, read_sequence, to_scans

SENSOR = Sensor(dt=0.1, r_max=50.0)


def test_mercator_round_trip_and_scale():
    scale = math.cos(math.radians(49.0))
    mx, my = latlon_to_mercator(np.array([49.0, 49.001]), np.array([8.43, 8.431]), scale)
    lat, lon = mercator_to_latlon(mx, my, scale)
    assert np.allclose(lat, [49.0, 49.001], atol=1e-12) and np.allclose(lon, [8.43, 8.431], atol=1e-12)
    # 0.001 deg of longitude at 49 N is scale * er * pi / 180 * 0.001 m east
    assert mx[1] - mx[0] == pytest.approx(scale * EARTH_RADIUS * math.pi / 180 * 0.001, rel=1e-9)


def test_poses_start_at_identity_and_follow_yaw():
    # first packet heading north (yaw = pi/2); the second 10 m further north and turned to west (yaw = pi)
    scale = math.cos(math.radians(49.0))
    mx, my = latlon_to_mercator(49.0, 8.43, scale)
    lat2, lon2 = mercator_to_latlon(mx, my + 10.0, scale)
    oxts = np.array([[49.0, 8.43, 0.0, 0.0, 0.0, math.pi / 2], [lat2, lon2, 0.0, 0.0, 0.0, math.pi]])
    T = poses_from_oxts(oxts)
    assert np.allclose(T[0], np.eye(4), atol=1e-12)
    # in the first IMU frame (x = north there): 10 m straight ahead, heading turned left by 90 deg
    assert np.allclose(T[1][:3, 3], [10.0, 0.0, 0.0], atol=1e-6)
    assert math.atan2(T[1][1, 0], T[1][0, 0]) == pytest.approx(math.pi / 2)


def test_calib_accepts_tracking_and_object_key_spellings(tmp_path):
    tr = "0 -1 0 0.5 0 0 -1 0 1 0 0 -0.3"
    a = tmp_path / "a.txt"
    a.write_text(f"P2: 700 0 600 0 0 700 180 0 0 0 1 0\nR_rect 1 0 0 0 1 0 0 0 1\nTr_velo_cam {tr}\n")
    b = tmp_path / "b.txt"
    b.write_text(f"P2: 700 0 600 0 0 700 180 0 0 0 1 0\nR0_rect: 1 0 0 0 1 0 0 0 1\nTr_velo_to_cam: {tr}\n")
    ca, cb = parse_calib(a), parse_calib(b)
    assert np.array_equal(ca.velo_to_rect, cb.velo_to_rect)
    assert ca.nominal == ["Tr_imu_to_velo"]
    assert ca.fov_deg(1242) == pytest.approx(2 * math.degrees(math.atan(621 / 700)))
    # a point 10 m ahead of the Velodyne is 10.3 m ahead of (and 0.5 m right of) this camera
    assert np.allclose(ca.velo_to_rect_pts([10.0, 0.0, 0.0]), [[0.5, 0.0, 9.7]])
    assert np.allclose(ca.rect_to_velo(ca.velo_to_rect_pts([[3.0, -2.0, 1.0]])), [[3.0, -2.0, 1.0]])


def test_nominal_calib_axes():
    c = nominal_calib()
    # camera forward (z) is Velodyne x; camera right (x) is Velodyne -y; the camera is 0.27 m ahead of the Velodyne
    v = c.rect_to_velo([[1.0, 0.0, 10.0]])[0]
    assert v[0] == pytest.approx(10.27) and v[1] == pytest.approx(-1.0)
    assert c.fov_deg() == pytest.approx(81.43, abs=0.01)


def test_box_footprint_orientation():
    """rotation_y = -pi/2 points the box length along the camera's forward axis = the Velodyne x axis."""
    from soabench.kitti.formats import Objects

    obj = Objects(
        frame=np.array([0]), track_id=np.array([1]), type=np.array(["Car"]), occluded=np.array([0]),
        hwl=np.array([[1.5, 2.0, 4.0]]), xyz=np.array([[0.0, 1.65, 20.0]]), ry=np.array([-math.pi / 2]),
        score=np.array([1.0]), line=np.array([1]),
    )  # fmt: skip
    corners = footprints_ego(obj, nominal_calib())[0]
    ext = corners.max(axis=0) - corners.min(axis=0)
    assert ext == pytest.approx([4.0, 2.0])
    assert corners.mean(axis=0) == pytest.approx([20.27, 0.0])


def test_ab3dmot_and_result_formats_give_the_same_measurements(tmp_path):
    write_dataset(tmp_path / "a", n=2)
    write_dataset(tmp_path / "b", n=2)
    for seq in ("0000", "0001"):
        p = tmp_path / "b" / "detections" / f"{seq}.txt"
        p.write_text(ab3dmot_rows(p.read_text()))
    kc = KittiConfig()
    za = to_scans(read_sequence(open_dataset(tmp_path / "a"), "0001"), kc, SENSOR)
    seq_b = read_sequence(open_dataset(tmp_path / "b"), "0001")
    assert seq_b.det_format == "ab3dmot"
    zb = to_scans(seq_b, kc, SENSOR)
    assert all(np.array_equal(a.Z, b.Z) for a, b in zip(za.scans.scans, zb.scans.scans, strict=True))
    # score threshold: the clutter rows (score 0.2) go
    kept = to_scans(seq_b, kitti_from_dict({"score_min": 0.5}), SENSOR)
    assert sum(len(s.Z) for s in kept.scans.scans) == 12
    assert kept.info["below_score"] == 4


def test_reader_truth_measurements_and_sources(tmp_path):
    write_sequence(tmp_path, "0000")
    ss = to_scans(read_sequence(open_dataset(tmp_path), "0000"), KittiConfig(), SENSOR)
    s = ss.scans
    assert list(s.ped_ids) == ["0"] and len(s) == 12 and s.dt == 0.1
    # pedestrian at camera (x, z) = (-3 + 0.5 k, 15): Velodyne (15.27, 3 - 0.5 k); the oxts packets do not move, so
    # the Velodyne sits at its nominal offset from the IMU (0.81 m ahead, 0.32 m right) in the first IMU frame
    k = 4
    assert s.scans[k].ego == pytest.approx([0.81, -0.32, 0.0])
    assert s.truth_xy[k, 0] - s.scans[k].ego[:2] == pytest.approx([15.27, 1.0])
    assert s.present.all() and s.in_fov.all() and s.visible.all() and s.detected.all()
    # the pedestrian's detection is matched to it, the clutter row (at 30 m) is not
    assert sorted(s.source[0].tolist()) == [-1, 0] and s.source[1].tolist() == [0]
    r, b = s.scans[k].Z[0]
    assert r == pytest.approx(math.hypot(15.27, 1.0)) and b == pytest.approx(math.atan2(1.0, 15.27))
    # the parked car (label) is the one obstacle, and the DontCare row is ignored
    assert len(s.scans[k].obstacles) == 1 and s.scans[k].obstacles.kind[0] == "vehicle"
    assert ss.info["notes"] == ["no calib/0000.txt: nominal KITTI calibration used"]


def test_no_oxts_means_stationary_ego_with_a_note(tmp_path):
    write_sequence(tmp_path, "0000", oxts=False)
    seq = read_sequence(open_dataset(tmp_path), "0000")
    assert seq.imu_poses is None and seq.n_frames == 12
    assert any("stationary" in n for n in seq.notes)
    assert np.array_equal(to_scans(seq, KittiConfig(), SENSOR).scans.scans[5].ego, np.zeros(3))


def test_folds_and_n_hat():
    ids = [f"{i:04d}" for i in range(21)]
    folds = fold_partition(ids, 7)
    assert [len(f) for f in folds] == [3] * 7 and sum(folds, []) == ids
    assert [len(f) for f in fold_partition(ids[:5], 7)] == [1] * 5
    assert [len(f) for f in fold_partition(ids[:8], 3)] == [3, 3, 2]
    targets = {"a": 10, "b": 30, "c": 7}
    frames = {"a": 100, "b": 500, "c": 70}
    assert n_hat(targets, frames, ["a", "b"]) == pytest.approx(40 / 600)
    assert sweep_n_hat(3, 100, -10) == pytest.approx(0.01) and sweep_n_hat(3, 100, 2) == pytest.approx(0.05)


def test_sequence_ranges():
    assert parse_sequences("0000-0003,0007") == [0, 1, 2, 3, 7]
    assert parse_sequences("5") == [5]
    from soabench.errors import SoabenchError

    with pytest.raises(SoabenchError, match="--sequences"):
        parse_sequences("3-1")


def test_label_rows_parse_and_drop_dontcare(tmp_path):
    write_sequence(tmp_path, "0000", n_frames=2)
    obj, fmt = parse_objects(tmp_path / "label_02" / "0000.txt", "label")
    assert fmt == "label" and len(obj) == 4 and "DontCare" not in set(obj.type)
    assert obj.line.tolist() == [1, 2, 4, 5]


def test_semantic_polygons_used_and_other_classes_reported(tmp_path):
    write_sequence(tmp_path, "0000", n_frames=3)
    sem = tmp_path / "sem"
    sem.mkdir()
    (sem / "0000.txt").write_text(
        "1 sidewalk 5 -10 30 -10 30 -6 5 -6\n"  # a strip 6-10 m right of the ego, in the FOV
        "1 building 20 4 30 4 30 14 20 14\n"
        "1 Sidewalk 5 6 30 6 30 10 5 10\n"  # class names are case-sensitive: reported, not used
        "2 sidewalk 0 0 1 1 2 2 3 3\n"  # zero area
    )
    ds = open_dataset(tmp_path, semantics=sem)
    ss = to_scans(read_sequence(ds, "0000"), KittiConfig(), SENSOR)
    scan = ss.scans.scans[1]
    assert scan.visible_region.area > 0 and ss.scans.scans[0].visible_region.is_empty
    assert list(scan.obstacles.kind).count("building") == 1
    assert ss.scene.sidewalk.area == pytest.approx(25 * 4)
    notes = " ".join(ss.info["notes"])
    assert "Sidewalk (1) not used" in notes and "1 polygon(s) of zero area" in notes
