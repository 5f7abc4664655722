"""Resumable runs: a run killed midway and resumed equals an uninterrupted run."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import fake_trial as ft
import pytest
from repo_paths import TESTS

from soabench.config import Config
from soabench.errors import SoabenchError
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.reports.finished import run_experiment

pytestmark = pytest.mark.slow  # runs killed and resumed in subprocesses

HERE = TESTS
CSV_FILES = ("trials.csv", "episodes.csv", "steps.csv")

SCRIPT = """
import sys
from pathlib import Path
sys.path.insert(0, {here!r})
import fake_trial as ft
from soabench.config import Config
from soabench.experiment.reports.finished import run_experiment
from soabench.experiment.execution.options import RunOptions
cfg = Config.from_dict({cfg!r}).validate()
options = RunOptions(workers=1, progress=False, figures=False)
run_experiment(cfg, "intersection", out=Path({out!r}), options=options, trial_fn=ft.slow_trial, load_fn=ft.fake_load)
"""


def small_config(trials: int) -> Config:
    return ft.small_config(trials=trials, duration=15.0, clutter=(0.5, 3.0), seed=5)


def start_run(cfg: Config, out: Path) -> subprocess.Popen:
    code = SCRIPT.format(here=str(HERE), cfg=cfg.to_dict(), out=str(out))
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_for_trials(out: Path, n: int, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    t0 = time.monotonic()
    while len(list((out / "trials").glob("trial_*.json"))) < n:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < timeout, "the run produced no trials"
        time.sleep(0.05)


def assert_same_as_uninterrupted(out: Path, cfg: Config, ref_dir: Path) -> None:
    """An uninterrupted serial run of ``cfg`` writes the same CSV files, byte for byte, as the run in ``out``."""
    ref = ft.run_fake(cfg, ref_dir)
    assert ref.complete
    for name in CSV_FILES:
        assert (out / name).read_bytes() == (ref_dir / name).read_bytes(), name


def test_killed_run_resumes_to_the_uninterrupted_result(tmp_path):
    cfg = small_config(trials=10)
    out = tmp_path / "killed"
    proc = start_run(cfg, out)
    try:
        wait_for_trials(out, 3, proc)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.communicate()
    n_on_disk = len(list((out / "trials").glob("trial_*.json")))
    assert 3 <= n_on_disk < 10
    assert not (out / "trials.csv").exists() and not (out / "summary.md").exists()
    stamp = {p.name: p.stat().st_mtime_ns for p in (out / "trials").glob("trial_*.json")}

    # resume uses the run's stored config and functions (run.json); the net argument is ignored
    o = run_experiment(None, "ignored", resume=out, options=RunOptions(workers=1, progress=False, figures=False))
    assert o.complete and o.n_done == 10 and o.n_missing == 0
    assert {p.name: p.stat().st_mtime_ns for p in (out / "trials").glob("trial_*.json") if p.name in stamp} == stamp
    sessions = [json.loads(p.read_text()) for p in (out / "sessions").glob("*.json")]
    assert [s["trials_run"] for s in sessions if s["resumed"]] == [10 - n_on_disk]

    assert_same_as_uninterrupted(out, cfg, tmp_path / "ref")
    assert json.loads((out / "summary.json").read_text())["config"] == cfg.to_dict()


def test_interrupted_run_says_how_to_resume(tmp_path):
    cfg = small_config(trials=10)
    out = tmp_path / "interrupted"
    proc = start_run(cfg, out)
    try:
        wait_for_trials(out, 2, proc)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode != 0
    assert f"soabench run --resume {out}" in err
    assert not (out / "trials.csv").exists()
    assert 2 <= len(list((out / "trials").glob("trial_*.json"))) < 10


def test_resume_of_a_complete_run_reruns_nothing(tmp_path):
    cfg = small_config(trials=3)
    out = tmp_path / "run"
    ft.run_fake(cfg, out)
    before = (out / "trials.csv").read_bytes()
    o = run_experiment(
        None, "x", resume=out, trial_fn=ft.failing_trial, options=RunOptions(progress=False, figures=False)
    )
    assert o.complete and o.n_done == 3 and not o.failures  # failing_trial would fail trial 2 if it ran
    assert (out / "trials.csv").read_bytes() == before
    assert len(list((out / "sessions").glob("*.json"))) == 1


def test_resume_needs_a_run_folder(tmp_path):
    with pytest.raises(SoabenchError, match="not a run folder"):
        run_experiment(None, "intersection", resume=tmp_path, options=RunOptions(progress=False))


def test_lost_worker_loses_only_trials_in_flight(tmp_path, capsys):
    cfg = small_config(trials=10)
    out = tmp_path / "run"
    o = run_experiment(
        cfg,
        "intersection",
        out=out,
        options=RunOptions(workers=2, progress=False, figures=False),
        trial_fn=ft.crashing_trial,
        load_fn=ft.fake_load,
    )
    failed = [f["trial"] for f in o.failures]
    assert 3 in failed and len(failed) <= 4  # at most 2 x workers trials in flight
    assert all("worker process died" in f["error"] and f["sumo_seed"] > 0 for f in o.failures)
    assert o.n_done == 10 - len(failed) and not o.complete
    assert "trial 3 failed" in capsys.readouterr().err
    o2 = run_experiment(
        None, "x", resume=out, options=RunOptions(workers=1, progress=False, figures=False), trial_fn=ft.fake_trial
    )
    assert o2.complete
    assert_same_as_uninterrupted(out, cfg, tmp_path / "ref")
