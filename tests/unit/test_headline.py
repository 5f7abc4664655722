"""The headline of a run (soabench/experiment/reports/headline.py): paired differences, intervals, wins, leaders."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from soabench.experiment.reports.headline import METRICS, headline, mean_interval, paired_difference
from soabench.experiment.reports.tables import RunTables

DELAY = next(m for m in METRICS if m.key == "delay_mean")
PRECISION = next(m for m in METRICS if m.key == "precision")


def test_mean_interval_is_students_t():
    d = np.array([0.3, -0.1, 0.4, 0.2, 0.0, 0.5])
    mean, low, high = mean_interval(d)
    ref = stats.t.interval(0.95, len(d) - 1, loc=d.mean(), scale=stats.sem(d))
    assert mean == pytest.approx(d.mean()) and (low, high) == pytest.approx(ref)
    assert math.isnan(mean_interval(np.array([1.0]))[1]) and math.isnan(mean_interval(np.array([]))[0])


def test_paired_difference_counts_wins_by_direction_and_skips_missing_trials():
    soa = {0: 1.0, 1: 2.0, 2: 3.0, 3: math.nan}
    other = {0: 2.0, 1: 2.0, 2: 1.0, 3: 5.0, 4: 1.0}
    p = paired_difference(DELAY, soa, other, "static", "pubm")
    assert (p.n, p.wins, p.ties, p.losses) == (3, 1, 1, 1)  # lower delay wins; trial 3 (NaN) and 4 (absent) out
    assert p.diff == pytest.approx(1 / 3) and not p.settled  # differences -1, 0, +2
    q = paired_difference(PRECISION, soa, other, "static", "pubm")
    assert (q.wins, q.losses) == (1, 1)  # higher precision wins: trial 2
    r = paired_difference(DELAY, {n: 1.0 + 0.01 * n for n in range(5)}, {n: 2.0 for n in range(5)}, "s", "x")
    assert r.settled and r.high < 0 and r.wins == 5


def _tables() -> RunTables:
    rows = []
    for trial in range(8):
        for model, delay, precision in (("soa", 1.0, 0.9), ("atbm", 0.5, 0.6), ("pubm", 1.3, 0.88)):
            rows.append((trial, model, delay + 0.01 * trial, precision - 0.001 * trial))
    trials = {
        "trial": np.array([r[0] for r in rows], dtype=float),
        "clutter": np.full(len(rows), 3.0),
        "model": np.array([r[1] for r in rows]),
        "mode": np.array(["static"] * len(rows)),
        "delay_mean": np.array([r[2] for r in rows]),
        "precision": np.array([r[3] for r in rows]),
    }
    meta = {"config": {"experiment": {"models": ["soa", "pubm", "atbm"], "probabilities": ["static"]}}}
    return RunTables(trials=trials, episodes={}, steps={}, timing={}, meta=meta)


def test_headline_leaders_pairs_and_tradeoff():
    head = headline(_tables(), 3.0)
    assert [m.key for m in head.metrics] == ["delay_mean", "precision"]  # only the columns the run has
    assert head.leader("delay_mean", "static").model == "atbm"
    assert head.leader("precision", "static").model == "soa"
    p = head.pair("delay_mean", "static", "atbm")
    assert p.diff == pytest.approx(0.5) and p.wins == 0 and p.losses == 8 and p.settled
    assert head.pair("delay_mean", "static", "pubm").wins == 8
    assert [p.other for p in head.paired if p.metric == "delay_mean"] == ["pubm", "atbm"]  # baselines' order
    (sentence,) = head.tradeoffs
    assert sentence.startswith("ATBM leads on tracking delay k̄") and "precision 0.596" in sentence
