"""The PMBM's global hypotheses (docs/method.md §10.3) against the plain assembly of the same pieces.

:func:`soabench.pmbm.association.global_hypotheses` keeps its solution sets in flat arrays, counts its output rows
before writing them in place, takes the repaired root directly when a choice is asked for one solution, and merges
the best sums on scratch arrays it reuses. The reference below builds the same result the straightforward way: a
list of (costs, choices) per cluster and distinct choice, Murty's ranking started for every choice, and
:func:`best_sums` per prior global hypothesis on fresh arrays. Both must give the same bits.
"""

from __future__ import annotations

import numpy as np
import pytest

from soabench.pmbm.association import (
    MISS,
    assignments_asked,
    best_sums,
    cluster_costs,
    cluster_solutions,
    flat_clusters,
    global_hypotheses,
)
from soabench.pmbm.murty import murty_from, repaired_root, square_root


def _reference(table, log_w, ks, T_flat, T_start, L_flat, L_start, base0, lm, ld, ln, max_gap):
    A, n = table.shape
    base = np.full(A, base0)
    fixed = np.full((A, n), MISS, dtype=np.int64)
    feasible = np.ones(A, dtype=bool)
    multi = [[] for _ in range(A)]  # (costs, choice, T) of the clusters with several solutions
    n_murty = 0
    for g in range(len(T_start) - 1):
        T, L = T_flat[T_start[g] : T_start[g + 1]], L_flat[L_start[g] : L_start[g + 1]]
        nT, nL, m = len(T), len(L), len(T) + len(L)
        reps: dict[tuple, int] = {}
        for a in range(A):  # distinct choices in order of first appearance
            reps.setdefault(tuple(table[a, T]), len(reps))
        k_u = np.zeros(len(reps), dtype=np.int64)
        for a in range(A):
            u = reps[tuple(table[a, T])]
            k_u[u] = max(k_u[u], ks[a])
        sets, prev, warm, C = [], None, False, None
        sol, u_, v_ = np.empty(m, dtype=np.int64), np.empty(m), np.empty(m)
        for key, u in reps.items():
            hs = np.array(key, dtype=np.int64)
            if nT > 1 and nL > 1:
                n_murty += 1
                if warm:
                    changed = np.flatnonzero(hs != prev)
                    C = C.copy()
                    C[:, changed] = lm[hs[changed]][None, :] - ld[np.ix_(hs[changed], L)].T
                    cost0 = repaired_root(C, changed, sol, u_, v_)
                else:
                    C = cluster_costs(hs, L, lm, ld, ln)
                    cost0 = square_root(C, sol, u_, v_)
                warm, prev = cost0 < np.inf, hs
                costs, cols = murty_from(C, int(k_u[u]), max_gap, sol, u_, v_, cost0)
                choice = np.full((len(costs), nT), MISS, dtype=np.int64)
                for s in range(len(costs)):
                    for row in range(nL):
                        if cols[s, row] < nT:
                            choice[s, cols[s, row]] = L[row]
                costs = costs - float(lm[hs].sum())
            else:
                costs, choice = cluster_solutions(hs, L, lm, ld, ln, int(k_u[u]), max_gap)
            sets.append((costs, choice))
        for a in range(A):
            costs, choice = sets[reps[tuple(table[a, T])]]
            if len(costs) == 0:
                feasible[a] = False
                base[a] += np.inf
            elif len(costs) == 1 or ks[a] == 1:
                base[a] += costs[0]
                fixed[a, T] = choice[0]
            else:
                multi[a].append((costs, choice, T))
    parent, choices, logs = [], [], []
    for a in range(A):
        if not feasible[a]:
            continue
        x = log_w[a] - base[a]
        if not multi[a]:
            parent.append(a), choices.append(fixed[a].copy()), logs.append(x)
            continue
        sums, idx = best_sums([c[: ks[a]] for c, _, _ in multi[a]], int(ks[a]))
        for b in range(len(sums)):
            row = fixed[a].copy()
            for j, (_, choice, T) in enumerate(multi[a]):
                row[T] = choice[idx[b, j]]
            parent.append(a), choices.append(row), logs.append(x - sums[b])
    return (np.array(parent, dtype=np.int64), np.array(choices, dtype=np.int64).reshape(-1, n),
            np.array(logs, dtype=float), n_murty)  # fmt: skip


def _problem(rng, ties: bool):
    """Tracks with one to three hypotheses, prior global hypotheses drawn from them (repeats included), gated pairs
    and likelihood factors (small integers when ``ties``, so equal costs abound)."""
    n = int(rng.integers(2, 9))
    n_h = rng.integers(1, 4, n)
    track = np.repeat(np.arange(n), n_h).astype(np.int64)
    first = np.concatenate([[0], np.cumsum(n_h)[:-1]])
    H, M = len(track), int(rng.integers(1, 9))
    A = int(rng.integers(1, 12))
    table = (first[None, :] + rng.integers(0, 3, (A, n)) % n_h[None, :]).astype(np.int64)
    log_w = rng.normal(0.0, 1.0, A)
    log_w -= np.logaddexp.reduce(log_w)

    def draw(shape):
        return -rng.integers(0, 3, shape).astype(float) if ties else rng.normal(-2.0, 1.0, shape)

    ld = np.where(rng.random((H, M)) < 0.5, draw((H, M)), -np.inf)
    return table, log_w, track, n, draw(H), ld, draw(M)


@pytest.mark.parametrize("ties", [False, True])
def test_global_hypotheses_equal_the_plain_assembly(ties):
    rng = np.random.default_rng(11 + ties)
    n_multi_rows = n_root_only = 0
    for trial in range(150):
        table, log_w, track, n, lm, ld, ln = _problem(rng, ties)
        M_max = (1, 3, 20, 100)[trial % 4]
        max_gap = (np.inf, 2.0)[trial % 2]
        ks = assignments_asked(log_w, M_max)
        T_flat, T_start, L_flat, L_start, base0 = flat_clusters(track, ld, n, ln)
        args = (table, log_w, ks, T_flat, T_start, L_flat, L_start, base0, lm, ld, ln, max_gap)
        got, want = global_hypotheses(*args), _reference(*args)
        for x, y in zip(got[:3], want[:3], strict=True):
            assert x.dtype == y.dtype and x.shape == y.shape
            assert x.tobytes() == y.tobytes()
        assert got[3] == want[3]
        n_multi_rows += len(got[0]) > len(np.unique(got[0]))
        n_root_only += M_max == 1 and got[3] > 0
    assert n_multi_rows > 20 and n_root_only > 5  # the combined and the root-only paths were both taken
