"""Metrics (docs/method.md §5; tests T24, T25, T26 of §6)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon

from soabench.config import MetricsConfig, Sensor
from soabench.metrics import (
    SERIES_KEYS,
    SUMMARY_KEYS,
    Episode,
    delay_episodes,
    delay_summary,
    evaluate,
    gated_assignment,
    gospa,
    ospa,
    visibility_runs,
)
from soabench.types import Scan, Scans, StepResult

# ---------------------------------------------------------------------------------------------------------------------
# helpers: hand-built Scans and StepResults


def make_scans(truth_xy: np.ndarray, visible: np.ndarray, detected: np.ndarray, dt: float = 1.0, in_fov=None) -> Scans:
    """Scans of K steps with the ego at the origin, heading 0, no measurements (metrics read only the truth)."""
    K, P = visible.shape
    present = np.isfinite(truth_xy).all(axis=-1)
    in_fov = present.copy() if in_fov is None else in_fov
    scans = [
        Scan(k, k * dt, np.zeros(3), np.zeros((0, 2)), None, [], Polygon())  # type: ignore[arg-type]
        for k in range(K)
    ]
    return Scans(
        scans=scans,
        dt=dt,
        source=[np.zeros(0, dtype=int) for _ in range(K)],
        truth_xy=truth_xy,
        present=present,
        in_fov=in_fov,
        visible=visible,
        detected=detected,
        ped_ids=np.array([f"p{i}" for i in range(P)]),
    )


def make_result(k: int, xy: np.ndarray, sum_w: float | None = None, n_reduced: int = 7) -> StepResult:
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    X = np.column_stack([xy, np.zeros((len(xy), 2))])
    return StepResult(
        k=k,
        X=X,
        X_w=np.ones(len(xy)),
        sum_w=float(len(xy)) if sum_w is None else sum_w,
        sum_w_reduced=float(len(xy)),
        n_predicted=n_reduced + 3,
        n_updated=n_reduced + 5,
        n_reduced=n_reduced,
        cap_hit=False,
        t_predict=0.001,
        t_update=0.002,
        t_reduce=0.003,
        mean_pD=0.98,
        A=np.zeros(0),
        kappa=np.zeros(0),
    )


# ---------------------------------------------------------------------------------------------------------------------
# T24 OSPA


def test_t24_ospa_known_values() -> None:
    X = np.array([[0.0, 0.0], [10.0, 0.0]])
    assert ospa(X, X, 100, 1) == (0.0, 0.0, 0.0)
    assert ospa(np.zeros((0, 2)), np.zeros((0, 2)), 100, 1) == (0.0, 0.0, 0.0)
    assert ospa(np.zeros((0, 2)), X, 100, 1) == (100.0, 0.0, 100.0)
    assert ospa(X, [], 100, 1)[0] == 100.0
    assert ospa([[0, 0]], [[3, 4]], 100, 1)[0] == pytest.approx(5.0, abs=1e-12)
    assert ospa([[0, 0]], [[300, 400]], 100, 1)[0] == pytest.approx(100.0, abs=1e-12)
    Y = np.array([[0.0, 1.0]])
    assert ospa(X, Y, 100, 1)[0] == pytest.approx(50.5, abs=1e-12)
    assert ospa(X, Y, 10, 1)[0] == pytest.approx(5.5, abs=1e-12)
    assert ospa(X, Y, 100, 2)[0] == pytest.approx(70.7142, abs=1e-4)


def test_t24_ospa_decomposition() -> None:
    X = np.array([[0.0, 0.0], [10.0, 0.0]])
    total, loc, card = ospa(X, [[0.0, 1.0]], 100, 2)
    assert loc == pytest.approx(math.sqrt(1 / 2))
    assert card == pytest.approx(math.sqrt(100**2 / 2))
    assert total**2 == pytest.approx(loc**2 + card**2)
    # rows may carry velocities: only (x, y) are used
    assert ospa(np.array([[0.0, 0.0, 9.0, 9.0]]), np.array([[3.0, 4.0, -9.0, 0.0]]))[0] == pytest.approx(5.0)


def _random_set(rng: np.random.Generator) -> np.ndarray:
    return rng.uniform(-60, 60, size=(rng.integers(0, 5), 2))


def test_t24_ospa_axioms_on_1000_random_triples() -> None:
    rng = np.random.default_rng(24)
    for _ in range(1000):
        X, Y, Z = _random_set(rng), _random_set(rng), _random_set(rng)
        dxy, dyz, dxz = ospa(X, Y)[0], ospa(Y, Z)[0], ospa(X, Z)[0]
        assert dxy == pytest.approx(ospa(Y, X)[0], abs=1e-9)
        assert 0.0 <= dxy <= 100.0
        assert dxz <= dxy + dyz + 1e-9


points = st.lists(
    st.tuples(st.floats(-200, 200, allow_nan=False), st.floats(-200, 200, allow_nan=False)), min_size=0, max_size=4
)


@settings(max_examples=150, deadline=None)
@given(points, points, points, st.sampled_from([10.0, 100.0]), st.sampled_from([1.0, 2.0]))
def test_ospa_metric_axioms(x, y, z, c, p) -> None:
    X, Y, Z = (np.array(a, dtype=float).reshape(-1, 2) for a in (x, y, z))
    dxy = ospa(X, Y, c, p)[0]
    assert ospa(X, X, c, p)[0] == pytest.approx(0.0, abs=1e-9)
    assert dxy == pytest.approx(ospa(Y, X, c, p)[0], abs=1e-9)
    assert -1e-12 <= dxy <= c + 1e-9
    assert ospa(X, Z, c, p)[0] <= dxy + ospa(Y, Z, c, p)[0] + 1e-7


# ---------------------------------------------------------------------------------------------------------------------
# T25 GOSPA


def test_t25_gospa_known_values() -> None:
    three = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
    assert gospa(np.zeros((0, 2)), three, 5, 1) == (7.5, 0.0, 0.0, 7.5)
    assert gospa(three, np.zeros((0, 2)), 5, 1) == (7.5, 0.0, 7.5, 0.0)
    total, loc, missed, false = gospa([[0, 0]], [[0, 1]], 5, 1)
    assert (total, loc, missed, false) == pytest.approx((1.0, 1.0, 0.0, 0.0))


def test_gospa_edge_cases() -> None:
    assert gospa([], [], 5, 1) == (0.0, 0.0, 0.0, 0.0)
    # beyond the cut-off: one miss and one false, not a localisation error
    assert gospa([[0, 0]], [[10, 0]], 5, 1) == pytest.approx((5.0, 0.0, 2.5, 2.5))
    # exactly at c: counted as unassigned, same total
    assert gospa([[0, 0]], [[5, 0]], 5, 1) == pytest.approx((5.0, 0.0, 2.5, 2.5))
    # p = 2: total^2 = loc + missed + false; (0,3) assigned, extra estimate false
    total, loc, missed, false = gospa([[0, 0]], [[0, 3], [40, 40]], 5, 2)
    assert (loc, missed, false) == pytest.approx((9.0, 0.0, 12.5))
    assert total == pytest.approx(math.sqrt(21.5))
    # not normalised by max(m, n): n far-apart misses grow linearly
    assert gospa(np.arange(8.0).reshape(4, 2) * 100, [], 5, 1)[0] == pytest.approx(10.0)


# ---------------------------------------------------------------------------------------------------------------------
# gated assignment


def test_gated_assignment_gate_and_optimality() -> None:
    assert gated_assignment([[0, 0]], [[5, 0]], 5.0).tolist() == [[0, 0]]
    assert gated_assignment([[0, 0]], [[5.0001, 0]], 5.0).shape == (0, 2)
    assert gated_assignment([], [[0, 0]], 5.0).shape == (0, 2)
    # greedy nearest-first would pair (est 1, gt 0) and leave gt 1 unmatched; Hungarian keeps both pairs
    pairs = gated_assignment([[0, 0], [4, 0]], [[3, 0], [8.5, 0]], 5.0)
    assert pairs.tolist() == [[0, 0], [1, 1]]


# ---------------------------------------------------------------------------------------------------------------------
# T26 delay episodes


def t26_flags(K: int = 50) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Target visible on [10, 19] and [25, 40], first detected at 11 and 25, estimates from 13 and from 25."""
    vis = np.zeros((K, 1), bool)
    vis[10:20] = vis[25:41] = True
    det = np.zeros((K, 1), bool)
    det[11:20] = det[25:41] = True
    assoc = np.zeros((K, 1), bool)
    assoc[13:20] = assoc[25:41] = True
    return vis, det, assoc


def test_t26_two_episodes_and_censoring() -> None:
    vis, det, assoc = t26_flags()
    eps = delay_episodes(vis, det, assoc, dt=0.5)
    assert [(e.k0, e.k_end, e.k_d, e.k_t) for e in eps] == [(10, 19, 11, 13), (25, 40, 25, 25)]
    assert [e.delay for e in eps] == [2 * 0.5, 0.0]
    assert not any(e.censored for e in eps)
    eps = delay_episodes(vis, det, np.zeros_like(assoc), dt=0.5)
    assert [e.censored for e in eps] == [True, True]
    assert all(math.isnan(e.delay) for e in eps) and [e.k_t for e in eps] == [-1, -1]
    assert [e.delay_lb for e in eps] == [(19 - 11 + 1) * 0.5, (40 - 25 + 1) * 0.5]


def test_undetected_episode_not_counted_and_visible_at_zero() -> None:
    vis = np.zeros((10, 2), bool)
    vis[0:4, 0] = True  # visible at k = 0, detected at 2, associated from 2
    vis[3:8, 1] = True  # never detected: not counted
    det = np.zeros_like(vis)
    det[2, 0] = True
    assoc = np.zeros_like(vis)
    assoc[2:, 0] = True
    eps = delay_episodes(vis, det, assoc, dt=1.0)
    assert eps == [Episode(0, 0, 3, 2, 2, 0.0, 0.0, False)]


def test_association_before_detection_is_ignored() -> None:
    vis, det, assoc = t26_flags()
    assoc[10:12] = True  # before k_d = 11 and at it: k_t = 11
    assoc[12] = False
    eps = delay_episodes(vis, det, assoc, dt=1.0)
    assert eps[0].k_t == 11 and eps[0].delay == 0.0


def test_g_min_two_joins_one_step_flicker() -> None:
    vis = np.zeros(20, bool)
    vis[2:6] = vis[7:10] = vis[12:15] = True  # gaps of 1 and 2 invisible steps
    assert visibility_runs(vis, 1) == [(2, 5), (7, 9), (12, 14)]
    assert visibility_runs(vis, 2) == [(2, 9), (12, 14)]
    assert visibility_runs(vis, 3) == [(2, 14)]
    det = np.zeros((20, 1), bool)
    det[[3, 7, 12], 0] = True
    assoc = np.zeros((20, 1), bool)
    assoc[[8, 13], 0] = True
    one = delay_episodes(vis[:, None], det, assoc, 1.0, g_min=1)
    two = delay_episodes(vis[:, None], det, assoc, 1.0, g_min=2)
    assert [(e.k_d, e.k_t) for e in one] == [(3, -1), (7, 8), (12, 13)]
    assert [(e.k_d, e.k_t, e.delay) for e in two] == [(3, 8, 5.0), (12, 13, 1.0)]


def test_confirm_n_two_ignores_single_step_association() -> None:
    vis, det, assoc = t26_flags()
    assoc[:] = False
    assoc[[12, 15, 16], 0] = True  # a flicker at 12, a confirmed pair at 15-16
    assoc[40, 0] = True  # the last step of episode 2: no room to confirm
    e1 = delay_episodes(vis, det, assoc, 1.0, confirm_n=1)
    e2 = delay_episodes(vis, det, assoc, 1.0, confirm_n=2)
    assert [(e.k_t, e.delay) for e in e1] == [(12, 1.0), (40, 15.0)]
    assert [e.k_t for e in e2] == [15, -1]
    assert e2[0].delay == 4.0 and e2[1].censored


def test_delay_summary_censoring_variants_and_ddof() -> None:
    eps = [
        Episode(0, 0, 9, 1, 3, 2.0, 2.0, False),
        Episode(0, 20, 29, 20, 20, 0.0, 0.0, False),
        Episode(1, 0, 9, 5, -1, math.nan, 5.0, True),
    ]
    s0 = delay_summary(eps, ddof=0)
    assert (s0["delay_mean"], s0["delay_std"]) == (1.0, 1.0)
    assert s0["delay_mean_lb"] == pytest.approx(7 / 3)
    assert s0["delay_std_lb"] == pytest.approx(np.std([2.0, 0.0, 5.0]))
    assert (s0["n_episodes"], s0["n_censored"]) == (3, 1)
    s1 = delay_summary(eps, ddof=1)
    assert s1["delay_std"] == pytest.approx(math.sqrt(2.0))
    lb = delay_summary(eps, ddof=0, censored="lower_bound")
    assert lb["delay_mean"] == pytest.approx(7 / 3)
    none = delay_summary(eps[2:], ddof=0)
    assert math.isnan(none["delay_mean"]) and math.isnan(none["delay_std"]) and none["delay_mean_lb"] == 5.0
    assert math.isnan(delay_summary(eps[:1], ddof=1)["delay_std"])


# ---------------------------------------------------------------------------------------------------------------------
# evaluate: the whole run


def t26_run(K: int = 50) -> tuple[Scans, list[StepResult]]:
    """Target 0 as in T26 (at (20, 0)); target 1 visible and detected on [30, 34] at (-20, 0) but never estimated."""
    vis, det, assoc = t26_flags(K)
    vis = np.column_stack([vis[:, 0], np.zeros(K, bool)])
    vis[30:35, 1] = True
    det = np.column_stack([det[:, 0], vis[:, 1]])
    truth = np.full((K, 2, 2), np.nan)
    truth[5:45, 0] = [20.0, 0.0]
    truth[28:40, 1] = [-20.0, 0.0]
    scans = make_scans(truth, vis, det)
    results = [make_result(k, [[21.0, 1.0]] if assoc[k, 0] else []) for k in range(K)]
    return scans, results


def test_t26_through_evaluate() -> None:
    scans, results = t26_run()
    m = evaluate(scans, results, MetricsConfig(), Sensor())
    assert [(e.target, e.k0, e.k_d, e.k_t, e.censored) for e in m.episodes] == [
        (0, 10, 11, 13, False),
        (0, 25, 25, 25, False),
        (1, 30, 30, -1, True),
    ]
    assert [e.delay for e in m.episodes[:2]] == [2.0, 0.0] and math.isnan(m.episodes[2].delay)
    assert m.summary["delay_mean"] == 1.0 and m.summary["delay_std"] == 1.0
    assert (m.summary["n_episodes"], m.summary["n_censored"]) == (3, 1)
    assert m.summary["delay_mean_lb"] == pytest.approx((2 + 0 + 5) / 3)
    assert set(m.summary) == set(SUMMARY_KEYS) and set(m.series) == set(SERIES_KEYS)
    assert all(len(v) == 50 for v in m.series.values())


def test_precision_recall_and_cardinality_on_constructed_sequence() -> None:
    K = 4
    truth = np.full((K, 2, 2), np.nan)
    truth[:, 0] = [10.0, 0.0]
    truth[2:, 1] = [0.0, 30.0]
    vis = np.isfinite(truth).all(-1)
    scans = make_scans(truth, vis, vis)
    est = [
        [],  # k0: 1 GT, 0 est -> FN
        [[11, 0], [10, -40]],  # k1: TP + FP (inside the FOV)
        [[10, 1], [0, 33]],  # k2: 2 TP
        [[10, 0], [0, 36], [90, 0]],  # k3: TP, (0,36) outside the gate: FP + FN; (90,0) outside the FOV: ignored
    ]
    results = [make_result(k, e, sum_w=[0.4, 2.0, 2.2, 1.0][k]) for k, e in enumerate(est)]
    m = evaluate(scans, results, MetricsConfig(), Sensor())
    assert m.series["n_gt"].tolist() == [1, 1, 2, 2]
    assert m.series["n_est"].tolist() == [0, 2, 2, 2]
    assert m.series["tp"].tolist() == [0, 1, 2, 1]
    assert m.series["fp"].tolist() == [0, 1, 0, 1]
    assert m.series["fn"].tolist() == [1, 0, 0, 1]
    assert (m.summary["tp"], m.summary["fp"], m.summary["fn"]) == (4, 2, 2)
    assert m.summary["precision"] == pytest.approx(4 / 6)
    assert m.summary["recall"] == pytest.approx(4 / 6)
    assert m.summary["card_err"] == pytest.approx((1 + 1 + 0 + 0) / 4)
    assert m.summary["card_err_sumw"] == pytest.approx((0.6 + 1.0 + 0.2 + 1.0) / 4)
    # OSPA (c = 100, p = 1) per step: k0 = c; k1 = (1 + 100) / 2; k2 = (1 + 3) / 2; k3 = (0 + 6) / 2
    assert m.series["ospa"] == pytest.approx([100.0, 50.5, 2.0, 3.0])
    assert m.summary["ospa"] == pytest.approx((100 + 50.5 + 2 + 3) / 4)
    assert m.summary["ospa_card"] == pytest.approx((100 + 50 + 0 + 0) / 4)
    # GOSPA (c = 5, p = 1): k0 miss 2.5; k1 1 + false 2.5; k2 1 + 3; k3 0 + (6 >= 5: miss + false)
    assert m.series["gospa"] == pytest.approx([2.5, 3.5, 4.0, 5.0])
    # scene: the estimate at (90, 0) counts, as an FP
    scene = evaluate(scans, results, MetricsConfig(gt_set="scene"), Sensor())
    assert scene.series["fp"].tolist() == [0, 1, 0, 2]
    assert scene.summary["precision"] == pytest.approx(4 / 7)


def test_gt_sets_and_empty_steps() -> None:
    K = 3
    truth = np.full((K, 1, 2), np.nan)
    truth[1:, 0] = [10.0, 0.0]
    vis = np.array([[False], [False], [True]])  # occluded at k = 1
    scans = make_scans(truth, vis, vis)
    results = [make_result(k, []) for k in range(K)]
    fov = evaluate(scans, results, MetricsConfig(), Sensor())
    visible = evaluate(scans, results, MetricsConfig(gt_set="visible"), Sensor())
    assert fov.series["n_gt"].tolist() == [0, 1, 1]
    assert visible.series["n_gt"].tolist() == [0, 0, 1]
    # both-empty step contributes 0 to the mean OSPA
    assert fov.summary["ospa"] == pytest.approx(200 / 3)
    assert visible.summary["ospa"] == pytest.approx(100 / 3)
    assert math.isnan(fov.summary["precision"]) and fov.summary["recall"] == 0.0
    assert fov.summary["mean_components"] == 7 and fov.summary["t_update"] == pytest.approx(0.006)


def test_evaluate_rejects_length_mismatch() -> None:
    scans, results = t26_run()
    with pytest.raises(ValueError, match="filter results"):
        evaluate(scans, results[:-1], MetricsConfig(), Sensor())
