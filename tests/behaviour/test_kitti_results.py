"""Labelled estimates written as KITTI tracking results (soabench/kitti/results.py), scored by TrackEval's KITTI
2-D box reader against the label_02 file the export writes for the same trial (docs/method.md §9.3)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from soabench.errors import SoabenchError
from soabench.experiment.campaigns.kitti.results import tracking_rows, write_tracking_results
from soabench.kitti.config import kitti_base_config
from soabench.kitti.export import export_calib, export_default_fov, export_trial
from soabench.scenario import load, simulate
from soabench.seeding import trial_seeds
from soabench.sensor import observe


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    """Trial 0 of the intersection (30 s) observed as the export observes it, and its label_02 file."""
    cfg = kitti_base_config()
    sensor = dataclasses.replace(cfg.sensor_at(), fov_deg=export_default_fov(cfg.sensor))
    calib = export_calib(sensor)
    scene, scenario = load("intersection", (), None)
    seeds = trial_seeds(cfg.experiment.seed, 0)
    recording = simulate(scene, scenario, seeds, duration=30.0)
    scans = observe(recording, scene, sensor, seeds.sensor_rngs())
    gt = tmp_path_factory.mktemp("kitti_results") / "gt"
    export_trial(0, recording, scans, scene, sensor, calib, gt, cfg.experiment.seed)
    (gt / "evaluate_tracking.seqmap.training").write_text(f"0000 empty 000000 {len(scans.scans):06d}\n")
    return recording, scans, sensor, calib, gt


def truth_as_estimates(recording, scans, sensor) -> tuple[list, list]:
    """Every present pedestrian as an estimate [x, y, vx, vy] along its heading, labelled with its index."""
    from soabench.sensor import scan_steps

    steps = scan_steps(recording.t, recording.step_length, sensor.dt)
    X, labels = [], []
    for k in range(len(scans.scans)):
        i = np.flatnonzero(scans.present[k])
        h = np.asarray(recording.ped_heading[int(steps[k]), i], dtype=float)
        X.append(np.column_stack([scans.truth_xy[k, i], np.cos(h), np.sin(h)]))
        labels.append(i.astype(np.int64))
    return X, labels


def test_trackeval_scores_written_estimates(trial, tmp_path, trackeval_kitti):
    """The truth written as a tracker's results scores HOTA = MOTA = IDF1 = 1; the same with two pedestrians'
    labels swapped halfway through their common frames costs identity switches and HOTA."""
    recording, scans, sensor, calib, gt = trial
    X, labels = truth_as_estimates(recording, scans, sensor)
    egos = np.array([s.ego for s in scans.scans])
    frames: dict[int, set[int]] = {}  # the frames of each evaluated pedestrian (untruncated, not out of the FOV)
    for r in (line.split() for line in (gt / "label_02" / "0000.txt").read_text().splitlines()):
        if r[2] == "Pedestrian" and int(r[3]) == 0 and int(r[4]) <= 2:
            frames.setdefault(int(r[1]), set()).add(int(r[0]))
    ids = sorted(frames)
    common, a, b = max((len(frames[a] & frames[b]), a, b) for i, a in enumerate(ids) for b in ids[i + 1 :])
    assert common >= 10
    at = sorted(frames[a] & frames[b])[common // 2]  # the two pedestrians swap labels from here on
    swapped = [np.where(lab == a, b, np.where(lab == b, a, lab)) if k >= at else lab for k, lab in enumerate(labels)]
    for name, lab in (("perfect", labels), ("swapped", swapped)):
        assert write_tracking_results(tmp_path / "trackers" / name, 0, X, lab, egos, calib, sensor.r_max) > 2 * common
    r = trackeval_kitti(gt, tmp_path / "trackers", ["perfect", "swapped"], ["pedestrian"])
    p, s = r["perfect"]["pedestrian"], r["swapped"]["pedestrian"]
    assert p["CLEAR"]["CLR_TP"] > 2 * common and p["CLEAR"]["MOTA"] == 1.0 and p["Identity"]["IDF1"] == 1.0
    assert np.allclose(p["HOTA"]["HOTA"], 1.0)
    assert s["CLEAR"]["IDSW"] >= 1 and s["HOTA"]["HOTA"].mean() < 1.0 and s["Identity"]["IDF1"] < 1.0


def test_rows_only_for_boxes_the_camera_sees(trial):
    recording, scans, sensor, calib, gt = trial
    ego = scans.scans[0].ego
    behind = ego[:2] - 10.0 * np.array([np.cos(ego[2]), np.sin(ego[2])])
    ahead = ego[:2] + 10.0 * np.array([np.cos(ego[2]), np.sin(ego[2])])
    far = ego[:2] + 10 * sensor.r_max * np.array([np.cos(ego[2]), np.sin(ego[2])])
    rows = tracking_rows(
        3, np.array([behind, ahead, far]), np.array([1, 2, 3]), ego, calib, sensor.r_max, w=np.array([0.2, 0.7, 0.9])
    )
    assert len(rows) == 1
    r = rows[0].split()
    assert (r[0], r[1], r[2], r[-1]) == ("3", "2", "Pedestrian", "0.7") and len(r) == 18


def test_bad_estimates_are_one_clear_error(trial):
    _, scans, sensor, calib, _ = trial
    with pytest.raises(SoabenchError, match=r"give \(n, 2\) positions or \(n, 4\) states"):
        tracking_rows(0, np.zeros((2, 3)), np.array([1, 2]), scans.scans[0].ego, calib, sensor.r_max)
