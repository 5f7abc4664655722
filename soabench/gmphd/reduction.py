"""Pruning, merging, capping (Vo & Ma 2006, Table II) and state extraction (Table III) (ALGORITHMS.md §2.9, §2.10).

Exactly Vo & Ma: prune w <= T (no renormalisation); greedy merge around the heaviest remaining component j* of
every i with (m_i - m_j*)^T P_i^-1 (m_i - m_j*) <= U (P_i of the candidate); no weight cap, no redistribution;
then keep the J_max heaviest (logged when hit).

The O(J^2) merge is vectorised: P_i^-1 is computed once per call, and the Mahalanobis distances of a batch of
passes are computed at once for the candidates a k-d tree proposes (d^T P_i^-1 d <= U implies
|d|^2 <= U lambda_max(P_i)); see :func:`merge_groups`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from soabench.gmphd.mixture import Mixture
from soabench.gmphd.probabilities import beta_mean, beta_moment_match, beta_var

log = logging.getLogger(__name__)


def prune(mix: Mixture, T: float) -> Mixture:
    """Keep components with w > T (§2.9); weights are not renormalised."""
    keep = mix.w > T
    return mix if keep.all() else mix.select(keep)


def lambda_max_bound(P: np.ndarray) -> np.ndarray:
    """Cheap upper bound of the largest eigenvalue of each SPD block (J, 4, 4): min(Frobenius, Gershgorin)."""
    fro = np.sqrt(np.einsum("nij,nij->n", P, P))
    gersh = np.abs(P).sum(axis=2).max(axis=1)
    return np.minimum(fro, gersh)


def _mahalanobis2(PiT: np.ndarray, i: np.ndarray, d: np.ndarray) -> np.ndarray:
    """d_n^T P_{i_n}^-1 d_n for pairs n, from P^-1 stored coordinate-major (16, J) and d (4, n)."""
    d2 = np.zeros(d.shape[1])
    for a in range(4):
        d2 += PiT[5 * a][i] * d[a] * d[a]
        for b in range(a + 1, 4):
            d2 += 2.0 * PiT[4 * a + b][i] * d[a] * d[b]
    return d2


def merge_groups(m: np.ndarray, P: np.ndarray, w: np.ndarray, U: float) -> tuple[np.ndarray, np.ndarray]:
    """Vo-Ma greedy merge groups: returns (label (J,), centre index per group (G,)), groups in creation order.

    Pass g takes j* = the heaviest unmerged component (lowest index on ties) and absorbs every unmerged i with
    (m_i - m_j*)^T P_i^-1 (m_i - m_j*) <= U.

    Vectorised by batches of passes: the next B heaviest unmerged components are the next B possible centres, in
    order. One k-d tree query per radius class finds, for all of them at once, the unmerged i within the candidate
    radius sqrt(U lambda_max(P_i)) (a necessary condition), one array expression applies the exact test with
    P_i^-1 (computed once per call), and the passes then run in weight order over these lists (a batch member
    already absorbed by an earlier pass is skipped). Only lists of actual or possible centres are built, so a dense
    clique of n components costs O(n B), not O(n^2). B doubles from 64 up to 512.
    """
    J = len(w)
    if J == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    r2 = U * lambda_max_bound(P) * (1.0 + 1e-9) + 1e-24
    # two radius classes (split at the median) so narrow candidates are not searched with the widest radius
    wide = r2 > np.median(r2)
    mT = np.ascontiguousarray(m.T)
    PiT = np.ascontiguousarray(np.linalg.inv(P).reshape(J, 16).T)  # P_i^-1 once per call, coordinate-major
    order = np.argsort(-w, kind="stable")
    alive_b = bytearray(b"\x01") * J  # Python-side flags for the pass loop ...
    alive = np.frombuffer(alive_b, dtype=bool)  # ... and the same memory seen by numpy
    label = [0] * J
    centres: list[int] = []
    pos = 0
    B = 64
    while pos < J:
        rest = order[pos:]
        nxt = np.flatnonzero(alive[rest])[:B]  # the next B heaviest unmerged components, in weight order
        if not len(nxt):
            break
        bidx = rest[nxt]
        pos += int(nxt[-1]) + 1
        btree = cKDTree(m[bidx])
        ks, iss = [], []
        for cls in (alive & ~wide, alive & wide):  # unmerged candidates (trees rebuilt: merged ones drop out)
            cand = np.flatnonzero(cls)
            if not len(cand):
                continue
            r = float(np.sqrt(r2[cand].max()))
            sdm = btree.sparse_distance_matrix(cKDTree(m[cand]), r, output_type="ndarray")
            i = cand[sdm["j"]]
            keep = sdm["v"] ** 2 <= r2[i]
            ks.append(sdm["i"][keep])
            iss.append(i[keep])
        k = np.concatenate(ks)
        i = np.concatenate(iss)
        c = bidx[k]
        ok = _mahalanobis2(PiT, i, mT[:, i] - mT[:, c]) <= U
        k, i = k[ok], i[ok]
        srt = np.argsort(k, kind="stable")
        i = i[srt]
        il = i.tolist()
        ptr = np.searchsorted(k[srt], np.arange(len(bidx) + 1)).tolist()
        for kk, cj in enumerate(bidx.tolist()):  # the passes, in weight order
            if not alive_b[cj]:
                continue
            g = len(centres)
            centres.append(cj)
            alive_b[cj] = 0
            label[cj] = g
            lo, hi = ptr[kk], ptr[kk + 1]
            if hi - lo > 48:  # long candidate list (a clique): filter it in numpy
                members = i[lo:hi]
                members = members[alive[members]].tolist()
                for ii in members:
                    alive_b[ii] = 0
                    label[ii] = g
            else:
                for ii in il[lo:hi]:
                    if alive_b[ii]:
                        alive_b[ii] = 0
                        label[ii] = g
        B = min(2 * B, 512)
    return np.asarray(label, dtype=np.int64), np.asarray(centres, dtype=np.int64)


def merge(mix: Mixture, U: float, theta_min: float = 2.0) -> Mixture:
    """Vo-Ma merging (§2.9) with moment-matched Gaussians, Beta moment matching (§4.5) and metadata rules.

    w~ = sum w_i; m~ = sum w_i m_i / w~; P~ = sum w_i [P_i + (m~ - m_i)(m~ - m_i)^T] / w~;
    n_det = max, age = max, origin = that of j*. Singleton groups are passed through unchanged.
    """
    J = len(mix)
    if J == 0:
        return mix
    label, centres = merge_groups(mix.m, mix.P, mix.w, U)
    G = len(centres)
    if G == J:
        return mix.select(centres)
    counts = np.bincount(label, minlength=G)
    multi = counts[label] > 1  # members of groups with >= 2 components; singletons pass through unchanged
    W = mix.w[centres].copy()
    mt = mix.m[centres].copy()
    Pt = mix.P[centres].copy()
    beta = None if mix.beta is None else mix.beta[centres].copy()
    n_det = mix.n_det[centres].copy()
    age = mix.age[centres].copy()
    idx = np.flatnonzero(multi)
    perm = idx[np.argsort(label[idx], kind="stable")]
    lab_s = label[perm]
    starts = np.flatnonzero(np.r_[True, lab_s[1:] != lab_s[:-1]])
    gs = lab_s[starts]  # the multi-member groups
    w = mix.w[perm]
    m = mix.m[perm]
    Wg = np.add.reduceat(w, starts)
    mg = np.add.reduceat(w[:, None] * m, starts, axis=0) / Wg[:, None]
    dev = m - np.repeat(mg, counts[gs], axis=0)
    second = w[:, None, None] * (mix.P[perm] + dev[:, :, None] * dev[:, None, :])
    Pg = np.add.reduceat(second, starts, axis=0) / Wg[:, None, None]
    W[gs] = Wg
    mt[gs] = mg
    Pt[gs] = 0.5 * (Pg + np.swapaxes(Pg, 1, 2))
    n_det[gs] = np.maximum.reduceat(mix.n_det[perm], starts)
    age[gs] = np.maximum.reduceat(mix.age[perm], starts)
    if beta is not None:
        b = mix.beta[perm]
        for c in (0, 2):
            mu = beta_mean(b[:, c], b[:, c + 1])
            sec = beta_var(b[:, c], b[:, c + 1]) + mu * mu
            beta[gs, c], beta[gs, c + 1] = beta_moment_match(
                Wg, np.add.reduceat(w * mu, starts), np.add.reduceat(w * sec, starts), theta_min
            )
    return Mixture(W, mt, Pt, mix.origin[centres], n_det, age, beta)


def cap(mix: Mixture, J_max: int) -> tuple[Mixture, bool]:
    """Keep the J_max heaviest components (§2.9); returns (mixture, hit). A hit is logged (§2.12 item 12)."""
    if len(mix) <= J_max:
        return mix, False
    keep = np.sort(np.argsort(-mix.w, kind="stable")[:J_max])
    log.info("J_max = %d hit: %d components reduced to %d", J_max, len(mix), J_max)
    return mix.select(keep), True


@dataclass
class ReductionResult:
    """Output of :func:`prune_merge_cap` with the counts of §5.7."""

    mix: Mixture
    n_pruned: int  #: components left after pruning
    n_merged: int  #: components left after merging
    cap_hit: bool


def prune_merge_cap(mix: Mixture, T: float, U: float, J_max: int, theta_min: float = 2.0) -> ReductionResult:
    """Vo-Ma Table II: prune (w > T), merge (U, squared Mahalanobis with P_i), cap (J_max) (§2.9)."""
    pruned = prune(mix, T)
    merged = merge(pruned, U, theta_min)
    capped, hit = cap(merged, J_max)
    return ReductionResult(capped, len(pruned), len(merged), hit)


def extract(mix: Mixture, thr: float = 0.5, rule: str = "vo_ma") -> tuple[np.ndarray, np.ndarray]:
    """State extraction (§2.10): returns (X (n, 4), X_w (n,)).

    ``vo_ma``: every component with w > thr, repeated floor(w + 0.5) times (not Python's half-to-even ``round``).
    ``top_n`` (ablation): the floor(sum w + 0.5) heaviest components, once each.
    """
    if rule == "top_n":
        n = int(np.floor(mix.w.sum() + 0.5)) if len(mix) else 0
        idx = np.argsort(-mix.w, kind="stable")[:n]
        return mix.m[idx].copy(), mix.w[idx].copy()
    idx = np.flatnonzero(mix.w > thr)
    reps = np.floor(mix.w[idx] + 0.5).astype(np.int64)
    return np.repeat(mix.m[idx], reps, axis=0), np.repeat(mix.w[idx], reps)
