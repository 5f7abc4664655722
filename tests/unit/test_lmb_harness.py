"""The filter family as an axis of a trial (docs/method.md "LMB filter"): ``experiment.filters = ("gmphd", "lmb")``
runs every birth model in both families, the LMB in static mode only, with a final ``filter`` column; the GM-PHD
rows equal those of a default run; a default run writes no ``filter`` column; the LMB runs are reproducible."""

from __future__ import annotations

import pytest
from test_trial import FakeBirth, fake_config, fake_observe, fake_simulate, without_timing

from soabench.config import Config, ExperimentConfig
from soabench.errors import SoabenchError
from soabench.experiment.trial.trial import FILTER_COLUMN, ROW_KEYS, run_trial


def _trial(**experiment):
    return run_trial(
        2, fake_config(**experiment), scene=None, scenario=None, simulate_fn=fake_simulate,
        observe_fn=fake_observe, birth_factory=lambda name: FakeBirth,
    )  # fmt: skip


def test_both_families_with_the_lmb_in_static_mode_only():
    res = _trial(filters=("gmphd", "lmb"), clutter=(3.0,))
    runs = [(r["model"], r["mode"], r[FILTER_COLUMN]) for r in res.rows]
    assert runs == [
        ("soa", "static", "gmphd"), ("soa", "static", "lmb"), ("soa", "dynamic", "gmphd"),
        ("ubm", "static", "gmphd"), ("ubm", "static", "lmb"), ("ubm", "dynamic", "gmphd"),
    ]  # fmt: skip
    assert all(list(r) == [*ROW_KEYS, FILTER_COLUMN] for r in res.rows)  # the column comes last
    assert {e[FILTER_COLUMN] for e in res.episodes} <= {"gmphd", "lmb"} and res.episodes
    assert all(list(s)[-1] == FILTER_COLUMN for s in res.steps)
    assert sum(s["n_est"] for s in res.steps if s[FILTER_COLUMN] == "lmb") > 0  # the LMB's estimates were scored

    default = _trial(clutter=(3.0,))
    assert all(FILTER_COLUMN not in r for r in default.rows + default.episodes + default.steps)
    gm = [{k: v for k, v in r.items() if k != FILTER_COLUMN} for r in res.rows if r[FILTER_COLUMN] == "gmphd"]
    assert without_timing(gm) == without_timing(default.rows)  # the LMB runs change no GM-PHD number

    again = _trial(filters=("gmphd", "lmb"), clutter=(3.0,))
    assert without_timing(again.rows) == without_timing(res.rows)
    assert again.steps == res.steps


def test_lmb_only_and_bad_families():
    res = _trial(filters=("lmb",), probabilities=("static",), clutter=(3.0,))
    assert [(r["model"], r[FILTER_COLUMN]) for r in res.rows] == [("soa", "lmb"), ("ubm", "lmb")]
    with pytest.raises(SoabenchError, match="filter family = 'kf' is not allowed"):
        Config(experiment=ExperimentConfig(filters=("kf",))).validate()
    with pytest.raises(SoabenchError, match="names 'lmb' twice"):
        Config(experiment=ExperimentConfig(filters=("lmb", "lmb"))).validate()
    with pytest.raises(SoabenchError, match="'lmb' runs the probability modes static, static\\+occ only"):
        Config(experiment=ExperimentConfig(filters=("gmphd", "lmb"), probabilities=("dynamic",))).validate()
    assert "filters" not in Config().to_dict()["experiment"]  # a default run's run.json is as before
    assert Config(experiment=ExperimentConfig(filters=("gmphd", "lmb"))).to_dict()["experiment"]["filters"] == [
        "gmphd",
        "lmb",
    ]


def _hand_run(folder, families=("gmphd", "lmb")):
    """A run folder written by hand: S-OA and PUBM in both families; in the GM-PHD S-OA is slower in every trial, in
    the LMB faster in every trial; only the rows of ``families`` are written."""
    import dataclasses

    from soabench.experiment.reports.report import load_tables
    from soabench.experiment.runs.files import write_csv
    from soabench.experiment.runs.store import RunStore

    cfg = Config()
    cfg.experiment = dataclasses.replace(
        cfg.experiment, trials=3, models=("soa", "pubm"), probabilities=("static", "dynamic"), filters=families
    )
    cfg.validate()
    RunStore(folder).create({"net": "hand", "trials": 3, "config": cfg.to_dict()})
    rows = []
    for t in range(3):
        for model, mode, fam, delay in (
            ("soa", "static", "gmphd", 3.0), ("soa", "static", "lmb", 1.0), ("soa", "dynamic", "gmphd", 3.0),
            ("pubm", "static", "gmphd", 2.0), ("pubm", "static", "lmb", 2.0), ("pubm", "dynamic", "gmphd", 2.0),
        ):  # fmt: skip
            if fam in families:
                rows.append({"trial": t, "clutter": 3.0, "model": model, "mode": mode, "delay_mean": delay,
                             "delay_std": 0.5, "card_err": 1.0 + t, "ospa": 10.0 * (1 + t) + delay, "precision": 1.0,
                             "n_episodes": 4, "n_censored": 0, FILTER_COLUMN: fam})  # fmt: skip
    write_csv(folder / "trials.csv", rows, ("trial", "clutter", "model", "mode"))
    return load_tables(folder)


def test_summary_is_per_family_with_paired_statistics_inside_each(tmp_path):
    """Each family's win counts see only its own rows; the LMB's dynamic cells read "—"."""
    from soabench.experiment.reports.report import render_markdown, summarize

    summary = summarize(_hand_run(tmp_path))
    gm, lmb = summary["results"]
    assert (gm["filter"], lmb["filter"]) == ("gmphd", "lmb")
    assert [(c["mode"], c["wins"], c["losses"]) for c in gm["vs_soa"]] == [("static", 0, 3), ("dynamic", 0, 3)]
    assert [(c["mode"], c["wins"], c["losses"]) for c in lmb["vs_soa"]] == [("static", 3, 0)]
    assert [(m["model"], m["mode"]) for m in lmb["models"]] == [("soa", "static"), ("pubm", "static")]
    md = render_markdown(summary)
    assert "## λ = 3, GM-PHD" in md and "## λ = 3, LMB" in md
    assert "| S-OA | dynamic |" + " — |" * 10 in md and "| PUBM | dynamic |" + " — |" * 10 in md


def test_figures_of_a_families_run(tmp_path):
    """The paper's figures are drawn on the GM-PHD rows only (byte for byte those of a run holding only them), and
    families.png sets the families side by side: each bar the mean of its family's static rows."""
    from soabench.figures.families import families_figure
    from soabench.figures.results import bars_figure, figure_jobs
    from soabench.figures.style import png_bytes

    both = _hand_run(tmp_path / "both")
    gm_only = _hand_run(tmp_path / "gm", families=("gmphd",))
    jobs = {job.path.name: job for job in figure_jobs(both, tmp_path / "figures")}
    assert "families.png" in jobs and "fig5g_ospa.png" in jobs
    ospa = ("ospa", "mean OSPA (m)", "OSPA", 3.0, "g")
    assert png_bytes(jobs["fig5g_ospa.png"].build(both, *jobs["fig5g_ospa.png"].args)) == png_bytes(
        bars_figure(gm_only, *ospa)
    )
    assert png_bytes(bars_figure(both, *ospa)) != png_bytes(bars_figure(gm_only, *ospa))  # the LMB rows would show

    fig = families_figure(both, 3.0)
    delay, _, ospa_ax = fig.axes[:3]
    heights = [round(p.get_height(), 9) for p in delay.patches if p.get_width() > 0]
    assert heights == [3.0, 2.0, 1.0, 2.0]  # S-OA, PUBM in the GM-PHD, then in the LMB (static mode)
    assert [round(p.get_height(), 9) for p in ospa_ax.patches if p.get_width() > 0] == [23.0, 22.0, 21.0, 22.0]
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["GM-PHD", "LMB"]


def test_sensitivity_of_a_families_run_is_refused(tmp_path):
    """`soabench sensitivity --main` of a run naming filter families: one line, before any folder is made."""
    from soabench.experiment.campaigns.sensitivity_runs import run_sensitivity

    _hand_run(tmp_path / "main")
    with pytest.raises(SoabenchError, match=r"`soabench sensitivity` \(--main .*main\) runs the GM-PHD family only"):
        run_sensitivity(tmp_path / "main", tmp_path / "sens")
    assert not (tmp_path / "sens").exists()
