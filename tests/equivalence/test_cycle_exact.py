"""Shortcuts of the fused cycle that must not change a bit (docs/method.md §2.6, §2.9; soabench/gmphd/cycle.py).

* :func:`cycle.support` skips the bearing and the exp of a pair that the range alone puts beyond the gate, and sums
  the log-sum-exp row by row: every term, log L and A must equal those of the dense column-by-column loop it
  replaces (written out below), bit for bit, including the -inf of gated pairs;
* the heaviest-first order of the reduction (an LSD radix sort for large mixtures) must be numpy's stable argsort.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from soabench.gmphd import cycle, kernels
from soabench.gmphd.models import gate_threshold, measurement_noise


@njit(cache=False)
def dense_support(w, p_D, det_idx, eta, Sinv, logdet, Z, kappa, gate_thr):
    """The loop before the shortcuts: every (row, measurement) term, then a log-sum-exp per column."""
    n_d, M = det_idx.shape[0], Z.shape[0]
    log_t = np.empty((n_d, M))
    for k in range(n_d):
        j = det_idx[k]
        a, b, d = Sinv[k, 0, 0], Sinv[k, 0, 1], Sinv[k, 1, 1]
        c = -math.log(2.0 * math.pi) - 0.5 * logdet[k]
        lpw = np.log(p_D[j] * w[j])
        for ll in range(M):
            r = Z[ll, 0] - eta[k, 0]
            t = kernels.wrap(Z[ll, 1] - eta[k, 1])
            d2 = a * r * r + 2.0 * b * r * t + d * t * t
            log_t[k, ll] = lpw + (-0.5 * d2 + c if d2 <= gate_thr else -np.inf)
    log_L = np.log(kappa)
    A = np.zeros(M)
    for ll in range(M):
        mx = -np.inf
        for k in range(n_d):
            mx = max(mx, log_t[k, ll])
        shift = mx if math.isfinite(mx) else 0.0
        acc = 0.0
        for k in range(n_d):
            acc += math.exp(log_t[k, ll] - shift)
        log_A = (np.log(acc) if acc > 0.0 else -np.inf) + shift
        log_L[ll] = cycle._logaddexp(log_L[ll], log_A)
        A[ll] = math.exp(log_A)
    return log_t, log_L, A


def _scene(rng: np.random.Generator, J: int, M: int) -> tuple:
    """J components around the sensor (some wide, some inside r_min or outside the FOV) and M measurements."""
    xy = rng.uniform(-40.0, 40.0, (J, 2))
    xy[:3] = np.array([[0.3, 0.1], [1e-12, 0.0], [25.0, 0.0]])[: min(J, 3)]  # inside r_min, at the sensor, far
    m = np.column_stack([xy, rng.normal(0.0, 1.0, (J, 2))])
    A = rng.normal(0.0, 0.6, (J, 4, 4))
    P = A @ np.swapaxes(A, 1, 2) + 0.2 * np.eye(4)
    wide = rng.choice(J, J // 10, replace=False)
    P[wide, :2, :2] *= rng.uniform(10.0, 1000.0, len(wide))[:, None, None]
    w = 10.0 ** rng.uniform(-6.0, 0.0, J)
    w[5:6] = 0.0  # a zero weight: log p_D w = -inf
    g = (rng.uniform(size=J) < 0.9).astype(float)
    Z = np.column_stack([rng.uniform(0.0, 60.0, M), rng.uniform(-math.pi, math.pi, M)])
    kappa = rng.uniform(1e-4, 1e-2, M)
    return w, m, P, g, Z, kappa


@pytest.mark.parametrize("ukf", [False, True])
@pytest.mark.parametrize("gate_prob", [0.99, 0.9999])
def test_support_equals_dense_loop(ukf, gate_prob):
    rng = np.random.default_rng(7 + ukf)
    R = measurement_noise(1.0, math.radians(5.0))
    ego = np.array([0.5, -0.2, 0.3])
    gate_thr = gate_threshold(True, gate_prob)
    for J, M in ((1, 1), (40, 0), (300, 45)):
        w, m, P, g, Z, kappa = _scene(rng, J, M)
        beta = np.empty((0, 0))
        sup = cycle.support(w, m, P, beta, g, 0.9, Z, ego, R, 0.5, gate_thr, kappa, ukf)
        p_D, det_idx, Sinv, log_t, log_L, A, ok = sup[0], sup[2], sup[4], sup[9], sup[10], sup[11], sup[12]
        assert ok
        if M == 0:
            assert log_t.shape == (0, 0) and log_L.shape == (0,)
            continue
        m_d, P_d = m[det_idx], P[det_idx]
        terms = cycle.ukf_terms(m_d, P_d, ego, R, 0.5) if ukf else kernels.ekf_terms(m_d, P_d, ego, R, 0.5)
        eta, logdet = terms[0], terms[3]
        ref_t, ref_L, ref_A = dense_support(w, p_D, det_idx, eta, Sinv, logdet, Z, kappa, gate_thr)
        if J > 100:
            assert np.isneginf(log_t).mean() > 0.5  # the shortcut is exercised: most pairs are gated out
        assert log_t.tobytes() == ref_t.tobytes()
        assert log_L.tobytes() == ref_L.tobytes()
        assert A.tobytes() == ref_A.tobytes()


@pytest.mark.parametrize("J", [0, 1, 7, 1499, 1500, 4000])
def test_heaviest_first_is_the_stable_argsort(J):
    rng = np.random.default_rng(J)
    cases = [
        rng.uniform(0.0, 1.0, J),
        np.round(rng.uniform(0.0, 1.0, J), 2),  # many ties: index order inside a tie
        10.0 ** rng.uniform(-300.0, 300.0, J) * rng.choice([-1.0, 1.0], J),
        np.where(rng.uniform(size=J) < 0.5, 0.0, -0.0),  # signed zeros compare equal
    ]
    for w in cases:
        np.testing.assert_array_equal(cycle._order_heaviest_first(w), np.argsort(-w, kind="stable"))
