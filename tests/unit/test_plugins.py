"""Public API, plugin registry, plugin checks and failure records.

The broken plugins of ``tests/plugin_fixtures.py`` are named by import path, as a user would type them.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from local_dask import local_cluster

from soabench import plugins
from soabench.config import Config, ExperimentConfig
from soabench.errors import SoabenchError
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.trial import guard
from soabench.experiment.trial.trial import run_trial
from soabench.types import Births, Estimates, NewbornTerms, Scan

FX = "plugin_fixtures"


pytestmark = pytest.mark.usefixtures("typed_plugins_cleared")  # conftest.py


# ------------------------------------------------------------------------------------------------ the API layer
def test_types_module_imports_no_stage() -> None:
    code = (
        "import sys, soabench.types, soabench.protocols; "
        "print(sorted(m for m in sys.modules if m.startswith('soabench')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert eval(out) == ["soabench", "soabench.errors", "soabench.protocols", "soabench.types"]


def test_api_hands_out_the_classes_of_types_and_protocols() -> None:
    from soabench import api
    from soabench.protocols import BirthModel
    from soabench.types import BirthContext, Births, NewbornTerms, Recording, Scan, Scans, StepResult

    assert (Births, NewbornTerms, BirthContext, BirthModel) == (
        api.Births,
        api.NewbornTerms,
        api.BirthContext,
        api.BirthModel,
    )
    assert (StepResult, Recording, Scan, Scans) == (api.StepResult, api.Recording, api.Scan, api.Scans)
    assert set(api.__all__) <= set(dir(api))


# ------------------------------------------------------------------------------------------------ the registry
def test_closed_list_refuses_untyped_import_paths() -> None:
    with pytest.raises(SoabenchError, match="is an import path its caller did not name"):
        plugins.check_name(plugins.BIRTH, f"{FX}:OneBirth")
    with pytest.raises(SoabenchError, match="unknown; choose one of soa, pubm"):
        plugins.check_name(plugins.BIRTH, "nosuch")
    with pytest.raises(SoabenchError, match="tracker 'nosuch' is unknown; choose one of stonesoup-gmphd"):
        plugins.check_name(plugins.TRACKER, "nosuch")
    with pytest.raises(SoabenchError, match="package.module:Class"):
        plugins.allow_import_paths(["os:system()"])
    plugins.allow_import_paths([f"{FX}:OneBirth", "soa"])
    assert plugins.session_import_paths() == (f"{FX}:OneBirth",)
    from plugin_fixtures import OneBirth

    assert plugins.resolve(plugins.BIRTH, f"{FX}:OneBirth") is OneBirth


def test_resolve_names_the_plugin_on_import_errors() -> None:
    plugins.allow_import_paths(["no_such_module_xyz:Thing", f"{FX}:Missing", f"{FX}:NotATracker"])
    with pytest.raises(plugins.PluginError, match="'no_such_module_xyz:Thing' cannot be imported: ModuleNotFound"):
        plugins.resolve(plugins.BIRTH, "no_such_module_xyz:Thing")
    with pytest.raises(plugins.PluginError, match="'plugin_fixtures:Missing' cannot be imported: AttributeError"):
        plugins.resolve(plugins.TRACKER, f"{FX}:Missing")
    with pytest.raises(SoabenchError, match="has no step"):
        plugins.resolve(plugins.TRACKER, f"{FX}:NotATracker")


def test_plugin_options_from_toml_and_preflight(tmp_path) -> None:
    from soabench.config import load_config

    name = f"{FX}:OneBirth"
    plugins.allow_import_paths([name, f"{FX}:EchoTracker"])
    f = tmp_path / "c.toml"
    f.write_text(
        f'[experiment]\nmodels = ["soa", "{name}"]\ntrackers = ["{FX}:EchoTracker"]\n'
        f'[plugins."{name}"]\nahead = 5\n[plugins."{FX}:EchoTracker"]\nscale = 2.0\n'
    )
    cfg = load_config(f)
    assert cfg.plugins == {name: {"ahead": 5}, f"{FX}:EchoTracker": {"scale": 2.0}}
    assert Config.from_dict(cfg.to_dict()).plugins == cfg.plugins
    plugins.preflight(cfg)
    cfg.plugins[name] = {"behind": 1}
    with pytest.raises(
        SoabenchError, match="sets 'behind', which the birth model .* does not accept; its options: ahead"
    ):
        plugins.preflight(cfg)
    cfg.plugins = {"soa": {"x": 1}}
    with pytest.raises(SoabenchError, match=r"\[plugins.soa\]: soa is a built-in"):
        plugins.preflight(cfg)
    with pytest.raises(SoabenchError, match="named both as a model and as a tracker"):
        ExperimentConfig(models=(name,), trackers=(name,)).validate()


# ------------------------------------------------------------------------------------------------ output checks
def _scan(M: int = 2) -> Scan:
    return Scan(0, 0.0, np.zeros(3), np.ones((M, 2)), None, [], None)


def _births(**change) -> Births:
    b = Births(np.array([0.1]), np.zeros((1, 4)), np.eye(4)[None].copy(), np.zeros(1, dtype=np.int8))
    for k, v in change.items():
        setattr(b, k, v)
    return b


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"w": np.array([np.nan])}, "Births.w holds NaN"),
        ({"w": np.array([-0.1])}, "negative weights"),
        ({"m": np.zeros((1, 2))}, r"Births.m has shape \(1, 2\); \(1, 4\) is required"),
        ({"P": np.zeros((2, 4, 4))}, r"Births.P has shape"),
        ({"w": np.array(["a"])}, "dtype <U1; a real-valued numeric array"),
        ({"source": np.zeros(1)}, r"Births.source .* int needed"),
        ({"P": np.triu(np.ones((4, 4)))[None]}, "not symmetric"),
        ({"w": np.array([1e300])}, r"Births.w\[0\] = 1e\+300; a birth weight .* in \[0, 100\]"),
        ({"m": np.full((1, 4), 1e300)}, r"Births.m\[0\] = .* within \+-1e\+07"),
        ({"P": -np.eye(4)[None]}, r"Births.P\[0\] is not positive definite \(smallest eigenvalue -1\)"),
        ({"P": np.zeros((1, 4, 4))}, r"Births.P\[0\] is not positive definite"),
        ({"P": np.ones((1, 4, 4))}, r"Births.P\[0\] is not positive definite"),
        ({"P": 1e300 * np.eye(4)[None]}, r"Births.P\[0\] has an eigenvalue of 1e\+300"),
    ],
)
def test_check_births_rejects(change, message) -> None:
    with pytest.raises(guard.PluginOutputError, match=message):
        guard.check_births(_births(**change), _scan())


def test_check_births_names_the_plugin_when_given() -> None:
    with pytest.raises(guard.PluginOutputError, match=r"^birth model 'pkg:Mine' at scan 0: Births.w\[0\] = 1e\+300"):
        guard.check_births(_births(w=np.array([1e300])), _scan(), "pkg:Mine")
    nb = NewbornTerms(np.zeros((2, 4)), np.zeros((2, 4, 4)), lambda A, k: np.ones(2))
    with pytest.raises(guard.PluginOutputError, match=r"NewbornTerms.P\[0\] is not positive definite"):
        guard.check_births(_births(newborn=nb), _scan(2), "pkg:Mine")


def test_check_births_accepts_and_checks_newborn_beta() -> None:
    ok = guard.check_births(_births(), _scan())
    assert ok.w.dtype == float and len(ok) == 1
    with pytest.raises(guard.PluginOutputError, match="returned None"):
        guard.check_births(None, _scan())
    nb = NewbornTerms(np.zeros((3, 4)), np.tile(np.eye(4), (3, 1, 1)), lambda A, k: np.ones(3))
    with pytest.raises(guard.PluginOutputError, match=r"NewbornTerms.m has shape \(3, 4\); \(2, 4\)"):
        guard.check_births(_births(newborn=nb), _scan(2))
    nb = NewbornTerms(np.zeros((2, 4)), np.tile(np.eye(4), (2, 1, 1)), lambda A, k: -np.ones(2))
    checked = guard.check_births(_births(newborn=nb), _scan(2))
    with pytest.raises(guard.PluginOutputError, match="beta.* is negative"):
        checked.newborn.beta(np.zeros(2), np.ones(2))


def test_check_estimates() -> None:
    res = guard.check_estimates(Estimates(np.ones((2, 2))), _scan(), 0.01)
    assert res.X.shape == (2, 4) and np.all(res.X[:, 2:] == 0) and res.n_reduced == 2 and math.isnan(res.sum_w)
    res = guard.check_estimates(Estimates(np.zeros((0, 4)), n_components=7, cardinality=0.5), _scan(), 0.0)
    assert res.n_reduced == 7 and res.sum_w == 0.5
    for bad, msg in [
        (None, "returned None"),
        ([1, 2], "returned list"),
        (Estimates(np.full((1, 2), np.inf)), "NaN or infinite"),
        (Estimates(np.ones((1, 2)), w=np.array([-1.0])), "negative"),
        (Estimates(np.ones((1, 2)), n_components=-1), "n_components"),
    ]:
        with pytest.raises(guard.PluginOutputError, match=msg):
            guard.check_estimates(bad, _scan(), 0.0)
    for X, msg in [(np.ones(3), r"shape \(3,\)"), (np.ones((1, 3)), r"shape \(1, 3\)")]:
        with pytest.raises(ValueError, match=r"^Estimates: X has " + msg):  # refused when built, naming X
            Estimates(X)
        built = Estimates(np.ones((1, 2)))
        built.X = X  # changed after building: the harness still refuses it
        with pytest.raises(guard.PluginOutputError, match=msg):
            guard.check_estimates(built, _scan(), 0.0)


# ------------------------------------------------------------------------------------------------ real trial
BAD_MODELS = {
    "RaiseAtScan3": (3, "RuntimeError: boom at three"),
    "NaNWeights": (2, "Births.w holds NaN"),
    "NegativeWeights": (0, "negative weights"),
    "WrongShape": (0, "Births.m has shape (1, 2)"),
    "ReturnsNone": (0, "returned None"),
    "BadInit": (-1, "ImportError: a dependency of this plugin is missing"),
}
BAD_TRACKERS = {
    "SilentTracker": (0, "the tracker returned None"),
    "NaNTracker": (0, "NaN or infinite"),
    "StringTracker": (0, "dtype <U1"),
}


@pytest.fixture(scope="module")
def intersection():
    from soabench.scenario import load

    return load("intersection")


def _cfg(models, trackers=(), **plugin_options) -> Config:
    exp = ExperimentConfig(trials=1, duration=8.0, models=models, trackers=trackers, probabilities=("static",), seed=3)
    return Config(experiment=exp, plugins=plugin_options)


def test_bad_plugins_are_recorded_and_others_kept(intersection) -> None:
    scene, scenario = intersection
    models = ("soa", *(f"{FX}:{m}" for m in BAD_MODELS), f"{FX}:OneBirth", f"{FX}:NegativeNewborn")
    trackers = tuple(f"{FX}:{t}" for t in (*BAD_TRACKERS, "EchoTracker"))
    plugins.allow_import_paths(models + trackers)
    cfg = _cfg(models, trackers)
    cfg.validate()
    res = run_trial(0, cfg, scene, scenario)
    got = {r["model"] for r in res.rows}
    assert got == {"soa", f"{FX}:OneBirth", f"{FX}:EchoTracker"}
    fails = {f["model"].split(":")[1]: f for f in res.failures}
    assert set(fails) == {*BAD_MODELS, *BAD_TRACKERS, "NegativeNewborn"}
    for name, (k, msg) in {**BAD_MODELS, **BAD_TRACKERS}.items():
        assert fails[name]["k"] == k and msg in fails[name]["error"], fails[name]
        assert fails[name]["trial"] == 0 and fails[name]["mode"] == "static"
    assert "NewbornTerms.beta" in fails["NegativeNewborn"]["error"]
    line = guard.failure_message(fails["RaiseAtScan3"])
    assert "'plugin_fixtures:RaiseAtScan3' failed in trial 0 at scan 3" in line
    assert "before the first scan" in guard.failure_message(fails["BadInit"])
    for r in res.rows:  # the kept rows are real results
        assert all(math.isfinite(r[k]) for k in ("ospa", "card_err", "gospa")), r
    # the plugins do not disturb S-OA's run: same numbers as S-OA alone (common random numbers)
    alone = run_trial(0, _cfg(("soa",)), scene, scenario)
    drop = {k for k in alone.rows[0] if k.startswith("t_")}
    soa = [r for r in res.rows if r["model"] == "soa"]
    assert [{k: v for k, v in r.items() if k not in drop} for r in soa] == [
        {k: v for k, v in r.items() if k not in drop} for r in alone.rows
    ]


def test_run_workers_summary_failures_and_resume_by_name(tmp_path) -> None:
    from soabench.experiment.reports.finished import run_experiment
    from soabench.experiment.runs.files import read_csv

    one, echo, bad = f"{FX}:OneBirth", f"{FX}:EchoTracker", f"{FX}:RaiseAtScan3"
    plugins.allow_import_paths([one, echo, bad])
    cfg = _cfg(("soa", one, bad), (echo,), **{one: {"ahead": 5.0}})
    cfg.experiment.trials = 2
    out = tmp_path / "run"
    o = run_experiment(cfg, "intersection", out=out, options=RunOptions(workers=2, progress=False, figures=False))
    assert o.complete
    rows = read_csv(out / "trials.csv")
    assert sorted(set(rows["model"])) == sorted({"soa", one, echo}) and len(rows["model"]) == 6
    summary = json.loads((out / "summary.json").read_text())
    assert [(f["model"], f["trial"], f["k"]) for f in summary["model_failures"]] == [(bad, 0, 3), (bad, 1, 3)]
    vs = {c["baseline"] for c in summary["results"][0]["vs_soa"]}
    assert vs == {one, echo}  # paired statistics against S-OA for every plugin
    assert "Failed model runs (2)" in (out / "summary.md").read_text()
    assert read_csv(out / "model_failures.csv")["model"].tolist() == [bad, bad]
    run_json = json.loads((out / "run.json").read_text())
    assert run_json["config"]["plugins"] == {one: {"ahead": 5.0}}

    # resume: names from run.json are not imported unless typed again on this command line
    (out / "trials" / "trial_00001.json").unlink()
    plugins._TYPED.clear()
    with pytest.raises(SoabenchError, match="is an import path its caller did not name"):
        run_experiment(None, "ignored", resume=out, options=RunOptions(workers=1, progress=False, figures=False))
    plugins.allow_import_paths([one, echo, bad])
    o2 = run_experiment(None, "ignored", resume=out, options=RunOptions(workers=1, progress=False, figures=False))
    assert o2.complete
    again = read_csv(out / "trials.csv")
    for col in ("model", "ospa", "card_err", "gospa", "n_episodes"):
        assert (
            np.array_equal(again[col], rows[col])
            if again[col].dtype.kind in "OU"
            else np.allclose(again[col], rows[col], equal_nan=True)
        ), col


def test_cli_plugin_errors_are_one_line(capsys) -> None:
    from soabench.cli.main import main

    assert main(["run", "--models", "soa", "--trackers", "nosuch", "--trials", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tracker 'nosuch' is unknown" in err[0]
    assert main(["run", "--models", "no_such_module_xyz:Thing", "--trials", "1", "--duration", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'no_such_module_xyz:Thing' cannot be imported" in err[0]


@pytest.mark.slow
def test_plugins_on_dask_match_a_serial_run(tmp_path) -> None:
    """Dask workers get the typed import paths from the task (not from a file) and compute the same numbers."""

    pytest.importorskip("distributed")
    from soabench.experiment.reports.finished import run_experiment
    from soabench.experiment.runs.files import read_csv

    one, echo, bad = f"{FX}:OneBirth", f"{FX}:EchoTracker", f"{FX}:RaiseAtScan3"
    plugins.allow_import_paths([one, echo, bad])
    cfg = _cfg(("soa", one, bad), (echo,))
    serial = run_experiment(
        cfg, "intersection", out=tmp_path / "s", options=RunOptions(workers=1, progress=False, figures=False)
    )
    with local_cluster(1) as address:
        dask = run_experiment(
            cfg,
            "intersection",
            out=tmp_path / "d",
            options=RunOptions(scheduler=address, progress=False, figures=False),
        )
    assert serial.complete and dask.complete
    a, b = read_csv(tmp_path / "s" / "trials.csv"), read_csv(tmp_path / "d" / "trials.csv")
    assert list(a["model"]) == list(b["model"]) == ["soa", one, echo]
    for col in a:
        if not col.startswith("t_") and a[col].dtype.kind == "f":
            assert np.array_equal(a[col], b[col], equal_nan=True), col
    fa = json.loads((tmp_path / "d" / "summary.json").read_text())["model_failures"]
    assert [(f["model"], f["k"]) for f in fa] == [(bad, 3)]


def test_study_takes_plugins_beside_the_papers_five(monkeypatch, capsys) -> None:
    from types import SimpleNamespace

    from soabench.cli.main import main
    from soabench.config import BIRTH_MODEL_NAMES
    from soabench.experiment.campaigns import study

    seen = {}

    def fake_study(request):
        seen["cfg"] = request.config
        return SimpleNamespace(summary_markdown="", complete=True, run_dir="x", n_missing=0)

    monkeypatch.setattr(study, "study", fake_study)
    one, echo = f"{FX}:OneBirth", f"{FX}:EchoTracker"
    assert main(["study", "--models", one, "--trackers", echo, "--trials", "1"]) == 0
    exp = seen["cfg"].experiment
    assert exp.models == (*BIRTH_MODEL_NAMES, one) and exp.trackers == (echo,)
    assert main(["study", "--models", "soa"]) == 2
    assert "adds plugins only" in capsys.readouterr().err


def test_an_import_path_whose_package_is_missing_says_how_to_make_it_importable(tmp_path, monkeypatch) -> None:
    """The advice names PYTHONPATH and an install only when the plugin's own top-level package is missing."""
    plugins.allow_import_paths(["no_such_pkg_xyz.births:Ring"])
    with pytest.raises(
        plugins.PluginError,
        match=r"No module named 'no_such_pkg_xyz' \(the module 'no_such_pkg_xyz.births' must be importable",
    ):
        plugins.resolve(plugins.BIRTH, "no_such_pkg_xyz.births:Ring")
    (tmp_path / "broken_pkg_xyz").mkdir()
    (tmp_path / "broken_pkg_xyz" / "__init__.py").write_text("")
    (tmp_path / "broken_pkg_xyz" / "births.py").write_text("import no_such_dependency_xyz\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    plugins.allow_import_paths(["broken_pkg_xyz.births:Ring"])
    with pytest.raises(plugins.PluginError) as info:  # the plugin's own missing dependency: no PYTHONPATH advice
        plugins.resolve(plugins.BIRTH, "broken_pkg_xyz.births:Ring")
    assert "no_such_dependency_xyz" in str(info.value) and "PYTHONPATH" not in str(info.value)
