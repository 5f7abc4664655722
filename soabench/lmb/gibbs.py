"""Association of tracks and measurements: exact marginals (enumeration or a forward-backward pass) or Gibbs
sampling of Vo, Vo & Hoang (2017) (docs/method.md "LMB filter", association).

Track i has one association variable theta_i in {absent, missed, measurement j}. Its log cost row is
``logc[i] = [log eta_i(absent), log eta_i(missed), log eta_i(z_1) ... log eta_i(z_M)]`` (-inf where the option is
impossible, e.g. a measurement outside the gate), and a joint association (distinct measurements) has weight
prod_i eta_i(theta_i). The kernels return the marginal association probabilities
``marg[i, c] = sum_theta w(theta) 1[theta_i = c]``.

* Existence is marginalised in closed form. A track that takes no measurement is absent or present and missed; in
  every joint association those two alternatives of the track add, whatever the other tracks do, so the
  association hypotheses are the maps theta of measurements to tracks (each track one measurement or none,
  measurements distinct) with the weight prod_i eta_i(theta_i) where eta_i(none) = eta_i(absent) + eta_i(missed),
  and P(absent) = P(none) eta_i(absent) / eta_i(none), P(missed) = P(none) eta_i(missed) / eta_i(none) exactly.
  A cluster's valid hypotheses are counted over theta alone (n tracks sharing one measurement: n + 1, not
  2^(n - 1) (n + 2)).
* Tracks that share no measurement are independent (the weight factorises), so the tracks are split into clusters
  (connected by a measurement both may take) and each cluster is solved alone: a track with no measurement in its
  gate has the closed form marg = (eta_absent, eta_missed) / sum.
* A cluster whose valid hypotheses number at most ``max_hyp`` gets its exact marginals (docs/method.md "LMB
  filter", association). With at most ``DP_MAX_M`` measurements the hypotheses are counted and the marginals
  summed by a forward-backward pass over the cluster's tracks whose state is the set of measurements already
  taken (:func:`_count_dp`, :func:`_marginals_dp`: O(n 2^m m), no hypothesis listed); with more, a depth-first
  enumeration lists them and stops at ``max_hyp`` + 1 (:func:`_enumerate_valid`). Both are exact; they differ only
  in the order of the sums.
* A larger cluster runs the Gibbs sampler of Vo, Vo & Hoang (2017, Algorithm 1 with every track starting without a
  measurement, as in Vo's toolbox) over theta: ``max_hyp`` sweeps, each redrawing every theta_i from its
  conditional given the others (measurements held by the others locked out); the distinct hypotheses visited are
  weighted exactly.

Randomness: a SplitMix64 stream (Steele, Lea & Flood 2014) private to each call, started from ``seed`` (drawn by
the filter from the trial's association stream, :mod:`soabench.seeding`): no global generator state, so a run is
bit-identical whatever ran before it, in any process or thread.
"""

from __future__ import annotations

import math

import numpy as np

from soabench.cache import configure_numba_cache

configure_numba_cache()

from llvmlite import ir  # noqa: E402
from numba import njit, types  # noqa: E402
from numba.extending import intrinsic  # noqa: E402

ABSENT, MISSED = 0, 1  #: the first two columns of a cost row; measurement j is column 2 + j
NONE = 0  #: the first column of a cluster's reduced row (absent or missed); measurement j is column 1 + j
DP_MAX_M = 10  #: clusters with at most this many measurements are counted and solved by the forward-backward pass


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


@njit(cache=True)
def _uniform(state):
    """The next uniform in [0, 1) of the SplitMix64 stream ``state`` (a (1,) uint64 array, advanced in place)."""
    state[0] += _GOLDEN
    return _unit(state[0])


@njit(cache=True)
def _unit(z):
    """The uniform in [0, 1) of the SplitMix64 state ``z``, already advanced: :func:`_uniform` on a state the sampler
    keeps in a local variable during its sweeps."""
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@intrinsic
def _trailing_zeros(typingctx, x):  # pragma: no cover - compiled
    """The index of the lowest set bit of the uint64 ``x`` (``x`` != 0), LLVM's ``cttz``: how the sampler walks a
    bit mask of measurements."""
    sig = types.int64(types.uint64)

    def codegen(context, builder, signature, args):
        return builder.cttz(args[0], ir.Constant(ir.IntType(1), 1))

    return sig, codegen


@njit(cache=True)
def _find(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True)
def _log_weight(logc, theta):
    s = 0.0
    for i in range(theta.shape[0]):
        s += logc[i, theta[i]]
    return s


@njit(cache=True)
def _accumulate(logc, hyps, n_hyp, marg_out, rows):
    """Add the normalised weights of hypotheses ``hyps[:n_hyp]`` to the marginals of ``rows``."""
    n = logc.shape[0]
    lw = np.empty(n_hyp)
    h = 0
    while h + 4 <= n_hyp:  # four hypotheses at a time, each summed over its tracks in order as _log_weight sums
        s0 = s1 = s2 = s3 = 0.0
        for i in range(n):
            s0 += logc[i, hyps[h, i]]
            s1 += logc[i, hyps[h + 1, i]]
            s2 += logc[i, hyps[h + 2, i]]
            s3 += logc[i, hyps[h + 3, i]]
        lw[h], lw[h + 1], lw[h + 2], lw[h + 3] = s0, s1, s2, s3
        h += 4
    for g in range(h, n_hyp):
        lw[g] = _log_weight(logc, hyps[g])
    mx = -np.inf
    for h in range(n_hyp):
        if lw[h] > mx:
            mx = lw[h]
    if not mx > -np.inf:  # no hypothesis of positive weight (only if r = 1 and p_D = 1 leave a track no option)
        return
    tot = 0.0
    for h in range(n_hyp):
        lw[h] = math.exp(lw[h] - mx)
        tot += lw[h]
    for h in range(n_hyp):
        p = lw[h] / tot
        for i in range(n):
            marg_out[rows[i], hyps[h, i]] += p


@njit(cache=True)
def _enumerate_valid(options, n_opt, M, limit):
    """The valid associations theta (distinct measurements) depth first, track 0 varying fastest (the order of a
    mixed-radix count over the options; column 0 is "none", column 1 + j measurement j); stops once ``limit`` + 1
    are found. Returns (hyps, count) with count ``limit`` + 1 when there are more than ``limit``."""
    n = options.shape[0]
    cap = min(limit + 1, 1024)
    hyps = np.empty((cap, n), dtype=np.int64)
    theta = np.empty(n, dtype=np.int64)
    digit = np.zeros(n, dtype=np.int64)
    used = np.zeros(M, dtype=np.bool_)
    count = 0
    lvl = n - 1
    while True:
        if digit[lvl] == n_opt[lvl]:  # this level is exhausted: back up one level and advance it
            digit[lvl] = 0
            lvl += 1
            if lvl == n:
                break
            if theta[lvl] >= 1:
                used[theta[lvl] - 1] = False
            digit[lvl] += 1
            continue
        c = options[lvl, digit[lvl]]
        if c >= 1 and used[c - 1]:
            digit[lvl] += 1
            continue
        theta[lvl] = c
        if lvl == 0:
            if count == cap:
                grown = np.empty((min(2 * cap, limit + 1), n), dtype=np.int64)
                for h in range(cap):
                    for t in range(n):
                        grown[h, t] = hyps[h, t]
                hyps, cap = grown, grown.shape[0]
            for t in range(n):
                hyps[count, t] = theta[t]
            count += 1
            if count > limit:
                break
            digit[0] += 1
            continue
        if c >= 1:
            used[c - 1] = True
        lvl -= 1
    return hyps, count


@njit(cache=True)
def _count_up_to_two(options, n_opt, M):
    """The number of valid associations theta in which at most two tracks take a measurement: 1 + sum_i a_i +
    sum_{i<k} (a_i a_k - |S_i & S_k|), with S_i the a_i measurements track i may take; sum_{i<k} |S_i & S_k| is
    sum_j d_j (d_j - 1) / 2 over the d_j tracks that may take z_j. A lower bound of the count, in O(n + M): when it
    exceeds ``max_hyp`` the enumeration need not run."""
    deg = np.zeros(M, dtype=np.int64)
    A = 0
    A2 = 0
    for i in range(options.shape[0]):
        a = 0
        for o in range(n_opt[i]):
            if options[i, o] >= 1:
                a += 1
                deg[options[i, o] - 1] += 1
        A += a
        A2 += a * a
    shared = 0
    for j in range(M):
        shared += deg[j] * (deg[j] - 1) // 2
    return 1 + A + (A * A - A2) // 2 - shared


@njit(cache=True)
def _count_dp(options, n_opt, M, limit):
    """The number of valid associations theta of a cluster with ``M`` measurements (``M`` <= ``DP_MAX_M``),
    counted track by track over the set S of measurements taken so far: count_{i+1}(S) = count_i(S) [none open] +
    sum_{j in S, j open to i} count_i(S - {j}); each count saturates at ``limit`` + 1 (an exact answer up to
    ``limit``, "more" beyond)."""
    n_states = 1 << M
    cap = limit + 1
    cnt = np.zeros(n_states, dtype=np.int64)
    new = np.empty(n_states, dtype=np.int64)
    cnt[0] = 1
    for i in range(options.shape[0]):
        new[:] = 0
        for o in range(n_opt[i]):
            c = options[i, o]
            if c == NONE:
                for S in range(n_states):
                    new[S] += cnt[S]
            else:
                b = 1 << (c - 1)
                for S in range(n_states):
                    if S & b:
                        new[S] += cnt[S ^ b]
        for S in range(n_states):
            cnt[S] = min(new[S], cap)
    total = 0
    for S in range(n_states):
        total = min(total + cnt[S], cap)
    return total


@njit(cache=True)
def _marginals_dp(sub, options, n_opt, M):
    """Exact marginals (n, 1 + M) of a cluster's reduced rows ``sub`` (log weights; column 0 none, 1 + j
    measurement j) by a forward-backward pass over its tracks, the state being the set S of measurements taken:

        B_i(S) = sum of prod_{t >= i} eta_t(theta_t) over the associations of tracks i.. that avoid S
        F_i(S) = sum of prod_{t < i} eta_t(theta_t) over the associations of tracks ..i-1 that take exactly S
        P(theta_i = c) prop. to sum_S F_i(S) eta_i(c) B_{i+1}(S + {c})   (c none or a measurement not in S)

    Each track's weights are scaled by the largest of its row, and F_i and B_i by their largest entry: the
    constants cancel when each track's marginals are normalised to sum to 1. Cost O(n 2^M (options per track))."""
    n = sub.shape[0]
    n_states = 1 << M
    w = np.zeros((n, 1 + M))
    for i in range(n):
        mx = -np.inf
        for o in range(n_opt[i]):
            mx = max(mx, sub[i, options[i, o]])
        if mx > -np.inf:
            for o in range(n_opt[i]):
                w[i, options[i, o]] = math.exp(sub[i, options[i, o]] - mx)
    B = np.empty((n + 1, n_states))
    B[n, :] = 1.0
    for i in range(n - 1, -1, -1):
        mx = 0.0
        for S in range(n_states):
            v = w[i, NONE] * B[i + 1, S]
            for o in range(n_opt[i]):
                c = options[i, o]
                if c >= 1:
                    b = 1 << (c - 1)
                    if not S & b:
                        v += w[i, c] * B[i + 1, S | b]
            B[i, S] = v
            mx = max(mx, v)
        if mx > 0.0:
            for S in range(n_states):
                B[i, S] /= mx
    local = np.zeros((n, 1 + M))
    F = np.zeros(n_states)
    Fn = np.empty(n_states)
    F[0] = 1.0
    for i in range(n):
        for S in range(n_states):
            f = F[S]
            if f > 0.0:
                local[i, NONE] += f * w[i, NONE] * B[i + 1, S]
                for o in range(n_opt[i]):
                    c = options[i, o]
                    if c >= 1:
                        b = 1 << (c - 1)
                        if not S & b:
                            local[i, c] += f * w[i, c] * B[i + 1, S | b]
        tot = 0.0
        for c in range(1 + M):
            tot += local[i, c]
        if tot > 0.0:
            for c in range(1 + M):
                local[i, c] /= tot
        mx = 0.0
        for S in range(n_states):
            v = F[S] * w[i, NONE]
            for o in range(n_opt[i]):
                c = options[i, o]
                if c >= 1:
                    b = 1 << (c - 1)
                    if S & b:
                        v += F[S ^ b] * w[i, c]
            Fn[S] = v
            mx = max(mx, v)
        if mx > 0.0:
            for S in range(n_states):
                F[S] = Fn[S] / mx
    return local


@njit(cache=True)
def _gibbs(logc, options, n_opt, n_sweeps, state):
    """Distinct associations visited by ``n_sweeps`` Gibbs sweeps (the start included), in the order of their
    hashes. ``logc``: a cluster's reduced rows (column 0 none, 1 + j measurement j); ``options[i, :n_opt[i]]``: the
    columns of track i with a finite log cost.

    Each draw of theta_i takes one uniform u of the stream and compares u times the sum of the weights of the track's
    open options (those whose measurement no other track holds) with their running sums, in option order, taking the
    first option whose running sum exceeds it (the last open one if none does). How the open options are found
    depends on what the other tracks hold: none of the track's measurements (its precomputed running sums); all but
    the one it holds ("none" and that one); else the measurements no track holds, read off bit masks. Every case
    adds the same weights in the same order, so the draws are those of one pass over the options, bit for bit."""
    n, n_cols = logc.shape
    M = n_cols - 1
    weight = np.zeros(options.shape)
    for i in range(n):  # exp of each row once, shifted by its maximum (the conditionals are ratios within a row)
        mx = -np.inf
        for o in range(n_opt[i]):
            mx = max(mx, logc[i, options[i, o]])
        for o in range(n_opt[i]):
            weight[i, o] = math.exp(logc[i, options[i, o]] - mx)
    # running sums of each track's weights in option order: the draw's sums when no other track holds one of the
    # track's measurements
    prefix = np.zeros(options.shape)
    n_fixed = np.zeros(n, dtype=np.int64)  # "none" comes first in a track's options
    for i in range(n):
        acc = 0.0
        for o in range(n_opt[i]):
            acc += weight[i, o]
            prefix[i, o] = acc
            if options[i, o] < 1:
                n_fixed[i] += 1
    theta = np.zeros(n, dtype=np.int64)  # every track without a measurement
    wcol = np.zeros((n, n_cols))  # the weight of each column of a track (0 where it is no option): a mask draw reads
    # a measurement's weight straight from its bit
    for i in range(n):
        for o in range(n_opt[i]):
            wcol[i, options[i, o]] = weight[i, o]
    # Zobrist hash of each sample (a sum of one random 64-bit key per (track, option)), kept up to date as theta
    # changes: distinct hypotheses are found by sorting the hashes and comparing rows of equal hash exactly
    zkey = np.empty((n, n_cols), dtype=np.uint64)
    zstate = np.full(1, np.uint64(n * n_cols), dtype=np.uint64)
    for i in range(n):
        for c in range(n_cols):
            _uniform(zstate)
            zkey[i, c] = zstate[0] * _MIX1
    h = np.uint64(0)
    for i in range(n):
        h += zkey[i, theta[i]]
    # the tracks that may take each measurement, and for each track how many of its measurements another track
    # holds: while that count is 0 (the usual case) its draw needs no look at the others
    deg = np.zeros(M + 1, dtype=np.int64)
    for i in range(n):
        for o in range(n_fixed[i], n_opt[i]):
            deg[options[i, o]] += 1
    for j in range(M):
        deg[j + 1] += deg[j]
    takers = np.empty(deg[M], dtype=np.uint64)  # unsigned, as the loops over them: no negative-index wraparound
    fill = deg[:M].copy()
    for i in range(n):
        for o in range(n_fixed[i], n_opt[i]):
            j = options[i, o] - 1
            takers[fill[j]] = np.uint64(i)
            fill[j] += 1
    blocked = np.zeros(n, dtype=np.int64)
    W = (M + 63) >> 6
    gate = np.zeros((n, W), dtype=np.uint64)  # each track's gated measurements, as bits
    for i in range(n):
        for o in range(n_fixed[i], n_opt[i]):
            j = options[i, o] - 1
            gate[i, j >> 6] |= np.uint64(1) << np.uint64(j & 63)
    held = np.zeros(W, dtype=np.uint64)  # the measurements some track holds
    buf_w = np.empty(options.shape[1])
    buf_c = np.empty(options.shape[1], dtype=np.int64)
    # the samples, each stored only when its sweep changed the hypothesis: a repeat of the previous sample adds no
    # distinct hypothesis and would not change which one comes first among equal hashes. A sample is stored packed,
    # ``bits`` per track (theta_i < n_cols), ``per`` tracks a word: two samples are equal exactly when their words are
    # equal, and comparing the samples of equal hash takes a few words each instead of a row of n int64
    bits = 1
    while (1 << bits) < n_cols:
        bits += 1
    per = 64 // bits
    W2 = (n + per - 1) // per
    key = np.zeros(W2, dtype=np.uint64)  # the current theta, packed (every track without a measurement: all zero)
    word = np.empty(n, dtype=np.int64)  # track i's word and shift in a packed sample
    shift = np.empty(n, dtype=np.uint64)
    for i in range(n):
        word[i] = i // per
        shift[i] = np.uint64((i % per) * bits)
    samples = np.empty((n_sweeps, W2), dtype=np.uint64)
    hashes = np.empty(n_sweeps, dtype=np.uint64)
    for a in range(W2):
        samples[0, a] = key[a]
    hashes[0] = h
    n_st = 1
    st = state[0]  # the stream's state during the sweeps (stored back after them): each draw advances it by _GOLDEN
    for _sweep in range(1, n_sweeps):
        changed = False
        for i in range(n):
            if blocked[i] == 0:
                st += _GOLDEN
                u = _unit(st) * prefix[i, n_opt[i] - 1]
                c = -1
                for o in range(n_opt[i]):
                    if weight[i, o] > 0.0:
                        c = options[i, o]
                        if u < prefix[i, o]:
                            break
            else:
                own = 1 if theta[i] >= 1 else 0
                if n_fixed[i] == 1 and n_opt[i] - 1 - blocked[i] - own == 0:
                    # every measurement in the track's gate but the one it holds is held by another track: its open
                    # options are "none" and that measurement, if any
                    if own == 0:
                        st += _GOLDEN  # the uniform is drawn; with one option open it decides nothing
                        c = NONE if weight[i, 0] > 0.0 else -1
                    else:
                        w0 = weight[i, 0]
                        w1 = wcol[i, theta[i]]
                        st += _GOLDEN
                        u = _unit(st) * (w0 + w1)
                        c = NONE if w0 > 0.0 else -1
                        if not (w0 > 0.0 and u < w0) and w1 > 0.0:
                            c = theta[i]
                else:
                    # the open options: "none", the measurement it holds, and the gated measurements no track
                    # holds, in column order (the order of its options), read off the bit masks. buf_w keeps the
                    # running sum at each open option of positive weight: weights are >= 0, so adding a zero one
                    # leaves the sum as it was, and these are the sums a second pass over buf would reach (a NaN
                    # weight makes tot and u NaN, and every comparison below false, either way)
                    tot = 0.0
                    k = np.uint64(0)  # unsigned: no negative-index wraparound on buf
                    if n_fixed[i] == 1:
                        w = weight[i, 0]
                        tot += w
                        if w > 0.0:
                            buf_w[k] = tot
                            buf_c[k] = NONE
                            k += np.uint64(1)
                    for a in range(W):
                        x = gate[i, a] & ~held[a]
                        if own == 1 and ((theta[i] - 1) >> 6) == a:
                            x |= np.uint64(1) << np.uint64((theta[i] - 1) & 63)
                        while x != 0:
                            # an unsigned column: no negative-index wraparound in the innermost loop
                            cu = np.uint64(1 + (a << 6)) + np.uint64(_trailing_zeros(x))
                            x &= x - np.uint64(1)
                            w = wcol[i, cu]
                            c = np.int64(cu)
                            tot += w
                            if w > 0.0:
                                buf_w[k] = tot
                                buf_c[k] = c
                                k += np.uint64(1)
                    st += _GOLDEN
                    u = _unit(st) * tot
                    c = -1
                    q = np.uint64(0)
                    while q < k:
                        c = buf_c[q]
                        if u < buf_w[q]:
                            break
                        q += np.uint64(1)
            if c < 0:  # no option of positive weight (only when r = 1 and p_D = 1 leave the track none)
                c = theta[i]
            if c == theta[i]:
                continue
            changed = True
            if theta[i] >= 1:
                j = theta[i] - 1
                held[j >> 6] &= ~(np.uint64(1) << np.uint64(j & 63))
                tu = np.uint64(deg[j])
                te = np.uint64(deg[j + 1])
                while tu < te:  # every taker of z_j, i among them (i's own measurement does not block i: undone)
                    blocked[takers[tu]] -= 1
                    tu += np.uint64(1)
                blocked[i] += 1
            h += zkey[i, c] - zkey[i, theta[i]]
            key[word[i]] ^= np.uint64(theta[i] ^ c) << shift[i]
            theta[i] = c
            if c >= 1:
                j = c - 1
                held[j >> 6] |= np.uint64(1) << np.uint64(j & 63)
                tu = np.uint64(deg[j])
                te = np.uint64(deg[j + 1])
                while tu < te:
                    blocked[takers[tu]] += 1
                    tu += np.uint64(1)
                blocked[i] -= 1
        if changed:
            for a in range(W2):
                samples[n_st, a] = key[a]
            hashes[n_st] = h
            n_st += 1
    state[0] = st
    # the distinct samples in the order of their first visit, found with a table keyed by a hash of their words
    # (equal words, equal key; a hit is confirmed word by word), then ordered by their hashes h (a stable sort: the
    # first visited first among equal h). That is the order of a stable sort of every sample by h keeping the first
    # of each distinct one: the order in which the marginals add them up
    size = 1
    while size < 2 * n_st:
        size <<= 1
    table = np.full(size, -1, dtype=np.int64)
    first = np.empty(n_st, dtype=np.int64)  # the stored sample of each distinct hypothesis
    tag = np.empty(n_st, dtype=np.uint64)
    n_hyp = 0
    for s in range(n_st):
        g = np.uint64(0)
        for a in range(W2):
            g = (g ^ samples[s, a]) * _MIX1
            g ^= g >> np.uint64(29)
        slot = np.int64(g & np.uint64(size - 1))
        new = True
        while table[slot] >= 0:
            d = table[slot]
            if tag[d] == g:
                same = True
                f = first[d]
                for a in range(W2):
                    if samples[f, a] != samples[s, a]:
                        same = False
                        break
                if same:
                    new = False
                    break
            slot = (slot + 1) & (size - 1)
        if new:
            table[slot] = n_hyp
            first[n_hyp] = s
            tag[n_hyp] = g
            n_hyp += 1
    h_first = np.empty(n_hyp, dtype=np.uint64)
    for d in range(n_hyp):
        h_first[d] = hashes[first[d]]
    order = np.argsort(h_first, kind="mergesort")
    out = np.empty((n_hyp, n), dtype=np.int64)
    mask = np.uint64((1 << bits) - 1)
    for u in range(n_hyp):
        f = first[order[u]]
        for i in range(n):
            out[u, i] = np.int64((samples[f, word[i]] >> shift[i]) & mask)
    return out, n_hyp


@njit(cache=True)
def _split_none(a, b):
    """P(absent | none) and P(missed | none) from log eta(absent) = ``a`` and log eta(missed) = ``b``, and
    log eta(none) = log(eta(absent) + eta(missed)); (0, 1, -inf) when both are impossible."""
    mx = max(a, b)
    if not mx > -np.inf:
        return 0.0, 1.0, -np.inf
    ea, eb = math.exp(a - mx), math.exp(b - mx)
    return ea / (ea + eb), eb / (ea + eb), mx + math.log(ea + eb)


@njit(cache=True)
def association_marginals(logc, max_hyp, seed, force_gibbs=False, exact=False):
    """Marginal association probabilities ``marg`` (N, 2 + M) of the cost rows ``logc`` (module docstring), and
    the number of valid hypotheses weighted (summed over the clusters; a track alone counts 1; a cluster solved by
    the forward-backward pass beyond ``max_hyp`` counts ``max_hyp`` + 1) and of clusters solved by Gibbs sampling.

    ``force_gibbs``: sample every cluster with measurements, even one small enough to solve exactly (tests).
    ``exact``: solve every cluster of at most ``DP_MAX_M`` measurements by the forward-backward pass, however many
    hypotheses it has (``[lmb] association = "exact"``); the others as the default.
    """
    state = np.full(1, seed, dtype=np.uint64)
    N, n_cols = logc.shape
    M = n_cols - 2
    marg = np.zeros((N, n_cols))
    parent = np.arange(N)
    first = np.full(M, -1, dtype=np.int64)
    n_meas = np.zeros(N, dtype=np.int64)
    for i in range(N):
        for j in range(M):
            if logc[i, 2 + j] > -np.inf:
                n_meas[i] += 1
                if first[j] < 0:
                    first[j] = i
                else:
                    a, b = _find(parent, i), _find(parent, first[j])
                    if a != b:
                        parent[max(a, b)] = min(a, b)
    root = np.empty(N, dtype=np.int64)
    for i in range(N):
        root[i] = _find(parent, i)
    p_absent = np.empty(N)
    p_missed = np.empty(N)
    log_none = np.empty(N)
    for i in range(N):
        p_absent[i], p_missed[i], log_none[i] = _split_none(logc[i, ABSENT], logc[i, MISSED])
    total_hyp = 0
    n_gibbs = 0
    for i in range(N):
        if n_meas[i] == 0:  # absent or missed: closed form
            marg[i, ABSENT], marg[i, MISSED] = p_absent[i], p_missed[i]  # r = 1, p_D = 1, no measurement: kept
            total_hyp += 1
            continue
        if root[i] != i:
            continue
        rows_l = [r for r in range(N) if root[r] == i]
        rows = np.array(rows_l, dtype=np.int64)
        cols_l = [j for j in range(M) if first[j] >= 0 and root[first[j]] == i]
        cols = np.array(cols_l, dtype=np.int64)
        n, mc = rows.shape[0], cols.shape[0]
        sub = np.empty((n, 1 + mc))
        options = np.empty((n, 1 + mc), dtype=np.int64)
        n_opt = np.zeros(n, dtype=np.int64)
        for a in range(n):
            sub[a, NONE] = log_none[rows[a]]
            for j in range(mc):
                sub[a, 1 + j] = logc[rows[a], 2 + cols[j]]
            for c in range(1 + mc):
                if sub[a, c] > -np.inf:
                    options[a, n_opt[a]] = c
                    n_opt[a] += 1
        local = np.zeros((n, 1 + mc))
        n_hyp = max_hyp + 1
        solved = False
        if not force_gibbs:
            if mc <= DP_MAX_M:
                n_hyp = _count_dp(options, n_opt, mc, max_hyp)
                if n_hyp <= max_hyp or exact:
                    local = _marginals_dp(sub, options, n_opt, mc)
                    solved = True
            elif _count_up_to_two(options, n_opt, mc) <= max_hyp:  # else certainly more than max_hyp
                hyps, n_hyp = _enumerate_valid(options, n_opt, mc, max_hyp)
                if n_hyp <= max_hyp:
                    _accumulate(sub, hyps, n_hyp, local, np.arange(n))
                    solved = True
        if not solved:
            hyps, n_hyp = _gibbs(sub, options, n_opt, max_hyp, state)
            n_gibbs += 1
            _accumulate(sub, hyps, n_hyp, local, np.arange(n))
        for a in range(n):
            r = rows[a]
            marg[r, ABSENT] = local[a, NONE] * p_absent[r]
            marg[r, MISSED] = local[a, NONE] * p_missed[r]
            for j in range(mc):
                marg[r, 2 + cols[j]] = local[a, 1 + j]
        total_hyp += n_hyp
    return marg, total_hyp, n_gibbs
