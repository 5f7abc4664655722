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
def reduce_components(start, w, m, P, T, U, L_max):
    """Per track: prune components with w <= T, merge (Vo-Ma Table II with U, the GM-PHD's kernels), keep the
    L_max heaviest and renormalise to 1 (docs/method.md §2.9 applied to each track's density).

    A track whose components are all pruned keeps its heaviest one. Returns (start, w, m, P) of the result.
    """
    N = start.shape[0] - 1
    C = w.shape[0]
    out_start = np.zeros(N + 1, dtype=np.int64)
    out_w = np.empty(C)
    out_m = np.empty((C, 4))
    out_P = np.empty((C, 4, 4))
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
        keep = np.empty(n, dtype=np.int64)
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
        keep = keep[:nk]
        wk = w[keep].copy()
        mk = np.ascontiguousarray(m[keep])
        Pk = np.ascontiguousarray(P[keep])
        order = np.argsort(-wk, kind="mergesort")
        label, centres = kernels.merge_groups_window(mk, Pk, order, U)
        dummy = np.zeros(nk, dtype=np.int32)
        W, mt, Pt, _, _, _ = kernels.merge_moments(label, centres, wk, mk, Pk, dummy, dummy)
        G = W.shape[0]
        sel = np.argsort(-W, kind="mergesort")[: min(G, L_max)]
        sel = np.sort(sel)
        total = 0.0
        for g in sel:
            total += W[g]
        for g in sel:
            out_w[n_out] = W[g] / total
            out_m[n_out] = mt[g]
            out_P[n_out] = Pt[g]
            n_out += 1
        out_start[i + 1] = n_out
    return out_start, out_w[:n_out], out_m[:n_out], out_P[:n_out]
