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
