"""Global hypotheses of the PMBM update (docs/method.md §10.3): clusters, Murty's ranked assignments per cluster,
and their combination into the best new global hypotheses of each prior global hypothesis.

For a prior global hypothesis a (hypothesis a_i of each track i) and a cluster of tracks T and measurements L, the
assignment problem has one row per measurement of L and columns T then one new track per measurement of L; a
track whose column no row takes is missed. Measurement l to track i costs -ln l_det(i, a_i, l) + ln l_miss(i, a_i),
to its own new track -ln(kappa_l + e_l), to another new track +inf (forbidden); an assignment's cost plus
-sum_i ln l_miss(i, a_i) is minus the log of its likelihood factors (:func:`cluster_costs`). Each association is one
assignment: a square form with "no measurement" rows (whose cost-0 cells to the freed new-track columns can be
permuted) would list every association with k detected tracks k! times. A cluster's ranked
solutions are cached per choice of its tracks' hypotheses, so global hypotheses that differ only elsewhere share
them. Clusters are independent, so the best joint assignments are the best sums of one solution per cluster
(:func:`best_sums`).
"""

from __future__ import annotations

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()

from numba import njit  # noqa: E402

from soabench.metrics_kernels import np_sum  # noqa: E402
from soabench.pmbm.kernels import global_weights  # noqa: E402
from soabench.pmbm.murty import murty_from, repair, square_root  # noqa: E402
from soabench.pmbm.search import ranked_by_search  # noqa: E402

MISS = -1  #: a track's choice when no measurement is assigned to it
#: :func:`soabench.pmbm.search.ranked_by_search`'s limits, beyond which Murty's algorithm ranks instead: the branches
#: it may visit, SEARCH_VISITS (k |L| + 16) (about Murty's own work, which grows as k |L|), and the product of its
#: rows' numbers of finite cells
SEARCH_VISITS = 16
SEARCH_MAX_PRODUCT = 1e6


@njit(cache=True)
def _components(track, hh, ll, n, M):
    """Connected components of the graph of tracks 0..n-1 and measurements n..n+M-1 with the edges
    (track[hh[e]], n + ll[e]) (union-find); returns each node's component as the smallest node in it."""
    parent = np.arange(n + M)
    for e in range(hh.shape[0]):
        a, b = track[hh[e]], n + ll[e]
        while parent[a] != a:
            a = parent[a]
        while parent[b] != b:
            b = parent[b]
        if a < b:
            parent[b] = a
        elif b < a:
            parent[a] = b
    for x in range(n + M):
        r = x
        while parent[r] != r:
            r = parent[r]
        parent[x] = r
    return parent


def clusters(track: np.ndarray, gated: np.ndarray, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Tracks and measurements that share no gated pair, in any hypothesis, fall into different clusters.

    Args:
        track: (H,) the track of each hypothesis; gated: (H, M) True where hypothesis h may have generated z_l.
    Returns:
        (tracks, measurements) index arrays of every cluster, in increasing order of their smallest member
        (tracks first: a cluster without tracks is one measurement that no track gates).
    """
    M = gated.shape[1]
    hh, ll = np.nonzero(gated)
    comp = _components(np.ascontiguousarray(track, dtype=np.int64), hh.astype(np.int64), ll.astype(np.int64), n, M)
    order = np.argsort(comp, kind="stable")
    roots, first = np.unique(comp[order], return_index=True)
    bounds = np.append(first, len(order))
    out = []
    for g in range(len(roots)):
        members = order[bounds[g] : bounds[g + 1]]
        out.append((members[members < n], members[members >= n] - n))
    return out


@njit(cache=True)
def flat_clusters(track, log_l_det, n, log_new):
    """:func:`clusters` as flat arrays, with the gated pairs those of a finite ``log_l_det`` (H, M): the tracked
    clusters' tracks ``T_flat[T_start[g]:T_start[g + 1]]`` and measurements (likewise ``L_*``), in increasing order
    of their smallest member, and ``base0``: minus the summed ``log_new`` of the measurements no track gates (in
    increasing order, numpy's summation); the arguments of :func:`global_hypotheses` that
    :func:`new_global_hypotheses` builds from :func:`clusters`. A cluster has tracks iff its smallest member is a
    track (< n)."""
    H, M = log_l_det.shape
    n_e = 0
    for h in range(H):
        for ll in range(M):
            if np.isfinite(log_l_det[h, ll]):
                n_e += 1
    hh = np.empty(n_e, dtype=np.int64)
    le = np.empty(n_e, dtype=np.int64)
    e = 0
    for h in range(H):  # row-major, as np.nonzero lists them
        for ll in range(M):
            if np.isfinite(log_l_det[h, ll]):
                hh[e] = h
                le[e] = ll
                e += 1
    comp = _components(track, hh, le, n, M)
    slot = np.full(n + M, -1, dtype=np.int64)  # cluster index of each root with tracks
    G = 0
    for x in range(n):
        if comp[x] == x:
            slot[x] = G
            G += 1
    n_T = np.zeros(G, dtype=np.int64)
    n_L = np.zeros(G, dtype=np.int64)
    n_lone = 0
    for x in range(n + M):
        g = slot[comp[x]]
        if g < 0:
            n_lone += 1
        elif x < n:
            n_T[g] += 1
        else:
            n_L[g] += 1
    T_start = np.zeros(G + 1, dtype=np.int64)
    L_start = np.zeros(G + 1, dtype=np.int64)
    for g in range(G):
        T_start[g + 1] = T_start[g] + n_T[g]
        L_start[g + 1] = L_start[g] + n_L[g]
    T_flat = np.empty(T_start[G], dtype=np.int64)
    L_flat = np.empty(L_start[G], dtype=np.int64)
    lone = np.empty(n_lone)
    fill_T = T_start[:G].copy()
    fill_L = L_start[:G].copy()
    q = 0
    for x in range(n + M):  # members in increasing order
        g = slot[comp[x]]
        if g < 0:
            lone[q] = log_new[x - n]
            q += 1
        elif x < n:
            T_flat[fill_T[g]] = x
            fill_T[g] += 1
        else:
            L_flat[fill_L[g]] = x - n
            fill_L[g] += 1
    return T_flat, T_start, L_flat, L_start, (-np_sum(lone, n_lone) if n_lone else 0.0)


@njit(cache=True)
def cluster_costs(
    hs: np.ndarray, L: np.ndarray, log_l_miss: np.ndarray, log_l_det: np.ndarray, log_new: np.ndarray
) -> np.ndarray:
    """The (|L|, |T| + |L|) cost matrix of one cluster (module docstring): ``hs`` the chosen hypothesis of each of
    its tracks, ``L`` its measurements; +inf marks a forbidden cell. The missed factors (floored, never 0) make the
    track costs finite wherever the detection factor is positive."""
    nT, nL = hs.shape[0], L.shape[0]
    C = np.full((nL, nT + nL), np.inf)
    for ll in range(nL):
        for i in range(nT):
            C[ll, i] = log_l_miss[hs[i]] - log_l_det[hs[i], L[ll]]
        C[ll, nT + ll] = -log_new[L[ll]]
    return C


@njit(cache=True)
def _sum_at(x: np.ndarray, idx: np.ndarray) -> float:
    """``x[idx].sum()`` in numpy's order."""
    return np_sum(x[idx], idx.shape[0])


@njit(cache=True)
def cluster_solutions(
    hs: np.ndarray,
    L: np.ndarray,
    log_l_miss: np.ndarray,
    log_l_det: np.ndarray,
    log_new: np.ndarray,
    k: int,
    max_gap: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The (at most) ``k`` best solutions of a cluster with measurements ``L`` and its tracks in hypotheses ``hs``:
    costs (K,) increasing, and the choice of each of its tracks (K, |T|): a measurement index or :data:`MISS`.

    A cluster with one track or at most one measurement has few associations: they are listed and sorted (ties in
    the order listed: missed first, then by measurement or track). Otherwise Murty's algorithm ranks the
    assignments of :func:`cluster_costs`. Solutions costing more than ``max_gap`` above the best are left out."""
    nT, nL = hs.shape[0], L.shape[0]
    all_miss = -_sum_at(log_l_miss, hs)
    if nT == 1 or nL <= 1:
        all_new = -_sum_at(log_new, L)
        if nT == 1:  # missed, or detected by one of L (the others to their new tracks)
            costs = np.empty(nL + 1)
            choice = np.full((nL + 1, 1), MISS, dtype=np.int64)
            costs[0] = all_miss + all_new
            n_opt = 1
            for ll in range(nL):
                det = log_l_det[hs[0], L[ll]]
                if np.isfinite(det):
                    costs[n_opt] = all_new + log_new[L[ll]] - det
                    choice[n_opt, 0] = L[ll]
                    n_opt += 1
        elif nL == 0:  # every track missed
            costs = np.full(1, all_miss)
            choice = np.full((1, nT), MISS, dtype=np.int64)
            n_opt = 1
        else:  # one measurement: to its new track, or to one of the tracks
            ell = L[0]
            costs = np.empty(nT + 1)
            choice = np.full((nT + 1, nT), MISS, dtype=np.int64)
            costs[0] = all_miss + all_new
            n_opt = 1
            for i in range(nT):
                det = log_l_det[hs[i], ell]
                if np.isfinite(det):
                    costs[n_opt] = all_miss + log_l_miss[hs[i]] - det
                    choice[n_opt, i] = ell
                    n_opt += 1
        costs, choice = costs[:n_opt], choice[:n_opt]
        order = np.argsort(costs, kind="mergesort")
        limit = costs[order[0]] + max_gap
        n_keep = 0
        while n_keep < min(k, n_opt) and costs[order[n_keep]] <= limit:
            n_keep += 1
        order = order[:n_keep]
        out_choice = np.empty((n_keep, choice.shape[1]), dtype=np.int64)
        for s in range(n_keep):
            out_choice[s] = choice[order[s]]
        return costs[order], out_choice
    C = cluster_costs(hs, L, log_l_miss, log_l_det, log_new)
    m = C.shape[1]
    sol, u, v = np.empty(m, dtype=np.int64), np.empty(m), np.empty(m)
    return _ranked(C, L, nT, k, max_gap, sol, u, v, square_root(C, sol, u, v), all_miss)


@njit(cache=True)
def _ranked(
    C: np.ndarray,
    L: np.ndarray,
    nT: int,
    k: int,
    max_gap: float,
    sol: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    cost0: float,
    all_miss: float,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`cluster_solutions` by Murty's algorithm over the cost matrix ``C`` from its best assignment (sol, u, v)
    of cost ``cost0`` (:func:`soabench.pmbm.murty.murty_from`)."""
    sol_costs, cols = murty_from(C, k, max_gap, sol, u, v, cost0)
    K = sol_costs.shape[0]
    nL = L.shape[0]
    choice = np.full((K, nT), MISS, dtype=np.int64)
    for s in range(K):
        for row in range(nL):
            if cols[s, row] < nT:  # measurement L[row] assigned to a track column
                choice[s, cols[s, row]] = L[row]
    return sol_costs - (-all_miss), choice


def unique_rows(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of the int array ``x`` (A, n) in lexicographic order and the index of each row among them:
    ``np.unique(x, axis=0, return_inverse=True)`` without its structured-view overhead."""
    A = x.shape[0]
    if x.shape[1] == 0 or A <= 1:
        return x[:1], np.zeros(A, dtype=np.int64)
    order = np.lexsort(x.T[::-1])
    xs = x[order]
    new = np.empty(A, dtype=bool)
    new[0] = True
    new[1:] = (xs[1:] != xs[:-1]).any(axis=1)
    inv = np.empty(A, dtype=np.int64)
    inv[order] = np.cumsum(new) - 1
    return xs[new], inv


@njit(cache=True)
def _merge_step(
    total: np.ndarray,
    idx: np.ndarray,
    nt: int,
    c: np.ndarray,
    c0: int,
    nc: int,
    j: int,
    K: int,
    total2: np.ndarray,
    idx2: np.ndarray,
    hs: np.ndarray,
    heap: np.ndarray,
) -> None:
    """One term of :func:`best_sums`: the ``K`` smallest of total[a] + c[c0 + b] (a < nt, b < nc; ``total`` sorted)
    into ``total2`` and ``idx2`` (columns 0..j-1 those of row a of ``idx``, column j set to b), by a merge of the
    rows a, each increasing in b, through a heap of the rows' next entries ordered by (sum, a, b). Scratch: ``hs``
    (>= nt) row a's next sum, ``heap`` (2, >= nt) the heap order and row a's next b."""
    for a in range(nt):  # rows in order: already a heap by (sum, a) when the sums are sorted
        hs[a] = total[a] + c[c0]
        heap[1, a] = 0
        heap[0, a] = a
    n_heap = nt if nc > 0 else 0
    for r in range(K):
        e = heap[0, 0]
        total2[r] = hs[e]
        for q in range(j):  # the earlier terms' indices (the later columns are set by their own steps)
            idx2[r, q] = idx[e, q]
        idx2[r, j] = heap[1, e]
        heap[1, e] += 1
        if heap[1, e] < nc:
            hs[e] = total[e] + c[c0 + heap[1, e]]
        else:
            n_heap -= 1
            heap[0, 0] = heap[0, n_heap]
        p = 0  # sift down; x before y by (sum, a): a row's a is its index, and two entries never share a row
        while True:
            best = p
            q = 2 * p + 1
            if q < n_heap:
                x, y = heap[0, q], heap[0, best]
                if hs[x] < hs[y] or (hs[x] == hs[y] and x < y):
                    best = q
            q = 2 * p + 2
            if q < n_heap:
                x, y = heap[0, q], heap[0, best]
                if hs[x] < hs[y] or (hs[x] == hs[y] and x < y):
                    best = q
            if best == p:
                break
            heap[0, p], heap[0, best] = heap[0, best], heap[0, p]
            p = best


def best_sums(costs: list, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest sums of one entry of each sorted cost array: (sums (K,), index of each term (K, len)).

    The terms are added one array at a time: the k smallest of total[a] + c[b] (total: the sorted sums so far) by
    a merge of the rows a, each increasing in b, through a heap of the rows' next entries (:func:`_merge_step`,
    which :func:`global_hypotheses` runs on its own buffers). Equal sums keep the order of the (earlier terms' rank,
    this term's rank) pairs, i.e. that of a stable sort of every sum."""
    J = len(costs)
    total, idx = np.zeros(1), np.zeros((1, J), dtype=np.int64)
    for j in range(J):
        c = np.ascontiguousarray(costs[j], dtype=float)
        nt = min(total.shape[0], k)
        K = min(k, nt * c.shape[0])
        total2, idx2 = np.empty(K), np.empty((K, J), dtype=np.int64)
        hs, heap = np.empty(nt), np.empty((2, nt), dtype=np.int64)
        _merge_step(total, idx, nt, c, 0, c.shape[0], j, K, total2, idx2, hs, heap)
        total, idx = total2, idx2
    return total, idx


@njit(cache=True)
def global_hypotheses(
    table: np.ndarray,
    log_w: np.ndarray,
    ks: np.ndarray,
    T_flat: np.ndarray,
    T_start: np.ndarray,
    L_flat: np.ndarray,
    L_start: np.ndarray,
    base0: float,
    log_l_miss: np.ndarray,
    log_l_det: np.ndarray,
    log_new: np.ndarray,
    max_gap: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """:func:`new_global_hypotheses` on the clusters with tracks (T and L of cluster g: ``T_flat[T_start[g]:
    T_start[g + 1]]``, likewise L); ``base0``: minus the log factors of the measurements no track gates. Also
    returns the number of Murty runs.

    The solution sets (one per cluster and distinct choice of its tracks' hypotheses) are kept flat: set s has the
    costs ``sol_cost[sol_start[s]:sol_start[s + 1]]`` and the choice of track i of its cluster in its solution b at
    ``sol_choice[ch_start[s] + b |T| + i]``. The output rows are counted first and written in place; the scratch
    arrays are allocated once per call."""
    A, n = table.shape
    G = T_start.shape[0] - 1
    base = np.full(A, base0)
    fixed = np.full((A, n), MISS, dtype=np.int64)  # the choices of the single-solution clusters
    feasible = np.ones(A, dtype=np.bool_)
    n_multi = np.zeros(A, dtype=np.int64)
    multi = np.empty((A, max(G, 1)), dtype=np.int64)  # the solution sets combined per a
    n_sets = 0
    set_g = np.empty(A * G + 1, dtype=np.int64)  # each set's cluster
    sol_start = np.zeros(A * G + 2, dtype=np.int64)  # each set's first solution (costs)
    ch_start = np.zeros(A * G + 2, dtype=np.int64)  # each set's first choice entry
    sol_cost = np.empty(64)
    sol_choice = np.empty(256, dtype=np.int64)
    n_murty = 0
    inv = np.empty(A, dtype=np.int64)
    reps = np.empty(A, dtype=np.int64)
    hashes = np.empty(A, dtype=np.int64)
    nT_max = 0
    for g in range(G):
        nT_max = max(nT_max, T_start[g + 1] - T_start[g])
    hs = np.empty(nT_max, dtype=np.int64)
    prev = np.empty(nT_max, dtype=np.int64)
    changed = np.empty(nT_max, dtype=np.int64)
    miss_terms = np.empty(nT_max)
    all_miss = 0.0
    root_only = False
    costs = np.empty(0)
    cols = np.empty((0, 0), dtype=np.int64)
    choice = np.empty((0, 0), dtype=np.int64)
    for g in range(G):
        T = T_flat[T_start[g] : T_start[g + 1]]
        L = L_flat[L_start[g] : L_start[g + 1]]
        nT, nL = T.shape[0], L.shape[0]
        # distinct choices of the cluster's tracks' hypotheses among the prior global hypotheses, in order of first
        # appearance (a row is compared in full only with the earlier ones of equal hash)
        n_u = 0
        for a in range(A):
            h = np.int64(nT)
            for i in range(nT):
                h = h * np.int64(1000003) + table[a, T[i]]
            u = 0
            while u < n_u:
                if hashes[u] == h:
                    same = True
                    for i in range(nT):
                        if table[a, T[i]] != table[reps[u], T[i]]:
                            same = False
                            break
                    if same:
                        break
                u += 1
            if u == n_u:
                reps[n_u] = a
                hashes[n_u] = h
                n_u += 1
            inv[a] = u
        k_u = np.zeros(n_u, dtype=np.int64)
        for a in range(A):
            k_u[inv[a]] = max(k_u[inv[a]], ks[a])
        first_set = n_sets
        # room for every choice's solutions (at most k_u each), made here: arrays reassigned in the loop below would
        # take reference counts at each of its iterations
        n_room = 0
        for u in range(n_u):
            n_room += k_u[u]
        p = sol_start[n_sets]
        q = ch_start[n_sets]
        if p + n_room > sol_cost.shape[0]:
            grown = np.empty(2 * (p + n_room))
            grown[:p] = sol_cost[:p]
            sol_cost = grown
        if q + n_room * nT > sol_choice.shape[0]:
            grown_ch = np.empty(2 * (q + n_room * nT), dtype=np.int64)
            grown_ch[:q] = sol_choice[:q]
            sol_choice = grown_ch
        # Murty's best assignment for a choice is repaired from the previous choice's (they differ in a few columns);
        # its ranking comes from a search (:func:`soabench.pmbm.search.ranked_by_search`) where that is sure to agree
        m = nT + nL
        r_sol, r_u, r_v = np.empty(m, dtype=np.int64), np.empty(m), np.empty(m)
        r_iwork, r_d = np.empty((6, m), dtype=np.int64), np.empty(m)  # the repair's scratch
        C = np.empty((0, 0))
        warm = False
        for u in range(n_u):
            for i in range(nT):
                hs[i] = table[reps[u], T[i]]
            if nT > 1 and nL > 1:
                n_murty += 1
                if warm:  # the previous choice's matrix with the changed track columns rewritten
                    n_ch = 0
                    for i in range(nT):
                        if hs[i] != prev[i]:
                            changed[n_ch] = i
                            n_ch += 1
                            for ll in range(nL):
                                C[ll, i] = log_l_miss[hs[i]] - log_l_det[hs[i], L[ll]]
                    cost0 = repair(C, changed, n_ch, r_sol, r_u, r_v, r_iwork, r_d)
                else:
                    C = cluster_costs(hs[:nT], L, log_l_miss, log_l_det, log_new)
                    cost0 = square_root(C, r_sol, r_u, r_v)
                warm = cost0 < np.inf
                for i in range(nT):
                    prev[i] = hs[i]
                    miss_terms[i] = log_l_miss[hs[i]]
                all_miss = -np_sum(miss_terms, nT)
                root_only = k_u[u] == 1 or cost0 == np.inf  # Murty's first assignment is the root (none: +inf)
                if root_only:
                    K = 1 if cost0 < np.inf else 0
                else:
                    budget = SEARCH_VISITS * (k_u[u] * nL + 16)
                    found, costs, cols = ranked_by_search(C, k_u[u], max_gap, budget, SEARCH_MAX_PRODUCT)
                    if not found:
                        costs, cols = murty_from(C, k_u[u], max_gap, r_sol, r_u, r_v, cost0)
                    K = costs.shape[0]
            else:
                costs, choice = cluster_solutions(hs[:nT], L, log_l_miss, log_l_det, log_new, k_u[u], max_gap)
                K = costs.shape[0]
            p = sol_start[n_sets]  # append the set (room made above)
            q = ch_start[n_sets]
            if nT > 1 and nL > 1:  # Murty's columns to the tracks' choices (cost: the missed factors added back)
                for b in range(K):
                    sol_cost[p + b] = (cost0 if root_only else costs[b]) - (-all_miss)
                    for i in range(nT):
                        sol_choice[q + b * nT + i] = MISS
                    for row in range(nL):
                        col = r_sol[row] if root_only else cols[b, row]
                        if col < nT:  # measurement L[row] assigned to a track column
                            sol_choice[q + b * nT + col] = L[row]
            else:
                for b in range(K):
                    sol_cost[p + b] = costs[b]
                    for i in range(nT):
                        sol_choice[q + b * nT + i] = choice[b, i]
            set_g[n_sets] = g
            sol_start[n_sets + 1] = p + K
            ch_start[n_sets + 1] = q + K * nT
            n_sets += 1
        for a in range(A):
            s = first_set + inv[a]
            p = sol_start[s]
            K = sol_start[s + 1] - p
            if K == 0:
                feasible[a] = False
                base[a] += np.inf
            elif K == 1 or ks[a] == 1:
                base[a] += sol_cost[p]
                q = ch_start[s]
                for i in range(nT):
                    fixed[a, T[i]] = sol_choice[q + i]
            else:
                multi[a, n_multi[a]] = s
                n_multi[a] += 1
    # the number of rows of each prior global hypothesis: min(k, product of its sets' sizes, each cut at k), as
    # :func:`best_sums` gives them
    n_rows = 0
    k_max = 1
    for a in range(A):
        if not feasible[a]:
            continue
        B = 1
        for j in range(n_multi[a]):
            s = multi[a, j]
            B = min(ks[a], B * min(sol_start[s + 1] - sol_start[s], ks[a]))
        n_rows += B
        k_max = max(k_max, ks[a])
    parent = np.empty(n_rows, dtype=np.int64)
    choice_out = np.empty((n_rows, n), dtype=np.int64)
    log_out = np.empty(n_rows)
    G1 = max(G, 1)
    total, total2 = np.zeros(k_max), np.empty(k_max)
    idx, idx2 = np.zeros((k_max, G1), dtype=np.int64), np.empty((k_max, G1), dtype=np.int64)
    h_sum, heap = np.empty(k_max), np.empty((2, k_max), dtype=np.int64)
    r = 0
    for a in range(A):
        if not feasible[a]:
            continue
        x = log_w[a] - base[a]
        k = ks[a]
        B = 1
        total[0] = 0.0
        for j in range(n_multi[a]):  # the k best sums of one solution of each multi-solution set
            s = multi[a, j]
            p = sol_start[s]
            nc = min(sol_start[s + 1] - p, k)
            nt = min(B, k)
            K = min(k, nt * nc)
            _merge_step(total, idx, nt, sol_cost, p, nc, j, K, total2, idx2, h_sum, heap)
            for b in range(K):  # copied back (swapping the arrays would take reference counts at every a)
                total[b] = total2[b]
                for e in range(j + 1):
                    idx[b, e] = idx2[b, e]
            B = K
        for b in range(B):
            parent[r] = a
            for i in range(n):
                choice_out[r, i] = fixed[a, i]
            for j in range(n_multi[a]):
                s = multi[a, j]
                g = set_g[s]
                nT = T_start[g + 1] - T_start[g]
                q = ch_start[s] + idx[b, j] * nT
                for i in range(nT):
                    choice_out[r, T_flat[T_start[g] + i]] = sol_choice[q + i]
            log_out[r] = x - total[b] if n_multi[a] else x
            r += 1
    return parent, choice_out, log_out, n_murty


def new_global_hypotheses(
    table: np.ndarray,
    log_w: np.ndarray,
    groups: list[tuple[np.ndarray, np.ndarray]],
    log_l_miss: np.ndarray,
    log_l_det: np.ndarray,
    log_new: np.ndarray,
    M_max: int,
    max_gap: float = np.inf,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """For each prior global hypothesis a, its ceil(M_max w_a) best assignments (at least one when it has any).

    Returns (parent (B,), choice (B, n): each track's measurement or :data:`MISS`, log weight (B,) unnormalised:
    log w_a minus the assignment cost, the number of Murty runs). Measurements no track takes go to their new
    tracks. Each cluster is solved once per distinct choice of its tracks' hypotheses among the prior global
    hypotheses (with the largest k that any of them asks); a cluster with one solution for a global hypothesis adds
    its cost and choice to every one of that hypothesis's assignments, and only the clusters with several solutions
    are combined by :func:`best_sums`. ``max_gap``: solutions costing more than this above their cluster's best are
    not searched for: a global hypothesis built on one weighs at most exp(-max_gap) times its parent's best child,
    so with max_gap = -ln(w_floor) it could never reach the weight floor.
    """
    A, n = table.shape
    lone = [L for T, L in groups if len(T) == 0]
    base0 = -float(log_new[np.concatenate(lone)].sum()) if lone else 0.0
    ks = assignments_asked(log_w, M_max)
    tracked = [(T, L) for T, L in groups if len(T)]
    T_start = _segments([len(T) for T, _ in tracked])
    L_start = _segments([len(L) for _, L in tracked])
    T_flat = np.concatenate([T for T, _ in tracked]).astype(np.int64) if tracked else np.zeros(0, dtype=np.int64)
    L_flat = np.concatenate([L for _, L in tracked]).astype(np.int64) if tracked else np.zeros(0, dtype=np.int64)
    return global_hypotheses(
        np.ascontiguousarray(table, dtype=np.int64), np.ascontiguousarray(log_w, dtype=float), ks, T_flat, T_start,
        L_flat, L_start, base0, np.ascontiguousarray(log_l_miss, dtype=float),
        np.ascontiguousarray(log_l_det, dtype=float), np.ascontiguousarray(log_new, dtype=float), float(max_gap),
    )  # fmt: skip


def assignments_asked(log_w: np.ndarray, M_max: int) -> np.ndarray:
    """(A,) int64: ceil(M_max w_a) for each prior global hypothesis, at least 1, at most M_max (w_a by
    :func:`soabench.pmbm.kernels.global_weights`, the exp of the compiled twin in
    :func:`soabench.pmbm.cycle.association_inputs`)."""
    w = global_weights(np.ascontiguousarray(log_w, dtype=float))
    return np.maximum(1, np.minimum(M_max, np.ceil(M_max * w - 1e-9))).astype(np.int64)


def _segments(counts: list[int]) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts, dtype=np.int64)]).astype(np.int64)
