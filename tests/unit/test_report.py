"""Report and store: statistics in the paper's terms from CSV files alone (docs/method.md §5.8)."""

from __future__ import annotations

import gzip
import json
import math
import shutil

import fake_trial as ft
import numpy as np
import pytest

from soabench.config import Config
from soabench.experiment.reports.report import RunTables, load_tables, summarize, write_report
from soabench.experiment.runs.files import format_value, read_csv, write_csv
from soabench.experiment.runs.store import RunStore
from soabench.figures.results import cumulative_precision


def small_config(trials: int = 3, models=("soa", "pubm", "atbm"), modes=("static",)) -> Config:
    return ft.small_config(trials=trials, duration=12.0, models=tuple(models), probabilities=tuple(modes), seed=3)


@pytest.mark.slow
def test_report_is_rebuilt_from_the_csv_files_alone(tmp_path):
    out = tmp_path / "run"
    o = ft.run_fake(small_config(), out, figures=True, save_estimates=True)
    md = (out / "summary.md").read_text()
    js = json.loads((out / "summary.json").read_text())
    # the per-trial records are not needed once merged: the report reads the CSV files (and run.json)
    shutil.rmtree(out / "trials")
    shutil.rmtree(out / "figures")
    (out / "summary.md").unlink()
    assert write_report(out) == md == o.summary_markdown
    assert json.loads((out / "summary.json").read_text())["results"] == js["results"]
    assert len(list((out / "figures").glob("*.png"))) >= 7
    # --save-estimates: one gzipped JSON per trial
    est = json.loads(gzip.decompress((out / "estimates" / "trial_00001.json.gz").read_bytes()))
    assert (
        est["trial"] == 1
        and len(est["estimates"]) == 12 * 3
        and {"model", "mode", "k", "xy"} <= set(est["estimates"][0])
    )


def _hand_run(tmp_path, soa_delays, pubm_delays, soa_card, pubm_card) -> RunTables:
    """A run folder written by hand: S-OA and PUBM, static, one row per trial."""
    cfg = small_config(trials=len(soa_delays), models=("soa", "pubm"))
    store = RunStore(tmp_path)
    store.create({"net": "hand", "trials": len(soa_delays), "config": cfg.to_dict()})
    rows = []
    for model, delays, cards in (("soa", soa_delays, soa_card), ("pubm", pubm_delays, pubm_card)):
        for t, (d, c) in enumerate(zip(delays, cards, strict=False)):
            rows.append(
                {
                    "trial": t,
                    "clutter": 3.0,
                    "model": model,
                    "mode": "static",
                    "delay_mean": d,
                    "delay_std": 0.5,
                    "card_err": c,
                    "ospa": 10 * c,
                    "precision": 1.0,
                    "n_episodes": 4,
                    "n_censored": 1,
                }
            )
    write_csv(tmp_path / "trials.csv", rows, ("trial", "clutter", "model", "mode"))
    return load_tables(tmp_path)


def test_win_counts_ties_na_and_reductions(tmp_path):
    nan = math.nan
    tables = _hand_run(
        tmp_path,
        soa_delays=[1.0, 2.0, 3.0, nan, 0.5],
        pubm_delays=[2.0, 2.0, 1.0, 1.0, nan],
        soa_card=[1.0, 1.0, 1.0, 1.0, 1.0],
        pubm_card=[2.0, 2.0, 2.0, 2.0, 2.0],
    )
    s = summarize(tables)
    (res,) = s["results"]
    (c,) = res["vs_soa"]
    assert (c["wins"], c["ties"], c["losses"], c["na"]) == (1, 1, 1, 2)
    assert math.isclose(c["card_reduction"], 50.0) and math.isclose(c["ospa_reduction"], 50.0)
    soa = next(m for m in res["models"] if m["model"] == "soa")
    assert math.isclose(soa["delay_mean"], (1 + 2 + 3 + 0.5) / 4)
    assert math.isclose(soa["delay_sigma_bar"], 0.5)
    assert (soa["n_censored"], soa["n_episodes"]) == (5, 20)


def test_csv_round_trip_is_exact(tmp_path):
    vals = [0.1 + 0.2, 1 / 3, 1e-300, -2.5e17, math.nan, math.inf]
    write_csv(tmp_path / "x.csv", [{"a": v, "b": "s,1", "c": i} for i, v in enumerate(vals)], ("a", "b", "c"))
    back = read_csv(tmp_path / "x.csv")
    assert [format_value(v) for v in back["a"]] == [format_value(v) for v in vals]
    assert list(back["b"]) == ["s,1"] * len(vals) and list(back["c"]) == list(range(len(vals)))
    assert not list(tmp_path.glob(".*tmp"))  # atomic writes leave no temporary files


def test_cumulative_precision_known_answer(tmp_path):
    cfg = small_config(trials=2, models=("soa",))
    store = RunStore(tmp_path)
    store.create({"net": "hand", "trials": 2, "config": cfg.to_dict()})
    steps = []
    for trial, tps, fps in ((0, [1, 1, 0], [0, 1, 0]), (1, [0, 2, 2], [0, 0, 2])):
        for k, (tp, fp) in enumerate(zip(tps, fps, strict=False)):
            steps.append({"trial": trial, "clutter": 3.0, "model": "soa", "mode": "static", "k": k, "tp": tp, "fp": fp})
    write_csv(tmp_path / "steps.csv", steps, ("trial", "clutter", "model", "mode", "k"))
    write_csv(
        tmp_path / "trials.csv",
        [{"trial": t, "clutter": 3.0, "model": "soa", "mode": "static"} for t in (0, 1)],
        ("trial", "clutter", "model", "mode"),
    )
    k, p = cumulative_precision(load_tables(tmp_path), 3.0, "soa", "static")
    # trial 0: 1/1, 2/3, 2/3; trial 1: undefined, 2/2, 4/6 -> mean over the defined trials
    assert np.allclose(k, [0, 1, 2])
    assert np.allclose(p, [1.0, (2 / 3 + 1.0) / 2, (2 / 3 + 4 / 6) / 2])
