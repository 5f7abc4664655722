"""The fair LMB (docs/method.md §10.7-10.8): T42 (birth components pooled per merge group; exact enumeration up to
``max_hypotheses`` valid hypotheses equals the exhaustive delta-GLMB), PUBM's own newborn weighting, the old mapping
as ``birth_mapping = "components"``, and the depth-first enumeration against a brute-force reference."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from test_lmb import EGO, _glmb_reference, _model, _random_case, _run, _scan, _track_means, _tracks_of, _walk_scans

from soabench.config import Config, FilterConfig, LMBConfig, Sensor
from soabench.errors import SoabenchError
from soabench.lmb import LMBFilter, label_pairs
from soabench.lmb.birth import EXPLAINED_TOL, adaptive_existence, group_birth, intensity_existence
from soabench.lmb.cycle import newborn_existence
from soabench.lmb.gibbs import _count_dp, _enumerate_valid, association_marginals
from soabench.lmb.update import update
from soabench.types import SOURCE_GM, Births, NewbornTerms

U = FilterConfig().merge_U


def _births(w, m, P=None):
    m = np.asarray(m, dtype=float)
    P = np.stack([np.diag([4.0, 4.0, 1.0, 1.0])] * len(w)) if P is None else P
    return Births(np.asarray(w, dtype=float), m, P, np.full(len(w), SOURCE_GM, dtype=np.int8))


def test_T42_components_at_one_point_make_one_bernoulli():
    t = group_birth(_births([0.2, 0.2], [[5.0, 1.0, 0, 0]] * 2), 3, 0.5, U, 10)
    assert len(t) == 1 and t.r.tolist() == [pytest.approx(0.4, abs=1e-15)]
    assert label_pairs(t.label).tolist() == [[3, 0]] and t.w.tolist() == [0.5, 0.5]
    far = group_birth(_births([0.2, 0.1], [[5.0, 1.0, 0, 0], [40.0, 1.0, 0, 0]]), 3, 0.5, U, 10)
    assert far.r.tolist() == [0.2, 0.1] and label_pairs(far.label).tolist() == [[3, 0], [3, 1]]
    capped = group_birth(_births([0.4, 0.3], [[5.0, 1.0, 0, 0]] * 2), 3, 0.5, U, 10)
    assert capped.r.tolist() == [0.5]  # min(sum w, r_B,max)


def test_group_density_keeps_the_heaviest_components_of_each_group():
    w = np.array([0.01, 0.05, 0.02, 0.04, 0.03, 0.3])
    m = np.array([[5.0 + 0.3 * i, 1.0, 0, 0] for i in range(5)] + [[60.0, 0, 0, 0]])
    t = group_birth(_births(w, m), 0, 0.5, U, 3)
    assert len(t) == 2 and t.r[0] == 0.3  # the heavier group first, as the merge creates it
    assert t.r[1] == pytest.approx(w[:5].sum(), abs=1e-15)  # the mass of the whole group, not only the kept three
    a, b = t.start[1], t.start[2]
    np.testing.assert_allclose(t.w[a:b], np.array([0.05, 0.04, 0.03]) / 0.12, rtol=1e-15)
    np.testing.assert_array_equal(t.m[a:b], m[[1, 3, 4]])
    assert group_birth(_births([0.0, 0.0], [[0.0] * 4] * 2), 0, 0.5, U, 3).r.size == 0  # no mass: no Bernoulli


def test_intensity_existence_is_the_share_of_the_birth_term():
    r_U, beta, kappa = np.array([0.0, 0.5, 1.0, 0.2]), np.array([1.0, 1.0, 1.0, 0.0]), np.array([1.0, 3.0, 1.0, 1.0])
    got = intensity_existence(r_U, beta, kappa, 0.5)
    np.testing.assert_allclose(got, [0.5, 0.5 * 0.25, 0.0, 0.0], rtol=1e-15)
    assert intensity_existence(np.zeros(1), np.array([2.0]), np.array([0.0]), 0.9).tolist() == [0.9]


def test_a_measurement_explained_to_the_last_bits_gives_no_birth():
    """1 - r_U at or below EXPLAINED_TOL counts as 0: the remainder rounding leaves where a track surely took z
    neither gives a Bernoulli of r ~ 1e-17 nor, when every measurement is explained, is normalised up by the
    adaptive rule; just above the tolerance the formulas are unchanged."""
    tol = EXPLAINED_TOL
    for r_U in (np.array([1.0, 1.0]), np.array([1.0 - 2.2e-16, 1.0]), np.array([1.0 - tol, 1.0 - 1e-12])):
        assert adaptive_existence(r_U, 0.06, 0.5).tolist() == [0.0, 0.0]
        assert intensity_existence(r_U, np.ones(2), np.ones(2), 0.5).tolist() == [0.0, 0.0]
    above = np.array([1.0 - 4 * tol, 1.0 - 1e-16])
    assert adaptive_existence(above, 0.06, 0.5).tolist() == [0.06, 0.0]
    np.testing.assert_allclose(intensity_existence(above, np.ones(2), np.ones(2), 0.5), [2 * tol, 0.0], rtol=1e-6)


def test_birth_mapping_is_a_checked_lmb_key():
    assert LMBConfig().birth_mapping == "groups"
    with pytest.raises(SoabenchError, match="lmb.birth_mapping = 'pairs' is not allowed; choose one of 'groups', "):
        Config.from_dict({"lmb": {"birth_mapping": "pairs"}, "experiment": {"filters": ["lmb"],
                          "probabilities": ["static"]}}).validate()  # fmt: skip


def test_pubm_and_atbm_rows_differ_in_the_fair_lmb_and_agree_in_the_old_one():
    scene, scans = _walk_scans()
    fair = {m: _run(m, scene, scans) for m in ("pubm", "atbm")}
    assert any(a.sum_w != b.sum_w for a, b in zip(fair["pubm"], fair["atbm"], strict=True))
    old = {m: _run(m, scene, scans, mapping="components") for m in ("pubm", "atbm")}
    for a, b in zip(old["pubm"], old["atbm"], strict=True):  # the old mapping: PUBM is Reuter's adaptive birth
        assert a.sum_w == b.sum_w and np.array_equal(a.X, b.X)


def test_components_mapping_keeps_one_bernoulli_per_component():
    births = _births([0.2, 0.2], [[5.0, 1.0, 0, 0]] * 2)
    for mapping, n in (("components", 2), ("groups", 1)):
        filt = LMBFilter(FilterConfig(), Sensor(), lmb_cfg=LMBConfig(birth_mapping=mapping))
        res = filt.step(_scan(0, np.zeros((0, 2))), births)
        assert res.n_predicted == n


# ---------------------------------------------------------------------------------------------------------------------
# exact enumeration below max_hypotheses valid hypotheses (§10.8)


def _valid_reference(options, n_opt):
    """Every valid association (column 0 none, 1 + j measurement j) by brute force, track 0 varying fastest."""
    rows = [options[i, : n_opt[i]].tolist() for i in range(len(n_opt))]
    out = []
    for theta in itertools.product(*reversed(rows)):
        theta = theta[::-1]
        meas = [c for c in theta if c >= 1]
        if len(meas) == len(set(meas)):
            out.append(list(theta))
    return out


@pytest.mark.parametrize("seed", range(6))
def test_depth_first_enumeration_finds_every_valid_hypothesis_in_order(seed):
    rng = np.random.default_rng(seed)
    n, M = int(rng.integers(1, 6)), int(rng.integers(0, 5))
    options = np.zeros((n, 1 + M), dtype=np.int64)
    n_opt = np.zeros(n, dtype=np.int64)
    for i in range(n):
        cols = [0] * (rng.uniform() < 0.8) + [1 + j for j in range(M) if rng.uniform() < 0.6]
        options[i, : len(cols)] = cols
        n_opt[i] = len(cols)
    ref = _valid_reference(options, n_opt)
    hyps, count = _enumerate_valid(options, n_opt, M, 10_000)
    assert count == len(ref) and hyps[:count].tolist() == ref
    assert _count_dp(options, n_opt, M, 10_000) == len(ref)  # the forward pass counts the same hypotheses
    if len(ref) > 1:  # stops at limit + 1
        _, stopped = _enumerate_valid(options, n_opt, M, len(ref) - 1)
        assert stopped == len(ref) and _count_dp(options, n_opt, M, len(ref) - 1) == len(ref)


def test_a_sparse_cluster_with_a_large_option_product_is_enumerated_exactly():
    """8 tracks of r = 1 (no "absent" option) in a ring, each gating two measurements shared with its neighbours:
    the product of option counts is 3^8 = 6,561, the valid hypotheses 2,207 (the matchings of a 16-cycle); with
    max_hypotheses = 2,500 the cluster is solved exactly (no Gibbs) and its marginals are the brute-force ones."""
    rng = np.random.default_rng(5)
    n = 8
    logc = np.full((n, 2 + n), -np.inf)
    logc[:, 1] = np.log(rng.uniform(0.2, 1.0, n))
    for i in range(n):
        for j in (i, (i + 1) % n):
            logc[i, 2 + j] = np.log(rng.uniform(0.2, 1.0))
    marg, n_hyp, n_gibbs = association_marginals(logc, 2500, np.uint32(0), False)
    assert (n_gibbs, n_hyp) == (0, 2207) and 3**n > 2500  # the product rule would have sampled
    _, n_cut, g_cut = association_marginals(logc, 2206, np.uint32(0), False)
    assert g_cut == 1 and n_cut <= 2206  # one fewer allowed: sampled
    ref = np.zeros_like(marg)  # brute force over the option product
    total = 0.0
    for theta in itertools.product(*[np.flatnonzero(np.isfinite(row)) for row in logc]):
        meas = [c for c in theta if c >= 2]
        if len(meas) == len(set(meas)):
            w = math.exp(sum(logc[i, c] for i, c in enumerate(theta)))
            total += w
            for i, c in enumerate(theta):
                ref[i, c] += w
    np.testing.assert_allclose(marg, ref / total, rtol=0, atol=1e-12)


@pytest.mark.parametrize("kind", ["linear", "range-bearing"])
@pytest.mark.parametrize("seed", range(8))
def test_T42_exact_up_to_max_hypotheses_valid_hypotheses_equals_the_delta_glmb(kind, seed):
    r, comps, p_D, Z, kappa, R = _random_case(seed, kind)
    r_ref, mean_ref, n_ref = _glmb_reference(r, comps, p_D, Z, kappa, R, kind)
    tracks = _tracks_of(r, comps)
    pD = np.full(len(tracks.w), p_D)
    up = update(tracks, Z, EGO, pD, kappa, _model(kind, R), max_hyp=n_ref, seed=seed)
    assert up.n_gibbs == 0  # exactly max_hypotheses valid hypotheses: enumerated
    np.testing.assert_allclose(up.tracks.r, r_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(_track_means(up.tracks), mean_ref, rtol=0, atol=1e-9)
    if len(Z) and n_ref > 1:
        fewer = update(tracks, Z, EGO, pD, kappa, _model(kind, R), max_hyp=n_ref - 1, seed=seed)
        assert fewer.n_gibbs == 1  # one more than max_hypotheses: sampled


def test_newborn_terms_carry_their_kind():
    nb = NewbornTerms(np.zeros((1, 4)), np.eye(4)[None], lambda A, kappa: np.ones(1))
    assert nb.adaptive is False


def test_compiled_newborn_existences_equal_the_numpy_rules_bit_for_bit():
    """The fused cycle's newborn existences (one compiled call) against adaptive_existence and intensity_existence:
    r_U outside [0, 1], at and around 1 - EXPLAINED_TOL, NaN; beta = 0 with kappa = 0 (no share); all explained."""
    rng = np.random.default_rng(3)
    edge = np.array([-0.5, 0.0, 1.0, 1.5, 1.0 - EXPLAINED_TOL, 1.0 - 2 * EXPLAINED_TOL, np.nan, 0.999, 1e-300])
    for r_U in (edge, rng.uniform(0.0, 1.0, 23), np.ones(4), rng.uniform(0.9, 1.0, 200)):
        M = len(r_U)
        kappa = rng.uniform(0.0, 2.0, M)
        beta = rng.uniform(0.0, 3.0, M)
        kappa[::3] = 0.0
        beta[::3] = 0.0
        for lam, r_max in ((0.06, 0.5), (5.0, 0.3)):
            got = newborn_existence(r_U, beta, kappa, lam, r_max, EXPLAINED_TOL, True)
            assert got.tobytes() == adaptive_existence(r_U, lam, r_max).tobytes()
            got = newborn_existence(r_U, beta, kappa, lam, r_max, EXPLAINED_TOL, False)
            assert got.tobytes() == intensity_existence(r_U, beta, kappa, r_max).tobytes()
