"""Test-session setup shared by every test module."""

from __future__ import annotations

import signal

import pytest

# A test run started from a background shell (`pytest &`, some CI runners) inherits SIGINT ignored, and an ignored
# disposition survives fork and exec: every driver process the Ctrl-C tests start would then ignore the Ctrl-C they
# send. Python's own handler (reset to the default on exec) gives the children what a terminal gives them.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture
def typed_plugins_cleared():
    """The test starts with no typed import paths (soabench.plugins keeps them per process) and leaves none."""
    from soabench import plugins

    saved = set(plugins._TYPED)
    plugins._TYPED.clear()
    yield
    plugins._TYPED.clear()
    plugins._TYPED.update(saved)


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
