"""The Monte Carlo harness: outputs agree with each other, executors agree bit for bit, failures.

Uses the deterministic fake trial function of ``tests/fake_trial.py`` (the real pipeline has its own end-to-end
test).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
from pathlib import Path

import fake_trial as ft
import numpy as np
import pytest
from local_dask import local_cluster

from soabench.config import Config
from soabench.errors import SoabenchError
from soabench.experiment.campaigns.sweep import run_sweep, sweep_points
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.reports.finished import run_experiment
from soabench.experiment.reports.report import LABEL, fmt, fmt_pct
from soabench.experiment.runs.files import read_csv

pytestmark = pytest.mark.slow  # process pools and a Dask cluster

CSV_FILES = ("trials.csv", "episodes.csv", "steps.csv")


def small_config(trials: int = 4, clutter=(3.0,), duration: float = 20.0, seed: int = 11) -> Config:
    return ft.small_config(trials=trials, duration=duration, clutter=tuple(clutter), seed=seed)


def run(cfg: Config, out: Path, trial_fn=ft.fake_trial, **options):
    """A run of the fake trial; ``options``: fields of :class:`RunOptions` (default: one worker, no figures)."""
    options = RunOptions(**{"workers": 1, "figures": False, "progress": False, **options})
    return run_experiment(cfg, "intersection", out=out, load_fn=ft.fake_load, trial_fn=trial_fn, options=options)


@pytest.fixture(scope="module")
def dask_scheduler():
    """One Dask LocalCluster (2 processes, 1 thread each) for the module; workers can import fake_trial."""
    with local_cluster(2) as address:
        yield address


def test_end_to_end_files_agree(tmp_path):
    cfg = small_config(trials=4, clutter=(0.5, 3.0))
    out = tmp_path / "run"
    o = run(cfg, out, figures=True)
    assert o.complete and o.n_done == 4 and o.n_missing == 0 and not o.failures
    for name in (*CSV_FILES, "timing.csv", "summary.json", "summary.md", "run.json"):
        assert (out / name).is_file(), name
    for name in (
        "fig5a_delay_soa",
        "fig5e_delay_atbm",
        "fig5f_cardinality",
        "fig5g_ospa",
        "fig5h_precision",
        "fig6_delay_hist",
        "fig7_components",
    ):
        assert list((out / "figures").glob(f"{name}*.png")), name
    tr = read_csv(out / "trials.csv")
    exp = cfg.experiment
    assert len(tr["trial"]) == exp.trials * len(exp.models) * len(exp.probabilities) * len(exp.clutter)
    assert not any(c.startswith("t_") for c in tr), "wall-clock columns belong in timing.csv"
    for c in ("card_err", "ospa", "precision", "recall", "mean_components"):
        assert np.all(np.isfinite(tr[c])), c
    st = read_csv(out / "steps.csv")
    assert len(st["k"]) == len(tr["trial"]) * int(exp.duration / cfg.sensor.dt)
    ep = read_csv(out / "episodes.csv")
    assert len(ep["trial"]) == int(np.sum(tr["n_episodes"]))

    summary = json.loads((out / "summary.json").read_text())
    assert summary["config"] == cfg.to_dict()
    assert summary["net"] == "intersection" and summary["complete"]
    assert set(summary["versions"]) >= {"numpy", "scipy", "shapely", "sumo", "soabench", "python"}
    md = (out / "summary.md").read_text()
    assert md == o.summary_markdown
    for res in summary["results"]:
        for c in res["vs_soa"]:
            assert c["wins"] + c["ties"] + c["losses"] + c["na"] == exp.trials
            assert 0 <= c["wins"] <= exp.trials
    # the Markdown table holds the CSV numbers
    lam = 3.0
    section = md.split(f"## λ = {lam:g}")[1]
    for model in exp.models:
        for mode in exp.probabilities:
            m = (tr["model"] == model) & (tr["mode"] == mode) & (tr["clutter"] == lam)
            row = next(ln for ln in section.splitlines() if ln.startswith(f"| {LABEL[model]} | {mode} |"))
            assert fmt(float(np.nanmean(tr["delay_mean"][m]))) in row
            assert fmt(float(np.nanmean(tr["delay_std"][m]))) in row
            assert f"{fmt(float(tr['card_err'][m].mean()))} ± {fmt(float(tr['card_err'][m].std()))}" in row
            assert f"{fmt(float(tr['ospa'][m].mean()))} ± {fmt(float(tr['ospa'][m].std()))}" in row
            assert fmt(float(np.nanmean(tr["precision"][m]))) in row
            assert f"{int(tr['n_censored'][m].sum())} / {int(tr['n_episodes'][m].sum())}" in row
    # win count and reduction for S-OA vs UBM, static
    s = (tr["model"] == "soa") & (tr["mode"] == "static") & (tr["clutter"] == lam)
    u = (tr["model"] == "ubm") & (tr["mode"] == "static") & (tr["clutter"] == lam)
    wins = int(np.sum(tr["delay_mean"][s] < tr["delay_mean"][u]))
    red = 100 * (tr["card_err"][u].mean() - tr["card_err"][s].mean()) / tr["card_err"][u].mean()
    row = next(ln for ln in section.splitlines() if ln.startswith(f"| static | {LABEL['ubm']} |"))
    assert f"| {wins} / {exp.trials} |" in row and fmt_pct(float(red)) in row


def test_serial_pool_dask_bit_identical(tmp_path, dask_scheduler):
    cfg = small_config(trials=5, clutter=(0.5, 5.0))
    outs = {
        "serial": run(cfg, tmp_path / "serial", workers=1),
        "pool": run(cfg, tmp_path / "pool", workers=2),
        "dask": run(cfg, tmp_path / "dask", scheduler=dask_scheduler),
    }
    assert all(o.complete for o in outs.values())
    sessions = {k: json.loads(next((tmp_path / k / "sessions").glob("*.json")).read_text()) for k in outs}
    assert sessions["serial"]["executor"] == "serial"
    assert sessions["pool"]["executor"] == "process-pool"
    assert sessions["dask"]["executor"].startswith("dask")
    workers = {json.loads(p.read_text())["worker"] for p in (tmp_path / "pool" / "trials").glob("*.json")}
    assert all(w.split(":")[1] != str(os.getpid()) for w in workers), "the pool must run trials in other processes"
    for name in CSV_FILES:
        ref = (tmp_path / "serial" / name).read_bytes()
        assert (tmp_path / "pool" / name).read_bytes() == ref, name
        assert (tmp_path / "dask" / name).read_bytes() == ref, name


def test_failed_trial_is_reported_and_others_complete(tmp_path, capsys):
    cfg = small_config(trials=5)
    out = tmp_path / "run"
    o = run(cfg, out, trial_fn=ft.failing_trial, workers=2)
    assert not o.complete and o.n_done == 4 and o.n_missing == 1
    assert [f["trial"] for f in o.failures] == [2]
    f = o.failures[0]
    assert f["seed"] == cfg.experiment.seed and "forced failure of trial 2" in f["error"] and f["sumo_seed"] > 0
    assert "trial 2 failed" in capsys.readouterr().err
    tr = read_csv(out / "trials.csv")
    assert sorted(set(tr["trial"].astype(int))) == [0, 1, 3, 4]
    md = (out / "summary.md").read_text()
    assert "Failed trials (1)" in md and "forced failure of trial 2" in md
    assert json.loads((out / "summary.json").read_text())["complete"] is False
    # --resume retries the failed trial; the result equals an uninterrupted run
    o2 = run_experiment(
        None,
        "ignored",
        resume=out,
        trial_fn=ft.fake_trial,
        load_fn=ft.fake_load,
        options=RunOptions(progress=False, figures=False),
    )
    assert o2.complete and o2.n_done == 5 and not o2.failures
    run(cfg, tmp_path / "ref")
    for name in CSV_FILES:
        assert (out / name).read_bytes() == (tmp_path / "ref" / name).read_bytes(), name


def test_fail_fast_stops_at_first_failure(tmp_path):
    cfg = small_config(trials=8)
    out = tmp_path / "run"
    o = run(cfg, out, trial_fn=ft.failing_trial, workers=1, fail_fast=True)
    assert not o.complete and o.n_done == 2 and o.n_missing == 6
    assert [f["trial"] for f in o.failures] == [2]
    assert o.summary_markdown == ""
    assert not (out / "trials.csv").exists() and not (out / "summary.md").exists()
    assert sorted(p.name for p in (out / "trials").glob("*.json")) == ["trial_00000.json", "trial_00001.json"]


def test_bad_network_fails_before_any_output(tmp_path):
    with pytest.raises(SoabenchError, match="no-such-net"):
        run_experiment(
            small_config(),
            "no-such-net",
            out=tmp_path / "run",
            load_fn=ft.fake_load,
            options=RunOptions(progress=False),
        )
    assert not (tmp_path / "run").exists()


def test_existing_run_dir_is_refused(tmp_path):
    run(small_config(trials=1), tmp_path / "run")
    with pytest.raises(SoabenchError, match="already holds a run"):
        run(small_config(trials=1), tmp_path / "run")


def test_default_out_dir_and_dask_missing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    o = run_experiment(
        small_config(trials=1),
        "sumo_nets/foo/foo.net.xml",
        load_fn=ft.fake_load,
        trial_fn=ft.fake_trial,
        options=RunOptions(workers=1, progress=False, figures=False),
    )
    # run folders are resolved before any check, so the outcome names the absolute folder
    assert o.run_dir.parent == (tmp_path / "results" / "foo").resolve() and o.run_dir.name.endswith("Z")
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(SoabenchError, match=r"pip install soabench\[dask\]"):
        run(small_config(trials=1), tmp_path / "d", dask_local=True)


def test_births_sweep_points():
    cfg = small_config(duration=50.0)
    pts = sweep_points("births", range(-10, 11), cfg)
    n_tots = [p["value"] for p in pts]
    assert n_tots == list(range(1, 17))  # N_true = 6, clipped at 1, duplicates dropped
    K = 50
    assert all(math.isclose(p["config"]["birth"]["N_hat"], p["value"] / K) for p in pts)
    assert all(p["config"]["experiment"]["models"] == ["soa", "pubm", "ubm", "ubm-ws"] for p in pts)
    (c,) = sweep_points("clutter", (0.5, 3, 5), cfg)
    assert c["config"]["experiment"]["clutter"] == [0.5, 3.0, 5.0]
    with pytest.raises(SoabenchError):
        sweep_points("speed", (1,), cfg)


def test_births_sweep_runs_and_tabulates(tmp_path):
    cfg = small_config(trials=2, duration=20.0)
    o = run_sweep(
        "births",
        (-5, 0, 4),
        cfg,
        "intersection",
        out=tmp_path / "sw",
        options=RunOptions(workers=1, progress=False, figures=False),
        trial_fn=ft.fake_trial,
        load_fn=ft.fake_load,
    )
    assert o.complete and o.n_done == 6
    assert sorted(p.name for p in (tmp_path / "sw" / "points").iterdir()) == ["ntot_001", "ntot_006", "ntot_010"]
    data = json.loads((tmp_path / "sw" / "sweep_summary.json").read_text())
    means = [r["delay"]["soa/static"] for r in data["table"]]
    assert math.isclose(data["std_over_N_tot"]["soa/static"], float(np.std(means)))
    # the table's S-OA static column is the mean of that point's counted episode delays
    ep = read_csv(tmp_path / "sw" / "points" / "ntot_006" / "episodes.csv")
    m = (ep["model"] == "soa") & (ep["mode"] == "static") & (ep["censored"] == 0)
    assert math.isclose(means[1], float(ep["delay"][m].mean()))
    assert "| 6 | 0.3 |" in o.summary_markdown and "std over N_tot" in o.summary_markdown
    assert (tmp_path / "sw" / "sweep_births.png").is_file()


def test_births_sweep_points_draw_their_figures_only_on_request(tmp_path):
    """The N̂ sweep's points write tables and summaries; their own figures only with ``figures=True``
    (``--all-figures``): ``sweep_births.png`` summarises them."""
    cfg = small_config(trials=1, duration=10.0)
    kw = dict(trial_fn=ft.fake_trial, load_fn=ft.fake_load, models=("soa", "atbm"))
    for name, figures in (("default", None), ("all", True)):
        o = run_sweep(
            "births",
            (-1, 0),
            cfg,
            "intersection",
            out=tmp_path / name,
            options=RunOptions(workers=1, progress=False, figures=figures),
            **kw,
        )
        assert o.complete and (tmp_path / name / "sweep_births.png").is_file()
        for point in ("ntot_005", "ntot_006"):
            pdir = tmp_path / name / "points" / point
            summary = json.loads((pdir / "summary.json").read_text())
            pngs = sorted(p.name for p in (pdir / "figures").glob("*.png"))
            assert sorted(summary["figures"]) == ([f"figures/{p}" for p in pngs] if figures else []), (name, point)
            assert ("fig5f_cardinality.png" in pngs) == bool(figures), (name, point)


def test_clutter_sweep_one_run_per_sweep(tmp_path):
    cfg = small_config(trials=2)
    o = run_sweep(
        "clutter",
        (0.5, 5.0),
        cfg,
        "intersection",
        out=tmp_path / "sw",
        options=RunOptions(workers=1, progress=False),
        models=("soa", "atbm"),
        trial_fn=ft.fake_trial,
        load_fn=ft.fake_load,
    )
    assert o.complete
    tr = read_csv(tmp_path / "sw" / "points" / "clutter" / "trials.csv")
    assert sorted(set(tr["clutter"])) == [0.5, 5.0]
    assert "| 0.5 | S-OA | static |" in o.summary_markdown and "| 5 | ATBM | dynamic |" in o.summary_markdown
    assert (tmp_path / "sw" / "points" / "clutter" / "figures" / "fig5h_precision.png").is_file()


def test_sweep_stops_with_fail_fast_and_resumes(tmp_path):
    cfg = small_config(trials=3, duration=10.0)
    kw = dict(load_fn=ft.fake_load)
    options = RunOptions(progress=False, figures=False, workers=1)
    o = run_sweep(
        "births",
        (-2, 0),
        cfg,
        "intersection",
        out=tmp_path / "sw",
        trial_fn=ft.failing_trial,
        options=dataclasses.replace(options, fail_fast=True),
        **kw,
    )
    assert not o.complete and o.summary_markdown == "" and [f["trial"] for f in o.failures] == [2]
    assert [p.name for p in (tmp_path / "sw" / "points").iterdir()] == ["ntot_004"]
    o2 = run_sweep("births", (), None, "ignored", resume=tmp_path / "sw", trial_fn=ft.fake_trial, options=options, **kw)
    assert o2.complete and o2.n_done == 6 and "std over N_tot" in o2.summary_markdown
    assert sorted(p.name for p in (tmp_path / "sw" / "points").iterdir()) == ["ntot_004", "ntot_006"]
