"""Standard GM birth model (GMBM) of Vo & Ma (2006): fixed, predefined Gaussians (docs/method.md §3.5, row 18).

The J_GM entry points are derived from the network, not typed in:

* sidewalk exits: every point where a sidewalk or crossing centre line (``scene.sidewalk_lines``) crosses the
  world-box boundary (the arms extend beyond the box, docs/user-guide/sumo.md), points closer than ``MERGE_DIST``
  merged;
* building accesses: every door of ``scene.doors`` (where pedestrians enter and leave buildings).

Each component has P_p = sigma_gm^2 I and the fixed weight N_hat / J_GM. Components outside the FOV at k are
skipped by the FOV-only rule (§3.0) without renormalisation, so the instantiated mass is <= N_hat.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import shapely

from soabench.birth.base import FOVRule, build_components
from soabench.config import BirthConfig, SensorConfig
from soabench.scenario.scene import SceneMap
from soabench.types import SOURCE_GM, BirthContext, Births

#: exits closer than this (m) are one exit (e.g. two touching lane segments crossing the boundary at one point)
MERGE_DIST = 1.0


def boundary_exits(scene: SceneMap, merge_dist: float = MERGE_DIST) -> np.ndarray:
    """(E, 2) points where the sidewalk/crossing centre lines cross the world-box boundary, clamped into the box."""
    lines = scene.sidewalk_lines
    if lines is None or lines.is_empty:
        return np.zeros((0, 2))
    hits = shapely.intersection(lines, scene.world_box.exterior)
    parts = shapely.get_parts(hits)
    # a line running along the boundary yields a segment: keep its end points
    pts = shapely.get_coordinates(parts) if len(parts) else np.zeros((0, 2))
    if len(pts) == 0:
        return np.zeros((0, 2))
    x0, y0, x1, y1 = scene.bounds
    pts = np.column_stack([np.clip(pts[:, 0], x0, x1), np.clip(pts[:, 1], y0, y1)])
    pts = pts[np.lexsort((pts[:, 1], pts[:, 0]))]
    keep: list[np.ndarray] = []
    for p in pts:
        if all(np.hypot(*(p - q)) >= merge_dist for q in keep):
            keep.append(p)
    return np.asarray(keep).reshape(-1, 2)


def entry_points(scene: SceneMap) -> np.ndarray:
    """(J_GM, 2) GMBM component means: boundary exits, then doors (§3.5)."""
    doors = np.asarray(scene.doors, dtype=float).reshape(-1, 2)
    return np.concatenate([boundary_exits(scene), doors])


class StandardGMBirth:
    """GMBM (§3.5). ``StandardGMBirth(cfg, sensor, scene, rng)(ctx) -> Births``; ``rng`` is unused.

    ``mass`` overrides the total N_hat (PUBM's hybrid variant uses eta N_hat).
    """

    name = "gmbm"
    #: births read only the scan (not ``ctx.prev`` nor ``ctx.p_D_b``): one call per scan serves every probability mode
    mode_free = True

    def __init__(
        self,
        cfg: BirthConfig,
        sensor: SensorConfig,
        scene: SceneMap,
        rng: np.random.Generator,
        mass: float | None = None,
    ) -> None:
        cfg.validate()
        self.cfg = cfg
        self.rule = FOVRule(cfg, sensor, scene)
        self.points = entry_points(scene)
        self.J_GM = len(self.points)
        self.static_ok = self.rule.static_mask(self.points)
        total = cfg.N_hat if mass is None else float(mass)
        self.w = total / self.J_GM if self.J_GM else 0.0
        self.m_all, self.P_all = build_components(self.points, cfg.sigma_gm**2 * np.eye(2), cfg.sigma_v_birth)

    def __call__(self, ctx: BirthContext) -> Births:
        """The fixed components that pass the FOV-only rule at k, weights N_hat / J_GM (not renormalised)."""
        if self.J_GM == 0:
            return Births.empty()
        return self._births(self.candidates(ctx), self.w)

    def candidates(self, ctx: BirthContext) -> GMCandidates:
        """The fixed components that pass the FOV-only rule at k, before their weights. They read only the scan's
        pose and occluders, so one set serves every probability mode, clutter rate and N_hat of a trial."""
        if self.J_GM == 0:
            return GMCandidates(np.zeros((0, 4)), np.zeros((0, 4, 4)), 0)
        idx = np.flatnonzero(self.rule.mask(self.points, ctx.scan, self.static_ok))
        return GMCandidates(self.m_all[idx], self.P_all[idx], self.J_GM)

    @staticmethod
    def weigh(cfg: BirthConfig, c: GMCandidates) -> Births:
        """The fixed weights N_hat / J_GM (§3.5)."""
        if c.J_GM == 0:
            return Births.empty()
        return StandardGMBirth._births(c, cfg.N_hat / c.J_GM)

    @staticmethod
    def _births(c: GMCandidates, w: float) -> Births:
        n = len(c.m)
        return Births(np.full(n, w), c.m, c.P, np.full(n, SOURCE_GM, dtype=np.int8))


class GMCandidates(NamedTuple):
    """GMBM's components of one scan before weighting (:meth:`StandardGMBirth.candidates`)."""

    m: np.ndarray  #: (n, 4) means
    P: np.ndarray  #: (n, 4, 4) covariances
    J_GM: int  #: number of a-priori components (the weight's denominator)
