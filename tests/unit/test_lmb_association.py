"""LMB association with existence summed out (docs/method.md "LMB filter", association): the marginals over the
maps of measurements to tracks equal those over every (absent | missed | measurement) combination, the
forward-backward pass equals explicit enumeration, and hypotheses are counted over the maps alone."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from soabench.config import Config
from soabench.errors import SoabenchError
from soabench.lmb.gibbs import (
    _GOLDEN,
    _MIX1,
    DP_MAX_M,
    _accumulate,
    _count_dp,
    _count_up_to_two,
    _enumerate_valid,
    _gibbs,
    _marginals_dp,
    _uniform,
    association_marginals,
)


def _brute_force(logc):
    """Marginals (N, 2 + M) over every combination of (absent, missed, measurement j) per track with distinct
    measurements: the association space before existence is summed out, written apart from the kernels."""
    marg = np.zeros_like(logc)
    total = 0.0
    for theta in itertools.product(*[np.flatnonzero(np.isfinite(row)) for row in logc]):
        meas = [c for c in theta if c >= 2]
        if len(meas) != len(set(meas)):
            continue
        w = math.exp(sum(logc[i, c] for i, c in enumerate(theta)))
        total += w
        for i, c in enumerate(theta):
            marg[i, c] += w
    return marg / total


def _random_costs(rng, n, M, p_gate=0.5, p_no_absent=0.2):
    """Random cost rows: absent impossible (r = 1) for some tracks, each measurement gated with ``p_gate``."""
    logc = np.log(rng.uniform(0.01, 1.0, (n, 2 + M)))
    logc[rng.uniform(size=n) < p_no_absent, 0] = -np.inf
    logc[:, 2:][rng.uniform(size=(n, M)) >= p_gate] = -np.inf
    return logc


def _reduced(logc):
    """A cluster's reduced rows (column 0 none = log(eta_absent + eta_missed), 1 + j measurement j) and options."""
    sub = np.concatenate([np.logaddexp(logc[:, :1], logc[:, 1:2]), logc[:, 2:]], axis=1)
    return (sub, *_options(sub))


def _options(sub):
    """Each row's finite columns, left-packed (options), and their count (n_opt)."""
    options = np.zeros(sub.shape, dtype=np.int64)
    n_opt = np.zeros(len(sub), dtype=np.int64)
    for i in range(len(sub)):
        cols = np.flatnonzero(np.isfinite(sub[i]))
        options[i, : len(cols)] = cols
        n_opt[i] = len(cols)
    return options, n_opt


@pytest.mark.parametrize("seed", range(8))
def test_existence_summed_out_gives_the_marginals_of_every_absent_missed_combination(seed):
    rng = np.random.default_rng(seed)
    logc = _random_costs(rng, int(rng.integers(1, 7)), int(rng.integers(1, 5)))
    marg, _, n_gibbs = association_marginals(logc, 1000, np.uint32(seed), False)
    assert n_gibbs == 0
    np.testing.assert_allclose(marg, _brute_force(logc), rtol=0, atol=1e-14)
    np.testing.assert_allclose(marg.sum(axis=1), 1.0, rtol=0, atol=1e-14)


@pytest.mark.parametrize("seed", range(10))
def test_forward_backward_pass_equals_explicit_enumeration(seed):
    rng = np.random.default_rng(100 + seed)
    n, M = int(rng.integers(2, 12)), int(rng.integers(1, 7))
    logc = _random_costs(rng, n, M, p_gate=0.6)
    logc[int(rng.integers(n)), :2] = -np.inf  # one track with r = 1 and p_D = 1: it must take a measurement
    sub, options, n_opt = _reduced(logc)
    sub[:, 1:] += rng.uniform(-30.0, 30.0, (n, 1))  # rows of very different scale
    hyps, count = _enumerate_valid(options, n_opt, M, 10**6)
    assert _count_dp(options, n_opt, M, 10**6) == count
    ref = np.zeros_like(sub)
    _accumulate(sub, hyps, count, ref, np.arange(n))
    got = _marginals_dp(sub, options, n_opt, M)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-14)


def test_thirty_tracks_sharing_two_measurements_are_exact():
    """30 tracks that all gate the same 2 measurements: 1 + 2·30 + 30·29 = 931 associations (2.7e11 counted with
    absent and missed apart), within max_hypotheses = 1000, so exact; their marginals equal a direct sum over the
    931 maps. With a third shared measurement the count passes 1000 and the cluster is sampled."""
    rng = np.random.default_rng(3)
    n = 30
    logc = np.log(rng.uniform(0.05, 1.0, (n, 4)))
    marg, n_hyp, n_gibbs = association_marginals(logc, 1000, np.uint32(0), False)
    assert (n_hyp, n_gibbs) == (931, 0)
    eta = np.exp(logc)
    none = eta[:, 0] + eta[:, 1]
    ref = np.zeros((n, 4))
    total = 0.0
    for a, b in itertools.product(range(-1, n), repeat=2):  # track taking z_1, track taking z_2 (-1: none)
        if a >= 0 and a == b:
            continue
        w = np.prod([eta[i, 2] if i == a else eta[i, 3] if i == b else none[i] for i in range(n)])
        total += w
        for i in range(n):
            if i == a:
                ref[i, 2] += w
            elif i == b:
                ref[i, 3] += w
            else:
                ref[i, :2] += w * eta[i, :2] / none[i]
    np.testing.assert_allclose(marg, ref / total, rtol=0, atol=1e-14)
    three = np.log(rng.uniform(0.05, 1.0, (n, 5)))
    _, n3, g3 = association_marginals(three, 1000, np.uint32(0), False)
    assert g3 == 1 and n3 <= 1000  # 1 + 90 + 2,610 + 24,360 associations: sampled


@pytest.mark.parametrize("seed", range(4))
def test_count_up_to_two_assignments_is_a_lower_bound_of_the_count(seed):
    """The closed-form count of the maps with at most two tracks taking a measurement equals a listing of them, and
    is at most the count of every map (what lets a cluster skip the enumeration when it already exceeds the limit)."""
    rng = np.random.default_rng(seed)
    n, M = 6, 5
    gated = rng.uniform(size=(n, M)) < 0.5
    options = np.zeros((n, 1 + M), dtype=np.int64)
    n_opt = np.zeros(n, dtype=np.int64)
    for i in range(n):
        cols = [0, *(1 + np.flatnonzero(gated[i]))]
        options[i, : len(cols)] = cols
        n_opt[i] = len(cols)
    maps = [t for t in itertools.product(*[options[i, : n_opt[i]] for i in range(n)])
            if len([c for c in t if c]) == len({c for c in t if c})]  # fmt: skip
    assert _count_up_to_two(options, n_opt, M) == sum(1 for t in maps if sum(c > 0 for c in t) <= 2)
    assert _count_up_to_two(options, n_opt, M) <= len(maps) == _count_dp(options, n_opt, M, 10**6)


def test_a_cluster_with_many_measurements_is_enumerated_depth_first():
    """One track gating DP_MAX_M + 2 measurements, a second one gating only the last of them: too many measurements
    for the forward-backward pass but 2 M + 1 associations (the second track without a measurement: the first has
    1 + M options; with z_M: M), so the depth-first enumeration solves it exactly."""
    M = DP_MAX_M + 2
    rng = np.random.default_rng(8)
    logc = np.log(rng.uniform(0.05, 1.0, (2, 2 + M)))
    logc[1, 2:-1] = -np.inf
    marg, n_hyp, n_gibbs = association_marginals(logc, 1000, np.uint32(0), False)
    assert n_gibbs == 0 and n_hyp == 2 * M + 1
    np.testing.assert_allclose(marg, _brute_force(logc), rtol=0, atol=1e-14)


def test_gibbs_over_associations_starts_without_measurements_and_visits_them_all():
    rng = np.random.default_rng(11)
    logc = _random_costs(rng, 5, 3, p_gate=0.8)
    exact, n_exact, _ = association_marginals(logc, 1000, np.uint32(0), False)
    sampled, n_sampled, g = association_marginals(logc, 4000, np.uint32(0), True)
    assert g == 1 and n_sampled == n_exact
    np.testing.assert_allclose(sampled, exact, rtol=0, atol=1e-12)
    _, n_one, _ = association_marginals(logc, 1, np.uint32(0), True)
    assert n_one == 1  # one sweep: the start only, every track without a measurement


def _gibbs_one_pass(sub, options, n_opt, n_sweeps, state):
    """The sampler written plainly, apart from the kernel: each draw passes over all the track's options, sums those
    whose measurement no other track holds, and compares one uniform of the same stream with the running sums.
    Returns the distinct hypotheses visited (tuples) in the order of their first visit; ``state`` is advanced as the
    kernel advances it."""
    n = sub.shape[0]
    weight = [[math.exp(sub[i, options[i, o]] - max(sub[i, options[i, :n_opt[i]]])) for o in range(n_opt[i])]
              for i in range(n)]  # fmt: skip
    theta = [0] * n
    seen = {tuple(theta): None}
    for _ in range(1, n_sweeps):
        for i in range(n):
            held = {theta[t] for t in range(n) if t != i and theta[t] >= 1}
            opened = [(options[i, o], weight[i][o]) for o in range(n_opt[i]) if options[i, o] not in held]
            u = _uniform(state) * sum(w for _, w in opened)  # the sum in option order, as float additions
            c, acc = -1, 0.0
            for col, w in opened:
                if w > 0.0:
                    c, acc = col, acc + w
                    if u < acc:
                        break
            theta[i] = theta[i] if c < 0 else c
        seen.setdefault(tuple(theta))
    return list(seen)


def _by_hash(hyps, n_cols):
    """``hyps`` (in the order of their first visit) in the order the kernel returns them: by the sum of the keys
    k(i, c) = (n n_cols + (1 + i n_cols + c) GOLDEN) MIX1 mod 2**64 of their (track, column) pairs, the first
    visited first among equal sums (the order in which the marginals add the hypotheses' weights)."""
    n, mod = len(hyps[0]), 2**64
    key = [[(n * n_cols + (1 + i * n_cols + c) * int(_GOLDEN)) % mod * int(_MIX1) % mod for c in range(n_cols)]
           for i in range(n)]  # fmt: skip
    return sorted(hyps, key=lambda row: sum(key[i][c] for i, c in enumerate(row)) % mod)


@pytest.mark.parametrize(("n", "M", "lo", "seed"), [(14, 6, 0, 0), (30, 12, 0, 1), (16, 70, 56, 2)])
def test_gibbs_draws_are_those_of_one_pass_over_the_options(n, M, lo, seed):
    """The kernel finds a track's open options by its running sums, by "none and its own measurement", or by bit
    masks of the measurements held (two 64-bit words when M = 70, the gated ones z_56..z_69 on both): each way must
    give the draws of the plain pass, the same hypotheses visited and the same number of uniforms drawn. The
    hypotheses come in the order of their hashes, the first visited first among equal hashes (the samples are
    stored packed, several tracks a word, and compared word by word: 3, 4 and 7 bits per track here, over 1 or 2
    words)."""
    rng = np.random.default_rng(seed)
    sub = np.full((n, 1 + M), -np.inf)
    sub[:, 0] = np.log(rng.uniform(0.05, 1.0, n))
    for i in range(n):  # a few gated measurements each, many shared, weights across several orders of magnitude
        cols = lo + rng.choice(M - lo, size=int(rng.integers(1, 6)), replace=False)
        sub[i, 1 + cols] = rng.normal(0.0, 3.0, len(cols))
    options, n_opt = _options(sub)
    s_kernel = np.full(1, np.uint64(seed + 7), dtype=np.uint64)
    s_plain = s_kernel.copy()
    hyps, n_hyp = _gibbs(sub, options, n_opt, 200, s_kernel)
    plain = _gibbs_one_pass(sub, options, n_opt, 200, s_plain)
    assert s_kernel[0] == s_plain[0]
    assert [tuple(int(c) for c in row) for row in hyps[:n_hyp]] == _by_hash(plain, 1 + M) and n_hyp > 20


def test_exact_association_solves_a_cluster_beyond_max_hypotheses():
    """``[lmb] association = "exact"``: 30 tracks sharing 3 measurements (27,061 associations, far above
    max_hypotheses = 1000) are solved by the forward-backward pass, equal to listing every association."""
    rng = np.random.default_rng(4)
    logc = np.log(rng.uniform(0.05, 1.0, (30, 5)))
    marg, n_hyp, n_gibbs = association_marginals(logc, 1000, np.uint32(0), False, True)
    assert n_gibbs == 0 and n_hyp == 1001  # counted up to max_hypotheses + 1, solved exactly all the same
    sub, options, n_opt = _reduced(logc)
    hyps, count = _enumerate_valid(options, n_opt, 3, 10**6)
    assert count == 1 + 3 * 30 + 3 * 30 * 29 + 30 * 29 * 28  # none, one, two or three measurements taken
    local = np.zeros_like(sub)
    _accumulate(sub, hyps, count, local, np.arange(30))
    split = np.exp(logc[:, :2] - np.logaddexp(logc[:, :1], logc[:, 1:2]))
    ref = np.concatenate([local[:, :1] * split, local[:, 1:]], axis=1)
    np.testing.assert_allclose(marg, ref, rtol=0, atol=1e-14)
    _, _, sampled = association_marginals(logc, 1000, np.uint32(0), False, False)
    assert sampled == 1  # the default samples it


def test_association_is_a_checked_lmb_key():
    experiment = {"filters": ["lmb"], "probabilities": ["static"]}
    assert Config.from_dict({"lmb": {"association": "exact"}, "experiment": experiment}).validate()
    with pytest.raises(SoabenchError, match="lmb.association = 'sampled' is not allowed; choose one of 'bounded', "):
        Config.from_dict({"lmb": {"association": "sampled"}, "experiment": experiment}).validate()
