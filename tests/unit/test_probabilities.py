"""Detection/survival probabilities (docs/method.md §4; tests T22, T23 of §6)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Polygon

from soabench.config import FilterConfig, Sensor
from soabench.gmphd.mixture import Mixture
from soabench.gmphd.models import measurement_noise, update
from soabench.gmphd.probabilities import (
    beta_inflate,
    beta_mean,
    beta_moment_match,
    beta_predict,
    beta_prior,
    beta_survival_predict,
    beta_var,
    detection_gate,
)

R = measurement_noise(1.0, math.radians(5.0))
EGO = np.zeros(3)


def _dyn_component(x: float, y: float, sD: float, tD: float, w: float = 1.0) -> Mixture:
    return Mixture.from_arrays([w], [[x, y, 0.0, 0.0]], [np.eye(4)], beta=[sD, tD, 19.8, 0.2])


# ---------------------------------------------------------------------------------------------------------------------
# T22: Beta p_D


def test_t22_miss_multiplies_by_t_over_n_and_increments_t():
    mix = _dyn_component(10.0, 0.0, 9.8, 0.2)
    g = np.ones(1)
    up = update(mix, np.zeros((0, 2)), EGO, g * beta_mean(mix.sD, mix.tD), np.zeros(0), R, g=g)
    assert len(up.mix) == 1
    assert up.mix.w[0] == pytest.approx(0.02, abs=1e-12)
    np.testing.assert_allclose(up.mix.beta[0, :2], [9.8, 1.2], atol=1e-12)
    # the next miss multiplies by 1.2 / 11 = 0.109
    up2 = update(up.mix, np.zeros((0, 2)), EGO, beta_mean(up.mix.sD, up.mix.tD), np.zeros(0), R, g=g)
    assert up2.mix.w[0] / up.mix.w[0] == pytest.approx(1.2 / 11.0, rel=1e-12)


def test_t22_detection_multiplies_prenormalisation_weight_by_098_and_increments_s():
    mix = _dyn_component(10.0, 0.0, 9.8, 0.2, w=0.7)
    g = np.ones(1)
    z = np.array([[10.2, 0.01]])
    up = update(mix, z, EGO, g * beta_mean(mix.sD, mix.tD), 0.0, R, g=g, gate_thr=np.inf)
    stat = update(Mixture.from_arrays([0.7], mix.m, mix.P), z, EGO, 1.0, 0.0, R, gate_thr=np.inf)
    # A = p_D w q: the Beta mean 0.98 times the p_D = 1 support
    assert up.A[0] == pytest.approx(0.98 * stat.A[0], rel=1e-12)
    det = up.mix.n_det == 1
    assert det.sum() == 1
    np.testing.assert_allclose(up.mix.beta[det][0], [10.8, 0.2, 19.8, 0.2], atol=1e-12)
    # the missed term got t + 1, and with kappa = 0 the detection term carries weight exactly 1
    np.testing.assert_allclose(up.mix.beta[~det][0, :2], [9.8, 1.2], atol=1e-12)
    assert up.mix.w[det][0] == pytest.approx(1.0, abs=1e-12)


def test_t22_out_of_fov_gains_no_information():
    mix = _dyn_component(500.0, 0.0, 9.8, 0.2)
    g = detection_gate(mix.m, EGO, Sensor())
    assert g[0] == 0.0
    up = update(mix, np.array([[10.0, 0.0]]), EGO, g * beta_mean(mix.sD, mix.tD), 0.01, R, g=g)
    assert len(up.mix) == 1
    assert up.mix.w[0] == 1.0
    np.testing.assert_array_equal(up.mix.beta[0], [9.8, 0.2, 19.8, 0.2])


def test_t22_inflation_numbers_and_mean_preserved():
    s, t = beta_inflate(np.array([49.0, 9.8]), np.array([1.0, 0.2]), 1.1, 2.0)
    np.testing.assert_allclose(s, [44.4564, 8.82], atol=1e-4)
    np.testing.assert_allclose(t, [0.907273, 0.18], atol=1e-6)
    np.testing.assert_allclose(beta_mean(s, t), [0.98, 0.98], rtol=1e-12)
    # the variance grows by f (when theta stays above theta_min)
    np.testing.assert_allclose(beta_var(s, t), 1.1 * beta_var(np.array([49.0, 9.8]), np.array([1.0, 0.2])), rtol=1e-12)


def test_t22_theta_never_below_theta_min():
    rng = np.random.default_rng(1)
    s = rng.uniform(0.01, 3.0, 1000)
    t = rng.uniform(0.01, 3.0, 1000)
    for f in (1.1, 5.0, 1e6):
        s2, t2 = beta_inflate(s, t, f, 2.0)
        assert np.all(s2 + t2 >= 2.0 - 1e-12)
        assert np.all(np.isfinite(s2)) and np.all(np.isfinite(t2))
        np.testing.assert_allclose(beta_mean(s2, t2), beta_mean(s, t), rtol=1e-12)
    # degenerate variance inflation (f var >= mu(1-mu) gives theta = 0) is guarded, no NaN
    s3, t3 = beta_inflate(np.array([0.5]), np.array([0.5]), 100.0, 2.0)
    np.testing.assert_allclose([s3[0], t3[0]], [1.0, 1.0])


# ---------------------------------------------------------------------------------------------------------------------
# T23: Beta p_S


def test_t23_survival_factors_over_five_steps():
    s, t = np.array([19.8]), np.array([0.2])
    factors = []
    for _ in range(5):
        f, s, t = beta_survival_predict(s, t, 1.1, 2.0, 0.999)
        factors.append(f[0])
    np.testing.assert_allclose(factors, [0.99000, 0.99048, 0.99095, 0.99143, 0.99190], atol=1e-5)


def test_t23_cap_at_p_S_max_keeps_strength():
    f, s, t = beta_survival_predict(np.array([9990.0]), np.array([0.5]), 1.0, 2.0, 0.999)
    assert beta_mean(s, t)[0] == pytest.approx(0.999, rel=1e-12)
    assert s[0] + t[0] == pytest.approx(9991.5, rel=1e-9)
    assert f[0] == pytest.approx(9990.0 / 9990.5)


def test_beta_predict_columns_and_prior():
    cfg = FilterConfig()
    b0 = beta_prior(cfg)
    np.testing.assert_allclose(b0, [9.8, 0.2, 19.8, 0.2])
    factor, b1 = beta_predict(np.tile(b0, (3, 1)), cfg)
    np.testing.assert_allclose(factor, 0.99)
    np.testing.assert_allclose(b1[:, :2], np.tile([8.82, 0.18], (3, 1)), atol=1e-12)
    np.testing.assert_allclose(beta_mean(b1[:, 2], b1[:, 3]), 20.8 / 21.0)


def test_beta_moment_match_identity_and_pooling():
    s, t = np.array([9.8]), np.array([0.2])
    mu, var = beta_mean(s, t), beta_var(s, t)
    s2, t2 = beta_moment_match(np.array([2.0]), 2.0 * mu, 2.0 * (var + mu * mu), 2.0)
    np.testing.assert_allclose([s2[0], t2[0]], [9.8, 0.2], rtol=1e-10)
    # pooling two different means increases the variance: strength drops, mean is the weighted mean
    s_a, t_a = np.array([9.8, 5.0]), np.array([0.2, 5.0])
    w = np.array([1.0, 3.0])
    mu_a, var_a = beta_mean(s_a, t_a), beta_var(s_a, t_a)
    s3, t3 = beta_moment_match(np.array([w.sum()]), np.array([w @ mu_a]), np.array([w @ (var_a + mu_a**2)]), 2.0)
    assert beta_mean(s3, t3)[0] == pytest.approx((w @ mu_a) / 4.0)
    assert s3[0] + t3[0] < 10.0


# ---------------------------------------------------------------------------------------------------------------------
# detection gate g(x) (§4.1, §4.4)


def test_detection_gate_fov_range_and_sector():
    m = np.array([[10.0, 0, 0, 0], [0.2, 0, 0, 0], [60.0, 0, 0, 0], [-10.0, 0, 0, 0], [0, 10.0, 0, 0]])
    np.testing.assert_array_equal(detection_gate(m, EGO, Sensor()), [1, 0, 0, 1, 1])
    sector = Sensor(fov_deg=120.0)
    np.testing.assert_array_equal(detection_gate(m, EGO, sector), [1, 0, 0, 0, 0])
    # the sector is centred on the ego heading
    np.testing.assert_array_equal(detection_gate(m, np.array([0.0, 0.0, math.pi / 2]), sector), [0, 0, 0, 0, 1])


def test_detection_gate_line_of_sight():
    box = Polygon([(9, -1), (11, -1), (11, 1), (9, 1)])
    m = np.array([[20.0, 0, 0, 0], [5.0, 0, 0, 0], [0, 20.0, 0, 0], [80.0, 0, 0, 0]])
    g = detection_gate(m, EGO, Sensor(), [box])
    np.testing.assert_array_equal(g, [0, 1, 1, 0])
    np.testing.assert_array_equal(detection_gate(m, EGO, Sensor(), None), [1, 1, 1, 0])
