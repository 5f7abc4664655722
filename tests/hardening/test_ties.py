"""Decisions that rounding would make, settled by the tie rules (docs/method.md §2.3, §2.9, §4.4; register rows 34
and 35): a perturbation of the inputs at the 1e-12 scale never flips a merge or a line-of-sight decision, and every
merge kernel (window, grid, tree) gives the literal loop's groups on layouts full of exact ties.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from gmphd_cases import reference_merge_groups

from soabench.birth.soa import occlusion_layers
from soabench.config import BirthConfig, FilterConfig, Sensor
from soabench.gmphd import cycle, kernels
from soabench.gmphd.filter import GMPHDFilter, _mixture_arrays
from soabench.gmphd.mixture import Mixture
from soabench.gmphd.reduction import merge, merge_groups
from soabench.sensor import SIGHT_TOL, compute_obstacles, line_of_sight, line_of_sight_past, sight_blockers

EPS = 1e-12  #: the perturbation scale (m)

# ---------------------------------------------------------------------------------------------------------------------
# merging at the threshold (register row 35)


def _pair(d2: float, jitter: np.ndarray | None = None) -> Mixture:
    m = np.array([[0.0, 0, 0, 0], [math.sqrt(d2), 0, 0, 0]])
    if jitter is not None:
        m = m + jitter
    return Mixture.from_arrays([1.0, 0.5], m, [np.eye(4), np.eye(4)])


def test_t9_exact_threshold_merges_and_above_it_does_not():
    assert len(merge(_pair(4.0), 4.0)) == 1
    assert len(merge(_pair(4.0001), 4.0)) == 2
    assert len(merge(_pair(4.0 * (1.0 + 1e-7)), 4.0)) == 2  # the margin is far below any deliberate distance


def test_a_pair_at_the_threshold_merges_under_any_1e12_perturbation():
    rng = np.random.default_rng(35)
    for _ in range(200):
        assert len(merge(_pair(4.0, rng.uniform(-EPS, EPS, (2, 4))), 4.0)) == 1


def test_the_compiled_cycle_reduces_with_the_same_tie_rule():
    """The filter's compiled reduction (one call per scan) merges a pair at the threshold under any 1e-12
    perturbation, as :func:`merge` does: the cycle calls the merge kernel with the tie rule, not a copy compiled
    before it."""
    red = GMPHDFilter(FilterConfig(), Sensor(), "static")._red_pars
    rng = np.random.default_rng(350)
    for d2 in (4.0, 4.0 * (1.0 + 1e-12), 4.0 * (1.0 - 1e-12)):
        for _ in range(20):
            mix = _pair(d2, rng.uniform(-EPS, EPS, (2, 4)))
            out = cycle.reduce(*_mixture_arrays(mix), red, 1)
            assert out[5][2] == 1 and len(out[0][0]) == len(merge(mix, 4.0)) == 1  # n_merged
    assert len(cycle.reduce(*_mixture_arrays(_pair(4.0001)), red, 1)[0][0]) == 2


def ubm_grid(x0: float, y0: float, n: int, d_u: float = 5.0, sigma_u: float = 2.5) -> tuple[np.ndarray, ...]:
    """An n x n UBM grid (§3.3) whose neighbours sit at squared Mahalanobis distance (d_u / sigma_u)^2 = 4 = U,
    up to the rounding of the node coordinates (x0 + (i + 1/2) d_u)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    xy = np.column_stack([x0 + (i.ravel() + 0.5) * d_u, y0 + (j.ravel() + 0.5) * d_u])
    m = np.column_stack([xy, np.zeros((n * n, 2))])
    P = np.tile(np.diag([sigma_u**2, sigma_u**2, 1.0, 1.0]), (n * n, 1, 1))
    return m, P


@pytest.mark.parametrize("n", [6, 14])  # 36 components: the window; 196: the grid
def test_ubm_grid_neighbours_merge_whatever_the_last_bit(n):
    rng = np.random.default_rng(n)
    m, P = ubm_grid(-87.3, 13.1, n)
    w = rng.uniform(0.1, 1.0, len(m))
    base, centres = merge_groups(m, P, w, 4.0)
    np.testing.assert_array_equal(base, reference_merge_groups(m, P, w, 4.0))
    assert len(centres) < len(m) // 2  # the grid's neighbours did merge (a pass takes j* and up to 4 neighbours)
    order = np.argsort(-w, kind="stable")
    exact = 4.0 / (1.0 + 1e-9)  # the reference loop with the bare test d^2 <= 4: rounding decides
    flips = 0
    for _ in range(20):
        mj = m + np.column_stack([rng.uniform(-EPS, EPS, (len(m), 2)), np.zeros((len(m), 2))])
        label, _ = merge_groups(mj, P, w, 4.0)
        np.testing.assert_array_equal(label, base)
        np.testing.assert_array_equal(label, reference_merge_groups(mj, P, w, 4.0))
        for kernel in (kernels.merge_groups_window, kernels.merge_groups_grid, kernels.merge_groups_tree):
            np.testing.assert_array_equal(kernel(mj, P, order, 4.0)[0], base)
        flips += not np.array_equal(reference_merge_groups(mj, P, w, exact), base)
    assert flips > 0  # without the margin the same perturbations do change the groups


def test_soa_layers_two_apart_merge():
    """S-OA's layers l and l + 2 on one ray (delta_r = 2 m, sigma_par = 2 m) sit at d^2 = U: they merge."""
    cfg = BirthConfig()
    obs = compute_obstacles([np.array([[9.0, -1], [11, -1], [11, 1], [9, 1]])], ["parked"], np.zeros(2), 50.0)
    p, P_p, _, _ = occlusion_layers(obs, np.zeros(3), cfg)
    ray = slice(0, cfg.L)  # the layers of the theta_min ray
    m = np.column_stack([p[ray], np.zeros((cfg.L, 2))])
    P = np.zeros((cfg.L, 4, 4))
    P[:, :2, :2] = P_p[ray]
    P[:, 2:, 2:] = np.eye(2)
    d = m[2] - m[0]
    assert d @ np.linalg.solve(P[2], d) == pytest.approx(4.0, rel=1e-12)
    w = np.array([0.5, 0.1, 0.3])  # the first layer is heaviest: it absorbs the third (and the second)
    label, _ = merge_groups(m, P, w, 4.0)
    assert label[2] == label[0]


# ---------------------------------------------------------------------------------------------------------------------
# line of sight at a touch (register row 34)

BOX = np.array([[9.0, -1], [11, -1], [11, 1], [9, 1]])  # T13's box


def _visible(ego, pts, polys=(BOX,)):
    occ = [shapely.Polygon(p) for p in polys]
    return line_of_sight(np.asarray(ego, dtype=float), np.asarray(pts, dtype=float), occ)


def test_grazing_a_vertex_or_running_along_an_edge_is_visible():
    # beyond the tangent vertex (9, 1) on the ray from the origin, and along the top edge from (0, 1)
    assert _visible([0.0, 0.0], [[13.5, 1.5]]).all()
    assert _visible([0.0, 1.0], [[12.0, 1.0], [10.0, 1.0]]).all()
    # through the middle: blocked; just past the corner by 1e-6 m: blocked (the tolerance is 1e-9 m)
    assert not _visible([0.0, 0.0], [[12.0, 0.0]]).any()
    assert SIGHT_TOL == 1e-9
    dip = 1e-6 * math.hypot(9.0, 1.0) / 9.0  # the line through (13.5, 1.5 - dip) passes 1e-6 m inside the corner
    assert not _visible([0.0, 0.0], [[13.5, 1.5 - 1.5 * dip]]).any()


def test_a_1e12_perturbation_never_flips_a_touch():
    rng = np.random.default_rng(34)
    for _ in range(100):
        ego = rng.uniform(-EPS, EPS, 2)
        along = np.array([13.5, 1.5]) + rng.uniform(-EPS, EPS, 2)
        edge = np.array([[12.0, 1.0], [10.0, 1.0]]) + rng.uniform(-EPS, EPS, (2, 2))
        assert _visible(ego, [along]).all()
        assert _visible(ego + [0.0, 1.0], edge).all()
        assert not _visible(ego, [[12.0, 0.0]]).any()


def test_soa_births_on_tangent_rays_are_visible_from_the_sensor():
    """Every occlusion birth of random boxes lies on a tangent ray, behind the tangent vertex: its sight line grazes
    that vertex, so it is visible (without other occluders), also after a 1e-12 perturbation of the birth."""
    rng = np.random.default_rng(7)
    cfg = BirthConfig()
    n_births = 0
    for _ in range(30):
        c = rng.uniform(-30.0, 30.0, 2)
        if np.hypot(*c) < 8.0:
            continue
        a = rng.uniform(0.0, np.pi)
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        box = c + np.array([[-2.3, -1.0], [2.3, -1.0], [2.3, 1.0], [-2.3, 1.0]]) @ R.T
        ego = np.array([*rng.uniform(-1.0, 1.0, 2), 0.0])
        obs = compute_obstacles([box], ["vehicle"], ego[:2], 50.0)
        p = occlusion_layers(obs, ego, cfg)[0]
        n_births += len(p)
        blockers = sight_blockers(ego[:2], [shapely.Polygon(box)])
        assert line_of_sight_past(ego[:2], p, blockers).all()
        assert line_of_sight_past(ego[:2], p + rng.uniform(-EPS, EPS, p.shape), blockers).all()
    assert n_births > 100


def test_decisions_of_random_scenes_are_stable_under_1e12_perturbations():
    """Random targets among random (also non-convex) occluders: the same decisions after a 1e-12 jitter, and the
    blockers of a pose tested twice give the same answers as a fresh test (the cores are built once and reused)."""
    rng = np.random.default_rng(12)
    ell = np.array([[0.0, 0], [8, 0], [8, 3], [3, 3], [3, 9], [0, 9]])  # an L-shaped building
    polys = [ell + rng.uniform(-40, 40, 2) for _ in range(4)] + [BOX + rng.uniform(-30, 30, 2) for _ in range(10)]
    occ = [shapely.Polygon(p) for p in polys]
    ego = np.array([0.5, -0.25])
    pts = rng.uniform(-50, 50, (2000, 2))
    base = line_of_sight(ego, pts, occ)
    assert 0.05 < 1.0 - base.mean() < 0.95  # a scene that blocks some sight lines and not others
    blockers = sight_blockers(ego, occ)
    for _ in range(3):
        jit = pts + rng.uniform(-EPS, EPS, pts.shape)
        np.testing.assert_array_equal(line_of_sight_past(ego, jit, blockers), base)
        np.testing.assert_array_equal(line_of_sight(ego, jit, occ), base)
