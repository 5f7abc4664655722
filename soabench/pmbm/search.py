"""Ranked assignments by search (docs/method.md §10.3): the k best assignments of a small cost matrix by a bounded
depth-first search, where the result must be Murty's ranking (:mod:`soabench.pmbm.murty`), bit for bit.

An assignment's cost is the sum of its cells in row order in numpy's order, as Murty's algorithm sums it, so the
same assignment has the same bits whichever way it was found; the search declines wherever its order could differ
from Murty's (a near-tie among the ranked assignments) and the caller runs Murty's algorithm instead.
"""

from __future__ import annotations

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()

from numba import njit  # noqa: E402

from soabench.metrics_kernels import np_sum  # noqa: E402

#: the relative margin within which two assignment costs count as tied in :func:`ranked_by_search`, and the larger
#: one within which its search keeps a branch whose bound lies above the k-th best cost
SEARCH_TIE = 1e-10
SEARCH_SLACK = 1e-9


@njit(cache=True)
def _declined(n: int) -> tuple[bool, np.ndarray, np.ndarray]:
    """:func:`ranked_by_search`'s answer when it gives up (empty costs and columns for ``n`` rows)."""
    return False, np.empty(0), np.empty((0, n), dtype=np.int64)


@njit(cache=True)
def ranked_by_search(
    C: np.ndarray, k: int, max_gap: float, budget: int, max_product: float
) -> tuple[bool, np.ndarray, np.ndarray]:
    """The answer of :func:`soabench.pmbm.murty.murty_from` (started from the best assignment of
    :func:`~soabench.pmbm.murty.square_root`) by a depth-first search instead, where it is sure to be the same:
    (True, costs, cols), or (False, ...) when the caller must run Murty's algorithm.

    The rows are assigned in order, each to one of its finite cells in increasing cost, skipping columns taken;
    a branch is cut when its cost so far plus the least cell of every later row exceeds the k-th best complete
    assignment found, or the best found plus ``max_gap`` if that is lower, by more than a margin far above rounding
    (:data:`SEARCH_SLACK`). The assignments kept are sorted by their costs (their cells in row order, numpy's sum:
    the bits Murty's algorithm gives them), and those at most ``max_gap`` above the best are listed. They are the
    best assignment and Murty's ranking exactly when no two of the k listed, nor the k-th and the next, are tied
    within :data:`SEARCH_TIE`: the best assignment and Murty's order among ties follow the order their algorithms
    meet them, and a near-tie may be decided by rounding. Otherwise, beyond ``budget`` visited branches, or when
    the product of the rows' numbers of finite cells exceeds ``max_product`` (many rows contending for the same
    columns, where the least cells bound the cost poorly), it gives up."""
    n, m = C.shape
    if n == 0 or k <= 0:
        return _declined(n)
    product = 1.0  # of the rows' numbers of finite cells (a row without one: no assignment)
    for r in range(n):
        n_fin = 0
        for j in range(m):
            if C[r, j] != np.inf:
                n_fin += 1
        product *= n_fin
        if product == 0.0 or product > max_product:
            return _declined(n)
    # each row's finite cells by increasing cost, and the least cost of the rows from r on
    opt = np.empty((n, m), dtype=np.int64)
    n_opt = np.zeros(n, dtype=np.int64)
    rest = np.zeros(n + 1)
    for r in range(n - 1, -1, -1):
        for j in range(m):
            c = C[r, j]
            if c == np.inf:
                continue
            q = n_opt[r]  # insertion by cost
            while q > 0 and C[r, opt[r, q - 1]] > c:
                opt[r, q] = opt[r, q - 1]
                q -= 1
            opt[r, q] = j
            n_opt[r] += 1
        rest[r] = rest[r + 1] + C[r, opt[r, 0]]
    pos = np.zeros(n, dtype=np.int64)
    taken = np.zeros(m, dtype=np.bool_)
    partial = np.zeros(n + 1)
    cells = np.empty(n)
    cap = 2 * k + 16
    cand_cost = np.empty(cap)
    cand_cols = np.empty((cap, n), dtype=np.int64)
    n_cand = 0
    best = np.empty(k)  # max-heap of the k least costs found so far
    n_best = 0
    lowest = np.inf
    visits = 0
    r = 0
    while r >= 0:
        # the candidates' store grows here, outside the inner loop (arrays reassigned inside a loop cost reference
        # counts at every iteration)
        if n_cand == cap:
            cap *= 2
            grown = np.empty(cap)
            grown[:n_cand] = cand_cost[:n_cand]
            grown_cols = np.empty((cap, n), dtype=np.int64)
            grown_cols[:n_cand] = cand_cols[:n_cand]
            cand_cost, cand_cols = grown, grown_cols
        while r >= 0 and n_cand < cap:
            if pos[r] == n_opt[r]:  # row r exhausted: back to the previous row's next cell
                r -= 1
                if r >= 0:
                    taken[opt[r, pos[r]]] = False
                    pos[r] += 1
                continue
            visits += 1
            if visits > budget:
                return _declined(n)
            j = opt[r, pos[r]]
            if taken[j]:
                pos[r] += 1
                continue
            thr = lowest + max_gap
            if n_best == k:
                thr = min(thr, best[0])
            bound = partial[r] + C[r, j] + rest[r + 1]
            if bound > thr + SEARCH_SLACK * (1.0 + abs(thr)):  # this cell and every dearer one of row r are cut
                pos[r] = n_opt[r]
                continue
            if r < n - 1:
                taken[j] = True
                partial[r + 1] = partial[r] + C[r, j]
                r += 1
                pos[r] = 0
                continue
            # a complete assignment: rows 0..n-2 at their current cells, row n-1 at j; its cost in row order,
            # numpy's sum
            for i in range(n - 1):
                cells[i] = C[i, opt[i, pos[i]]]
            cells[n - 1] = C[n - 1, j]
            cost = np_sum(cells, n)
            cand_cost[n_cand] = cost
            for i in range(n - 1):
                cand_cols[n_cand, i] = opt[i, pos[i]]
            cand_cols[n_cand, n - 1] = j
            n_cand += 1
            lowest = min(lowest, cost)
            if n_best < k:  # into the heap of the k least: sift up
                q = n_best
                best[q] = cost
                n_best += 1
                while q > 0 and best[(q - 1) // 2] < best[q]:
                    best[q], best[(q - 1) // 2] = best[(q - 1) // 2], best[q]
                    q = (q - 1) // 2
            elif cost < best[0]:  # replace the largest: sift down
                best[0] = cost
                q = 0
                while True:
                    c1, c2, big = 2 * q + 1, 2 * q + 2, q
                    if c1 < k and best[c1] > best[big]:
                        big = c1
                    if c2 < k and best[c2] > best[big]:
                        big = c2
                    if big == q:
                        break
                    best[q], best[big] = best[big], best[q]
                    q = big
            pos[r] += 1
    if n_cand == 0:
        return _declined(n)
    order = np.argsort(cand_cost[:n_cand], kind="mergesort")
    limit = cand_cost[order[0]] + max_gap  # as murty_from's cost0 + max_gap
    K = 0
    while K < min(k, n_cand) and cand_cost[order[K]] <= limit:
        K += 1
    for p in range(min(K, n_cand - 1)):  # ties among the k best, or between the k-th and the next
        a, b = cand_cost[order[p]], cand_cost[order[p + 1]]
        if b - a <= SEARCH_TIE * (1.0 + abs(b)):
            return _declined(n)
    out_cost = np.empty(K)
    out_cols = np.empty((K, n), dtype=np.int64)
    for s in range(K):
        out_cost[s] = cand_cost[order[s]]
        out_cols[s] = cand_cols[order[s]]
    return True, out_cost, out_cols
