"""Uniform Birth Model (UBM): Gaussians spread uniformly across the workspace (docs/method.md §3.3, register row 16).

A regular grid of spacing d_u over the world box, node centres at (x_min + (i + 1/2) d_u, y_min + (j + 1/2) d_u),
built once per trial with its time-invariant part of the FOV-only rule (§3.0). Each scan instantiates the nodes in
FOV_k (one :func:`~soabench.geometry.fov_mask`) that are not inside an occluder of the scan (one tree query), with
w = N_hat / J_u,k and P_p = sigma_u^2 I, so the birth mass is exactly N_hat.
"""

from __future__ import annotations

import dataclasses
from collections import OrderedDict
from typing import NamedTuple

import numpy as np

from soabench.birth.base import FOVRule, build_components
from soabench.config import BirthConfig, SensorConfig
from soabench.scenario.scene import SceneMap
from soabench.types import SOURCE_GRID, BirthContext, Births


def grid_nodes(bounds: tuple[float, float, float, float], d_u: float) -> np.ndarray:
    """(n_x n_y, 2) cell centres of a d_u grid over the box ``(x_min, y_min, x_max, y_max)`` (§3.3)."""
    x0, y0, x1, y1 = bounds
    nx, ny = int(np.floor((x1 - x0) / d_u + 1e-9)), int(np.floor((y1 - y0) / d_u + 1e-9))
    X, Y = np.meshgrid(x0 + (np.arange(nx) + 0.5) * d_u, y0 + (np.arange(ny) + 0.5) * d_u, indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel()])


#: per process: (scene, its static geometry, d_u, sigma_u, sigma_v_birth) -> (scene, nodes, m_all, P_all)
_GRIDS: OrderedDict[tuple, tuple] = OrderedDict()
_N_GRIDS = 8


def _grid(scene: SceneMap, rule: FOVRule, cfg: BirthConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grid nodes in the workspace and not inside a building or static occluder (the time-invariant part of the
    FOV-only rule), with their birth components: the same for every trial of a scene, so a worker builds them once
    (they are read-only; each scan selects copies). The key holds the scene object (so its id stays unique while
    cached), the identity of every static polygon and the settings the grid reads."""
    key = (
        id(scene),
        tuple(float(b) for b in scene.bounds),
        tuple(map(id, scene.buildings)),
        tuple(map(id, scene.static_occluders)),
        float(cfg.d_u),
        float(cfg.sigma_u),
        float(cfg.sigma_v_birth),
    )
    hit = _GRIDS.get(key)
    if hit is None:
        nodes = grid_nodes(scene.bounds, cfg.d_u)
        nodes = nodes[rule.static_mask(nodes)]  # in the workspace, not inside a building
        m_all, P_all = build_components(nodes, cfg.sigma_u**2 * np.eye(2), cfg.sigma_v_birth)
        for a in (nodes, m_all, P_all):
            a.setflags(write=False)
        hit = _GRIDS[key] = (scene, nodes, m_all, P_all)
        while len(_GRIDS) > _N_GRIDS:
            _GRIDS.popitem(last=False)
    _GRIDS.move_to_end(key)
    return hit[1], hit[2], hit[3]


class UniformBirth:
    """UBM (§3.3). ``UniformBirth(cfg, sensor, scene, rng)(ctx) -> Births``; ``rng`` is unused (deterministic)."""

    name = "ubm"
    #: births read only the scan (not ``ctx.prev`` nor ``ctx.p_D_b``): one call per scan serves every probability mode
    mode_free = True

    def __init__(self, cfg: BirthConfig, sensor: SensorConfig, scene: SceneMap, rng: np.random.Generator) -> None:
        cfg.validate()
        self.cfg, self.sensor = cfg, sensor
        self.rule = FOVRule(cfg, sensor, scene)
        # the grid and its components, built once per scene and setting in a process, selected per scan
        self.nodes, self.m_all, self.P_all = _grid(scene, self.rule, cfg)

    def __call__(self, ctx: BirthContext) -> Births:
        """Grid nodes passing the FOV-only rule (``ubm_extent = fov``; ``workspace`` skips the FOV test)."""
        return self.weigh(self.cfg, self.candidates(ctx))

    def candidates(self, ctx: BirthContext) -> GridCandidates:
        """The grid components that pass the FOV-only rule at k, before their weights. They read only the scan's
        pose and occluders, so one set serves every probability mode, clutter rate and N_hat of a trial."""
        scan = ctx.scan
        if self.cfg.ubm_extent == "fov":
            ok = self.rule.in_fov(self.nodes, scan)
        else:
            ok = np.ones(len(self.nodes), dtype=bool)
        idx = np.flatnonzero(ok)
        idx = idx[~self.rule.in_occluder(self.nodes[idx], scan)]
        return GridCandidates(self.m_all[idx], self.P_all[idx])

    @staticmethod
    def weigh(cfg: BirthConfig, c: GridCandidates) -> Births:
        """Equal weights w = N_hat / J_u,k (§3.3)."""
        J = len(c.m)
        if J == 0:
            return Births.empty()
        w = np.full(J, cfg.N_hat / J)
        return Births(w, c.m, c.P, np.full(J, SOURCE_GRID, dtype=np.int8))


class GridCandidates(NamedTuple):
    """The grid's birth components of one scan before weighting (:meth:`UniformBirth.candidates`)."""

    m: np.ndarray  #: (J, 4) means
    P: np.ndarray  #: (J, 4, 4) covariances


class WorkspaceUniformBirth(UniformBirth):
    """The paper's UBM (§3.3, register row 16): the same grid spread uniformly across the whole workspace, every scan,
    not clipped to the field of view (``ubm_extent = "workspace"`` whatever the config says). ``ubm`` is the
    field-of-view variant, a stronger baseline; the headline table reports both (docs/method.md §3.3)."""

    name = "ubm-ws"

    def __init__(self, cfg: BirthConfig, sensor: SensorConfig, scene: SceneMap, rng: np.random.Generator) -> None:
        super().__init__(dataclasses.replace(cfg, ubm_extent="workspace"), sensor, scene, rng)
