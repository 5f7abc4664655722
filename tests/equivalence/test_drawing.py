"""Figures drawn in parallel: the same PNG bytes as drawn one after another, and no report
passed off as complete when a figure fails."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import fake_trial as ft
import pytest

from soabench.config import Config
from soabench.experiment.execution.executors import PoolExecutor, SerialExecutor
from soabench.experiment.reports.tables import load_tables
from soabench.figures import drawing
from soabench.figures import results as plots


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    cfg = Config()
    cfg.experiment = dataclasses.replace(cfg.experiment, trials=2, duration=6.0, models=("soa", "atbm"))
    out = tmp_path_factory.mktemp("drawing") / "run"
    ft.run_fake(cfg.validate(), out)
    return out


def test_tables_travel_as_plain_arrays(run_dir, tmp_path):
    tables = load_tables(run_dir)
    assert drawing.save_arrays(tables, tmp_path / "t.npz")
    back = drawing.load_arrays(str(tmp_path / "t.npz"), str(run_dir))
    assert back.meta == tables.meta and back.run_dir == run_dir
    for part in ("trials", "episodes", "steps", "timing"):
        a, b = getattr(tables, part), getattr(back, part)
        assert list(a) == list(b) and all(a[c].dtype == b[c].dtype and a[c].tobytes() == b[c].tobytes() for c in a)


@pytest.mark.slow
@pytest.mark.parametrize("arrays", [True, False], ids=["arrays", "workers-read-the-folder"])
def test_parallel_figures_are_the_serial_ones_byte_for_byte(run_dir, tmp_path, monkeypatch, arrays):
    tables = load_tables(run_dir)
    serial = plots.make_figures(tables, tmp_path / "serial")
    if not arrays:  # a column that is not plain numbers or text: each worker reads the run folder
        monkeypatch.setattr(drawing, "save_arrays", lambda tables, path: False)
    exe = PoolExecutor(2)
    try:
        with drawing.parallel(exe):
            par = plots.make_figures(tables, tmp_path / "parallel")
    finally:
        exe.close()
    assert [p.name for p in serial] == [p.name for p in par] and len(par) >= 8  # the same files, in the same order
    assert exe._generation == 1  # the pool was started (and closed): the figures were drawn by its workers
    for a, b in zip(serial, par, strict=True):
        assert a.read_bytes() == b.read_bytes(), a.name


def test_serial_executor_and_in_memory_tables_draw_here(run_dir, tmp_path, monkeypatch):
    tables = load_tables(run_dir)
    calls = []
    monkeypatch.setattr(SerialExecutor, "results", lambda *a: calls.append(a) or iter(()))
    monkeypatch.setattr(PoolExecutor, "results", lambda *a: calls.append(a) or iter(()))
    jobs = plots.figure_jobs(tables, tmp_path / "f")[-2:]  # the two precision figures
    with drawing.parallel(SerialExecutor()):
        assert [p.is_file() for p in drawing.draw_all(jobs, tables)] == [True, True]
    with drawing.parallel(PoolExecutor(2)):  # tables built in memory: nothing for a worker to read
        assert [p.is_file() for p in drawing.draw_all(jobs, dataclasses.replace(tables, run_dir=None))] == [True] * 2
    assert not calls


def test_a_failed_figure_raises_and_the_report_is_not_written(run_dir, tmp_path, monkeypatch):
    from soabench.experiment.reports.report import write_report

    def broken(tables, *args):
        raise ValueError("no figure today")

    jobs = plots.figure_jobs
    monkeypatch.setattr(plots, "figure_jobs", lambda t, d: [drawing.FigureJob(d / "x.png", broken), *jobs(t, d)])
    (run_dir / "summary.json").unlink(missing_ok=True)
    with pytest.raises(ValueError, match="no figure today"):
        write_report(run_dir)
    assert not (run_dir / "summary.json").exists()
