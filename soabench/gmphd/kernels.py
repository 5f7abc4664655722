"""Compiled inner loops of the GM-PHD update and of Vo-Ma merging (docs/method.md §2.6, §2.8, §2.9).

Each kernel is the formula written once per component or per (j, l) pair, compiled by numba. Why compiled: a
filter step is a few hundred small array operations, and at the mixture sizes of a trial (tens of components) numpy's
fixed cost per call, not arithmetic, sets the step time. Compiled, the step costs a small fraction of that
(``benchmarks/README.md`` has both; ``benchmarks/bench_filter_vs_stonesoup.py`` measures it against Stone Soup).

Arithmetic is IEEE (no ``fastmath``: no reassociation, no fused multiply-add contraction), so a result does not
depend on the vector width of the CPU, and the same seed gives bit-identical results serial or parallel.
``cache=True`` stores the machine code in a per-user cache folder (:mod:`soabench.cache`: ``NUMBA_CACHE_DIR``, else
``~/.cache/soabench/numba``), never inside the installed package, so only the first import on a machine compiles.
"""

from __future__ import annotations

import math

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()  # before numba is imported: compiled kernels go to the per-user cache, not site-packages

from numba import njit  # noqa: E402

_TWO_PI = 2.0 * math.pi
_LOG_2PI = math.log(_TWO_PI)


@njit(cache=True)
def wrap(a: float) -> float:
    """Map an angle to (-pi, pi] (§2.1), as :func:`soabench.geometry.wrap`."""
    out = (a + math.pi) % _TWO_PI - math.pi
    return math.pi if out == -math.pi else out


@njit(cache=True, inline="always")
def inv2_sym(a, b, d, Sinv, logdet, j):
    """Closed-form inverse of the symmetric 2x2 block [[a, b], [b, d]] into Sinv (2, 2) and log det into logdet[j]
    (§2.12 item 5). A block whose determinant is not positive and finite gets det = 1 (its row is marked invalid by
    the caller). Returns whether the determinant was positive and finite."""
    det = a * d - b * b
    good = det > 0.0 and math.isfinite(det)
    if not good:
        det = 1.0
    Sinv[0, 0], Sinv[1, 1] = d / det, a / det
    Sinv[0, 1] = Sinv[1, 0] = -b / det
    logdet[j] = math.log(det)
    return good


@njit(cache=True)
def ekf_terms(m, P, ego, R, r_min):
    """EKF linearisation at each predicted mean (§2.3, §2.6): eta = h(m), H = H(m), C = P H^T, S = H P H^T + R.

    Returns (eta (J, 2), S, Sinv (J, 2, 2), logdet (J,), C (J, 4, 2), H (J, 2, 4), valid (J,)). ``valid`` is False
    where r < r_min or r -> 0 (H is then taken at a dummy point so that it stays finite; the row is never used) or
    det S <= 0 (§2.12 item 5).
    """
    J = m.shape[0]
    eta = np.empty((J, 2))
    S = np.empty((J, 2, 2))
    Sinv = np.empty((J, 2, 2))
    logdet = np.empty(J)
    C = np.empty((J, 4, 2))
    H = np.zeros((J, 2, 4))
    valid = np.empty(J, dtype=np.bool_)
    for j in range(J):
        dx = m[j, 0] - ego[0]
        dy = m[j, 1] - ego[1]
        r = math.hypot(dx, dy)
        eta[j, 0] = r
        eta[j, 1] = wrap(math.atan2(dy, dx) - ego[2])
        ok = r >= r_min and r > 1e-9
        if not ok:
            dx, dy = 1.0, 0.0
        r2 = dx * dx + dy * dy
        rr = math.sqrt(r2)
        h00, h01, h10, h11 = dx / rr, dy / rr, -dy / r2, dx / r2
        H[j, 0, 0], H[j, 0, 1], H[j, 1, 0], H[j, 1, 1] = h00, h01, h10, h11
        for a in range(4):  # C = P H^T: H has zero velocity columns
            C[j, a, 0] = P[j, a, 0] * h00 + P[j, a, 1] * h01
            C[j, a, 1] = P[j, a, 0] * h10 + P[j, a, 1] * h11
        s00 = h00 * C[j, 0, 0] + h01 * C[j, 1, 0] + R[0, 0]
        s11 = h10 * C[j, 0, 1] + h11 * C[j, 1, 1] + R[1, 1]
        s01 = 0.5 * ((h00 * C[j, 0, 1] + h01 * C[j, 1, 1] + R[0, 1]) + (h10 * C[j, 0, 0] + h11 * C[j, 1, 0] + R[1, 0]))
        S[j, 0, 0], S[j, 0, 1], S[j, 1, 0], S[j, 1, 1] = s00, s01, s01, s11
        good = inv2_sym(s00, s01, s11, Sinv[j], logdet, j)
        valid[j] = ok and good
    return eta, S, Sinv, logdet, C, H, valid


@njit(cache=True)
def log_likelihood(eta, Sinv, logdet, Z, gate_thr):
    """log q_jl = -d2/2 - log 2 pi - log det S_j / 2 with nu_jl = z_l - eta_j (bearing wrapped), and -inf where
    d2 > gate_thr (§2.6, §2.8, T11). Returns (log q, nu_r, nu_b), each (J, M)."""
    J, M = eta.shape[0], Z.shape[0]
    logq = np.empty((J, M))
    nu_r = np.empty((J, M))
    nu_b = np.empty((J, M))
    for j in range(J):
        a, b, d = Sinv[j, 0, 0], Sinv[j, 0, 1], Sinv[j, 1, 1]
        c = -_LOG_2PI - 0.5 * logdet[j]
        for ll in range(M):
            r = Z[ll, 0] - eta[j, 0]
            t = wrap(Z[ll, 1] - eta[j, 1])
            nu_r[j, ll] = r
            nu_b[j, ll] = t
            d2 = a * r * r + 2.0 * b * r * t + d * t * t
            logq[j, ll] = -0.5 * d2 + c if d2 <= gate_thr else -np.inf
    return logq, nu_r, nu_b


@njit(cache=True)
def posterior_pairs(m, P, C, Sinv, S, H, R, jj, ll, nu_r, nu_b):
    """Kalman-updated mean and covariance of every detection pair (j, l) (§2.6, §2.7), pairs sorted by j.

    K_j = C_j S_j^-1; m' = m_j + K_j nu_jl; EKF (``H`` has J rows): Joseph form (I - K H) P (I - K H)^T + K R K^T;
    UKF (``H`` empty): P - K S K^T; symmetrised. K and P' depend on j only and are computed once per row.
    """
    n = jj.shape[0]
    m_new = np.empty((n, 4))
    P_new = np.empty((n, 4, 4))
    joseph = H.shape[0] > 0
    K = np.empty((4, 2))
    Pp = np.empty((4, 4))
    A = np.empty((4, 4))
    T = np.empty((4, 4))
    prev = -1
    for p in range(n):
        j = jj[p]
        if j != prev:
            prev = j
            for a in range(4):
                for b in range(2):
                    K[a, b] = C[j, a, 0] * Sinv[j, 0, b] + C[j, a, 1] * Sinv[j, 1, b]
            if joseph:
                for a in range(4):  # A = I - K H
                    for b in range(4):
                        A[a, b] = (1.0 if a == b else 0.0) - (K[a, 0] * H[j, 0, b] + K[a, 1] * H[j, 1, b])
                for a in range(4):  # T = A P
                    for b in range(4):
                        acc = 0.0
                        for c in range(4):
                            acc += A[a, c] * P[j, c, b]
                        T[a, b] = acc
                for a in range(4):  # Pp = T A^T + K R K^T
                    for b in range(4):
                        acc = 0.0
                        for c in range(4):
                            acc += T[a, c] * A[b, c]
                        kr0 = K[a, 0] * R[0, 0] + K[a, 1] * R[1, 0]
                        kr1 = K[a, 0] * R[0, 1] + K[a, 1] * R[1, 1]
                        Pp[a, b] = acc + kr0 * K[b, 0] + kr1 * K[b, 1]
            else:
                for a in range(4):  # Pp = P - K S K^T
                    ks0 = K[a, 0] * S[j, 0, 0] + K[a, 1] * S[j, 1, 0]
                    ks1 = K[a, 0] * S[j, 0, 1] + K[a, 1] * S[j, 1, 1]
                    for b in range(4):
                        Pp[a, b] = P[j, a, b] - (ks0 * K[b, 0] + ks1 * K[b, 1])
            for a in range(4):
                for b in range(a, 4):
                    s = 0.5 * (Pp[a, b] + Pp[b, a])
                    Pp[a, b] = s
                    Pp[b, a] = s
        r = nu_r[j, ll[p]]
        t = nu_b[j, ll[p]]
        for a in range(4):
            m_new[p, a] = m[j, a] + (K[a, 0] * r + K[a, 1] * t)
        P_new[p] = Pp
    return m_new, P_new


@njit(cache=True)
def _cholesky4(P, L):
    """Lower Cholesky factor of a 4x4 block into L; False if the block is not positive definite."""
    for a in range(4):
        for b in range(a + 1):
            s = P[a, b]
            for c in range(b):
                s -= L[a, c] * L[b, c]
            if a == b:
                if not s > 0.0:
                    return False
                L[a, a] = math.sqrt(s)
            else:
                L[a, b] = s / L[b, b]
    return True


@njit(cache=True, inline="always")
def cholesky4_at(P, c, L, t):
    """:func:`_cholesky4` of ``P[c]`` into ``L[t]``, indexed on the whole arrays: inlined, it takes no row view (a
    view passed to a function costs two atomic reference-count updates), for the merges that run once per
    component in hot loops."""
    for a in range(4):
        for b in range(a + 1):
            s = P[c, a, b]
            for e in range(b):
                s -= L[t, a, e] * L[t, b, e]
            if a == b:
                if not s > 0.0:
                    return False
                L[t, a, a] = math.sqrt(s)
            else:
                L[t, a, b] = s / L[t, b, b]
    return True


_LEAF = 32  #: components per k-d tree leaf
_SLACK = 1.0 + 1e-8  #: relative slack of the reach radius (rounding of Cholesky and substitution is ~1e-15)


@njit(cache=True)
def _merge_reaches(m, P, U):
    """Cholesky factors and squared reaches of the components for the indexed merges (§2.9): rho_i^2 =
    U lambda_max(P_i,xy) with slack, or -1 for a component outside the index (its covariance is not positive
    definite or its position is not finite). Returns (L (J, 4, 4), reach2 (J,), how many are indexed)."""
    J = m.shape[0]
    L = np.zeros((J, 4, 4))
    reach2 = np.empty(J)
    n_idx = 0
    for i in range(J):
        ok = _cholesky4(P[i], L[i]) and math.isfinite(m[i, 0]) and math.isfinite(m[i, 1])
        if ok:
            a, b, d = P[i, 0, 0], P[i, 1, 0], P[i, 1, 1]
            lam = 0.5 * (a + d) + math.sqrt(0.25 * (a - d) * (a - d) + b * b)
            reach2[i] = U * lam * _SLACK
            n_idx += 1
        else:
            reach2[i] = -1.0
    return L, reach2, n_idx


@njit(cache=True, inline="always")
def _merge_q(x, c, L, y):
    """q = (x - c)^T P^-1 (x - c) = |y|^2 with y = L^-1 (x - c) by forward substitution (L the Cholesky factor of
    P, y a scratch vector of 4), summed in row order: the one evaluation every merge kernel shares (§2.9)."""
    q = 0.0
    for a in range(4):
        s = x[a] - c[a]
        for b in range(a):
            s -= L[a, b] * y[b]
        y[a] = s / L[a, a]
        q += y[a] * y[a]
    return q


@njit(cache=True, inline="always")
def merge_q_at(m, i, j, L, t, y):
    """:func:`_merge_q` of ``m[i]`` against the centre ``m[j]`` with the factor ``L[t]``, indexed on the whole arrays
    (no row views, as :func:`cholesky4_at`)."""
    q = 0.0
    for a in range(4):
        s = m[i, a] - m[j, a]
        for b in range(a):
            s -= L[t, a, b] * y[b]
        y[a] = s / L[t, a, a]
        q += y[a] * y[a]
    return q


@njit(cache=True)
def _select(perm, key, a, b, k):
    """Reorder perm[a:b] so that key[perm[k]] is the (k - a)-th smallest, smaller-or-equal keys before it and
    larger-or-equal after it (Hoare's quickselect with the median of three as pivot; O(b - a) on average)."""
    lo, hi = a, b - 1
    while hi > lo:
        mid = (lo + hi) // 2
        p0, p1, p2 = key[perm[lo]], key[perm[mid]], key[perm[hi]]
        pivot = max(min(p0, p1), min(max(p0, p1), p2))
        i, j = lo, hi
        while i <= j:
            while key[perm[i]] < pivot:
                i += 1
            while key[perm[j]] > pivot:
                j -= 1
            if i <= j:
                perm[i], perm[j] = perm[j], perm[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            return


@njit(cache=True)
def _kdtree(x, y, perm):
    """Static 2-d tree over the points (x[perm], y[perm]), median splits on the wider side, ``_LEAF`` per leaf.

    Reorders ``perm`` in place so that every node owns the contiguous range perm[lo:hi]. Children get larger node
    ids than their parent (so a reverse sweep is bottom-up). Returns (lo, hi, left, right, parent, box (n, 4)).
    """
    n = perm.shape[0]
    cap = 2 * (n // _LEAF + 1) * 2 + 1
    lo = np.empty(cap, dtype=np.int64)
    hi = np.empty(cap, dtype=np.int64)
    left = np.full(cap, -1, dtype=np.int64)
    right = np.full(cap, -1, dtype=np.int64)
    parent = np.full(cap, -1, dtype=np.int64)
    box = np.empty((cap, 4))
    lo[0], hi[0] = 0, n
    n_nodes = 1
    stack = np.empty(cap, dtype=np.int64)
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        nd = stack[top]
        a, b = lo[nd], hi[nd]
        x0, x1, y0, y1 = np.inf, -np.inf, np.inf, -np.inf
        for k in range(a, b):
            i = perm[k]
            x0, x1 = min(x0, x[i]), max(x1, x[i])
            y0, y1 = min(y0, y[i]), max(y1, y[i])
        box[nd, 0], box[nd, 1], box[nd, 2], box[nd, 3] = x0, x1, y0, y1
        if b - a <= _LEAF:
            continue
        mid = (a + b) // 2
        _select(perm, x if x1 - x0 >= y1 - y0 else y, a, b, mid)
        lo[n_nodes], hi[n_nodes], lo[n_nodes + 1], hi[n_nodes + 1] = a, mid, mid, b
        parent[n_nodes] = parent[n_nodes + 1] = nd
        left[nd], right[nd] = n_nodes, n_nodes + 1
        stack[top], stack[top + 1] = n_nodes, n_nodes + 1
        top += 2
        n_nodes += 2
    return lo[:n_nodes], hi[:n_nodes], left[:n_nodes], right[:n_nodes], parent[:n_nodes], box[:n_nodes]


_SMALL_MERGE = 96  #: up to this many components the x-sorted window is faster than building the tree

#: relative margin of the merge test (docs/method.md §2.9, register row 35): i joins j*'s group when
#: q <= U (1 + MERGE_TIE). Candidates at exactly q = U (the UBM grid's neighbours, S-OA's layers l and l + 2 on one
#: ray) then merge whatever the last bit of q's rounding, on every CPU
MERGE_TIE = 1e-9


@njit(cache=True, inline="always")
def merge_threshold(U):
    """The bound every merge kernel compares q with: U (1 + MERGE_TIE) (§2.9)."""
    return U * (1.0 + MERGE_TIE)


@njit(cache=True, inline="always")  # a dispatch only: inlined, its callers do not optimise both searches again
def merge_groups(m, P, order, U):
    """Vo-Ma greedy merge groups (Table II, §2.9), literally: pass g takes j* = the next component of ``order``
    (heaviest first) still unmerged, and absorbs every unmerged i with q = (m_i - m_j*)^T P_i^-1 (m_i - m_j*) <= U,
    compared as q <= U (1 + MERGE_TIE) (:func:`merge_threshold`) so that a tie at q = U merges whatever the rounding.

    Every search structure gives exactly the same groups (the same quadratic form, evaluated the same way, on a
    superset of the candidates that can merge): :func:`merge_groups_window` for small mixtures, where its O(J x
    groups) costs least, :func:`merge_groups_grid` (about O(J) plus each pass's 3 x 3 cells) above
    ``_SMALL_MERGE`` components. :func:`merge_groups_tree` (a 2-d tree, about O(J log J)) gives the same groups
    and is kept as the reference of ``benchmarks/bench_merge_scaling.py``, which times all three.
    Returns (label (J,), centres (G,)): the group of each component and the j* of each group, in creation order.
    """
    if m.shape[0] <= _SMALL_MERGE:
        return merge_groups_window(m, P, order, U)
    return merge_groups_grid(m, P, order, U)


@njit(cache=True)
def merge_groups_tree(m, P, order, U):
    """:func:`merge_groups` with a spatial index over the positions.

    The quadratic form is |y|^2 with y = L_i^-1 d by forward substitution (L_i the Cholesky factor of P_i), exactly
    as in :func:`merge_groups_window`, so the groups are identical. Candidates are found with a spatial index: since
    |y|^2 >= y_0^2 + y_1^2 = d_xy^T P_i,xy^-1 d_xy >= |d_xy|^2 / lambda_max(P_i,xy), only an i whose position lies
    within its own reach rho_i = sqrt(U lambda_max(P_i,xy)) of m_j* can merge. A 2-d tree over the positions keeps,
    per node, the bounding box of its positions, the largest reach and the number of unmerged members; a pass
    descends only into nodes with unmerged members whose box lies within their largest reach of m_j*, and each
    merge updates the counts and reaches on its leaf-to-root path. A few wide components only widen the reach of
    their own ancestors, so a pass costs about O(log J + its group) instead of the window's O(J), and the whole
    merge about O(J log J). A covariance that is not positive definite never joins another component's group;
    a centre or candidate with a non-finite position merges with nothing (its quadratic form is NaN or inf).
    Returns (label (J,), centres (G,)): the group of each component and the j* of each group, in creation order.
    """
    U = merge_threshold(U)  # the tie rule of §2.9; every bound below is derived from this U
    J = m.shape[0]
    L, reach2, n_idx = _merge_reaches(m, P, U)
    perm = np.empty(n_idx, dtype=np.int64)
    k = 0
    for i in range(J):
        if reach2[i] >= 0.0:
            perm[k] = i
            k += 1
    lo, hi, left, right, parent, box = _kdtree(np.ascontiguousarray(m[:, 0]), np.ascontiguousarray(m[:, 1]), perm)
    n_nodes = lo.shape[0]
    # slot k of the tree holds component perm[k]; leaves own contiguous slots, so a leaf is read from one place
    slot_of = np.full(J, -1, dtype=np.int64)
    sm = np.empty((n_idx, 4))
    sL = np.empty((n_idx, 4, 4))
    sreach2 = np.empty(n_idx)
    salive = np.ones(n_idx, dtype=np.bool_)
    for k in range(n_idx):  # scalar copies: a numba slice assignment per row costs more than the row
        i = perm[k]
        slot_of[i] = k
        for a in range(4):
            sm[k, a] = m[i, a]
            for b in range(a + 1):
                sL[k, a, b] = L[i, a, b]
        sreach2[k] = reach2[i]
    count = np.zeros(n_nodes, dtype=np.int64)  # unmerged indexed members
    rmax2 = np.full(n_nodes, -1.0)  # largest reach^2 among them
    leaf_of = np.full(n_idx, -1, dtype=np.int64)
    for nd in range(n_nodes - 1, -1, -1):
        if left[nd] < 0:
            for k in range(lo[nd], hi[nd]):
                leaf_of[k] = nd
                rmax2[nd] = max(rmax2[nd], sreach2[k])
            count[nd] = hi[nd] - lo[nd]
        else:
            count[nd] = count[left[nd]] + count[right[nd]]
            rmax2[nd] = max(rmax2[left[nd]], rmax2[right[nd]])

    alive = np.ones(J, dtype=np.bool_)
    label = np.empty(J, dtype=np.int64)
    centres = np.empty(J, dtype=np.int64)
    stack = np.empty(n_nodes + 1, dtype=np.int64)
    y = np.empty(4)
    mc = np.empty(4)
    G = 0
    for c in order:
        if not alive[c]:
            continue
        alive[c] = False
        label[c] = G
        centres[G] = c
        if slot_of[c] >= 0:
            _retire(slot_of[c], salive, leaf_of, count, rmax2, sreach2, lo, hi, left, right, parent)
        for a in range(4):
            mc[a] = m[c, a]
        px, py = mc[0], mc[1]
        top = 0
        if math.isfinite(px) and math.isfinite(py) and n_nodes > 0 and count[0] > 0:
            stack[0] = 0
            top = 1
        while top > 0:
            top -= 1
            nd = stack[top]
            if count[nd] == 0:
                continue
            dx = max(box[nd, 0] - px, 0.0, px - box[nd, 1])
            dy = max(box[nd, 2] - py, 0.0, py - box[nd, 3])
            if dx * dx + dy * dy > rmax2[nd]:
                continue
            if left[nd] >= 0:
                stack[top] = left[nd]
                stack[top + 1] = right[nd]
                top += 2
                continue
            for k in range(lo[nd], hi[nd]):
                if not salive[k]:
                    continue
                ex = sm[k, 0] - px
                ey = sm[k, 1] - py
                if ex * ex + ey * ey > sreach2[k]:  # beyond its own reach: q > U (the node test, per member)
                    continue
                q = _merge_q(sm[k], mc, sL[k], y)
                if q <= U:
                    i = perm[k]
                    alive[i] = False
                    label[i] = G
                    _retire(k, salive, leaf_of, count, rmax2, sreach2, lo, hi, left, right, parent)
        G += 1
    return label, centres[:G]


@njit(cache=True, inline="always")
def _retire(k, salive, leaf_of, count, rmax2, sreach2, lo, hi, left, right, parent):
    """Mark tree slot k merged; update the unmerged counts and largest reaches from its leaf up to the root."""
    salive[k] = False
    nd = leaf_of[k]
    r = -1.0
    for kk in range(lo[nd], hi[nd]):
        if salive[kk]:
            r = max(r, sreach2[kk])
    rmax2[nd] = r
    count[nd] -= 1
    nd = parent[nd]
    while nd >= 0:
        count[nd] -= 1
        rmax2[nd] = max(rmax2[left[nd]], rmax2[right[nd]])
        nd = parent[nd]


_GRID_SLACK = 1.01  #: a member's reach is at most cell size / this (margin for the rounding of cell indices)
_GRID_LEVELS = 24  #: reach classes of the grid: cell sizes h0 4^l; the last one takes every larger reach
_GRID_H0 = 1.5  #: the finest cell size in median reaches


@njit(cache=True)
def _grid_cell(v, v0, h, n):
    """floor((v - v0) / h) for a cell index in [0, n): clamped to [-2, n + 1] first (so that a far or NaN
    coordinate gives an index with no cell within one of it, never an integer overflow)."""
    if h == np.inf:
        return 0
    q = (v - v0) / h
    if not q >= -2.0:
        return -2
    if q > n + 1.0:
        return n + 1
    return int(math.floor(q))


@njit(cache=True)
def merge_groups_grid(m, P, order, U):
    """:func:`merge_groups` with uniform grids over the positions, one per reach class.

    Same candidate bound as :func:`merge_groups_tree`: only an i whose position lies within its own reach
    rho_i = sqrt(U lambda_max(P_i,xy)) (with the same slack) of m_j* can merge. Component i goes to the grid of
    the smallest cell size h_l = h0 4^l with rho_i <= h_l (h0 = 1.5 median reach), so a pass looks only at the 3 x 3
    cells around m_j* in each grid, and at the members still unmerged there: a merged member is swapped out of its
    cell's live range. The quadratic form is the window's (forward substitution with the Cholesky factor of P_i),
    and whether i joins a pass does not depend on the order in which the pass meets its candidates, so the groups
    are exactly those of the literal loop. A grid never has more than about 4 cells per member: a sparse level
    gets larger cells (still >= its reaches). Covariances that are not positive definite and non-finite positions
    are handled as in the tree. Returns (label (J,), centres (G,)).
    """
    U = merge_threshold(U)  # the tie rule of §2.9; every bound below is derived from this U
    J = m.shape[0]
    L, reach2, n_idx = _merge_reaches(m, P, U)
    # reach classes
    level = np.full(J, -1, dtype=np.int64)
    n_lev = 0
    h0 = 1.0
    if n_idx > 0:
        rs = np.empty(n_idx)
        k = 0
        for i in range(J):
            if reach2[i] >= 0.0:
                rs[k] = math.sqrt(reach2[i])
                k += 1
        # the median of the reaches as np.median gives it (the middle one, or (a + b) / 2 of the middle two a <= b),
        # with this module's quickselect: rs[perm[half]] is the half-th smallest, every one before it at most that
        perm = np.arange(n_idx)
        half = n_idx // 2
        _select(perm, rs, 0, n_idx, half)
        mid = rs[perm[half]]
        if n_idx % 2 == 0:
            below = rs[perm[0]]
            for q in range(1, half):
                below = max(below, rs[perm[q]])
            mid = (below + mid) / 2
        h0 = _GRID_H0 * mid
        if not (h0 > 0.0 and math.isfinite(h0)):
            h0 = 1.0
        for i in range(J):
            if reach2[i] >= 0.0:
                r = math.sqrt(reach2[i]) * _GRID_SLACK
                lv = 0
                h = h0
                while r > h and lv < _GRID_LEVELS - 1:
                    h *= 4.0
                    lv += 1
                level[i] = lv
                n_lev = max(n_lev, lv + 1)
    # geometry of each level: origin, cell size (the last level is unbounded), cells per side
    x0 = np.full(n_lev, np.inf)
    x1 = np.full(n_lev, -np.inf)
    y0 = np.full(n_lev, np.inf)
    y1 = np.full(n_lev, -np.inf)
    n_mem = np.zeros(n_lev, dtype=np.int64)
    for i in range(J):
        lv = level[i]
        if lv >= 0:
            n_mem[lv] += 1
            x0[lv], x1[lv] = min(x0[lv], m[i, 0]), max(x1[lv], m[i, 0])
            y0[lv], y1[lv] = min(y0[lv], m[i, 1]), max(y1[lv], m[i, 1])
    hl = np.empty(n_lev)
    nx = np.ones(n_lev, dtype=np.int64)
    ny = np.ones(n_lev, dtype=np.int64)
    base = np.zeros(n_lev + 1, dtype=np.int64)
    h = h0
    for lv in range(n_lev):
        hl[lv] = np.inf if lv == _GRID_LEVELS - 1 else h
        h *= 4.0
        if n_mem[lv] > 0:
            W, H = x1[lv] - x0[lv], y1[lv] - y0[lv]
            cap = 4.0 * n_mem[lv] + 16.0
            if not (math.isfinite(W) and math.isfinite(H) and math.isfinite(hl[lv])):
                hl[lv] = np.inf
            elif (W / hl[lv] + 1.0) * (H / hl[lv] + 1.0) > cap:  # sparse: larger cells, at most ~cap of them
                hl[lv] = max(hl[lv], math.sqrt(W * H / cap), W / cap, H / cap)
            if math.isfinite(hl[lv]):  # both <= cap + 1: hl >= W / cap, H / cap
                nx[lv] = int(W / hl[lv]) + 1
                ny[lv] = int(H / hl[lv]) + 1
        base[lv + 1] = base[lv] + (nx[lv] * ny[lv] if n_mem[lv] > 0 else 0)
    n_cells = base[n_lev]
    # members by cell (counting sort); slot k holds component sidx[k]
    cell_of = np.full(J, -1, dtype=np.int64)
    cstart = np.zeros(n_cells + 1, dtype=np.int64)
    for i in range(J):
        lv = level[i]
        if lv >= 0:
            cx = min(max(_grid_cell(m[i, 0], x0[lv], hl[lv], nx[lv]), 0), nx[lv] - 1)
            cy = min(max(_grid_cell(m[i, 1], y0[lv], hl[lv], ny[lv]), 0), ny[lv] - 1)
            cell_of[i] = base[lv] + cx * ny[lv] + cy
            cstart[cell_of[i] + 1] += 1
    for c in range(n_cells):
        cstart[c + 1] += cstart[c]
    ccount = np.empty(n_cells, dtype=np.int64)
    for c in range(n_cells):
        ccount[c] = cstart[c + 1] - cstart[c]
    fill = cstart[:n_cells].copy()
    sidx = np.empty(n_idx, dtype=np.int64)
    sm = np.empty((n_idx, 4))
    sL = np.empty((n_idx, 10))  # packed lower factor: row a starts at a (a + 1) / 2
    sreach2 = np.empty(n_idx)
    slot_of = np.full(J, -1, dtype=np.int64)
    for i in range(J):
        c = cell_of[i]
        if c >= 0:
            k = fill[c]
            fill[c] += 1
            sidx[k] = i
            slot_of[i] = k
            sreach2[k] = reach2[i]
            for a in range(4):
                sm[k, a] = m[i, a]
                for b in range(a + 1):
                    sL[k, a * (a + 1) // 2 + b] = L[i, a, b]

    alive = np.ones(J, dtype=np.bool_)
    label = np.empty(J, dtype=np.int64)
    centres = np.empty(J, dtype=np.int64)
    mc = np.empty(4)
    G = 0
    for c in order:
        if not alive[c]:
            continue
        alive[c] = False
        label[c] = G
        centres[G] = c
        if slot_of[c] >= 0:
            _grid_remove(slot_of[c], cell_of[c], cstart, ccount, sidx, sm, sL, sreach2, slot_of)
        for a in range(4):
            mc[a] = m[c, a]
        px, py = mc[0], mc[1]
        if math.isfinite(px) and math.isfinite(py):
            for lv in range(n_lev):
                if n_mem[lv] == 0:
                    continue
                cx = _grid_cell(px, x0[lv], hl[lv], nx[lv])
                cy = _grid_cell(py, y0[lv], hl[lv], ny[lv])
                for gx in range(max(cx - 1, 0), min(cx + 2, nx[lv])):
                    for gy in range(max(cy - 1, 0), min(cy + 2, ny[lv])):
                        cell = base[lv] + gx * ny[lv] + gy
                        k = cstart[cell]
                        while k < cstart[cell] + ccount[cell]:
                            ex = sm[k, 0] - px
                            ey = sm[k, 1] - py
                            if ex * ex + ey * ey > sreach2[k]:  # beyond its own reach: q > U
                                k += 1
                                continue
                            # y = L_i^-1 d by forward substitution, q = |y|^2 summed in the order of the
                            # window's loop; q only grows, so past U after the position rows it is out
                            u0 = (sm[k, 0] - mc[0]) / sL[k, 0]
                            q = 0.0 + u0 * u0
                            u1 = ((sm[k, 1] - mc[1]) - sL[k, 1] * u0) / sL[k, 2]
                            q += u1 * u1
                            if q > U:
                                k += 1
                                continue
                            u2 = (((sm[k, 2] - mc[2]) - sL[k, 3] * u0) - sL[k, 4] * u1) / sL[k, 5]
                            q += u2 * u2
                            u3 = ((((sm[k, 3] - mc[3]) - sL[k, 6] * u0) - sL[k, 7] * u1) - sL[k, 8] * u2) / sL[k, 9]
                            q += u3 * u3
                            if q <= U:
                                i = sidx[k]
                                alive[i] = False
                                label[i] = G
                                _grid_remove(k, cell, cstart, ccount, sidx, sm, sL, sreach2, slot_of)
                            else:
                                k += 1
        G += 1
    return label, centres[:G]


@njit(cache=True, inline="always")
def _grid_remove(k, cell, cstart, ccount, sidx, sm, sL, sreach2, slot_of):
    """Take slot k out of its cell's live range: the cell's last live slot moves into k."""
    last = cstart[cell] + ccount[cell] - 1
    if k != last:
        j = sidx[last]
        sidx[k] = j
        slot_of[j] = k
        sreach2[k] = sreach2[last]
        for a in range(4):
            sm[k, a] = sm[last, a]
        for a in range(10):
            sL[k, a] = sL[last, a]
    ccount[cell] -= 1


@njit(cache=True)
def merge_groups_window(m, P, order, U):
    """:func:`merge_groups` with an x-sorted window (also the baseline of ``benchmarks/bench_merge_scaling.py``).
    Each pass scans every component in the window, merged or not: O(J x groups) once the widest covariance makes
    the window wide.

    The quadratic form is |L_i^-1 d|^2 with L_i the Cholesky factor of P_i. Candidates are looked up in a window
    of the x-sorted means: d^T P_i^-1 d >= dx^2 / P_i,xx, so only |dx| <= sqrt(U max_i P_i,xx) can merge. A
    covariance that is not positive definite never joins another component's group.
    Returns (label (J,), centres (G,)): the group of each component and the j* of each group, in creation order.
    """
    U = merge_threshold(U)  # the tie rule of §2.9; every bound below is derived from this U
    J = m.shape[0]
    L = np.zeros((J, 4, 4))
    spd = np.empty(J, dtype=np.bool_)
    pxx_max = 0.0
    for i in range(J):
        spd[i] = _cholesky4(P[i], L[i])
        if spd[i] and P[i, 0, 0] > pxx_max:
            pxx_max = P[i, 0, 0]
    x = np.empty(J)
    for i in range(J):
        x[i] = m[i, 0]
    # any order of equal x gives the same window, and so the same groups; the stable sort of a contiguous float64
    # array is the one _order_heaviest_first compiles, so no second sort is compiled for this one
    by_x = np.argsort(x, kind="mergesort")
    xs = m[by_x, 0]
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
        lo = np.searchsorted(xs, m[c, 0] - half)
        hi = np.searchsorted(xs, m[c, 0] + half, side="right")
        for k in range(lo, hi):
            i = by_x[k]
            if not alive[i] or not spd[i]:
                continue
            d0 = m[i, 0] - m[c, 0]
            if d0 * d0 > U * P[i, 0, 0] * (1.0 + 1e-9):  # the x marginal alone already exceeds U
                continue
            q = _merge_q(m[i], m[c], L[i], y)
            if q <= U:
                alive[i] = False
                label[i] = G
        G += 1
    return label, centres[:G]


@njit(cache=True, inline="always")
def copy_state(mo, Po, q, m, P, j):
    """mo[q] = m[j], Po[q] = P[j] element by element: cheaper than numba's row slice assignment, and links no
    shape-mismatch error (see :func:`copy_row`)."""
    for a in range(4):
        mo[q, a] = m[j, a]
        for b in range(4):
            Po[q, a, b] = P[j, a, b]


@njit(cache=True, inline="always")
def copy_row(dst, q, src, j):
    """dst[q] = src[j] for rows of 4, element by element: a row assignment would link numba's shape-mismatch error,
    whose message formatting (numba's string functions) compiles into every caller."""
    for a in range(4):
        dst[q, a] = src[j, a]


@njit(cache=True, inline="always")
def heaviest(w, lo, hi):
    """The index of the largest of w[lo:hi] (the first at a tie): the component a track is reported at (estimator of
    docs/method.md §10.4 and the LMB's extraction)."""
    best = lo
    for c in range(lo, hi):
        if w[c] > w[best]:
            best = c
    return best


@njit(cache=True, inline="always")
def set_row(dst, q, v):
    """dst[q] = v for a row of 4, element by element (as :func:`copy_row`)."""
    for a in range(4):
        dst[q, a] = v[a]


@njit(cache=True)
def merge_moments(label, centres, w, m, P, n_det, age):
    """Moment-matched group Gaussians (§2.9): W = sum w_i, m~ = sum w_i m_i / W,
    P~ = sum w_i [P_i + (m~ - m_i)(m~ - m_i)^T] / W (symmetrised); n_det and age are the group maxima.
    A singleton group is its component, unchanged. Members are summed in index order."""
    G = centres.shape[0]
    J = w.shape[0]
    W = np.zeros(G)
    mt = np.zeros((G, 4))
    Pt = np.zeros((G, 4, 4))
    nd = np.empty(G, dtype=n_det.dtype)
    ag = np.empty(G, dtype=age.dtype)
    count = np.zeros(G, dtype=np.int64)
    for i in range(J):
        count[label[i]] += 1
    for g in range(G):
        c = centres[g]
        nd[g] = n_det[c]
        ag[g] = age[c]
        if count[g] == 1:
            W[g] = w[c]
            copy_state(mt, Pt, g, m, P, c)
    for i in range(J):
        g = label[i]
        if count[g] > 1:
            W[g] += w[i]
            for a in range(4):
                mt[g, a] += w[i] * m[i, a]
            nd[g] = max(nd[g], n_det[i])
            ag[g] = max(ag[g], age[i])
    for g in range(G):
        if count[g] > 1:
            for a in range(4):
                mt[g, a] /= W[g]
    for i in range(J):
        g = label[i]
        if count[g] > 1:
            for a in range(4):
                da = mt[g, a] - m[i, a]
                for b in range(4):
                    Pt[g, a, b] += w[i] * (P[i, a, b] + da * (mt[g, b] - m[i, b]))
    for g in range(G):
        if count[g] > 1:
            for a in range(4):
                for b in range(a, 4):
                    s = 0.5 * (Pt[g, a, b] + Pt[g, b, a]) / W[g]
                    Pt[g, a, b] = s
                    Pt[g, b, a] = s
    return W, mt, Pt, nd, ag, count


_FEW_ESTIMATES = 24  #: up to this many extracted components, label conflicts are found by a pairwise test


@njit(cache=True)
def extract_labels(w, label, idx, reps, next_label):
    """The labels of the estimates extracted from components ``idx`` (``reps[k]`` copies of component idx[k], in
    the order of X), by the rule of §2.13: each estimate takes its component's label; when extracted components
    share a label, the heaviest keeps it (equal weights: the lower index) and each other one gets a fresh label,
    written back, heaviest first; the second and later copies of one component get fresh labels that are not
    written back. Fresh labels are next_label, next_label + 1, ...

    Returns (labels of the estimates, the components' labels after the write-back (``label`` itself, changed in
    place), the next unused label).
    """
    n = idx.shape[0]
    n_dup = 0  # estimates whose label an earlier one has: the losers of the conflicts
    if n <= _FEW_ESTIMATES:  # the usual scan: a pairwise test allocates nothing
        for a in range(1, n):
            for c in range(a):
                if label[idx[c]] == label[idx[a]]:
                    n_dup += 1
                    break
    else:
        keys = np.empty(n, dtype=np.int64)
        for k in range(n):
            keys[k] = label[idx[k]]
        by_key = np.argsort(keys, kind="mergesort")
        for k in range(1, n):
            if keys[by_key[k]] == keys[by_key[k - 1]]:
                n_dup += 1
    if n_dup > 0:  # every member of a run of equal labels but its heaviest is a loser
        keys = np.empty(n, dtype=np.int64)
        for k in range(n):
            keys[k] = label[idx[k]]
        by_key = np.argsort(keys, kind="mergesort")
        loser = np.zeros(n, dtype=np.bool_)
        a = 0
        while a < n:
            b = a + 1
            while b < n and keys[by_key[b]] == keys[by_key[a]]:
                b += 1
            best = by_key[a]
            for k in range(a + 1, b):
                c = by_key[k]
                if w[idx[c]] > w[idx[best]] or (w[idx[c]] == w[idx[best]] and idx[c] < idx[best]):
                    best = c
            for k in range(a, b):
                loser[by_key[k]] = by_key[k] != best
            a = b
        pos = np.empty(n_dup, dtype=np.int64)
        q = 0
        for k in range(n):
            if loser[k]:
                pos[q] = k
                q += 1
        pos = pos[np.argsort(idx[pos], kind="mergesort")]  # component order, then heaviest first (stable)
        ww = np.empty(n_dup)
        for q in range(n_dup):
            ww[q] = -w[idx[pos[q]]]
        pos = pos[np.argsort(ww, kind="mergesort")]
        for q in range(n_dup):
            label[idx[pos[q]]] = next_label
            next_label += 1
    n_x = 0
    for k in range(n):
        n_x += reps[k]
    out = np.empty(n_x, dtype=np.int64)
    q = 0
    for k in range(n):
        for r in range(reps[k]):
            if r == 0:
                out[q] = label[idx[k]]
            else:
                out[q] = next_label
                next_label += 1
            q += 1
    return out, label, next_label
