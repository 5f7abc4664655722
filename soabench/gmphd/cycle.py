"""The fused GM-PHD cycle (docs/method.md §2.11): predict, gate, update, prune, merge, cap and extract as compiled
loops over arrays, one call per scan (EKF and UKF, both probability modes).

Why: at the mixture sizes of a trial (tens of components, a handful of measurements) the array path of
:mod:`soabench.gmphd.models` and :mod:`soabench.gmphd.reduction` is about 60 small numpy calls per step, each
costing microseconds of fixed overhead. Here the stages are compiled functions (:func:`predict_append`,
:func:`update` or :func:`support` + :func:`posterior` when a birth model adds measurement-driven newborn terms,
:func:`reduce`), and a filter step runs them in one call, :func:`step`, which times each stage inside with the
clock of ``time.perf_counter`` (:mod:`soabench.gmphd.clock`) so that ``StepResult`` still reports the three stage
times. Only what needs Python splits a step: the line-of-sight gate (shapely) of the occlusion-aware mode, between
the prediction and :func:`update_reduce`, and the newborn terms' ``beta(A, kappa)``, between :func:`support` and
:func:`posterior_reduce`. Work that would be fixed Python cost around the stages is done inside: the birth
components' input check (:func:`births_ok`, §2.12) and the posterior's origin counts (:func:`origin_counts`, §5.7);
the settings of a call travel as one float array (``PRED_*``, ``RED_*`` name its entries) that the filter packs
once instead of converting them on every step.

Each formula is the one of the array path, evaluated in the same order where that order is ours (elementwise Beta
algebra, log-sum-exp, the Kalman kernels of :mod:`soabench.gmphd.kernels`, which both paths share); matrix products
and sums that numpy hands to BLAS or pairwise summation can differ in the last bits, so the two paths agree to
1e-12 (``tests/equivalence/test_fused_cycle.py`` runs both on recorded scans), not bit for bit. Arithmetic is IEEE (no
``fastmath``), so the fused path itself is bit-reproducible. The array path stays callable as the reference:
``GMPHDFilter(..., fused=False)``. The UKF form takes it for a step in which a covariance is not positive
definite (its jitter retry perturbs every component of the batch, a rule kept in one place).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from soabench.gmphd.clock import monotonic
from soabench.gmphd.kernels import (
    _cholesky4,
    copy_row,
    copy_state,
    ekf_terms,
    extract_labels,
    inv2_sym,
    merge_groups,
    merge_moments,
    posterior_pairs,
    set_row,
    wrap,
)

_TINY = 1e-300  #: as :data:`soabench.gmphd.probabilities._TINY`
_LOG2 = math.log(2.0)
#: relative slack of the range-only gate test in :func:`support` (d2 and Sinv round to ~1e-12 relative at
#: worst: R keeps S well conditioned)
_RANGE_SLACK = 1.0 + 1e-4
_RADIX_MIN = 1500  #: from this many weights on, the radix sort is faster than numba's mergesort


@njit(cache=True)
def _order_heaviest_first(w):
    """``np.argsort(-w, kind="mergesort")`` for finite weights: the indices by decreasing w, ties in index order.

    A stable sort has one result, so an LSD radix sort (8 passes of 8 bits over keys that order as -w does,
    -0.0 taken as 0.0) gives the same permutation in O(J) instead of O(J log J). Non-finite weights (never in a
    posterior that passed the filter's checks) and small mixtures (below ``_RADIX_MIN``, where the comparison sort is
    faster) take numpy's sort.
    """
    J = w.shape[0]
    if J < _RADIX_MIN:
        return np.argsort(-w, kind="mergesort")
    for j in range(J):
        if not math.isfinite(w[j]):
            return np.argsort(-w, kind="mergesort")
    neg = np.empty(J)
    for j in range(J):
        neg[j] = -w[j] if w[j] != 0.0 else 0.0  # -0.0 and 0.0 compare equal: one key
    keys = neg.view(np.uint64)
    sign = np.uint64(1) << np.uint64(63)
    for j in range(J):
        b = keys[j]
        keys[j] = ~b if b & sign else b | sign  # unsigned order of the keys = order of the floats
    idx = np.arange(J)
    tmp = np.empty(J, dtype=np.int64)
    tmpk = np.empty(J, dtype=np.uint64)
    count = np.empty(257, dtype=np.int64)
    for shift in range(0, 64, 8):
        sh = np.uint64(shift)
        count[:] = 0
        for j in range(J):
            count[((keys[j] >> sh) & np.uint64(255)) + 1] += 1
        if count.max() == J:  # every key has the same byte here: the pass would not move anything
            continue
        for d in range(256):
            count[d + 1] += count[d]
        for j in range(J):
            d = (keys[j] >> sh) & np.uint64(255)
            tmp[count[d]] = idx[j]
            tmpk[count[d]] = keys[j]
            count[d] += 1
        idx, tmp = tmp, idx
        keys, tmpk = tmpk, keys
    return idx


@njit(cache=True)
def _beta_inflate(s, t, f, theta_min):
    """§4.2, as :func:`soabench.gmphd.probabilities.beta_inflate` for one component."""
    mu = s / (s + t)
    v = mu * (1.0 - mu)
    n = s + t
    var = s * t / (n * n * (n + 1.0))
    theta = v / max(min(f * var, v), _TINY) - 1.0
    theta = max(theta, theta_min)
    return theta * mu, theta * (1.0 - mu)


@njit(cache=True)
def _logaddexp(x, y):
    """numpy's ``logaddexp`` for two scalars (same branches)."""
    if x == y:
        return x + _LOG2
    d = x - y
    if d > 0.0:
        return x + math.log1p(math.exp(-d))
    if d <= 0.0:
        return y + math.log1p(math.exp(d))
    return d  # NaN


#: indices of :func:`predict_append`'s ``pars``: p_S, then the Beta parameters beta_factor, theta_min, p_S_max
#: (§4.2, §4.3), then the FOV r_min, r_max, Theta/2 + 1e-12 and 1.0 for a limited FOV (0.0 for 360 deg)
PRED_P_S, PRED_BETA_FACTOR, PRED_THETA_MIN, PRED_P_S_MAX, PRED_R_MIN, PRED_R_MAX, PRED_HALF_FOV, PRED_LIMITED = range(8)


@njit(cache=True)
def _new_mixture(n, dyn):
    """(w, m, P, origin, n_det, age, beta, label) of n components, uninitialised, as the compiled calls pass a
    mixture (beta is (n, 4) for dynamic p_D, else (0, 0); label int64, §2.13)."""
    return (
        np.empty(n),
        np.empty((n, 4)),
        np.empty((n, 4, 4)),
        np.empty(n, dtype=np.int8),
        np.empty(n, dtype=np.int32),
        np.empty(n, dtype=np.int32),
        np.empty((n, 4) if dyn else (0, 0)),
        np.empty(n, dtype=np.int64),
    )


@njit(cache=True)
def births_ok(bw, bm, bP):
    """Every birth weight, mean and covariance finite and every weight >= 0: the fused cycle's part of
    :func:`soabench.gmphd.inputs.births_finite` (the newborn terms are checked before the cycle)."""
    for k in range(bw.shape[0]):
        if not (math.isfinite(bw[k]) and bw[k] >= 0.0):
            return False
        for a in range(4):
            if not math.isfinite(bm[k, a]):
                return False
            for b in range(4):
                if not math.isfinite(bP[k, a, b]):
                    return False
    return True


@njit(cache=True)
def predict_append(w, m, P, origin, n_det, age, beta, label, F, Q, pars, bw, bm, bP, bsrc, beta0, ego, label0):
    """Steps 1-2 of §2.11 and the FOV gate: predict (§2.5; Beta prediction §4.2, §4.3 when ``beta`` has rows),
    append the birth components (n_det = age = 0, Beta prior ``beta0``, fresh labels label0, label0 + 1, ... in
    their order, §2.13), and g_j = 1[m_j in FOV_k] (§4.1).

    ``pars``: the scalars named by the ``PRED_*`` indices (p_S, Beta parameters, FOV), one array so that a call
    unboxes one argument for them. Returns (w, m, P, origin, n_det, age, beta, label, g) of the J + J_b predicted
    components and :func:`births_ok` of the birth components; when that is False (a non-finite or negative birth
    input, which the caller must raise on or drop, docs/method.md §2.12) nothing else is computed and the arrays
    are empty. Throughout this module a static-mode mixture carries a (0, 0) ``beta`` and a dynamic one a (J, 4)
    ``beta``.
    """
    dyn = beta.shape[1] == 4
    if not births_ok(bw, bm, bP):
        return (*_new_mixture(np.int64(0), dyn), np.empty(0), False)
    p_S = pars[PRED_P_S]
    f_beta, theta_min, p_S_max = pars[PRED_BETA_FACTOR], pars[PRED_THETA_MIN], pars[PRED_P_S_MAX]
    r_min, r_max, half_fov = pars[PRED_R_MIN], pars[PRED_R_MAX], pars[PRED_HALF_FOV]
    limited = pars[PRED_LIMITED] > 0.0
    J0 = w.shape[0]
    Jb = bw.shape[0]
    J = J0 + Jb
    w2, m2, P2, origin2, n_det2, age2, beta2, label2 = _new_mixture(J, dyn)
    T = np.empty((4, 4))
    for j in range(J0):
        factor = p_S
        if dyn:
            beta2[j, 0], beta2[j, 1] = _beta_inflate(beta[j, 0], beta[j, 1], f_beta, theta_min)
            sS, tS = beta[j, 2], beta[j, 3]
            factor = sS / (sS + tS)
            s, t = _beta_inflate(sS + 1.0, tS, f_beta, theta_min)
            n = s + t
            if s > p_S_max * n:
                s, t = p_S_max * n, (1.0 - p_S_max) * n
            beta2[j, 2], beta2[j, 3] = s, t
        w2[j] = w[j] * factor
        for a in range(4):
            acc = 0.0
            for b in range(4):
                acc += m[j, b] * F[a, b]
            m2[j, a] = acc
        for a in range(4):  # T = F P
            for b in range(4):
                acc = 0.0
                for c in range(4):
                    acc += F[a, c] * P[j, c, b]
                T[a, b] = acc
        for a in range(4):  # F P F^T + Q
            for b in range(4):
                acc = 0.0
                for c in range(4):
                    acc += T[a, c] * F[b, c]
                P2[j, a, b] = acc + Q[a, b]
        for a in range(4):
            for b in range(a, 4):
                s = 0.5 * (P2[j, a, b] + P2[j, b, a])
                P2[j, a, b] = s
                P2[j, b, a] = s
        origin2[j] = origin[j]
        n_det2[j] = n_det[j]
        age2[j] = age[j] + 1
        label2[j] = label[j]
    for k in range(Jb):
        j = J0 + k
        w2[j] = bw[k]
        copy_state(m2, P2, j, bm, bP, k)
        origin2[j] = bsrc[k]
        n_det2[j] = 0
        age2[j] = 0
        label2[j] = label0 + k
        if dyn:
            set_row(beta2, j, beta0)
    g = fov_gate(m2, ego, r_min, r_max, half_fov, limited)
    return w2, m2, P2, origin2, n_det2, age2, beta2, label2, g, True


@njit(cache=True, inline="always")
def fov_gate(m, ego, r_min, r_max, half_fov, limited):
    """g_j = 1[m_j in FOV_k] (§4.1) for the means m (J, 4) seen from ``ego``: r_min <= r <= r_max and, with a
    ``limited`` field of view, |bearing| <= ``half_fov`` (Θ/2 + 1e-12), as :func:`soabench.geometry.fov_mask`."""
    J = m.shape[0]
    g = np.empty(J)
    for j in range(J):
        dx = m[j, 0] - ego[0]
        dy = m[j, 1] - ego[1]
        r = math.hypot(dx, dy)
        ok = r >= r_min and r <= r_max
        if ok and limited:
            ok = abs(wrap(math.atan2(dy, dx) - ego[2])) <= half_fov
        g[j] = 1.0 if ok else 0.0
    return g


@njit(cache=True)
def _sum8(x):
    """numpy's pairwise sum of 8 values (its unrolled block), so that means match ``np.mean(axis=-1)``."""
    return ((x[0] + x[1]) + (x[2] + x[3])) + ((x[4] + x[5]) + (x[6] + x[7]))


@njit(cache=True)
def ukf_terms(m, P, ego, R, r_min):
    """Equal-weight cubature terms (§2.7), as :func:`soabench.gmphd.models.ukf_terms`: 8 points m +- 2 L columns
    (L = chol(sym P)), weights 1/8, circular bearing mean, wrapped differences; a component with a point inside
    r_min is undetectable. Returns the tuple of :func:`soabench.gmphd.kernels.ekf_terms` (with an empty H) and
    ``ok``: False if some P is not positive definite, where the array path's jitter retry (which perturbs every
    component) must decide instead.
    """
    J = m.shape[0]
    eta = np.empty((J, 2))
    S = np.empty((J, 2, 2))
    Sinv = np.empty((J, 2, 2))
    logdet = np.empty(J)
    C = np.zeros((J, 4, 2))
    H = np.zeros((0, 2, 4))
    valid = np.empty(J, dtype=np.bool_)
    L = np.zeros((J, 4, 4))
    Ps = np.empty((4, 4))
    for j in range(J):
        for a in range(4):
            for b in range(4):
                Ps[a, b] = 0.5 * (P[j, a, b] + P[j, b, a])
        if not _cholesky4(Ps, L[j]):
            return eta, S, Sinv, logdet, C, H, valid, False
    X = np.empty((8, 4))
    rr = np.empty(8)
    bb = np.empty(8)
    sn = np.empty(8)
    cs = np.empty(8)
    D = np.empty((8, 2))
    w0 = 1.0 / 8.0
    r_lo = max(r_min, 1e-9)
    for j in range(J):
        for i in range(4):
            for a in range(4):
                X[i, a] = 2.0 * L[j, a, i]
                X[i + 4, a] = -X[i, a]
        rmin = np.inf
        for i in range(8):
            dx = m[j, 0] + X[i, 0] - ego[0]
            dy = m[j, 1] + X[i, 1] - ego[1]
            rr[i] = math.hypot(dx, dy)
            bb[i] = math.atan2(dy, dx) - ego[2]
            sn[i] = math.sin(bb[i])
            cs[i] = math.cos(bb[i])
            rmin = min(rmin, rr[i])
        zr = _sum8(rr) / 8.0
        zb = math.atan2(_sum8(sn) / 8.0, _sum8(cs) / 8.0)
        for i in range(8):
            D[i, 0] = rr[i] - zr
            D[i, 1] = wrap(bb[i] - zb)
        for a in range(2):
            for b in range(2):
                acc = 0.0
                for i in range(8):
                    acc += (w0 * D[i, a]) * D[i, b]
                S[j, a, b] = acc + R[a, b]
        s01 = 0.5 * (S[j, 0, 1] + S[j, 1, 0])
        S[j, 0, 1] = S[j, 1, 0] = s01
        for a in range(4):
            for b in range(2):
                acc = 0.0
                for i in range(8):
                    acc += (w0 * X[i, a]) * D[i, b]
                C[j, a, b] = acc
        good = inv2_sym(S[j, 0, 0], 0.5 * (S[j, 0, 1] + S[j, 1, 0]), S[j, 1, 1], Sinv[j], logdet, j)
        eta[j, 0], eta[j, 1] = zr, wrap(zb)
        valid[j] = rmin >= r_lo and good
    return eta, S, Sinv, logdet, C, H, valid, True


@njit(cache=True)
def support(w, m, P, beta, g, p_D0, Z, ego, R, r_min, gate_thr, kappa, ukf=False):
    """First half of the update (§2.6, §2.8, §3.4): p_D,j (static p_D g, dynamic g sD/(sD+tD)), the EKF terms of
    the detectable components, log p_D w q (J_d, M), and per measurement log(kappa_l + A_l) and A_l.

    Returns (p_D, g, det_idx, C, Sinv, S, H, nu_r, nu_b, log_t, log_L, A, ok). Components with r < r_min or
    det S <= 0 get p_D = g = 0 (§2.12); without measurements or detectable components log_t has no rows. ``ukf``
    selects the cubature terms (:func:`ukf_terms`); ``ok`` is False when one of their covariances is not positive
    definite: the caller then runs the step on the array path.
    """
    J = w.shape[0]
    M = Z.shape[0]
    dyn = beta.shape[1] == 4
    p_D = np.empty(J)
    g = g.copy()
    n_d = 0
    for j in range(J):
        p_D[j] = g[j] * (beta[j, 0] / (beta[j, 0] + beta[j, 1]) if dyn else p_D0)
        if p_D[j] > 0.0:
            n_d += 1
    det_idx = np.empty(n_d, dtype=np.int64)
    k = 0
    for j in range(J):
        if p_D[j] > 0.0:
            det_idx[k] = j
            k += 1
    m_d = np.empty((n_d, 4))
    P_d = np.empty((n_d, 4, 4))
    for k in range(n_d):
        copy_state(m_d, P_d, k, m, P, det_idx[k])
    if ukf:
        eta, S, Sinv, logdet, C, H, valid, ok = ukf_terms(m_d, P_d, ego, R, r_min)
    else:
        eta, S, Sinv, logdet, C, H, valid = ekf_terms(m_d, P_d, ego, R, r_min)
        ok = True
    for k in range(n_d):
        if not valid[k]:
            p_D[det_idx[k]] = 0.0
            g[det_idx[k]] = 0.0
    log_L = np.log(kappa)
    A = np.zeros(M)
    n_rows = n_d if M > 0 else 0
    log_t = np.empty((n_rows, M))
    nu_r = np.empty((n_rows, M))
    nu_b = np.empty((n_rows, M))
    mx = np.full(M, -np.inf)  # per measurement, the largest term (max over rows in row order)
    if n_rows > 0:
        for k in range(n_d):  # log_likelihood of kernels, fused with log p_D w
            j = det_idx[k]
            a, b, d = Sinv[k, 0, 0], Sinv[k, 0, 1], Sinv[k, 1, 1]
            c = -math.log(2.0 * math.pi) - 0.5 * logdet[k]
            lpw = np.log(p_D[j] * w[j])
            # a pair beyond the gate in range alone is -inf without its bearing (no wrap, no quadratic form):
            # min over t of d2(r, t) = r^2 / S_rr, so r^2 > gate_thr S_rr (with slack for rounding) means d2 > gate_thr
            r2_out = gate_thr * S[k, 0, 0] * _RANGE_SLACK if (S[k, 0, 0] > 0.0 and lpw > -np.inf) else np.inf
            for ll in range(M):
                r = Z[ll, 0] - eta[k, 0]
                if r * r > r2_out:
                    log_t[k, ll] = -np.inf  # nu_r, nu_b of a -inf pair are never read
                    continue
                t = wrap(Z[ll, 1] - eta[k, 1])
                nu_r[k, ll] = r
                nu_b[k, ll] = t
                d2 = a * r * r + 2.0 * b * r * t + d * t * t
                v = lpw + (-0.5 * d2 + c if d2 <= gate_thr else -np.inf)
                log_t[k, ll] = v
                mx[ll] = max(mx[ll], v)
        # logsumexp over rows per measurement, then log L = logaddexp(log kappa, log A); row-major passes, each
        # column still reduced in row order k = 0, 1, ... (max, then the sum of exp), so the sums are those of a
        # column loop; a -inf term (max(x, -inf) = x, and exp(-inf) = 0 exactly) is skipped
        for ll in range(M):
            if not math.isfinite(mx[ll]):
                mx[ll] = 0.0
        acc = np.zeros(M)
        for k in range(n_d):
            for ll in range(M):
                v = log_t[k, ll]
                if v > -np.inf:
                    acc[ll] += math.exp(v - mx[ll])
        for ll in range(M):
            log_A = (np.log(acc[ll]) if acc[ll] > 0.0 else -np.inf) + mx[ll]
            log_L[ll] = _logaddexp(log_L[ll], log_A)
            A[ll] = math.exp(log_A)
    return p_D, g, det_idx, C, Sinv, S, H, nu_r, nu_b, log_t, log_L, A, ok


@njit(cache=True)
def posterior(w, m, P, origin, n_det, age, beta, label, sup, R, beta_nb, nb_m, nb_P, nb_beta, nb_origin, nb_label0):
    """Second half of the update (§2.6, §3.4, §4.2): missed-detection terms (all J), detection pairs (j, l) with
    w p_D q / L > 0 in (j, l) order, newborn terms with beta_l / L_l > 0 (``beta_nb`` has M rows, else none).
    Labels (§2.13): a missed-detection term and every detection pair keep the label of their prior component; the
    newborn term of measurement l gets the fresh label nb_label0 + l.

    Returns (w, m, P, origin, n_det, age, beta, label) of the posterior and (n_pairs, n_newborn).
    """
    p_D, g, det_idx, C, Sinv, S, H, nu_r, nu_b, log_t, log_L, A, _ = sup
    J = w.shape[0]
    M = log_L.shape[0]
    dyn = beta.shape[1] == 4
    has_nb = beta_nb.shape[0] == M and M > 0
    log_L = log_L.copy()
    log_nb = np.empty(beta_nb.shape[0])
    if has_nb:
        for ll in range(M):
            log_nb[ll] = np.log(beta_nb[ll])
            log_L[ll] = _logaddexp(log_L[ll], log_nb[ll])
    for ll in range(M):
        if not math.isfinite(log_L[ll]):
            log_L[ll] = 0.0  # L_l = 0: every term of L_l is 0, so w = 0
    n_rows = log_t.shape[0]
    w_det = np.empty((n_rows, M))
    n_pairs = 0
    for k in range(n_rows):
        for ll in range(M):
            v = log_t[k, ll]
            if v > -np.inf:  # exp(-inf - log L) = 0 exactly: a gated pair is skipped
                w_det[k, ll] = math.exp(v - log_L[ll])
                if w_det[k, ll] > 0.0:
                    n_pairs += 1
            else:
                w_det[k, ll] = 0.0
    jj = np.empty(n_pairs, dtype=np.int64)
    lj = np.empty(n_pairs, dtype=np.int64)
    p = 0
    for k in range(n_rows):
        for ll in range(M):
            if w_det[k, ll] > 0.0:
                jj[p] = k
                lj[p] = ll
                p += 1
    n_det_rows = det_idx.shape[0]
    m_d = np.empty((n_det_rows, 4))
    P_d = np.empty((n_det_rows, 4, 4))
    for k in range(n_det_rows):
        copy_state(m_d, P_d, k, m, P, det_idx[k])
    m_new, P_new = posterior_pairs(m_d, P_d, C, Sinv, S, H, R, jj, lj, nu_r, nu_b)
    w_nb = np.empty(M if has_nb else 0)
    n_nb = 0
    for ll in range(w_nb.shape[0]):
        w_nb[ll] = math.exp(log_nb[ll] - log_L[ll])
        if w_nb[ll] > 0.0:
            n_nb += 1
    n = J + n_pairs + n_nb
    wo, mo, Po, oo, no, ao, bo, lo = _new_mixture(n, dyn)
    for j in range(J):
        wo[j] = w[j] * (1.0 - p_D[j])
        copy_state(mo, Po, j, m, P, j)
        oo[j] = origin[j]
        lo[j] = label[j]
        no[j] = n_det[j]
        ao[j] = age[j]
        if dyn:
            copy_row(bo, j, beta, j)
            bo[j, 1] += g[j]
    for p in range(n_pairs):
        q = J + p
        src = det_idx[jj[p]]
        wo[q] = w_det[jj[p], lj[p]]
        copy_state(mo, Po, q, m_new, P_new, p)
        oo[q] = origin[src]
        lo[q] = label[src]
        no[q] = n_det[src] + 1
        ao[q] = age[src]
        if dyn:
            copy_row(bo, q, beta, src)
            bo[q, 0] += 1.0
    q = J + n_pairs
    for ll in range(w_nb.shape[0]):
        if w_nb[ll] > 0.0:
            wo[q] = w_nb[ll]
            copy_state(mo, Po, q, nb_m, nb_P, ll)
            oo[q] = nb_origin
            lo[q] = nb_label0 + ll
            no[q] = 1
            ao[q] = 0
            if dyn:
                set_row(bo, q, nb_beta)
            q += 1
    return wo, mo, Po, oo, no, ao, bo, lo, n_pairs, n_nb


@njit(cache=True, inline="always")
def update(w, m, P, origin, n_det, age, beta, label, g, p_D0, Z, ego, R, r_min, gate_thr, kappa, ukf=False):
    """:func:`support` then :func:`posterior` without newborn terms, in one call; returns (posterior, A, ok)."""
    sup = support(w, m, P, beta, g, p_D0, Z, ego, R, r_min, gate_thr, kappa, ukf)
    no_nb = np.empty(0)
    # writable empty newborn arrays and nb_origin as an int64 variable, not the literal 0: the argument types the
    # filter's newborn step passes to posterior_reduce, so posterior is compiled once (a literal or a read-only array
    # would make numba compile it a second time)
    nb_origin = np.int64(0)
    out = posterior(w, m, P, origin, n_det, age, beta, label, sup, R, no_nb, np.empty((0, 4)), np.empty((0, 4, 4)),
                    no_nb, nb_origin, nb_origin)  # fmt: skip
    return out, sup[11], sup[12]


@njit(cache=True)
def _take(w, m, P, origin, n_det, age, beta, label, keep):
    """The components where ``keep`` (bool, J) is True, in order."""
    n = 0
    for j in range(keep.shape[0]):
        if keep[j]:
            n += 1
    idx = np.empty(n, dtype=np.int64)
    k = 0
    for j in range(keep.shape[0]):
        if keep[j]:
            idx[k] = j
            k += 1
    return _select(w, m, P, origin, n_det, age, beta, label, idx)


@njit(cache=True)
def _select(w, m, P, origin, n_det, age, beta, label, idx):
    n = idx.shape[0]
    dyn = beta.shape[1] == 4
    wo, mo, Po, oo, no, ao, bo, lo = _new_mixture(n, dyn)
    for k in range(n):
        i = idx[k]
        wo[k], oo[k], no[k], ao[k], lo[k] = w[i], origin[i], n_det[i], age[i], label[i]
        copy_state(mo, Po, k, m, P, i)
        if dyn:
            copy_row(bo, k, beta, i)
    return wo, mo, Po, oo, no, ao, bo, lo


#: indices of :func:`reduce`'s ``pars``: max_age (< 0: off), T, U, J_max, theta_min, the extraction threshold,
#: 1.0 for Vo-Ma extraction (0.0: none here), the number of birth source codes (:data:`soabench.types.SOURCE_NAMES`)
RED_MAX_AGE, RED_T, RED_U, RED_J_MAX, RED_THETA_MIN, RED_EXTRACT_THR, RED_VO_MA, RED_N_SOURCES = range(8)


@njit(cache=True)
def origin_counts(origin, age, n_sources):
    """:func:`soabench.origins.origin_counts` (docs/method.md §5.7) in the compiled cycle: component j counts in bin
    origin_j if age_j = 0, n_sources + origin_j if older, and in the last bin (2 n_sources) if origin_j is not a
    source code in [0, n_sources)."""
    counts = np.zeros(2 * n_sources + 1, dtype=np.int64)
    for j in range(origin.shape[0]):
        o = np.int64(origin[j])
        if 0 <= o < n_sources:
            counts[o + n_sources if age[j] > 0 else o] += 1
        else:
            counts[2 * n_sources] += 1
    return counts


@njit(cache=True)
def reduce(w, m, P, origin, n_det, age, beta, label, pars, next_label):
    """§2.9-2.10 and §4.5: drop undetected births older than max_age (< 0: off), prune w > T, Vo-Ma merge
    (Table II, moment matching, Beta moment matching of multi-member groups), keep the J_max heaviest, extract
    (Vo-Ma: w > thr, floor(w + 0.5) copies; otherwise no extraction here), count the posterior by origin (§5.7).
    Labels (§2.13): a merged component takes the label of its group's j*; the estimates are labelled by
    :func:`extract_labels` with fresh labels from ``next_label`` on.

    ``pars``: the scalars named by the ``RED_*`` indices, one array so that a call unboxes one argument for them.
    Returns ((w, m, P, origin, n_det, age, beta, label), X, X_w, X_label, origin counts, (sum_w, n_pruned, n_merged,
    cap_hit, next unused label)).
    """
    max_age, T, U = int(pars[RED_MAX_AGE]), pars[RED_T], pars[RED_U]
    J_max, theta_min, extract_thr = int(pars[RED_J_MAX]), pars[RED_THETA_MIN], pars[RED_EXTRACT_THR]
    vo_ma, n_sources = pars[RED_VO_MA] > 0.0, int(pars[RED_N_SOURCES])
    J = w.shape[0]
    sum_w = 0.0
    for j in range(J):
        sum_w += w[j]
    keep = np.empty(J, dtype=np.bool_)
    for j in range(J):
        keep[j] = w[j] > T and not (max_age >= 0 and n_det[j] == 0 and age[j] > max_age)
    w, m, P, origin, n_det, age, beta, label = _take(w, m, P, origin, n_det, age, beta, label, keep)
    n_pruned = w.shape[0]
    dyn = beta.shape[1] == 4
    if n_pruned > 0:
        order = _order_heaviest_first(w)
        group, centres = merge_groups(m, P, order, U)  # q <= U (1 + 1e-9): a pair at exactly U merges (§2.9)
        G = centres.shape[0]
        if G == n_pruned:
            w, m, P, origin, n_det, age, beta, label = _select(w, m, P, origin, n_det, age, beta, label, centres)
        else:
            W, mt, Pt, nd, ag, counts = merge_moments(group, centres, w, m, P, n_det, age)
            bo = np.empty((G, 4) if dyn else (0, 0))
            if dyn:
                for g in range(G):
                    copy_row(bo, g, beta, centres[g])
                wmu = np.zeros((G, 2))
                wsec = np.zeros((G, 2))
                for i in range(n_pruned):
                    g = group[i]
                    if counts[g] > 1:
                        for h in range(2):
                            s, t = beta[i, 2 * h], beta[i, 2 * h + 1]
                            mu = s / (s + t)
                            n = s + t
                            sec = s * t / (n * n * (n + 1.0)) + mu * mu
                            wmu[g, h] += w[i] * mu
                            wsec[g, h] += w[i] * sec
                for g in range(G):
                    if counts[g] > 1:
                        for h in range(2):
                            mu = wmu[g, h] / W[g]
                            v = max(wsec[g, h] / W[g] - mu * mu, _TINY)
                            theta = max(mu * (1.0 - mu) / v - 1.0, theta_min)
                            bo[g, 2 * h], bo[g, 2 * h + 1] = theta * mu, theta * (1.0 - mu)
            oo = np.empty(G, dtype=np.int8)
            lo = np.empty(G, dtype=np.int64)
            for g in range(G):
                oo[g] = origin[centres[g]]
                lo[g] = label[centres[g]]
            w, m, P, origin, n_det, age, beta, label = W, mt, Pt, oo, nd, ag, bo, lo
    n_merged = w.shape[0]
    cap_hit = n_merged > J_max
    if cap_hit:
        top = _order_heaviest_first(w)[:J_max]
        keep = np.zeros(n_merged, dtype=np.bool_)
        keep[top] = True
        w, m, P, origin, n_det, age, beta, label = _take(w, m, P, origin, n_det, age, beta, label, keep)
    n_e = 0
    if vo_ma:
        for j in range(w.shape[0]):
            if w[j] > extract_thr:
                n_e += 1
    idx = np.empty(n_e, dtype=np.int64)
    reps = np.empty(n_e, dtype=np.int64)
    n_x = 0
    k = 0
    if vo_ma:
        for j in range(w.shape[0]):
            if w[j] > extract_thr:
                idx[k] = j
                reps[k] = int(math.floor(w[j] + 0.5))
                n_x += reps[k]
                k += 1
    X = np.empty((n_x, 4))
    X_w = np.empty(n_x)
    k = 0
    for e in range(n_e):
        for _ in range(reps[e]):
            copy_row(X, k, m, idx[e])
            X_w[k] = w[idx[e]]
            k += 1
    X_label, label, next_label = extract_labels(w, label, idx, reps, next_label)
    counts = origin_counts(origin, age, n_sources)
    return (
        (w, m, P, origin, n_det, age, beta, label),
        X,
        X_w,
        X_label,
        counts,
        (sum_w, n_pruned, n_merged, cap_hit, next_label),
    )


# -- one call per scan -----------------------------------------------------------------------------------------------
# Each stage above is its own compiled call so that the array path's reference tests can reach it; a filter step
# composes them here instead, so that a scan costs one call (two with measurement-driven newborn terms, whose
# beta(A, kappa) is caller code in Python). The stage times are read inside with the clock of time.perf_counter
# (soabench.gmphd.clock). The arithmetic is that of the separate calls, so the results are the same bit for bit.
# The thin compositions update and update_reduce are inlined into their callers by numba (inline="always"): numba
# compiles every compiled function into a library of its own with all its callees linked in and optimised and emitted
# again, so each wrapper of its own would cost one more optimisation of the whole update and reduction under it.
# Called from Python (the line-of-sight step calls update_reduce) they are still compiled on their own.

#: ``status`` of :func:`step` and :func:`update_reduce`: the cycle ran; a birth component is not finite or has a
#: negative weight (nothing computed); the UKF met a covariance that is not positive definite (nothing kept)
STEP_OK, STEP_BAD_BIRTHS, STEP_NOT_PD = 0, 1, 2


@njit(cache=True)
def _no_reduction(dyn):
    """What :func:`reduce` returns for an empty posterior (the value :func:`step` returns when it stops early)."""
    empty_label = np.zeros(0, dtype=np.int64)
    empty = _new_mixture(np.int64(0), dyn)
    return empty, np.empty((0, 4)), np.empty(0), empty_label, empty_label, (0.0, 0, 0, False, 0)


@njit(cache=True)
def step(w, m, P, origin, n_det, age, beta, label, F, Q, pred_pars, bw, bm, bP, bsrc, beta0, ego, p_D0, Z, R, r_min,
         gate_thr, kappa, ukf, red_pars, next_label):  # fmt: skip
    """One filter cycle without newborn terms and without the line-of-sight gate: :func:`predict_append`, then
    :func:`update_reduce` (:func:`update`, :func:`reduce`), in one call. The birth components take the labels
    next_label, next_label + 1, ... (§2.13); the reduction's fresh labels follow them.

    Returns (status, n_predicted, n_updated, n_pairs, A, reduction, times): ``status`` one of ``STEP_*``;
    ``reduction`` is :func:`reduce`'s value (empty unless ``status`` is ``STEP_OK``); ``times`` the seconds of
    predict, update and reduce.
    """
    times = np.zeros(3)
    t0 = monotonic()
    pred = predict_append(w, m, P, origin, n_det, age, beta, label, F, Q, pred_pars, bw, bm, bP, bsrc, beta0, ego,
                          next_label)  # fmt: skip
    times[0] = monotonic() - t0
    if not pred[9]:
        return STEP_BAD_BIRTHS, 0, 0, 0, np.empty(0), _no_reduction(beta.shape[1] == 4), times
    w1, m1, P1, origin1, n_det1, age1, beta1, label1, g1 = pred[:9]  # named: numba inlines no call with *args
    status, n_updated, n_pairs, A, red, ur = update_reduce(w1, m1, P1, origin1, n_det1, age1, beta1, label1, g1, p_D0,
                                                           Z, ego, R, r_min, gate_thr, kappa, ukf, red_pars,
                                                           next_label + bw.shape[0])  # fmt: skip
    times[1], times[2] = ur[0], ur[1]
    return status, pred[0].shape[0] if status == STEP_OK else 0, n_updated, n_pairs, A, red, times


@njit(cache=True, inline="always")
def update_reduce(w, m, P, origin, n_det, age, beta, label, g, p_D0, Z, ego, R, r_min, gate_thr, kappa, ukf, red_pars,
                  next_label):  # fmt: skip
    """:func:`update` and :func:`reduce` in one call, for a predicted mixture whose gate ``g`` the caller has
    refined (the line-of-sight gate, §4.4). Returns (status, n_updated, n_pairs, A, reduction, times) as
    :func:`step` (``times``: update, reduce)."""
    times = np.zeros(2)
    t1 = monotonic()
    post, A, ok = update(w, m, P, origin, n_det, age, beta, label, g, p_D0, Z, ego, R, r_min, gate_thr, kappa, ukf)
    t2 = monotonic()
    times[0] = t2 - t1
    if not ok:
        return STEP_NOT_PD, 0, 0, A, _no_reduction(beta.shape[1] == 4), times
    red = reduce(*post[:8], red_pars, next_label)
    times[1] = monotonic() - t2
    return STEP_OK, post[0].shape[0], post[8], A, red, times


@njit(cache=True)
def posterior_reduce(w, m, P, origin, n_det, age, beta, label, sup, R, beta_nb, nb_m, nb_P, nb_beta, nb_origin,
                     red_pars, nb_label0):  # fmt: skip
    """:func:`posterior` (with the newborn terms' ``beta_nb``, labelled nb_label0 + l) and :func:`reduce` (fresh
    labels after the M newborn labels) in one call. Returns (n_updated, n_pairs, n_newborn, reduction, times) with
    ``times`` the seconds of posterior and reduce."""
    times = np.zeros(2)
    t1 = monotonic()
    post = posterior(w, m, P, origin, n_det, age, beta, label, sup, R, beta_nb, nb_m, nb_P, nb_beta, nb_origin,
                     nb_label0)  # fmt: skip
    t2 = monotonic()
    times[0] = t2 - t1
    red = reduce(*post[:8], red_pars, nb_label0 + beta_nb.shape[0])
    times[1] = monotonic() - t2
    return post[0].shape[0], post[8], post[9], red, times
