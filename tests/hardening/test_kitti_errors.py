"""Bad KITTI input: one clear line and exit 2, or a reported skip of one unreadable sequence; never a silent drop."""

from __future__ import annotations

import json

import pytest
from kitti_files import write_dataset

from soabench.cli.main import main


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(["kitti", *argv])
    out, err = capsys.readouterr()
    return code, out, err


def _one_error_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("soabench: error: "), err
    assert "Traceback" not in err
    return lines[0]


@pytest.fixture
def data(tmp_path):
    return write_dataset(tmp_path / "kitti", n=3, n_frames=10)


def test_missing_root_folder(tmp_path, capsys):
    code, _, err = _run(capsys, "--root", str(tmp_path / "nope"), "--out", str(tmp_path / "run"))
    assert code == 2 and "--root" in _one_error_line(err) and "not a folder" in err
    assert not (tmp_path / "run").exists()


def test_missing_label_folder(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    code, _, err = _run(capsys, "--root", str(tmp_path / "empty"), "--out", str(tmp_path / "run"))
    assert code == 2 and "label_02" in _one_error_line(err)


def test_missing_detections_folder(data, tmp_path, capsys):
    nodet = str(tmp_path / "nodet")
    code, _, err = _run(capsys, "--root", str(data), "--detections", nodet, "--out", str(tmp_path / "r"))
    assert code == 2 and "--detections" in _one_error_line(err)


def test_detections_for_a_sequence_without_labels(data, tmp_path, capsys):
    (data / "detections" / "0007.txt").write_text("")
    code, _, err = _run(capsys, "--root", str(data), "--out", str(tmp_path / "run"))
    line = _one_error_line(err)
    assert code == 2 and "0007" in line and "must match" in line


def test_labels_without_detections(data, tmp_path, capsys):
    (data / "detections" / "0001.txt").unlink()
    code, _, err = _run(capsys, "--root", str(data), "--out", str(tmp_path / "run"))
    line = _one_error_line(err)
    assert code == 2 and "0001" in line and "must match" in line


def test_requested_sequence_without_labels(data, tmp_path, capsys):
    code, _, err = _run(capsys, "--root", str(data), "--sequences", "0000-0004", "--out", str(tmp_path / "run"))
    line = _one_error_line(err)
    assert code == 2 and "0003, 0004" in line


@pytest.mark.parametrize(
    ("row", "what"),
    [
        ("3 0 Pedestrian 0 0 0.0 -1 -1 -1 -1 1.75 0.6 0.8 1.0 1.65", "columns; expected 17"),
        ("3 0 Pedestrian 0 0 0.0 -1 -1 -1 -1 1.75 0.6 0.8 x 1.65 15.0 0.0", "location 'x' is not a number"),
        ("-1 0 Pedestrian 0 0 0.0 -1 -1 -1 -1 1.75 0.6 0.8 1.0 1.65 15.0 0.0", "frame -1 is negative"),
    ],
)
def test_malformed_label_row_names_file_and_line(data, tmp_path, capsys, row, what):
    path = data / "label_02" / "0001.txt"
    lines = path.read_text().splitlines()
    lines.insert(4, row)
    path.write_text("\n".join(lines) + "\n")
    code, _, err = _run(capsys, "--root", str(data), "--out", str(tmp_path / "run"))
    line = _one_error_line(err)
    assert code == 2 and f"{path}:5:" in line and what in line
    assert not (tmp_path / "run" / "summary.json").exists()


def test_malformed_detection_row_names_file_and_line(data, tmp_path, capsys):
    path = data / "detections" / "0002.txt"
    path.write_text(path.read_text() + "4 -1 Pedestrian 0 0 0.0 -1 -1 -1 -1 1.75 0.6 0.8 1.0 1.65 15.0 0.0\n")
    n = len(path.read_text().splitlines())
    code, _, err = _run(capsys, "--root", str(data), "--out", str(tmp_path / "run"))
    line = _one_error_line(err)
    assert code == 2 and f"{path}:{n}:" in line and "expected 18" in line


def test_empty_sequence(data, tmp_path, capsys):
    (data / "label_02" / "0001.txt").write_text("")
    (data / "oxts" / "0001.txt").unlink()
    code, _, err = _run(capsys, "--root", str(data), "--out", str(tmp_path / "run"))
    line = _one_error_line(err)
    assert code == 2 and "sequence 0001 is empty" in line


def test_detections_in_frames_without_labels(data, tmp_path, capsys):
    path = data / "detections" / "0000.txt"
    path.write_text(path.read_text() + "10 -1 Pedestrian 0 0 0.0 -1 -1 -1 -1 1.75 0.6 0.8 1.0 1.65 15.0 0.0 0.9\n")
    code, _, err = _run(capsys, "--root", str(data), "--out", str(tmp_path / "run"))
    line = _one_error_line(err)
    assert code == 2 and "frame 10, a frame without labels" in line and "0000.txt:" in line


def test_unknown_detection_format(data, tmp_path, capsys):
    (data / "detections" / "0000.txt").write_text("0 1 2 3\n")
    code, _, err = _run(capsys, "--root", str(data), "--out", str(tmp_path / "run"))
    line = _one_error_line(err)
    assert code == 2 and "0000.txt:1: 4 columns" in line and "AB3DMOT" in line


def test_unreadable_sequence_is_a_reported_skip(data, tmp_path, capsys):
    (data / "label_02" / "0001.txt").write_bytes(b"\xff\xfe\x00binary")
    code, out, err = _run(capsys, "--root", str(data), "--out", str(tmp_path / "run"), "--models", "soa")
    assert code == 0
    assert "skipped sequence 0001" in err and "cannot be read as text" in err
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert [s["sequence"] for s in summary["skipped"]] == ["0001"]
    assert [f["sequences"] for f in summary["folds"]] == [["0000"], ["0002"]]
    assert "Skipped sequence 0001" in (tmp_path / "run" / "report.md").read_text()


def test_skip_bad_turns_a_malformed_sequence_into_a_reported_skip(data, tmp_path, capsys):
    (data / "label_02" / "0002.txt").write_text("garbage row\n")
    code, _, err = _run(capsys, "--root", str(data), "--out", str(tmp_path / "run"), "--models", "soa", "--skip-bad")
    assert code == 0 and "skipped sequence 0002" in err and "0002.txt:1: 2 columns" in err
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert [s["sequence"] for s in summary["skipped"]] == ["0002"]


def test_existing_run_folder_is_refused_and_resume_flags_checked(data, tmp_path, capsys):
    assert _run(capsys, "--root", str(data), "--out", str(tmp_path / "run"), "--models", "soa")[0] == 0
    code, _, err = _run(capsys, "--root", str(data), "--out", str(tmp_path / "run"))
    assert code == 2 and "already holds a run" in _one_error_line(err)
    code, _, err = _run(capsys, "--resume", str(tmp_path / "run"), "--root", str(data))
    assert code == 2 and "--root" in _one_error_line(err)
    code, _, err = _run(capsys, "--resume", str(tmp_path / "nothing"))
    assert code == 2 and "not a `soabench kitti` run folder" in _one_error_line(err)


def test_bad_kitti_config_key(data, tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[kitti]\nobstacles = 'lidar'\n")
    code, _, err = _run(capsys, "--root", str(data), "--out", str(tmp_path / "run"), "--config", str(cfg))
    assert code == 2 and "kitti.obstacles = 'lidar'" in _one_error_line(err)


def test_classes_and_score_flags(data, tmp_path, capsys):
    code, _, err = _run(capsys, "--root", str(data), "--out", str(tmp_path / "r1"), "--classes", "Pedestrian,Car")
    assert code == 2 and "overlap" in _one_error_line(err)
    r2 = str(tmp_path / "r2")
    code, _, _ = _run(capsys, "--root", str(data), "--out", r2, "--models", "soa", "--score-min", "0.5")
    assert code == 0
    info = json.loads((tmp_path / "r2" / "summary.json").read_text())["sequence_info"]["0000"]
    assert info["below_score"] == 4 and info["measurements"] == 10
    assert json.loads((tmp_path / "r2" / "run.json").read_text())["kitti"]["score_min"] == 0.5


def test_resume_refuses_records_made_with_other_data(data, tmp_path, capsys):
    run = tmp_path / "run"
    assert _run(capsys, "--root", str(data), "--out", str(run), "--models", "soa")[0] == 0
    (run / "records" / "cv" / "0000.json").unlink()
    path = data / "label_02" / "0000.txt"  # one more target in sequence 0000 changes N_hat of the other folds
    path.write_text(path.read_text() + "3 9 Cyclist 0 0 0.0 -1 -1 -1 -1 1.75 0.6 1.8 2.0 1.65 20.0 0.0\n")
    code, _, err = _run(capsys, "--resume", str(run))
    assert code == 2 and "made with other data or settings" in _one_error_line(err)
