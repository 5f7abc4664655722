"""Compiled scan loops of the track metrics (docs/method.md §9.3).

* :func:`match_scans`: HOTA's alignment-weighted matching and CLEAR MOT's continuity-first matching of every scan,
  in scan order (CLEAR carries the previous scan's matches forward);
* :func:`ospa2_scans`: OSPA(2) of every sliding window.

Each assignment is the minimum-cost one of :func:`soabench.metrics_kernels.assignment` on the cost matrices that
TrackEval and :func:`soabench.metrics.ospa` build, with the same floating-point operations (IEEE double, no
``fastmath``). An optimal assignment is unique unless two have the same cost; :func:`match_scans` stops at a scan
whose cost matrix has two equal rows or columns (two equal positions that the labels do not tell apart) so that the
caller matches it with scipy, as TrackEval does. :func:`match_scans` finds each scan's assignments per connected
component of the non-zero costs (:func:`sparse_assignment`): a pair of zero similarity is never a match, so these
are the matches of the whole matrix's assignment.
"""

from __future__ import annotations

import math

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()  # before numba is imported: compiled kernels go to the per-user cache, not site-packages

from numba import njit  # noqa: E402

from soabench.metrics_kernels import assignment, np_sum  # noqa: E402

_EPS = np.finfo(np.float64).eps


@njit(cache=True)
def scan_similarity(gx, g0, ng, ex, e0, ne, d_gate):  # pragma: no cover - compiled
    """(ng, ne) similarity max(0, 1 - d / (2 d_gate)) of rows ``gx[g0:g0 + ng]`` and ``ex[e0:e0 + ne]``, with the
    operations of :func:`soabench.tracks.sequence.similarity`. A pair whose squared distance exceeds (2 d_gate) ** 2
    by more than its rounding has d >= 2 d_gate, so 0.0 (the value of the formula) without a square root."""
    S = np.empty((ng, ne))
    far2 = (2.0 * d_gate) * (2.0 * d_gate) * (1.0 + 4.0 * _EPS)
    for i in range(ng):
        for j in range(ne):
            dx = gx[g0 + i, 0] - ex[e0 + j, 0]
            dy = gx[g0 + i, 1] - ex[e0 + j, 1]
            dd = dx * dx + dy * dy
            S[i, j] = 0.0 if dd > far2 else max(0.0, 1.0 - math.sqrt(dd) / (2.0 * d_gate))
    return S


@njit(cache=True)
def _equal_rows(C):  # pragma: no cover - compiled
    """True if two rows of ``C`` are equal and not all zero. Two such rows have their first non-zero entry in the
    same column, so only rows that share it are compared (from that column on)."""
    a, b = C.shape
    first = np.full(a, b, dtype=np.int64)  # b: an all-zero row
    for i in range(a):
        for c in range(b):
            if C[i, c] != 0.0:
                first[i] = c
                break
    order = np.argsort(first, kind="mergesort")
    s = 0
    while s < a:
        e = s + 1
        while e < a and first[order[e]] == first[order[s]]:
            e += 1
        f = first[order[s]]
        if f < b:
            for x in range(s, e):
                for y in range(x + 1, e):
                    i, j = order[x], order[y]
                    same = True
                    for c in range(f, b):
                        if C[i, c] != C[j, c]:
                            same = False
                            break
                    if same:
                        return True
        s = e
    return False


@njit(cache=True)
def _tied(C):  # pragma: no cover - compiled
    """True if two rows or two columns of ``C`` are equal and not all zero: then several assignments are optimal
    and which one is taken can change the matches (a zero row or column is never a kept match)."""
    return _equal_rows(C) or _equal_rows(np.ascontiguousarray(C.T))


@njit(cache=True)
def _root(parent, x):  # pragma: no cover - compiled
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@njit(cache=True)
def sparse_assignment(C):  # pragma: no cover - compiled
    """(rows, cols) of the pairs with a non-zero cost in a minimum-cost assignment of ``C`` (a, b) whose entries
    are <= 0, sorted by row.

    A pair of zero cost changes no total, so a minimum-cost assignment's non-zero pairs are a minimum-cost matching
    of the graph of non-zero entries, which splits into that graph's connected components: each is assigned on its
    own rows and columns (:func:`soabench.metrics_kernels.assignment`). Where the optimum is unique (:func:`_tied`
    sends the ties equal rows or columns make to scipy) these are the non-zero pairs of the whole matrix's
    assignment."""
    a, b = C.shape
    parent = np.arange(a + b)
    for i in range(a):
        for j in range(b):
            if C[i, j] != 0.0:
                ri, rj = _root(parent, i), _root(parent, a + j)
                if ri != rj:
                    parent[max(ri, rj)] = min(ri, rj)
    comp = np.empty(a + b, dtype=np.int64)
    for x in range(a + b):
        comp[x] = _root(parent, x)
    out_r = np.empty(min(a, b), dtype=np.int64)
    out_c = np.empty(min(a, b), dtype=np.int64)
    n = 0
    rows = np.empty(a, dtype=np.int64)
    cols = np.empty(b, dtype=np.int64)
    for r0 in range(a):
        if comp[r0] != r0:  # a component is handled at its root, its smallest row
            continue
        na = nb = 0
        for i in range(a):
            if comp[i] == r0:
                rows[na] = i
                na += 1
        for j in range(b):
            if comp[a + j] == r0:
                cols[nb] = j
                nb += 1
        if nb == 0:
            continue
        sub = np.empty((na, nb))
        for x in range(na):
            for y in range(nb):
                sub[x, y] = C[rows[x], cols[y]]
        sr, sc = assignment(sub)
        for t in range(len(sr)):
            if sub[sr[t], sc[t]] != 0.0:
                out_r[n], out_c[n] = rows[sr[t]], cols[sc[t]]
                n += 1
    order = np.argsort(out_r[:n], kind="mergesort")
    return out_r[:n][order], out_c[:n][order]


@njit(cache=True)
def match_scans(t, g_ids, g_off, gx, e_ids, e_off, ex, d_gate, threshold, alignment, state):  # pragma: no cover
    """Scans t, t + 1, ... of :func:`soabench.tracks.scores._scan_matches` until the end or a scan whose matching
    has several optimal answers (:func:`_tied`); returns the index of that scan (K at the end) and its similarity
    S, HOTA's cost ``-(alignment * S)`` and CLEAR's cost ``-score`` (``score``: 1000 for the previous scan's pair
    plus S, 0 below the threshold), with the operations of the numpy form scipy matches it on (empty at the end).

    ``state`` is :class:`soabench.tracks.scores._MatchState`'s arrays in order: counts (tp, fn, fp, idsw, n_pairs),
    motp_sum (1,), gt_seen, gt_matched, frag_count, prev_id, prev_scan_id, and HOTA's pairs hg, he, hs.
    """
    counts, motp, gt_seen, gt_matched, frag, prev_id, prev_scan, hg, he, hs = state
    K = len(g_off) - 1
    S = C = Q = np.empty((0, 0))
    while t < K:
        g0, e0 = g_off[t], e_off[t]
        ng, ne = g_off[t + 1] - g0, e_off[t + 1] - e0
        if ng == 0:
            counts[2] += ne
        elif ne == 0:
            counts[1] += ng
            for i in range(ng):
                gt_seen[g_ids[g0 + i]] += 1
        else:
            S = scan_similarity(gx, g0, ng, ex, e0, ne, d_gate)
            C = np.empty((ng, ne))  # HOTA: alignment-weighted similarity
            Q = np.empty((ng, ne))  # CLEAR: the previous scan's pairs first, then similarity, 0 below the threshold
            for i in range(ng):
                for j in range(ne):
                    # -(alignment * 0.0) is -0.0 for the finite, non-negative alignment: not read where S is 0.0
                    C[i, j] = -(alignment[g_ids[g0 + i], e_ids[e0 + j]] * S[i, j]) if S[i, j] != 0.0 else -0.0
                    score = (1000.0 if e_ids[e0 + j] == prev_scan[g_ids[g0 + i]] else 0.0) + S[i, j]
                    Q[i, j] = -(0.0 if S[i, j] < threshold - _EPS else score)
            if _tied(C) or _tied(Q):
                return t, S, C, Q
            rows, cols = sparse_assignment(C)  # the pairs of zero similarity are never a match
            n = counts[4]
            for r in range(len(rows)):
                hg[n + r] = g_ids[g0 + rows[r]]
                he[n + r] = e_ids[e0 + cols[r]]
                hs[n + r] = S[rows[r], cols[r]]
            counts[4] = n + len(rows)
            rows, cols = sparse_assignment(Q)  # the zero entries are never kept
            for i in range(ng):
                gt_seen[g_ids[g0 + i]] += 1
            untracked = prev_scan < 0
            prev_scan[:] = -1
            matched = 0
            sim_sum = 0.0
            for r in range(len(rows)):
                if -Q[rows[r], cols[r]] > _EPS:
                    mg, me = g_ids[g0 + rows[r]], e_ids[e0 + cols[r]]
                    if prev_id[mg] >= 0 and prev_id[mg] != me:
                        counts[3] += 1
                    gt_matched[mg] += 1
                    prev_id[mg] = me
                    prev_scan[mg] = me
                    matched += 1
                    sim_sum += S[rows[r], cols[r]]
            for i in range(len(frag)):
                if untracked[i] and prev_scan[i] >= 0:
                    frag[i] += 1
            counts[0] += matched
            counts[1] += ng - matched
            counts[2] += ne - matched
            motp[0] += sim_sum
        t += 1
    return t, S[:0, :0], C[:0, :0], Q[:0, :0]


@njit(cache=True)
def global_counts(g_ids, g_off, gx, e_ids, e_off, ex, d_gate, threshold, step, nT, potential, id_potential):
    """HOTA's summed Jaccard overlaps and Identity's potential-match counts into ``potential`` and ``id_potential``
    (nG * nT,), with the operations of the padded-array form of :func:`soabench.tracks.scores._global_counts` (its
    runs of ``step`` scans padded to G truths x E estimates): per scan, each truth's similarity sum over the E
    padded entries in numpy's pairwise order, each estimate's sum over the G padded truths one after another, the
    overlap ``S / (col + row - S)`` where that exceeds machine epsilon; per run of scans, the overlaps summed per
    cell in scan order from 0.0 and added to ``potential``. A pair of zero similarity adds 0.0 and is skipped.
    Returns the cells that ``potential`` and ``id_potential`` hold a non-zero value in (each once, unsorted), so that
    the (nG * nT,) arrays need not be searched for them."""
    K = len(g_off) - 1
    G, E = 0, 0
    for t in range(K):
        G = max(G, g_off[t + 1] - g_off[t])
        E = max(E, e_off[t + 1] - e_off[t])
    row = np.zeros(max(E, 1))
    col = np.zeros(max(E, 1))
    rsum = np.zeros(max(G, 1))
    block = np.zeros(len(potential))
    touched = np.empty(16, dtype=np.int64)
    n_touched = 0
    cells = np.empty(16, dtype=np.int64)
    id_cells = np.empty(16, dtype=np.int64)
    n_cells = n_id = 0
    for t in range(K):
        g0, e0 = g_off[t], e_off[t]
        ng, ne = g_off[t + 1] - g0, e_off[t + 1] - e0
        if ng > 0 and ne > 0:
            if n_touched + ng * ne > len(touched):  # grown here, not inside the pair loop (reference counts)
                touched = np.concatenate((touched[:n_touched], np.empty(n_touched + 2 * ng * ne, dtype=np.int64)))
            if n_id + ng * ne > len(id_cells):
                id_cells = np.concatenate((id_cells[:n_id], np.empty(n_id + 2 * ng * ne, dtype=np.int64)))
            S = scan_similarity(gx, g0, ng, ex, e0, ne, d_gate)
            for j in range(ne):  # element loops: no slice assignment (and its shape-mismatch message) compiled
                col[j] = S[0, j]
            for i in range(1, ng):
                for j in range(ne):
                    col[j] += S[i, j]
            for i in range(ng):
                for j in range(ne):
                    row[j] = S[i, j]
                for j in range(ne, E):
                    row[j] = 0.0
                rsum[i] = np_sum(row, np.int64(E))
            for i in range(ng):
                for j in range(ne):
                    if S[i, j] == 0.0:
                        continue
                    denom = (col[j] + rsum[i]) - S[i, j]
                    iou = S[i, j] / denom if denom > _EPS else 0.0
                    x = g_ids[g0 + i] * nT + e_ids[e0 + j]
                    if block[x] == 0.0 and iou != 0.0:
                        touched[n_touched] = x
                        n_touched += 1
                    block[x] += iou
                    if S[i, j] >= threshold:
                        if id_potential[x] == 0.0:
                            id_cells[n_id] = x
                            n_id += 1
                        id_potential[x] += 1.0
        if (t + 1) % step == 0 or t == K - 1:  # the end of a run of scans: its sums join the totals
            if n_cells + n_touched > len(cells):
                cells = np.concatenate((cells[:n_cells], np.empty(n_cells + 2 * n_touched, dtype=np.int64)))
            for q in range(n_touched):
                x = touched[q]
                if potential[x] == 0.0:  # a sum of positive overlaps: non-zero from its first one on
                    cells[n_cells] = x
                    n_cells += 1
                potential[x] += block[x]
                block[x] = 0.0
            n_touched = 0
    return cells[:n_cells], id_cells[:n_id]


@njit(cache=True)
def _sparse_block(pos, val, lo, hi, start, n, out, acc):  # pragma: no cover - compiled
    """``out[i]``: numpy's pairwise sum of a zero array of ``n`` <= 128 elements from ``start`` with ``val[lo:hi, i]``
    at the sorted positions ``pos[lo:hi]`` (all inside it), for every column i of ``val``: its leaf case (eight running
    sums ``acc``), adding a zero being exact."""
    R = val.shape[1]
    if n < 8:
        for i in range(R):
            out[i] = -0.0
        for q in range(lo, hi):
            for i in range(R):
                out[i] += val[q, i]
        return
    for j in range(8):
        for i in range(R):
            acc[j, i] = 0.0
    stop = start + n - n % 8
    q = lo
    while q < hi and pos[q] < stop:
        j = (pos[q] - start) % 8
        for i in range(R):
            acc[j, i] += val[q, i]
        q += 1
    for i in range(R):
        left = (acc[0, i] + acc[1, i]) + (acc[2, i] + acc[3, i])
        out[i] = left + ((acc[4, i] + acc[5, i]) + (acc[6, i] + acc[7, i]))
    while q < hi:
        for i in range(R):
            out[i] += val[q, i]
        q += 1


@njit(cache=True)
def _first_at_or_after(pos, lo, hi, x):  # pragma: no cover - compiled
    """The first index q in lo..hi with ``pos[q] >= x`` (hi if none; ``pos`` sorted)."""
    while lo < hi:
        mid = (lo + hi) // 2
        if pos[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True)
def sparse_np_sum(pos, val, n):  # pragma: no cover - compiled
    """``a.sum()`` of each column of ``val`` (m, R) as an (n,) float64 array ``a`` that is zero but for that column's
    values (>= 0) at the sorted positions ``pos`` (m,): (R,) sums, bit for bit, in time of the listed entries. numpy's
    pairwise summation (halves split at a multiple of 8 above 128 elements, eight running sums below;
    :func:`soabench.metrics_kernels.np_sum`) with every part that holds no listed entry known to be 0.0, which adds
    exactly, as does a listed 0.0; the R sums share one walk over the positions."""
    R = val.shape[1]
    if n == 0 or len(pos) == 0:
        return np.zeros(R)
    f_start = np.empty(64, dtype=np.int64)
    f_n = np.empty(64, dtype=np.int64)
    f_lo = np.empty(64, dtype=np.int64)
    f_mid = np.empty(64, dtype=np.int64)
    f_hi = np.empty(64, dtype=np.int64)
    f_stage = np.zeros(64, dtype=np.int64)
    vals = np.empty((64, R))
    acc = np.empty((8, R))
    nv = 0
    top = 0
    f_start[0], f_n[0], f_lo[0], f_hi[0] = 0, n, 0, len(pos)
    while top >= 0:
        s, m, lo, hi = f_start[top], f_n[top], f_lo[top], f_hi[top]
        if lo == hi or m <= 128:
            if lo == hi:
                for i in range(R):
                    vals[nv, i] = 0.0
            else:
                _sparse_block(pos, val, lo, hi, s, m, vals[nv], acc)
            nv += 1
            top -= 1
            continue
        half = m // 2
        half -= half % 8
        if f_stage[top] == 0:  # the left half first
            f_stage[top] = 1
            mid = _first_at_or_after(pos, lo, hi, s + half)
            f_mid[top] = mid
            top += 1
            f_start[top], f_n[top], f_lo[top], f_hi[top], f_stage[top] = s, half, lo, mid, 0
        elif f_stage[top] == 1:  # then the right half
            f_stage[top] = 2
            mid = f_mid[top]
            top += 1
            f_start[top], f_n[top], f_lo[top], f_hi[top], f_stage[top] = s + half, m - half, mid, hi, 0
        else:  # both done: left + right
            for i in range(R):
                vals[nv - 2, i] = vals[nv - 2, i] + vals[nv - 1, i]
            nv -= 1
            top -= 1
    out = np.empty(R)
    for i in range(R):
        out[i] = vals[0, i]
    return out


@njit(cache=True)
def _popcount(x):  # pragma: no cover - compiled
    """Number of set bits of the uint64 ``x`` (the bits counted in parallel: pairs, nibbles, then bytes summed)."""
    x = x - ((x >> np.uint64(1)) & np.uint64(0x5555555555555555))
    x = (x & np.uint64(0x3333333333333333)) + ((x >> np.uint64(2)) & np.uint64(0x3333333333333333))
    x = (x + (x >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return np.int64((x * np.uint64(0x0101010101010101)) >> np.uint64(56))


@njit(cache=True)
def _union_count(mg, me):  # pragma: no cover - compiled
    """Scans of the window where either of two tracks exists: the set bits of their presence masks or-ed."""
    n = 0
    for w in range(len(mg)):
        n += _popcount(mg[w] | me[w])
    return n


@njit(cache=True)
def _near_events(g_ids, g0, ng, gx, e_ids, e0, ne, ex, c, ev_i, ev_j, ev_d, n_ev):  # pragma: no cover - compiled
    """Append the pairs of one scan closer than ``c`` (truth id, estimate id, ``min(c, d)``) to the event arrays
    from ``n_ev`` on, growing them first to hold every pair of the scan (an array replaced inside the pair loop
    would be reference-counted at every pair); returns the arrays and the new count."""
    if n_ev + ng * ne > len(ev_i):
        size = max(2 * len(ev_i), n_ev + ng * ne)
        ev_i = np.concatenate((ev_i[:n_ev], np.empty(size - n_ev, dtype=np.int64)))
        ev_j = np.concatenate((ev_j[:n_ev], np.empty(size - n_ev, dtype=np.int64)))
        ev_d = np.concatenate((ev_d[:n_ev], np.empty(size - n_ev)))
    far2 = c * c * (1.0 + 4.0 * _EPS)  # above c ** 2 by more than its rounding: sqrt(dd) >= c from dd > far2 on
    for a in range(ng):
        for b in range(ne):
            dx = gx[g0 + a, 0] - ex[e0 + b, 0]
            dy = gx[g0 + a, 1] - ex[e0 + b, 1]
            dd = dx * dx + dy * dy
            if dd > far2:
                continue
            d = min(c, math.sqrt(dd))
            if d < c:
                ev_i[n_ev], ev_j[n_ev], ev_d[n_ev] = g_ids[g0 + a], e_ids[e0 + b], d
                n_ev += 1
    return ev_i, ev_j, ev_d, n_ev


@njit(cache=True)
def _window_tracks(ids, off, lo, k, stamp, sel):  # pragma: no cover - compiled
    """The ids with a row in scans lo..k, sorted, into ``sel``; returns how many (``stamp``: per id, the last
    window that counted it)."""
    m = 0
    for t in range(lo, k + 1):
        for r in range(off[t], off[t + 1]):
            i = ids[r]
            if stamp[i] != k:
                stamp[i] = k
                sel[m] = i
                m += 1
    sel[:m].sort()
    return m


@njit(cache=True)
def sparse_assign_rows(n_rows, n_cols, off, col, cost, unmatched):  # pragma: no cover - compiled
    """Minimum-cost assignment of rows to columns where row r may take column ``col[q]`` at ``cost[q]`` (q in
    ``off[r]:off[r + 1]``) or stay unmatched at ``unmatched`` (>= every cost): the column of each row, -1 unmatched.

    The dense method of :func:`soabench.metrics_kernels.assign_rows` on the listed pairs only: each row has a
    column of its own that stands for staying unmatched, and row i is added by Dijkstra's shortest path from it over
    the reduced costs ``cost - u[r] - v[j]`` of the listed pairs (the dual potentials u, v kept non-negative on
    them), to the nearest free column; the path is then flipped and the potentials of the columns it settled moved.
    A column settled first wins a tie of distances unless another is free."""
    n_all = n_cols + n_rows  # column n_cols + r: row r unmatched
    u = np.zeros(n_rows)
    v = np.zeros(n_all)
    row4col = np.full(n_all, -1, dtype=np.int64)
    col4row = np.full(n_rows, -1, dtype=np.int64)
    dist = np.empty(n_all)
    pred = np.empty(n_all, dtype=np.int64)
    state = np.zeros(n_all, dtype=np.int8)  # 0: not reached, 1: reached, 2: settled
    front = np.empty(n_all, dtype=np.int64)
    settled = np.empty(n_all, dtype=np.int64)
    visited = np.empty(n_rows, dtype=np.int64)
    # augmenting row reduction (Jonker & Volgenant 1987), two passes: each free row takes the column of its
    # cheapest reduced cost c - v, whose v is lowered to tie it with the row's second cheapest; a row it displaces
    # is free for the next pass. Only a column that stays matched has its v lowered, so the free columns keep v = 0
    # and the potentials stay those of an optimal assignment's dual once every row is placed.
    free = np.arange(n_rows)
    n_free = n_rows
    for _ in range(2):
        n_todo, n_free = n_free, 0
        for k in range(n_todo):
            i = free[k]
            h1, h2, j1, j2 = np.inf, np.inf, -1, -1
            for q in range(off[i], off[i + 1] + 1):
                if q < off[i + 1]:
                    j, cst = col[q], cost[q]
                else:
                    j, cst = n_cols + i, unmatched
                h = cst - v[j]
                if h < h2:
                    if h < h1:
                        h2, j2, h1, j1 = h1, j1, h, j
                    else:
                        h2, j2 = h, j
            i0 = row4col[j1]
            if h1 < h2 < np.inf:
                v[j1] -= h2 - h1
            elif i0 >= 0 and j2 >= 0:  # a tie: the second column, free or not
                j1, i0 = j2, row4col[j2]
            row4col[j1], col4row[i] = i, j1
            if i0 >= 0:
                col4row[i0] = -1
                free[n_free] = i0  # n_free <= k: nothing still to read is overwritten
                n_free += 1
    for r in range(n_rows):  # u[r]: the row's cheapest reduced cost (its own column's, where it holds one)
        u[r] = np.inf
        for q in range(off[r], off[r + 1] + 1):
            if q < off[r + 1]:
                j, cst = col[q], cost[q]
            else:
                j, cst = n_cols + r, unmatched
            u[r] = min(u[r], cst - v[j])
    for i in range(n_rows):
        if col4row[i] >= 0:
            continue
        n_front = n_settled = n_visited = 0
        r, d_r = i, 0.0
        bound = np.inf  # the distance of the nearest free column reached: nothing farther is settled before it
        while True:
            for q in range(off[r], off[r + 1] + 1):
                if q < off[r + 1]:
                    j, cst = col[q], cost[q]
                else:
                    j, cst = n_cols + r, unmatched
                if state[j] == 2:
                    continue
                d = d_r + cst - u[r] - v[j]
                if d >= bound and (d > bound or row4col[j] >= 0):
                    continue
                if row4col[j] < 0:
                    bound = d
                if state[j] == 0:
                    state[j] = 1
                    front[n_front] = j
                    n_front += 1
                    dist[j], pred[j] = d, r
                elif d < dist[j]:
                    dist[j], pred[j] = d, r
            best = 0
            for t in range(1, n_front):
                j, b = front[t], front[best]
                if dist[j] < dist[b] or (dist[j] == dist[b] and row4col[j] < 0 and row4col[b] >= 0):
                    best = t
            sink = front[best]
            n_front -= 1
            front[best] = front[n_front]
            state[sink] = 2
            settled[n_settled] = sink
            n_settled += 1
            if row4col[sink] < 0:
                break
            r, d_r = row4col[sink], dist[sink]
            visited[n_visited] = r
            n_visited += 1
        low = dist[sink]
        u[i] += low
        for t in range(n_visited):
            r = visited[t]
            u[r] += low - dist[col4row[r]]
        for t in range(n_settled):
            j = settled[t]
            v[j] -= low - dist[j]
            state[j] = 0
        for t in range(n_front):
            state[front[t]] = 0
        j = sink
        while True:  # flip the path back to row i
            r = pred[j]
            row4col[j] = r
            j, col4row[r] = col4row[r], j
            if r == i:
                break
    for r in range(n_rows):
        if col4row[r] >= n_cols:
            col4row[r] = -1
    return col4row


@njit(cache=True)
def _near_assignment(near_a, near_b, cost, n_near, m, n, cp, vals):  # pragma: no cover - compiled
    """``vals[r]``: the cost of row r of the smaller side in a minimum-cost assignment of the window's (m, n) cost
    matrix whose every pair but the near ones (``near_a[q]``, ``near_b[q]``; cost ``cost[q]``) costs ``cp``, the
    largest cost; ``cp`` for a row assigned to such a pair.

    An assignment of the rows costs the sum of its near pairs plus ``cp`` per other row, whichever pairs those are,
    and a set of near pairs without a shared row or column can always be completed by pairs that cost at most
    ``cp``: so the minimum is that of the near pairs alone, each row free to stay unmatched at ``cp``
    (:func:`sparse_assign_rows`). Where the optimum is unique the rows' costs are those of the dense matrix's."""
    rows_are_g = m <= n
    n_rows, n_cols = (m, n) if rows_are_g else (n, m)
    off = np.zeros(n_rows + 1, dtype=np.int64)
    for q in range(n_near):
        r = near_a[q] if rows_are_g else near_b[q]
        off[r + 1] += 1
    for r in range(n_rows):
        off[r + 1] += off[r]
    fill = off[:-1].copy()
    col = np.empty(n_near, dtype=np.int64)
    cst = np.empty(n_near)
    for q in range(n_near):  # each row's pairs in the order of their first event
        a, b = near_a[q], near_b[q]
        r, j = (a, b) if rows_are_g else (b, a)
        col[fill[r]], cst[fill[r]] = j, cost[q]
        fill[r] += 1
    col_of = sparse_assign_rows(n_rows, n_cols, off, col, cst, cp)
    for r in range(n_rows):
        vals[r] = cp
        if col_of[r] >= 0:
            for q in range(off[r], off[r + 1]):
                if col[q] == col_of[r]:
                    vals[r] = cst[q]
                    break


@njit(cache=True)
def _dense_assignment(near_a, near_b, cost, n_near, m, n, gsel, esel, mask_g, mask_e, far, vals):  # pragma: no cover
    """``vals[r]``: the cost of row r of the smaller side in a minimum-cost assignment of the window's (m, n) cost
    matrix (:func:`soabench.metrics_kernels.assignment`): ``far`` of the count of scans where either exists for a
    pair never closer than c, ``cost`` for the near ones (``near_a``, ``near_b``)."""
    rows_are_g = m <= n
    Cm = np.empty((m, n) if rows_are_g else (n, m))
    for a in range(m):
        mg = mask_g[gsel[a]]
        for b in range(n):
            d = far[_union_count(mg, mask_e[esel[b]])]
            if rows_are_g:
                Cm[a, b] = d
            else:
                Cm[b, a] = d
    for q in range(n_near):
        a, b = near_a[q], near_b[q]
        if rows_are_g:
            Cm[a, b] = cost[q]
        else:
            Cm[b, a] = cost[q]
    rows, cols = assignment(Cm)
    for r in range(len(rows)):
        vals[r] = Cm[rows[r], cols[r]]


@njit(cache=True)
def _scan_events(g_ids, g_off, gx, e_ids, e_off, ex, c):  # pragma: no cover - compiled
    """The pairs closer than ``c`` of every scan (:func:`_near_events`), scan k's from ``ev_off[k]`` on."""
    K = len(g_off) - 1
    ev_i = np.empty(64, dtype=np.int64)
    ev_j = np.empty(64, dtype=np.int64)
    ev_d = np.empty(64)
    ev_off = np.zeros(K + 1, dtype=np.int64)
    n_ev = np.int64(0)  # not the literal 0: one specialisation of _near_events
    for k in range(K):
        ev_i, ev_j, ev_d, n_ev = _near_events(
            g_ids, g_off[k], g_off[k + 1] - g_off[k], gx, e_ids, e_off[k], e_off[k + 1] - e_off[k], ex, c,
            ev_i, ev_j, ev_d, n_ev,
        )  # fmt: skip
        ev_off[k + 1] = n_ev
    return ev_i, ev_j, ev_d, ev_off


@njit(cache=True)
def _event_links(ev_i, ev_j, ev_off, n_g, n_e):  # pragma: no cover - compiled
    """Per near event (:func:`_scan_events`): its scan, and the previous and the next event of the same pair
    (truth id, estimate id), -1 where there is none. The events are grouped by estimate id in event order (a stable
    counting sort), so each pair's events meet in scan order with one mark per truth id."""
    n_ev = ev_off[-1]
    ev_t = np.empty(n_ev, dtype=np.int64)
    for k in range(len(ev_off) - 1):
        for e in range(ev_off[k], ev_off[k + 1]):
            ev_t[e] = k
    start = np.zeros(n_e + 1, dtype=np.int64)
    for e in range(n_ev):
        start[ev_j[e] + 1] += 1
    for j in range(n_e):
        start[j + 1] += start[j]
    fill = start[:-1].copy()
    by_j = np.empty(n_ev, dtype=np.int64)
    for e in range(n_ev):
        by_j[fill[ev_j[e]]] = e
        fill[ev_j[e]] += 1
    prev = np.full(n_ev, -1, dtype=np.int64)
    nxt = np.full(n_ev, -1, dtype=np.int64)
    last = np.empty(n_g, dtype=np.int64)  # per truth id: its latest event with the estimate id at hand
    mark = np.full(n_g, -1, dtype=np.int64)  # per truth id: the estimate id ``last`` belongs to
    for j in range(n_e):
        for q in range(start[j], start[j + 1]):
            e = by_j[q]
            i = ev_i[e]
            if mark[i] == j:
                prev[e] = last[i]
                nxt[last[i]] = e
            mark[i] = j
            last[i] = e
    return ev_t, prev, nxt


@njit(cache=True)
def ospa2_scans(g_ids, g_off, gx, n_g, e_ids, e_off, ex, n_e, c, p, window):  # pragma: no cover - compiled
    """(K, 3) OSPA(2) per scan (total, localisation, cardinality) of stacked truth and estimate rows (ids 0..n_g - 1
    and 0..n_e - 1, scan k's rows ``off[k]:off[k + 1]``; :func:`soabench.tracks.ospa2.ospa2_of`).

    The base distance of a pair is ``min(c, total / count)`` with total the in-order sum over the window's scans
    where either track exists of ``min(c, |x(t) - y(t)|)`` (both exist) or ``c``. A pair never closer than c in the
    window adds c at each such scan, so its total is c added ``count`` times, with ``count`` the set bits of the two
    tracks' presence masks over the window; only the pairs closer than c at some scan of the window are summed. The
    pairs closer than c are listed once per run as events (scan, truth, estimate, distance) linked to the same
    pair's previous and next events (:func:`_event_links`): a window's pairs are its events that have no earlier one
    in the window, in event order, and each pair's sum follows its links. Before its first near scan a pair adds
    only c, so that part of the sum is read from a table of c added n times (n: the set bits of its presence masks
    before that scan; a window of at most 64 scans fits one mask word). Where c added n times and divided by n
    is c for every n <= window (c = 10), every other pair costs ``c ** p``, the largest cost, and the assignment
    needs only the near pairs (:func:`_near_assignment`); otherwise the dense cost matrix, entry for entry the one
    of summing every pair, is assigned (:func:`_dense_assignment`)."""
    K = len(g_off) - 1
    out = np.zeros((K, 3))
    n_words = (window + 63) // 64
    ring = 64 * n_words
    mask_g = np.zeros((n_g, n_words), dtype=np.uint64)
    mask_e = np.zeros((n_e, n_words), dtype=np.uint64)
    far = np.zeros(window + 1)  # far[n]: the base distance ** p of a pair that adds c at n scans
    c_times = np.zeros(window + 1)  # c_times[n]: c added n times from 0.0
    total = 0.0
    for n in range(1, window + 1):
        total += c
        c_times[n] = total
        far[n] = min(total / n, c) ** p
    far_is_cp = np.all(far[1:] == far[1])
    stamp_g = np.full(n_g, -1, dtype=np.int64)
    stamp_e = np.full(n_e, -1, dtype=np.int64)
    gsel = np.empty(n_g, dtype=np.int64)
    esel = np.empty(n_e, dtype=np.int64)
    loc_g = np.zeros(n_g, dtype=np.int64)
    loc_e = np.zeros(n_e, dtype=np.int64)
    ev_i, ev_j, ev_d, ev_off = _scan_events(g_ids, g_off, gx, e_ids, e_off, ex, c)
    ev_t, prev, nxt = _event_links(ev_i, ev_j, ev_off, n_g, n_e)
    # every buffer of the window loop at its largest size first (none replaced inside the loop)
    max_small, max_ev = 0, 0
    for k in range(K):
        lo = max(0, k - window + 1)
        m = _window_tracks(g_ids, g_off, lo, k, stamp_g, gsel)
        n = _window_tracks(e_ids, e_off, lo, k, stamp_e, esel)
        max_small = max(max_small, min(m, n))
        max_ev = max(max_ev, ev_off[k + 1] - ev_off[lo])
    for i in range(n_g):
        stamp_g[i] = -1
    for j in range(n_e):
        stamp_e[j] = -1
    near_a = np.empty(max_ev, dtype=np.int64)
    near_b = np.empty(max_ev, dtype=np.int64)
    near_cost = np.empty(max_ev)
    vals = np.empty(max_small)
    word = np.empty(window, dtype=np.int64)  # per scan of the window: its mask word and bit
    bits = np.empty(window, dtype=np.uint64)
    for k in range(K):
        lo = max(0, k - window + 1)
        if k >= window:  # scan k - window leaves the window
            s = (k - window) % ring
            bit = np.uint64(1) << np.uint64(s % 64)
            for r in range(g_off[k - window], g_off[k - window + 1]):
                mask_g[g_ids[r], s // 64] &= ~bit
            for r in range(e_off[k - window], e_off[k - window + 1]):
                mask_e[e_ids[r], s // 64] &= ~bit
        s = k % ring
        bit = np.uint64(1) << np.uint64(s % 64)
        for r in range(g_off[k], g_off[k + 1]):
            mask_g[g_ids[r], s // 64] |= bit
        for r in range(e_off[k], e_off[k + 1]):
            mask_e[e_ids[r], s // 64] |= bit
        m = _window_tracks(g_ids, g_off, lo, k, stamp_g, gsel)
        n = _window_tracks(e_ids, e_off, lo, k, stamp_e, esel)
        small, large = min(m, n), max(m, n)
        if large == 0:
            continue
        card_p = c**p * (large - small) / large
        loc_p = 0.0
        if small > 0:
            for a in range(m):
                loc_g[gsel[a]] = a
            for b in range(n):
                loc_e[esel[b]] = b
            for t in range(lo, k + 1):
                s = t % ring
                word[t - lo] = s // 64
                bits[t - lo] = np.uint64(1) << np.uint64(s % 64)
            # each pair closer than c somewhere in the window, at its first event there (in event order): in order
            # over the scans where either exists, its distance where near (its next events), else c
            first = ev_off[lo]
            rot = np.uint64(lo % 64)
            in_window = (np.uint64(1) << np.uint64(k + 1 - lo)) - np.uint64(1) if k + 1 - lo < 64 else ~np.uint64(0)
            n_near = 0
            for e in range(first, ev_off[k + 1]):
                if prev[e] >= first:
                    continue
                i, j = ev_i[e], ev_j[e]
                near_a[n_near], near_b[n_near] = loc_g[i], loc_e[j]
                t0 = ev_t[e] - lo
                f, t_near = e, t0
                if n_words == 1:  # the window's presence bits rotated to bit t = scan lo + t
                    u = mask_g[i, 0] | mask_e[j, 0]
                    u = ((u >> rot) | (u << (np.uint64(64) - rot))) & in_window if rot else u & in_window
                    count = _popcount(u & ((np.uint64(1) << np.uint64(t0)) - np.uint64(1)))
                    total = c_times[count]
                    for t in range(t0, k + 1 - lo):
                        if (u >> np.uint64(t)) & np.uint64(1):
                            if t == t_near:
                                total += ev_d[f]
                                f = nxt[f]
                                t_near = ev_t[f] - lo if f >= 0 else -1
                            else:
                                total += c
                            count += 1
                else:
                    total, count = 0.0, 0
                    for t in range(k + 1 - lo):
                        if ((mask_g[i, word[t]] | mask_e[j, word[t]]) & bits[t]) != 0:
                            if t == t_near:
                                total += ev_d[f]
                                f = nxt[f]
                                t_near = ev_t[f] - lo if f >= 0 else -1
                            else:
                                total += c
                            count += 1
                d = min(total / count, c)
                near_cost[n_near] = d if p == 1.0 else d**p  # x ** 1.0 is x
                n_near += 1
            if far_is_cp:
                _near_assignment(near_a, near_b, near_cost, n_near, m, n, far[1], vals)
            else:
                _dense_assignment(near_a, near_b, near_cost, n_near, m, n, gsel, esel, mask_g, mask_e, far, vals)
            loc_p = np_sum(vals, small) / large
        out[k, 0] = (loc_p + card_p) ** (1.0 / p)
        out[k, 1] = loc_p ** (1.0 / p)
        out[k, 2] = card_p ** (1.0 / p)
    return out
