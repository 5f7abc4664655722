"""Measurement models of the LMB update: the GM-PHD's range-bearing EKF (docs/method.md §2.3, §2.6, §2.8) and a
linear position sensor (the linear-Gaussian case of the known-answer test T36).

A model turns the predicted components (m, P) into :class:`~soabench.gmphd.models.MeasurementTerms` and the
log-likelihoods ``log q (C, M)`` with the innovations the Kalman update of
:func:`soabench.gmphd.kernels.posterior_pairs` reads; gating sets log q = -inf.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from soabench.gmphd import kernels
from soabench.gmphd.models import MeasurementTerms, _inv2, ekf_terms, log_likelihood, ukf_terms


class MeasurementModel(Protocol):
    """What the LMB update needs of a sensor model."""

    R: np.ndarray

    def terms(self, m: np.ndarray, P: np.ndarray, ego: np.ndarray) -> MeasurementTerms: ...

    def log_likelihood(self, terms: MeasurementTerms, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


class RangeBearingEKF:
    """The GM-PHD's sensor: h(x) = (range, bearing) relative to the ego pose, EKF linearisation at each mean
    (``form = "ekf"``, §2.6) or the equal-weight cubature transform (``"ukf"``, §2.7), chi-square gate ``gate_thr``
    on the squared Mahalanobis distance (§2.3, §2.8)."""

    def __init__(self, R: np.ndarray, r_min: float, gate_thr: float, form: str = "ekf") -> None:
        self.R = np.asarray(R, dtype=float)
        self.r_min = float(r_min)
        self.gate_thr = float(gate_thr)
        self.form = form
        self._terms = ekf_terms if form == "ekf" else ukf_terms

    def terms(self, m: np.ndarray, P: np.ndarray, ego: np.ndarray) -> MeasurementTerms:
        return self._terms(m, P, ego, self.R, self.r_min)

    def log_likelihood(self, terms: MeasurementTerms, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return log_likelihood(terms, Z, self.gate_thr)


class LinearPosition:
    """z = H x + v with H = [I_2 0] and v ~ N(0, R) (world frame; the ego pose is ignored), gate ``gate_thr``."""

    def __init__(self, R: np.ndarray, gate_thr: float = math.inf) -> None:
        self.R = np.asarray(R, dtype=float)
        self.gate_thr = float(gate_thr)

    def terms(self, m: np.ndarray, P: np.ndarray, ego: np.ndarray) -> MeasurementTerms:
        m = np.asarray(m, dtype=float).reshape(-1, 4)
        P = np.asarray(P, dtype=float).reshape(-1, 4, 4)
        J = len(m)
        H = np.zeros((J, 2, 4))
        H[:, 0, 0] = H[:, 1, 1] = 1.0
        C = np.ascontiguousarray(P[:, :, :2])
        S = P[:, :2, :2] + self.R
        S = 0.5 * (S + np.swapaxes(S, 1, 2))
        Sinv, logdet, ok = _inv2(S)
        return MeasurementTerms(np.ascontiguousarray(m[:, :2]), S, Sinv, logdet, C, H, ok)

    def log_likelihood(self, terms: MeasurementTerms, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        Z = np.asarray(Z, dtype=float).reshape(-1, 2)
        nu = Z[None, :, :] - terms.eta[:, None, :]  # (J, M, 2)
        Si = terms.Sinv
        d2 = (
            Si[:, None, 0, 0] * nu[..., 0] ** 2
            + 2.0 * Si[:, None, 0, 1] * nu[..., 0] * nu[..., 1]
            + Si[:, None, 1, 1] * nu[..., 1] ** 2
        )
        logq = -0.5 * d2 - math.log(2.0 * math.pi) - 0.5 * terms.logdet[:, None]
        logq = np.where(d2 <= self.gate_thr, logq, -np.inf)
        return logq, np.ascontiguousarray(nu[..., 0]), np.ascontiguousarray(nu[..., 1])


def kalman_pairs(
    m: np.ndarray, P: np.ndarray, terms: MeasurementTerms, R: np.ndarray, jj: np.ndarray, ll: np.ndarray,
    nu_r: np.ndarray, nu_b: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Kalman-updated (m, P) of the component-measurement pairs (jj, ll), jj sorted (Joseph form, as the GM-PHD:
    :func:`soabench.gmphd.kernels.posterior_pairs`)."""
    H = terms.H if terms.H is not None else np.zeros((0, 2, 4))
    return kernels.posterior_pairs(
        np.ascontiguousarray(m), np.ascontiguousarray(P), terms.C, terms.Sinv, terms.S, H, np.asarray(R, dtype=float),
        np.ascontiguousarray(jj, dtype=np.int64), np.ascontiguousarray(ll, dtype=np.int64),
        np.ascontiguousarray(nu_r), np.ascontiguousarray(nu_b),
    )  # fmt: skip
