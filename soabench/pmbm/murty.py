"""Murty's ranked assignments (docs/method.md §10.3; Murty 1968): the k cheapest assignments of a cost matrix with
no more rows than columns (every row gets a distinct column), compiled.

Forbidden cells are +inf. The best assignment is split into subproblems (Murty's partition): subproblem t keeps the
first t pairs of the assignment, forbids its pair t, and leaves the rest free; the cheapest open subproblem gives the
next assignment and is split the same way. Ties between assignments of equal cost are broken by the order in which
they were found, so the ranking is deterministic.

Each subproblem is solved by :func:`lsa`, the shortest augmenting path algorithm for rectangular problems (Crouse
2016, the algorithm of :func:`scipy.optimize.linear_sum_assignment`) with its deterministic choices: rows are added
in order; among the columns at the lowest reduced path cost the scan, which runs from the last column down, keeps
the first it meets, except that a free column (one that ends the path) beats an assigned one at equal cost. An
assignment's cost is the sum of its cells in row order, summed as numpy sums an array (pairwise in blocks of 8:
:func:`soabench.metrics_kernels.np_sum`). So the assignments and costs are those of scipy's solver, exact ties
included, on every CPU.
"""

from __future__ import annotations

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()

from numba import njit  # noqa: E402

from soabench.metrics_kernels import np_sum  # noqa: E402


@njit(cache=True)
def lsa(C: np.ndarray, col4row: np.ndarray, n_fixed: int) -> bool:
    """The cheapest assignment of the (nr, nc) cost matrix ``C`` (nr <= nc; +inf forbidden) by shortest augmenting
    paths (module docstring): fills ``col4row`` (nr,) and returns True, or returns False when every assignment
    uses a forbidden cell.

    ``n_fixed``: the first rows are fixed, row i to column ``col4row[i]`` (given), which is the only finite cell of
    its row and of its column. Solving them would give each its column and leave every dual of a free row and
    column at 0 (no path from a free row can enter a fixed column), so they are set so and the search starts at
    the first free row, with the same result."""
    nr, nc = C.shape
    if nr == 0:
        return True
    lo = np.inf
    for i in range(nr):
        for j in range(nc):
            if C[i, j] < lo:
                lo = C[i, j]
    u = np.zeros(nr)
    v = np.zeros(nc)
    spc = np.empty(nc)  # shortest path cost to each column
    path = np.full(nc, -1, dtype=np.int64)
    row4col = np.full(nc, -1, dtype=np.int64)
    for i in range(n_fixed):
        row4col[col4row[i]] = i
        u[i] = C[i, col4row[i]] - lo
    col4row[n_fixed:] = -1
    in_rows = np.zeros(nr, dtype=np.bool_)
    in_cols = np.zeros(nc, dtype=np.bool_)
    remaining = np.empty(nc, dtype=np.int64)
    for cur in range(n_fixed, nr):
        for it in range(nc):
            remaining[it] = nc - it - 1
        n_rem = nc
        in_rows[:] = False
        in_cols[:] = False
        spc[:] = np.inf
        min_val = 0.0
        i = cur
        sink = -1
        while sink == -1:
            index = -1
            lowest = np.inf
            in_rows[i] = True
            for it in range(n_rem):
                j = remaining[it]
                r = min_val + (C[i, j] - lo) - u[i] - v[j]
                if r < spc[j]:
                    path[j] = i
                    spc[j] = r
                if spc[j] < lowest or (spc[j] == lowest and row4col[j] == -1):
                    lowest = spc[j]
                    index = it
            min_val = lowest
            if min_val == np.inf or index < 0:
                return False
            j = remaining[index]
            if row4col[j] == -1:
                sink = j
            else:
                i = row4col[j]
            in_cols[j] = True
            n_rem -= 1
            remaining[index] = remaining[n_rem]
        u[cur] += min_val
        for i in range(nr):
            if in_rows[i] and i != cur:
                u[i] += min_val - spc[col4row[i]]
        for j in range(nc):
            if in_cols[j]:
                v[j] -= min_val - spc[j]
        j = sink
        while True:
            i = path[j]
            row4col[j] = i
            prev = col4row[i]
            col4row[i] = j
            j = prev
            if i == cur:
                break
    return True


@njit(cache=True)
def _solve(C: np.ndarray, cols: np.ndarray, n_fixed: int) -> float:
    """The cost of the cheapest assignment of ``C`` (its columns in ``cols``), +inf when there is none; the first
    ``n_fixed`` rows fixed to their columns in ``cols`` (:func:`lsa`)."""
    if not lsa(C, cols, n_fixed):
        return np.inf
    n = C.shape[0]
    cells = np.empty(n)
    for r in range(n):
        cells[r] = C[r, cols[r]]
    return np_sum(cells, n)


@njit(cache=True)
def _before(cost_a: float, a: int, cost_b: float, b: int) -> bool:
    return cost_a < cost_b or (cost_a == cost_b and a < b)


@njit(cache=True)
def _row_min_bound(C: np.ndarray) -> float:
    """A lower bound on the cost of every assignment of ``C``: the sum of its row minima (+inf: none exists)."""
    total = 0.0
    for i in range(C.shape[0]):
        lo = np.inf
        for j in range(C.shape[1]):
            if C[i, j] < lo:
                lo = C[i, j]
        total += lo
    return total


@njit(cache=True)
def murty_arrays(C: np.ndarray, k: int, max_gap: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`murty` as arrays: costs (K,) increasing and columns (K, rows).

    A subproblem is solved only when it reaches the top of the queue: until then it waits under a lower bound of
    its cost (its parent's cost or the sum of its row minima, whichever is larger, less a margin far above the
    rounding of a sum). A solved subproblem leaves the queue only when its cost is at most every waiting bound, so
    the assignments come out in the order, and with the tie rule, of solving every subproblem as it is made; the
    subproblems that the k-th assignment makes unnecessary are never solved."""
    n, m = C.shape
    out_cost = np.empty(k)
    out_cols = np.empty((k, n), dtype=np.int64)
    if k <= 0:
        return out_cost[:0], out_cols[:0]
    if n == 0:
        out_cost[0] = 0.0
        return out_cost[:1], out_cols[:1]
    # subproblems (nodes): matrix, assignment, key (cost once solved, else a lower bound), solved, first free row;
    # node index = order made (the tie rule)
    cap = 16
    mats = np.empty((cap, n, m))
    sols = np.empty((cap, n), dtype=np.int64)
    keys = np.empty(cap)
    solved = np.zeros(cap, dtype=np.bool_)
    t0s = np.empty(cap, dtype=np.int64)
    heap = np.empty(cap, dtype=np.int64)  # binary min-heap of node indices by (key, index)
    mats[0] = C
    keys[0] = _solve(mats[0], sols[0], 0)
    if keys[0] == np.inf:
        return out_cost[:0], out_cols[:0]
    solved[0] = True
    limit = keys[0] + max_gap
    t0s[0] = 0
    heap[0] = 0
    n_heap, n_nodes, n_out = 1, 1, 0
    last = n - 1 if n == m else n  # square: with n - 1 rows fixed the last has no choice
    while n_heap > 0 and n_out < k:
        node = heap[0]  # pop the smallest key
        n_heap -= 1
        heap[0] = heap[n_heap]
        p = 0
        while True:
            c1, c2, best = 2 * p + 1, 2 * p + 2, p
            if c1 < n_heap and _before(keys[heap[c1]], heap[c1], keys[heap[best]], heap[best]):
                best = c1
            if c2 < n_heap and _before(keys[heap[c2]], heap[c2], keys[heap[best]], heap[best]):
                best = c2
            if best == p:
                break
            heap[p], heap[best] = heap[best], heap[p]
            p = best
        if solved[node]:
            out_cost[n_out] = keys[node]
            out_cols[n_out] = sols[node]
            n_out += 1
            if n_out == k:
                break
            forced = mats[node].copy()
            parent_cost = keys[node]
            for t in range(t0s[node], last):
                c = sols[node, t]
                keep = forced[t, c]
                forced[t, c] = np.inf
                bound = max(parent_cost, _row_min_bound(forced))
                bound -= 1e-9 * (1.0 + abs(bound))  # margin for rounding
                if bound < np.inf and bound <= limit:  # may be in the ranking: wait in the queue under the bound
                    if n_nodes == cap:  # grow the node store
                        cap *= 2
                        mats2 = np.empty((cap, n, m))
                        mats2[:n_nodes] = mats[:n_nodes]
                        sols2 = np.empty((cap, n), dtype=np.int64)
                        sols2[:n_nodes] = sols[:n_nodes]
                        keys2 = np.empty(cap)
                        keys2[:n_nodes] = keys[:n_nodes]
                        solved2 = np.zeros(cap, dtype=np.bool_)
                        solved2[:n_nodes] = solved[:n_nodes]
                        t0s2 = np.empty(cap, dtype=np.int64)
                        t0s2[:n_nodes] = t0s[:n_nodes]
                        heap2 = np.empty(cap, dtype=np.int64)
                        heap2[:n_heap] = heap[:n_heap]
                        mats, sols, keys, solved, t0s, heap = mats2, sols2, keys2, solved2, t0s2, heap2
                    mats[n_nodes] = forced
                    sols[n_nodes, :t] = sols[node, :t]  # its fixed rows
                    keys[n_nodes] = bound
                    solved[n_nodes] = False
                    t0s[n_nodes] = t
                    n_heap = _push(heap, n_heap, n_nodes, keys)
                    n_nodes += 1
                # fix the pair (t, c) for the next subproblems
                forced[t, :] = np.inf
                forced[:, c] = np.inf
                forced[t, c] = keep
        else:  # solve it and put it back under its cost
            cost = _solve(mats[node], sols[node], t0s[node])
            if cost < np.inf and cost <= limit:
                keys[node] = cost
                solved[node] = True
                n_heap = _push(heap, n_heap, node, keys)
    return out_cost[:n_out], out_cols[:n_out]


@njit(cache=True)
def _push(heap: np.ndarray, n_heap: int, node: int, keys: np.ndarray) -> int:
    """Push ``node`` on the binary heap ``heap[:n_heap]`` ordered by (key, index); returns the new size."""
    q = n_heap
    heap[q] = node
    while q > 0:
        parent = (q - 1) // 2
        if _before(keys[heap[q]], heap[q], keys[heap[parent]], heap[parent]):
            heap[q], heap[parent] = heap[parent], heap[q]
            q = parent
        else:
            break
    return n_heap + 1


def murty(C: np.ndarray, k: int, max_gap: float = np.inf) -> list[tuple[float, np.ndarray]]:
    """The (at most) ``k`` cheapest assignments of the cost matrix ``C`` (rows <= columns; +inf: forbidden), by
    increasing cost: a list of (cost, cols) with ``cols[r]`` the column of row r. Only assignments that cost at most
    ``max_gap`` more than the cheapest are returned (their ranking is unchanged: the search stops there)."""
    C = np.ascontiguousarray(C, dtype=float)
    if C.ndim != 2 or C.shape[0] > C.shape[1]:
        raise ValueError(f"Murty's algorithm needs no more rows than columns, got shape {C.shape}")
    costs, cols = murty_arrays(C, int(k), float(max_gap))
    return [(float(costs[s]), cols[s]) for s in range(len(costs))]
