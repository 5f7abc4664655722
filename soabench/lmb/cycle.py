"""The fused LMB cycle (docs/method.md "LMB filter"): prediction and birth, then the joint update, the per-track
reduction and the extraction, as two compiled calls per scan.

Why: at a trial's sizes (tens of tracks of a few components, a handful of measurements) the array path of
:mod:`soabench.lmb.update`, :mod:`soabench.lmb.birth` and :mod:`soabench.lmb.tracks` is about a hundred small numpy
calls per step, each costing microseconds of fixed overhead, against the GM-PHD's one compiled call
(:mod:`soabench.gmphd.cycle`). Here the stages are compiled loops over the same flat track arrays, built from the
GM-PHD's kernels (prediction and FOV gate :func:`~soabench.gmphd.cycle.predict_append`, EKF/UKF terms, gated
log-likelihoods, Joseph-form Kalman pairs, Vo-Ma merge groups, origin counts) and the LMB's own (association
marginals :func:`soabench.lmb.gibbs.association_marginals`, per-track reduction
:func:`soabench.lmb.tracks.reduce_components`):

* :func:`predict_births`: survivors r <- p_S r and every component predicted (§2.5); the birth tracks of scan k
  (one Bernoulli per §2.9 merge group of the birth components, or one per component); the Bernoullis of the
  previous scan's measurements, predicted one step; and the FOV gate g at every component mean (§4.1). Only the
  line-of-sight gate of ``static+occ`` (shapely) runs between the two calls, in Python.
* :func:`update_reduce`: association costs, marginals (exact or Gibbs, the array path's kernel), the LMB approximation,
  track pruning and capping, each track's prune/merge/cap, the estimates, and A_l for a model that reads the
  previous step.

The formulas and their order are those of the array path, the reference it is tested against (``LMBFilter(...,
fused=False)``); this cycle is the default. Two things differ in the last bits: numpy
evaluates ``exp`` and ``log`` with its own vectorised routines and the prediction's 4x4 products through BLAS, where
the compiled loops call the C library and sum in index order, so one cycle of the two paths agrees to about 1e-13
(``tests/equivalence/test_lmb_cycle.py``), not bit for bit. Arithmetic is IEEE (no ``fastmath``), so the fused
path itself is bit-reproducible.
"""

from __future__ import annotations

import math

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()

from numba import njit  # noqa: E402

from soabench.gmphd.clock import monotonic  # noqa: E402
from soabench.gmphd.cycle import origin_counts, predict_append, ukf_terms  # noqa: E402
from soabench.gmphd.kernels import (  # noqa: E402
    cholesky4_at,
    copy_row,
    copy_state,
    ekf_terms,
    heaviest,
    log_likelihood,
    merge_q_at,
    merge_threshold,
    posterior_pairs,
)
from soabench.lmb.gibbs import MISSED, association_marginals  # noqa: E402
from soabench.lmb.tracks import LABEL_SHIFT, reduce_components  # noqa: E402
from soabench.metrics_kernels import np_sum  # noqa: E402

KAPPA_FLOOR = 1e-300  #: smallest clutter intensity the costs divide by (as :data:`soabench.lmb.update.KAPPA_FLOOR`)
_A_MAX = np.finfo(np.float64).max

#: indices of :func:`update_reduce`'s ``pars``: r_min, the gate, and the ``[lmb]`` / ``[filter]`` reduction
#: settings (``max_hypotheses``, ``prune_r``, ``max_tracks``, ``prune_T``, ``merge_U``, ``max_components``,
#: ``extract_r``), packed once by the filter
UP_R_MIN, UP_GATE, UP_MAX_HYP, UP_PRUNE_R, UP_MAX_TRACKS, UP_PRUNE_T, UP_MERGE_U, UP_MAX_COMP, UP_EXTRACT_R = range(9)
UP_EXACT = 9  #: 1.0 with ``[lmb] association = "exact"``


@njit(cache=True)
def _merge_groups_at(m, P, idx, order, U):
    """:func:`soabench.gmphd.kernels.merge_groups` of the components ``m[idx]``, ``P[idx]`` (finite) without gathering
    them: the x-sorted window of ``merge_groups_window``, its Cholesky factors, bounds, x-marginal test and
    quadratic form, indexed on the whole arrays (``cholesky4_at``, ``merge_q_at``: a row view passed to a function
    costs two atomic reference-count updates). Every search structure of ``merge_groups`` gives the same groups (its
    docstring), so this one does for any number of components. Returns (label (J,), centres (G,)) over the
    positions of ``idx``."""
    U = merge_threshold(U)
    J = idx.shape[0]
    L = np.zeros((J, 4, 4))
    spd = np.empty(J, dtype=np.bool_)
    pxx_max = 0.0
    for i in range(J):
        c = idx[i]
        ok = cholesky4_at(P, c, L, i)
        spd[i] = ok
        if ok and P[c, 0, 0] > pxx_max:
            pxx_max = P[c, 0, 0]
    x = np.empty(J)
    for i in range(J):
        x[i] = m[idx[i], 0]
    by_x = np.argsort(x, kind="mergesort")
    xs = np.empty(J)
    for k in range(J):
        xs[k] = x[by_x[k]]
    half = math.sqrt(U * pxx_max) * (1.0 + 1e-9) + 1e-12
    alive = np.ones(J, dtype=np.bool_)
    label = np.empty(J, dtype=np.int64)
    centres = np.empty(J, dtype=np.int64)
    y = np.empty(4)
    G = 0
    for c in order:
        if not alive[c]:
            continue
        alive[c] = False
        label[c] = G
        centres[G] = c
        mc = idx[c]
        lo = np.searchsorted(xs, m[mc, 0] - half)
        hi = np.searchsorted(xs, m[mc, 0] + half, side="right")
        for k in range(lo, hi):
            i = by_x[k]
            if not alive[i] or not spd[i]:
                continue
            mi = idx[i]
            d0 = m[mi, 0] - m[mc, 0]
            if d0 * d0 > U * P[mi, 0, 0] * (1.0 + 1e-9):  # the x marginal alone already exceeds U
                continue
            if merge_q_at(m, mi, mc, L, i, y) <= U:
                alive[i] = False
                label[i] = G
        G += 1
    return label, centres[:G]


@njit(cache=True)
def birth_groups(bw, bm, bP, bsrc, r_max, U, J_h):
    """:func:`soabench.lmb.birth.group_birth`'s tracks as (r, origin, n_comp (G,), comp (sum n_comp,), w): each
    group's components (indices into the birth arrays), heaviest first, lowest index on ties, at most J_h, with
    their normalised weights; components of zero weight join no group."""
    n_pos = 0
    for j in range(bw.shape[0]):
        if bw[j] > 0.0:
            n_pos += 1
    keep = np.empty(n_pos, dtype=np.int64)
    q = 0
    for j in range(bw.shape[0]):
        if bw[j] > 0.0:
            keep[q] = j
            q += 1
    w = np.empty(n_pos)
    for q in range(n_pos):
        w[q] = bw[keep[q]]
    order = np.argsort(-w, kind="mergesort")
    group, centres = _merge_groups_at(bm, bP, keep, order, U)
    G = centres.shape[0]
    total = np.zeros(G)
    count = np.zeros(G, dtype=np.int64)
    for q in range(n_pos):  # in index order, as np.bincount sums the weights
        total[group[q]] += w[q]
        count[group[q]] += 1
    first = np.zeros(G + 1, dtype=np.int64)
    for g in range(G):
        first[g + 1] = first[g] + count[g]
    members = np.empty(n_pos, dtype=np.int64)
    fill = first[:G].copy()
    for q in range(n_pos):
        members[fill[group[q]]] = q
        fill[group[q]] += 1
    r = np.empty(G)
    origin = np.empty(G, dtype=np.int8)
    n_comp = np.empty(G, dtype=np.int64)
    comp = np.empty(n_pos, dtype=np.int64)
    wk = np.empty(n_pos)
    by_w = np.empty(n_pos, dtype=np.int64)  # scratch: one group's members, heaviest first
    rest = np.empty(n_pos)
    n_out = 0
    for g in range(G):
        # insertion in index order, each member placed after every heavier or equal one: heaviest first, index
        # order on ties (a stable sort by -w)
        size = np.int64(0)
        for t in range(first[g], first[g + 1]):
            q = members[t]
            a = size
            while a > 0 and w[by_w[a - 1]] < w[q]:
                by_w[a] = by_w[a - 1]
                a -= 1
            by_w[a] = q
            size += 1
        n = min(size, J_h)
        for a in range(1, n):
            rest[a - 1] = w[by_w[a]]
        s = w[by_w[0]] + np_sum(rest, n - 1)  # numpy's add.reduceat: the first term, then the rest's pairwise sum
        for a in range(n):
            comp[n_out + a] = keep[by_w[a]]
            wk[n_out + a] = w[by_w[a]] / s
        n_out += n
        n_comp[g] = n
        r[g] = min(total[g], r_max)
        origin[g] = bsrc[keep[centres[g]]]
    return r, origin, n_comp, comp[:n_out], wk[:n_out]


@njit(cache=True)
def predict_births(r, label, origin, age, start, w, m, P, F, Q, pred_pars, p_S, bw, bm, bP, bsrc, groups, r_max,
                   U, J_h, nb_m, nb_P, nb_r, nb_src, k, j0, ego):  # fmt: skip
    """Step 1 of the cycle (module docstring): the predicted tracks [survivors, birth tracks, measurement births]
    as (r, label, origin, age, start, w, m, P) and the FOV gate g (C,) at every component mean.

    ``pred_pars``: :func:`~soabench.gmphd.cycle.predict_append`'s scalars with p_S = 1 (a track's component
    weights are not scaled; its existence is); ``groups``: one Bernoulli per merge group (else one per component,
    r = min(w, r_max)); ``nb_*``: the previous scan's newborn terms with their existences r_B (labels
    (k, j0 + l), only r_B > 0 kept). Birth components must be finite with w >= 0 (the filter checks them first).
    """
    N0 = r.shape[0]
    C0 = w.shape[0]
    # birth tracks: their components (indices into the birth arrays), weights and existences
    n_pos = 0
    for j in range(bw.shape[0]):
        if bw[j] > 0.0:
            n_pos += 1
    if groups and n_pos > 0:
        rb, ob, nb_comp, bcomp, bwk = birth_groups(bw, bm, bP, bsrc, r_max, U, J_h)
    elif groups:  # no component of positive weight: no group
        rb = np.empty(0)
        ob = np.empty(0, dtype=np.int8)
        nb_comp = np.empty(0, dtype=np.int64)
        bcomp = np.empty(0, dtype=np.int64)
        bwk = np.empty(0)
    else:
        n_pos = 0
        for j in range(bw.shape[0]):
            if min(bw[j], r_max) > 0.0:
                n_pos += 1
        rb = np.empty(n_pos)
        ob = np.empty(n_pos, dtype=np.int8)
        nb_comp = np.ones(n_pos, dtype=np.int64)
        bcomp = np.empty(n_pos, dtype=np.int64)
        bwk = np.ones(n_pos)
        q = 0
        for j in range(bw.shape[0]):
            if min(bw[j], r_max) > 0.0:
                rb[q] = min(bw[j], r_max)
                ob[q] = bsrc[j]
                bcomp[q] = j
                q += 1
    Gb = rb.shape[0]
    Cb = bcomp.shape[0]
    n_nb = 0
    for l in range(nb_r.shape[0]):
        if nb_r[l] > 0.0:
            n_nb += 1
    # one predict_append call: survivors' and measurement births' components predicted, the birth tracks'
    # components appended (they are this scan's), and the FOV gate at every mean
    Cp = C0 + n_nb
    wp = np.empty(Cp)
    mp = np.empty((Cp, 4))
    Pp = np.empty((Cp, 4, 4))
    for c in range(C0):
        wp[c] = w[c]
        copy_state(mp, Pp, c, m, P, c)
    nb_idx = np.empty(n_nb, dtype=np.int64)
    q = 0
    for l in range(nb_r.shape[0]):
        if nb_r[l] > 0.0:
            nb_idx[q] = l
            wp[C0 + q] = 1.0
            copy_state(mp, Pp, C0 + q, nb_m, nb_P, l)
            q += 1
    bw2 = np.empty(Cb)
    bm2 = np.empty((Cb, 4))
    bP2 = np.empty((Cb, 4, 4))
    bs2 = np.zeros(Cb, dtype=np.int8)
    for c in range(Cb):
        bw2[c] = bwk[c]
        copy_state(bm2, bP2, c, bm, bP, bcomp[c])
    zi8 = np.zeros(Cp, dtype=np.int8)
    zi32 = np.zeros(Cp, dtype=np.int32)
    zi64 = np.zeros(Cp, dtype=np.int64)
    pred = predict_append(wp, mp, Pp, zi8, zi32, zi32, np.empty((0, 0)), zi64, F, Q, pred_pars, bw2, bm2, bP2, bs2,
                          np.zeros(4), ego, np.int64(0))  # fmt: skip
    pw, pm, pP, pg = pred[0], pred[1], pred[2], pred[8]
    # reorder into [survivors, birth tracks, measurement births]
    N = N0 + Gb + n_nb
    C = C0 + Cb + n_nb
    src = np.empty(C, dtype=np.int64)  # row of predict_append's output for each output component
    for c in range(C0):
        src[c] = c
    for c in range(Cb):
        src[C0 + c] = Cp + c
    for q in range(n_nb):
        src[C0 + Cb + q] = C0 + q
    w2 = np.empty(C)
    m2 = np.empty((C, 4))
    P2 = np.empty((C, 4, 4))
    g = np.empty(C)
    for c in range(C):
        s = src[c]
        w2[c] = pw[s]
        g[c] = pg[s]
        for a in range(4):
            m2[c, a] = pm[s, a]
            for b in range(4):
                P2[c, a, b] = pP[s, a, b]
    r2 = np.empty(N)
    label2 = np.empty(N, dtype=np.int64)
    origin2 = np.empty(N, dtype=np.int8)
    age2 = np.empty(N, dtype=np.int32)
    start2 = np.empty(N + 1, dtype=np.int64)
    start2[0] = 0
    for i in range(N0):
        r2[i] = r[i] * p_S
        label2[i] = label[i]
        origin2[i] = origin[i]
        age2[i] = age[i] + 1
        start2[i + 1] = start[i + 1]
    kk = np.int64(k) << np.int64(LABEL_SHIFT)
    for g_ in range(Gb):
        i = N0 + g_
        r2[i] = rb[g_]
        label2[i] = kk + (g_ if groups else bcomp[g_])
        origin2[i] = ob[g_]
        age2[i] = 0
        start2[i + 1] = start2[i] + nb_comp[g_]
    for q in range(n_nb):
        i = N0 + Gb + q
        r2[i] = nb_r[nb_idx[q]]
        label2[i] = kk + j0 + nb_idx[q]
        origin2[i] = nb_src
        age2[i] = 0
        start2[i + 1] = start2[i] + 1
    return r2, label2, origin2, age2, start2, w2, m2, P2, g


@njit(cache=True)
def all_finite(m, P):
    """Every entry of ``m`` and ``P`` finite (the newborn terms' check of
    :func:`soabench.gmphd.inputs.newborn_finite`)."""
    for x in m.flat:
        if not math.isfinite(x):
            return False
    for x in P.flat:
        if not math.isfinite(x):
            return False
    return True


@njit(cache=True)
def newborn_existence(r_U, beta, kappa, lambda_B, r_max, tol, adaptive):
    """The birth existences r_B of this scan's newborn terms (docs/method.md "LMB filter", birth) from the
    measurements' r_U: :func:`soabench.lmb.birth.adaptive_existence` (``adaptive``; ``beta`` and ``kappa`` unread)
    or :func:`soabench.lmb.birth.intensity_existence`, the same operations in the same order as those numpy
    expressions (``tol``: their :data:`~soabench.lmb.birth.EXPLAINED_TOL`; the sum is numpy's pairwise one)."""
    M = r_U.shape[0]
    free = np.empty(M)
    for ll in range(M):
        f = 1.0 - r_U[ll]  # clipped to [0, 1], and 0 at or below tol (a NaN too)
        free[ll] = (f if f <= 1.0 else 1.0) if f > tol else 0.0
    r_B = np.zeros(M)
    if adaptive:
        total = np_sum(free, M)
        if total > 0.0:
            for ll in range(M):
                x = lambda_B * free[ll] / total
                r_B[ll] = r_max if r_max < x else x  # np.minimum(r_max, x): x when x is NaN
    else:
        for ll in range(M):
            den = kappa[ll] + beta[ll]
            x = free[ll] * (beta[ll] / den if den > 0.0 else 0.0)
            r_B[ll] = r_max if r_max < x else x
    return r_B


@njit(cache=True)
def _segment_logsumexp(x, start, out, col):
    """out[i, col] = log sum exp of x[start[i]:start[i + 1]] (every segment non-empty), shifted by each segment's
    maximum (0 when that is not finite), as :func:`soabench.lmb.update._segment_logsumexp`."""
    for i in range(start.shape[0] - 1):
        mx = -np.inf
        for c in range(start[i], start[i + 1]):
            mx = max(mx, x[c])
        shift = mx if math.isfinite(mx) else 0.0
        s = 0.0
        for c in range(start[i], start[i + 1]):
            if x[c] != -np.inf:  # exp(-inf - shift) adds +0.0: nothing
                s += math.exp(x[c] - shift)
        out[i, col] = (math.log(s) if s > 0.0 else -np.inf) + shift


@njit(cache=True)
def _not_pd(n_sources):
    """What :func:`update_reduce` returns when a UKF covariance is not positive definite: ok False, all empty."""
    i64 = np.zeros(0, dtype=np.int64)
    tracks = (np.empty(0), i64, np.zeros(0, dtype=np.int8), np.zeros(0, dtype=np.int32), np.zeros(1, dtype=np.int64),
              np.empty(0), np.empty((0, 4)), np.empty((0, 4, 4)))  # fmt: skip
    counts = np.zeros(2 * n_sources + 1, dtype=np.int64)
    return (
        False,
        tracks,
        np.empty((0, 4)),
        np.empty(0),
        i64,
        np.empty(0),
        np.empty(0),
        np.zeros(2),
        np.zeros(6, dtype=np.int64),
        counts,
        np.zeros(2),
    )


@njit(cache=True)
def update_reduce(r, label, origin, age, start, w, m, P, p_D0, Z, ego, R, kappa, ukf, pars, seed, n_sources):
    """Steps 2-6 of the cycle (module docstring) on the predicted tracks with detection probabilities p_D0 (C,)
    (0 outside the FOV, behind an occluder, or for a dropped scan).

    Returns (ok, tracks (r, label, origin, age, start, w, m, P), X, X_r, labels, r_U, A, sums, counts, times):
    ``sums`` = (sum of the updated r, sum of the kept r), ``counts`` = (n_updated components, tracks kept by
    pruning, cap hit, detection pairs, ...), ``times`` the seconds of update and reduction, and ``ok`` False when
    a UKF covariance is not positive definite (nothing else computed: the caller runs the array path's rule).
    """
    t1 = monotonic()
    N = r.shape[0]
    C = w.shape[0]
    M = Z.shape[0]
    r_min, gate_thr = pars[UP_R_MIN], pars[UP_GATE]
    p_D = p_D0.copy()
    logq = np.full((C, M), -np.inf)
    # the measurement terms of the components that may be detected: every one with the UKF (a covariance that is
    # not positive definite decides the step wherever it is), else those with p_D != 0. A component with p_D = 0
    # takes no measurement whatever its terms, and each component's terms are its own, so the others' are the same
    # numbers either way. det[q] is the q-th such component, det_row[c] its row among them (-1 for none)
    det = np.arange(C)
    if not ukf:
        n_det = 0
        for c in range(C):
            if p_D0[c] != 0.0:
                det[n_det] = c
                n_det += 1
        det = det[:n_det]
    D = det.shape[0]
    det_row = np.full(C, -1, dtype=np.int64)
    for q in range(D):
        det_row[det[q]] = q
    if D == C:
        dm, dP = m, P
    else:
        dm = np.empty((D, 4))
        dP = np.empty((D, 4, 4))
        for q in range(D):
            copy_state(dm, dP, q, m, P, det[q])
    nu_r = np.empty((D, M))
    nu_b = np.empty((D, M))
    if ukf:
        eta, S, Sinv, logdet, Cx, H, valid, ok = ukf_terms(dm, dP, ego, R, r_min)
        if not ok:
            return _not_pd(n_sources)
    else:
        eta, S, Sinv, logdet, Cx, H, valid = ekf_terms(dm, dP, ego, R, r_min)
    for q in range(D):
        if not valid[q]:
            p_D[det[q]] = 0.0  # r -> 0 or det S <= 0: undetectable this step (§2.12)
    if D > 0 and M > 0:
        logq_d, nu_r, nu_b = log_likelihood(eta, Sinv, logdet, Z, gate_thr)
        for q in range(D):
            if p_D[det[q]] > 0.0:
                for ll in range(M):
                    logq[det[q], ll] = logq_d[q, ll]
    # association costs (docs/method.md "LMB filter", step 2), in the log domain
    log_miss = np.empty(C)
    log_det = np.empty((C, M))
    for c in range(C):
        log_w = math.log(w[c]) if w[c] > 0.0 else -np.inf
        log_miss[c] = log_w + (math.log1p(-p_D[c]) if p_D[c] < 1.0 else -np.inf)
        lwd = log_w + (math.log(p_D[c]) if p_D[c] > 0.0 else -np.inf)
        for ll in range(M):
            log_det[c, ll] = lwd + logq[c, ll]
    eta_tab = np.empty((N, 1 + M))  # log eta_miss, log eta_det (without r and kappa)
    _segment_logsumexp(log_miss, start, eta_tab, 0)
    col = np.empty(C)
    for ll in range(M):
        for c in range(C):
            col[c] = log_det[c, ll]
        _segment_logsumexp(col, start, eta_tab, 1 + ll)
    log_kappa = np.empty(M)
    for ll in range(M):
        log_kappa[ll] = math.log(max(kappa[ll], KAPPA_FLOOR))
    logc = np.empty((N, 2 + M))
    for i in range(N):
        log_r = math.log(r[i]) if r[i] > 0.0 else -np.inf
        logc[i, 0] = math.log1p(-r[i]) if r[i] < 1.0 else -np.inf
        logc[i, MISSED] = log_r + eta_tab[i, 0]
        for ll in range(M):
            logc[i, 2 + ll] = log_r + eta_tab[i, 1 + ll] - log_kappa[ll]
    marg, n_hyp, n_gibbs = association_marginals(logc, np.int64(pars[UP_MAX_HYP]), seed, False, pars[UP_EXACT] > 0.0)
    # the LMB approximation (step 4): r' and the posterior components, missed first, then by measurement
    r_new = np.empty(N)
    row = np.empty(M)
    for i in range(N):
        for ll in range(M):
            row[ll] = marg[i, 2 + ll]
        r_new[i] = marg[i, MISSED] + np_sum(row, M)
    r_U = np.zeros(M)
    for i in range(N):
        for ll in range(M):
            r_U[ll] += marg[i, 2 + ll]
    n_miss = 0
    n_pair = 0
    wm = np.zeros(C)
    wd = np.zeros((C, M))
    for i in range(N):
        r_safe = r_new[i] if r_new[i] > 0.0 else 1.0
        for c in range(start[i], start[i + 1]):
            v = marg[i, MISSED] * math.exp(log_miss[c] - eta_tab[i, 0]) / r_safe
            if math.isfinite(v) and v > 0.0:
                wm[c] = v
                n_miss += 1
            for ll in range(M):
                if marg[i, 2 + ll] == 0.0 or log_det[c, ll] == -np.inf:  # v would be 0 or NaN: not a pair
                    continue
                v = marg[i, 2 + ll] * math.exp(log_det[c, ll] - eta_tab[i, 1 + ll]) / r_safe
                if math.isfinite(v) and v > 0.0:
                    wd[c, ll] = v
                    n_pair += 1
    jj = np.empty(n_pair, dtype=np.int64)
    lj = np.empty(n_pair, dtype=np.int64)
    q = 0
    for c in range(C):  # component-major, as np.nonzero lists the pairs
        for ll in range(M):
            if wd[c, ll] > 0.0:
                jj[q] = c
                lj[q] = ll
                q += 1
    jd = np.empty(n_pair, dtype=np.int64)  # each pair's component among the detectable ones
    for p in range(n_pair):
        jd[p] = det_row[jj[p]]
    m_det, P_det = posterior_pairs(dm, dP, Cx, Sinv, S, H, R, jd, lj, nu_r, nu_b)
    pair_of = np.full((C, M), -1, dtype=np.int64)
    for p in range(n_pair):
        pair_of[jj[p], lj[p]] = p
    # posterior tracks: alive (r' > 0) with at least one component
    n_out = n_miss + n_pair
    uw = np.empty(n_out)
    um = np.empty((n_out, 4))
    uP = np.empty((n_out, 4, 4))
    ustart = np.zeros(N + 1, dtype=np.int64)
    kept = np.empty(N, dtype=np.int64)
    n_kept = np.int64(0)  # int64 from the start: a literal 0 compiles a second np_sum
    q = 0
    for i in range(N):
        q0 = q
        for c in range(start[i], start[i + 1]):
            if wm[c] > 0.0:
                uw[q] = wm[c]
                copy_state(um, uP, q, m, P, c)
                q += 1
        for ll in range(M):
            for c in range(start[i], start[i + 1]):
                p = pair_of[c, ll]
                if p >= 0:
                    uw[q] = wd[c, ll]
                    copy_state(um, uP, q, m_det, P_det, p)
                    q += 1
        if r_new[i] > 0.0 and q > q0:
            kept[n_kept] = i
            ustart[n_kept + 1] = q
            n_kept += 1
        else:
            q = q0
    n_updated = q
    post_r = np.empty(n_kept)
    for a in range(n_kept):
        post_r[a] = r_new[kept[a]]
    sum_r = np_sum(post_r, n_kept)
    # A_l such that A / (kappa + A) = r_U(z_l): what a model reading the previous step (ATBM prev_scan) needs
    A = np.empty(M)
    for ll in range(M):
        a = kappa[ll] * r_U[ll] / max(1.0 - r_U[ll], 1e-300) if r_U[ll] < 1.0 else np.inf
        A[ll] = a if math.isfinite(a) else _A_MAX
    t2 = monotonic()

    # track pruning and cap (step 5)
    sel = np.empty(n_kept, dtype=np.int64)
    n_sel = np.int64(0)
    for a in range(n_kept):
        if post_r[a] >= pars[UP_PRUNE_R]:
            sel[n_sel] = a
            n_sel += 1
    sel = sel[:n_sel]
    max_tracks = np.int64(pars[UP_MAX_TRACKS])
    cap_hit = n_sel > max_tracks
    if cap_hit:
        rs = np.empty(n_sel)
        for a in range(n_sel):
            rs[a] = -post_r[sel[a]]
        sel = np.sort(sel[np.argsort(rs, kind="mergesort")[:max_tracks]])
        n_sel = max_tracks
    s_start = np.zeros(n_sel + 1, dtype=np.int64)
    for a in range(n_sel):
        s_start[a + 1] = s_start[a] + ustart[sel[a] + 1] - ustart[sel[a]]
    Cs = s_start[n_sel]
    sw = np.empty(Cs)
    sm = np.empty((Cs, 4))
    sP = np.empty((Cs, 4, 4))
    fr = np.empty(n_sel)
    fl = np.empty(n_sel, dtype=np.int64)
    fo = np.empty(n_sel, dtype=np.int8)
    fa = np.empty(n_sel, dtype=np.int32)
    for a in range(n_sel):
        i = kept[sel[a]]
        fr[a] = r_new[i]
        fl[a] = label[i]
        fo[a] = origin[i]
        fa[a] = age[i]
        d = s_start[a] - ustart[sel[a]]
        for c in range(ustart[sel[a]], ustart[sel[a] + 1]):
            sw[c + d] = uw[c]
            copy_state(sm, sP, c + d, um, uP, c)
    fstart, fw, fm, fP = reduce_components(s_start, sw, sm, sP, pars[UP_PRUNE_T], pars[UP_MERGE_U],
                                           np.int64(pars[UP_MAX_COMP]))  # fmt: skip
    # estimates (step 6): r > extract_r, at the mean of the heaviest component (lowest index on ties)
    n_x = 0
    for a in range(n_sel):
        if fr[a] > pars[UP_EXTRACT_R]:
            n_x += 1
    X = np.empty((n_x, 4))
    X_r = np.empty(n_x)
    labels = np.empty(n_x, dtype=np.int64)
    q = 0
    for a in range(n_sel):
        if fr[a] > pars[UP_EXTRACT_R]:
            copy_row(X, q, fm, heaviest(fw, fstart[a], fstart[a + 1]))
            X_r[q] = fr[a]
            labels[q] = fl[a]
            q += 1
    sum_kept = np_sum(fr, n_sel)
    counts = origin_counts(fo, fa, n_sources)
    times = np.empty(2)
    times[0] = t2 - t1
    times[1] = monotonic() - t2
    sums = np.empty(2)
    sums[0], sums[1] = sum_r, sum_kept
    info = np.empty(6, dtype=np.int64)
    info[0], info[1], info[2], info[3], info[4], info[5] = n_updated, n_sel, cap_hit, n_pair, n_hyp, n_gibbs
    return True, (fr, fl, fo, fa, fstart, fw, fm, fP), X, X_r, labels, r_U, A, sums, info, counts, times
