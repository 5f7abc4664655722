"""Partially Uniform Birth Model (PUBM) of Beard, Vo, Vo & Arulampalam (FUSION 2012) (docs/method.md §3.2, row 15).

The birth intensity is uniform over the measurement-space FOV V_z and Gaussian in velocity; with a position-observing
sensor its update is measurement-driven. Each scan hands the filter one newborn term per measurement
(:class:`~soabench.types.NewbornTerms`):

* beta_l = p_D,b w_PU / |V_z| (``pubm_space = meas``) or p_D,b w_PU r_l / A with A = Theta (r_max^2 - r_min^2) / 2
  (``cart``), w_PU = (1 - eta) N_hat;
* mean [x_e + r_l cos phi_l, y_e + r_l sin phi_l, 0, 0] with phi_l = b_l + theta_e (inverse measurement) and
  covariance blkdiag(J_l R J_l^T, sigma_v^2 I).

The undetected part (1 - p_D) w_PU cannot be a Gaussian mixture and is dropped. ``pubm_hybrid = eta`` adds the GMBM
components (§3.5) with total mass eta N_hat.
"""

from __future__ import annotations

import numpy as np

from soabench.baselines.standard_gm import StandardGMBirth
from soabench.birth.base import build_components
from soabench.config import BirthConfig, SensorConfig
from soabench.geometry import fov_area, inverse_measurement_cov, measurement_volume, polar_to_world
from soabench.scenario.scene import SceneMap
from soabench.types import BirthContext, Births, NewbornTerms, Scan, scan_once


def inverse_measurement_terms(
    Z: np.ndarray, ego: np.ndarray, sensor: SensorConfig, sigma_v: float
) -> tuple[np.ndarray, np.ndarray]:
    """(m, P) of the newborn of each measurement: inverse-measurement mean and blkdiag(J R J^T, sigma_v^2 I) (§3.2)."""
    Z = np.asarray(Z, dtype=float).reshape(-1, 2)
    return build_components(polar_to_world(Z, ego), inverse_measurement_cov(Z, ego, sensor), sigma_v)


def scan_inverse_terms(scan: Scan, sensor: SensorConfig, sigma_v: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`inverse_measurement_terms` of the scan's own Z_k and pose, computed once per scan for every run that
    asks (PUBM and ATBM, static and dynamic: the same values, docs/method.md §5.8) and kept read-only on the scan
    (:meth:`soabench.types.Scan.once`); computed here for a scan that cannot keep it."""

    def make() -> tuple[np.ndarray, np.ndarray]:
        m, P = inverse_measurement_terms(scan.Z, scan.ego, sensor, sigma_v)
        m.setflags(write=False)
        P.setflags(write=False)
        return m, P

    key = ("birth.inverse_terms", id(scan.Z), id(scan.ego), float(sensor.sigma_r), float(sensor.sigma_b))
    key += (float(sigma_v),)
    return scan_once(scan, key, lambda: (*make(), scan.Z, scan.ego))[:2]  # held with Z and ego: their ids stay theirs


class PartiallyUniformBirth:
    """PUBM (§3.2). ``PartiallyUniformBirth(cfg, sensor, scene, rng)(ctx) -> Births`` with newborn terms."""

    name = "pubm"

    def __init__(self, cfg: BirthConfig, sensor: SensorConfig, scene: SceneMap, rng: np.random.Generator) -> None:
        cfg.validate()
        self.cfg, self.sensor = cfg, sensor
        self.w_PU = (1.0 - cfg.pubm_hybrid) * cfg.N_hat
        self.gm = (
            StandardGMBirth(cfg, sensor, scene, rng, mass=cfg.pubm_hybrid * cfg.N_hat) if cfg.pubm_hybrid > 0 else None
        )

    def __call__(self, ctx: BirthContext) -> Births:
        """Newborn terms of Z_k (none when M = 0), plus the hybrid GMBM components if eta > 0."""
        scan = ctx.scan
        births = self.gm(ctx) if self.gm is not None else Births.empty()
        Z = np.asarray(scan.Z, dtype=float).reshape(-1, 2)
        if len(Z) == 0:
            return births
        m, P = scan_inverse_terms(scan, self.sensor, self.cfg.sigma_v_birth)
        if self.cfg.pubm_space == "meas":
            beta = np.full(len(Z), ctx.p_D_b * self.w_PU / measurement_volume(self.sensor))
        else:
            beta = ctx.p_D_b * self.w_PU * Z[:, 0] / fov_area(self.sensor)
        births.newborn = NewbornTerms(m, P, lambda A, kappa: beta)
        return births
