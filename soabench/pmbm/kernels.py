"""The PMBM cycle's bookkeeping as compiled loops (docs/method.md §10.3-10.5).

* :func:`children`: given the kept new global hypotheses (parent and each track's choice), the posterior's
  single-target hypotheses (the old tracks' children, the new tracks' "went to a track" and "is its own"), their
  Gaussian-mixture densities (missed components and newborn components; the Kalman-updated components are marked
  for the caller, which fills them with the GM-PHD's Joseph-form kernel), the new global table, and the track
  pruning of the update (a track whose every hypothesis has r < ``r_floor`` is dropped with the hypotheses no global
  hypothesis uses any more);
* :func:`collapse`: the PMB's track-oriented collapse (§10.5);
* :func:`estimates`: the estimates of one global hypothesis (§10.4);
* :func:`global_weights`: the global hypotheses' weights from their logarithms, for every path alike.

Why: at a trial's sizes the array path of these steps is about eighty small numpy calls per scan, each costing
microseconds of fixed overhead. The arithmetic is the array path's (:func:`soabench.pmbm.update.update` and
:class:`soabench.pmbm.filter.PMBMFilter` with ``fused=False``) in the same order. :func:`children` takes the
exponentiated weights from its caller (:func:`soabench.pmbm.cycle.posterior`, which also merges the global
hypotheses that became equal and normalises their log weights). These kernels call no other large compiled function
(numba would compile it again inside each caller): the callers chain them with the GM-PHD's and the LMB's kernels.
"""

from __future__ import annotations

import math

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()

from numba import njit  # noqa: E402

from soabench.gmphd.kernels import copy_row, copy_state, heaviest  # noqa: E402

MISS = -1  #: a track's choice when no measurement is assigned to it (as :data:`soabench.pmbm.association.MISS`)


@njit(cache=True)
def unique_codes(code, size):
    """``np.unique(code, return_inverse=True)`` of the int64 codes (B, n) in 0 .. size - 1: the sorted distinct codes
    and the index of each code among them (B, n); by a table of the codes present when ``size`` is small against the
    number of codes, by a stable sort otherwise."""
    B, n = code.shape
    N = B * n
    inv = np.empty((B, n), dtype=np.int64)
    out = np.empty(N, dtype=np.int64)
    n_u = 0
    if size <= 4 * N + 4096:
        rank = np.full(size, -1, dtype=np.int64)
        for b in range(B):
            for i in range(n):
                rank[code[b, i]] = 0
        for x in range(size):
            if rank[x] == 0:
                rank[x] = n_u
                out[n_u] = x
                n_u += 1
        for b in range(B):
            for i in range(n):
                inv[b, i] = rank[code[b, i]]
        return out[:n_u], inv
    flat = np.empty(N, dtype=np.int64)
    for b in range(B):
        for i in range(n):
            flat[b * n + i] = code[b, i]
    order = np.argsort(flat, kind="mergesort")
    for q in range(N):
        x = flat[order[q]]
        if n_u == 0 or out[n_u - 1] != x:
            out[n_u] = x
            n_u += 1
        inv[order[q] // n, order[q] % n] = n_u - 1
    return out[:n_u], inv


@njit(cache=True)
def _row_less(t, x, y):
    """Row x of ``t`` comes before row y in lexicographic order."""
    for i in range(t.shape[1]):
        if t[x, i] != t[y, i]:
            return t[x, i] < t[y, i]
    return False


@njit(cache=True)
def unique_rows(t):
    """The distinct rows of the int64 table ``t`` (B, n) in lexicographic order and the index of each row among
    them, as :func:`soabench.pmbm.association.unique_rows` (a bottom-up merge sort of the rows)."""
    B, n = t.shape
    order = np.arange(B)
    tmp = np.empty(B, dtype=np.int64)
    width = 1
    while width < B:
        for lo in range(0, B, 2 * width):
            mid, hi = min(lo + width, B), min(lo + 2 * width, B)
            i, j, k = lo, mid, lo
            while i < mid and j < hi:
                if _row_less(t, order[j], order[i]):
                    tmp[k] = order[j]
                    j += 1
                else:
                    tmp[k] = order[i]
                    i += 1
                k += 1
            while i < mid:
                tmp[k] = order[i]
                i += 1
                k += 1
            while j < hi:
                tmp[k] = order[j]
                j += 1
                k += 1
        order, tmp = tmp, order
        width *= 2
    inv = np.empty(B, dtype=np.int64)
    first = np.empty(B, dtype=np.int64)
    n_u = 0
    for q in range(B):
        if q == 0 or _row_less(t, order[q - 1], order[q]):
            first[n_u] = order[q]
            n_u += 1
        inv[order[q]] = n_u - 1
    uniq = np.empty((n_u, n), dtype=np.int64)
    for u in range(n_u):
        for i in range(n):
            uniq[u, i] = t[first[u], i]
    return uniq, inv


@njit(cache=True)
def children(table, parent, choice, track, start, w, label, origin, age, r_miss, degenerate, E_miss, E_det,
             has_new, W_all, w_nb, r_own, ppp_origin, m_all, P_all, nb_m, nb_P, label0, r_floor,
             source_meas):  # fmt: skip
    """The posterior hypotheses, table and pruning of the update (module docstring).

    Args:
        table: (A, n) the prior global table; parent (B,), choice (B, n): the kept new global hypotheses.
        track, start, w, label, origin, age: the predicted hypotheses (H of them, C components).
        r_miss: (H,) r of each hypothesis's missed child; degenerate: (H,) its missed density is the prior
            (every component has p_D = 1); E_miss (C,), E_det (C, M): each component's missed and detected weight
            within its hypothesis (w p q / eta, exponentiated by the caller).
        has_new: (M,) e_l > 0 (z_l has a new track); W_all (J, M): the new tracks' intensity weights
            p_D w q / e_l; w_nb (M,): the newborn component's weight beta_l / e_l (0 without one); r_own (M,):
            e_l / (kappa_l + e_l); ppp_origin: (J,) the intensity's origins.
        m_all, P_all: the intensity's components then the hypotheses' (J + C rows).
        nb_m, nb_P: the newborn components (one per measurement, or none).
        label0: the new track of z_l gets label label0 + l; source_meas: the origin of a measurement-driven birth.

    Returns (r, label, origin, age, start, w, m, P, track, table, uniq, inv, kal, rows, ells, n_pairs, n_new): the
    kept hypotheses, the track of each, the table (B, kept tracks) indexing them, its distinct rows in lexicographic
    order with the index of each row among them (when a track was dropped; else the table itself), the components
    ``kal`` whose m and P the caller fills with the Kalman update of row ``rows`` of m_all by measurement ``ells``
    (:func:`soabench.lmb.measurement.kalman_pairs`, which a compiled caller would have to compile again), the
    Kalman pairs built (kept or not) and the new tracks.
    """
    B, n = choice.shape
    M = has_new.shape[0]
    J = W_all.shape[0]
    n_hyp = start.shape[0] - 1
    # the old tracks' children: the distinct (hypothesis, choice) codes of the new global hypotheses
    code = np.empty((B, n), dtype=np.int64)
    for b in range(B):
        a = parent[b]
        for i in range(n):
            code[b, i] = table[a, i] * (M + 1) + (choice[b, i] + 1)
    old_u, old_inv = unique_codes(code, n_hyp * (M + 1))
    n_old = old_u.shape[0]
    # the new tracks: measurements with e_l > 0; "went to a track" used where some hypothesis takes z_l
    n_new = 0
    for ll in range(M):
        if has_new[ll]:
            n_new += 1
    new_l = np.empty(n_new, dtype=np.int64)
    q = 0
    for ll in range(M):
        if has_new[ll]:
            new_l[q] = ll
            q += 1
    taken = np.zeros((B, M), dtype=np.bool_)
    for b in range(B):
        for i in range(n):
            if choice[b, i] != MISS:
                taken[b, choice[b, i]] = True
    used0 = np.zeros(n_new, dtype=np.bool_)
    used1 = np.zeros(n_new, dtype=np.bool_)
    for t in range(n_new):
        for b in range(B):
            if taken[b, new_l[t]]:
                used0[t] = True
            else:
                used1[t] = True
    first = np.empty(n_new, dtype=np.int64)
    n_child = n_old
    for t in range(n_new):
        first[t] = n_child
        n_child += np.int64(used0[t]) + np.int64(used1[t])
    # each new track's heaviest intensity term and origin
    heaviest = np.zeros(n_new, dtype=np.int64)
    any_ppp = np.zeros(n_new, dtype=np.bool_)
    new_origin = np.empty(n_new, dtype=np.int8)
    for t in range(n_new):
        ll = new_l[t]
        best = 0
        for j in range(J):
            v = W_all[j, ll]
            if v > 0.0:
                any_ppp[t] = True
            if (v if v > 0.0 else -1.0) > (W_all[best, ll] if W_all[best, ll] > 0.0 else -1.0):
                best = j
        heaviest[t] = best
        nb_heavier = w_nb[ll] > 0.0 and (not any_ppp[t] or w_nb[ll] >= (W_all[best, ll] if J else 0.0))
        new_origin[t] = source_meas if nb_heavier or J == 0 else ppp_origin[best]
    # every child: existence, track, label, origin, age
    c_r = np.empty(n_child)
    c_track = np.empty(n_child, dtype=np.int64)
    c_label = np.empty(n_child, dtype=np.int64)
    c_origin = np.empty(n_child, dtype=np.int8)
    c_age = np.empty(n_child, dtype=np.int32)
    h_par = np.empty(n_old, dtype=np.int64)
    h_choice = np.empty(n_old, dtype=np.int64)
    for u in range(n_old):
        hp = old_u[u] // (M + 1)
        h_par[u] = hp
        h_choice[u] = old_u[u] % (M + 1) - 1
        c_r[u] = r_miss[hp] if h_choice[u] == MISS else 1.0
        c_track[u] = track[hp]
        c_label[u] = label[hp]
        c_origin[u] = origin[hp]
        c_age[u] = age[hp]
    for t in range(n_new):
        c = first[t]
        if used0[t]:
            c_r[c] = 0.0
            c += 1
        if used1[t]:
            c_r[c] = r_own[new_l[t]]
        for c in range(first[t], first[t] + np.int64(used0[t]) + np.int64(used1[t])):
            c_track[c] = n + t
            c_label[c] = label0 + new_l[t]
            c_origin[c] = new_origin[t]
            c_age[c] = 0
    # track pruning: a track lives while one of its hypotheses has r >= r_floor; its children are all used
    n_tr = n + n_new
    alive = np.zeros(n_tr, dtype=np.bool_)
    for c in range(n_child):
        if c_r[c] >= r_floor:
            alive[c_track[c]] = True
    track_remap = np.full(n_tr, -1, dtype=np.int64)
    n_alive = 0
    for i in range(n_tr):
        if alive[i]:
            track_remap[i] = n_alive
            n_alive += 1
    child_remap = np.full(n_child, -1, dtype=np.int64)
    n_kept = 0
    for c in range(n_child):
        if alive[c_track[c]]:
            child_remap[c] = n_kept
            n_kept += 1
    # the children's densities: component records (source row of m_all, measurement or MISS, newborn or -1, weight)
    n_rec = 0
    n_pairs = 0
    for u in range(n_old):
        hp, ell = h_par[u], h_choice[u]
        for c in range(start[hp], start[hp + 1]):
            v = E_det[c, ell] if ell != MISS else (w[c] if degenerate[hp] else E_miss[c])
            if v > 0.0:
                if ell != MISS:
                    n_pairs += 1
                if child_remap[u] >= 0:
                    n_rec += 1
    for t in range(n_new):
        ll = new_l[t]
        keep = 1 if alive[n + t] else 0
        if used0[t]:
            n_rec += keep
        if used1[t]:
            for j in range(J):
                if W_all[j, ll] > 0.0:
                    n_pairs += 1
                    n_rec += keep
            if w_nb[ll] > 0.0:
                n_rec += keep
    rec_row = np.empty(n_rec, dtype=np.int64)
    rec_ell = np.empty(n_rec, dtype=np.int64)
    rec_nb = np.empty(n_rec, dtype=np.int64)
    out_w = np.empty(n_rec)
    out_start = np.zeros(n_kept + 1, dtype=np.int64)
    q = 0
    for u in range(n_old):
        if child_remap[u] < 0:
            continue
        hp, ell = h_par[u], h_choice[u]
        for c in range(start[hp], start[hp + 1]):
            v = E_det[c, ell] if ell != MISS else (w[c] if degenerate[hp] else E_miss[c])
            if v > 0.0:
                rec_row[q] = J + c
                rec_ell[q] = ell
                rec_nb[q] = -1
                out_w[q] = v
                q += 1
        out_start[child_remap[u] + 1] = q
    for t in range(n_new):
        if not alive[n + t]:
            continue
        ll = new_l[t]
        c = first[t]
        if used0[t]:  # one component: the heaviest intensity term's prediction, or the newborn component
            rec_row[q] = heaviest[t] if any_ppp[t] else 0
            rec_ell[q] = MISS
            rec_nb[q] = -1 if any_ppp[t] else ll
            out_w[q] = 1.0
            q += 1
            out_start[child_remap[c] + 1] = q
            c += 1
        if used1[t]:  # the intensity's Kalman-updated terms, then the newborn component
            for j in range(J):
                if W_all[j, ll] > 0.0:
                    rec_row[q] = j
                    rec_ell[q] = ll
                    rec_nb[q] = -1
                    out_w[q] = W_all[j, ll]
                    q += 1
            if w_nb[ll] > 0.0:
                rec_row[q] = 0
                rec_ell[q] = MISS
                rec_nb[q] = ll
                out_w[q] = w_nb[ll]
                q += 1
            out_start[child_remap[c] + 1] = q
    out_m = np.empty((n_rec, 4))
    out_P = np.empty((n_rec, 4, 4))
    n_kal = 0
    for q in range(n_rec):
        if rec_ell[q] != MISS:
            n_kal += 1
        elif rec_nb[q] >= 0:
            copy_state(out_m, out_P, q, nb_m, nb_P, rec_nb[q])
        else:
            copy_state(out_m, out_P, q, m_all, P_all, rec_row[q])
    kal = np.empty(n_kal, dtype=np.int64)  # the Kalman-updated records, left to the caller
    p = 0
    for q in range(n_rec):
        if rec_ell[q] != MISS:
            kal[p] = q
            p += 1
    # the kept children's attributes and the table over the kept tracks
    o_r = np.empty(n_kept)
    o_label = np.empty(n_kept, dtype=np.int64)
    o_origin = np.empty(n_kept, dtype=np.int8)
    o_age = np.empty(n_kept, dtype=np.int32)
    o_track = np.empty(n_kept, dtype=np.int64)
    for c in range(n_child):
        k = child_remap[c]
        if k >= 0:
            o_r[k] = c_r[c]
            o_label[k] = c_label[c]
            o_origin[k] = c_origin[c]
            o_age[k] = c_age[c]
            o_track[k] = track_remap[c_track[c]]
    out_table = np.empty((B, n_alive), dtype=np.int64)
    for b in range(B):
        for i in range(n):
            if alive[i]:
                out_table[b, track_remap[i]] = child_remap[old_inv[b, i]]
        for t in range(n_new):
            if alive[n + t]:
                own = 0 if taken[b, new_l[t]] else 1
                out_table[b, track_remap[n + t]] = child_remap[first[t] + (own & np.int64(used0[t]))]
    # global hypotheses that became equal when a track was dropped: the caller adds their weights
    if n_alive < n_tr and B > 1:
        uniq, inv = unique_rows(out_table)
    else:
        uniq, inv = out_table, np.arange(B)
    return (o_r, o_label, o_origin, o_age, out_start, out_w, out_m, out_P, o_track, out_table, uniq, inv, kal,
            rec_row[kal], rec_ell[kal], n_pairs, n_new)  # fmt: skip


@njit(cache=True)
def global_weights(log_w):
    """(A,) the weights e^(log w_a) of the global hypotheses, by the C library's exp: every path of the PMBM and the
    PMB exponentiates them here (numpy's vectorised exp can differ from it in the last bit on some CPUs), so the
    whole-cycle path, which exponentiates them inside its compiled calls, and the others agree bit for bit (the
    marginals P(h), the PMB's collapse, the assignments asked of each cluster, the cardinality distribution)."""
    ew = np.empty(log_w.shape[0])
    for a in range(log_w.shape[0]):
        ew[a] = math.exp(log_w[a])
    return ew


@njit(cache=True)
def marginals(table, ew, n_hyp):
    """(n_hyp,) the marginal probability P(h) of each single-target hypothesis: the weights ``ew`` (A,) of the
    global hypotheses that pick it (table (A, n)) added in the table's row order, as
    :meth:`soabench.pmbm.density.PMBMDensity.hypothesis_probabilities` adds them (``np.bincount``)."""
    p = np.zeros(n_hyp)
    A, n = table.shape
    for a in range(A):
        for i in range(n):
            p[table[a, i]] += ew[a]
    return p


@njit(cache=True)
def collapse(track, table, ew, r, label, origin, age, start, w, m, P):
    """The track-oriented PMB (docs/method.md §10.5) of the hypotheses with global table ``table`` (A, n) and
    weights ``ew`` (A,) (exponentiated by the caller), as :func:`soabench.pmbm.pmb.collapse` computes it (the same
    sums in the same order): (r, label, origin, age, start, w, m, P) of one Bernoulli per track with r > 0."""
    n = table.shape[1]
    n_hyp = r.shape[0]
    p = marginals(table, ew, n_hyp)  # P(h)
    pr = np.empty(n_hyp)
    rt = np.zeros(n)
    for h in range(n_hyp):
        pr[h] = p[h] * r[h]
        rt[track[h]] += pr[h]
    best = np.full(n, -1, dtype=np.int64)  # the most probable hypothesis of each track (lowest index on ties)
    for h in range(n_hyp):
        i = track[h]
        if best[i] < 0 or pr[h] > pr[best[i]]:
            best[i] = h
    N = 0
    for i in range(n):
        if rt[i] > 0.0:
            N += 1
    count = np.zeros(n, dtype=np.int64)
    n_c = 0
    for h in range(n_hyp):
        i = track[h]
        if rt[i] > 0.0:
            for c in range(start[h], start[h + 1]):
                if pr[h] * w[c] > 0.0:
                    count[i] += 1
                    n_c += 1
    o_r = np.empty(N)
    o_label = np.empty(N, dtype=np.int64)
    o_origin = np.empty(N, dtype=np.int8)
    o_age = np.empty(N, dtype=np.int32)
    o_start = np.zeros(N + 1, dtype=np.int64)
    k = 0
    for i in range(n):
        if rt[i] > 0.0:
            b = best[i]
            o_r[k] = rt[i]
            o_label[k] = label[b]
            o_origin[k] = origin[b]
            o_age[k] = age[b]
            o_start[k + 1] = o_start[k] + count[i]
            k += 1
    o_w = np.empty(n_c)
    o_m = np.empty((n_c, 4))
    o_P = np.empty((n_c, 4, 4))
    q = 0
    for h in range(n_hyp):  # components grouped by track: the hypotheses of a track are contiguous
        i = track[h]
        if rt[i] > 0.0:
            for c in range(start[h], start[h + 1]):
                v = pr[h] * w[c]
                if v > 0.0:
                    o_w[q] = v / rt[i]
                    copy_state(o_m, o_P, q, m, P, c)
                    q += 1
    return o_r, o_label, o_origin, o_age, o_start, o_w, o_m, o_P


@njit(cache=True)
def estimates(row, r, label, start, w, m, thr):
    """Step 4's estimates (docs/method.md §10.4) in the global hypothesis that picks hypothesis ``row[i]`` of each
    track i: every track whose hypothesis has r > ``thr``, at the mean of its heaviest component (lowest index on
    ties), labelled, as :meth:`soabench.lmb.tracks.Tracks.estimates` of those hypotheses. Returns (X, X_r, labels)."""
    n = row.shape[0]
    n_x = 0
    for i in range(n):
        if r[row[i]] > thr:
            n_x += 1
    X = np.empty((n_x, 4))
    X_r = np.empty(n_x)
    labels = np.empty(n_x, dtype=np.int64)
    q = 0
    for i in range(n):
        h = row[i]
        if r[h] > thr:
            if start[h + 1] == start[h]:
                raise ValueError("a reported track has no component")
            copy_row(X, q, m, heaviest(w, start[h], start[h + 1]))
            X_r[q] = r[h]
            labels[q] = label[h]
            q += 1
    return X, X_r, labels
