"""Plugins that fail or misbehave: a failed method is never a success, a plugin cannot end, hang or change the run
(docs/user-guide/own-tracker.md, "When a plugin fails"; soabench.experiment.trial.isolate).

The plugins are the module-level classes of ``tests/plugin_fixtures.py``, named by import path as a user types them.
"""

from __future__ import annotations

import dataclasses
import json
import time

import numpy as np
import pytest

from soabench import plugins
from soabench.cli.main import main
from soabench.config import Config, ExperimentConfig
from soabench.errors import Interrupted, SoabenchError
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.reports.finished import run_experiment
from soabench.experiment.runs.files import read_csv
from soabench.experiment.trial.trial import run_trial

FX = "plugin_fixtures"


pytestmark = pytest.mark.usefixtures("typed_plugins_cleared")  # conftest.py


@pytest.fixture(scope="module")
def intersection():
    from soabench.scenario import load

    return load("intersection")


def _cfg(models=("soa",), trackers=(), trials=1, duration=6.0, **exp) -> Config:
    plugins.allow_import_paths([*models, *trackers])
    e = ExperimentConfig(
        trials=trials, duration=duration, models=models, trackers=trackers, probabilities=("static",), seed=3, **exp
    )
    return Config(experiment=e).validate()


def _no_times(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if not k.startswith("t_")} for r in rows]


def _cli_run(tmp_path, capsys, *args: str) -> tuple[int, str, str]:
    argv = ["run", "--trials", "2", "--duration", "4", "--probabilities", "static", "--models", "soa"]
    rc = main([*argv, "--workers", "1", "--no-progress", "--out", str(tmp_path / "run"), *args])
    out, err = capsys.readouterr()
    return rc, out, err


# ------------------------------------------------------------------------------------------------ failure = not 0
def test_a_method_that_fails_everywhere_is_not_a_success(tmp_path, capsys) -> None:
    rc, out, err = _cli_run(tmp_path, capsys, "--trackers", f"{FX}:AlwaysRaises")
    assert rc == 1, err
    line = [ln for ln in err.splitlines() if "method run(s) failed" in ln]
    assert len(line) == 1 and f"'{FX}:AlwaysRaises' in 2 run(s) of 2 trial(s)" in line[0]
    assert "exit status 1" in line[0]
    run = tmp_path / "run"
    assert set(read_csv(run / "trials.csv")["model"]) == {"soa"}  # the good method's results are all there
    record = json.loads((run / "trials" / "trial_00001.json").read_text())
    (fail,) = record["model_failures"]
    assert "RuntimeError: fails at every scan" in fail["traceback"] and "plugin_fixtures.py" in fail["traceback"]
    assert "traceback" not in (run / "model_failures.csv").read_text().splitlines()[0]  # the table keeps its columns


@pytest.mark.slow
def test_a_run_without_failures_still_exits_0(tmp_path, capsys) -> None:
    rc, out, err = _cli_run(tmp_path, capsys, "--trackers", f"{FX}:EchoTracker")
    assert rc == 0 and "method run(s) failed" not in err


def test_fail_fast_stops_at_a_failed_method_run(tmp_path) -> None:
    cfg = _cfg(trackers=(f"{FX}:AlwaysRaises",), trials=3, duration=4.0)
    o = run_experiment(
        cfg, "intersection", out=tmp_path / "r", options=RunOptions(workers=1, fail_fast=True, progress=False)
    )
    assert not o.complete and o.n_done == 1 and o.n_missing == 2
    assert not (tmp_path / "r" / "summary.md").exists()  # no report passed off as complete


# ------------------------------------------------------------------------------------------------ ending the process
@pytest.mark.parametrize(
    ("tracker", "message"),
    [
        ("SysExit", "the plugin called sys.exit(0)"),
        ("OsExit", "the plugin called os._exit(0)"),
        ("RaisesKeyboardInterrupt", "the plugin raised KeyboardInterrupt"),
    ],
)
def test_a_plugin_cannot_end_the_run(tmp_path, tracker, message) -> None:
    name = f"{FX}:{tracker}"
    cfg = _cfg(trackers=(name,), trials=2, duration=4.0)
    out = tmp_path / "r"
    o = run_experiment(cfg, "intersection", out=out, options=RunOptions(workers=1, progress=False, figures=False))
    assert o.complete and o.n_done == 2
    assert [(f["model"], f["k"], f["error"]) for f in o.model_failures] == [(name, 0, message)] * 2
    # the same on --resume
    (out / "trials" / "trial_00001.json").unlink()
    o2 = run_experiment(None, "ignored", resume=out, options=RunOptions(workers=1, progress=False, figures=False))
    assert o2.complete and [f["error"] for f in o2.model_failures] == [message] * 2


def test_os_exit_in_a_pool_worker_is_the_plugins_failure(tmp_path) -> None:
    cfg = _cfg(trackers=(f"{FX}:OsExit",), trials=2, duration=4.0)
    o = run_experiment(
        cfg, "intersection", out=tmp_path / "r", options=RunOptions(workers=2, progress=False, figures=False)
    )
    assert o.complete and [f["error"] for f in o.model_failures] == ["the plugin called os._exit(0)"] * 2


def test_a_dying_worker_is_named_with_its_trial_and_plugin(tmp_path) -> None:
    name = f"{FX}:KillsItsProcess"
    cfg = _cfg(trackers=(name,), trials=2, duration=4.0)
    o = run_experiment(
        cfg, "intersection", out=tmp_path / "r", options=RunOptions(workers=2, progress=False, figures=False)
    )
    assert not o.complete
    errors = {f["trial"]: f["error"] for f in o.failures}
    assert errors, o
    died = [e for e in errors.values() if "killed by signal SIGKILL" in e]
    assert died, errors
    for t, e in errors.items():  # the dead worker's own trial, or one the broken pool stopped, naming the culprit
        assert f"trial {t}" in e or (f"tracker plugin '{name}'" in e and "pool stopped" in e), e
    assert any(f"tracker plugin '{name}'" in e for e in died), died


def test_a_real_ctrl_c_while_a_plugin_runs_still_stops_the_run(tmp_path) -> None:
    cfg = _cfg(trackers=(f"{FX}:CtrlCWhileRunning",), trials=2, duration=4.0)
    with pytest.raises(Interrupted, match="soabench run --resume"):
        run_experiment(
            cfg, "intersection", out=tmp_path / "r", options=RunOptions(workers=1, progress=False, figures=False)
        )


# ------------------------------------------------------------------------------------------------ hangs and prints
@pytest.mark.slow
def test_a_plugin_that_hangs_is_stopped_by_the_budget(tmp_path, capsys) -> None:
    (tmp_path / "c.toml").write_text("[experiment]\nplugin_budget = 1.0\n")
    t0 = time.perf_counter()
    rc, out, err = _cli_run(tmp_path, capsys, "--trackers", f"{FX}:SleepsForever", "--config", str(tmp_path / "c.toml"))
    assert time.perf_counter() - t0 < 120
    assert rc == 1
    lines = [ln for ln in err.splitlines() if "budget" in ln and "SleepsForever" in ln]
    said = [ln for ln in lines if "passed its budget of 1 s (experiment.plugin_budget) in one call: stopped" in ln]
    assert [ln.split("(trial ")[1][:1] for ln in said] == ["0", "1"], err  # each said when its budget passed
    assert lines.index(said[1]) > lines.index(said[0]) + 1  # trial 0's failure record came in between
    assert len(lines) == 4 and "budget of 1 s (experiment.plugin_budget)" in lines[1], err
    record = json.loads((tmp_path / "run" / "trials" / "trial_00000.json").read_text())
    assert "time.sleep(1e6)" in record["model_failures"][0]["traceback"]  # where it hung


def test_the_budget_is_a_validated_config_key() -> None:
    with pytest.raises(SoabenchError, match="plugin_budget"):
        Config.from_dict({"experiment": {"plugin_budget": -1.0}}).validate()
    assert Config.from_dict({"experiment": {"plugin_budget": 0}}).experiment.plugin_budget == 0.0


@pytest.mark.slow
def test_plugin_prints_stay_off_stdout(tmp_path, capsys) -> None:
    rc, out, err = _cli_run(tmp_path, capsys, "--trackers", f"{FX}:Prints")
    assert rc == 0
    assert "PLUGIN OUTPUT LINE" not in out and "PLUGIN OUTPUT LINE" in err
    assert "every table:" in out  # the run's answer is on stdout, the plugin's print is not


# ------------------------------------------------------------------------------------------------ private scans
def test_a_plugin_that_changes_its_scan_changes_no_other_method(intersection) -> None:
    """S-OA's rows with a scan-mutating tracker and birth model beside it (listed first) equal S-OA's alone."""
    scene, scenario = intersection
    models = (f"{FX}:ScanMutatingBirth", "soa", "ubm")
    cfg = _cfg(models=models, trackers=(f"{FX}:ScanMutator",), clutter=(0.5, 5.0))
    res = run_trial(0, cfg, scene, scenario)
    assert not res.failures
    alone = run_trial(0, _cfg(models=("soa", "ubm"), clutter=(0.5, 5.0)), scene, scenario)
    builtin = [r for r in res.rows if r["model"] in ("soa", "ubm")]
    assert _no_times(builtin) == _no_times(alone.rows)
    assert [s for s in res.steps if s["model"] in ("soa", "ubm")] == alone.steps


def test_private_scan_is_equal_and_shares_nothing(intersection) -> None:
    from soabench.config import Sensor
    from soabench.experiment.trial.isolate import private_scan
    from soabench.scenario import simulate
    from soabench.seeding import trial_seeds
    from soabench.sensor import observe

    scene, scenario = intersection
    seeds = trial_seeds(3, 0)
    scans = observe(simulate(scene, scenario, seeds, duration=3.0), scene, Sensor(), seeds.sensor_rngs())
    scan = next(s for s in scans.scans if len(s.obstacles))
    copy = private_scan(scan)
    for f in ("ego", "Z"):
        a, b = getattr(scan, f), getattr(copy, f)
        assert np.array_equal(a, b) and not np.shares_memory(a, b)
    for f in dataclasses.fields(scan.obstacles):
        a, b = getattr(scan.obstacles, f.name), getattr(copy.obstacles, f.name)
        if isinstance(a, np.ndarray):
            assert np.array_equal(a, b) and not np.shares_memory(a, b)
    assert copy.occluders == scan.occluders and copy.occluders is not scan.occluders
    assert copy.k == scan.k and copy.__dict__["_visible_region"] is scan.__dict__["_visible_region"]


# ------------------------------------------------------------------------------------------------ refused at load
@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["run", "--models", "os:system", "--trials", "1"], "is the built-in function posix.system, not a class"),
        (["run", "--models", "soa", "--trackers", "os:getcwd", "--trials", "1"], "not a class"),
        (["run", "--models", "json:JSONDecoder", "--trials", "1"], "has no __call__() method"),
        (["birth", "--model", "os:system", "--out", "x.png"], "not a class"),
        (["run", "--models", "no_such_module_xyz:Thing", "--trials", "1"], "must be importable: put the folder"),
    ],
)
def test_import_paths_that_name_no_plugin_class_are_refused(tmp_path, capsys, monkeypatch, argv, needle) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], err
    assert not list(tmp_path.iterdir())  # nothing written


def test_a_missing_dependency_of_a_plugin_is_named(tmp_path, monkeypatch) -> None:
    (tmp_path / "needs_dep.py").write_text("import not_installed_dep_xyz\nclass T:\n    def step(self, scan): ...\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    plugins.allow_import_paths(["needs_dep:T"])
    with pytest.raises(SoabenchError, match="imports 'not_installed_dep_xyz', which is not installed"):
        plugins.resolve(plugins.TRACKER, "needs_dep:T")


def test_birth_command_names_a_failing_plugin_in_one_line(tmp_path, capsys) -> None:
    out = tmp_path / "b.png"
    argv = ["birth", "--model", f"{FX}:RaiseAtScan3", "--time", "5", "--out", str(out)]
    assert main(argv) == 2
    lines = [ln for ln in capsys.readouterr().err.strip().splitlines() if "compiling" not in ln]
    assert len(lines) == 1 and f"birth model plugin '{FX}:RaiseAtScan3' failed: RuntimeError: boom at three" in lines[0]
    assert not out.exists()


def test_failed_method_runs_of_sweep_and_study_outcomes_are_collected(tmp_path) -> None:
    from types import SimpleNamespace

    from soabench.experiment.execution.runner import RunOutcome
    from soabench.experiment.runs.failures import failed_methods_line, outcome_model_failures

    def run(*models):
        fails = [{"model": m, "trial": t, "k": 0} for t, m in enumerate(models)]
        return RunOutcome(tmp_path, True, 1, 0, model_failures=fails)

    sweep = SimpleNamespace(points=[run("a"), run(), run("a", "b")])
    study = SimpleNamespace(main=run("b"), clutter=sweep, births=SimpleNamespace(points=[]), sensitivity=(run("c"),))
    assert [f["model"] for f in outcome_model_failures(study)] == ["b", "a", "a", "b", "c"]
    line = failed_methods_line(outcome_model_failures(sweep))
    assert "3 method run(s) failed" in line and "'a' in 2 run(s) of 1 trial(s)" in line and "'b' in 1 run(s)" in line
    assert failed_methods_line([]) == ""
