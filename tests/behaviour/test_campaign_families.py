"""The family axis of the campaigns: ``sweep``, ``study`` and ``check`` run the filter families of the registry as
``run`` does, and their reports hold one table per family (fake trials: tests/fake_trial.py)."""

from __future__ import annotations

import json
import math

import fake_trial as ft
import numpy as np
import pytest

from soabench.cli.main import main
from soabench.experiment.campaigns.study import write_comparison
from soabench.experiment.campaigns.sweep import run_sweep
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.reports import paper
from soabench.experiment.runs.files import read_csv

OPTIONS = RunOptions(workers=1, progress=False, figures=False)


def _sweep(kind, values, out, **experiment):
    cfg = ft.small_config(trials=2, duration=20.0, seed=5, **experiment)
    kw = dict(trial_fn=ft.fake_trial, load_fn=ft.fake_load, models=("soa", "pubm"))
    return run_sweep(kind, values, cfg, "intersection", out=out, options=OPTIONS, **kw)


def test_births_sweep_tabulates_each_family_from_its_own_episodes(tmp_path):
    o = _sweep("births", (-1, 0), tmp_path / "sw", filters=("gmphd", "lmb"))
    assert o.complete
    md = o.summary_markdown
    assert md.index("## GM-PHD") < md.index("## LMB")
    data = json.loads((tmp_path / "sw" / "sweep_summary.json").read_text())
    assert [f["filter"] for f in data["families"]] == ["gmphd", "lmb"]
    assert data["table"] == data["families"][0]["table"]  # the figure's and the summary's table: the first family
    ep = read_csv(tmp_path / "sw" / "points" / "ntot_006" / "episodes.csv")
    for fam, table in ((f["filter"], f["table"]) for f in data["families"]):
        m = (ep["model"] == "soa") & (ep["mode"] == "static") & (ep["censored"] == 0) & (ep["filter"] == fam)
        assert math.isclose(table[1]["delay"]["soa/static"], float(np.nanmean(ep["delay"][m])))
        # the LMB defines no `dynamic`: its column is empty, the GM-PHD's is not
        assert math.isnan(table[1]["delay"]["soa/dynamic"]) == (fam == "lmb")
    lmb_section = md[md.index("## LMB") :]
    assert "| 6 | 0.3 |" in lmb_section and "n/a" in lmb_section


def test_clutter_sweep_rows_name_their_family_and_a_default_sweep_has_no_sections(tmp_path):
    o = _sweep("clutter", (0.5, 5.0), tmp_path / "fam", filters=("gmphd", "pmb"))
    rows = json.loads((tmp_path / "fam" / "sweep_summary.json").read_text())["table"]
    assert {r["filter"] for r in rows} == {"gmphd", "pmb"}
    pmb = o.summary_markdown[o.summary_markdown.index("## PMB") :]
    assert "| 0.5 | S-OA | static |" in pmb and "| 5 | PUBM | static |" in pmb and "dynamic" not in pmb
    # the GM-PHD alone (the default): one table, no family headings, no filter key
    plain = _sweep("clutter", (0.5, 5.0), tmp_path / "plain")
    assert "## GM-PHD" not in plain.summary_markdown
    assert all("filter" not in r for r in json.loads((tmp_path / "plain" / "sweep_summary.json").read_text())["table"])


@pytest.fixture
def fake_study(monkeypatch):
    import soabench.experiment.campaigns.sweep as sweep
    import soabench.experiment.reports.report as report

    monkeypatch.setattr(report, "write_report", lambda run_dir, figures=True, store=None: "summary")
    monkeypatch.setattr(sweep, "write_sweep_report", lambda d: "sweep")
    with ft.as_builtins():
        yield


def test_study_runs_every_part_in_the_families_and_compares_with_the_paper_in_the_gmphd(tmp_path, fake_study):
    out = tmp_path / "study"
    argv = ["study", "--filters", "gmphd,lmb", "--trials", "2", "--births-trials", "1", "--duration", "10"]
    assert main([*argv, "--workers", "1", "--no-progress", "--out", str(out)]) == 0
    folders = [out / "main", *(out / "clutter" / "points").iterdir(), *(out / "births" / "points").iterdir()]
    folders += [out / "sensitivity" / k for k in ("gate_off", "visible")]
    for folder in folders:
        meta = json.loads((folder / "run.json").read_text())
        assert meta["config"]["experiment"]["filters"] == ["gmphd", "lmb"], folder
        assert set(read_csv(folder / "trials.csv")["filter"]) == {"gmphd", "lmb"}, folder
    assert (out / "sensitivity" / "sensitivity.md").is_file()
    md = write_comparison(out)  # the study wrote none: 10 s trials are not the paper's protocol
    assert "the paper's numbers in its filter family, the GM-PHD" in md
    # the paper's tables read the GM-PHD rows only: the same tables as from those rows alone
    gm = [r for r in paper.read_rows(out / "main" / "trials.csv") if r["filter"] == "gmphd"]
    assert paper.markdown(gm) in md


CHECK_SUITE = """[suite]
name = "families"

[[scenario]]
name = "gm"
net = "intersection"
duration = 10
models = ["soa", "pubm"]
probabilities = ["static"]

[[scenario]]
name = "lmb"
net = "intersection"
duration = 10
models = ["soa", "pubm"]
probabilities = ["static"]
filter = "lmb"

[[threshold]]
metric = "ospa"
max = 1000.0
"""


def test_a_check_scenario_names_its_family(tmp_path, capsys, fake_builtins):
    suite = tmp_path / "suite.toml"
    suite.write_text(CHECK_SUITE)
    assert main(["check", "--suite", str(suite), "--out", str(tmp_path / "chk")]) == 0
    runs = tmp_path / "chk" / "runs"
    gm = read_csv(next((runs / "gm").iterdir()) / "trials.csv")
    lmb = read_csv(next((runs / "lmb").iterdir()) / "trials.csv")
    assert "filter" not in gm and set(lmb["filter"]) == {"lmb"}
    values = json.loads((tmp_path / "chk" / "check.json").read_text())["values"]
    assert values["lmb/soa/static/lambda=3/ospa"] == pytest.approx(float(np.mean(lmb["ospa"][lmb["model"] == "soa"])))
    assert "gm/pubm/static/lambda=3/ospa" in values and "lmb/pubm/static/lambda=3/ospa" in values
