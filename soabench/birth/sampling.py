"""Placement of semantic birth means in a region Omega (docs/method.md §3.1.4, paper eq. 14).

Four placements, each a pure function of the region (shapely geometry) and, where random, a
``numpy.random.Generator`` (the trial's placement stream, §2.12 item 11):

* :func:`poisson_disk`: Bridson's sampler (Bridson 2007), all pairwise distances >= d_min (eq. 14), seeded again in
  every disconnected piece;
* :func:`hex_lattice`: the deterministic alternative, a hexagonal lattice of pitch d_min clipped to Omega;
* :func:`uniform_points`: i.i.d. uniform points by rejection sampling;
* :func:`dbscan_clusters`: DBSCAN over a regular grid of candidate points, one mean per cluster (optionally split
  with k-means), with the cluster dispersion as variance.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from soabench.errors import require
from soabench.notice import announced, ready


def uniform_points(region: BaseGeometry, n: int, rng: np.random.Generator, batch: int | None = None) -> np.ndarray:
    """``n`` i.i.d. uniform points in ``region`` by rejection from its bounding box; (n, 2).

    Batches are sized from the region's fill ratio; an empty region gives (0, 2), a degenerate one maybe fewer.
    """
    if n <= 0 or region.is_empty or region.area <= 0.0:
        return np.zeros((0, 2))
    x0, y0, x1, y1 = region.bounds
    fill = region.area / max((x1 - x0) * (y1 - y0), 1e-300)
    shapely.prepare(region)
    out: list[np.ndarray] = []
    got = 0
    for _ in range(100):  # bounded: a region of (numerically) zero fill returns what it found
        if got >= n:
            break
        size = batch or int(min(1_000_000, max(64, 1.3 * (n - got) / fill)))
        cand = np.column_stack([rng.uniform(x0, x1, size), rng.uniform(y0, y1, size)])
        cand = cand[shapely.contains_xy(region, cand[:, 0], cand[:, 1])]
        out.append(cand)
        got += len(cand)
    return np.concatenate(out)[:n] if out else np.zeros((0, 2))


def poisson_disk(region: BaseGeometry, d_min: float, rng: np.random.Generator, k: int = 30) -> np.ndarray:
    """Poisson-disk sample of ``region`` with minimum distance ``d_min`` (eq. 14), Bridson's algorithm; (J, 2).

    * Background grid of cell d_min/sqrt(2): at most one sample per cell, neighbours within 2 cells (a point's
      d_min-disk spans at most 5 x 5 cells); its look-ups and the acceptance are compiled
      (:mod:`soabench.geometry_kernels`), the random draws and the test "in Omega" are numpy's and GEOS's.
    * Each active point draws ``k`` candidates uniformly in the annulus [d_min, 2 d_min]; the first candidate in
      Omega with no sample within d_min is accepted, else the point retires.
    * Omega may be disconnected (§3.1.4): when the active list empties, ``n_seed = 30 area / d_min^2`` uniform
      points of Omega are tried in order as new seeds, and the active process restarts from each accepted one.

    Every pair of returned points is at least ``d_min`` apart and every point is in Omega.
    """
    require(d_min > 0, f"d_min = {d_min!r} must be > 0")
    if region.is_empty or region.area <= 0.0:
        return np.zeros((0, 2))
    # imported when called: numba would slow every start-up
    from soabench.geometry_kernels import poisson_accept, poisson_first_free

    if not ready("geometry.poisson"):  # the kernels' first call in a process may compile them
        announced("geometry.poisson", _warm_poisson, poisson_accept, poisson_first_free)

    shapely.prepare(region)
    x0, y0, x1, y1 = region.bounds
    cell = d_min / math.sqrt(2.0)
    nx, ny = int((x1 - x0) / cell) + 1, int((y1 - y0) / cell) + 1
    # padded grid: index [i + 2, j + 2] so that neighbour look-ups never leave the array; at most one sample a cell
    grid = np.full((nx + 4, ny + 4), -1, dtype=np.int64)
    P = np.empty(((nx + 4) * (ny + 4), 2))
    n = 0
    d2 = d_min * d_min
    geo = (x0, y0, cell)

    def grow(n: int, sx: float, sy: float) -> int:
        active = [n]
        n = poisson_accept(P, n, grid, *geo, sx, sy)
        while active:
            a = active[int(rng.integers(len(active)))]
            rad = np.sqrt(rng.uniform(d2, 4.0 * d2, k))  # uniform in the annulus area
            ang = rng.uniform(0.0, 2.0 * np.pi, k)
            cx = P[a, 0] + rad * np.cos(ang)
            cy = P[a, 1] + rad * np.sin(ang)
            inside = shapely.contains_xy(region, cx, cy)  # in Omega (so inside its bounds and the grid)
            i = poisson_first_free(P, grid, *geo, d2, cx, cy, inside, 0)  # the first free candidate, if any
            if i >= 0:
                active.append(n)
                n = poisson_accept(P, n, grid, *geo, cx[i], cy[i])
            else:
                active.remove(a)
        return n

    n_seed = max(1, int(math.ceil(30.0 * region.area / d2)))
    seeds = uniform_points(region, n_seed, rng)
    sx, sy = seeds[:, 0].copy(), seeds[:, 1].copy()
    every = np.ones(len(seeds), dtype=bool)
    pos = 0
    while pos < len(seeds):  # a seed that is not free stays not free: each is checked once, in order
        i = poisson_first_free(P, grid, *geo, d2, sx, sy, every, pos)
        if i < 0:
            break
        n = grow(n, sx[i], sy[i])
        pos = i + 1
    return P[:n].copy()


def _warm_poisson(accept: Callable[..., int], first_free: Callable[..., int]) -> None:
    """Call the sampler's two kernels once on a one-cell grid (compiles or loads them)."""
    P, grid = np.zeros((1, 2)), np.full((5, 5), -1, dtype=np.int64)
    accept(P, 0, grid, 0.0, 0.0, 1.0, 0.5, 0.5)
    first_free(P, grid, 0.0, 0.0, 1.0, 1.0, np.array([0.5]), np.array([0.5]), np.ones(1, dtype=bool), 0)


def hex_lattice(region: BaseGeometry, pitch: float) -> np.ndarray:
    """Hexagonal lattice of ``pitch`` anchored at the region's lower-left bound, clipped to Omega; (J, 2).

    Rows are ``pitch * sqrt(3)/2`` apart and odd rows shift by ``pitch/2``: nearest neighbours are exactly ``pitch``
    apart, so eq. 14 holds with d_min = pitch.
    """
    require(pitch > 0, f"pitch = {pitch!r} must be > 0")
    if region.is_empty:
        return np.zeros((0, 2))
    x0, y0, x1, y1 = region.bounds
    dy = pitch * math.sqrt(3.0) / 2.0
    rows = np.arange(int((y1 - y0) / dy) + 1)
    cols = np.arange(int((x1 - x0) / pitch) + 2)
    X = x0 + cols[None, :] * pitch + 0.5 * pitch * (rows[:, None] % 2)
    Y = np.broadcast_to(y0 + rows[:, None] * dy, X.shape)
    xy = np.column_stack([X.ravel(), Y.ravel()])
    return xy[shapely.contains_xy(region, xy[:, 0], xy[:, 1])]


def grid_points(region: BaseGeometry, step: float) -> np.ndarray:
    """Regular square grid of ``step`` (cell centres) over the region's bounds, clipped to Omega; (n, 2)."""
    if region.is_empty:
        return np.zeros((0, 2))
    x0, y0, x1, y1 = region.bounds
    xs = np.arange(x0 + 0.5 * step, x1, step)
    ys = np.arange(y0 + 0.5 * step, y1, step)
    X, Y = np.meshgrid(xs, ys)
    xy = np.column_stack([X.ravel(), Y.ravel()])
    return xy[shapely.contains_xy(region, xy[:, 0], xy[:, 1])]


def dbscan_labels(points: np.ndarray, eps: float, min_samples: int) -> np.ndarray:
    """DBSCAN (Ester et al. 1996) cluster labels of ``points`` (n, 2); -1 marks noise.

    A core point has at least ``min_samples`` points (itself included) within ``eps``; clusters are the connected
    components of core points linked within ``eps``; a border point joins the cluster of its nearest core
    neighbour. Built on scipy's k-d tree and graph components, so the mode needs no extra dependency.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = len(points)
    tree = cKDTree(points)
    pairs = tree.query_pairs(eps, output_type="ndarray")
    core = np.bincount(pairs.ravel(), minlength=n) + 1 >= min_samples
    cc = pairs[core[pairs[:, 0]] & core[pairs[:, 1]]]
    graph = coo_matrix((np.ones(len(cc)), (cc[:, 0], cc[:, 1])), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    labels = np.full(n, -1)
    core_ids = np.flatnonzero(core)
    _, labels[core_ids] = np.unique(comp[core_ids], return_inverse=True)  # clusters numbered 0..C-1
    border = np.flatnonzero(~core)
    if len(border) and len(core_ids):
        d, j = cKDTree(points[core_ids]).query(points[border], distance_upper_bound=eps * (1 + 1e-12))
        ok = np.isfinite(d)
        labels[border[ok]] = labels[core_ids[j[ok]]]
    return labels


def dbscan_clusters(
    points: np.ndarray,
    eps: float,
    min_samples: int,
    cell_area: float,
    split_d_min: float | None = None,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """DBSCAN placement (§3.1.4 ``dbscan``): one mean per cluster and its dispersion.

    Args:
        points: (n, 2) candidate points in Omega_k (a regular grid in simulation).
        eps, min_samples: DBSCAN parameters.
        cell_area: area represented by one candidate point (step^2), for the k-means split.
        split_d_min: if given, split each cluster with k-means into ceil(area_c / d_min^2) parts.
        seed: k-means seed (per trial and step).

    Returns:
        ``(mu, sigma2)``: (C, 2) cluster means and (C,) variances, the largest eigenvalue of each cluster's
        covariance ("adaptively scaled by cluster dispersion"), floored at cell_area / 12 for one-point clusters.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    from scipy.cluster.vq import kmeans2

    labels = dbscan_labels(points, eps, min_samples)
    groups = [points[labels == c] for c in range(labels.max() + 1)]
    if split_d_min is not None:
        parts: list[np.ndarray] = []
        for g in groups:
            n_parts = min(len(g), int(math.ceil(len(g) * cell_area / split_d_min**2)))
            if n_parts <= 1:
                parts.append(g)
                continue
            _, sub = kmeans2(g, n_parts, minit="++", rng=np.random.default_rng(seed))
            parts.extend(g[sub == c] for c in range(n_parts) if np.any(sub == c))
        groups = parts
    if not groups:
        return np.zeros((0, 2)), np.zeros(0)
    mu = np.array([g.mean(axis=0) for g in groups])
    floor = cell_area / 12.0
    sigma2 = np.array([max(np.linalg.eigvalsh(np.cov(g.T)).max() if len(g) > 1 else 0.0, floor) for g in groups])
    return mu, sigma2
