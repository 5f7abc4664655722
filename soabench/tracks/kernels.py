"""Compiled scan loops of the track metrics (docs/method.md §9.3).

* :func:`match_scans`: HOTA's alignment-weighted matching and CLEAR MOT's continuity-first matching of every scan,
  in scan order (CLEAR carries the previous scan's matches forward);
* :func:`ospa2_scans`: OSPA(2) of every sliding window.

Each assignment is the minimum-cost one of :func:`soabench.metrics_kernels.assignment` on the cost matrices that
TrackEval and :func:`soabench.metrics.ospa` build, with the same floating-point operations (IEEE double, no
``fastmath``). An optimal assignment is unique unless two have the same cost; :func:`match_scans` stops at a scan
whose cost matrix has two equal rows or columns (two equal positions that the labels do not tell apart) so that the
caller matches it with scipy, as TrackEval does.
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
    operations of :func:`soabench.tracks.sequence.similarity`."""
    S = np.empty((ng, ne))
    for i in range(ng):
        for j in range(ne):
            dx = gx[g0 + i, 0] - ex[e0 + j, 0]
            dy = gx[g0 + i, 1] - ex[e0 + j, 1]
            S[i, j] = max(0.0, 1.0 - math.sqrt(dx * dx + dy * dy) / (2.0 * d_gate))
    return S


@njit(cache=True)
def _equal_rows(C):  # pragma: no cover - compiled
    """True if two rows of ``C`` are equal and not all zero."""
    a, b = C.shape
    for i in range(a):
        for j in range(i + 1, a):
            same, nonzero = True, False
            for c in range(b):
                same = same and C[i, c] == C[j, c]
                nonzero = nonzero or C[i, c] != 0.0
            if same and nonzero:
                return True
    return False


@njit(cache=True)
def _tied(C):  # pragma: no cover - compiled
    """True if two rows or two columns of ``C`` are equal and not all zero: then several assignments are optimal
    and which one is taken can change the matches (a zero row or column is never a kept match)."""
    return _equal_rows(C) or _equal_rows(np.ascontiguousarray(C.T))


@njit(cache=True)
def match_scans(t, g_ids, g_off, gx, e_ids, e_off, ex, d_gate, threshold, alignment, state):  # pragma: no cover
    """Scans t, t + 1, ... of :func:`soabench.tracks.scores._scan_matches` until the end or a scan whose matching
    has several optimal answers (:func:`_tied`); returns the index of that scan (K at the end).

    ``state`` is :class:`soabench.tracks.scores._MatchState`'s arrays in order: counts (tp, fn, fp, idsw, n_pairs),
    motp_sum (1,), gt_seen, gt_matched, frag_count, prev_id, prev_scan_id, and HOTA's pairs hg, he, hs.
    """
    counts, motp, gt_seen, gt_matched, frag, prev_id, prev_scan, hg, he, hs = state
    K = len(g_off) - 1
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
                    C[i, j] = -(alignment[g_ids[g0 + i], e_ids[e0 + j]] * S[i, j])
                    score = (1000.0 if e_ids[e0 + j] == prev_scan[g_ids[g0 + i]] else 0.0) + S[i, j]
                    Q[i, j] = 0.0 if S[i, j] < threshold - _EPS else -score
            if _tied(C) or _tied(Q):
                return t
            rows, cols = assignment(C)
            n = counts[4]
            for r in range(len(rows)):
                hg[n + r] = g_ids[g0 + rows[r]]
                he[n + r] = e_ids[e0 + cols[r]]
                hs[n + r] = S[rows[r], cols[r]]
            counts[4] = n + len(rows)
            rows, cols = assignment(Q)
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
    return t


@njit(cache=True)
def ospa2_scans(G, E, c, p, window):  # pragma: no cover - compiled
    """(K, 3) OSPA(2) per scan (total, localisation, cardinality) from dense (K, n, 2) track positions, NaN where a
    track does not exist (:func:`soabench.tracks.ospa2.ospa2_of`)."""
    K = G.shape[0]
    out = np.zeros((K, 3))
    g_on = ~np.isnan(G[:, :, 0])
    e_on = ~np.isnan(E[:, :, 0])
    gsel = np.empty(G.shape[1], dtype=np.int64)
    esel = np.empty(E.shape[1], dtype=np.int64)
    for k in range(K):
        lo = max(0, k - window + 1)
        m = 0
        for i in range(G.shape[1]):
            if g_on[lo : k + 1, i].any():
                gsel[m] = i
                m += 1
        n = 0
        for j in range(E.shape[1]):
            if e_on[lo : k + 1, j].any():
                esel[n] = j
                n += 1
        small, large = min(m, n), max(m, n)
        if large == 0:
            continue
        card_p = c**p * (large - small) / large
        loc_p = 0.0
        if small > 0:
            Cm = np.empty((small, large))
            for a in range(m):
                for b in range(n):
                    i, j = gsel[a], esel[b]
                    total, count = 0.0, 0
                    for t in range(lo, k + 1):
                        if g_on[t, i] and e_on[t, j]:
                            dx = G[t, i, 0] - E[t, j, 0]
                            dy = G[t, i, 1] - E[t, j, 1]
                            total += min(c, math.sqrt(dx * dx + dy * dy))
                            count += 1
                        elif g_on[t, i] or e_on[t, j]:
                            total += c
                            count += 1
                    d = min(total / count, c) ** p
                    if m <= n:
                        Cm[a, b] = d
                    else:
                        Cm[b, a] = d
            rows, cols = assignment(Cm)
            vals = np.empty(small)
            for r in range(small):
                vals[r] = Cm[rows[r], cols[r]]
            loc_p = np_sum(vals, small) / large
        out[k, 0] = (loc_p + card_p) ** (1.0 / p)
        out[k, 1] = loc_p ** (1.0 / p)
        out[k, 2] = card_p ** (1.0 / p)
    return out
