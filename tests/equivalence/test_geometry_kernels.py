"""The compiled scan-geometry loops (soabench.geometry_kernels) give bit for bit what the numpy form of the same
formula gives: the numpy forms they replaced are kept here as the references."""

from __future__ import annotations

import numpy as np
import pytest

from soabench.birth.soa import dedup
from soabench.sensor import _padded, segment_meets_convex


def _dedup_numpy(xy: np.ndarray, d_dup: float) -> np.ndarray:
    """The numpy form S-OA used before (greedy in order over the upper triangle of close pairs)."""
    keep = np.ones(len(xy), dtype=bool)
    if len(xy) < 2:
        return keep
    d2 = np.sum((xy[:, None, :] - xy[None, :, :]) ** 2, axis=-1)
    close = np.triu(d2 < d_dup * d_dup, k=1)
    for i in np.flatnonzero(close.any(axis=1)):
        if keep[i]:
            keep[close[i]] = False
    return keep


def _segments_numpy(ego_xy: np.ndarray, points: np.ndarray, polygons: list[np.ndarray]) -> np.ndarray:
    """Cyrus-Beck over all (point, polygon, edge) at once with numpy (polygons padded by their first vertex)."""
    e = np.asarray(ego_xy, dtype=float)[:2]
    v = _padded(polygons) - e
    edge = np.roll(v, -1, axis=1) - v
    nx, ny = edge[..., 1], -edge[..., 0]
    num = nx * v[..., 0] + ny * v[..., 1]
    d = points - e
    den = d[:, 0, None, None] * nx + d[:, 1, None, None] * ny
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / den
    t_in = np.where(den < 0.0, t, 0.0).max(axis=2, initial=0.0)
    t_out = np.where(den > 0.0, t, 1.0).min(axis=2, initial=1.0)
    parallel_out = ((den == 0.0) & (num < 0.0)).any(axis=2)
    return ((t_in <= t_out) & ~parallel_out).any(axis=1)


@pytest.mark.parametrize("seed", range(4))
def test_dedup_equals_the_numpy_form(seed):
    rng = np.random.default_rng(seed)
    for trial in range(150):
        xy = rng.uniform(0.0, 6.0, (int(rng.integers(0, 80)), 2))
        if trial % 3 == 0:
            xy = np.round(xy, 1)  # exact ties at the threshold and duplicates
        d = float(rng.choice([0.1, 0.5, 1.0]))
        assert np.array_equal(dedup(xy, d), _dedup_numpy(xy, d))


def test_segments_equal_the_numpy_form_on_obstacle_hulls():
    import shapely

    rng = np.random.default_rng(11)
    checked = 0
    for _ in range(150):
        n_obs = int(rng.integers(1, 12))
        hulls = shapely.orient_polygons(
            shapely.convex_hull(
                shapely.multipoints(rng.uniform(-2.0, 2.0, (n_obs, 6, 2)) + rng.uniform(-30, 30, (n_obs, 1, 2)))
            )
        )
        hulls = hulls[shapely.area(hulls) > 1e-6]
        polys = [shapely.get_coordinates(h)[:-1] for h in hulls]
        ego = rng.uniform(-5.0, 5.0, 2)
        polys = [p for p, h in zip(polys, hulls, strict=True) if not h.intersects(shapely.points(ego))]
        if not polys:
            continue
        pts = np.concatenate([rng.uniform(-40, 40, (200, 2)), np.concatenate(polys), ego[None, :]])
        got = segment_meets_convex(ego, pts, polys)
        assert np.array_equal(got, _segments_numpy(ego, pts, polys))
        checked += len(pts)
    assert checked > 25000


def _ego_inside_numpy(polygons: list[np.ndarray], e: np.ndarray) -> np.ndarray:
    """The numpy form of soabench.birth.soa.ego_inside: the reference of the compiled kernel."""
    n = np.array([len(v) for v in polygons])
    V = np.concatenate([np.asarray(v, dtype=float).reshape(-1, 2) for v in polygons])
    start = np.concatenate([[0], np.cumsum(n)[:-1]])
    nxt = np.arange(len(V)) + 1
    nxt[np.cumsum(n) - 1] = start
    edge = V[nxt] - V
    to_e = np.asarray(e, dtype=float)[:2] - V
    cross = edge[:, 0] * to_e[:, 1] - edge[:, 1] * to_e[:, 0]
    tol = 1e-12 * max(1.0, float(np.abs(V).max()))
    return (np.minimum.reduceat(cross, start) >= -tol) | (np.maximum.reduceat(cross, start) <= tol)


def _layers_numpy(obstacles, ego, cfg):
    """The numpy form of soabench.birth.soa.occlusion_layers before its arithmetic was compiled."""
    from soabench.birth.soa import OCCL_SPEED

    e = np.asarray(ego, dtype=float)
    keep = ~_ego_inside_numpy(obstacles.polygons, e)
    theta = np.column_stack([obstacles.theta_min, obstacles.theta_max])[keep]
    if cfg.ray_start == "centroid":
        rb = np.repeat(np.asarray(obstacles.centroid_range, dtype=float)[keep, None], 2, axis=1)
    else:
        rb = np.column_stack([obstacles.r_min, obstacles.r_max])[keep]
    layers = cfg.delta_r * np.arange(1, cfg.L + 1)
    r = rb[:, :, None] + layers[None, None, :]
    u = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    u_perp = np.stack([-u[..., 1], u[..., 0]], axis=-1)
    p = e[:2] + r[..., None] * u[:, :, None, :]
    uu = u[..., :, None] * u[..., None, :]
    vv = u_perp[..., :, None] * u_perp[..., None, :]
    P2 = cfg.sigma_par**2 * uu + cfg.sigma_perp**2 * vv
    P_p = np.broadcast_to(P2[:, :, None], (*r.shape, 2, 2))
    v = np.zeros_like(p)
    if cfg.occl_velocity_prior:
        side = np.array([-1.0, 1.0])[None, :, None]
        v = np.broadcast_to((OCCL_SPEED * side)[..., None] * u_perp[:, :, None, :], p.shape)
    return p.reshape(-1, 2), P_p.reshape(-1, 2, 2), np.asarray(v).reshape(-1, 2), r.reshape(-1)


@pytest.mark.parametrize("ray_start", ["tangent", "centroid"])
@pytest.mark.parametrize("prior", [False, True])
def test_occlusion_layers_equal_the_numpy_form(ray_start, prior):
    import dataclasses

    import shapely

    from soabench.birth.soa import ego_inside, occlusion_layers
    from soabench.config import BirthConfig
    from soabench.sensor import compute_obstacles

    cfg = dataclasses.replace(BirthConfig(), ray_start=ray_start, occl_velocity_prior=prior, sigma_par=1.3)
    rng = np.random.default_rng(21)
    checked = 0
    for _ in range(120):
        n_obs = int(rng.integers(1, 10))
        pts = rng.uniform(-2.0, 2.0, (n_obs, 6, 2)) + rng.uniform(-40, 40, (n_obs, 1, 2))
        polys = [shapely.get_coordinates(h)[:-1] for h in shapely.convex_hull(shapely.multipoints(pts))]
        polys = [q for q in polys if len(q) >= 3]
        if not polys:
            continue
        ego = np.r_[rng.uniform(-5.0, 5.0, 2), rng.uniform(-np.pi, np.pi)]
        assert np.array_equal(ego_inside(polys, ego), _ego_inside_numpy(polys, ego))
        obs = compute_obstacles(polys, ["parked"] * len(polys), ego[:2], 60.0)
        if len(obs) == 0:
            continue
        got, ref = occlusion_layers(obs, ego, cfg), _layers_numpy(obs, ego, cfg)
        for a, b in zip(got, ref, strict=True):
            assert a.shape == b.shape and np.array_equal(a, b)
        checked += len(got[0])
    assert checked > 1000
    square = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    on_edge = np.array([1.0, 0.0, 0.0])
    assert ego_inside([square, square[::-1], square + 5.0], on_edge).tolist() == [True, True, False]
