"""Labelled Bernoulli tracks with Gaussian-mixture densities, as flat arrays (docs/method.md "LMB filter").

An LMB density is a set of Bernoulli components {(r_i, p_i)} with distinct labels l_i. Track i has existence
probability ``r[i]``, label ``label[i]`` (int64) and the density p_i = sum_c w_c N(x; m_c, P_c) over its components
``start[i]:start[i + 1]`` of the flat arrays ``w (C,)``, ``m (C, 4)``, ``P (C, 4, 4)`` (component weights of a track
sum to 1). ``origin`` is the birth source code of the track (:data:`soabench.types.SOURCE_NAMES`) and ``age`` the
predictions it has survived, as the GM-PHD's mixture keeps them for the origin counts of §5.7.

A label is the pair (k, j): scan of birth and index of the birth term in that scan, packed into one int64 as
``k * 2**32 + j`` (:func:`make_labels`, :func:`label_pairs`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()

from numba import njit  # noqa: E402

from soabench.gmphd import kernels  # noqa: E402

LABEL_SHIFT = 32  #: label (k, j) = k * 2**32 + j


def make_labels(k: int, j: np.ndarray) -> np.ndarray:
    """Labels (k, j) of the birth terms ``j`` (int array) of scan ``k`` as int64."""
    return (np.int64(k) << np.int64(LABEL_SHIFT)) + np.asarray(j, dtype=np.int64)


def label_pairs(label: np.ndarray) -> np.ndarray:
    """(n, 2) int64 (k, j) of packed labels (the inverse of :func:`make_labels`)."""
    label = np.asarray(label, dtype=np.int64).reshape(-1)
    return np.stack([label >> np.int64(LABEL_SHIFT), label & np.int64(2**LABEL_SHIFT - 1)], axis=1)


@dataclass
class Tracks:
    """N labelled Bernoulli tracks with Gaussian-mixture densities (module docstring)."""

    r: np.ndarray  #: (N,) existence probabilities
    label: np.ndarray  #: (N,) int64 labels
    origin: np.ndarray  #: (N,) int8 birth source codes
    age: np.ndarray  #: (N,) int32 predictions survived
    start: np.ndarray  #: (N + 1,) int64 offsets of each track's components
    w: np.ndarray  #: (C,) component weights (per track summing to 1)
    m: np.ndarray  #: (C, 4) component means
    P: np.ndarray  #: (C, 4, 4) component covariances

    @classmethod
    def empty(cls) -> Tracks:
        """No track (the prior at k = 0)."""
        return cls(
            np.zeros(0),
            np.zeros(0, dtype=np.int64),
            np.zeros(0, dtype=np.int8),
            np.zeros(0, dtype=np.int32),
            np.zeros(1, dtype=np.int64),
            np.zeros(0),
            np.zeros((0, 4)),
            np.zeros((0, 4, 4)),
        )

    @classmethod
    def single(
        cls,
        r: np.ndarray,
        m: np.ndarray,
        P: np.ndarray,
        label: np.ndarray,
        origin: np.ndarray | int = -1,
        age: int = 0,
    ) -> Tracks:
        """N tracks of one Gaussian each: existence ``r`` (N,), density N(m_i, P_i)."""
        r = np.asarray(r, dtype=float).reshape(-1)
        n = len(r)
        return cls(
            r,
            np.asarray(label, dtype=np.int64).reshape(n),
            np.broadcast_to(np.asarray(origin, dtype=np.int8), (n,)).copy(),
            np.full(n, age, dtype=np.int32),
            np.arange(n + 1, dtype=np.int64),
            np.ones(n),
            np.asarray(m, dtype=float).reshape(n, 4).copy(),
            np.asarray(P, dtype=float).reshape(n, 4, 4).copy(),
        )

    def __len__(self) -> int:
        return len(self.r)

    def owner(self) -> np.ndarray:
        """(C,) the track index of each component."""
        return np.repeat(np.arange(len(self.r)), np.diff(self.start))

    def select(self, idx: np.ndarray) -> Tracks:
        """The tracks ``idx`` (int indices, in that order) with their components."""
        idx = np.asarray(idx, dtype=np.int64)
        counts = np.diff(self.start)[idx]
        start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        comp = np.repeat(self.start[idx] - start[:-1], counts) + np.arange(start[-1])
        return Tracks(
            self.r[idx], self.label[idx], self.origin[idx], self.age[idx], start,
            self.w[comp], self.m[comp], self.P[comp],
        )  # fmt: skip

    @staticmethod
    def concatenate(parts: list[Tracks]) -> Tracks:
        """The tracks of ``parts`` one after the other."""
        parts = [p for p in parts if len(p)]
        if not parts:
            return Tracks.empty()
        if len(parts) == 1:
            return parts[0]
        offsets = np.cumsum([0] + [len(p.w) for p in parts[:-1]])
        start = np.concatenate([[0]] + [p.start[1:] + o for p, o in zip(parts, offsets, strict=True)])
        cat = np.concatenate
        return Tracks(
            cat([p.r for p in parts]), cat([p.label for p in parts]), cat([p.origin for p in parts]),
            cat([p.age for p in parts]), start.astype(np.int64), cat([p.w for p in parts]),
            cat([p.m for p in parts]), cat([p.P for p in parts]),
        )  # fmt: skip

    def estimates(self, thr: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(X (n, 4), r (n,), labels (n,))`` of the tracks with r > thr, each at the mean of its heaviest
        component (as Vo's LMB toolbox extracts; the lowest index on ties)."""
        idx = np.flatnonzero(self.r > thr)
        X = np.empty((len(idx), 4))
        for n, i in enumerate(idx):
            a, b = self.start[i], self.start[i + 1]
            X[n] = self.m[a + int(np.argmax(self.w[a:b]))]
        return X, self.r[idx].copy(), self.label[idx].copy()


@njit(cache=True)
def _finite_components(keep, nk, w, m, P):
    """Every weight, mean and covariance of the components ``keep[:nk]`` finite."""
    for t in range(nk):
        c = keep[t]
        if not math.isfinite(w[c]):
            return False
        for a in range(4):
            if not math.isfinite(m[c, a]):
                return False
            for b in range(4):
                if not math.isfinite(P[c, a, b]):
                    return False
    return True


@njit(cache=True)
def _merge_track(keep, nk, w, m, P, U, L, spd, alive, order, label, centres, count, W, mt, Pt):
    """The merge groups of one track's components ``keep[:nk]`` (finite) into W (G,), mt (G, 4), Pt (G, 4, 4);
    returns G. The same groups and moments, bit for bit, as ``kernels.merge_groups_window`` followed by
    ``kernels.merge_moments`` on the gathered components: the same Cholesky factors, window bound, x-marginal
    test and quadratic form against each centre in order of weight (heaviest first, lowest index on ties; which
    candidate is tested first does not change the groups), then each group's sums over its members in index order.
    ``L``, ``spd``, ``alive``, ``order``, ``label``, ``centres`` and ``count`` are scratch of at least nk rows. The
    Cholesky factor and the quadratic form are ``kernels.cholesky4_at`` and ``kernels.merge_q_at``, indexed on the
    whole arrays: a row view passed to a function costs two atomic reference-count updates.
    """
    Uq = kernels.merge_threshold(U)
    pxx_max = 0.0
    for t in range(nk):
        c = keep[t]
        spd[t] = kernels.cholesky4_at(P, c, L, t)
        if spd[t] and P[c, 0, 0] > pxx_max:
            pxx_max = P[c, 0, 0]
        alive[t] = True
        # insertion in index order after every heavier or equal weight: a stable sort by -w
        a = t
        while a > 0 and w[keep[order[a - 1]]] < w[c]:
            order[a] = order[a - 1]
            a -= 1
        order[a] = t
    half = math.sqrt(Uq * pxx_max) * (1.0 + 1e-9) + 1e-12
    y = np.empty(4)
    G = 0
    for s in range(nk):
        j = order[s]
        if not alive[j]:
            continue
        alive[j] = False
        label[j] = G
        centres[G] = j
        cj = keep[j]
        x_lo = m[cj, 0] - half
        x_hi = m[cj, 0] + half
        for t in range(nk):
            c = keep[t]
            if not alive[t] or not spd[t] or not (m[c, 0] >= x_lo and m[c, 0] <= x_hi):  # in the x window
                continue
            d0 = m[c, 0] - m[cj, 0]
            if d0 * d0 > Uq * P[c, 0, 0] * (1.0 + 1e-9):  # the x marginal alone already exceeds U
                continue
            if kernels.merge_q_at(m, c, cj, L, t, y) <= Uq:
                alive[t] = False
                label[t] = G
        G += 1
    for g in range(G):
        count[g] = 0
    for t in range(nk):
        count[label[t]] += 1
    for g in range(G):
        j = centres[g]
        if count[g] == 1:
            W[g] = w[keep[j]]
            kernels.copy_state(mt, Pt, g, m, P, keep[j])
        else:
            W[g] = 0.0
            for a in range(4):
                mt[g, a] = 0.0
                for b in range(4):
                    Pt[g, a, b] = 0.0
    for t in range(nk):
        g = label[t]
        if count[g] > 1:
            c = keep[t]
            W[g] += w[c]
            for a in range(4):
                mt[g, a] += w[c] * m[c, a]
    for g in range(G):
        if count[g] > 1:
            for a in range(4):
                mt[g, a] /= W[g]
    for t in range(nk):
        g = label[t]
        if count[g] > 1:
            c = keep[t]
            for a in range(4):
                da = mt[g, a] - m[c, a]
                for b in range(4):
                    Pt[g, a, b] += w[c] * (P[c, a, b] + da * (mt[g, b] - m[c, b]))
    for g in range(G):
        if count[g] > 1:
            for a in range(4):
                for b in range(a, 4):
                    v = 0.5 * (Pt[g, a, b] + Pt[g, b, a]) / W[g]
                    Pt[g, a, b] = v
                    Pt[g, b, a] = v
    return G


@njit(cache=True)
def reduce_components(start, w, m, P, T, U, L_max):
    """Per track: prune components with w <= T, merge (Vo-Ma Table II with U, the GM-PHD's kernels), keep the
    L_max heaviest and renormalise to 1 (docs/method.md §2.9 applied to each track's density).

    A track whose components are all pruned keeps its heaviest one. Returns (start, w, m, P) of the result.

    A track of one component is copied. A track of finite components is merged in scratch buffers sized once for
    the largest track (:func:`_merge_track`: the arithmetic of ``merge_groups_window`` and ``merge_moments``, in
    their order, without their per-call arrays); any other track goes through those kernels.
    """
    N = start.shape[0] - 1
    C = w.shape[0]
    out_start = np.zeros(N + 1, dtype=np.int64)
    out_w = np.empty(C)
    out_m = np.empty((C, 4))
    out_P = np.empty((C, 4, 4))
    n_max = 0
    for i in range(N):
        n_max = max(n_max, start[i + 1] - start[i])
    keep = np.empty(n_max, dtype=np.int64)
    # scratch of _merge_track, for the largest track
    L = np.zeros((n_max, 4, 4))
    spd = np.empty(n_max, dtype=np.bool_)
    alive = np.empty(n_max, dtype=np.bool_)
    order = np.empty(n_max, dtype=np.int64)
    label = np.empty(n_max, dtype=np.int64)
    centres = np.empty(n_max, dtype=np.int64)
    count = np.empty(n_max, dtype=np.int64)
    W = np.empty(n_max)
    mt = np.empty((n_max, 4))
    Pt = np.empty((n_max, 4, 4))
    n_out = 0
    for i in range(N):
        a, b = start[i], start[i + 1]
        n = b - a
        if n == 1 and L_max >= 1:  # one component: kept, its own group, weight w / (0 + w) as below
            total = 0.0
            total += w[a]
            out_w[n_out] = w[a] / total
            kernels.copy_state(out_m, out_P, n_out, m, P, a)
            n_out += 1
            out_start[i + 1] = n_out
            continue
        nk = 0
        best = a
        for c in range(a, b):
            if w[c] > w[best]:
                best = c
            if w[c] > T:
                keep[nk] = c
                nk += 1
        if nk == 0 and n > 0:
            keep[0] = best
            nk = 1
        if nk > 0 and _finite_components(keep, nk, w, m, P):
            G = _merge_track(keep, nk, w, m, P, U, L, spd, alive, order, label, centres, count, W, mt, Pt)
            # the L_max heaviest groups (a stable sort by -W: the lower index first among equal weights; no W is NaN
            # here), in creation order: group g is kept when fewer than L_max groups come before it in that sort
            chosen = alive  # scratch again
            for g in range(G):
                rank = 0
                if G > L_max:
                    for e in range(G):
                        if W[e] > W[g] or (W[e] == W[g] and e < g):
                            rank += 1
                chosen[g] = rank < L_max
            total = 0.0
            for g in range(G):
                if chosen[g]:
                    total += W[g]
            for g in range(G):
                if chosen[g]:
                    out_w[n_out] = W[g] / total
                    kernels.copy_state(out_m, out_P, n_out, mt, Pt, g)
                    n_out += 1
            out_start[i + 1] = n_out
            continue
        kk = keep[:nk]
        wk = w[kk].copy()
        mk = np.ascontiguousarray(m[kk])
        Pk = np.ascontiguousarray(P[kk])
        by_w = np.argsort(-wk, kind="mergesort")
        group, centre = kernels.merge_groups_window(mk, Pk, by_w, U)
        dummy = np.zeros(nk, dtype=np.int32)
        Wg, mg, Pg, _, _, _ = kernels.merge_moments(group, centre, wk, mk, Pk, dummy, dummy)
        sel = np.sort(np.argsort(-Wg, kind="mergesort")[: min(Wg.shape[0], L_max)])
        total = 0.0
        for g in sel:
            total += Wg[g]
        for g in sel:
            out_w[n_out] = Wg[g] / total
            kernels.copy_state(out_m, out_P, n_out, mg, Pg, g)
            n_out += 1
        out_start[i + 1] = n_out
    return out_start, out_w[:n_out], out_m[:n_out], out_P[:n_out]
