"""The real pipeline through the CLI, as a user runs it: SUMO -> sensor -> six birth models x two modes -> files.

40 s trials: in the first ~20 s the ego sits at the western edge of the box and sees almost no pedestrian, so a
20 s run has no delay episode to score.
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from soabench.cli.main import main
from soabench.origins import ORIGIN_KEYS

pytestmark = pytest.mark.slow  # the real pipeline through the CLI

MODELS = ("soa", "pubm", "ubm", "ubm-ws", "atbm", "gmbm")
MODES = ("static", "dynamic")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("e2e") / "run"
    code = main(["run", "--trials", "2", "--duration", "40", "--workers", "2", "--out", str(out), "--no-progress"])
    assert code == 0
    return out


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_files_exist_and_rows_are_trials_x_models_x_modes(run_dir):
    for name in ("trials.csv", "episodes.csv", "steps.csv", "timing.csv", "summary.json", "summary.md", "run.json"):
        assert (run_dir / name).is_file(), name
    rows = _rows(run_dir / "trials.csv")
    assert len(rows) == 2 * len(MODELS) * len(MODES)
    assert {(r["trial"], r["model"], r["mode"]) for r in rows} == {
        (str(t), m, p) for t in range(2) for m in MODELS for p in MODES
    }
    figures = sorted(p.name for p in (run_dir / "figures").glob("*.png"))
    # the paper's 13 figures, the track figure and identity kept by gap length (the labelled GM-PHD labels every
    # model's estimates), and the forest plot of S-OA's paired differences (the report's headline)
    assert len(figures) == 16 and "fig7b_components_origin.png" in figures and "tracks.png" in figures
    assert "identity_gaps.png" in figures and "paired.png" in figures
    assert all(p.stat().st_size > 10_000 for p in (run_dir / "figures").glob("*.png"))


def test_metrics_are_finite_where_defined(run_dir):
    rows = _rows(run_dir / "trials.csv")
    for r in rows:
        for key in ("card_err", "ospa", "gospa", "recall", "mean_components", "mean_pD"):
            assert math.isfinite(float(r[key])), (key, r)
        assert 0 <= float(r["ospa"]) <= 100 and float(r["mean_components"]) >= 0
        # a delay mean exists exactly when an episode was initiated (not censored)
        counted = int(r["n_episodes"]) - int(r["n_censored"])
        assert math.isfinite(float(r["delay_mean"])) == (counted > 0)
        # precision is undefined only when the filter extracted nothing
        assert math.isfinite(float(r["precision"])) == (int(r["tp"]) + int(r["fp"]) > 0)
    soa = [r for r in rows if r["model"] == "soa"]
    assert any(math.isfinite(float(r["delay_mean"])) for r in soa)


def test_episodes_and_steps_agree_with_trials(run_dir):
    rows = _rows(run_dir / "trials.csv")
    episodes = _rows(run_dir / "episodes.csv")
    steps = _rows(run_dir / "steps.csv")
    for r in rows:
        key = (r["trial"], r["model"], r["mode"])
        ep = [e for e in episodes if (e["trial"], e["model"], e["mode"]) == key]
        assert len(ep) == int(r["n_episodes"])
        assert sum(e["censored"] in ("True", "1", "true") for e in ep) == int(r["n_censored"])
        st = [s for s in steps if (s["trial"], s["model"], s["mode"]) == key]
        assert len(st) == 40  # one row per scan
        assert sum(int(s["tp"]) for s in st) == int(r["tp"])
        assert np.isclose(np.mean([float(s["ospa"]) for s in st]), float(r["ospa"]))
        # the posterior count by origin adds up to it at every scan and to the run's mean (§5.7)
        split = [sum(int(s[c]) for c in ORIGIN_KEYS) for s in st]
        assert split == [int(s["n_components"]) for s in st]
        assert np.isclose(np.mean(split), float(r["mean_components"]))


def test_summary_matches_the_csv(run_dir):
    rows = _rows(run_dir / "trials.csv")
    summary = json.loads((run_dir / "summary.json").read_text())
    md = (run_dir / "summary.md").read_text()
    card = np.mean([float(r["card_err"]) for r in rows if r["model"] == "soa" and r["mode"] == "static"])
    assert f"{card:.3f}" in md
    text = json.dumps(summary)
    assert "pubm" in text and "gmbm" in text
    for line in md.splitlines():  # win counts never exceed the number of trials
        if line.startswith("| static | ") or line.startswith("| dynamic | "):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if " / " in cells[2] and cells[2].split(" / ")[1] == "2":
                assert int(cells[2].split(" / ")[0]) <= 2


def test_resuming_a_finished_run_changes_nothing(run_dir, capsys):
    before = (run_dir / "trials.csv").read_bytes()
    assert main(["run", "--resume", str(run_dir), "--no-progress"]) == 0
    assert (run_dir / "trials.csv").read_bytes() == before


def test_record_and_scene_commands_write_their_files(tmp_path, capsys):
    assert main(["record", "--seed", "1", "--duration", "10", "--out", str(tmp_path / "r.npz"), "--scans"]) == 0
    with np.load(tmp_path / "r.npz") as rec, np.load(tmp_path / "r.scans.npz") as scans:
        assert rec["ped_xy"].shape[0] == 100 and "Z" in scans.files
    assert main(["scene", "--seed", "1", "--time", "10", "--sensor", "--out", str(tmp_path / "s.png")]) == 0
    assert (tmp_path / "s.png").stat().st_size > 10_000
    assert main(["birth", "--seed", "1", "--time", "10", "--model", "ubm", "--out", str(tmp_path / "b.png")]) == 0
    assert (tmp_path / "b.png").stat().st_size > 10_000
    assert "wrote" in capsys.readouterr().out


def test_serial_and_process_pool_give_bit_identical_csvs(run_dir, tmp_path):
    serial = tmp_path / "serial"
    argv = ["run", "--trials", "2", "--duration", "40", "--workers", "1", "--out", str(serial), "--no-progress"]
    assert main(argv) == 0
    for name in ("trials.csv", "episodes.csv", "steps.csv"):
        assert (serial / name).read_bytes() == (run_dir / name).read_bytes(), name
