"""Compiled loops of the semantic region from a point cloud (docs/method.md §3.1.4, "The semantic region from a point
cloud"): the cells a frame's class points and gap fill mark, the morphological closing, and the outline of the
occupied cells as rings of lattice vertices, simplified within a tolerance.

A frame has some 30,000 points but only a few hundred occupied cells per class; at these sizes numpy's and GEOS's
fixed cost per call (a dozen array passes per class, a union of one box per cell, a topology-preserving
simplification) set the time, not arithmetic. The loops here make one pass over the points and one over the cells.
The cells are those of the array form of the same formulas (IEEE double precision, no ``fastmath``, the same sort),
so the raster is the same bit for bit; the outline is traced on the raster, not unioned from boxes. Compiled code is
cached like the filter kernels (:mod:`soabench.cache`).
"""

from __future__ import annotations

import math

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()  # before numba is imported: compiled kernels go to the per-user cache, not site-packages

from numba import njit  # noqa: E402

#: lattice steps of the four edge directions: +x, +y, -x, -y (a left turn is the next one)
_DI = np.array([1, 0, -1, 0], dtype=np.int64)
_DJ = np.array([0, 1, 0, -1], dtype=np.int64)


@njit(cache=True)
def frame_cells(pts, lab, lut, n_cls, r_max, half_fov_deg, grid, sector_rad, fill):  # pragma: no cover - compiled
    """Cells ``(i, j, class)`` marked in one frame: i = floor(x / grid), j = floor(y / grid).

    ``pts`` are the scan's rows (x, y, z, intensity) in the ego frame, ``lab`` their 16-bit SemanticKITTI ids and
    ``lut[id]`` the configured class of an id (-1: none). Kept points are within r_max in x and y and, when
    ``half_fov_deg`` >= 0, within that many degrees of the x axis. Every kept point of a class marks its cell; with
    ``fill`` > 0, the kept points are ordered by azimuth sector (of ``sector_rad``), then range, then scan order, and
    between two consecutive ones of the same sector and class whose ranges differ by more than a cell and at most
    ``fill``, ceil(d / (grid / 2)) points at equal steps from the nearer one (d their distance) mark theirs. A cell
    may be listed more than once.
    """
    n = len(pts)
    keep = np.empty(n, dtype=np.int64)
    m = 0
    # below 90 deg, the sector test needs the angle only near the sector's edges: points with x < 0 lie outside,
    # points with |y| < x tan(half) (less a relative margin far above rounding) inside
    narrow = 0.0 <= half_fov_deg < 89.0
    slope = math.tan(math.radians(half_fov_deg)) * (1.0 - 1e-6) if narrow else 0.0
    for p in range(n):
        x, y = np.float64(pts[p, 0]), np.float64(pts[p, 1])
        if abs(x) <= r_max and abs(y) <= r_max:
            if half_fov_deg >= 0.0:
                if narrow and x < 0.0:
                    continue
                if not (narrow and abs(y) < x * slope):
                    if abs(math.atan2(y, x) * (180.0 / math.pi)) > half_fov_deg:
                        continue
            keep[m] = p
            m += 1
    kx, ky, kc = np.empty(m), np.empty(m), np.empty(m, dtype=np.int64)
    n_class = np.zeros(n_cls, dtype=np.int64)
    for q in range(m):
        p = keep[q]
        kx[q], ky[q], kc[q] = pts[p, 0], pts[p, 1], lut[lab[p]]
        if kc[q] >= 0:
            n_class[kc[q]] += 1
    # the gap fill: pairs of consecutive returns of one class along a sector
    pa = np.empty(m, dtype=np.int64)
    pb = np.empty(m, dtype=np.int64)
    ns = np.empty(m, dtype=np.int64)
    n_pairs = 0
    if fill > 0.0 and m > 1 and n_class.max() > 1:
        r = np.empty(m)
        sector = np.empty(m, dtype=np.int64)
        for q in range(m):
            r[q] = math.hypot(kx[q], ky[q])
            sector[q] = np.int64(math.floor((math.atan2(ky[q], kx[q]) + math.pi) / sector_rad))
        # by sector (a counting sort keeps the scan order), then by range within each sector (a stable sort)
        first = np.zeros(sector.max() + 2, dtype=np.int64)
        for q in range(m):
            first[sector[q] + 1] += 1
        first = np.cumsum(first)
        fill_at = first[:-1].copy()
        order = np.empty(m, dtype=np.int64)
        for q in range(m):
            order[fill_at[sector[q]]] = q
            fill_at[sector[q]] += 1
        for k in range(len(first) - 1):
            a, b = first[k], first[k + 1]
            if b - a > 1:
                idx = order[a:b].copy()
                order[a:b] = idx[np.argsort(r[idx], kind="mergesort")]
        for t in range(m - 1):
            a, b = order[t], order[t + 1]
            c = kc[a]
            if c < 0 or kc[b] != c or sector[a] != sector[b]:
                continue
            dr = r[b] - r[a]
            if dr <= fill and dr > grid:
                pa[n_pairs], pb[n_pairs] = a, b
                ns[n_pairs] = np.int64(math.ceil(math.hypot(kx[b] - kx[a], ky[b] - ky[a]) / (0.5 * grid)))
                n_pairs += 1
    total = 0
    for c in range(n_cls):
        total += n_class[c]
    for q in range(n_pairs):
        total += ns[q]
    ci = np.empty(total, dtype=np.int64)
    cj = np.empty(total, dtype=np.int64)
    cc = np.empty(total, dtype=np.int64)
    w = 0
    for q in range(m):
        if kc[q] >= 0:
            ci[w], cj[w], cc[w] = math.floor(kx[q] / grid), math.floor(ky[q] / grid), kc[q]
            w += 1
    for q in range(n_pairs):
        a, b, k = pa[q], pb[q], ns[q]
        dx, dy = kx[b] - kx[a], ky[b] - ky[a]
        for s in range(k):
            t = s / k
            px, py = kx[a] + t * dx, ky[a] + t * dy
            if abs(px) <= r_max and abs(py) <= r_max:
                ci[w], cj[w], cc[w] = math.floor(px / grid), math.floor(py / grid), kc[a]
                w += 1
    return ci[:w], cj[:w], cc[:w]


@njit(cache=True)
def closed_raster(ci, cj, rad):  # pragma: no cover - compiled
    """The occupancy of the cells ``(ci, cj)`` closed with the disc of radius ``rad`` cells (dilation, then erosion),
    on a grid with ``rad + 1`` empty cells around them, and the grid's lowest cell ``(i0, j0)``."""
    i0, j0 = ci.min() - rad - 1, cj.min() - rad - 1
    nx, ny = ci.max() - i0 + rad + 2, cj.max() - j0 + rad + 2
    occ = np.zeros((nx, ny), dtype=np.bool_)
    for p in range(len(ci)):
        occ[ci[p] - i0, cj[p] - j0] = True
    if rad == 0:
        return occ, i0, j0
    oi = np.empty((2 * rad + 1) ** 2, dtype=np.int64)
    oj = np.empty((2 * rad + 1) ** 2, dtype=np.int64)
    n_off = 0
    for di in range(-rad, rad + 1):
        for dj in range(-rad, rad + 1):
            if di * di + dj * dj <= rad * rad:
                oi[n_off], oj[n_off] = di, dj
                n_off += 1
    dil = np.zeros((nx, ny), dtype=np.bool_)
    for i in range(nx):
        for j in range(ny):
            if occ[i, j]:
                for o in range(n_off):
                    dil[i + oi[o], j + oj[o]] = True  # in the grid: occupied cells lie rad + 1 from its edge
    out = np.zeros((nx, ny), dtype=np.bool_)
    for i in range(nx):
        for j in range(ny):
            if not dil[i, j]:
                continue
            whole = True
            for o in range(n_off):
                a, b = i + oi[o], j + oj[o]
                if a < 0 or b < 0 or a >= nx or b >= ny or not dil[a, b]:
                    whole = False
                    break
            out[i, j] = whole
    return out, i0, j0


@njit(cache=True)
def _label4(occ):  # pragma: no cover - compiled
    """Labels 0, 1, ... of the 4-connected components of the occupied cells (-1: empty)."""
    nx, ny = occ.shape
    lab = np.full((nx, ny), -1, dtype=np.int64)
    stack = np.empty(nx * ny, dtype=np.int64)
    n = 0
    for i in range(nx):
        for j in range(ny):
            if not occ[i, j] or lab[i, j] >= 0:
                continue
            lab[i, j] = n
            top = 0
            stack[0] = i * ny + j
            top = 1
            while top:
                top -= 1
                a, b = stack[top] // ny, stack[top] % ny
                for d in range(4):
                    u, v = a + _DI[d], b + _DJ[d]
                    if 0 <= u < nx and 0 <= v < ny and occ[u, v] and lab[u, v] < 0:
                        lab[u, v] = n
                        stack[top] = u * ny + v
                        top += 1
            n += 1
    return lab


@njit(cache=True)
def outline_rings(occ):  # pragma: no cover - compiled
    """The outline of the occupied cells as closed rings of lattice vertices (vertex (i, j) is the lower-left corner
    of cell (i, j)), corners only, the occupied side on the left: outer rings counter-clockwise, holes clockwise.

    Where two occupied cells touch at a corner only, the trace turns to keep each cell's ring apart (the cells count
    as connected through their edges only). Returns the vertices ``vi, vj``, each ring's start and vertex count,
    twice its signed area, and the 4-connected component of the cells it bounds.
    """
    nx, ny = occ.shape
    # edge[i, j, d]: the unit edge from vertex (i, j) in direction d has an occupied cell on its left, an empty one
    # on its right
    edge = np.zeros((nx + 1, ny + 1, 4), dtype=np.bool_)
    n_edges = 0
    for i in range(nx):
        for j in range(ny):
            if not occ[i, j]:
                continue
            if j == 0 or not occ[i, j - 1]:
                edge[i, j, 0] = True  # bottom, +x
                n_edges += 1
            if i == nx - 1 or not occ[i + 1, j]:
                edge[i + 1, j, 1] = True  # right, +y
                n_edges += 1
            if j == ny - 1 or not occ[i, j + 1]:
                edge[i + 1, j + 1, 2] = True  # top, -x
                n_edges += 1
            if i == 0 or not occ[i - 1, j]:
                edge[i, j + 1, 3] = True  # left, -y
                n_edges += 1
    lab = _label4(occ)
    used = np.zeros((nx + 1, ny + 1, 4), dtype=np.bool_)
    vi = np.empty(n_edges, dtype=np.int64)
    vj = np.empty(n_edges, dtype=np.int64)
    starts = np.empty(n_edges, dtype=np.int64)
    counts = np.empty(n_edges, dtype=np.int64)
    area2 = np.empty(n_edges, dtype=np.int64)
    comp = np.empty(n_edges, dtype=np.int64)
    nv = 0
    nr = 0
    for i in range(nx + 1):  # the first unused edge met is at its ring's lowest vertex, a corner
        for j in range(ny + 1):
            for d0 in range(4):
                if not edge[i, j, d0] or used[i, j, d0]:
                    continue
                starts[nr] = nv
                # the cell on the left of the first edge
                li = i - 1 if d0 == 1 or d0 == 2 else i
                lj = j - 1 if d0 == 2 or d0 == 3 else j
                comp[nr] = lab[li, lj]
                a, b, d = i, j, d0
                vi[nv], vj[nv] = a, b
                nv += 1
                area = 0
                while True:
                    used[a, b, d] = True
                    na, nb = a + _DI[d], b + _DJ[d]
                    area += a * nb - na * b
                    a, b = na, nb
                    nd = -1
                    for turn in (1, 0, 3):  # left, straight, right: the occupied cell stays on the left
                        e = (d + turn) % 4
                        if edge[a, b, e]:
                            nd = e
                            break
                    if used[a, b, nd]:
                        break
                    if nd != d:
                        vi[nv], vj[nv] = a, b
                        nv += 1
                    d = nd
                counts[nr] = nv - starts[nr]
                area2[nr] = area
                nr += 1
    return vi[:nv], vj[:nv], starts[:nr], counts[:nr], area2[:nr], comp[:nr]


@njit(cache=True)
def _segment_distance(px, py, ax, ay, bx, by):  # pragma: no cover - compiled
    """Distance from point p to the segment ab, in the form GEOS computes it (so ties between equally far points of a
    staircase resolve as in ``shapely.simplify``)."""
    if ax == bx and ay == by:
        return math.sqrt((px - ax) * (px - ax) + (py - ay) * (py - ay))
    len2 = (bx - ax) * (bx - ax) + (by - ay) * (by - ay)
    r = ((px - ax) * (bx - ax) + (py - ay) * (by - ay)) / len2
    if r <= 0.0:
        return math.sqrt((px - ax) * (px - ax) + (py - ay) * (py - ay))
    if r >= 1.0:
        return math.sqrt((px - bx) * (px - bx) + (py - by) * (py - by))
    s = ((ay - py) * (bx - ax) - (ax - px) * (by - ay)) / len2
    return abs(s) * math.sqrt(len2)


@njit(cache=True)
def simplify_rings(x, y, starts, counts, tol):  # pragma: no cover - compiled
    """Douglas-Peucker on each closed ring, its first vertex fixed: True for the vertices kept. A run of vertices
    between two kept ones is dropped when all lie within ``tol`` of the segment joining those two (a point's distance
    when they coincide), else its farthest vertex is kept and both halves are looked at the same way."""
    keep = np.zeros(len(x), dtype=np.bool_)
    lo = np.empty(len(x) + 1, dtype=np.int64)
    hi = np.empty(len(x) + 1, dtype=np.int64)
    for r in range(len(starts)):
        s, n = starts[r], counts[r]
        keep[s] = True
        top = 0
        lo[0], hi[0] = 0, n  # index n is the first vertex again
        top = 1
        while top:
            top -= 1
            a, b = lo[top], hi[top]
            if b - a < 2:
                continue
            ax, ay = x[s + a], y[s + a]
            bx, by = x[s + b % n], y[s + b % n]
            far, far_d = -1, -1.0
            for k in range(a + 1, b):
                dist = _segment_distance(x[s + k], y[s + k], ax, ay, bx, by)
                if dist > far_d:
                    far, far_d = k, dist
            if far_d > tol:
                keep[s + far] = True
                lo[top], hi[top] = a, far
                lo[top + 1], hi[top + 1] = far, b
                top += 2
    return keep


@njit(cache=True, inline="always")
def _put_ring(out, w, x, y, keep, s, n):  # pragma: no cover - compiled
    """Write the kept vertices of the ring ``s .. s + n - 1`` and its first vertex again into ``out`` from row ``w``;
    returns the next free row."""
    for k in range(s, s + n):
        if keep[k]:
            out[w, 0], out[w, 1] = x[k], y[k]
            w += 1
    out[w, 0], out[w, 1] = x[s], y[s]
    return w + 1


@njit(cache=True)
def ring_polygons(occ, i0, j0, grid, tol):  # pragma: no cover - compiled
    """The outline of a raster whose cell (0, 0) is the ego frame's cell (i0, j0) as simplified closed rings (first
    vertex repeated at the end), in ego coordinates: :func:`outline_rings`, each ring taken from its lowest vertex
    clockwise (shells) or counter-clockwise (holes), the order GEOS's overlay writes, and :func:`simplify_rings`
    within ``tol``; rings left with fewer than 3 vertices (no area) dropped.

    Returns the shells of the components without holes (vertices, ring offsets), then the rings of the components
    with holes (vertices, ring offsets, component, True for its shell).
    """
    vi, vj, starts, counts, area2, comp = outline_rings(occ)
    nv, nr = len(vi), len(starts)
    x, y = np.empty(nv), np.empty(nv)
    for r in range(nr):
        s, n = starts[r], counts[r]
        for k in range(n):
            b = s + (n - k) % n
            x[s + k], y[s + k] = (vi[b] + i0) * grid, (vj[b] + j0) * grid
    keep = simplify_rings(x, y, starts, counts, tol)
    n_kept = np.zeros(nr, dtype=np.int64)
    for r in range(nr):
        for k in range(starts[r], starts[r] + counts[r]):
            n_kept[r] += keep[k]
    n_comp = comp.max() + 1 if nr else 0
    holed = np.zeros(n_comp, dtype=np.bool_)
    for r in range(nr):
        if n_kept[r] >= 3 and area2[r] < 0:
            holed[comp[r]] = True
    # sizes, then the two groups
    n_a = n_b = m_a = m_b = 0
    for r in range(nr):
        if n_kept[r] < 3 or (area2[r] < 0 and not holed[comp[r]]):
            continue
        if holed[comp[r]]:
            n_b += n_kept[r] + 1
            m_b += 1
        elif area2[r] > 0:
            n_a += n_kept[r] + 1
            m_a += 1
    xy_a, off_a = np.empty((n_a, 2)), np.zeros(m_a + 1, dtype=np.int64)
    xy_b, off_b = np.empty((n_b, 2)), np.zeros(m_b + 1, dtype=np.int64)
    comp_b, shell_b = np.empty(m_b, dtype=np.int64), np.empty(m_b, dtype=np.bool_)
    wa = wb = ra = rb = 0
    for r in range(nr):
        if n_kept[r] < 3 or (area2[r] < 0 and not holed[comp[r]]):
            continue
        if holed[comp[r]]:
            wb = _put_ring(xy_b, wb, x, y, keep, starts[r], counts[r])
            comp_b[rb], shell_b[rb] = comp[r], area2[r] > 0
            rb += 1
            off_b[rb] = wb
        else:
            wa = _put_ring(xy_a, wa, x, y, keep, starts[r], counts[r])
            ra += 1
            off_a[ra] = wa
    return xy_a, off_a, xy_b, off_b, comp_b, shell_b
