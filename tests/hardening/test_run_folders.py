"""Bad input in run folders: data never code (a poisoned run.json runs nothing), every value validated, owned folders
(resolved paths, stale/foreign folders refused, one process per folder), requested-vs-stored conflicts refused."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import fake_trial as ft
import pytest
from repo_paths import TESTS

from soabench.cli.main import main
from soabench.config import Config
from soabench.errors import SoabenchError
from soabench.experiment.campaigns.sweep import run_sweep
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.execution.runner import TodoTrials
from soabench.experiment.reports.finished import run_experiment
from soabench.experiment.trial import registry
from soabench.folders import FolderLock

HERE = TESTS
CSV_FILES = ("trials.csv", "episodes.csv", "steps.csv")


def _messages(err: str) -> list[str]:
    """stderr without the periodic progress lines (off a terminal a run reports progress there)."""
    return [ln for ln in err.strip().splitlines() if not ln.startswith("progress:")]


def small_config(trials: int = 3, **exp) -> Config:
    return ft.small_config(trials=trials, duration=10.0, clutter=(0.5, 3.0), seed=5, models=("soa", "ubm"), **exp)


def make_run(out: Path, trials: int = 3, **kw) -> Path:
    ft.run_fake(small_config(trials), out, **kw)
    return out


def edit_run_json(run: Path, **changes) -> None:
    meta = json.loads((run / "run.json").read_text())
    for k, v in changes.items():
        if v is ...:
            meta.pop(k, None)
        else:
            meta[k] = v
    (run / "run.json").write_text(json.dumps(meta))


def one_error_line(capsys) -> str:
    err = _messages(capsys.readouterr().err)
    assert len(err) == 1, err
    assert err[0].startswith("soabench: error: ")
    return err[0]


@pytest.fixture
def report_stub(monkeypatch):
    import soabench.experiment.reports.report as report

    monkeypatch.setattr(report, "write_report", lambda run_dir, figures=True, store=None: "summary")


# ------------------------------------------------------------------------------------------ 1. data, never code
@pytest.fixture
def poison_module(tmp_path, monkeypatch):
    """A module that writes a marker file when imported, importable from sys.path: if anything imports it, we see."""
    lib = tmp_path / "lib"
    lib.mkdir()
    marker = tmp_path / "PWNED"
    (lib / "poison_marker.py").write_text(
        f"from pathlib import Path\nPath({str(marker)!r}).write_text('imported')\ndef run(*a, **k):\n"
        f"    Path({str(marker)!r}).write_text('called')\n"
    )
    monkeypatch.syspath_prepend(str(lib))
    sys.modules.pop("poison_marker", None)
    return marker


#: run.json edits that name code: each must be refused without importing or calling anything
POISONS = [
    {"trial_kind": "poison_marker:run"},
    {"scene_loader": "poison_marker:run"},
    {"trial_kind": "os:system"},
    {"trial_kind": ..., "scene_loader": ..., "trial_fn": "poison_marker:run", "load_fn": None},  # old format
    {"trial_kind": ..., "scene_loader": ..., "trial_fn": None, "load_fn": "poison_marker:run"},
    {"trial_kind": ["poison_marker", "run"]},
]
#: run.json values that are not what a run may hold, and the words of their error
BAD_META = [
    ({"net": 5}, "net = 5 must be a non-empty string"),
    ({"polys": "a.xml"}, "polys = 'a.xml' must be a list"),
    ({"scenario": ["x"]}, "scenario = ['x']"),
    ({"save_estimates": "yes"}, "save_estimates = 'yes' must be true or false"),
    ({"trials": 7}, "trials = 7 must equal config.experiment.trials = 3"),
    ({"format": 99}, "unknown format"),
    ({"config": {"filter": {"gate": "no"}}}, "filter.gate = 'no' must be a boolean"),
    ({"config": {"birth": {"rho": [1.0, float("inf"), 1.0]}}}, "birth.rho"),
    ({"config": {"sensor": {"r_max": 1e300}}}, "sensor.r_max"),
    ({"config": {"experiment": {"trials": 10**9}}}, "[1, 100000]"),
    ({"config": "everything"}, "a configuration must be a table"),
]


@pytest.mark.parametrize("changes", POISONS)
def test_a_poisoned_run_folder_runs_nothing(tmp_path, capsys, poison_module, changes):
    run = make_run(tmp_path / "run")
    for p in (run / "trials").glob("*.json"):
        p.unlink()  # work to do, so a resolved function would be called
    edit_run_json(run, **changes)
    assert main(["run", "--resume", str(run)]) == 2
    line = one_error_line(capsys)
    assert "is not registered" in line and str(run / "run.json") in line
    assert not poison_module.exists() and "poison_marker" not in sys.modules
    assert not list((run / "trials").glob("*.json"))


def test_a_poisoned_sweep_point_name_is_refused(tmp_path, capsys):
    cfg = small_config(2)
    kw = dict(
        trial_fn=ft.fake_trial, load_fn=ft.fake_load, options=RunOptions(progress=False, figures=False, workers=1)
    )
    run_sweep("births", (-1, 0), cfg, "intersection", out=tmp_path / "sw", **kw)
    meta = json.loads((tmp_path / "sw" / "sweep.json").read_text())
    meta["points"][0]["name"] = "../../../evil"
    (tmp_path / "sw" / "sweep.json").write_text(json.dumps(meta))
    assert main(["sweep", "births", "--resume", str(tmp_path / "sw")]) == 2
    assert "point name '../../../evil' is not allowed" in one_error_line(capsys)
    assert not (tmp_path / "evil").exists()


@pytest.mark.parametrize(("changes", "needle"), BAD_META)
def test_every_run_json_value_is_validated(tmp_path, capsys, changes, needle):
    run = make_run(tmp_path / "run")
    edit_run_json(run, **changes)
    assert main(["run", "--resume", str(run)]) == 2
    assert needle in one_error_line(capsys)


def test_registry_is_closed_and_documented():
    with pytest.raises(SoabenchError, match=r"trial kind 'nope' is not registered; known: .*soabench"):
        registry.trial_kind("nope")
    with pytest.raises(SoabenchError, match="not a valid name"):
        registry.register_trial_kind("os:system", ft.fake_trial)
    with pytest.raises(SoabenchError, match="already registered"):
        registry.register_trial_kind("fake", ft.slow_trial)
    registry.register_trial_kind("fake", ft.fake_trial)  # the same function again: no-op
    assert registry.trial_kind("fake") is ft.fake_trial
    assert registry.trial_kind_name(ft.fake_trial) == "fake" and registry.trial_kind_name(None) == "soabench"
    assert registry.scene_loader_name(lambda *a: None).startswith("unregistered:")
    assert "soabench" in registry.trial_kinds() and "sumo" in registry.scene_loaders()


def test_run_json_names_the_registered_kind_not_an_import_path(tmp_path):
    meta = json.loads((make_run(tmp_path / "run") / "run.json").read_text())
    assert meta["trial_kind"] == "fake" and meta["scene_loader"] == "fake-load"
    assert "trial_fn" not in meta and "load_fn" not in meta


# ------------------------------------------------------------------------------------------ 2. owned folders
def test_dotdot_path_is_resolved_before_the_check(tmp_path, capsys):
    run = make_run(tmp_path / "run")
    before = (run / "run.json").read_bytes()
    sneaky = tmp_path / "missing" / ".." / "run"
    assert main(["run", "--trials", "1", "--duration", "5", "--workers", "1", "--out", str(sneaky)]) == 2
    assert "already holds a run" in one_error_line(capsys)
    assert (run / "run.json").read_bytes() == before and not (tmp_path / "missing").exists()


def test_foreign_folder_is_never_adopted(tmp_path):
    (tmp_path / "f" / "trials").mkdir(parents=True)
    (tmp_path / "f" / "trials" / "trial_00000.json").write_text("{}")
    with pytest.raises(SoabenchError, match="stale or foreign"):
        make_run(tmp_path / "f")
    with pytest.raises(SoabenchError, match="no run.json"):
        run_experiment(None, "x", resume=tmp_path / "f", options=RunOptions(progress=False))


def test_trial_records_beyond_the_run_are_foreign(tmp_path):
    run = make_run(tmp_path / "run")
    rec = json.loads((run / "trials" / "trial_00000.json").read_text())  # a record of this run, as trial 99
    (run / "trials" / "trial_00099.json").write_text(json.dumps(ft.renumbered(rec, 99)))
    with pytest.raises(SoabenchError, match="beyond its 3 trials"):
        run_experiment(None, "x", resume=run, options=RunOptions(progress=False, figures=False))


def test_a_locked_folder_names_its_holder(tmp_path, capsys):
    run = make_run(tmp_path / "run")
    import os

    with FolderLock(run):
        assert main(["run", "--resume", str(run)]) == 2
        line = one_error_line(capsys)
        assert f"is in use by pid {os.getpid()}" in line
    assert not (run / ".lock").exists()  # released and removed


def test_a_stale_lock_of_a_dead_process_does_not_block(tmp_path, report_stub):
    run = make_run(tmp_path / "run")
    (run / ".lock").write_text(json.dumps({"pid": 999999, "host": "gone", "since": "earlier"}))
    o = run_experiment(None, "x", resume=run, options=RunOptions(progress=False, figures=False))
    assert o.complete


SLOW_RESUME = """
import sys
sys.path.insert(0, {here!r})
import fake_trial as ft
from pathlib import Path
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.reports.finished import run_experiment
options = RunOptions(workers=1, progress=False, figures=False)
run_experiment(None, "x", resume=Path({run!r}), options=options, trial_fn=ft.slow_trial)
"""


@pytest.mark.slow
def test_two_processes_never_work_one_folder(tmp_path, capsys):
    run = make_run(tmp_path / "run", trials=12)
    for p in (run / "trials").glob("*.json"):
        p.unlink()
    proc = subprocess.Popen(
        [sys.executable, "-c", SLOW_RESUME.format(here=str(HERE), run=str(run))],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        t0 = time.monotonic()
        while not list((run / "trials").glob("*.json")):
            assert proc.poll() is None and time.monotonic() - t0 < 60, proc.communicate()
            time.sleep(0.05)
        assert main(["run", "--resume", str(run)]) == 2
        assert f"in use by pid {proc.pid}" in one_error_line(capsys)
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 0, err
    finally:
        if proc.poll() is None:
            proc.kill()
    # every trial ran exactly once: 12 records, 1 session
    assert len(list((run / "trials").glob("*.json"))) == 12
    assert len(list((run / "sessions").glob("*.json"))) == 2  # the creating run and the one resume


# ------------------------------------------------------------------------------------------ 3. streaming to-do
def test_todo_list_is_lazy():
    todo = TodoTrials(100_000, {1, 2, 5, 200_000})
    assert len(todo) == 99_997
    it = iter(todo)
    assert [next(it) for _ in range(4)] == [0, 3, 4, 6]


# ------------------------------------------------------------------------------------------ 4. conflicts
def test_resume_with_other_settings_is_refused_naming_each_key(tmp_path, capsys):
    run = make_run(tmp_path / "run")
    argv = ["run", "--resume", str(run), "--clutter", "5", "--trials", "99", "--models", "soa"]
    assert main(argv) == 2
    line = one_error_line(capsys)
    assert "experiment.clutter: stored [0.5, 3.0], requested [5.0]" in line
    assert "experiment.models: stored ['soa', 'ubm'], requested ['soa']" in line
    assert "experiment.trials" not in line  # more trials alone would be fine
    for extra, needle in (
        (["--seed", "9"], "experiment.seed: stored 5, requested 9"),
        (["--trials", "2"], "experiment.trials: stored 3, requested 2 (fewer trials would drop finished ones)"),
        (["--net", "crossing"], "net: stored 'intersection', requested 'crossing'"),
        (["--duration", "20"], "experiment.duration: stored 10.0, requested 20.0"),
    ):
        assert main(["run", "--resume", str(run), *extra]) == 2
        assert needle in one_error_line(capsys)
    cfg = tmp_path / "c.toml"
    cfg.write_text("[experiment]\nclutter = [4.0]\nseed = 5\n")  # seed as stored: only the clutter rate differs
    assert main(["run", "--resume", str(run), "--config", str(cfg)]) == 2
    line = one_error_line(capsys)
    assert "experiment.clutter: stored [0.5, 3.0], requested [4.0]" in line and "seed" not in line


def test_resume_with_more_trials_extends_the_run_exactly(tmp_path, report_stub):
    run = make_run(tmp_path / "run", trials=3)
    assert main(["run", "--resume", str(run), "--trials", "5", "--workers", "1"]) == 0
    meta = json.loads((run / "run.json").read_text())
    assert meta["trials"] == 5 and meta["config"]["experiment"]["trials"] == 5
    ref = make_run(tmp_path / "ref", trials=5)
    for name in CSV_FILES:
        assert (run / name).read_bytes() == (ref / name).read_bytes(), name


def test_sweep_resume_conflicts_and_more_trials(tmp_path, capsys, report_stub, monkeypatch):
    kw = dict(
        trial_fn=ft.fake_trial, load_fn=ft.fake_load, options=RunOptions(progress=False, figures=False, workers=1)
    )
    sw = tmp_path / "sw"
    run_sweep("births", (-1, 0), small_config(2), "intersection", out=sw, **kw)
    assert main(["sweep", "clutter", "--resume", str(sw)]) == 2
    assert "kind: stored 'births', requested 'clutter'" in one_error_line(capsys)
    assert main(["sweep", "births", "--resume", str(sw), "--duration", "50"]) == 2
    assert "experiment.duration: stored 10.0, requested 50.0" in one_error_line(capsys)
    assert main(["sweep", "births", "--resume", str(sw), "--offsets", "0,3"]) == 2
    assert "values: stored [-1.0, 0.0], requested [0.0, 3.0]" in one_error_line(capsys)
    import soabench.experiment.campaigns.sweep as sweep_mod

    monkeypatch.setattr(sweep_mod, "write_sweep_report", lambda d: "sweep")
    assert main(["sweep", "births", "--resume", str(sw), "--trials", "3", "--workers", "1"]) == 0
    for point in (sw / "points").iterdir():
        assert len(list((point / "trials").glob("*.json"))) == 3
        assert json.loads((point / "run.json").read_text())["trials"] == 3


def test_study_rerun_with_other_settings_is_refused(tmp_path, capsys):
    root = tmp_path / "study"
    make_run(root / "main", trials=2)
    assert main(["study", "--out", str(root), "--duration", "50"]) == 2
    assert "experiment.duration: stored 10.0, requested 50.0" in one_error_line(capsys)
    assert main(["study", "--out", str(root), "--seed", "1"]) == 2
    assert "experiment.seed: stored 5, requested 1" in one_error_line(capsys)
