"""KITTI's occlusion and truncation levels in the track metrics, and identity through undetected gaps
(docs/user-guide/kitti.md "Occlusion levels"), on a hand-made sequence with known levels (no SUMO)."""

from __future__ import annotations

import numpy as np
from kitti_files import label_row, write_sequence

from soabench.config import MetricsConfig, Sensor
from soabench.kitti.config import KittiConfig
from soabench.kitti.levels import id_switches, level_split
from soabench.kitti.reader import open_dataset, read_sequence, to_scans

SENSOR = Sensor(dt=0.1, r_max=50.0)
#: the pedestrian's occluded and truncated level in frames 0-11, as its label rows give them
OCCLUDED = [0, 0, 0, 0, 1, 1, 1, 2, 2, 3, 0, 0]
TRUNCATED = [0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 2, 0]
#: frames without the pedestrian's detection: an undetected gap of 3 frames (5-7)
MISSED = {5, 6, 7}


def sequence(root):
    write_sequence(root, "0000")
    labels, dets = [], []
    for k in range(12):
        x = -3.0 + 0.5 * k
        row = label_row(k, 0, "Pedestrian", x, 15.0, occluded=OCCLUDED[k]).split()
        row[3] = str(TRUNCATED[k])
        labels.append(" ".join(row))
        if k not in MISSED:
            dets.append(label_row(k, -1, "Pedestrian", x, 15.0, score=0.9))
    (root / "label_02" / "0000.txt").write_text("\n".join(labels) + "\n")
    (root / "detections" / "0000.txt").write_text("\n".join(dets) + "\n")
    return to_scans(read_sequence(open_dataset(root), "0000"), KittiConfig(), SENSOR)


def test_the_reader_keeps_each_frames_levels(tmp_path):
    ss = sequence(tmp_path)
    assert ss.levels["occluded"][:, 0].tolist() == OCCLUDED
    assert ss.levels["truncated"][:, 0].tolist() == TRUNCATED
    assert ss.scans.detected[:, 0].tolist() == [k not in MISSED for k in range(12)]


def test_level_split_counts_each_frame_at_its_level(tmp_path):
    """The tracker follows the pedestrian everywhere but frames 6 and 9, as track 4 until frame 7 and as track 5
    from frame 8 on: one identity switch, at frame 8 (occluded 2, truncated 1)."""
    ss = sequence(tmp_path)
    X, labels = [], []
    for k in range(12):
        shown = k not in (6, 9)
        X.append(ss.scans.truth_xy[k, :1] + 0.1 if shown else np.zeros((0, 2)))
        labels.append(np.array([4 if k < 8 else 5]) if shown else np.zeros(0, dtype=np.int64))
    split = level_split(ss, X, labels, MetricsConfig(d_gate=2.0))
    occ = {r["level"]: r for r in split["occluded"]}
    assert [occ[v]["frames"] for v in (0, 1, 2, 3)] == [6, 3, 2, 1]
    assert [occ[v]["associated"] for v in (0, 1, 2, 3)] == [6, 2, 2, 0]  # missed at 6 (level 1) and 9 (level 3)
    assert [occ[v]["idsw"] for v in (0, 1, 2, 3)] == [0, 0, 1, 0]
    trunc = {r["level"]: r for r in split["truncated"]}
    assert [trunc[v]["frames"] for v in (0, 1, 2)] == [9, 2, 1]
    assert [trunc[v]["idsw"] for v in (0, 1, 2)] == [0, 1, 0]
    # the undetected frames 5-7: estimates at 5 and 7 but not 6 (not coasted); track 4 before, track 5 after (lost)
    assert split["gaps"] == [{"scans": 3, "coasted": 0, "id_kept": 0}]
    plain = level_split(ss, X, None, MetricsConfig(d_gate=2.0))
    assert plain["gaps"] == [{"scans": 3, "coasted": 0, "id_kept": None}]
    assert all(r["idsw"] is None for r in plain["occluded"])


def test_id_switches_follow_the_last_label():
    assoc = np.array([[1], [1], [0], [1], [1]], dtype=bool)
    labels = np.array([[3], [3], [-1], [7], [3]])
    assert id_switches(assoc, labels)[:, 0].tolist() == [False, False, False, True, True]
