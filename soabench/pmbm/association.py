"""Global hypotheses of the PMBM update (docs/method.md §10.3): clusters, Murty's ranked assignments per cluster,
and their combination into the best new global hypotheses of each prior global hypothesis.

For a prior global hypothesis a (hypothesis a_i of each track i) and a cluster of tracks T and measurements L, the
assignment problem has rows L then one "no measurement" row per track of T, and columns T then one new track per
measurement of L; the costs are minus the log likelihood factors (:func:`cluster_costs`). A cluster's ranked
solutions are cached per choice of its tracks' hypotheses, so global hypotheses that differ only elsewhere share
them. Clusters are independent, so the best joint assignments are the best sums of one solution per cluster
(:func:`best_sums`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from soabench.pmbm.murty import murty

MISS = -1  #: a track's choice when no measurement is assigned to it


def clusters(track: np.ndarray, gated: np.ndarray, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Tracks and measurements that share no gated pair, in any hypothesis, fall into different clusters.

    Args:
        track: (H,) the track of each hypothesis; gated: (H, M) True where hypothesis h may have generated z_l.
    Returns:
        (tracks, measurements) index arrays of every cluster with at least one track, then one cluster per
        measurement that no track gates (no tracks), in increasing order of their smallest member.
    """
    M = gated.shape[1]
    hh, ll = np.nonzero(gated)
    ti = track[hh]
    graph = coo_matrix((np.ones(len(ti)), (ti, n + ll)), shape=(n + M, n + M))
    _, comp = connected_components(graph, directed=False)
    out = []
    for c in np.unique(comp):  # in order of first appearance = order of the smallest member
        members = np.flatnonzero(comp == c)
        out.append((members[members < n], members[members >= n] - n))
    return out


def cluster_costs(
    hs: np.ndarray, L: np.ndarray, log_l_miss: np.ndarray, log_l_det: np.ndarray, log_new: np.ndarray
) -> np.ndarray:
    """The square cost matrix of one cluster (module docstring): ``hs`` the chosen hypothesis of each of its
    tracks, ``L`` its measurements; +inf marks a forbidden cell."""
    nT, nL = len(hs), len(L)
    C = np.full((nL + nT, nT + nL), np.inf)
    C[:nL, :nT] = -log_l_det[np.ix_(hs, L)].T
    C[np.arange(nL), nT + np.arange(nL)] = -log_new[L]
    C[nL + np.arange(nT), np.arange(nT)] = -log_l_miss[hs]
    C[nL:, nT:] = 0.0
    return C


def best_sums(costs: list[np.ndarray], k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest sums of one entry of each sorted cost array: (sums (K,), index of each term (K, len))."""
    total = np.zeros(1)
    idx = np.zeros((1, 0), dtype=np.int64)
    for c in costs:
        if len(c) == 1:
            total = total + c[0]
            idx = np.hstack([idx, np.zeros((len(idx), 1), dtype=np.int64)])
            continue
        s = (total[:, None] + c[None, :]).ravel()
        order = np.argsort(s, kind="stable")[:k]
        a, b = np.divmod(order, len(c))
        total = s[order]
        idx = np.hstack([idx[a], b[:, None]])
    return total, idx


class ClusterSolver:
    """Ranked solutions of each cluster for a given choice of its tracks' hypotheses, cached (module docstring)."""

    def __init__(
        self,
        groups: list[tuple[np.ndarray, np.ndarray]],
        log_l_miss: np.ndarray,
        log_l_det: np.ndarray,
        log_new: np.ndarray,
    ) -> None:
        self.groups = groups
        self.log_l_miss, self.log_l_det, self.log_new = log_l_miss, log_l_det, log_new
        self._cache: dict[tuple, tuple[int, np.ndarray, np.ndarray]] = {}
        self.n_murty = 0  #: Murty runs so far

    def solve(self, c: int, hs: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The (at most) ``k`` best solutions of cluster ``c`` with its tracks in hypotheses ``hs``: costs (K,)
        increasing, and the choice of each of its tracks (K, |T|): a measurement index or :data:`MISS`."""
        T, L = self.groups[c]
        key = (c, hs.tobytes())
        hit = self._cache.get(key)
        if hit is not None and (hit[0] >= k or len(hit[1]) < hit[0]):  # enough, or every solution already found
            return hit[1][:k], hit[2][:k]
        nT, nL = len(T), len(L)
        if nL == 0:  # every track missed
            costs, choice = np.array([-float(self.log_l_miss[hs].sum())]), np.full((1, nT), MISS, dtype=np.int64)
        else:
            sols = murty(cluster_costs(hs, L, self.log_l_miss, self.log_l_det, self.log_new), k)
            self.n_murty += 1
            costs = np.array([s[0] for s in sols])
            choice = np.full((len(sols), nT), MISS, dtype=np.int64)
            for s, (_, cols) in enumerate(sols):
                row_of = np.argsort(cols)[:nT]  # the row assigned to each track column
                det = row_of < nL
                choice[s, det] = L[row_of[det]]
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
    log w_a minus the assignment cost). Measurements no track takes go to their new tracks. Clusters without
    tracks have one solution (every measurement to its new track) whose cost is added once.
    """
    n = table.shape[1]
    lone = [L for T, L in groups if len(T) == 0]
    lone_cost = -float(solver.log_new[np.concatenate(lone)].sum()) if lone else 0.0
    with_tracks = [c for c, (T, _) in enumerate(groups) if len(T)]
    parents, choices, logs = [], [], []
    for a in range(table.shape[0]):
        k = max(1, min(M_max, math.ceil(M_max * math.exp(log_w[a]) - 1e-9)))
        sols = [solver.solve(c, table[a, groups[c][0]], k) for c in with_tracks]
        if any(len(s[0]) == 0 for s in sols):
            continue
        sums, idx = best_sums([s[0] for s in sols], k)
        ch = np.full((len(sums), n), MISS, dtype=np.int64)
        for j, c in enumerate(with_tracks):
            ch[:, groups[c][0]] = sols[j][1][idx[:, j]]
        parents.append(np.full(len(sums), a, dtype=np.int64))
        choices.append(ch)
        logs.append(log_w[a] - sums - lone_cost)
    if not parents:
        return np.zeros(0, dtype=np.int64), np.zeros((0, n), dtype=np.int64), np.zeros(0)
    return np.concatenate(parents), np.concatenate(choices), np.concatenate(logs)
