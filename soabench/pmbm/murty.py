"""Murty's ranked assignments (docs/method.md §10.3; Murty 1968): the k cheapest assignments of a cost matrix with
no more rows than columns (every row gets a distinct column), compiled.

Forbidden cells are +inf. The best assignment is split into subproblems (Murty's partition): subproblem t keeps the
first t pairs of the assignment, forbids its pair t, and leaves the rest free; the cheapest open subproblem gives the
next assignment and is split the same way. Ties between assignments of equal cost are broken by the order in which
they were found, so the ranking is deterministic.

The best assignment comes from :func:`lsa`, the shortest augmenting path algorithm for rectangular problems (Crouse
2016, the algorithm of :func:`scipy.optimize.linear_sum_assignment`) with its deterministic choices: rows are added
in order; among the columns at the lowest reduced path cost the scan, which runs from the last column down, keeps
the first it meets, except that a free column (one that ends the path) beats an assigned one at equal cost. So the
best assignment is scipy's, exact ties included (:func:`square_root`). A matrix that differs from a solved one in a
few columns (a cluster under another choice of its tracks' hypotheses) has its best assignment repaired from the
solved one's instead (:func:`repaired_root`).

Each subproblem starts from its parent's assignment and dual variables (Miller, Stone & Cox 1997): with pair t
removed only row t is unassigned, the parent's duals stay feasible, and one shortest augmenting path from row t
(in :func:`murty_from`) gives the subproblem's best assignment. The rectangular problem is solved as the square one with
``cols - rows`` dummy rows of cost 0 (they hold the columns no row takes); Murty's partition runs over the real rows
only, so each assignment is still listed once. Among the columns at equal path cost the search takes the one that
ends the path, then the lowest column index; so between assignments of exactly equal cost, a subproblem returns the
one its parent's assignment leads to. An assignment's cost is the sum of its cells in row order, summed as numpy sums
an array (pairwise in blocks of 8: :func:`soabench.metrics_kernels.np_sum`): the same bits for the same assignment
however it was found. That lets a small problem's ranking come from a depth-first search instead
(:func:`soabench.pmbm.search.ranked_by_search`), which answers only where its sorted list must be Murty's.
"""

from __future__ import annotations

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()

from numba import njit  # noqa: E402

from soabench.metrics_kernels import np_sum  # noqa: E402


@njit(cache=True)
def lsa(C: np.ndarray, col4row: np.ndarray) -> tuple[bool, np.ndarray, np.ndarray]:
    """The cheapest assignment of the (nr, nc) cost matrix ``C`` (nr <= nc; +inf forbidden) by shortest augmenting
    paths (module docstring): fills ``col4row`` (nr,) and returns (True, u, v), or (False, u, v) when every
    assignment uses a forbidden cell.

    (u, v): dual variables of ``C - min(C)``: every reduced cost C_ij - min(C) - u_i - v_j is >= 0 (up to rounding),
    0 on the assigned cells; v_j <= 0, and 0 for every column no row takes."""
    nr, nc = C.shape
    u = np.zeros(nr)
    v = np.zeros(nc)
    if nr == 0:
        return True, u, v
    lo = np.inf
    for i in range(nr):
        for j in range(nc):
            if C[i, j] < lo:
                lo = C[i, j]
    spc = np.empty(nc)  # shortest path cost to each column
    path = np.full(nc, -1, dtype=np.int64)
    row4col = np.full(nc, -1, dtype=np.int64)
    col4row[:] = -1
    in_rows = np.zeros(nr, dtype=np.bool_)
    in_cols = np.zeros(nc, dtype=np.bool_)
    remaining = np.empty(nc, dtype=np.int64)
    for cur in range(nr):
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
                return False, u, v
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
    return True, u, v


@njit(cache=True)
def _assignment_cost(C: np.ndarray, cols: np.ndarray) -> float:
    """The cost of the assignment ``cols`` of ``C``'s rows: its cells summed in row order, in numpy's order."""
    n = C.shape[0]
    cells = np.empty(n)
    for r in range(n):
        cells[r] = C[r, cols[r]]
    return np_sum(cells, n)


@njit(cache=True)
def _finite_cells(C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The finite cells of ``C``'s rows as (start (n + 1,), col): row i's columns in increasing order are
    ``col[start[i]:start[i + 1]]``. A cluster's measurement row reaches its gated tracks and its own new track only,
    so a subproblem's path search relaxes these instead of every column."""
    n, m = C.shape
    start = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        c = 0
        for j in range(m):
            if C[i, j] != np.inf:
                c += 1
        start[i + 1] = start[i] + c
    col = np.empty(start[n], dtype=np.int64)
    q = 0
    for i in range(n):
        for j in range(m):
            if C[i, j] != np.inf:
                col[q] = j
                q += 1
    return start, col


@njit(cache=True)
def _before(cost_a: float, a: int, cost_b: float, b: int) -> bool:
    return cost_a < cost_b or (cost_a == cost_b and a < b)


@njit(cache=True)
def square_root(C: np.ndarray, sol: np.ndarray, u: np.ndarray, v: np.ndarray) -> float:
    """The cheapest assignment of ``C`` (n, m) by :func:`lsa`, as the square problem with m - n dummy rows of cost
    0 (on the columns no row takes, in column order): ``sol`` (m,) each row's column, (u, v) (m,) duals of ``C``
    (reduced costs C_ij - u_i - v_j >= 0, 0 on the assignment; a dummy row's cells cost 0). Returns its cost, +inf
    when there is none."""
    n, m = C.shape
    col4row = np.empty(n, dtype=np.int64)
    ok, u0, v0 = lsa(C, col4row)
    if not ok:
        return np.inf
    lo = np.inf
    for i in range(n):
        for j in range(m):
            if C[i, j] < lo:
                lo = C[i, j]
    used = np.zeros(m, dtype=np.bool_)
    for r in range(n):
        sol[r] = col4row[r]
        u[r] = u0[r] + lo
        used[col4row[r]] = True
    q = n
    for j in range(m):
        v[j] = v0[j]
        if not used[j]:
            sol[q] = j
            u[q] = 0.0
            q += 1
    return _assignment_cost(C, col4row)


@njit(cache=True)
def repaired_root(C: np.ndarray, changed: np.ndarray, sol: np.ndarray, u: np.ndarray, v: np.ndarray) -> float:
    """The cheapest assignment of ``C`` from the square assignment and duals (sol, u, v) of a matrix that differed
    from ``C`` only in the columns ``changed``, updated in place (as :func:`square_root`); returns its cost, +inf
    when there is none. Each changed column's dual becomes its least C_ij - u_i, which makes every reduced cost
    >= 0 again; a row whose cell in a changed column is no longer tight gives its column up, and each such row,
    in increasing order, takes one shortest augmenting path to a free column (the first reached; at equal path cost
    the lowest column index)."""
    m = C.shape[1]
    return repair(C, changed, changed.shape[0], sol, u, v, np.empty((6, m), dtype=np.int64), np.empty(m))


@njit(cache=True)
def repair(
    C: np.ndarray,
    changed: np.ndarray,
    n_changed: int,
    sol: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    iwork: np.ndarray,
    d: np.ndarray,
) -> float:
    """:func:`repaired_root` for the columns ``changed[:n_changed]`` on scratch arrays ``iwork`` (6, m) (rows:
    row4col, free row, free column, pred, seen, scanned) and ``d`` (m,), for a caller that repairs many times."""
    n, m = C.shape
    row4col, free_row, free_col, pred, seen, scanned = 0, 1, 2, 3, 4, 5  # the rows of iwork
    for i in range(m):
        iwork[row4col, sol[i]] = i
        iwork[free_row, i] = 0
        iwork[free_col, i] = 0
    for q in range(n_changed):
        j = changed[q]
        lo = np.inf
        for i in range(m):
            c = C[i, j] - u[i] if i < n else -u[i]
            if c < lo:
                lo = c
        if lo == np.inf:  # no row can take column j (square: every column is taken)
            return np.inf
        v[j] = lo
        h = iwork[row4col, j]
        c = C[h, j] if h < n else 0.0
        if not (c - u[h] - v[j] <= 0.0):
            iwork[free_row, h] = 1
            iwork[free_col, j] = 1
            iwork[row4col, j] = -1
            sol[h] = -1
    for start in range(m):
        if not iwork[free_row, start]:
            continue
        for j in range(m):
            d[j] = np.inf
            iwork[seen, j] = 0
            iwork[scanned, j] = 0
        i, dist, sink = start, 0.0, -1
        while sink < 0:
            iwork[scanned, i] = 1
            for j in range(m):
                if iwork[seen, j]:
                    continue
                c = C[i, j] if i < n else 0.0
                if c == np.inf:
                    continue
                r = dist + c - u[i] - v[j]
                if r < d[j]:
                    d[j] = r
                    iwork[pred, j] = i
            lowest = np.inf
            nxt = -1
            for j in range(m):
                if iwork[seen, j] or d[j] == np.inf:
                    continue
                if d[j] < lowest or (d[j] == lowest and iwork[free_col, j] and not iwork[free_col, nxt]):
                    lowest = d[j]
                    nxt = j
            if nxt < 0:
                return np.inf
            iwork[seen, nxt] = 1
            if iwork[free_col, nxt]:
                sink = nxt
            else:
                i = iwork[row4col, nxt]
                dist = lowest
        min_val = d[sink]
        for j in range(m):
            if iwork[seen, j]:
                v[j] -= min_val - d[j]
        u[start] += min_val
        for i in range(m):
            if iwork[scanned, i] and i != start:
                u[i] += min_val - d[sol[i]]
        iwork[free_col, sink] = 0
        iwork[free_row, start] = 0
        j = sink
        while True:
            i = iwork[pred, j]
            iwork[row4col, j] = i
            prev = sol[i]
            sol[i] = j
            j = prev
            if i == start:
                break
    for r in range(n):  # the cost: its cells in row order, summed in numpy's order (as _assignment_cost)
        d[r] = C[r, sol[r]]
    return np_sum(d, n)


@njit(cache=True)
def murty_arrays(C: np.ndarray, k: int, max_gap: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`murty` as arrays: costs (K,) increasing and columns (K, rows), from :func:`square_root`."""
    n, m = C.shape
    sol = np.empty(m, dtype=np.int64)
    u = np.empty(m)
    v = np.empty(m)
    cost0 = square_root(C, sol, u, v) if n else 0.0
    return murty_from(C, k, max_gap, sol, u, v, cost0)


@njit(cache=True)
def murty_from(
    C: np.ndarray, k: int, max_gap: float, sol: np.ndarray, u: np.ndarray, v: np.ndarray, cost0: float
) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` best assignments of ``C`` (costs (K,) increasing, columns (K, rows)) from its best one: the square
    assignment ``sol`` with duals (u, v) and cost ``cost0`` (+inf: there is none), as :func:`square_root` gives them.

    A subproblem is solved only when it reaches the top of the queue: until then it waits under a lower bound of
    its cost: its parent's cost plus the least reduced cost left in its row t (every path from row t starts with
    one such cell) plus the least reduced cost into its freed column from a row after t (row t may not take that
    column and the fixed rows are out, so the path ends with one such cell; with none, there is no assignment and
    the subproblem is dropped), less a margin far above the rounding of a sum. A solved subproblem leaves the queue
    only when its cost is at most every waiting bound, so the assignments come out in the order, and with the tie
    rule, of solving every subproblem as it is made; the subproblems that the k-th assignment makes unnecessary are
    never solved. A node is its parent, its row t and the column it forbids there (its other forbidden columns are those
    of its ancestors with the same t); a solved node keeps its square assignment and duals."""
    n, m = C.shape
    out_cost = np.empty(k)
    out_cols = np.empty((k, n), dtype=np.int64)
    if k <= 0:
        return out_cost[:0], out_cols[:0]
    if n == 0:
        out_cost[0] = 0.0
        return out_cost[:1], out_cols[:1]
    if cost0 == np.inf:
        return out_cost[:0], out_cols[:0]
    if k == 1:
        out_cost[0] = cost0
        out_cols[0] = sol[:n]
        return out_cost[:1], out_cols[:1]
    limit = cost0 + max_gap
    # solved nodes: square assignment and duals
    scap = 8
    s_sol = np.empty((scap, m), dtype=np.int64)
    s_u = np.empty((scap, m))
    s_v = np.empty((scap, m))
    s_sol[0] = sol
    s_u[0] = u
    s_v[0] = v
    used = np.zeros(m, dtype=np.bool_)
    n_slots = 1
    # nodes, numbered in the order made (the tie rule): key (cost once solved, else a lower bound)
    cap = 32
    keys = np.empty(cap)
    par = np.empty(cap, dtype=np.int64)
    row = np.empty(cap, dtype=np.int64)
    fcol = np.empty(cap, dtype=np.int64)
    slot = np.empty(cap, dtype=np.int64)  # its solved node's index, -1 while it waits under a bound
    heap = np.empty(cap, dtype=np.int64)  # binary min-heap of node indices by (key, index)
    keys[0], par[0], row[0], fcol[0], slot[0], heap[0] = cost0, -1, 0, -1, 0, 0
    n_heap, n_nodes, n_out = 1, 1, 0
    last = n - 1 if n == m else n  # square: with n - 1 rows fixed the last has no choice
    forbid = np.empty(m + 2, dtype=np.int64)  # a row has at most m forbidden columns
    # a subproblem's scratch (solved inline: a compiled call costs reference counts on every array it is passed)
    d = np.empty(m)  # path cost to each column
    pred = np.empty(m, dtype=np.int64)
    row4col = np.empty(m, dtype=np.int64)
    seen = np.empty(m, dtype=np.int64)
    scanned = np.empty(m, dtype=np.int64)
    front = np.empty(m, dtype=np.int64)
    cell_start, cell_col = _finite_cells(C)
    while n_heap > 0 and n_out < k:
        # the stores grow here, outside the inner loop, which has room for one more solved node and the children
        # of one more assignment (arrays reassigned inside a loop cost reference counts at every iteration)
        if n_slots == scap:
            scap *= 2
            a1 = np.empty((scap, m), dtype=np.int64)
            a1[:n_slots] = s_sol[:n_slots]
            a2 = np.empty((scap, m))
            a2[:n_slots] = s_u[:n_slots]
            a3 = np.empty((scap, m))
            a3[:n_slots] = s_v[:n_slots]
            s_sol, s_u, s_v = a1, a2, a3
        if n_nodes + last > cap:
            cap = max(2 * cap, n_nodes + last)
            keys2 = np.empty(cap)
            keys2[:n_nodes] = keys[:n_nodes]
            par2 = np.empty(cap, dtype=np.int64)
            par2[:n_nodes] = par[:n_nodes]
            row2 = np.empty(cap, dtype=np.int64)
            row2[:n_nodes] = row[:n_nodes]
            fcol2 = np.empty(cap, dtype=np.int64)
            fcol2[:n_nodes] = fcol[:n_nodes]
            slot2 = np.empty(cap, dtype=np.int64)
            slot2[:n_nodes] = slot[:n_nodes]
            heap2 = np.empty(cap, dtype=np.int64)
            heap2[:n_heap] = heap[:n_heap]
            keys, par, row, fcol, slot, heap = keys2, par2, row2, fcol2, slot2, heap2
        while n_heap > 0 and n_out < k and n_slots < scap and n_nodes + last <= cap:
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
            if slot[node] < 0:  # solve it from its parent's assignment and put it back under its cost
                t = row[node]
                nf = 0  # the columns forbidden to row t: the node's own and those of its ancestors with the same row
                x = node
                while x > 0 and row[x] == t:
                    forbid[nf] = fcol[x]
                    nf += 1
                    x = par[x]
                # its best assignment (one shortest augmenting path, module docstring) into row ns of the stores
                ps, ns = slot[par[node]], n_slots
                for i in range(m):
                    s_sol[ns, i] = s_sol[ps, i]
                    s_u[ns, i] = s_u[ps, i]
                    s_v[ns, i] = s_v[ps, i]
                    row4col[s_sol[ps, i]] = i
                    d[i] = np.inf
                    seen[i] = 0
                    scanned[i] = 0
                for i in range(t):  # the fixed rows' columns are out of the subproblem
                    seen[s_sol[ps, i]] = 1
                n_front = 0  # the columns reached (finite d) and not yet seen
                dummy_a = np.inf  # the least dist - u_i of the dummy rows scanned so far
                sink = s_sol[ps, t]
                i = t
                dist = 0.0
                reached = False
                while True:  # Dijkstra on the reduced costs (all >= 0) from row t to its freed column
                    scanned[i] = 1
                    if i < n:  # a real row relaxes its finite cells only
                        for q in range(cell_start[i], cell_start[i + 1]):
                            j = cell_col[q]
                            if seen[j]:
                                continue
                            c_ij = C[i, j]
                            if i == t:
                                banned = False
                                for f in range(nf):
                                    if forbid[f] == j:
                                        banned = True
                                        break
                                if banned:
                                    continue
                            red = dist + c_ij - s_u[ps, i] - s_v[ps, j]
                            if red < d[j]:
                                if d[j] == np.inf:
                                    front[n_front] = j
                                    n_front += 1
                                d[j] = red
                                pred[j] = i
                    else:  # a dummy row: r_j = a - v_j with a = dist - u_i, so a row whose a is no lower than an
                        # earlier dummy row's improves no column (subtracting v_j keeps the order) and is skipped
                        c_ij = 0.0
                        da = dist + c_ij - s_u[ps, i]
                        if da < dummy_a:
                            dummy_a = da
                            for j in range(m):
                                if seen[j]:
                                    continue
                                red = da - s_v[ps, j]
                                if red < d[j]:
                                    if d[j] == np.inf:
                                        front[n_front] = j
                                        n_front += 1
                                    d[j] = red
                                    pred[j] = i
                    if n_front == 0:  # row t cannot reach its freed column: no assignment
                        break
                    at = 0  # the next column: least path cost, the freed column first at equal cost, then lowest
                    nxt = front[0]
                    for q in range(1, n_front):
                        j = front[q]
                        if d[j] < d[nxt] or (d[j] == d[nxt] and (j == sink or (nxt != sink and j < nxt))):
                            at = q
                            nxt = j
                    n_front -= 1
                    front[at] = front[n_front]
                    seen[nxt] = 1
                    if nxt == sink:
                        reached = True
                        break
                    i = row4col[nxt]
                    dist = d[nxt]
                cost = np.inf
                if reached:
                    min_val = d[sink]
                    for j in range(m):  # the duals stay feasible, 0 reduced cost on the new pairs
                        if seen[j] and d[j] < np.inf:
                            s_v[ns, j] -= min_val - d[j]
                    s_u[ns, t] += min_val
                    for i in range(t + 1, m):
                        if scanned[i]:
                            s_u[ns, i] += min_val - d[s_sol[ps, i]]
                    j = sink
                    while True:
                        i = pred[j]
                        prev = s_sol[ns, i]
                        s_sol[ns, i] = j
                        j = prev
                        if i == t:
                            break
                    for i in range(n):  # its cells in row order, summed in numpy's order (as _assignment_cost)
                        d[i] = C[i, s_sol[ns, i]]
                    cost = np_sum(d, n)
                if cost < np.inf and cost <= limit:
                    slot[node] = n_slots
                    n_slots += 1
                    keys[node] = cost
                    q = n_heap  # back into the queue (sift up)
                    heap[q] = node
                    while q > 0 and _before(cost, node, keys[heap[(q - 1) // 2]], heap[(q - 1) // 2]):
                        heap[q] = heap[(q - 1) // 2]
                        q = (q - 1) // 2
                        heap[q] = node
                    n_heap += 1
                continue
            sl = slot[node]
            out_cost[n_out] = keys[node]
            for r in range(n):
                out_cols[n_out, r] = s_sol[sl, r]
            n_out += 1
            if n_out == k:
                break
            used[:] = False
            for r in range(row[node]):
                used[s_sol[sl, r]] = True
            for t in range(row[node], last):
                c_t = s_sol[sl, t]
                forbid[0] = c_t
                nf = 1
                x = node  # and in the node's own row, the columns forbidden there already
                while x > 0 and row[x] == t:
                    forbid[nf] = fcol[x]
                    nf += 1
                    x = par[x]
                lo_r = np.inf  # the least reduced cost of row t's cells left in the subproblem
                for j in range(m):
                    if used[j] or C[t, j] == np.inf:
                        continue
                    banned = False
                    for f in range(nf):
                        if forbid[f] == j:
                            banned = True
                            break
                    if not banned:
                        lo_r = min(lo_r, C[t, j] - s_u[sl, t] - s_v[sl, j])
                used[c_t] = True  # fixed for the next subproblems
                lo_c = np.inf  # the least reduced cost into the freed column c_t from a row after t
                for i in range(t + 1, m):
                    c_ic = C[i, c_t] if i < n else 0.0
                    if c_ic < np.inf:
                        lo_c = min(lo_c, c_ic - s_u[sl, i] - s_v[sl, c_t])
                bound = keys[node] + max(lo_r, 0.0) + max(lo_c, 0.0)
                bound -= 1e-9 * (1.0 + abs(bound))  # margin for rounding
                if bound < np.inf and bound <= limit:  # may be in the ranking: wait in the queue under the bound
                    keys[n_nodes], par[n_nodes], row[n_nodes], fcol[n_nodes], slot[n_nodes] = bound, node, t, c_t, -1
                    q = n_heap  # into the queue (sift up)
                    heap[q] = n_nodes
                    while q > 0 and _before(bound, n_nodes, keys[heap[(q - 1) // 2]], heap[(q - 1) // 2]):
                        heap[q] = heap[(q - 1) // 2]
                        q = (q - 1) // 2
                        heap[q] = n_nodes
                    n_heap += 1
                    n_nodes += 1
    return out_cost[:n_out], out_cols[:n_out]


def murty(C: np.ndarray, k: int, max_gap: float = np.inf) -> list[tuple[float, np.ndarray]]:
    """The (at most) ``k`` cheapest assignments of the cost matrix ``C`` (rows <= columns; +inf: forbidden), by
    increasing cost: a list of (cost, cols) with ``cols[r]`` the column of row r. Only assignments that cost at most
    ``max_gap`` more than the cheapest are returned (their ranking is unchanged: the search stops there)."""
    C = np.ascontiguousarray(C, dtype=float)
    if C.ndim != 2 or C.shape[0] > C.shape[1]:
        raise ValueError(f"Murty's algorithm needs no more rows than columns, got shape {C.shape}")
    costs, cols = murty_arrays(C, int(k), float(max_gap))
    return [(float(costs[s]), cols[s]) for s in range(len(costs))]
