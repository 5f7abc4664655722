"""The filter family as an axis of a trial (docs/method.md "LMB filter"): ``experiment.filters = ("gmphd", "lmb")``
runs every birth model in both families, the LMB in static mode only, with a final ``filter`` column; the GM-PHD
rows equal those of a default run; a default run writes no ``filter`` column; the LMB runs are reproducible."""

from __future__ import annotations

import pytest
from test_trial import FakeBirth, fake_config, fake_observe, fake_simulate, without_timing

from soabench.config import Config, ExperimentConfig
from soabench.errors import SoabenchError
from soabench.experiment.trial import FILTER_COLUMN, ROW_KEYS, run_trial


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
    with pytest.raises(SoabenchError, match="'lmb' runs the probability modes static only"):
        Config(experiment=ExperimentConfig(filters=("gmphd", "lmb"), probabilities=("dynamic",))).validate()
    assert "filters" not in Config().to_dict()["experiment"]  # a default run's run.json is as before
    assert Config(experiment=ExperimentConfig(filters=("gmphd", "lmb"))).to_dict()["experiment"]["filters"] == [
        "gmphd",
        "lmb",
    ]
