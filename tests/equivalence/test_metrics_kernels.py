"""The compiled matchings of a run (soabench.metrics_kernels) give the numbers of the numpy/scipy path of
soabench.metrics bit for bit: numpy's summation order, scipy's assignments, and every metric of real filter runs
and of constructed edge cases (empty sets, duplicates, points exactly at the gate and the cut-offs)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from soabench.config import Config, MetricsConfig, Sensor
from soabench.metrics import evaluate
from soabench.metrics_kernels import assignment, np_sum
from soabench.types import Obstacles, Scan, Scans, StepResult


def test_np_sum_is_numpys_summation_order():
    rng = np.random.default_rng(0)
    for n in list(range(0, 140)) + [255, 256, 257, 300, 1000, 1031]:
        a = rng.uniform(0.0, 10.0, n) * 10.0 ** rng.integers(-8, 8, n)
        assert np_sum(a, n) == float(a.sum()), n


@pytest.mark.parametrize("seed", range(3))
def test_assignment_is_scipys_on_continuous_costs(seed):
    rng = np.random.default_rng(seed)
    for _ in range(400):
        a, b = (int(v) for v in rng.integers(1, 13, 2))
        C = rng.uniform(0.0, 50.0, (a, b))
        rows, cols = assignment(C)
        r_ref, c_ref = linear_sum_assignment(C)
        assert np.array_equal(rows, r_ref) and np.array_equal(cols, c_ref)
        # gated costs (§5.4): pairs beyond the gate cost the same, so which of them fill up an assignment is a tie;
        # the pairs within the gate, all that the metrics keep, are the same
        G = np.where(C > 20.0, 1e6, C)
        rows, cols = assignment(G)
        r_ref, c_ref = linear_sum_assignment(G)
        kept = {(i, j) for i, j in zip(rows.tolist(), cols.tolist(), strict=True) if G[i, j] < 1e6}
        assert kept == {(i, j) for i, j in zip(r_ref.tolist(), c_ref.tolist(), strict=True) if G[i, j] < 1e6}
        assert np.all(np.diff(rows) > 0) and len(rows) == min(a, b)


def test_assignment_is_optimal_with_ties():
    rng = np.random.default_rng(7)
    for _ in range(300):
        a, b = (int(v) for v in rng.integers(1, 8, 2))
        C = np.minimum(rng.integers(0, 6, (a, b)).astype(float), 3.0)  # many equal costs
        rows, cols = assignment(C)
        r_ref, c_ref = linear_sum_assignment(C)
        assert len(set(cols.tolist())) == len(cols) == min(a, b) and np.all(np.diff(rows) > 0)
        assert C[rows, cols].sum() == C[r_ref, c_ref].sum()


def _step(X: np.ndarray, k: int = 0) -> StepResult:
    X = np.asarray(X, dtype=float).reshape(-1, 4)
    n = len(X)
    return StepResult(
        k, X, np.ones(n), float(n), float(n), n, n, n, False, 0.0, 0.0, 0.0, 0.98, np.zeros(0), np.zeros(0)
    )


def _same(a, b) -> None:
    for key in a.summary:
        x, y = a.summary[key], b.summary[key]
        assert (isinstance(x, float) and math.isnan(x) and math.isnan(y)) or x == y, key
    for key in a.series:
        assert a.series[key].dtype == b.series[key].dtype and np.array_equal(a.series[key], b.series[key]), key
    assert a.episodes == b.episodes
    assert a.partner.dtype == b.partner.dtype and np.array_equal(a.partner, b.partner)


def _scans(truth: np.ndarray, ego: np.ndarray, cfg: Sensor) -> Scans:
    K, P = truth.shape[:2]
    present = np.isfinite(truth).all(axis=-1)
    r = np.hypot(truth[..., 0] - ego[:, None, 0], truth[..., 1] - ego[:, None, 1])
    in_fov = present & (r <= cfg.r_max)
    scans = [Scan(k, float(k), ego[k], np.zeros((0, 2)), Obstacles.empty(), [], None) for k in range(K)]
    return Scans(
        scans,
        1.0,
        [np.zeros(0, dtype=np.int64)] * K,
        truth,
        present,
        in_fov,
        in_fov,
        in_fov.copy(),
        np.array([str(p) for p in range(P)]),
    )


@pytest.mark.parametrize("gt_set", ["fov", "visible", "scene"])
@pytest.mark.parametrize("fov_deg", [360.0, 100.0])
def test_constructed_edge_cases_match_the_numpy_path(gt_set, fov_deg):
    """Empty scans, duplicated estimates, estimates exactly at d_gate and at the GOSPA cut-off, more estimates than
    truths and the reverse, estimates outside the FOV."""
    rng = np.random.default_rng(3)
    sensor = dataclasses.replace(Sensor(), fov_deg=fov_deg)
    mcfg = dataclasses.replace(MetricsConfig(), gt_set=gt_set)
    K, P = 60, 5
    ego = np.column_stack([rng.uniform(-5, 5, (K, 2)), rng.uniform(-np.pi, np.pi, K)])
    truth = ego[:, None, :2] + rng.uniform(-40, 40, (K, P, 2))
    truth[rng.random((K, P)) < 0.2] = np.nan
    results = []
    for k in range(K):
        g = truth[k][np.isfinite(truth[k]).all(axis=1)]
        n = int(rng.integers(0, 8))
        est = ego[k, :2] + rng.uniform(-60, 60, (n, 2))
        if len(g) and k % 3 == 0:
            est = np.concatenate([est, g[:1] + (mcfg.d_gate, 0.0), g[:1] + (0.0, mcfg.gospa_c), g[:1], g[:1]])
        X = np.zeros((len(est), 4))
        X[:, :2] = est
        results.append(_step(X if k % 7 else X[:0]))
    scans = _scans(truth, ego, sensor)
    _same(evaluate(scans, results, mcfg, sensor), evaluate(scans, results, mcfg, sensor, compiled=False))


def test_filter_runs_of_a_trial_match_the_numpy_path(monkeypatch):
    """Every filter run of a short trial of the shipped scene (twelve runs), scored both ways."""
    import soabench.experiment.trial.trial as trial_mod
    from soabench.scenario import load

    seen = []

    def spy(scans, results, mcfg, scfg, **kw):
        seen.append((scans, results, mcfg, scfg))
        return evaluate(scans, results, mcfg, scfg, **kw)

    monkeypatch.setattr(trial_mod, "evaluate", spy)
    cfg = Config()
    cfg = dataclasses.replace(cfg, experiment=dataclasses.replace(cfg.experiment, duration=30.0))
    scene, scenario = load("intersection")
    trial_mod.run_trial(4, cfg, scene, scenario)
    assert len(seen) == 12
    for scans, results, mcfg, scfg in seen:
        _same(evaluate(scans, results, mcfg, scfg), evaluate(scans, results, mcfg, scfg, compiled=False))


def test_other_orders_use_the_numpy_path():
    sensor = Sensor()
    mcfg = dataclasses.replace(MetricsConfig(), ospa_p=2.0)
    truth = np.array([[[1.0, 0.0], [5.0, 5.0]]])
    scans = _scans(truth, np.zeros((1, 3)), sensor)
    res = [_step(np.array([[1.5, 0.0, 0.0, 0.0]]))]
    a = evaluate(scans, res, mcfg, sensor)
    assert a.series["ospa"][0] == pytest.approx(math.sqrt((0.5**2 + 100.0**2) / 2))
    _same(a, evaluate(scans, res, mcfg, sensor, compiled=False))


def test_coinciding_estimates_are_scored_with_scipys_choice():
    """An estimate extracted twice makes two equal rows in every cost matrix: both ways of matching it are optimal,
    and the order of the summed distances (their last bit) follows the assignment. Scans like trial 0's step 59 of
    the shipped protocol (two equal estimates between two truths) score exactly as on the numpy path."""
    rng = np.random.default_rng(9)
    sensor, mcfg = Sensor(), MetricsConfig()
    K, P = 400, 6
    ego = np.zeros((K, 3))
    truth = rng.uniform(-30, 30, (K, P, 2))
    results = []
    for k in range(K):
        est = truth[k] + rng.normal(0.0, 1.0, (P, 2))
        mid = 0.5 * (truth[k, 1] + truth[k, 2]) + rng.normal(0.0, 0.3, 2)
        est[1] = est[2] = mid  # one estimate, extracted twice, between truths 1 and 2
        X = np.zeros((P, 4))
        X[:, :2] = est
        results.append(_step(X, k))
    scans = _scans(truth, ego, sensor)
    a = evaluate(scans, results, mcfg, sensor)
    b = evaluate(scans, results, mcfg, sensor, compiled=False)
    _same(a, b)
    assert a.summary["tp"] > 4 * K
