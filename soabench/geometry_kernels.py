"""Compiled loops of the per-scan geometry (docs/method.md §3.1.3-3.1.4, §5.8).

A scan's birth geometry asks small questions of a few dozen points (is a point behind an obstacle, is a candidate
too close to one kept before), once per scan. Written with numpy they are a dozen array calls each, and at these
sizes numpy's fixed cost per call, not arithmetic, sets the time (measured in ``benchmarks/README.md``). The loops
here do the same arithmetic once per (point, edge) or per pair: only additions, subtractions, multiplications,
divisions and comparisons, in IEEE double precision without ``fastmath``, so a result is the same bit for bit as
the numpy form of the same formula and does not depend on the CPU. Compiled code is cached like the filter
kernels (:mod:`soabench.cache`).
"""

from __future__ import annotations

import math

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()  # before numba is imported: compiled kernels go to the per-user cache, not site-packages

from numba import njit  # noqa: E402


def flat_polygons(polygons) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The (n_i, 2) vertex arrays of ``polygons`` as the kernels take them: x and y of every vertex one polygon after
    another, and each polygon's start and vertex count."""
    counts = np.fromiter((len(p) for p in polygons), dtype=np.int64, count=len(polygons))
    starts = np.zeros_like(counts)
    np.cumsum(counts[:-1], out=starts[1:])
    v = np.concatenate([np.asarray(p, dtype=float).reshape(-1, 2) for p in polygons])
    return v[:, 0].copy(), v[:, 1].copy(), starts, counts


@njit(cache=True)
def segments_meet_convex(ex, ey, px, py, vx, vy, starts, counts):  # pragma: no cover - compiled
    """(n,) True where the closed segment from the sensor (ex, ey) to point i meets any closed convex polygon.

    Polygon j has the counter-clockwise vertices ``vx/vy[starts[j] : starts[j] + counts[j]]``. Cyrus-Beck clipping:
    with the outward normal n of an edge from v to its successor, the segment e + t d (0 <= t <= 1) stays in the
    edge's half-plane for t (d.n) <= (v - e).n; it meets the polygon where the largest entering t is at most the
    smallest leaving t, and misses it where it runs parallel outside an edge. Coordinates are taken relative to
    the sensor first, as in :func:`soabench.sensor.segment_meets_convex`.
    """
    n = px.shape[0]
    out = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        dx = px[i] - ex
        dy = py[i] - ey
        for j in range(starts.shape[0]):
            s, c = starts[j], counts[j]
            t_in, t_out = 0.0, 1.0
            miss = False
            for a in range(c):
                b = a + 1 if a + 1 < c else 0
                ax, ay = vx[s + a] - ex, vy[s + a] - ey
                bx, by = vx[s + b] - ex, vy[s + b] - ey
                nx, ny = by - ay, -(bx - ax)
                num = nx * ax + ny * ay
                den = dx * nx + dy * ny
                if den < 0.0:
                    t = num / den
                    if t > t_in:
                        t_in = t
                elif den > 0.0:
                    t = num / den
                    if t < t_out:
                        t_out = t
                elif den == 0.0 and num < 0.0:
                    miss = True
                    break
            if not miss and t_in <= t_out:
                out[i] = True
                break
    return out


@njit(cache=True)
def greedy_dedup(x, y, d_dup):  # pragma: no cover - compiled
    """(J,) keep-mask of :func:`soabench.birth.soa.dedup`: in order, a point closer than ``d_dup`` to a point kept
    before it is dropped (squared distances dx^2 + dy^2 against d_dup^2, as the numpy form)."""
    J = x.shape[0]
    keep = np.ones(J, dtype=np.bool_)
    dd = d_dup * d_dup
    for i in range(J):
        if not keep[i]:
            continue
        for j in range(i + 1, J):
            if keep[j]:
                dx = x[i] - x[j]
                dy = y[i] - y[j]
                if dx * dx + dy * dy < dd:
                    keep[j] = False
    return keep


# ---------------------------------------------------------------------------------------------------------------------
# Bridson's Poisson-disk sampler (soabench.birth.sampling.poisson_disk): the background grid's look-ups and the
# acceptance, with the random draws and the region test left to the caller (numpy's generator, GEOS)


@njit(cache=True)
def _is_free(P, grid, x0, y0, cell, d2, qx, qy):  # pragma: no cover - compiled
    """No accepted sample within d_min of (qx, qy): the 5 x 5 cells around its cell of the padded grid."""
    ci = np.int64(math.floor((qx - x0) / cell)) + 2
    cj = np.int64(math.floor((qy - y0) / cell)) + 2
    for di in range(-2, 3):
        for dj in range(-2, 3):
            j = grid[ci + di, cj + dj]
            if j >= 0:
                dx = P[j, 0] - qx
                dy = P[j, 1] - qy
                if dx * dx + dy * dy < d2:
                    return False
    return True


@njit(cache=True)
def poisson_accept(P, n, grid, x0, y0, cell, qx, qy):  # pragma: no cover - compiled
    """Store (qx, qy) as sample n and mark its grid cell; returns n + 1."""
    ci = np.int64(math.floor((qx - x0) / cell)) + 2
    cj = np.int64(math.floor((qy - y0) / cell)) + 2
    grid[ci, cj] = n
    P[n, 0] = qx
    P[n, 1] = qy
    return n + 1


@njit(cache=True)
def poisson_first_free(P, grid, x0, y0, cell, d2, qx, qy, ok, start):  # pragma: no cover - compiled
    """Index of the first point i >= ``start`` with ``ok[i]`` and no sample within d_min, or -1."""
    for i in range(start, qx.shape[0]):
        if ok[i] and _is_free(P, grid, x0, y0, cell, d2, qx[i], qy[i]):
            return i
    return -1


# ---------------------------------------------------------------------------------------------------------------------
# S-OA's occlusion layers (soabench.birth.soa.occlusion_layers, eqs. 9-11): the arithmetic after numpy's cos and sin


@njit(cache=True)
def occlusion_layer_arrays(ex, ey, c, s, rb, layers, sp2, sq2, speed, prior):  # pragma: no cover - compiled
    """Means, covariances, velocity means and ranges of the occlusion components, obstacle-major, then ray, then
    layer: r = r_b + l delta_r, p = e + r u, P = sigma_par^2 u u^T + sigma_perp^2 u_perp u_perp^T with
    u = (c, s) = (cos theta_b, sin theta_b) and u_perp = (-s, c); v = speed x side x u_perp (side -1 at theta_min,
    +1 at theta_max) if ``prior``, else 0. The same operations, in the same order, as the numpy form."""
    N = c.shape[0]
    L = layers.shape[0]
    J = N * 2 * L
    p = np.empty((J, 2))
    P = np.empty((J, 2, 2))
    v = np.zeros((J, 2))
    r = np.empty(J)
    i = 0
    for j in range(N):
        for b in range(2):
            cj, sj = c[j, b], s[j, b]
            ns = -sj
            p00 = sp2 * (cj * cj) + sq2 * (ns * ns)
            p01 = sp2 * (cj * sj) + sq2 * (ns * cj)
            p10 = sp2 * (sj * cj) + sq2 * (cj * ns)
            p11 = sp2 * (sj * sj) + sq2 * (cj * cj)
            side = speed * (-1.0 if b == 0 else 1.0)
            for lay in range(L):
                rr = rb[j, b] + layers[lay]
                r[i] = rr
                p[i, 0] = ex + rr * cj
                p[i, 1] = ey + rr * sj
                P[i, 0, 0], P[i, 0, 1], P[i, 1, 0], P[i, 1, 1] = p00, p01, p10, p11
                if prior:
                    v[i, 0] = side * ns
                    v[i, 1] = side * cj
                i += 1
    return p, P, v, r


@njit(cache=True)
def convex_contains(vx, vy, starts, counts, ex, ey, tol):  # pragma: no cover - compiled
    """(N,) True where (ex, ey) is inside or on convex polygon j (either winding): the cross products of every edge
    with the point share one sign within ``tol`` (:func:`soabench.birth.soa.ego_inside`)."""
    N = starts.shape[0]
    out = np.empty(N, dtype=np.bool_)
    for j in range(N):
        s0, n = starts[j], counts[j]
        lo, hi = np.inf, -np.inf
        for a in range(n):
            b = s0 + a + 1 if a + 1 < n else s0
            cross = (vx[b] - vx[s0 + a]) * (ey - vy[s0 + a]) - (vy[b] - vy[s0 + a]) * (ex - vx[s0 + a])
            lo = min(lo, cross)
            hi = max(hi, cross)
        out[j] = lo >= -tol or hi <= tol
    return out
