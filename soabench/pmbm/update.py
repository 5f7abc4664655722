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

import functools
from dataclasses import dataclass

import numpy as np

from soabench.gmphd.mixture import Mixture
from soabench.gmphd.models import logsumexp0
from soabench.lmb.measurement import MeasurementModel, kalman_pairs
from soabench.lmb.tracks import Tracks
from soabench.lmb.update import KAPPA_FLOOR, association_terms
from soabench.pmbm import cycle
from soabench.pmbm.association import (
    MISS,
    clusters,
    global_hypotheses,
    new_global_hypotheses,
    unique_rows,
)
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


_NO_NEWBORN = (np.zeros((0, 4)), np.zeros((0, 4, 4)))
_NO_JACOBIAN = np.zeros((0, 2, 4))  #: the UKF form has no H: the Kalman update then uses P - K S K^T


def _segments(counts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def _ranges(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The concatenated ranges starts[i] .. starts[i] + counts[i] - 1."""
    ends = np.cumsum(counts)
    return np.repeat(starts - (ends - counts), counts) + np.arange(ends[-1] if len(ends) else 0)


def _unique_codes(code: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(code, return_inverse=True)`` for codes in 0 .. size - 1, the inverse shaped like ``code``: by a
    table of the codes present when it is small against ``code``, with numpy's sort otherwise."""
    if size > 4 * code.size + 4096:
        u, inv = np.unique(code, return_inverse=True)
        return u, inv.reshape(code.shape)
    present = np.zeros(size, dtype=bool)
    present[code] = True
    return np.flatnonzero(present), (np.cumsum(present) - 1)[code]


@functools.cache
def _max_gap(w_floor: float) -> float:
    """-ln w_floor (inf for 0): solutions costing more than this above a cluster's best are not searched for."""
    return float(-np.log(w_floor)) if w_floor > 0.0 else np.inf


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
    fused: bool = True,
    stacked: tuple[np.ndarray, np.ndarray] | None = None,
    p_hyp: np.ndarray | None = None,
) -> UpdateResult:
    """PMBM update of the predicted density ``pred`` with Z (M, 2) (module docstring).

    Args:
        p_D_ppp, p_D_hyp: p_D at each component mean of the intensity (J,) and of the hypotheses (C,).
        kappa: (M,) clutter intensity of each measurement.
        newborn: the birth model's measurement-driven terms (PUBM, ATBM), or None.
        label0: the new track of z_l gets label label0 + l.
        fused: the update's arithmetic in three compiled calls (:mod:`soabench.pmbm.cycle`); False: the array path,
            its reference (the same formulas with numpy's exponentials and logarithms: equal to rounding).
        stacked: the means (J + C, 4) and covariances (J + C, 4, 4) of the intensity's components followed by the
            hypotheses', when the caller has them stacked; None stacks them here.
        p_hyp: ``pred.hypothesis_probabilities()`` when the caller has them; None computes them here.
    """
    Z = np.ascontiguousarray(Z, dtype=float).reshape(-1, 2)
    M = len(Z)
    ppp, hyps = pred.ppp, pred.hyps
    J, C, H, n = len(ppp), len(hyps.w), len(hyps), pred.n_tracks
    if stacked is None:
        m_all, P_all = np.concatenate([ppp.m, hyps.m]), np.concatenate([ppp.P, hyps.P])
    else:
        m_all, P_all = stacked
    p_D = np.concatenate([np.asarray(p_D_ppp, dtype=float).reshape(J), np.asarray(p_D_hyp, dtype=float).reshape(C)])
    terms = nu_r = nu_b = None
    if J + C:
        terms = model.terms(m_all, P_all, ego)
        p_D[~terms.valid] = 0.0  # r -> 0 or det S <= 0: undetectable this step (§2.12)
    if J + C and M:
        logq, nu_r, nu_b = model.log_likelihood(terms, Z)
        if not fused:  # the compiled terms read log q only where p_D > 0
            logq = np.where(p_D[:, None] > 0.0, logq, -np.inf)
    else:
        logq = np.full((J + C, M), -np.inf)
    kappa = np.asarray(kappa, dtype=float).reshape(M)
    if fused:
        return _update_compiled(pred, p_D, logq, kappa, terms, nu_r, nu_b, model, m_all, P_all, newborn, label0, hyp,
                                p_hyp)  # fmt: skip

    with np.errstate(divide="ignore", invalid="ignore"):
        # undetected intensity and the new tracks' detection terms
        log_t = np.log(p_D[:J] * ppp.w)[:, None] + logq[:J]  # (J, M) log p_D w q
        log_e_ppp = logsumexp0(log_t)
        # tracks: the LMB's per-hypothesis sums (eta without r and kappa)
        owner = hyps.owner()
        log_miss, log_det, log_eta_miss, log_eta_det = association_terms(hyps, p_D[J:], logq[J:], owner)
        log_r = np.log(hyps.r)
        log_l_miss_exact = np.logaddexp(np.log1p(-hyps.r), log_r + log_eta_miss)
        log_l_miss = np.maximum(log_l_miss_exact, LOG_FLOOR)
        log_l_det = log_r[:, None] + log_eta_det
        # support of each measurement by the predicted PHD (what ATBM's "unexplained" allocation reads)
        A = np.exp(log_e_ppp)
        if H and M:
            if p_hyp is None:
                p_hyp = pred.hypothesis_probabilities()
            A = A + (p_hyp * hyps.r) @ np.exp(log_eta_det)
        beta = np.zeros(M)
        if newborn is not None and M:
            beta = np.asarray(newborn.beta(A, kappa.copy()), dtype=float).reshape(M)
            beta = np.where(beta > 0.0, beta, 0.0)
        log_beta = np.log(beta)
        log_e = np.logaddexp(log_e_ppp, log_beta)
        log_new = np.logaddexp(np.log(np.maximum(kappa, KAPPA_FLOOR)), log_e)

    # global hypotheses
    max_gap = _max_gap(hyp.w_floor)
    groups = clusters(pred.track, np.isfinite(log_l_det), n)
    parent, choice, log_w, n_murty = new_global_hypotheses(
        pred.table, pred.log_w, groups, log_l_miss, log_l_det, log_new, hyp.M_max, max_gap
    )
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

    old_u, old_inv = _unique_codes(old_code, len(hyps) * (M + 1))
    h_par, h_choice = np.divmod(old_u, M + 1)
    h_choice = h_choice - 1
    # a track's kept children: the old codes are grouped by parent hypothesis, hence by track (pred.track sorted)
    child_track = pred.track[h_par]

    # --- the children's densities, as component records (child, source row, measurement for a Kalman update or -1,
    # weight); a child's records are its density's components in order
    n_old_u = len(old_u)
    start = hyps.start
    cnt = start[h_par + 1] - start[h_par]
    child = np.repeat(np.arange(n_old_u), cnt)
    comp = _ranges(start[h_par], cnt)  # component index in hyps
    ell = np.repeat(h_choice, cnt)
    hp = np.repeat(h_par, cnt)
    det = ell != MISS
    w_rec = np.empty(len(comp))
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.flatnonzero(det)
        w_rec[d] = np.exp(log_det[comp[d], ell[d]] - log_eta_det[hp[d], ell[d]])
        mi = np.flatnonzero(~det)
        degenerate = ~np.isfinite(log_eta_miss[hp[mi]])  # every component has p_D = 1: the prior density is kept
        w_rec[mi] = np.where(degenerate, hyps.w[comp[mi]], np.exp(log_miss[comp[mi]] - log_eta_miss[hp[mi]]))
        lr = log_r[h_par] + log_eta_miss[h_par] - log_l_miss_exact[h_par]
    r_old = np.where(h_choice == MISS, np.where(np.isfinite(lr), np.exp(lr), 0.0), 1.0)
    keep_rec = w_rec > 0.0
    rec_child, rec_row, rec_ell, rec_w = child[keep_rec], J + comp[keep_rec], ell[keep_rec], w_rec[keep_rec]
    rec_nb = np.full(len(rec_child), -1, dtype=np.int64)  # newborn term of a record (-1: none)

    # new tracks: "went to a track" (code 0, r = 0) then "is its own" (code 1), per measurement with e_l > 0
    n_new = len(new_l)
    with np.errstate(divide="ignore", invalid="ignore"):
        W = np.exp(log_t[:, new_l] - log_e[new_l])  # (J, n_new) the new tracks' intensity terms
        w_nb = np.where(beta[new_l] > 0.0, np.exp(log_beta[new_l] - log_e[new_l]), 0.0)
    used0 = (new_code == 0).any(axis=0)
    used1 = (new_code == 1).any(axis=0)
    n_hyp_new = used0.astype(np.int64) + used1
    first = n_old_u + np.concatenate([[0], np.cumsum(n_hyp_new)[:-1]]).astype(np.int64)  # first child of each
    is_child = first + used0  # the child index of "is its own" (when used1)
    not_child = first
    heaviest = np.argmax(np.where(W > 0.0, W, -1.0), axis=0) if J else np.zeros(n_new, dtype=np.int64)
    any_ppp = (W > 0.0).any(axis=0) if J else np.zeros(n_new, dtype=bool)
    nb_heavier = (w_nb > 0.0) & (~any_ppp | (w_nb >= (W[heaviest, np.arange(n_new)] if J else 0.0)))
    new_origin = np.where(nb_heavier, SOURCE_MEAS, ppp.origin[heaviest] if J else SOURCE_MEAS)
    # "is its own": the intensity's Kalman-updated terms, then the newborn component
    tt, jj = np.nonzero((W > 0.0).T & used1[:, None])
    nb_t = np.flatnonzero(used1 & (w_nb > 0.0))
    # "went to a track": one component, the heaviest intensity term's prediction or the newborn component
    n0 = np.flatnonzero(used0)
    n0_ppp = n0[any_ppp[n0]]
    n0_nb = n0[~any_ppp[n0]]
    rec_child = np.concatenate([rec_child, is_child[tt], is_child[nb_t], not_child[n0_ppp], not_child[n0_nb]])
    zeros = np.zeros(len(nb_t) + len(n0_nb), dtype=np.int64)
    rec_row = np.concatenate([rec_row, jj, zeros[: len(nb_t)], heaviest[n0_ppp], zeros[len(nb_t) :]])
    rec_ell = np.concatenate([rec_ell, new_l[tt], np.full(len(nb_t) + len(n0), MISS)])
    rec_w = np.concatenate([rec_w, W[jj, tt], w_nb[nb_t], np.ones(len(n0))])
    rec_nb = np.concatenate([rec_nb, np.full(len(tt), -1), new_l[nb_t], np.full(len(n0_ppp), -1), new_l[n0_nb]])
    order = np.argsort(rec_child, kind="stable")  # records of a child contiguous, in the order listed
    rec_child, rec_row, rec_ell, rec_w, rec_nb = (x[order] for x in (rec_child, rec_row, rec_ell, rec_w, rec_nb))

    n_out = len(rec_w)
    m_out = np.empty((n_out, 4))
    P_out = np.empty((n_out, 4, 4))
    plain = (rec_ell == MISS) & (rec_nb < 0)
    m_out[plain], P_out[plain] = m_all[rec_row[plain]], P_all[rec_row[plain]]
    nb = rec_nb >= 0
    if nb.any():
        m_out[nb] = np.asarray(newborn.m, dtype=float).reshape(-1, 4)[rec_nb[nb]]
        P_out[nb] = np.asarray(newborn.P, dtype=float).reshape(-1, 4, 4)[rec_nb[nb]]
    kal = np.flatnonzero(rec_ell != MISS)
    n_pairs = len(kal)
    if n_pairs:
        order_p = kal[np.argsort(rec_row[kal], kind="stable")]
        mk, Pk = kalman_pairs(m_all, P_all, terms, model.R, rec_row[order_p], rec_ell[order_p], nu_r, nu_b)
        m_out[order_p], P_out[order_p] = mk, Pk

    n_child = n_old_u + int(n_hyp_new.sum())
    counts = np.bincount(rec_child, minlength=n_child)
    # each new track's hypotheses in order: "went to a track" (when used0), then "is its own" (when used1)
    hyp_new = np.flatnonzero(np.column_stack([used0, used1]))  # 2 t + code
    new_t, is_own = hyp_new // 2, hyp_new % 2 == 1
    r_new = np.where(is_own, np.exp(log_e[new_l] - log_new[new_l])[new_t], 0.0)
    post_hyps = Tracks(
        np.concatenate([r_old, r_new]),
        np.concatenate([hyps.label[h_par], label0 + new_l[new_t]]).astype(np.int64),
        np.concatenate([hyps.origin[h_par], new_origin[new_t]]).astype(np.int8),
        np.concatenate([hyps.age[h_par], np.zeros(len(new_t), np.int32)]).astype(np.int32),
        _segments(counts),
        rec_w,
        m_out,
        P_out,
    )
    # the new table: old tracks' columns index their children, new tracks' columns follow
    table = np.hstack([old_inv, first[None, :] + (new_code & used0[None, :])]) if n_new else old_inv
    track_of = np.concatenate([child_track, n + new_t]).astype(np.int64)
    density = _prune_tracks(PMBMDensity(ppp_missed(ppp, p_D[:J]), post_hyps, track_of, table, log_w), hyp.r_floor)
    return UpdateResult(density, A, beta, n_pairs, n_new, n_murty, n_global)


def _floats(x: np.ndarray) -> np.ndarray:
    """``x`` as a C-contiguous float64 array (the one layout the compiled calls are specialised for)."""
    return np.ascontiguousarray(x, dtype=float)


def _update_compiled(
    pred: PMBMDensity,
    p_D: np.ndarray,
    logq: np.ndarray,
    kappa: np.ndarray,
    terms,
    nu_r: np.ndarray | None,
    nu_b: np.ndarray | None,
    model: MeasurementModel,
    m_all: np.ndarray,
    P_all: np.ndarray,
    newborn: NewbornTerms | None,
    label0: int,
    hyp: Hypotheses,
    p_hyp: np.ndarray | None,
) -> UpdateResult:
    """:func:`update` after the measurement terms, by :mod:`soabench.pmbm.cycle` (its module docstring): the
    compiled detection terms, the birth model's newborn terms, the compiled association inputs, the global
    hypotheses, the compiled posterior."""
    ppp, hyps = pred.ppp, pred.hyps
    J, H, M = len(ppp), len(hyps), len(kappa)
    if p_hyp is None:
        p_hyp = pred.hypothesis_probabilities() if H and M else np.zeros(H)
    start = hyps.start
    w, r, logq, w_ppp, p_hyp = (_floats(x) for x in (hyps.w, hyps.r, logq, ppp.w, p_hyp))
    log_t, log_e_ppp, log_miss, log_det, log_eta_miss, log_eta_det, log_r, log_l_miss_exact, log_l_miss, log_l_det, \
        A = cycle.detection_terms(p_D, logq, w_ppp, r, start, w, p_hyp)  # fmt: skip
    beta = np.zeros(M)
    if newborn is not None and M:
        beta = np.asarray(newborn.beta(A, kappa.copy()), dtype=float).reshape(M)
        beta = np.where(beta > 0.0, beta, 0.0)
    track = np.ascontiguousarray(pred.track, dtype=np.int64)
    table = np.ascontiguousarray(pred.table, dtype=np.int64)
    prior_log_w = np.ascontiguousarray(pred.log_w, dtype=float)
    log_beta, log_e, log_new, T_flat, T_start, L_flat, L_start, base0, ks = cycle.association_inputs(
        beta, kappa, log_e_ppp, track, log_l_det, pred.n_tracks, prior_log_w, int(hyp.M_max)
    )
    parent, choice, log_w, n_murty = global_hypotheses(
        table, prior_log_w, ks, T_flat, T_start, L_flat, L_start, base0, log_l_miss, log_l_det, log_new,
        float(_max_gap(hyp.w_floor)),
    )  # fmt: skip
    if newborn is not None and M:
        nb_m = np.ascontiguousarray(np.asarray(newborn.m, dtype=float).reshape(-1, 4))
        nb_P = np.ascontiguousarray(np.asarray(newborn.P, dtype=float).reshape(-1, 4, 4))
    else:
        nb_m, nb_P = _NO_NEWBORN
    n_rows = len(m_all)
    if terms is None:  # no component: no Kalman pair is ever built
        Ct, Sinv, S, Hj = np.zeros((0, 4, 2)), np.zeros((0, 2, 2)), np.zeros((0, 2, 2)), _NO_JACOBIAN
    else:
        Ct, Sinv, S = (_floats(x) for x in (terms.C, terms.Sinv, terms.S))
        Hj = _floats(terms.H) if terms.H is not None else _NO_JACOBIAN
    if nu_r is None:
        nu_r = nu_b = np.zeros((n_rows, M))
    nu_r, nu_b = _floats(nu_r), _floats(nu_b)
    r, label, origin, age, start, w, m, P, track_of, table, log_w, n_pairs, n_new = cycle.posterior(
        parent, choice, log_w, int(hyp.M_max), float(hyp.w_floor), table, track, start, w, hyps.label, hyps.origin,
        hyps.age, log_t, log_e, log_new, log_beta, beta, log_miss, log_det, log_eta_miss, log_eta_det, log_r,
        log_l_miss_exact, ppp.origin, m_all, P_all, nb_m, nb_P, int(label0), float(hyp.r_floor), int(SOURCE_MEAS),
        Ct, Sinv, S, Hj, np.asarray(model.R, dtype=float), nu_r, nu_b,
    )  # fmt: skip
    density = PMBMDensity(ppp_missed(ppp, p_D[:J]), Tracks(r, label, origin, age, start, w, m, P), track_of, table,
                          log_w)  # fmt: skip
    return UpdateResult(density, A, beta, int(n_pairs), int(n_new), int(n_murty), len(parent))


def ppp_missed(ppp: Mixture, p_D: np.ndarray) -> Mixture:
    """The undetected intensity after the update: w_c (1 - p_D,c), means and covariances unchanged."""
    return Mixture(ppp.w * (1.0 - p_D), ppp.m, ppp.P, ppp.origin, ppp.n_det, ppp.age, None, ppp.label)


def _merged(uniq: np.ndarray, inv: np.ndarray, log_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The global hypotheses ``uniq`` (distinct rows, lexicographic order) with the weights of the rows ``inv`` maps
    to each added, by decreasing weight (stable)."""
    merged = np.full(len(uniq), -np.inf)
    np.logaddexp.at(merged, inv, log_w)
    order = np.argsort(-merged, kind="stable")
    return uniq[order], merged[order]


def _prune_tracks(d: PMBMDensity, r_floor: float) -> PMBMDensity:
    """Drop the tracks whose every hypothesis has r < ``r_floor``; merge the global hypotheses that became equal
    (their weights add); drop the single-target hypotheses no global hypothesis uses; renumber."""
    n = d.n_tracks
    alive = np.bincount(d.track, weights=d.hyps.r >= r_floor, minlength=n) > 0.0
    cols = np.flatnonzero(alive)
    table, log_w = d.table[:, cols], d.log_w
    if len(cols) < n and table.shape[0] > 1:
        uniq, inv = unique_rows(table)
        if len(uniq) < table.shape[0]:
            table, log_w = _merged(uniq, inv, log_w)
    log_w = log_w - np.logaddexp.reduce(log_w)
    used = np.flatnonzero(np.bincount(table.ravel(), minlength=len(d.hyps)))  # sorted, as np.unique(table)
    hyps = d.hyps if len(used) == len(d.hyps) else d.hyps.select(used)
    remap = np.full(len(d.hyps), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    track_remap = np.full(n, -1, dtype=np.int64)
    track_remap[cols] = np.arange(len(cols))
    return PMBMDensity(d.ppp, hyps, track_remap[d.track[used]], remap[table], log_w)
