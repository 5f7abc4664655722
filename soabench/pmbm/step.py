"""The PMBM and PMB filter cycle in one or two compiled calls per scan (docs/method.md §10.3, "How it runs").

:mod:`soabench.pmbm.cycle` compiles the update's arithmetic in three calls, with the prediction, the gate, the
measurement terms, the global hypotheses, the reductions and the estimates each a call of its own and Python in
between. At a trial's sizes (a few tracks, a handful of measurements) the fixed cost of those calls and of the arrays
they hand back to Python is as large as the arithmetic. Here the same compiled functions run inside two calls:

1. :func:`front` (:func:`predict_gate`, then :func:`update_terms`): the prediction of §10.2, the FOV gate at every
   stacked mean (as :func:`soabench.geometry.fov_mask`), p_D, the EKF terms and gated log-likelihoods of the
   GM-PHD's kernels and :func:`soabench.pmbm.cycle.detection_terms` (A_ℓ included);
2. :func:`back`: with the birth model's newborn terms β_ℓ (a Python callback that reads A_ℓ, the one reason for
   two calls), :func:`~soabench.pmbm.cycle.association_inputs`, the global hypotheses
   (:func:`soabench.pmbm.association.global_hypotheses`), :func:`~soabench.pmbm.cycle.posterior`, the undetected
   intensity's miss factor and reduction (:func:`soabench.gmphd.cycle.reduce`, the GM-PHD's prune, merge and cap),
   each hypothesis's reduction (:func:`soabench.lmb.tracks.reduce_components`), the hypotheses' marginal
   probabilities and then, in the PMBM, the estimates of §10.4 (:func:`soabench.pmbm.kernels.estimates`), in the PMB
   the collapse of §10.5, its second reduction and its estimates (:func:`pmb_posterior`, which the three-call path
   calls too).

With ``occlusion_pd`` the line of sight (shapely) splits the first call: :func:`predict_gate`, the line of sight in
Python, :func:`update_terms`. The formulas, their order and the exponentials are those of the three-call path (the
global weights by :func:`soabench.pmbm.kernels.global_weights` on both), so the two give the same numbers bit for bit
(tests/equivalence/test_pmbm_fused.py).
"""

from __future__ import annotations

import math

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()

from numba import njit  # noqa: E402

from soabench.gmphd import cycle as gmphd_cycle  # noqa: E402
from soabench.gmphd.clock import monotonic  # noqa: E402
from soabench.gmphd.cycle import fov_gate  # noqa: E402
from soabench.gmphd.kernels import ekf_terms, log_likelihood  # noqa: E402
from soabench.gmphd.mixture import UNLABELLED  # noqa: E402
from soabench.lmb.tracks import reduce_components  # noqa: E402
from soabench.pmbm.association import global_hypotheses  # noqa: E402
from soabench.pmbm.cycle import association_inputs, detection_terms, posterior, predict  # noqa: E402
from soabench.pmbm.kernels import collapse, estimates, global_weights, marginals  # noqa: E402

#: indices of :func:`predict_gate`'s ``fov``: r_min, r_max, Θ/2 + 1e-12, 1.0 for a limited field of view (< 360°),
#: 1.0 when the scan has an ego pose (0.0: a dropped scan, every p_D is 0)
FOV_R_MIN, FOV_R_MAX, FOV_HALF, FOV_LIMITED, FOV_EGO = range(5)


@njit(cache=True)
def _all_finite(x):
    """Every entry of ``x`` finite (``np.isfinite(x).all()``)."""
    for v in x.ravel():
        if not math.isfinite(v):
            return False
    return True


@njit(cache=True)
def predict_gate(ppp_w, ppp_m, ppp_P, b_w, b_m, b_P, hyp_m, hyp_P, F, Q, p_S, ego, fov):
    """:func:`soabench.pmbm.cycle.predict` and g = 1[mean in FOV_k] at each stacked mean (§4.1, the test of
    :func:`soabench.geometry.fov_mask`; 0 everywhere for a dropped scan). Returns (w, m_all, P_all, g)."""
    w, m_all, P_all = predict(ppp_w, ppp_m, ppp_P, b_w, b_m, b_P, hyp_m, hyp_P, F, Q, p_S)
    if fov[FOV_EGO] > 0.0:
        g = fov_gate(m_all, ego, fov[FOV_R_MIN], fov[FOV_R_MAX], fov[FOV_HALF], fov[FOV_LIMITED] > 0.0)
    else:
        g = np.zeros(m_all.shape[0])
    return w, m_all, P_all, g


@njit(cache=True)
def update_terms(m_all, P_all, g, p_D0, ego, R, r_min, gate_thr, Z, w_ppp, r, start, w, p_hyp):
    """p_D = p_D0 g at each stacked mean, 0 where the EKF terms are not valid (§2.12); the EKF terms and the gated
    log-likelihoods (:func:`soabench.gmphd.kernels.ekf_terms`, :func:`~soabench.gmphd.kernels.log_likelihood`);
    :func:`soabench.pmbm.cycle.detection_terms`. Returns (p_D, C, Sinv, S, H, nu_r, nu_b, and the eleven arrays of
    ``detection_terms``)."""
    N, M = m_all.shape[0], Z.shape[0]
    p_D = np.empty(N)
    for j in range(N):
        p_D[j] = p_D0 * g[j]
    eta, S, Sinv, logdet, Ct, Hj, valid = ekf_terms(m_all, P_all, ego, R, r_min)
    for j in range(N):
        if not valid[j]:
            p_D[j] = 0.0
    if N and M:
        logq, nu_r, nu_b = log_likelihood(eta, Sinv, logdet, Z, gate_thr)
    else:
        logq = np.full((N, M), -np.inf)
        nu_r = np.zeros((N, M))
        nu_b = np.zeros((N, M))
    det = detection_terms(p_D, logq, w_ppp, r, start, w, p_hyp)
    return (p_D, Ct, Sinv, S, Hj, nu_r, nu_b, det[0], det[1], det[2], det[3], det[4], det[5], det[6], det[7], det[8],
            det[9], det[10])  # fmt: skip


@njit(cache=True)
def front(ppp_w, ppp_m, ppp_P, b_w, b_m, b_P, hyp_m, hyp_P, F, Q, p_S, ego, fov, p_D0, R, r_min, gate_thr, Z, r,
          start, w, p_hyp):  # fmt: skip
    """:func:`predict_gate` then :func:`update_terms` (no line-of-sight gate): (w, m_all, P_all) of the prediction,
    :func:`update_terms`'s values and the seconds of the two (the clock of ``time.perf_counter``)."""
    t0 = monotonic()
    w_pred, m_all, P_all, g = predict_gate(ppp_w, ppp_m, ppp_P, b_w, b_m, b_P, hyp_m, hyp_P, F, Q, p_S, ego, fov)
    t1 = monotonic()
    t = update_terms(m_all, P_all, g, p_D0, ego, R, r_min, gate_thr, Z, w_pred, r, start, w, p_hyp)
    return w_pred, m_all, P_all, t, (t1 - t0, monotonic() - t1)


@njit(cache=True)
def pmb_posterior(track, table, ew, r, label, origin, age, start, w, m, P, T, U, J_h, thr):
    """The PMB's posterior from the PMBM's reduced one: the collapse of §10.5
    (:func:`soabench.pmbm.kernels.collapse`, ``ew`` the global weights), each track's density reduced again
    (:func:`soabench.lmb.tracks.reduce_components`) and the estimates of its one global hypothesis, which holds
    every track (§10.4). Returns (r, label, origin, age, start, w, m, P, the tracks 0..n-1, X, X_r, labels)."""
    c_r, c_label, c_origin, c_age, c_start, c_w, c_m, c_P = collapse(track, table, ew, r, label, origin, age, start, w,
                                                                     m, P)  # fmt: skip
    f_start, f_w, f_m, f_P = reduce_components(c_start, c_w, c_m, c_P, T, U, J_h)
    f_track = np.arange(c_r.shape[0])
    X, X_r, X_label = estimates(f_track, c_r, c_label, f_start, f_w, f_m, thr)
    return c_r, c_label, c_origin, c_age, f_start, f_w, f_m, f_P, f_track, X, X_r, X_label


@njit(cache=True)
def back(beta, kappa, log_t, log_e_ppp, log_miss, log_det, log_eta_miss, log_eta_det, log_r, log_l_miss_exact,
         log_l_miss, log_l_det, p_D, w_pred, m_all, P_all, prior_origin, prior_n_det, prior_age, prior_label, source,
         track, table, prior_log_w, start, w, label, origin, age, nb_m, nb_P, Ct, Sinv, S, Hj, R, nu_r, nu_b,
         red_pars, pars, label0, pmb):  # fmt: skip
    """Step 2 (module docstring). ``pars``: M_max, max_gap, w_floor, r_floor, SOURCE_MEAS, T, U, J_h, EXTRACT_R;
    ``red_pars``: :func:`soabench.gmphd.cycle.reduce`'s (no extraction). ``pmb``: collapse the posterior to one
    multi-Bernoulli (§10.5) and estimate from it; False: the PMBM's estimates of the best global hypothesis (§10.4).
    The predicted intensity's metadata are the prior's (``prior_*``, one prediction older) followed by the births'
    (``source``, never detected, age 0, unlabelled), as :meth:`soabench.pmbm.filter.PMBMFilter.predict` appends them.

    Returns (the updated intensity's weights (J,), the reduced intensity (w, m, P, origin, n_det, age, label), its
    (n_pruned, n_merged, cap_hit), the posterior's hypotheses reduced (r, label, origin, age, start, w, m, P), their
    track, table and log weights (in the PMB: the collapsed tracks, one global hypothesis of log weight 0), the
    estimates (X, X_r, labels), the number of updated hypothesis components, n_pairs, n_new, the origin counts (§5.7)
    of the reduced intensity and of the hypotheses, whether the reduced weights, existences and estimates are finite,
    the updated hypotheses' marginal probabilities P(h) and existences r_h (before the PMB's collapse: the terms of
    the posterior's expected number of targets), and the seconds of the update (association to posterior) and of the
    rest (the clock of ``time.perf_counter``))."""
    M_max, max_gap, w_floor, r_floor = np.int64(pars[0]), pars[1], pars[2], pars[3]
    source_meas, T, U, J_h, thr = np.int64(pars[4]), pars[5], pars[6], np.int64(pars[7]), pars[8]
    n_sources = np.int64(red_pars[gmphd_cycle.RED_N_SOURCES])
    t0 = monotonic()
    n = table.shape[1]
    J0, nb = prior_origin.shape[0], source.shape[0]
    ppp_origin = np.empty(J0 + nb, dtype=np.int8)
    ppp_n_det = np.zeros(J0 + nb, dtype=np.int32)
    ppp_age = np.zeros(J0 + nb, dtype=np.int32)
    ppp_label = np.full(J0 + nb, UNLABELLED, dtype=np.int64)
    for j in range(J0):
        ppp_origin[j], ppp_n_det[j], ppp_age[j], ppp_label[j] = (prior_origin[j], prior_n_det[j], prior_age[j] + 1,
                                                                 prior_label[j])  # fmt: skip
    for j in range(nb):
        ppp_origin[J0 + j] = source[j]
    log_beta, log_e, log_new, T_flat, T_start, L_flat, L_start, base0, ks = association_inputs(
        beta, kappa, log_e_ppp, track, log_l_det, n, prior_log_w, M_max
    )
    parent, choice, log_w, n_murty = global_hypotheses(table, prior_log_w, ks, T_flat, T_start, L_flat, L_start,
                                                       base0, log_l_miss, log_l_det, log_new, max_gap)  # fmt: skip
    post = posterior(parent, choice, log_w, M_max, w_floor, table, track, start, w, label, origin, age, log_t, log_e,
                     log_new, log_beta, beta, log_miss, log_det, log_eta_miss, log_eta_det, log_r, log_l_miss_exact,
                     ppp_origin, m_all, P_all, nb_m, nb_P, label0, r_floor, source_meas, Ct, Sinv, S, Hj, R, nu_r,
                     nu_b)  # fmt: skip
    o_r, o_label, o_origin, o_age, o_start, o_w, o_m, o_P, o_track, o_table, o_log_w, n_pairs, n_new = post
    t1 = monotonic()
    # the undetected intensity: missed (w (1 - p_D)), then the GM-PHD's reduction
    J = w_pred.shape[0]
    w_miss = np.empty(J)
    for j in range(J):
        w_miss[j] = w_pred[j] * (1.0 - p_D[j])
    ppp_m = m_all[:J].copy()
    ppp_P = P_all[:J].copy()
    red = gmphd_cycle.reduce(w_miss, ppp_m, ppp_P, ppp_origin, ppp_n_det, ppp_age, np.empty((0, 0)), ppp_label,
                             red_pars, np.int64(0))  # fmt: skip
    mix, stats = red[0], red[5]
    h_start, h_w, h_m, h_P = reduce_components(o_start, o_w, o_m, o_P, T, U, J_h)
    ew = global_weights(o_log_w)
    p_post = marginals(o_table, ew, o_r.shape[0])
    if pmb:
        f_r, f_label, f_origin, f_age, f_start, f_w, f_m, f_P, f_track, X, X_r, X_label = pmb_posterior(
            o_track, o_table, ew, o_r, o_label, o_origin, o_age, h_start, h_w, h_m, h_P, T, U, J_h, thr
        )
        f_table = f_track.reshape((1, f_track.shape[0]))
        f_log_w = np.zeros(1)
    else:
        best = 0
        for a in range(1, o_log_w.shape[0]):
            if o_log_w[a] > o_log_w[best]:
                best = a
        X, X_r, X_label = estimates(o_table[best], o_r, o_label, h_start, h_w, h_m, thr)
        f_r, f_label, f_origin, f_age, f_start, f_w, f_m, f_P = o_r, o_label, o_origin, o_age, h_start, h_w, h_m, h_P
        f_track, f_table, f_log_w = o_track, o_table, o_log_w
    counts = red[4] + gmphd_cycle.origin_counts(f_origin, f_age, n_sources)
    finite = _all_finite(mix[0]) and _all_finite(f_r) and _all_finite(X)
    return (w_miss, mix[0], mix[1], mix[2], mix[3], mix[4], mix[5], mix[7], stats[1], stats[2], stats[3], f_r,
            f_label, f_origin, f_age, f_start, f_w, f_m, f_P, f_track, f_table, f_log_w, X, X_r, X_label,
            o_w.shape[0], n_pairs, n_new, counts, finite, p_post, o_r, (t1 - t0, monotonic() - t1))  # fmt: skip
