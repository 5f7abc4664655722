"""Murty's ranked assignments (docs/method.md §10.3; Murty 1968): the k cheapest assignments of a cost matrix with
no more rows than columns (every row gets a distinct column), each solved with
:func:`scipy.optimize.linear_sum_assignment`.

Forbidden cells are +inf. The best assignment is split into subproblems (Murty's partition): subproblem t keeps the
first t pairs of the assignment, forbids its pair t, and leaves the rest free; the cheapest open subproblem gives the
next assignment and is split the same way. Ties between assignments of equal cost are broken by the order in which
they were found, so the ranking is deterministic.
"""

from __future__ import annotations

import heapq

import numpy as np
from scipy.optimize import linear_sum_assignment


def _solve(C: np.ndarray) -> tuple[float, np.ndarray] | None:
    """(cost, column of each row) of the cheapest assignment of ``C``, or None when every assignment uses a
    forbidden cell."""
    try:
        rows, cols = linear_sum_assignment(C)
    except ValueError:  # scipy: "cost matrix is infeasible"
        return None
    cost = float(C[rows, cols].sum())
    return (cost, cols) if cost < np.inf else None


def murty(C: np.ndarray, k: int, max_gap: float = np.inf) -> list[tuple[float, np.ndarray]]:
    """The (at most) ``k`` cheapest assignments of the cost matrix ``C`` (rows <= columns; +inf: forbidden), by
    increasing cost: a list of (cost, cols) with ``cols[r]`` the column of row r. Only assignments that cost at most
    ``max_gap`` more than the cheapest are returned (their ranking is unchanged: the search stops there)."""
    C = np.asarray(C, dtype=float)
    n, n_cols = C.shape
    if n > n_cols:
        raise ValueError(f"Murty's algorithm needs no more rows than columns, got shape {C.shape}")
    out: list[tuple[float, np.ndarray]] = []
    if k <= 0:
        return out
    if n == 0:
        return [(0.0, np.zeros(0, dtype=np.int64))]
    first = _solve(C)
    if first is None:
        return out
    seq = 0
    limit = first[0] + max_gap
    # open subproblems: (cost, order found, cols, matrix, first free row)
    heap: list[tuple[float, int, np.ndarray, np.ndarray, int]] = [(first[0], seq, first[1], C, 0)]
    while heap and len(out) < k:
        cost, _, cols, M, t0 = heapq.heappop(heap)
        out.append((cost, cols))
        if len(out) == k:
            break
        forced = M.copy()
        for t in range(t0, n - 1 if n == n_cols else n):  # square: with n - 1 rows fixed the last has no choice
            c = cols[t]
            child = forced.copy()
            child[t, c] = np.inf
            sol = _solve(child)
            if sol is not None and sol[0] <= limit:
                seq += 1
                heapq.heappush(heap, (sol[0], seq, sol[1], child, t))
            keep = forced[t, c]  # fix the pair (t, c) for the next subproblems
            forced[t, :] = np.inf
            forced[:, c] = np.inf
            forced[t, c] = keep
    return out
