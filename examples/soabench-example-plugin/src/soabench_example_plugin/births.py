"""An example birth model for soabench's GM-PHD filter: births on the far range arc of the field of view.

New walkers mostly enter the sensor's view at its range limit, so this model spreads ``n_arc`` Gaussian
components evenly along the arc at ``r_max - delta_in - inset`` (in the FOV sector, world frame at scan k), drops
those the shared FOV rule rejects (inside buildings, occluders, outside the workspace), and gives the survivors
equal weights summing to the expected births per scan ``N_hat``.
"""

from __future__ import annotations

import numpy as np

from soabench.api import SOURCE_FOV, BirthContext, Births, FOVRule, births_from, isotropic


class EdgeBirth:
    """``EdgeBirth(cfg, sensor, scene, rng, n_arc=36, sigma=2.0, inset=2.0)``; ``model(ctx) -> Births``.

    Options (``[plugins.edge]``): ``n_arc`` components on the arc, ``sigma`` their position std (m), ``inset`` the
    distance of the arc inside the range limit (m).
    """

    name = "edge"

    def __init__(self, cfg, sensor, scene, rng, n_arc: int = 36, sigma: float = 2.0, inset: float = 2.0) -> None:
        if not (isinstance(n_arc, int) and n_arc >= 1):
            raise ValueError(f"n_arc = {n_arc!r} must be an integer >= 1")
        if not sigma > 0:
            raise ValueError(f"sigma = {sigma!r} must be > 0")
        self.cfg, self.sensor = cfg, sensor
        self.rule = FOVRule(cfg, sensor, scene)
        half = np.radians(sensor.fov_deg) / 2.0
        full = sensor.fov_deg >= 360.0
        self.bearings = np.linspace(-half, half, n_arc, endpoint=not full)
        self.radius = max(sensor.r_min, sensor.r_max - cfg.delta_in - inset)
        self.cov = isotropic(sigma, n_arc)

    def __call__(self, ctx: BirthContext) -> Births:
        x, y, theta = np.asarray(ctx.scan.ego, dtype=float)
        a = theta + self.bearings
        p = np.column_stack([x + self.radius * np.cos(a), y + self.radius * np.sin(a)])
        keep = self.rule.mask(p, ctx.scan)
        n = int(keep.sum())
        if n == 0:
            return Births.empty()
        w = np.full(n, self.cfg.N_hat / n)
        source = np.full(n, SOURCE_FOV)
        return births_from(p[keep], self.cov[keep], w, source, self.cfg.sigma_v_birth)
