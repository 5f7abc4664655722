"""Honest output on any scene: nothing observed -> a warning and no percentages; the scenario's
own name; the paper's numbers only beside the paper's protocol on the shipped intersection."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import fake_trial as ft
import pytest
from repo_paths import ROOT

from soabench.config import Config
from soabench.experiment.reports.report import (
    load_tables,
    paper_protocol_mismatch,
    render_markdown,
    summarize,
    write_report,
)
from soabench.experiment.runs.files import write_csv
from soabench.experiment.runs.store import RunStore
from soabench.scenario import load, shipped_nets

NET_DIR = ROOT / "sumo_nets" / "intersection"


def _config(trials=2, duration=100.0, models=("soa", "pubm")) -> Config:
    cfg = Config()
    cfg.experiment = dataclasses.replace(
        cfg.experiment, trials=trials, duration=duration, models=tuple(models), probabilities=("static",)
    )
    return cfg.validate()


def _unobserved_run(run_dir: Path):
    """A finished run in which no pedestrian was ever seen: no truth, no episodes; PUBM made false tracks."""
    store = RunStore(run_dir)
    store.create({"net": "/data/empty.net.xml", "net_name": "empty", "trials": 2, "config": _config().to_dict()})
    rows = [
        {"trial": t, "clutter": 3.0, "model": m, "mode": "static", "delay_mean": float("nan"), "n_episodes": 0,
         "n_censored": 0, "card_err": 0.0 if m == "soa" else 0.4, "ospa": 0.0 if m == "soa" else 3.0,
         "tp": 0, "fp": 0 if m == "soa" else 7, "fn": 0}
        for t in range(2) for m in ("soa", "pubm")
    ]  # fmt: skip
    write_csv(run_dir / "trials.csv", rows, ("trial", "clutter", "model", "mode"))
    return load_tables(run_dir)


def test_no_observed_targets_gives_a_warning_and_no_percentages(tmp_path, capsys):
    tables = _unobserved_run(tmp_path)
    summary = summarize(tables)
    (res,) = summary["results"]
    assert res["vs_soa"] == [] and "no pedestrian was observed at λ = 3 in 2 trial(s)" in res["warning"]
    assert summary["warnings"] == [res["warning"]]
    md = render_markdown(summary)
    assert "**Warning:** no pedestrian was observed" in md
    assert "%" not in md and "card. error reduction" not in md
    md = write_report(tmp_path, figures=False)
    assert "soabench: warning: no pedestrian was observed" in capsys.readouterr().err
    assert "%" not in md and "Against the paper" not in md
    assert json.loads((tmp_path / "summary.json").read_text())["warnings"]


def test_observed_targets_keep_their_comparison(tmp_path):
    tables = _unobserved_run(tmp_path)
    tables.trials["n_episodes"][:] = 3
    tables.trials["tp"][:] = 5
    (res,) = summarize(tables)["results"]
    assert res["warning"] == "" and len(res["vs_soa"]) == 1
    assert res["vs_soa"][0]["card_reduction"] == pytest.approx(100.0)


def test_paper_protocol_is_recognised():
    meta = {"net": "intersection", "scenario": None, "polys": [], "config": _config().to_dict()}
    assert paper_protocol_mismatch(meta) == ""
    cases = [
        ({"net": "/x/spider.net.xml", "net_name": "spider"}, "the network is 'spider', not the shipped intersection"),
        ({"scenario": "busy.toml"}, "a user scenario file (busy.toml) replaces the shipped one"),
        ({"polys": ["walls.poly.xml"]}, "extra polygon files"),
        ({"config": _config(duration=20.0).to_dict()}, "trials last 20 s, not the paper's 100 s"),
    ]
    for change, reason in cases:
        assert reason in paper_protocol_mismatch({**meta, **change})
    cfg = _config()
    cfg.sensor = dataclasses.replace(cfg.sensor, fov_deg=120.0)
    cfg.metrics = dataclasses.replace(cfg.metrics, gt_set="visible")
    reason = paper_protocol_mismatch({**meta, "config": cfg.to_dict()})
    assert reason == "[sensor] fov_deg differ from the paper's values"


@pytest.mark.parametrize(("net", "paper"), [("intersection", True), ("elsewhere/mine.net.xml", False)])
def test_against_the_paper_only_on_the_shipped_intersection(tmp_path, net, paper):
    out = tmp_path / "run"
    o = ft.run_fake(_config(trials=3), out, net)
    md = o.summary_markdown
    assert ("## Against the paper" in md) is paper
    if not paper:
        assert "No comparison with the paper: the network is 'mine', not the shipped intersection" in md


def named_load(net, polys=(), scenario=None):
    """A stand-in loader whose scenario has a name of its own."""
    return f"scene:{net}", SimpleNamespace(name="rush_hour", duration=100.0)


def test_default_run_folder_and_labels_use_the_scenario_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    o = ft.run_fake(_config(trials=1, duration=10.0), None, scenario="x.toml", load_fn=named_load)
    assert o.run_dir.parent == (Path("results") / "rush_hour").resolve()
    assert o.summary_markdown.startswith("# soabench run: rush_hour")
    assert json.loads((o.run_dir / "run.json").read_text())["net_name"] == "rush_hour"


def test_scenario_name_comes_from_the_scenario_file(tmp_path):
    assert "intersection" in shipped_nets()
    short = "[simulation]\nduration = 10.0\n"
    (tmp_path / "busy.toml").write_text(short)
    assert load("intersection", (), str(tmp_path / "busy.toml"))[1].name == "busy"
    (tmp_path / "named.toml").write_text('[scenario]\nname = "rush"\n' + short)
    assert load("intersection", (), str(tmp_path / "named.toml"))[1].name == "rush"
    (tmp_path / "myscene").mkdir()
    (tmp_path / "myscene" / "scenario.toml").write_text(short)
    assert load("intersection", (), str(tmp_path / "myscene" / "scenario.toml"))[1].name == "myscene"
    # a scenario naming its own network (with --net left at its default)
    shutil.copy(NET_DIR / "intersection.net.xml", tmp_path / "corner.net.xml")
    (tmp_path / "own.toml").write_text('[files]\nnet = "corner.net.xml"\n' + short)
    assert load("intersection", (), str(tmp_path / "own.toml"))[1].name == "corner"
    assert load("intersection")[1].name == "intersection"
