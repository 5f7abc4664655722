"""Motion and measurement models and the GM-PHD predict/update (docs/method.md §2.2, §2.3, §2.5-2.8, §3.2, §3.4).

The per-component and per-(j, l) formulas (EKF terms, log-likelihoods, Kalman posteriors) are compiled loops in
:mod:`soabench.gmphd.kernels`; this module holds the models and the update's bookkeeping as array code. The
likelihoods q (J, M) are formed in the log domain, and only (j, l) pairs with q > 0 become posterior components.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from soabench.geometry import wrap
from soabench.gmphd import kernels
from soabench.gmphd.mixture import Mixture
from soabench.types import SOURCE_MEAS, NewbornTerms

GATE_999 = -2.0 * math.log(1.0 - 0.999)  #: chi2_2(0.999) = 13.8155 (§2.8)
_I4 = np.eye(4)


def gate_threshold(gate: bool, gate_prob: float) -> float:
    """Squared-Mahalanobis gate of §2.8: chi2_2 quantile -2 ln(1 - p) (exact for 2 dof), or +inf when off."""
    return -2.0 * math.log1p(-gate_prob) if gate else math.inf


def cv_model(dt: float, sigma_a: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant-velocity F and discrete white-noise acceleration Q = sigma_a^2 G G^T (§2.2)."""
    F = np.array([[1.0, 0.0, dt, 0.0], [0.0, 1.0, 0.0, dt], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    G = np.array([[0.5 * dt * dt, 0.0], [0.0, 0.5 * dt * dt], [dt, 0.0], [0.0, dt]])
    return F, sigma_a**2 * (G @ G.T)


def measurement_noise(sigma_r: float, sigma_b: float) -> np.ndarray:
    """R = diag(sigma_r^2, sigma_b^2) with sigma_b in radians (§2.3)."""
    return np.diag([sigma_r**2, sigma_b**2])


def symmetrise(P: np.ndarray) -> np.ndarray:
    """(P + P^T) / 2 over the last two axes."""
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def predict(mix: Mixture, F: np.ndarray, Q: np.ndarray, p_S: float | np.ndarray) -> Mixture:
    """Vo-Ma prediction without spawning (§2.5): w <- p_S w, m <- F m, P <- F P F^T + Q; age += 1.

    ``p_S`` is a scalar (static mode) or the per-component factor E[p_S] (dynamic mode, §4.3). Beta parameters are
    carried unchanged (the caller replaces them, :func:`soabench.gmphd.probabilities.beta_predict`).
    """
    if len(mix) == 0:
        return mix.copy()
    m, P = predict_moments(mix.m, mix.P, F, Q)
    return Mixture(mix.w * p_S, m, P, mix.origin.copy(), mix.n_det.copy(), mix.age + 1, mix.beta, mix.label.copy())


def predict_moments(m: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The moments of :func:`predict` (§2.5): m <- F m, P <- F P F^T + Q (symmetrised), for (J, 4) and (J, 4, 4)."""
    return m @ F.T, symmetrise(F @ P @ F.T + Q)


# ----------------------------------------------------------------------------------------------------------------
# measurement model: h, H, S, gains (EKF §2.6, UKF §2.7)


def h(x: np.ndarray, ego: np.ndarray) -> np.ndarray:
    """h(x) = [r, b] (..., 2) relative to the ego pose (§2.3); b = wrap(atan2(dy, dx) - theta_e)."""
    dx = x[..., 0] - ego[0]
    dy = x[..., 1] - ego[1]
    return np.stack([np.hypot(dx, dy), wrap(np.arctan2(dy, dx) - ego[2])], axis=-1)


@dataclass
class MeasurementTerms:
    """Per-component predicted-measurement quantities (J rows), from :func:`ekf_terms` or :func:`ukf_terms`.

    Attributes:
        eta: (J, 2) predicted measurement (r, b).
        S: (J, 2, 2) innovation covariance; Sinv its closed-form inverse; logdet = log det S.
        C: (J, 4, 2) cross covariance (EKF: P H^T; UKF: C_xz), so K = C S^-1.
        H: (J, 2, 4) Jacobian (EKF only, for the Joseph form), else None.
        valid: (J,) False where the component is undetectable this step (r < r_min, a UKF sigma point with
            range < r_min, or det S <= 0): p_D is forced to 0 there.
    """

    eta: np.ndarray
    S: np.ndarray
    Sinv: np.ndarray
    logdet: np.ndarray
    C: np.ndarray
    H: np.ndarray | None
    valid: np.ndarray


def _inv2(S: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed-form inverse and log-determinant of symmetric 2x2 blocks (J, 2, 2); also det > 0 mask (§2.12 item 5)."""
    a, b, d = S[:, 0, 0], 0.5 * (S[:, 0, 1] + S[:, 1, 0]), S[:, 1, 1]
    det = a * d - b * b
    ok = (det > 0.0) & np.isfinite(det)
    det_safe = np.where(ok, det, 1.0)
    Sinv = np.empty_like(S)
    Sinv[:, 0, 0] = d / det_safe
    Sinv[:, 1, 1] = a / det_safe
    Sinv[:, 0, 1] = Sinv[:, 1, 0] = -b / det_safe
    return Sinv, np.log(det_safe), ok


def ekf_terms(m: np.ndarray, P: np.ndarray, ego: np.ndarray, R: np.ndarray, r_min: float) -> MeasurementTerms:
    """EKF linearisation at the predicted mean (§2.6): eta = h(m), H = H(m), S = H P H^T + R, C = P H^T
    (compiled: :func:`soabench.gmphd.kernels.ekf_terms`)."""
    eta, S, Sinv, logdet, C, H, valid = kernels.ekf_terms(
        np.ascontiguousarray(m, dtype=float),
        np.ascontiguousarray(P, dtype=float),
        np.asarray(ego, dtype=float),
        np.asarray(R, dtype=float),
        float(r_min),
    )
    return MeasurementTerms(eta, S, Sinv, logdet, C, H, valid)


def safe_cholesky(P: np.ndarray) -> np.ndarray:
    """Batched lower Cholesky factor with jitter retry 1e-9 trace/4 (x10 per retry) on failure (§2.12 item 5)."""
    P = symmetrise(P)
    jitter = 1e-9 * np.trace(P, axis1=-2, axis2=-1)[:, None, None] / 4.0 * _I4
    for _ in range(8):
        try:
            return np.linalg.cholesky(P)
        except np.linalg.LinAlgError:
            P = P + jitter
            jitter = jitter * 10.0
    # last resort: clip the eigenvalues
    lam, V = np.linalg.eigh(P)
    lam = np.maximum(lam, 1e-12 * np.maximum(lam.max(axis=-1, keepdims=True), 1e-12))
    return np.linalg.cholesky(symmetrise((V * lam[:, None, :]) @ np.swapaxes(V, 1, 2)))


def ukf_terms(m: np.ndarray, P: np.ndarray, ego: np.ndarray, R: np.ndarray, r_min: float) -> MeasurementTerms:
    """Equal-weight cubature/unscented transform (§2.7): 2n points m +- sqrt(n) chol(P) columns, weights 1/2n.

    The bearing mean is circular, differences are wrapped, and a component with any sigma point at range < r_min
    is undetectable this step.
    """
    n = 4
    Lc = safe_cholesky(P)  # (J, 4, 4), columns are the square-root directions
    dev = math.sqrt(n) * np.swapaxes(Lc, 1, 2)  # (J, 4, 4): row i = sqrt(n) C[:, i]
    X = np.concatenate([dev, -dev], axis=1)  # (J, 8, 4) deviations chi_i - m
    dxy = m[:, None, :2] + X[:, :, :2] - ego[:2]
    rr = np.hypot(dxy[..., 0], dxy[..., 1])
    bb = np.arctan2(dxy[..., 1], dxy[..., 0]) - ego[2]
    valid = rr.min(axis=1) >= max(r_min, 1e-9)
    zr = rr.mean(axis=1)
    zb = np.arctan2(np.sin(bb).mean(axis=1), np.cos(bb).mean(axis=1))
    D = np.stack([rr - zr[:, None], wrap(bb - zb[:, None])], axis=-1)  # (J, 8, 2)
    w0 = 1.0 / (2 * n)
    S = symmetrise(w0 * np.swapaxes(D, 1, 2) @ D + R)
    C = w0 * np.swapaxes(X, 1, 2) @ D  # (J, 4, 2)
    Sinv, logdet, ok = _inv2(S)
    eta = np.stack([zr, wrap(zb)], axis=-1)
    return MeasurementTerms(eta, S, Sinv, logdet, C, None, valid & ok)


def log_likelihood(terms: MeasurementTerms, Z: np.ndarray, gate_thr: float) -> tuple[np.ndarray, ...]:
    """log q_jl (J, M) = -d2/2 - log 2 pi - log det S / 2, -inf where d2 > gate_thr (§2.6, §2.8).

    Returns (log q, nu_r, nu_b) (compiled: :func:`soabench.gmphd.kernels.log_likelihood`).
    """
    Z = np.ascontiguousarray(Z, dtype=float).reshape(-1, 2)
    return kernels.log_likelihood(terms.eta, terms.Sinv, terms.logdet, Z, float(gate_thr))


# ----------------------------------------------------------------------------------------------------------------
# the update


def logsumexp0(x: np.ndarray) -> np.ndarray:
    """log sum_j exp(x_jl) over axis 0 with the max shift (the same result as ``scipy.special.logsumexp(x, axis=0)``
    for finite/-inf input, without its per-call array-API overhead, which dominated small updates); -inf for an
    all -inf column."""
    if x.shape[0] == 0:
        return np.full(x.shape[1:], -np.inf)
    mx = x.max(axis=0)
    shift = np.where(np.isfinite(mx), mx, 0.0)
    with np.errstate(divide="ignore"):
        return np.log(np.exp(x - shift).sum(axis=0)) + shift


_NO_JACOBIAN = np.zeros((0, 2, 4))  #: the UKF form has no H: ``posterior_pairs`` then uses P - K S K^T


def _per_row(x: np.ndarray | float, n: int) -> np.ndarray:
    """A scalar or an array broadcastable to (n,) as a float (n,) array (read-only use)."""
    if np.ndim(x) == 0:
        return np.full(n, float(x))
    return np.broadcast_to(np.asarray(x, dtype=float), (n,))


@dataclass
class UpdateResult:
    """Posterior of :func:`update` and its per-measurement diagnostics.

    Attributes:
        mix: posterior mixture: missed-detection terms (J), detection pairs (j, l) with q > 0, newborns.
        A: (M,) persistent support A_l = sum_j p_D,j w_j q_jl.
        log_L: (M,) log of the normaliser L_l = kappa_l + A_l (+ beta_l); -inf if L_l = 0 (measurement skipped).
        beta: (M,) newborn terms beta_l (zeros without newborn terms).
        n_pairs: number of detection components built.
        n_newborn: number of newborn components built.
        p_D: (J,) the p_D,j actually used (input p_D with the r_min / UKF / det S guards applied).
    """

    mix: Mixture
    A: np.ndarray
    log_L: np.ndarray
    beta: np.ndarray
    n_pairs: int
    n_newborn: int
    p_D: np.ndarray


def update(
    mix: Mixture,
    Z: np.ndarray,
    ego: np.ndarray,
    p_D: np.ndarray | float,
    kappa: np.ndarray | float,
    R: np.ndarray,
    *,
    g: np.ndarray | None = None,
    form: str = "ekf",
    gate_thr: float = GATE_999,
    r_min: float = 0.5,
    newborn: NewbornTerms | None = None,
    newborn_beta: np.ndarray | None = None,
    newborn_label0: int = 0,
) -> UpdateResult:
    """GM-PHD measurement update with range-bearing measurements relative to ``ego`` (§2.6-2.8, §3.2, §3.4).

    Args:
        mix: predicted intensity (persistent components plus appended births).
        Z: (M, 2) measurements (range, bearing); ego: (3,) sensor pose.
        p_D: (J,) or scalar p_D,j evaluated at the means (static: p_D g; dynamic: g sD/(sD+tD)). Components with
            r(m_j) < r_min (EKF) or a sigma point inside r_min (UKF) get p_D = 0 here.
        kappa: (M,) or scalar clutter intensity kappa(z_l) (never gated).
        R: measurement noise.
        g: (J,) detection gate used by the dynamic-mode miss update t_D <- t_D + g (default 1[p_D > 0]).
        form: "ekf" (default, Joseph form) or "ukf" (equal-weight cubature).
        gate_thr: squared-Mahalanobis gate (inf = off).
        newborn: measurement-driven newborn terms: beta_l = newborn.beta(A, kappa) enters L_l; newborn l gets
            weight beta_l / L_l, the given mean/cov, no Kalman correction and no missed-detection term.
        newborn_beta: (4,) Beta parameters of newborns in dynamic mode.
        newborn_label0: the newborn term of measurement l is labelled newborn_label0 + l (§2.13); missed-detection
            and detection terms keep their component's label.

    Log domain: log L_l = logsumexp(log kappa_l, log p_D,j w_j q_jl over j, log beta_l); a measurement with
    L_l = 0 is skipped. Dynamic mode: missed w (1 - p_D) with t_D += g; detected w p_D q/L with s_D += 1.
    The posterior may share (read-only) arrays with ``mix``.
    """
    Z = np.ascontiguousarray(Z, dtype=float).reshape(-1, 2)
    R = np.asarray(R, dtype=float)
    M = len(Z)
    J = len(mix)
    p_D = _per_row(p_D, J)
    kappa = _per_row(kappa, M)
    g = (p_D > 0.0).astype(float) if g is None else _per_row(g, J)

    det_idx = np.flatnonzero(p_D > 0.0)
    terms = None
    if len(det_idx):
        m_d, P_d = mix.m[det_idx], mix.P[det_idx]
        terms = (ekf_terms if form == "ekf" else ukf_terms)(m_d, P_d, ego, R, r_min)
        if not terms.valid.all():  # r -> 0 / UKF sigma point inside r_min / det S <= 0: undetectable (§2.12)
            bad = det_idx[~terms.valid]
            p_D = p_D.copy()
            g = g.copy()
            p_D[bad] = 0.0
            g[bad] = 0.0
        if M == 0:
            terms = None

    # missed-detection terms (all J)
    miss = Mixture(mix.w * (1.0 - p_D), mix.m, mix.P, mix.origin, mix.n_det, mix.age, None, mix.label)
    if mix.beta is not None:
        miss.beta = mix.beta.copy()
        miss.beta[:, 1] += g

    parts = [miss]
    n_pairs = 0
    with np.errstate(divide="ignore", invalid="ignore"):  # log 0 = -inf is the intended value throughout
        log_L = np.log(kappa)
        A = np.zeros(M)
        if terms is not None:
            logq, nu_r, nu_b = log_likelihood(terms, Z, gate_thr)
            log_t = np.log(p_D[det_idx] * mix.w[det_idx])[:, None] + logq  # (Jd, M) log p_D w q
            log_A = logsumexp0(log_t)
            log_L = np.logaddexp(log_L, log_A)
            A = np.exp(log_A)
        beta_nb = np.zeros(M)
        if newborn is not None and M:
            beta_nb = np.asarray(newborn.beta(A, kappa), dtype=float).reshape(M)
            beta_nb = np.where(beta_nb > 0.0, beta_nb, 0.0)  # a newborn term is a non-negative intensity
            log_L = np.logaddexp(log_L, np.log(beta_nb))
        log_L_safe = np.where(np.isfinite(log_L), log_L, 0.0)  # L_l = 0: every term of L_l is 0, so w = 0

        if terms is not None:
            w_det = np.exp(log_t - log_L_safe)
            jj, ll = np.nonzero(w_det > 0.0)
            n_pairs = len(jj)
            if n_pairs:
                H = terms.H if terms.H is not None else _NO_JACOBIAN
                m_new, P_new = kernels.posterior_pairs(m_d, P_d, terms.C, terms.Sinv, terms.S, H, R, jj, ll, nu_r, nu_b)
                src = det_idx[jj]
                beta_new = None
                if mix.beta is not None:
                    beta_new = mix.beta[src].copy()
                    beta_new[:, 0] += 1.0
                origin, n_det, age, label = mix.origin[src], mix.n_det[src] + 1, mix.age[src], mix.label[src]
                parts.append(Mixture(w_det[jj, ll], m_new, P_new, origin, n_det, age, beta_new, label))
        w_nb = np.exp(np.log(beta_nb) - log_L_safe) if newborn is not None and M else None

    n_newborn = 0
    if w_nb is not None:
        keep = np.flatnonzero(w_nb > 0.0)
        n_newborn = len(keep)
        if n_newborn:
            nb_beta = None
            if mix.beta is not None:
                if newborn_beta is None:
                    raise ValueError("dynamic-mode update with newborn terms needs newborn_beta (sD, tD, sS, tS)")
                nb_beta = np.broadcast_to(np.asarray(newborn_beta, dtype=float), (n_newborn, 4)).copy()
            parts.append(
                Mixture.from_arrays(
                    w_nb[keep],
                    np.asarray(newborn.m, dtype=float)[keep],
                    np.asarray(newborn.P, dtype=float)[keep],
                    origin=SOURCE_MEAS,
                    n_det=1,
                    age=0,
                    beta=nb_beta,
                    label=newborn_label0 + keep,
                )
            )
    post = Mixture.concatenate(parts) if len(parts) > 1 else parts[0]
    return UpdateResult(post, A, log_L, beta_nb, n_pairs, n_newborn, p_D)
