"""The run loop returns a finished run and writes no report; the report is written by one function of the layer above
(soabench/experiment/reports/finished.py), with the fake trial of tests/fake_trial.py."""

from __future__ import annotations

import fake_trial as ft

from soabench.experiment.execution.options import RunOptions
from soabench.experiment.execution.runner import Batch, RunRequest, execute
from soabench.experiment.reports.finished import report_run

OPTIONS = RunOptions(workers=1, progress=False, figures=False)


def _request(out) -> RunRequest:
    cfg = ft.small_config(trials=2, duration=10.0, seed=3)
    return RunRequest(cfg, "intersection", out=out, options=OPTIONS, trial_fn=ft.fake_trial, load_fn=ft.fake_load)


def test_the_loop_returns_a_finished_run_and_report_run_writes_its_report(tmp_path):
    outcome = execute(_request(tmp_path / "run"))
    assert outcome.complete and outcome.finished is not None and outcome.summary_markdown == ""
    assert not (tmp_path / "run" / "summary.md").exists() and not (tmp_path / "run" / "report.html").exists()
    assert outcome.finished.store.run_dir == tmp_path / "run" and outcome.finished.figures is False
    reported = report_run(outcome)
    assert reported.summary_markdown == (tmp_path / "run" / "summary.md").read_text(encoding="utf-8")
    assert (tmp_path / "run" / "report.html").is_file() and (tmp_path / "run" / "trials.csv").is_file()
    assert reported.finished is None  # reported once


def test_a_deferred_run_is_not_finished_and_its_report_waits(tmp_path):
    deferred: list = []
    outcome = execute(_request(tmp_path / "run"), Batch(defer=deferred))
    assert outcome.finished is None and len(deferred) == 1 and deferred[0].todo == frozenset({0, 1})
    assert report_run(outcome) is outcome and not (tmp_path / "run" / "summary.md").exists()
    spec = deferred[0].spec  # the worker's view of the run: derived from the run's record, not a copy of it
    assert spec.meta.net == "intersection" and spec.base_seed == 3 and spec.config["experiment"]["trials"] == 2
