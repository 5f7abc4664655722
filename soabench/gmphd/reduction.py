"""Pruning, merging, capping (Vo & Ma 2006, Table II) and state extraction (Table III) (docs/method.md §2.9, §2.10).

Exactly Vo & Ma: prune w <= T (no renormalisation); greedy merge around the heaviest remaining component j* of
every i with (m_i - m_j*)^T P_i^-1 (m_i - m_j*) <= U (P_i of the candidate; a tie at exactly U merges: the test is
<= U (1 + 1e-9), :func:`soabench.gmphd.kernels.merge_threshold`); no weight cap, no redistribution; then keep the
J_max heaviest (logged when hit).

The greedy merge and the moment matching are compiled loops (:mod:`soabench.gmphd.kernels`): Table II literally,
with a spatial index (uniform grids over the positions, one per reach class, or an x-sorted window for small
mixtures) so that a pass only visits the candidates whose position alone does not already exceed U: about O(J) plus
each pass's neighbouring cells instead of O(J x groups).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from soabench.gmphd import kernels
from soabench.gmphd.mixture import Mixture
from soabench.gmphd.probabilities import beta_mean, beta_moment_match, beta_var

log = logging.getLogger(__name__)


def prune(mix: Mixture, T: float) -> Mixture:
    """Keep components with w > T (§2.9); weights are not renormalised."""
    keep = mix.w > T
    return mix if keep.all() else mix.select(keep)


def merge_groups(m: np.ndarray, P: np.ndarray, w: np.ndarray, U: float) -> tuple[np.ndarray, np.ndarray]:
    """Vo-Ma greedy merge groups: returns (label (J,), centre index per group (G,)), groups in creation order.

    Pass g takes j* = the heaviest unmerged component (lowest index on ties) and absorbs every unmerged i with
    (m_i - m_j*)^T P_i^-1 (m_i - m_j*) <= U, ties at U included whatever the rounding (compiled loop:
    :func:`soabench.gmphd.kernels.merge_groups`).
    """
    if len(w) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    order = np.argsort(-np.asarray(w), kind="stable")
    m, P = np.ascontiguousarray(m, dtype=float), np.ascontiguousarray(P, dtype=float)
    return kernels.merge_groups(m, P, order, float(U))  # float U: one compiled signature, whatever the config type


def merge(mix: Mixture, U: float, theta_min: float = 2.0) -> Mixture:
    """Vo-Ma merging (§2.9) with moment-matched Gaussians, Beta moment matching (§4.5) and metadata rules.

    w~ = sum w_i; m~ = sum w_i m_i / w~; P~ = sum w_i [P_i + (m~ - m_i)(m~ - m_i)^T] / w~;
    n_det = max, age = max, origin and label = those of j* (§2.13). Singleton groups are passed through unchanged.
    """
    J = len(mix)
    if J == 0:
        return mix
    label, centres = merge_groups(mix.m, mix.P, mix.w, U)
    G = len(centres)
    if G == J:
        return mix.select(centres)
    W, mt, Pt, n_det, age, counts = kernels.merge_moments(label, centres, mix.w, mix.m, mix.P, mix.n_det, mix.age)
    beta = None
    if mix.beta is not None:  # §4.5: moment-matched Beta of each multi-member group; singletons unchanged
        beta = mix.beta[centres].copy()
        gs = np.flatnonzero(counts > 1)
        multi = counts[label] > 1
        lab, w, b = label[multi], mix.w[multi], mix.beta[multi]
        for c in (0, 2):
            mu = beta_mean(b[:, c], b[:, c + 1])
            sec = beta_var(b[:, c], b[:, c + 1]) + mu * mu
            beta[gs, c], beta[gs, c + 1] = beta_moment_match(
                W[gs],
                np.bincount(lab, weights=w * mu, minlength=G)[gs],
                np.bincount(lab, weights=w * sec, minlength=G)[gs],
                theta_min,
            )
    return Mixture(W, mt, Pt, mix.origin[centres], n_det, age, beta, mix.label[centres])


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


def _extraction(mix: Mixture, thr: float, rule: str) -> tuple[np.ndarray, np.ndarray]:
    """The extracted components (in the order of X) and the copies of each, by ``rule`` (:func:`extract`)."""
    if rule == "top_n":
        n = int(np.floor(mix.w.sum() + 0.5)) if len(mix) else 0
        idx = np.argsort(-mix.w, kind="stable")[:n]
        return idx, np.ones(len(idx), dtype=np.int64)
    idx = np.flatnonzero(mix.w > thr)
    return idx, np.floor(mix.w[idx] + 0.5).astype(np.int64)


def extract(mix: Mixture, thr: float = 0.5, rule: str = "vo_ma") -> tuple[np.ndarray, np.ndarray]:
    """State extraction (§2.10): returns (X (n, 4), X_w (n,)).

    ``vo_ma``: every component with w > thr, repeated floor(w + 0.5) times (not Python's half-to-even ``round``).
    ``top_n`` (ablation): the floor(sum w + 0.5) heaviest components, once each.
    """
    idx, reps = _extraction(mix, thr, rule)
    return np.repeat(mix.m[idx], reps, axis=0), np.repeat(mix.w[idx], reps)


def extract_labelled(
    mix: Mixture, thr: float, rule: str, next_label: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """:func:`extract` with the label of each estimate (§2.13, :func:`soabench.gmphd.kernels.extract_labels`):
    returns (X, X_w, labels (n,) int64, the next unused label). A component that lost a label conflict gets its fresh
    label written into ``mix.label``, so that its track continues under it."""
    idx, reps = _extraction(mix, thr, rule)
    X, X_w = np.repeat(mix.m[idx], reps, axis=0), np.repeat(mix.w[idx], reps)
    labels, mix.label, nxt = kernels.extract_labels(
        np.ascontiguousarray(mix.w, dtype=float), np.ascontiguousarray(mix.label, dtype=np.int64), idx, reps,
        int(next_label),
    )  # fmt: skip
    return X, X_w, labels, int(nxt)
