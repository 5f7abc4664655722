"""Adaptive Target Birth Model (ATBM) of Ristic, Clark, Vo & Vo (IEEE TAES 2012), GM form (docs/method.md §3.4).

``atbm = same_scan`` (default): one newborn term per measurement of Z_k (inverse-measurement mean and covariance,
as PUBM), entering only the detection update of that measurement: beta_l = p_D,b nu_l q_b with
q_b = N(0; 0, 2R) = 1 / (2 pi sqrt(det 2R)), or the SMC-literal raw mass beta_l = nu_l (``atbm_raw_mass``). The
newborn mass is nu_l = N_hat / M (``atbm_alloc = uniform``) or nu_l = N_hat (1 - rho_l) / sum (1 - rho_l') with
rho_l = A_l / (kappa_l + A_l) (``unexplained``), evaluated inside the update where A and kappa are known.

``atbm = prev_scan``: components built from the previous scan's measurements with the k-1 ego pose, weights nu_l
from the ``unexplained`` rule with ``ctx.prev.A`` / ``ctx.prev.kappa``, predicted one step with the CV model (F, Q)
and appended to the predicted intensity (they get a missed-detection term), after the FOV-only rule at k.
"""

from __future__ import annotations

import math

import numpy as np

from soabench.baselines.partially_uniform import inverse_measurement_terms, scan_inverse_terms
from soabench.birth.base import FOVRule
from soabench.config import BirthConfig, SensorConfig
from soabench.errors import require
from soabench.scenario.scene import SceneMap
from soabench.types import SOURCE_MEAS, BirthContext, Births, NewbornTerms, Scan


def newborn_likelihood(sensor: SensorConfig) -> float:
    """q_b = N(0; 0, 2R) = 1 / (2 pi sqrt(det 2R)) (§3.4; 0.911891 for the paper's R, T21)."""
    return 1.0 / (2.0 * math.pi * math.sqrt(4.0 * sensor.sigma_r**2 * sensor.sigma_b**2))


def unexplained_mass(A: np.ndarray, kappa: np.ndarray, N_hat: float) -> np.ndarray:
    """nu_l = N_hat (1 - rho_l) / sum_l' (1 - rho_l'), rho_l = A_l / (kappa_l + A_l) (§3.4 ``unexplained``).

    A measurement with kappa_l + A_l = 0 counts as fully unexplained; if every measurement is fully explained the
    allocation is zero.
    """
    A = np.asarray(A, dtype=float)
    kappa = np.asarray(kappa, dtype=float)
    den = kappa + A
    rho = np.divide(A, den, out=np.zeros_like(A), where=den > 0)
    free = 1.0 - rho
    total = free.sum()
    return N_hat * free / total if total > 0 else np.zeros_like(A)


def cv_model(dt: float, sigma_a: float) -> tuple[np.ndarray, np.ndarray]:
    """(F, Q) of the CV model with discrete white-noise acceleration (§2.2)."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    G = np.array([[0.5 * dt * dt, 0.0], [0.0, 0.5 * dt * dt], [dt, 0.0], [0.0, dt]])
    return F, sigma_a**2 * G @ G.T


class AdaptiveBirth:
    """ATBM (§3.4). ``AdaptiveBirth(cfg, sensor, scene, rng, sigma_a=0.5)(ctx) -> Births``.

    ``sigma_a`` is the CV process noise of the ``prev_scan`` prediction; it defaults to the FilterConfig default
    (0.5 m/s^2) because BirthConfig does not carry it. The model keeps the previous scan (Z, ego) for ``prev_scan``.
    """

    name = "atbm"

    def __init__(
        self,
        cfg: BirthConfig,
        sensor: SensorConfig,
        scene: SceneMap,
        rng: np.random.Generator,
        sigma_a: float = 0.5,
    ) -> None:
        cfg.validate()
        self.cfg, self.sensor = cfg, sensor
        self.q_b = newborn_likelihood(sensor)
        self.rule = FOVRule(cfg, sensor, scene)
        self.F, self.Q = cv_model(sensor.dt, sigma_a)
        self._last: Scan | None = None

    def __call__(self, ctx: BirthContext) -> Births:
        if self.cfg.atbm == "prev_scan":
            births = self._prev_scan(ctx)
            self._last = ctx.scan
            return births
        return self._same_scan(ctx)

    def _same_scan(self, ctx: BirthContext) -> Births:
        """Newborn terms of Z_k with beta_l = p_D,b nu_l q_b (or nu_l)."""
        scan, cfg = ctx.scan, self.cfg
        Z = np.asarray(scan.Z, dtype=float).reshape(-1, 2)
        births = Births.empty()
        M = len(Z)
        if M == 0:
            return births
        m, P = scan_inverse_terms(scan, self.sensor, cfg.sigma_v_birth)
        scale = 1.0 if cfg.atbm_raw_mass else ctx.p_D_b * self.q_b
        N_hat = cfg.N_hat

        if cfg.atbm_alloc == "uniform":
            beta_u = np.full(M, scale * N_hat / M)

            def beta(A: np.ndarray, kappa: np.ndarray) -> np.ndarray:
                return beta_u

        else:

            def beta(A: np.ndarray, kappa: np.ndarray) -> np.ndarray:
                return scale * unexplained_mass(A, kappa, N_hat)

        births.newborn = NewbornTerms(m, P, beta, adaptive=True)
        return births

    def _prev_scan(self, ctx: BirthContext) -> Births:
        """Appended components from Z_{k-1} (ego at k-1), weights nu_l (unexplained), predicted with F, Q."""
        last, prev = self._last, ctx.prev
        if last is None or prev is None:
            return Births.empty()
        Z = np.asarray(last.Z, dtype=float).reshape(-1, 2)
        if len(Z) == 0:
            return Births.empty()
        A, kappa = np.asarray(prev.A, dtype=float), np.asarray(prev.kappa, dtype=float)
        require(
            len(A) == len(Z) and len(kappa) == len(Z),
            f"atbm prev_scan: the previous step reports {len(A)} supports for {len(Z)} measurements of scan {last.k}",
        )
        require(prev.k == last.k, f"atbm prev_scan: ctx.prev is step {prev.k} but the previous scan was {last.k}")
        nu = unexplained_mass(A, kappa, self.cfg.N_hat)
        m, P = inverse_measurement_terms(Z, last.ego, self.sensor, self.cfg.sigma_v_birth)
        m = m @ self.F.T
        P = self.F @ P @ self.F.T + self.Q
        ok = self.rule.mask(m[:, :2], ctx.scan) & (nu > 0)
        n = int(ok.sum())
        return Births(nu[ok], m[ok], P[ok], np.full(n, SOURCE_MEAS, dtype=np.int8))
