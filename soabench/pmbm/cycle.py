"""The PMBM update's arithmetic as compiled loops (docs/method.md §10.3, "How it runs").

:func:`soabench.pmbm.update.update` makes, per scan, three calls of this module around two that stay outside it: the
birth model's newborn terms β_ℓ (a Python callback that reads A_ℓ) and the global hypotheses
(:func:`soabench.pmbm.association.global_hypotheses`, compiled on its own):

1. :func:`detection_terms`: from p_D and the gated log-likelihoods log q, the new tracks' intensity terms
   log p_D w q, their sums e_ℓ (without β_ℓ), each hypothesis's missed and detected sums (the LMB's η without r and
   κ), its likelihood factors l_miss and l_det, and A_ℓ, the predicted PHD's support of each measurement;
2. :func:`association_inputs`: with β_ℓ, the factor κ_ℓ + e_ℓ of each new track, the clusters and the number of
   assignments each prior global hypothesis asks for;
3. :func:`posterior`: the kept global hypotheses, the children's weights, :func:`soabench.pmbm.kernels.children`,
   the Kalman updates of the detected children (the GM-PHD's Joseph form), the merge of global hypotheses that
   became equal and the normalisation.

The formulas and their order are those of the array path (``update(..., fused=False)``, its reference); the
exponentials and logarithms are the C library's, where the array path takes numpy's vectorised ones, so the two
paths agree to rounding (tests/equivalence/test_pmbm_fused.py states the tolerance), not bit for bit. An entry that is
exp(-inf) is 0 without calling exp.
"""

from __future__ import annotations

import math

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()

from numba import njit  # noqa: E402

from soabench.gmphd.cycle import _logaddexp  # noqa: E402
from soabench.gmphd.kernels import copy_state, posterior_pairs  # noqa: E402
from soabench.pmbm.association import flat_clusters  # noqa: E402
from soabench.pmbm.kernels import children  # noqa: E402

KAPPA_FLOOR = 1e-300  #: the smallest clutter intensity and missed-detection factor (as the LMB's)
LOG_FLOOR = math.log(KAPPA_FLOOR)
NEG_INF = -np.inf


@njit(cache=True)
def _log(x: float) -> float:
    """ln x, -inf for x <= 0."""
    return math.log(x) if x > 0.0 else NEG_INF


@njit(cache=True)
def _exp_diff(x: float, y: float) -> float:
    """exp(x - y), 0 for x = -inf (the array path's exp(-inf - y) for finite y; 0 instead of its NaN when y is
    -inf too, which no caller reads)."""
    return math.exp(x - y) if x > NEG_INF else 0.0


@njit(cache=True)
def _predict_rows(m, P, F, Q, out_m, out_P, at):
    """Rows ``at`` .. of out_m, out_P: F m and (X + X^T) / 2 with X = F P F^T + Q (the GM-PHD's prediction, §2.5)."""
    T = np.empty((4, 4))
    X = np.empty((4, 4))
    for j in range(m.shape[0]):
        q = at + j
        for a in range(4):
            acc = 0.0
            for b in range(4):
                acc += F[a, b] * m[j, b]
            out_m[q, a] = acc
        for a in range(4):
            for b in range(4):
                acc = 0.0
                for c in range(4):
                    acc += F[a, c] * P[j, c, b]
                T[a, b] = acc
        for a in range(4):
            for b in range(4):
                acc = 0.0
                for c in range(4):
                    acc += T[a, c] * F[b, c]
                X[a, b] = acc + Q[a, b]
        for a in range(4):
            for b in range(4):
                out_P[q, a, b] = 0.5 * (X[a, b] + X[b, a])


@njit(cache=True)
def predict(ppp_w, ppp_m, ppp_P, b_w, b_m, b_P, hyp_m, hyp_P, F, Q, p_S):
    """The PMBM prediction's arithmetic (docs/method.md §10.2): the intensity's weights p_S w followed by the birth
    weights (J,), and the means (J + C, 4) and covariances (J + C, 4, 4) of the predicted intensity, the births and
    the hypotheses' predicted components, stacked in that order (the update's ``stacked`` input)."""
    J0, nb, C = ppp_w.shape[0], b_w.shape[0], hyp_m.shape[0]
    w = np.empty(J0 + nb)
    for j in range(J0):
        w[j] = ppp_w[j] * p_S
    for j in range(nb):
        w[J0 + j] = b_w[j]
    m_all = np.empty((J0 + nb + C, 4))
    P_all = np.empty((J0 + nb + C, 4, 4))
    _predict_rows(ppp_m, ppp_P, F, Q, m_all, P_all, 0)
    m_all[J0 : J0 + nb] = b_m
    P_all[J0 : J0 + nb] = b_P
    _predict_rows(hyp_m, hyp_P, F, Q, m_all, P_all, J0 + nb)
    return w, m_all, P_all


@njit(cache=True)
def detection_terms(p_D, logq, w_ppp, r, start, w, p_hyp):
    """Step 1 (module docstring).

    Args:
        p_D: (J + C,) p_D at the intensity's component means, then at the hypotheses' (0 where undetectable).
        logq: (J + C, M) gated log-likelihoods (-inf outside the gate).
        w_ppp: (J,) the predicted intensity's weights; r (H,), start (H + 1,), w (C,): the predicted hypotheses'
            existences and component weights; p_hyp (H,): each hypothesis's probability over the global hypotheses.

    Returns (log_t (J, M), log_e_ppp (M,), log_miss (C,), log_det (C, M), log_eta_miss (H,), log_eta_det (H, M),
    log_r (H,), log_l_miss_exact (H,), log_l_miss (H,) floored at ln 1e-300, log_l_det (H, M), A (M,)).
    """
    J = w_ppp.shape[0]
    C = w.shape[0]
    H = r.shape[0]
    M = logq.shape[1]
    # the undetected intensity's terms log p_D w q and their log-sum over the components (max shift)
    log_t = np.empty((J, M))
    mx = np.full(M, NEG_INF)
    for j in range(J):
        lpw = _log(p_D[j] * w_ppp[j]) if p_D[j] > 0.0 else NEG_INF
        for ll in range(M):
            x = lpw + logq[j, ll] if lpw > NEG_INF else NEG_INF
            log_t[j, ll] = x
            if x > mx[ll]:
                mx[ll] = x
    s = np.zeros(M)
    for j in range(J):
        for ll in range(M):
            if log_t[j, ll] > NEG_INF:
                s[ll] += math.exp(log_t[j, ll] - mx[ll])
    log_e_ppp = np.empty(M)
    for ll in range(M):
        log_e_ppp[ll] = math.log(s[ll]) + mx[ll] if mx[ll] > NEG_INF else NEG_INF
    # the hypotheses' per-component terms and their sums per hypothesis (eta without r)
    log_miss = np.empty(C)
    log_det = np.empty((C, M))
    log_eta_miss = np.empty(H)
    log_eta_det = np.empty((H, M))
    md = np.empty(M)  # per hypothesis: the detected terms' maxima and shifted sums (reset, not allocated, each time)
    sd = np.empty(M)
    for h in range(H):
        mm = NEG_INF
        md[:] = NEG_INF
        for c in range(start[h], start[h + 1]):
            pd = p_D[J + c]
            lw = _log(w[c])
            log_miss[c] = lw + (math.log1p(-pd) if pd < 1.0 else NEG_INF)
            if log_miss[c] > mm:
                mm = log_miss[c]
            lwd = lw + _log(pd)
            for ll in range(M):
                x = lwd + logq[J + c, ll] if lwd > NEG_INF else NEG_INF
                log_det[c, ll] = x
                if x > md[ll]:
                    md[ll] = x
        sm = 0.0
        sd[:] = 0.0
        for c in range(start[h], start[h + 1]):
            if log_miss[c] > NEG_INF:
                sm += math.exp(log_miss[c] - mm)
            for ll in range(M):
                if log_det[c, ll] > NEG_INF:
                    sd[ll] += math.exp(log_det[c, ll] - md[ll])
        log_eta_miss[h] = math.log(sm) + mm if mm > NEG_INF else NEG_INF
        for ll in range(M):
            log_eta_det[h, ll] = math.log(sd[ll]) + md[ll] if md[ll] > NEG_INF else NEG_INF
    # likelihood factors of a track's hypotheses: missed (1 - r + r eta_miss) and detected (r eta_det)
    log_r = np.empty(H)
    log_l_miss_exact = np.empty(H)
    log_l_miss = np.empty(H)
    log_l_det = np.empty((H, M))
    for h in range(H):
        log_r[h] = _log(r[h])
        l1m = math.log1p(-r[h]) if r[h] < 1.0 else NEG_INF
        log_l_miss_exact[h] = _logaddexp(l1m, log_r[h] + log_eta_miss[h])
        log_l_miss[h] = max(log_l_miss_exact[h], LOG_FLOOR)
        for ll in range(M):
            log_l_det[h, ll] = log_r[h] + log_eta_det[h, ll]
    # A_l: the predicted PHD's support of z_l (intensity, then every hypothesis weighted by its probability)
    A = np.empty(M)
    for ll in range(M):
        a = math.exp(log_e_ppp[ll]) if log_e_ppp[ll] > NEG_INF else 0.0
        for h in range(H):
            if log_eta_det[h, ll] > NEG_INF:
                a += p_hyp[h] * r[h] * math.exp(log_eta_det[h, ll])
        A[ll] = a
    return log_t, log_e_ppp, log_miss, log_det, log_eta_miss, log_eta_det, log_r, log_l_miss_exact, log_l_miss, \
        log_l_det, A  # fmt: skip


@njit(cache=True)
def association_inputs(beta, kappa, log_e_ppp, track, log_l_det, n, log_w, M_max):
    """Step 2 (module docstring): with the newborn terms ``beta`` (M,) (>= 0) and the clutter ``kappa`` (M,),
    (log_beta, log_e, log_new) of each measurement's new track (ln β_ℓ, ln e_ℓ, ln(κ_ℓ + e_ℓ) with κ floored at
    1e-300), the clusters of :func:`soabench.pmbm.association.flat_clusters` (T_flat, T_start, L_flat, L_start,
    base0) and ``ks``: ceil(M_max w_a) for each prior global hypothesis (log weights ``log_w``), at least 1, at most
    M_max (:func:`soabench.pmbm.association.assignments_asked`)."""
    M = beta.shape[0]
    log_beta = np.empty(M)
    log_e = np.empty(M)
    log_new = np.empty(M)
    for ll in range(M):
        log_beta[ll] = _log(beta[ll])
        log_e[ll] = _logaddexp(log_e_ppp[ll], log_beta[ll])
        log_new[ll] = _logaddexp(math.log(max(kappa[ll], KAPPA_FLOOR)), log_e[ll])
    T_flat, T_start, L_flat, L_start, base0 = flat_clusters(track, log_l_det, n, log_new)
    A = log_w.shape[0]
    ks = np.empty(A, dtype=np.int64)
    for a in range(A):
        k = np.ceil(M_max * math.exp(log_w[a]) - 1e-9)
        ks[a] = max(1, min(M_max, np.int64(k)))
    return log_beta, log_e, log_new, T_flat, T_start, L_flat, L_start, base0, ks


@njit(cache=True)
def _log_sum(x: np.ndarray) -> float:
    """ln sum exp(x) as numpy's ``logaddexp.reduce`` folds it (left to right)."""
    acc = x[0]
    for i in range(1, x.shape[0]):
        acc = _logaddexp(acc, x[i])
    return acc


@njit(cache=True)
def posterior(parent, choice, log_w, M_max, w_floor, table, track, start, w, label, origin, age, log_t, log_e,
              log_new, log_beta, beta, log_miss, log_det, log_eta_miss, log_eta_det, log_r, log_l_miss_exact,
              ppp_origin, m_all, P_all, nb_m, nb_P, label0, r_floor, source_meas, Ct, Sinv, S, Hj, R, nu_r,
              nu_b):  # fmt: skip
    """Step 3 (module docstring): from the new global hypotheses (parent, choice, unnormalised log weight) of
    :func:`soabench.pmbm.association.global_hypotheses`, the posterior's hypotheses, track of each, table and
    normalised log weights, with the counts of Kalman pairs and new tracks
    (:func:`soabench.pmbm.kernels.children`'s outputs; the Kalman-updated components filled in by
    :func:`soabench.gmphd.kernels.posterior_pairs` with the measurement terms Ct, Sinv, S, Hj, R, nu_r, nu_b).

    The global hypotheses below ``w_floor`` after normalisation are dropped (the heaviest is always kept; at most
    ``M_max``, by decreasing weight, ties in the order given); those that became equal once a track was dropped are
    merged (weights added, by decreasing weight, ties in lexicographic order of their rows)."""
    B0 = log_w.shape[0]
    norm = _log_sum(log_w)
    lw = np.empty(B0)
    for b in range(B0):
        lw[b] = log_w[b] - norm
    order = np.argsort(-lw, kind="mergesort")
    n_keep = 0
    for q in range(B0):
        if math.exp(lw[order[q]]) >= w_floor:
            n_keep += 1
    keep = np.empty(max(min(n_keep, M_max), 1), dtype=np.int64)
    if n_keep == 0:
        keep[0] = order[0]
    else:
        q = 0
        for p in range(B0):
            if q == keep.shape[0]:
                break
            if math.exp(lw[order[p]]) >= w_floor:
                keep[q] = order[p]
                q += 1
    B = keep.shape[0]
    n = choice.shape[1]
    k_parent = np.empty(B, dtype=np.int64)
    k_choice = np.empty((B, n), dtype=np.int64)
    k_log_w = np.empty(B)
    for b in range(B):
        k_parent[b] = parent[keep[b]]
        k_log_w[b] = lw[keep[b]]
        for i in range(n):
            k_choice[b, i] = choice[keep[b], i]
    # each hypothesis's missed existence, each component's missed and detected weight within its hypothesis
    H = log_r.shape[0]
    C, M = log_det.shape
    J = log_t.shape[0]
    r_miss = np.empty(H)
    degenerate = np.empty(H, dtype=np.bool_)
    E_miss = np.empty(C)
    E_det = np.empty((C, M))
    for h in range(H):
        lr = log_r[h] + log_eta_miss[h] - log_l_miss_exact[h]
        r_miss[h] = math.exp(lr) if np.isfinite(lr) else 0.0
        degenerate[h] = not np.isfinite(log_eta_miss[h])
        for c in range(start[h], start[h + 1]):
            E_miss[c] = _exp_diff(log_miss[c], log_eta_miss[h])
            for ll in range(M):
                E_det[c, ll] = _exp_diff(log_det[c, ll], log_eta_det[h, ll])
    # each measurement's new track: its intensity terms, newborn weight and "is its own" existence
    has_new = np.empty(M, dtype=np.bool_)
    W_all = np.empty((J, M))
    w_nb = np.empty(M)
    r_own = np.empty(M)
    for ll in range(M):
        has_new[ll] = np.isfinite(log_e[ll])
        w_nb[ll] = math.exp(log_beta[ll] - log_e[ll]) if beta[ll] > 0.0 else 0.0
        r_own[ll] = _exp_diff(log_e[ll], log_new[ll])
        for j in range(J):
            W_all[j, ll] = _exp_diff(log_t[j, ll], log_e[ll])
    out = children(table, k_parent, k_choice, track, start, w, label, origin, age, r_miss, degenerate, E_miss, E_det,
                   has_new, W_all, w_nb, r_own, ppp_origin, m_all, P_all, nb_m, nb_P, label0, r_floor,
                   source_meas)  # fmt: skip
    o_r, o_label, o_origin, o_age, o_start, o_w, o_m, o_P, o_track, o_table, uniq, inv, kal, rows, ells, n_pairs, \
        n_new = out  # fmt: skip
    if kal.shape[0]:
        order_p = np.argsort(rows, kind="mergesort")
        mk, Pk = posterior_pairs(m_all, P_all, Ct, Sinv, S, Hj, R, rows[order_p], ells[order_p], nu_r, nu_b)
        for p in range(order_p.shape[0]):
            q = kal[order_p[p]]
            copy_state(o_m, o_P, q, mk, Pk, p)  # element by element: a row view would take reference counts
    if uniq.shape[0] < o_table.shape[0]:
        merged = np.full(uniq.shape[0], NEG_INF)
        for b in range(B):
            merged[inv[b]] = _logaddexp(merged[inv[b]], k_log_w[b])
        order_u = np.argsort(-merged, kind="mergesort")
        o_table = uniq[order_u]
        k_log_w = merged[order_u]
    norm = _log_sum(k_log_w)
    for b in range(k_log_w.shape[0]):
        k_log_w[b] -= norm
    return o_r, o_label, o_origin, o_age, o_start, o_w, o_m, o_P, o_track, o_table, k_log_w, n_pairs, n_new
