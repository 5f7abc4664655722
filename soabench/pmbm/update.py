"""The PMBM update (docs/method.md §10.3) with the GM-PHD's measurement terms and the birth models' newborn terms.

With p_D,c at each component mean and q_cl the GM-PHD's gated likelihoods (the same measurement model, EKF or UKF):

* undetected intensity: w_c <- (1 - p_D,c) w_c;
* hypothesis h of a track (existence r, components omega_c), missed: likelihood factor
  l_miss = 1 - r + r sum_c omega_c (1 - p_D,c), r' = r sum_c omega_c (1 - p_D,c) / l_miss, density the missed
  components; detected by z_l: l_det = r sum_c omega_c p_D,c q_cl, r' = 1, density the Kalman-updated components;
* new track of z_l: e_l = sum_c p_D,c w_c q_cl + beta_l (beta_l: the birth model's newborn term, the number the
  GM-PHD adds to its normaliser); "z_l is its own" has factor kappa_l + e_l, r = e_l / (kappa_l + e_l) and the
  Kalman-updated intensity components plus the newborn component; "z_l went to a track" has factor 1, r = 0;
* global hypotheses by Murty's algorithm per cluster (:mod:`soabench.pmbm.association`); a new global weight is
  the parent's times the chosen likelihood factors, normalised; then the global hypotheses below ``w_floor`` are
  dropped (at most ``M_max`` kept), the single-target hypotheses no global hypothesis uses are dropped, and so is
  a track whose every hypothesis has r < ``r_floor``.

Clutter intensities and missed-detection factors below 1e-300 are raised to 1e-300 (a large finite cost, as the
LMB does): every measurement can then be clutter and every track missed, so an assignment always exists.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from soabench.gmphd.mixture import Mixture
from soabench.gmphd.models import logsumexp0
from soabench.lmb.measurement import MeasurementModel, kalman_pairs
from soabench.lmb.tracks import Tracks
from soabench.lmb.update import KAPPA_FLOOR, association_costs
from soabench.pmbm.association import MISS, ClusterSolver, clusters, new_global_hypotheses
from soabench.pmbm.density import PMBMDensity
from soabench.types import SOURCE_MEAS, NewbornTerms

LOG_FLOOR = float(np.log(KAPPA_FLOOR))  #: the smallest log likelihood factor of a miss or of clutter


@dataclass(frozen=True)
class Hypotheses:
    """Global hypothesis management of the update (§10.3, register row 36)."""

    M_max: int = 100  #: global hypotheses kept; each prior a asks Murty for ceil(M_max w_a) assignments
    w_floor: float = 1e-4  #: global hypotheses below this weight are dropped (then renormalised)
    r_floor: float = 1e-5  #: a track whose every hypothesis has r below this is dropped


@dataclass
class UpdateResult:
    """The posterior of :func:`update` (densities not yet reduced) and its diagnostics."""

    density: PMBMDensity
    A: np.ndarray  #: (M,) support of each measurement by the predicted PHD
    beta: np.ndarray  #: (M,) the birth model's newborn terms
    n_pairs: int  #: Kalman-updated (component, measurement) pairs built
    n_newborn: int  #: new tracks built
    n_murty: int  #: Murty runs
    n_global: int  #: global hypotheses before pruning


def _segments(counts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def update(
    pred: PMBMDensity,
    Z: np.ndarray,
    ego: np.ndarray,
    p_D_ppp: np.ndarray,
    p_D_hyp: np.ndarray,
    kappa: np.ndarray,
    model: MeasurementModel,
    *,
    newborn: NewbornTerms | None = None,
    label0: int = 1,
    hyp: Hypotheses = Hypotheses(),
) -> UpdateResult:
    """PMBM update of the predicted density ``pred`` with Z (M, 2) (module docstring).

    Args:
        p_D_ppp, p_D_hyp: p_D at each component mean of the intensity (J,) and of the hypotheses (C,).
        kappa: (M,) clutter intensity of each measurement.
        newborn: the birth model's measurement-driven terms (PUBM, ATBM), or None.
        label0: the new track of z_l gets label label0 + l.
    """
    Z = np.ascontiguousarray(Z, dtype=float).reshape(-1, 2)
    M = len(Z)
    ppp, hyps = pred.ppp, pred.hyps
    J, C, H, n = len(ppp), len(hyps.w), len(hyps), pred.n_tracks
    m_all = np.concatenate([ppp.m, hyps.m])
    P_all = np.concatenate([ppp.P, hyps.P])
    p_D = np.concatenate([np.asarray(p_D_ppp, dtype=float).reshape(J), np.asarray(p_D_hyp, dtype=float).reshape(C)])
    logq = np.full((J + C, M), -np.inf)
    terms = nu_r = nu_b = None
    if J + C:
        terms = model.terms(m_all, P_all, ego)
        p_D[~terms.valid] = 0.0  # r -> 0 or det S <= 0: undetectable this step (§2.12)
        if M:
            logq, nu_r, nu_b = model.log_likelihood(terms, Z)
            logq = np.where(p_D[:, None] > 0.0, logq, -np.inf)
    kappa = np.asarray(kappa, dtype=float).reshape(M)

    with np.errstate(divide="ignore", invalid="ignore"):
        # undetected intensity and the new tracks' detection terms
        log_t = np.log(p_D[:J] * ppp.w)[:, None] + logq[:J]  # (J, M) log p_D w q
        log_e_ppp = logsumexp0(log_t)
        # tracks: the LMB's per-hypothesis sums (eta without r and kappa)
        _, log_miss, log_det, log_eta_miss, log_eta_det = association_costs(hyps, p_D[J:], logq[J:], kappa)
        log_r = np.log(hyps.r)
        log_l_miss_exact = np.logaddexp(np.log1p(-hyps.r), log_r + log_eta_miss)
        log_l_miss = np.maximum(log_l_miss_exact, LOG_FLOOR)
        log_l_det = log_r[:, None] + log_eta_det
        # support of each measurement by the predicted PHD (what ATBM's "unexplained" allocation reads)
        A = np.exp(log_e_ppp)
        if H and M:
            A = A + (pred.hypothesis_probabilities() * hyps.r) @ np.exp(log_eta_det)
        beta = np.zeros(M)
        if newborn is not None and M:
            beta = np.asarray(newborn.beta(A, kappa.copy()), dtype=float).reshape(M)
            beta = np.where(beta > 0.0, beta, 0.0)
        log_beta = np.log(beta)
        log_e = np.logaddexp(log_e_ppp, log_beta)
        log_new = np.logaddexp(np.log(np.maximum(kappa, KAPPA_FLOOR)), log_e)

    # global hypotheses
    groups = clusters(pred.track, np.isfinite(log_l_det), n)
    max_gap = -np.log(hyp.w_floor) if hyp.w_floor > 0.0 else np.inf
    solver = ClusterSolver(groups, log_l_miss, log_l_det, log_new, max_gap)
    parent, choice, log_w = new_global_hypotheses(pred.table, pred.log_w, groups, solver, hyp.M_max)
    n_global = len(log_w)
    log_w = log_w - np.logaddexp.reduce(log_w)
    order = np.argsort(-log_w, kind="stable")
    keep = order[np.exp(log_w[order]) >= hyp.w_floor]
    keep = (keep if len(keep) else order[:1])[: hyp.M_max]
    parent, choice, log_w = parent[keep], choice[keep], log_w[keep]

    # single-target hypotheses used: (old hypothesis, choice) for the old tracks, (l, is-its-own) for the new ones
    B = len(log_w)
    old_code = pred.table[parent] * (M + 1) + (choice + 1)  # (B, n)
    has_new = np.isfinite(log_e)  # e_l > 0: a measurement without detection terms has no new track (r = 0)
    new_l = np.flatnonzero(has_new)
    taken = np.zeros((B, M), dtype=bool)
    rows, cols = np.nonzero(choice != MISS)
    taken[rows, choice[rows, cols]] = True
    new_code = (~taken[:, new_l]).astype(np.int64)  # (B, n_new): 1 = z_l is its own, 0 = it went to a track

    old_u, old_inv = np.unique(old_code, return_inverse=True)
    old_inv = old_inv.reshape(B, n)
    h_par, h_choice = np.divmod(old_u, M + 1)
    h_choice = h_choice - 1
    miss = h_choice == MISS
    # a track's kept children: the old codes are grouped by parent hypothesis, hence by track (pred.track sorted)
    child_track = pred.track[h_par]

    # --- the children's densities
    parts_r, parts_count, parts_w, parts_m, parts_P = [], [], [], [], []
    pairs_c, pairs_l, pairs_slot = [], [], []  # Kalman pairs (component row in m_all, measurement, output slot)
    n_out = 0
    labels, origins, ages = [], [], []
    for u in range(len(old_u)):
        h = h_par[u]
        a, b = hyps.start[h], hyps.start[h + 1]
        labels.append(hyps.label[h])
        origins.append(hyps.origin[h])
        ages.append(hyps.age[h])
        if miss[u]:
            lr = log_r[h] + log_eta_miss[h] - log_l_miss_exact[h]
            r_new = float(np.exp(lr)) if np.isfinite(lr) else 0.0
            if np.isfinite(log_eta_miss[h]):
                w = np.exp(log_miss[a:b] - log_eta_miss[h])
                sel = np.flatnonzero(w > 0.0)
                w = w[sel]
            else:  # every component has p_D = 1: r' = 0, the prior density is kept
                sel = np.arange(b - a)
                w = hyps.w[a:b]
            parts_r.append(r_new)
            parts_count.append(len(sel))
            parts_w.append(w)
            parts_m.append(hyps.m[a + sel])
            parts_P.append(hyps.P[a + sel])
            n_out += len(sel)
        else:
            ell = h_choice[u]
            w = np.exp(log_det[a:b, ell] - log_eta_det[h, ell])
            sel = np.flatnonzero(w > 0.0)
            parts_r.append(1.0)
            parts_count.append(len(sel))
            parts_w.append(w[sel])
            parts_m.append(None)
            parts_P.append(None)
            pairs_c.append(J + a + sel)
            pairs_l.append(np.full(len(sel), ell))
            pairs_slot.append(n_out + np.arange(len(sel)))
            n_out += len(sel)
    # new tracks: "is its own" then "went to a track", per measurement with e_l > 0
    n_new = len(new_l)
    used_new = [np.unique(new_code[:, t]) for t in range(n_new)]
    new_track_hyps = []
    for t, ell in enumerate(new_l):
        w_ppp = np.exp(log_t[:, ell] - log_e[ell])
        sel = np.flatnonzero(w_ppp > 0.0)
        w_nb = float(np.exp(log_beta[ell] - log_e[ell])) if beta[ell] > 0.0 else 0.0
        r_is = float(np.exp(log_e[ell] - log_new[ell]))
        heaviest_nb = w_nb > 0.0 and (len(sel) == 0 or w_nb >= w_ppp[sel].max())
        origin = SOURCE_MEAS if heaviest_nb else int(ppp.origin[sel[np.argmax(w_ppp[sel])]])
        comps_w = np.concatenate([w_ppp[sel], [w_nb] if w_nb > 0.0 else []])
        hyps_here = []
        for code in used_new[t]:
            labels.append(label0 + ell)
            origins.append(origin)
            ages.append(0)
            if code == 1:
                parts_r.append(r_is)
                k = len(comps_w)
                parts_count.append(k)
                parts_w.append(comps_w)
                if w_nb > 0.0:
                    nb_m = np.asarray(newborn.m, dtype=float).reshape(-1, 4)[ell : ell + 1]
                    nb_P = np.asarray(newborn.P, dtype=float).reshape(-1, 4, 4)[ell : ell + 1]
                    parts_m.append(np.concatenate([np.full((len(sel), 4), np.nan), nb_m]))
                    parts_P.append(np.concatenate([np.full((len(sel), 4, 4), np.nan), nb_P]))
                else:
                    parts_m.append(None)
                    parts_P.append(None)
                pairs_c.append(sel)
                pairs_l.append(np.full(len(sel), ell))
                pairs_slot.append(n_out + np.arange(len(sel)))
                n_out += k
            else:  # r = 0: any density; one component, the heaviest PPP term's prediction
                j = sel[np.argmax(w_ppp[sel])] if len(sel) else None
                parts_r.append(0.0)
                parts_count.append(1)
                parts_w.append(np.ones(1))
                if j is not None:
                    parts_m.append(ppp.m[j : j + 1])
                    parts_P.append(ppp.P[j : j + 1])
                else:
                    parts_m.append(np.asarray(newborn.m, dtype=float).reshape(-1, 4)[ell : ell + 1])
                    parts_P.append(np.asarray(newborn.P, dtype=float).reshape(-1, 4, 4)[ell : ell + 1])
                n_out += 1
            hyps_here.append(code)
        new_track_hyps.append(hyps_here)

    w_all = np.concatenate(parts_w) if parts_w else np.zeros(0)
    m_out = np.full((n_out, 4), np.nan)
    P_out = np.full((n_out, 4, 4), np.nan)
    pos = 0
    for cnt, mm, PP in zip(parts_count, parts_m, parts_P, strict=True):
        if mm is not None:
            ok = np.isfinite(mm[:, 0])
            m_out[pos : pos + cnt][ok] = mm[ok]
            P_out[pos : pos + cnt][ok] = PP[ok]
        pos += cnt
    n_pairs = 0
    if pairs_c:
        pc, pl, ps = np.concatenate(pairs_c), np.concatenate(pairs_l), np.concatenate(pairs_slot)
        n_pairs = len(pc)
        if n_pairs:
            order_p = np.argsort(pc, kind="stable")
            mk, Pk = kalman_pairs(m_all, P_all, terms, model.R, pc[order_p], pl[order_p], nu_r, nu_b)
            m_out[ps[order_p]] = mk
            P_out[ps[order_p]] = Pk

    counts = np.asarray(parts_count, dtype=np.int64)
    post_hyps = Tracks(
        np.asarray(parts_r, dtype=float),
        np.asarray(labels, dtype=np.int64),
        np.asarray(origins, dtype=np.int8),
        np.asarray(ages, dtype=np.int32),
        _segments(counts),
        w_all,
        m_out,
        P_out,
    )
    # the new table: old tracks' columns index their children, new tracks' columns follow
    n_old_h = len(old_u)
    table_old = old_inv
    new_cols = []
    offset = n_old_h
    for t in range(n_new):
        codes = np.asarray(new_track_hyps[t])
        new_cols.append(offset + np.searchsorted(codes, new_code[:, t]))
        offset += len(codes)
    table = np.hstack([table_old] + [c[:, None] for c in new_cols]) if n_new else table_old
    track_of = np.concatenate(
        [child_track] + [np.full(len(new_track_hyps[t]), n + t, dtype=np.int64) for t in range(n_new)]
    ).astype(np.int64)

    density = _prune_tracks(PMBMDensity(ppp_missed(ppp, p_D[:J]), post_hyps, track_of, table, log_w), hyp.r_floor)
    return UpdateResult(density, A, beta, n_pairs, n_new, solver.n_murty, n_global)


def ppp_missed(ppp: Mixture, p_D: np.ndarray) -> Mixture:
    """The undetected intensity after the update: w_c (1 - p_D,c), means and covariances unchanged."""
    return Mixture(ppp.w * (1.0 - p_D), ppp.m, ppp.P, ppp.origin, ppp.n_det, ppp.age, None, ppp.label)


def _prune_tracks(d: PMBMDensity, r_floor: float) -> PMBMDensity:
    """Drop the tracks whose every hypothesis has r < ``r_floor``; merge the global hypotheses that became equal
    (their weights add); drop the single-target hypotheses no global hypothesis uses; renumber."""
    n = d.n_tracks
    alive = np.zeros(n, dtype=bool)
    np.logical_or.at(alive, d.track, d.hyps.r >= r_floor)
    cols = np.flatnonzero(alive)
    table = d.table[:, cols]
    log_w = d.log_w
    if len(cols) < n and table.shape[0] > 1:
        uniq, inv = np.unique(table, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        if len(uniq) < table.shape[0]:
            merged = np.full(len(uniq), -np.inf)
            np.logaddexp.at(merged, inv, log_w)
            order = np.argsort(-merged, kind="stable")
            table, log_w = uniq[order], merged[order]
    log_w = log_w - np.logaddexp.reduce(log_w)
    used = np.unique(table)
    hyps = d.hyps.select(used)
    remap = np.full(len(d.hyps), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    track_remap = np.full(n, -1, dtype=np.int64)
    track_remap[cols] = np.arange(len(cols))
    return PMBMDensity(d.ppp, hyps, track_remap[d.track[used]], remap[table], log_w)
