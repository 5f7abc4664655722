"""Test-session setup shared by every test module."""

from __future__ import annotations

import signal

import pytest

# A test run started from a background shell (`pytest &`, some CI runners) inherits SIGINT ignored, and an ignored
# disposition survives fork and exec: every driver process the Ctrl-C tests start would then ignore the Ctrl-C they
# send. Python's own handler (reset to the default on exec) gives the children what a terminal gives them.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_sessionstart(session: pytest.Session) -> None:
    """Before the workers start (pytest-xdist, the whole suite on two or more of them): every kernel group compiled
    once into the cache, one process per group (soabench.kernel_warmup.ensure_compiled; nothing to do when the
    cache already holds them, as on a second run). Left to the tests on a fresh machine, each worker compiled the
    same kernels at the same time. A subset of the tests (files named on the command line, -n 0) compiles only what
    it calls, as before."""
    config = session.config
    workers = len(getattr(config.option, "tx", None) or ())
    whole_suite = getattr(config, "args_source", None) == pytest.Config.ArgsSource.TESTPATHS
    if hasattr(config, "workerinput") or workers < 2 or not whole_suite or config.option.collectonly:
        return
    from soabench.kernel_warmup import ensure_compiled

    ensure_compiled()


@pytest.fixture
def typed_plugins_cleared():
    """The test starts with no typed import paths (soabench.plugins keeps them per process) and leaves none."""
    from soabench import plugins

    saved = set(plugins._TYPED)
    plugins._TYPED.clear()
    yield
    plugins._TYPED.clear()
    plugins._TYPED.update(saved)


# ------------------------------------------------------------------------------------ stand-ins for real work
@pytest.fixture
def fake_builtins():
    """For the test, the built-in trial kind and scene loader are tests/fake_trial.py's fast, deterministic
    stand-ins (through the registry's public hook), so ``soabench run`` and the campaigns run fake trials."""
    import fake_trial as ft

    with ft.as_builtins():
        yield


@pytest.fixture
def fake_cli_runs(monkeypatch, fake_builtins):
    """:func:`fake_builtins`, and a run's report is the string "summary" (no statistics, no figures)."""
    import soabench.experiment.reports.report as report

    monkeypatch.setattr(report, "write_report", lambda run_dir, figures=True, store=None: "summary")


@pytest.fixture
def no_work(monkeypatch):
    """Any trial, simulation, KITTI sequence or netconvert started by a case fails the test (bad inputs must be
    refused before): the stubs of bad_inputs.work_stubbed raise WorkStarted and note the call in the list returned."""
    import bad_inputs

    monkeypatch.setattr(bad_inputs, "STARTED", [])
    with bad_inputs.work_stubbed(monkeypatch.setattr):
        yield bad_inputs.STARTED


@pytest.fixture(scope="session")
def recorded_intersection():
    """(config, scene, {lambda: (sensor, scans)} at lambda = 3 and 10, seeds) of a 30 s trial of the shipped
    intersection (SUMO), shared by the filter tests that run on recorded scans."""

    from soabench.config import Config
    from soabench.scenario import load, simulate
    from soabench.seeding import trial_seeds
    from soabench.sensor import observe

    scene, scenario = load("intersection")
    cfg = Config()
    seeds = trial_seeds(4, 1)
    rec = simulate(scene, scenario, seeds, duration=30.0)
    scans = {}
    for lam in (3.0, 10.0):
        sensor = cfg.sensor_at(lam)
        scans[lam] = (sensor, observe(rec, scene, sensor, seeds.sensor_rngs()))
    return cfg, scene, scans, seeds


@pytest.fixture
def trackeval_kitti():
    """TrackEval's KITTI 2-D box evaluation, printing nothing: ``evaluate(gt, trackers, names, classes)`` scores
    ``trackers/<name>/data/XXXX.txt`` against ``gt/label_02`` (with ``gt/evaluate_tracking.seqmap.training``) and
    returns ``{name: {class: {"HOTA": ..., "CLEAR": ..., "Identity": ...}}}`` of the combined sequences."""
    import trackeval  # the test extra installs it

    def evaluate(gt, trackers, names: list[str], classes: list[str]) -> dict:
        config = trackeval.Evaluator.get_default_eval_config()
        config.update(
            USE_PARALLEL=False, PRINT_RESULTS=False, PRINT_CONFIG=False, TIME_PROGRESS=False, OUTPUT_SUMMARY=False,
            OUTPUT_DETAILED=False, PLOT_CURVES=False, DISPLAY_LESS_PROGRESS=True,
        )  # fmt: skip
        dataset = trackeval.datasets.Kitti2DBox(
            {
                "GT_FOLDER": str(gt), "TRACKERS_FOLDER": str(trackers), "OUTPUT_FOLDER": str(trackers.parent / "o"),
                "TRACKERS_TO_EVAL": names, "CLASSES_TO_EVAL": classes, "PRINT_CONFIG": False,
            }
        )  # fmt: skip
        metrics = [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR(), trackeval.metrics.Identity()]
        res, msg = trackeval.Evaluator(config).evaluate([dataset], metrics)
        assert msg["Kitti2DBox"] == dict.fromkeys(names, "Success")
        return {name: res["Kitti2DBox"][name]["COMBINED_SEQ"] for name in names}

    return evaluate
