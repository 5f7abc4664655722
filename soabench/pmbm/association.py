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

from soabench.pmbm.murty import murty  # noqa: E402

MISS = -1  #: a track's choice when no measurement is assigned to it


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


def cluster_costs(
    hs: np.ndarray, L: np.ndarray, log_l_miss: np.ndarray, log_l_det: np.ndarray, log_new: np.ndarray
) -> np.ndarray:
    """The (|L|, |T| + |L|) cost matrix of one cluster (module docstring): ``hs`` the chosen hypothesis of each of
    its tracks, ``L`` its measurements; +inf marks a forbidden cell. The missed factors (floored, never 0) make the
    track costs finite wherever the detection factor is positive."""
    nT, nL = len(hs), len(L)
    C = np.full((nL, nT + nL), np.inf)
    C[:, :nT] = (log_l_miss[hs][:, None] - log_l_det[hs][:, L]).T
    idx = np.arange(nL)
    C[idx, nT + idx] = -log_new[L]
    return C


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


def best_sums(costs: list[np.ndarray], k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest sums of one entry of each sorted cost array: (sums (K,), index of each term (K, len))."""
    total = np.zeros(1)
    idx = np.zeros((1, len(costs)), dtype=np.int64)
    for j, c in enumerate(costs):
        s = (total[:, None] + c[None, :]).ravel()
        order = np.argsort(s, kind="stable")[:k]
        a, b = np.divmod(order, len(c))
        total = s[order]
        idx = idx[a]
        idx[:, j] = b
    return total, idx


class ClusterSolver:
    """Ranked solutions of each cluster for a given choice of its tracks' hypotheses, cached (module docstring).

    ``max_gap``: solutions costing more than this above the cluster's best are not searched for. A global
    hypothesis built on such a solution weighs at most exp(-max_gap) times its parent's best child, so with
    max_gap = -ln(w_floor) it could never reach the weight floor."""

    def __init__(
        self,
        groups: list[tuple[np.ndarray, np.ndarray]],
        log_l_miss: np.ndarray,
        log_l_det: np.ndarray,
        log_new: np.ndarray,
        max_gap: float = np.inf,
    ) -> None:
        self.groups = groups
        self.max_gap = max_gap
        self.log_l_miss, self.log_l_det, self.log_new = log_l_miss, log_l_det, log_new
        self._cache: dict[tuple, tuple[int, np.ndarray, np.ndarray]] = {}
        self.n_murty = 0  #: Murty runs so far

    def _options(self, hs: np.ndarray, L: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every association of a cluster with one track or one measurement (no measurement: every track missed),
        unsorted: costs (K,) and choices (K, |T|)."""
        lm, ld, ln = self.log_l_miss, self.log_l_det, self.log_new
        nT = len(hs)
        all_new, all_miss = -float(ln[L].sum()), -float(lm[hs].sum())
        if nT == 1:  # missed, or detected by one of L (the others to their new tracks)
            det = ld[hs[0], L]
            ok = np.flatnonzero(np.isfinite(det))
            costs = np.concatenate([[all_miss + all_new], all_new + ln[L[ok]] - det[ok]])
            return costs, np.concatenate([[MISS], L[ok]])[:, None]
        ell = L[0] if len(L) else -1  # one measurement: to its new track, or to one of the tracks
        if ell < 0:
            return np.array([all_miss]), np.full((1, nT), MISS, dtype=np.int64)
        det = ld[hs, ell]
        ok = np.flatnonzero(np.isfinite(det))
        costs = np.concatenate([[all_miss + all_new], all_miss + lm[hs[ok]] - det[ok]])
        choice = np.full((1 + len(ok), nT), MISS, dtype=np.int64)
        choice[1 + np.arange(len(ok)), ok] = ell
        return costs, choice

    def solve(self, c: int, hs: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The (at most) ``k`` best solutions of cluster ``c`` with its tracks in hypotheses ``hs``: costs (K,)
        increasing, and the choice of each of its tracks (K, |T|): a measurement index or :data:`MISS`."""
        T, L = self.groups[c]
        key = (c, hs.tobytes())
        hit = self._cache.get(key)
        if hit is not None and (hit[0] >= k or len(hit[1]) < hit[0]):  # enough, or every solution already found
            return hit[1][:k], hit[2][:k]
        nT, nL = len(T), len(L)
        lm, ld, ln = self.log_l_miss, self.log_l_det, self.log_new
        if nT == 1 or nL <= 1:  # one track or at most one measurement: the options are few, list them
            costs, choice = self._options(hs, L)
            order = np.argsort(costs, kind="stable")
            order = order[costs[order] <= costs[order[0]] + self.max_gap][:k]
            costs, choice = costs[order], choice[order]
        else:
            sols = murty(cluster_costs(hs, L, lm, ld, ln), k, self.max_gap)
            self.n_murty += 1
            costs = np.array([s[0] for s in sols]) - float(lm[hs].sum())
            choice = np.full((len(sols), nT), MISS, dtype=np.int64)
            for s, (_, cols) in enumerate(sols):
                det = cols < nT  # rows (measurements) assigned to a track column
                choice[s, cols[det]] = L[det]
        self._cache[key] = (k, costs, choice)
        return costs, choice


def new_global_hypotheses(
    table: np.ndarray,
    log_w: np.ndarray,
    groups: list[tuple[np.ndarray, np.ndarray]],
    solver: ClusterSolver,
    M_max: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each prior global hypothesis a, its ceil(M_max w_a) best assignments (at least one when it has any).

    Returns (parent (B,), choice (B, n): each track's measurement or :data:`MISS`, log weight (B,) unnormalised:
    log w_a minus the assignment cost). Measurements no track takes go to their new tracks. Each cluster is solved
    once per distinct choice of its tracks' hypotheses among the prior global hypotheses (with the largest k that
    any of them asks); a cluster with one solution for a global hypothesis adds its cost and choice to every one of
    that hypothesis's assignments, and only the clusters with several solutions are combined by :func:`best_sums`.
    """
    A, n = table.shape
    lone = [L for T, L in groups if len(T) == 0]
    base = np.full(A, -float(solver.log_new[np.concatenate(lone)].sum()) if lone else 0.0)
    ks = np.maximum(1, np.minimum(M_max, np.ceil(M_max * np.exp(log_w) - 1e-9))).astype(np.int64)
    fixed = np.full((A, n), MISS, dtype=np.int64)  # the choices of the single-solution clusters
    feasible = np.ones(A, dtype=bool)
    multi: list[list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = [[] for _ in range(A)]
    for c, (T, _) in enumerate(groups):
        if len(T) == 0:
            continue
        local = table[:, T]
        uniq, inv = unique_rows(local)
        k_u = np.zeros(len(uniq), dtype=np.int64)
        np.maximum.at(k_u, inv, ks)
        sols = [solver.solve(c, uniq[u], int(k_u[u])) for u in range(len(uniq))]
        n_sol = np.array([len(s[0]) for s in sols])
        costs0 = np.array([s[0][0] if len(s[0]) else np.inf for s in sols])
        feasible &= n_sol[inv] > 0
        single = (n_sol[inv] == 1) | (ks == 1)
        base[single] += costs0[inv[single]]
        first = np.stack([s[1][0] if len(s[0]) else np.full(len(T), MISS, dtype=np.int64) for s in sols])
        rows = np.flatnonzero(single)
        fixed[np.ix_(rows, T)] = first[inv[rows]]
        for a in np.flatnonzero(~single):
            multi[a].append((T, *sols[inv[a]]))
    parents, choices, logs = [], [], []
    for a in np.flatnonzero(feasible):
        if not multi[a]:
            parents.append(np.array([a]))
            choices.append(fixed[a][None, :])
            logs.append(np.array([log_w[a] - base[a]]))
            continue
        k = int(ks[a])
        sums, idx = best_sums([m[1][:k] for m in multi[a]], k)
        ch = np.repeat(fixed[a][None, :], len(sums), axis=0)
        for j, (T, _, choice) in enumerate(multi[a]):
            ch[:, T] = choice[idx[:, j]]
        parents.append(np.full(len(sums), a, dtype=np.int64))
        choices.append(ch)
        logs.append(log_w[a] - base[a] - sums)
    if not parents:
        return np.zeros(0, dtype=np.int64), np.zeros((0, n), dtype=np.int64), np.zeros(0)
    return np.concatenate(parents), np.concatenate(choices), np.concatenate(logs)
