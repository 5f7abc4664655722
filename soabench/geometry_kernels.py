"""Compiled loops of the per-scan geometry (docs/method.md §2.3, §3.1.3-3.1.4, §4.4, §5.8).

A scan's birth geometry asks small questions of a few dozen points (is a point behind an obstacle, is a candidate
too close to one kept before), once per scan. Written with numpy they are a dozen array calls each, and at these
sizes numpy's fixed cost per call, not arithmetic, sets the time (measured in ``benchmarks/README.md``). The loops
here do the same arithmetic once per (point, edge) or per pair: only additions, subtractions, multiplications,
divisions and comparisons, in IEEE double precision without ``fastmath``, so a result is the same bit for bit as
the numpy form of the same formula and does not depend on the CPU. Compiled code is cached like the filter
kernels (:mod:`soabench.cache`).

The line-of-sight test (:func:`sight_blocked`, for :class:`soabench.sensor.SightBlockers`) decides instead what
GEOS decides: whether a segment meets a polygon. It uses only the signs of orientation determinants, each certified
by Shewchuk's error bound (a floating-point sign is taken only where the bound proves it exact), and hands back
every (segment, occluder) pair that some needed sign leaves undecided (a touch, a collinear edge, a sign within the
bound), which the caller gives to GEOS. Where every needed sign is certified the answer is the exact one, and so
GEOS's, whose own predicates are exact there too.
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


# ---------------------------------------------------------------------------------------------------------------------
# The line-of-sight test (soabench.sensor.line_of_sight, method §2.3, §4.4): sight segments against the rings of the
# occluders and of their cores, decided with certified orientation signs; every pair a certified sign cannot decide
# is handed back to the caller (which asks GEOS)

#: Shewchuk's error bound of the floating-point orientation determinant (ccwerrboundA = (3 + 16 eps) eps, eps =
#: 2^-53): where |det| >= SIGN_BOUND * (|detleft| + |detright|), det has the sign of the exact determinant
SIGN_BOUND = (3.0 + 16.0 * 2.0**-53) * 2.0**-53
#: a sign that the floating-point determinant does not certify
UNSURE = 2
#: ``inside`` of a polygon its rings do not decide (not a valid polygon): every segment that reaches its box is UNSURE
ODD = 3
#: line_of_sight status of a sight line: visible, blocked, some occluder undecided, a core still to build
VISIBLE, BLOCKED, UNDECIDED, NEEDS_CORE = 0, 1, 2, 3
#: below this sum of the determinant's two products, underflow could void the error bound: no sign is certified
_TINY_DETSUM = 1e-280


@njit(cache=True, inline="always")
def _orient(ax, ay, bx, by, cx, cy):  # pragma: no cover - compiled
    """The exact sign (-1, 0, +1) of orient2d(a, b, c) = (a - c) x (b - c), positive when a, b, c turn counter-
    clockwise, or UNSURE when the floating-point determinant does not certify it (Shewchuk's fast filter)."""
    detleft = (ax - cx) * (by - cy)
    detright = (ay - cy) * (bx - cx)
    det = detleft - detright
    detsum = abs(detleft) + abs(detright)
    if not (detsum >= _TINY_DETSUM):
        return UNSURE  # both products (near) zero, underflowed, or NaN: never taken as certain
    # a difference of doubles rounds to zero only when they are equal, and rounding keeps signs: the products'
    # signs are exact, so where they differ (or one is zero) the sign of det is
    if detleft > 0.0:
        if detright <= 0.0:
            return 1
    elif detleft < 0.0:
        if detright >= 0.0:
            return -1
    else:
        return -1 if detright > 0.0 else 1
    bound = SIGN_BOUND * detsum
    if det >= bound:
        return 1
    if -det >= bound:
        return -1
    return UNSURE


@njit(cache=True)
def sight_polygons(ex, ey, vx, vy, rstart, vstart):  # pragma: no cover - compiled
    """The parts of a set of polygons that depend on the sensor (ex, ey), for :func:`sight_blocked`.

    Polygon j has the closed rings ``rstart[j] : rstart[j + 1]`` (exterior and holes, of every part of a
    MultiPolygon); ring r the vertices ``vstart[r] : vstart[r + 1]``, its last vertex repeating its first, so that
    edge v runs from vertex v to v + 1. Returns (bb (J, 4): each polygon's xmin, ymin, xmax, ymax (+-inf, never met,
    for an empty one); side (V,): the certified sign of orient2d(v, v + 1, sensor) per edge; inside (J,): 1 if the
    sensor lies inside polygon j by the even-odd count of the ring edges a ray towards +x crosses, 0 if not, UNSURE
    if an edge that straddles the ray has no certified side)."""
    J = rstart.shape[0] - 1
    V = vx.shape[0]
    bb = np.empty((J, 4))
    side = np.full(V, np.int8(UNSURE))
    inside = np.zeros(J, dtype=np.int8)
    for j in range(J):
        x0, y0, x1, y1 = np.inf, np.inf, -np.inf, -np.inf
        crossings = 0
        unsure = False
        for r in range(rstart[j], rstart[j + 1]):
            for v in range(vstart[r], vstart[r + 1]):
                x0, x1 = min(x0, vx[v]), max(x1, vx[v])
                y0, y1 = min(y0, vy[v]), max(y1, vy[v])
            for v in range(vstart[r], vstart[r + 1] - 1):
                s = _orient(vx[v], vy[v], vx[v + 1], vy[v + 1], ex, ey)
                side[v] = s
                b_above, a_above = vy[v + 1] > ey, vy[v] > ey
                if a_above != b_above:  # the edge straddles the ray's line (half-open in y: a vertex counts once)
                    if s == UNSURE or s == 0:
                        unsure = True  # the sensor on (or too near) the edge
                    elif (b_above and s > 0) or (a_above and s < 0):  # the edge passes to the right of the sensor
                        crossings += 1
        bb[j, 0], bb[j, 1], bb[j, 2], bb[j, 3] = x0, y0, x1, y1
        inside[j] = UNSURE if unsure else crossings % 2
    return bb, side, inside


@njit(cache=True)
def sight_blocked(ex, ey, px, py, bb, rstart, vstart, vx, vy, side, inside, built):  # pragma: no cover - compiled
    """The line-of-sight status of each segment sensor (ex, ey) -> (px[i], py[i]) against J occluders: polygon j
    of the ring set (:func:`sight_polygons`) is occluder j, polygon J + j its core once ``built[j]``; a polygon
    whose ``inside`` is ODD is never decided here.

    Occluder j blocks the segment where the segment meets the occluder and its core (the rule of method §2.3). A
    closed segment meets a closed polygon where it touches or crosses a ring edge, or else where the sensor lies
    inside (then the whole segment does). Returns (status (n,): VISIBLE, BLOCKED, UNDECIDED (some occluder's
    decision was not certified, none certainly blocks; its pairs are listed), NEEDS_CORE (the segment meets an
    occluder whose core is not built, none certainly blocks); pairs (m, 2): the undecided (segment, occluder)
    pairs; need (J,): the cores to build)."""
    n = px.shape[0]
    J = built.shape[0]
    status = np.zeros(n, dtype=np.int8)
    pairs = np.empty((n * J, 2), dtype=np.int64)
    need = np.zeros(J, dtype=np.bool_)
    m = 0
    for i in range(n):
        qx, qy = px[i], py[i]
        if not (math.isfinite(qx) and math.isfinite(qy)) or (qx == ex and qy == ey):
            for j in range(J):  # not a segment the signs decide: every occluder goes to GEOS
                pairs[m, 0], pairs[m, 1] = i, j
                m += 1
            status[i] = UNDECIDED if J > 0 else VISIBLE
            continue
        sx0, sx1 = min(ex, qx), max(ex, qx)
        sy0, sy1 = min(ey, qy), max(ey, qy)
        start = m
        st = VISIBLE
        for j in range(J):
            if bb[j, 0] > sx1 or bb[j, 2] < sx0 or bb[j, 1] > sy1 or bb[j, 3] < sy0:
                continue  # the segment's box misses the occluder's (the core lies within it)
            verdict = 1  # meets the core (t = 0) and the occluder (t = 1): 0 no, 1 yes, UNSURE
            for t in range(2):
                g = J + j if t == 0 else j
                if t == 0 and not built[j]:
                    continue
                if bb[g, 0] > sx1 or bb[g, 2] < sx0 or bb[g, 1] > sy1 or bb[g, 3] < sy0:
                    verdict = 0
                    break
                meets = 1 if inside[g] == 1 else (0 if inside[g] == 0 else UNSURE)
                r = rstart[g] if inside[g] != ODD else rstart[g + 1]
                while meets != 1 and r < rstart[g + 1]:
                    for v in range(vstart[r], vstart[r + 1] - 1):
                        ax, ay, bx, by = vx[v], vy[v], vx[v + 1], vy[v + 1]
                        if max(ax, bx) < sx0 or min(ax, bx) > sx1 or max(ay, by) < sy0 or min(ay, by) > sy1:
                            continue
                        oa = _orient(ex, ey, qx, qy, ax, ay)
                        ob = _orient(ex, ey, qx, qy, bx, by)
                        if oa == ob and (oa == 1 or oa == -1):
                            continue  # the edge lies strictly on one side of the segment's line
                        op = side[v]
                        oq = _orient(ax, ay, bx, by, qx, qy)
                        if op == oq and (op == 1 or op == -1):
                            continue  # the segment lies strictly on one side of the edge's line
                        if oa * ob == -1 and op * oq == -1:
                            meets = 1  # a proper crossing, every sign certified
                            break
                        meets = UNSURE  # collinear, touching, or a sign not certified
                    r += 1
                if meets == 0:
                    verdict = 0
                    break
                if meets == UNSURE:
                    verdict = UNSURE
            if verdict == 0:
                continue
            if not built[j]:
                need[j] = True
                st = NEEDS_CORE
            elif verdict == 1:
                st = BLOCKED
                break
            else:
                if st == VISIBLE:
                    st = UNDECIDED
                pairs[m, 0], pairs[m, 1] = i, j
                m += 1
        if st != UNDECIDED:
            m = start  # a blocked segment needs no other decision; one waiting for a core is decided again
        status[i] = st
    return status, pairs[:m].copy(), need
