"""Compiled per-step matchings of one filter run (docs/method.md §5.2, §5.4, §5.6): the gated assignment, OSPA
and GOSPA of every scan in one call.

:func:`soabench.metrics.evaluate` computes, per scan, the distances between Est_k and GT_k and three optimal
assignments on them. With numpy and scipy that is about twenty small calls per scan (a few dozen points at most),
and their fixed costs, not arithmetic, set the time of the metrics. Here each scan is a loop over its pairs:

* the distances are sqrt(dx^2 + dy^2), the operations of :func:`soabench.metrics.pairwise_distances`;
* each assignment is a minimum-cost one, found by the shortest augmenting path method with dual potentials (the
  Hungarian method in its O(n^2 m) form), on the same cost matrices as before: the gated costs of §5.4, and
  min(d, c) for OSPA and GOSPA;
* sums over assigned pairs are taken in row order with numpy's pairwise summation (:func:`np_sum`), so that the
  same pairs give the same bits as ``ndarray.sum``.

Only additions, subtractions, multiplications, divisions, square roots and comparisons: IEEE double precision
without ``fastmath``, the same on every CPU. This path serves the order p = 1 of both metrics (the defaults); other
orders use the numpy functions of :mod:`soabench.metrics`. An optimal assignment is unique unless two assignments
have exactly the same cost; the results can differ from scipy's choice only then, and only where such a tie
between different sets of kept pairs changes a sum or a count (``tests/equivalence/test_metrics_kernels.py``
compares every output with the numpy path).
"""

from __future__ import annotations

import math

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()  # before numba is imported: compiled kernels go to the per-user cache, not site-packages

from numba import njit  # noqa: E402


@njit(cache=True)
def np_sum(a, n):  # pragma: no cover - compiled
    """Sum of ``a[:n]`` in the order numpy's ``add.reduce`` takes for a contiguous float64 array: its pairwise
    summation (below 8 elements one after another, up to 128 in eight running sums, above that the two halves split
    at a multiple of 8, each summed the same way). 0.0 for n = 0."""
    if n == 0:
        return 0.0
    if n < 8:  # _block's short case, here so that a short sum makes no call (and takes no reference count)
        res = -0.0
        for i in range(n):
            res += a[i]
        return res
    return _pairwise(a, np.int64(0), n)  # an int64 start, not the literal 0: one specialisation of _pairwise


@njit(cache=True)
def _block(a, start, n):  # pragma: no cover - compiled
    """numpy's pairwise sum of ``a[start:start + n]`` for n <= 128 (its leaf case)."""
    if n < 8:
        res = -0.0
        for i in range(start, start + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[start], a[start + 1], a[start + 2], a[start + 3]
    r4, r5, r6, r7 = a[start + 4], a[start + 5], a[start + 6], a[start + 7]
    i = 8
    stop = n - n % 8
    while i < stop:
        s = start + i
        r0 += a[s]
        r1 += a[s + 1]
        r2 += a[s + 2]
        r3 += a[s + 3]
        r4 += a[s + 4]
        r5 += a[s + 5]
        r6 += a[s + 6]
        r7 += a[s + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[start + i]
        i += 1
    return res


@njit(cache=True)
def _pairwise(a, start, n):  # pragma: no cover - compiled
    """numpy's pairwise sum of ``a[start:start + n]``: above 128 elements the sum of the two halves split at a
    multiple of 8, each summed the same way (walked with an explicit stack: numba caches no recursive function)."""
    if n <= 128:
        return _block(a, start, n)
    f_start = np.empty(64, dtype=np.int64)
    f_n = np.empty(64, dtype=np.int64)
    f_stage = np.zeros(64, dtype=np.int64)
    vals = np.empty(64)
    nv = 0
    top = 0
    f_start[0], f_n[0] = start, n
    while top >= 0:
        s, m = f_start[top], f_n[top]
        if m <= 128:
            vals[nv] = _block(a, s, m)
            nv += 1
            top -= 1
            continue
        half = m // 2
        half -= half % 8
        if f_stage[top] == 0:  # the left half first
            f_stage[top] = 1
            top += 1
            f_start[top], f_n[top], f_stage[top] = s, half, 0
        elif f_stage[top] == 1:  # then the right half
            f_stage[top] = 2
            top += 1
            f_start[top], f_n[top], f_stage[top] = s + half, m - half, 0
        else:  # both done: left + right
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
            top -= 1
    return vals[0]


@njit(cache=True)
def assign_rows(C):  # pragma: no cover - compiled
    """Minimum-cost assignment of the rows of ``C`` (a, b) with a <= b: the column of each row (a,).

    Shortest augmenting paths with dual potentials u (rows) and v (columns): row i is added by growing a tree of
    tight edges from it, lowering the reduced costs C[i, j] - u[i] - v[j] of the columns not yet in the tree by
    the smallest one, until a free column is reached; the path to it is then flipped. Finite costs only.

    Each step's lowering of the columns outside the tree (``minv[j] -= delta``) is applied when the next step reads
    that column, in the same pass, and the potentials of the tree's columns are kept in a list: one pass over the
    columns per step, the same operations on every value as two.
    """
    a, b = C.shape
    u = np.zeros(a + 1)
    v = np.zeros(b + 1)
    owner = np.zeros(b + 1, dtype=np.int64)  # owner[j]: row (1-based) holding column j; 0 = free
    way = np.zeros(b + 1, dtype=np.int64)
    minv = np.empty(b + 1)
    used = np.empty(b + 1, dtype=np.bool_)
    tree = np.empty(b + 1, dtype=np.int64)  # the columns in the tree, in the order they joined it
    for i in range(1, a + 1):
        owner[0] = i
        j0 = 0
        minv[:] = np.inf
        used[:] = False
        n_tree = 0
        lowered = 0.0  # the previous step's delta, not yet taken off minv outside the tree
        while True:
            used[j0] = True
            tree[n_tree] = j0
            n_tree += 1
            i0 = owner[j0]
            delta = np.inf
            j1 = 0
            for j in range(1, b + 1):
                if not used[j]:
                    if n_tree > 1:
                        minv[j] -= lowered
                    cur = C[i0 - 1, j - 1] - u[i0] - v[j]
                    if cur < minv[j]:
                        minv[j] = cur
                        way[j] = j0
                    if minv[j] < delta:
                        delta = minv[j]
                        j1 = j
            for q in range(n_tree):
                j = tree[q]
                u[owner[j]] += delta
                v[j] -= delta
            lowered = delta
            j0 = j1
            if owner[j0] == 0:
                break
        while True:  # flip the path back to the root
            j1 = way[j0]
            owner[j0] = owner[j1]
            j0 = j1
            if j0 == 0:
                break
    col = np.empty(a, dtype=np.int64)
    for j in range(1, b + 1):
        if owner[j] > 0:
            col[owner[j] - 1] = j - 1
    return col


@njit(cache=True)
def assignment(C):  # pragma: no cover - compiled
    """(rows, cols) of a minimum-cost assignment of ``C`` (a, b), min(a, b) pairs sorted by row, as
    ``scipy.optimize.linear_sum_assignment`` returns them."""
    a, b = C.shape
    if a <= b:
        return np.arange(a), assign_rows(C)
    row_of_col = assign_rows(C.T.copy())
    rows = np.empty(b, dtype=np.int64)
    cols = np.empty(b, dtype=np.int64)
    order = np.argsort(row_of_col)
    for t in range(b):
        rows[t] = row_of_col[order[t]]
        cols[t] = order[t]
    return rows, cols


@njit(cache=True)
def run_matchings(E, e_off, G, gt, d_gate, gate_cost, ospa_c, gospa_c):  # pragma: no cover - compiled
    """Every scan's matchings of one run, for order p = 1 (§5.2, §5.4, §5.6).

    Args:
        E: (N, 2) Est_k of all scans one after another; scan k's rows are ``E[e_off[k]:e_off[k + 1]]``.
        G: (K, P, 2) true positions; gt: (K, P) GT_k membership.

    Returns:
        ``(tp (K,), partner (K, P), ospa (K, 3), gospa (K, 4), redo (K,))``: the gated pairs' count and, per target,
        the index in Est_k of its gated partner, -1 for none (:func:`soabench.metrics.gated_assignment`), OSPA
        (total, loc, card) and GOSPA (total, loc, missed, false) as :func:`soabench.metrics.ospa` and
        :func:`soabench.metrics.gospa` give them; ``redo``: scans left
        unscored because two estimates (or two truths) coincide. Equal points make equal rows (columns) of every
        cost matrix, so several assignments are optimal, and which one is taken decides the order of a sum's terms
        (its last bit): the caller scores those scans with scipy's choice (:func:`soabench.metrics.evaluate`).
    """
    K, P = gt.shape
    tp = np.zeros(K, dtype=np.int64)
    partner = np.full((K, P), -1, dtype=np.int64)
    ospa = np.zeros((K, 3))
    gospa = np.zeros((K, 4))
    redo = np.zeros(K, dtype=np.bool_)
    gidx = np.empty(P, dtype=np.int64)
    for k in range(K):
        m = np.int64(0)  # int64 from the start: a literal 0 would compile _repeats_gt once more
        for p in range(P):
            if gt[k, p]:
                gidx[m] = p
                m += 1
        s = e_off[k]
        n = e_off[k + 1] - s
        if _repeats(E, s, n) or _repeats_gt(G, k, gidx, m):
            redo[k] = True  # equal points: several optimal assignments (left to the caller's scipy path)
            continue
        D = np.empty((n, m))  # Est_k x GT_k
        for i in range(n):
            for j in range(m):
                dx = E[s + i, 0] - G[k, gidx[j], 0]
                dy = E[s + i, 1] - G[k, gidx[j], 1]
                D[i, j] = math.sqrt(dx * dx + dy * dy)
        half = 0.5 * gospa_c
        if n == 0 or m == 0:
            if max(n, m) > 0:
                ospa[k, 0] = ospa[k, 2] = ospa_c * (max(n, m) - min(n, m)) / max(n, m)
            gospa[k, 2] = half * m
            gospa[k, 3] = half * n
            gospa[k, 0] = (0.0 + gospa[k, 2]) + gospa[k, 3]
            continue
        # gated assignment (§5.4 step 1)
        Cg = np.empty((n, m))
        for i in range(n):
            for j in range(m):
                Cg[i, j] = gate_cost if D[i, j] > d_gate else D[i, j]
        rows, cols = assignment(Cg)
        for t in range(len(rows)):
            if D[rows[t], cols[t]] <= d_gate:
                tp[k] += 1
                partner[k, gidx[cols[t]]] = rows[t]
        # OSPA (§5.2): the smaller set as rows
        lo, hi = min(n, m), max(n, m)
        Co = np.empty((lo, hi))
        for i in range(lo):
            for j in range(hi):
                d = D[i, j] if n <= m else D[j, i]
                Co[i, j] = min(d, ospa_c)
        rows, cols = assignment(Co)
        vals = np.empty(lo)
        for t in range(lo):
            vals[t] = Co[rows[t], cols[t]]
        loc_p = np_sum(vals, lo) / hi
        card_p = ospa_c * (hi - lo) / hi
        ospa[k, 0] = loc_p + card_p
        ospa[k, 1] = loc_p
        ospa[k, 2] = card_p
        # GOSPA (§5.6): truths as rows
        Cq = np.empty((m, n))
        for i in range(m):
            for j in range(n):
                Cq[i, j] = min(D[j, i], gospa_c)
        rows, cols = assignment(Cq)
        kept = np.empty(len(rows))
        n_kept = np.int64(0)  # likewise for np_sum
        for t in range(len(rows)):
            d = D[cols[t], rows[t]]
            if d < gospa_c:
                kept[n_kept] = d
                n_kept += 1
        loc = np_sum(kept, n_kept)
        gospa[k, 1] = loc
        gospa[k, 2] = half * (m - n_kept)
        gospa[k, 3] = half * (n - n_kept)
        gospa[k, 0] = (loc + gospa[k, 2]) + gospa[k, 3]
    return tp, partner, ospa, gospa, redo


@njit(cache=True)
def _repeats(E, s, n):  # pragma: no cover - compiled
    """True if two of the points ``E[s:s + n]`` are equal (an estimate extracted with multiplicity)."""
    for i in range(s, s + n):
        for j in range(i + 1, s + n):
            if E[i, 0] == E[j, 0] and E[i, 1] == E[j, 1]:
                return True
    return False


@njit(cache=True)
def _repeats_gt(G, k, gidx, m):  # pragma: no cover - compiled
    """True if two truths of GT_k are at the same position."""
    for a in range(m):
        for b in range(a + 1, m):
            if G[k, gidx[a], 0] == G[k, gidx[b], 0] and G[k, gidx[a], 1] == G[k, gidx[b], 1]:
                return True
    return False
