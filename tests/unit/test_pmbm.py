"""PMBM filter and its PMB variant (docs/method.md §10): Murty's ranked assignments against enumeration, T37 (the
first scan equals the GM-PHD for every birth model), T38 (against a brute-force multi-target Bayes update), T39 (the
PMB keeps the first moment), T40 (occluded targets stay undetected, not lost), T41 (single target = Kalman filter),
two pedestrians crossing keep their labels, every birth model (built-in or plugin) runs inside."""

from __future__ import annotations

import heapq
import itertools
import math

import numpy as np
import pytest
import shapely
from plugin_fixtures import OneBirth
from scipy.optimize import linear_sum_assignment
from scipy.stats import poisson
from test_baselines import make_scan, make_scene
from test_lmb import _walk_scans

from soabench.birth import get_birth_model
from soabench.config import BirthConfig, Config, FilterConfig, PMBMConfig, Sensor
from soabench.errors import SoabenchError
from soabench.geometry import clutter_intensity, wrap
from soabench.gmphd.mixture import Mixture
from soabench.gmphd.models import gate_threshold, measurement_noise
from soabench.gmphd.models import update as gmphd_update
from soabench.gmphd.probabilities import detection_gate
from soabench.lmb import LinearPosition, RangeBearingEKF, Tracks
from soabench.plugins import BUILTIN_BIRTH_MODELS
from soabench.pmbm import Hypotheses, PMBMDensity, PMBMFilter, murty
from soabench.pmbm.pmb import collapse
from soabench.pmbm.update import update
from soabench.trackers import build_filter
from soabench.types import BirthContext, Births, NewbornTerms

# ---------------------------------------------------------------------------------------------------------------------
# Murty


def _all_assignments(C):
    n, n_cols = C.shape
    out = []
    for perm in itertools.permutations(range(n_cols), n):
        cost = sum(C[r, perm[r]] for r in range(n))
        if np.isfinite(cost):
            out.append(cost)
    return sorted(out)


@pytest.mark.parametrize("seed", range(12))
def test_murty_ranks_like_enumeration(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 5))
    C = rng.normal(0, 3, (n, n + int(rng.integers(0, 3))))
    C[rng.random(C.shape) < 0.3] = np.inf
    want = _all_assignments(C)
    got = murty(C, 10_000)
    assert len(got) == len(want)  # every feasible assignment, each once
    np.testing.assert_allclose([g[0] for g in got], want, rtol=0, atol=1e-9)
    assert len({tuple(g[1]) for g in got}) == len(got)
    for cost, cols in got:
        assert cost == pytest.approx(C[np.arange(n), cols].sum(), abs=1e-12)
    k = max(1, len(want) // 2)
    assert [g[0] for g in murty(C, k)] == [g[0] for g in got[:k]]


def _random_costs(rng, kind, n_max=6):
    """A small cost matrix (rows <= columns): continuous, small integers (many exact ties) or with forbidden cells
    (sometimes no assignment at all)."""
    n = int(rng.integers(1, n_max + 1))
    shape = (n, n + int(rng.integers(0, min(n + 2, 3))))
    if kind == 0:
        return rng.normal(0, 3, shape)
    C = rng.integers(-2, 3, shape).astype(float)
    if kind == 2:
        C[rng.random(shape) < 0.45] = np.inf
    return C


def test_assignment_solver_is_scipys():
    """The compiled solver gives scipy's assignment, column for column (ties included), and finds the same
    matrices infeasible."""
    from soabench.pmbm.murty import lsa

    rng = np.random.default_rng(7)
    n_ties = n_infeasible = 0
    for t in range(600):
        C = _random_costs(rng, t % 3)
        cols = np.empty(len(C), dtype=np.int64)
        ok, u, v = lsa(C, cols)
        try:
            want = linear_sum_assignment(C)[1]
        except ValueError:  # scipy: "cost matrix is infeasible"
            want = None
        assert ok == (want is not None)
        if ok:
            np.testing.assert_array_equal(cols, want)
            n_ties += t % 3 == 1
            # the duals a subproblem starts from: feasible, tight on the assignment, 0 on the free columns
            reduced = C - C.min() - u[:, None] - v[None, :]
            assert (reduced[np.isfinite(C)] >= -1e-9).all()
            np.testing.assert_allclose(reduced[np.arange(len(C)), cols], 0.0, atol=1e-9)
            free = np.setdiff1d(np.arange(C.shape[1]), cols)
            assert (v[free] == 0.0).all() and (v <= 0.0).all()
        n_infeasible += not ok
    assert n_ties > 100 and n_infeasible > 10  # the cases of interest were drawn


def test_murty_with_ties_is_deterministic_and_complete():
    """Small-integer costs (many exact ties): every assignment once with the enumeration's costs, and the k best
    are the first k of the full ranking, assignment for assignment."""
    rng = np.random.default_rng(3)
    for t in range(40):
        C = _random_costs(rng, 1 + t % 2, n_max=4)
        got = murty(C, 10_000)
        assert [g[0] for g in got] == _all_assignments(C)
        assert len({tuple(g[1]) for g in got}) == len(got)
        k = max(1, len(got) // 3)
        head = murty(C, k)
        assert [(c, tuple(x)) for c, x in head] == [(c, tuple(x)) for c, x in got[:k]]


def _murty_from_scratch(C, k):
    """Murty's partition with every subproblem solved from scratch by scipy (the reference)."""
    n = len(C)

    def solve(Cs):
        try:
            rows, cols = linear_sum_assignment(Cs)
        except ValueError:
            return None
        return Cs[rows, cols].sum(), cols

    best = solve(C)
    queue = [(best[0], 0, C, best[1], 0)] if best is not None else []
    out, made = [], 1
    while queue and len(out) < k:
        cost, _, Cs, cols, t0 = heapq.heappop(queue)
        out.append((cost, cols))
        fixed = Cs.copy()
        for t in range(t0, n - 1 if n == C.shape[1] else n):
            child = fixed.copy()
            child[t, cols[t]] = np.inf
            s = solve(child)
            if s is not None:
                heapq.heappush(queue, (s[0], made, child, s[1], t))
                made += 1
            fixed[t, :] = np.inf
            fixed[:, cols[t]] = np.inf
            fixed[t, cols[t]] = Cs[t, cols[t]]
    return out


def test_warm_started_subproblems_are_solved_exactly():
    """Each subproblem starts from its parent's assignment and duals: on matrices without exact ties (continuous
    costs, forbidden cells, square and rectangular) the ranking is that of solving every subproblem from scratch
    with scipy, assignment for assignment."""
    rng = np.random.default_rng(11)
    for t in range(60):
        n = int(rng.integers(2, 8))
        C = rng.normal(0, 3, (n, n + int(rng.integers(0, 4))))
        if t % 2:
            C[rng.random(C.shape) < 0.3] = np.inf
        k = int(rng.integers(1, 40))
        got, want = murty(C, k), _murty_from_scratch(C, k)
        assert len(got) == len(want)
        for (c1, x1), (c2, x2) in zip(got, want, strict=True):
            np.testing.assert_array_equal(x1, x2)
            assert c1 == pytest.approx(c2, abs=1e-9)


def test_compiled_sum_is_numpys():
    from soabench.metrics_kernels import np_sum

    rng = np.random.default_rng(5)
    for n in (0, 1, 7, 8, 9, 16, 17, 127, 128, 129, 300):
        a = rng.normal(0, 1, n) * 10.0 ** rng.normal(0, 3, n)
        assert np_sum(a, len(a)) == a.sum()


def test_each_association_is_listed_once():
    """Two tracks gating two measurements: each measurement to track 0, track 1 or its new track, no track twice:
    7 associations, each once, with the weights of their likelihood factors."""
    from soabench.pmbm.association import cluster_solutions

    lm, ld, ln = np.log([0.3, 0.4]), np.log([[0.5, 0.2], [0.3, 0.6]]), np.log([0.1, 0.2])
    costs, choice = cluster_solutions(np.arange(2), np.arange(2), lm, ld, ln, 100, np.inf)
    assert len({tuple(c) for c in choice}) == len(choice) == 7
    want = []
    for c0, c1 in itertools.product((-1, 0, 1), repeat=2):  # the measurement each track takes (-1: missed)
        if c0 == c1 != -1:
            continue
        f = [lm[0] if c0 < 0 else ld[0, c0], lm[1] if c1 < 0 else ld[1, c1]]
        f += [ln[ll] for ll in (0, 1) if ll not in (c0, c1)]
        want.append(-sum(f))
    np.testing.assert_allclose(costs, sorted(want), rtol=0, atol=1e-12)


def test_repaired_best_assignment_is_the_best():
    """The best assignment repaired from that of a matrix differing in a few columns (a cluster under another
    choice of its tracks' hypotheses) is the best of the new matrix: scipy's on continuous costs, with forbidden
    cells and infeasible cases."""
    from soabench.pmbm.murty import repaired_root, square_root

    rng = np.random.default_rng(4)
    n_infeasible = 0
    for _ in range(300):
        n = int(rng.integers(2, 8))
        C = rng.normal(0, 3, (n, n + int(rng.integers(0, 5))))
        C[rng.random(C.shape) < 0.25] = np.inf
        m = C.shape[1]
        sol, u, v = np.empty(m, dtype=np.int64), np.empty(m), np.empty(m)
        if square_root(C, sol, u, v) == np.inf:
            continue
        changed = np.flatnonzero(rng.random(m) < 0.3)
        C2 = C.copy()
        C2[:, changed] = rng.normal(0, 3, (n, len(changed)))
        C2[:, changed] = np.where(rng.random((n, len(changed))) < 0.7, np.inf, C2[:, changed])
        cost = repaired_root(C2, changed, sol, u, v)
        try:
            rows, want = linear_sum_assignment(C2)
        except ValueError:
            want = None
        if want is None:
            assert cost == np.inf
            n_infeasible += 1
            continue
        np.testing.assert_array_equal(sol[:n], want)
        assert cost == C2[rows, want].sum()
        assert sorted(sol) == list(range(m))  # the square assignment: every column once
    assert n_infeasible > 3


def _cluster_matrix(rng, nL, nT, integer):
    """A cluster's cost matrix (measurement rows; track columns, then each row's own new track): gated track cells
    drawn continuous or as small integers (exact ties), the other new-track cells forbidden."""
    C = np.full((nL, nT + nL), np.inf)
    draw = rng.integers(-2, 3, (nL, nT)).astype(float) if integer else rng.normal(0, 3, (nL, nT))
    C[:, :nT] = np.where(rng.random((nL, nT)) < 0.6, draw, np.inf)
    C[np.arange(nL), nT + np.arange(nL)] = rng.integers(-1, 2, nL) if integer else rng.normal(1, 1, nL)
    return C


@pytest.mark.parametrize("integer", [False, True])
def test_ranking_by_search_is_murtys_or_declines(integer):
    """Where the search answers, its k best assignments are Murty's, cost bits and columns; with small-integer costs
    (exact ties) it declines wherever a tie falls among them, and Murty's ranking is kept."""
    from soabench.pmbm.murty import murty_from, square_root
    from soabench.pmbm.search import ranked_by_search

    rng = np.random.default_rng(21 + integer)
    n_found = n_declined = 0
    for t in range(400):
        nL, nT = int(rng.integers(2, 6)), int(rng.integers(2, 9))
        C = _cluster_matrix(rng, nL, nT, integer)
        k, max_gap = (2, 5, 40, 1000)[t % 4], (np.inf, 3.0)[t % 2]
        m = C.shape[1]
        sol, u, v = np.empty(m, dtype=np.int64), np.empty(m), np.empty(m)
        want_cost, want_cols = murty_from(C, k, max_gap, sol, u, v, square_root(C, sol, u, v))
        found, cost, cols = ranked_by_search(C, k, max_gap, 10**6, 1e12)
        if not found:
            n_declined += 1
            continue
        n_found += 1
        assert cost.tobytes() == want_cost.tobytes() and cols.tobytes() == want_cols.tobytes()
        ranked = np.sort(want_cost[: min(k, len(want_cost))])
        assert (np.diff(ranked) > 0).all()  # it answered only where no two listed costs tie
    if integer:
        assert n_declined > 100 and n_found > 20
    else:
        assert n_declined == 0


def test_ranking_by_search_declines_beyond_its_limits():
    """A tie between the k-th best and the next, too many branches, or too large a product of the rows' finite
    cells: no answer (Murty's algorithm ranks instead)."""
    from soabench.pmbm.search import ranked_by_search

    C = np.array([[1.0, 2.0, np.inf], [2.0, 1.0, 3.0]])  # assignments: 2, 4, 4, 5, ...
    assert ranked_by_search(C, 1, np.inf, 10**6, 1e12)[0]
    assert not ranked_by_search(C, 2, np.inf, 10**6, 1e12)[0]  # the second and third tie at 4
    found, cost, _ = ranked_by_search(C, 2, 1.5, 10**6, 1e12)  # at most 1.5 above the best: one assignment
    assert found and cost.tolist() == [2.0]
    rng = np.random.default_rng(5)
    C = _cluster_matrix(rng, 5, 8, False)
    assert ranked_by_search(C, 50, np.inf, 10**6, 1e12)[0]
    assert not ranked_by_search(C, 50, np.inf, 10, 1e12)[0]
    assert not ranked_by_search(C, 50, np.inf, 10**6, 2.0)[0]


def test_best_sums_is_a_stable_sort_of_every_sum():
    """The k best sums of one entry per sorted array (a heap merge) are the first k of a stable sort of every
    sum, term indices included, also with exact ties."""
    from numba.typed import List

    from soabench.pmbm.association import best_sums

    rng = np.random.default_rng(2)
    for t in range(200):
        costs = [
            np.sort(
                rng.integers(0, 4, int(rng.integers(1, 12))).astype(float)
                if t % 2
                else rng.normal(0, 1, int(rng.integers(1, 12)))
            )
            for _ in range(int(rng.integers(1, 4)))
        ]
        k = int(rng.integers(1, 60))
        total, idx = np.zeros(1), np.zeros((1, len(costs)), dtype=np.int64)
        for j, c in enumerate(costs):
            s = (total[:, None] + c[None, :]).ravel()
            order = np.argsort(s, kind="stable")[:k]
            idx = idx[order // len(c)]
            idx[:, j] = order % len(c)
            total = s[order]
        got_total, got_idx = best_sums(List(costs), k)
        np.testing.assert_array_equal(got_total, total)
        np.testing.assert_array_equal(got_idx, idx)


@pytest.mark.parametrize("shape", [(1, 3), (7, 0), (40, 3), (25, 1)])
def test_unique_rows_is_numpys(shape):
    from soabench.pmbm.association import unique_rows

    x = np.random.default_rng(shape[0]).integers(0, 3, shape)
    u, inv = unique_rows(x)
    if shape[1]:
        want_u, want_inv = np.unique(x, axis=0, return_inverse=True)
        np.testing.assert_array_equal(u, want_u)
        np.testing.assert_array_equal(inv, want_inv.reshape(-1))
    np.testing.assert_array_equal(u[inv], x)


@pytest.mark.parametrize("size", [1, 12, 300, 100_000])
def test_unique_codes_is_numpys(size):
    """Both ways (a table of the codes present, numpy's sort for sparse codes) give np.unique's values, dtypes and
    inverse, shaped like the codes."""
    from soabench.pmbm.update import _unique_codes

    rng = np.random.default_rng(size)
    for shape in [(1, 0), (1, 4), (9, 3), (40, 12)]:
        x = rng.integers(0, size, shape)
        u, inv = _unique_codes(x, size)
        want_u, want_inv = np.unique(x, return_inverse=True)
        assert u.dtype == want_u.dtype and inv.dtype == want_inv.dtype and inv.shape == x.shape
        np.testing.assert_array_equal(u, want_u)
        np.testing.assert_array_equal(inv, want_inv.reshape(x.shape))


def test_murty_infeasible_gives_nothing():
    C = np.array([[1.0, np.inf], [2.0, np.inf]])
    assert murty(C, 5) == []


# ---------------------------------------------------------------------------------------------------------------------
# T37: first scan = GM-PHD, every birth model


def _gmphd_and_pmbm_first_scan(name):
    scene = make_scene()
    ego = np.array([10.0, 0.0, 0.0])
    xy = np.array([[18.0, 7.0], [30.0, -7.5], [27.0, 2.0], [12.0, 7.6], [0.5, 7.0]])
    d = xy - ego[:2]
    Z = np.column_stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])])
    scan = make_scan(scene, ego=ego, Z=Z)
    scan.visible_region = scene.sidewalk.intersection(shapely.Point(10, 0).buffer(50))
    sensor, cfg = Sensor(), FilterConfig()
    births = get_birth_model(name)(BirthConfig(), sensor, scene, np.random.default_rng(0))(BirthContext(scan, None))
    prior = Mixture.from_arrays(births.w, births.m, births.P, origin=births.source)
    p_D = cfg.p_D * detection_gate(prior.m, ego, sensor)
    kappa = clutter_intensity(Z, sensor)
    R = measurement_noise(sensor.sigma_r, sensor.sigma_b)
    gate = gate_threshold(cfg.gate, cfg.gate_prob)
    gm = gmphd_update(prior, Z, ego, p_D, kappa, R, gate_thr=gate, r_min=sensor.r_min, newborn=births.newborn)
    dens = PMBMDensity(prior, Tracks.empty(), np.zeros(0, np.int64), np.zeros((1, 0), np.int64), np.zeros(1))
    up = update(dens, Z, ego, p_D, np.zeros(0), kappa, RangeBearingEKF(R, sensor.r_min, gate), newborn=births.newborn)
    return births, gm, up


def _sorted_components(mix):
    order = np.lexsort((mix.m[:, 1], mix.m[:, 0], np.round(mix.w, 9)))
    return mix.w[order], mix.m[order], mix.P[order]


@pytest.mark.parametrize("name", list(BUILTIN_BIRTH_MODELS))
def test_T37_first_scan_equals_gmphd(name):
    births, gm, up = _gmphd_and_pmbm_first_scan(name)
    assert len(gm.mix) > len(births)  # detections happened
    if births.newborn is not None:
        assert (up.beta > 0).all()
        np.testing.assert_allclose(up.beta, gm.beta, rtol=1e-12, atol=0)
    np.testing.assert_allclose(up.A, gm.A, rtol=1e-12, atol=0)
    assert up.density.table.shape[0] == 1  # without tracks the assignment is unique
    phd = up.density.phd()
    keep_g, keep_p = gm.mix.w > 0, phd.w > 0
    assert keep_g.sum() == keep_p.sum()
    wg, mg, Pg = _sorted_components(gm.mix.select(keep_g))
    wp, mp, Pp = _sorted_components(phd.select(keep_p))
    np.testing.assert_allclose(wp, wg, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(mp, mg, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(Pp, Pg, rtol=1e-10, atol=1e-12)


# ---------------------------------------------------------------------------------------------------------------------
# T38: an independent multi-target Bayes update by enumeration (linear position sensor, no gate)

H_LIN = np.hstack([np.eye(2), np.zeros((2, 2))])


def _kf(m, P, z, R):
    """(q, m', P') of N(m, P) and the position measurement z."""
    S = H_LIN @ P @ H_LIN.T + R
    nu = z - H_LIN @ m
    q = math.exp(-0.5 * nu @ np.linalg.solve(S, nu)) / (2 * math.pi * math.sqrt(np.linalg.det(S)))
    K = P @ H_LIN.T @ np.linalg.inv(S)
    A = np.eye(4) - K @ H_LIN
    return q, m + K @ nu, A @ P @ A.T + K @ R @ K.T


def _random_prior(rng):
    """A PMBM prior: <= 2 tracks with <= 2 hypotheses each (1-2 components), a PPP of <= 3 components, random global
    weights over every combination of hypotheses; p_D per component; measurements and clutter; newborn terms."""
    centre = np.array([5.0, 3.0])

    def gauss(n):
        m = np.column_stack([centre + rng.normal(0, 1.5, (n, 2)), rng.normal(0, 0.5, (n, 2))])
        L = rng.normal(0, 0.3, (n, 4, 4))
        return m, L @ np.swapaxes(L, 1, 2) + np.diag([1.5, 1.5, 0.5, 0.5])

    n = int(rng.choice([0, 1, 2, 2, 2]))
    rs, labels, starts, ws, ms, Ps, track = [], [], [0], [], [], [], []
    for i in range(n):
        for _ in range(int(rng.choice([1, 2, 2]))):
            c = int(rng.integers(1, 3))
            m, P = gauss(c)
            rs.append(rng.uniform(0.1, 1.0))
            labels.append(i + 1)
            ws.append(rng.dirichlet(np.ones(c)))
            ms.append(m)
            Ps.append(P)
            starts.append(starts[-1] + c)
            track.append(i)
    track = np.array(track, dtype=np.int64)
    if n:
        nh = len(rs)
        meta = (np.array(labels, np.int64), np.zeros(nh, np.int8), np.zeros(nh, np.int32), np.array(starts, np.int64))
        hyps = Tracks(np.array(rs), *meta, np.concatenate(ws), np.concatenate(ms), np.concatenate(Ps))
        per_track = [np.flatnonzero(track == i) for i in range(n)]
        table = np.array(list(itertools.product(*per_track)), dtype=np.int64)
    else:
        hyps = Tracks.empty()
        table = np.zeros((1, 0), dtype=np.int64)
    w = rng.dirichlet(np.ones(len(table)))
    J = int(rng.integers(0, 4))
    m, P = gauss(J)
    ppp = Mixture.from_arrays(rng.uniform(0.05, 0.6, J), m, P)
    M = int(rng.choice([0, 1, 2, 3, 3, 3]))
    Z = centre + rng.normal(0, 2.0, (M, 2))
    kappa = rng.uniform(0.002, 0.03, M)
    p_D_ppp = rng.uniform(0.3, 0.95, J)
    p_D_hyp = rng.uniform(0.3, 0.95, len(hyps.w))
    newborn = None
    if rng.random() < 0.5 and M:
        nb_m, nb_P = gauss(M)
        beta = rng.uniform(0.0, 0.02, M)
        newborn = NewbornTerms(nb_m, nb_P, lambda A, kappa, b=beta: b)
    dens = PMBMDensity(ppp, hyps, track, table, np.log(w))
    return dens, Z, kappa, p_D_ppp, p_D_hyp, newborn


def _brute_force(dens, Z, kappa, p_D_ppp, p_D_hyp, newborn, R):
    """Every assignment of each measurement to a prior target (track i, detected), a new target (from the PPP or
    the newborn term) or clutter, with each prior target absent, missed or detected. Returns the posterior PHD as
    lists (w, m, P) and the cardinality distribution without the undetected Poisson part."""
    M = len(Z)
    hyps, ppp = dens.hyps, dens.ppp
    beta = newborn.beta(None, None) if newborn is not None else np.zeros(M)
    comps_of = [range(hyps.start[h], hyps.start[h + 1]) for h in range(len(hyps))]
    det = {}  # (h, l) -> (factor, [(w, m, P)])
    for h in range(len(hyps)):
        for ll in range(M):
            terms = []
            for c in comps_of[h]:
                q, m1, P1 = _kf(hyps.m[c], hyps.P[c], Z[ll], R)
                terms.append((hyps.w[c] * p_D_hyp[c] * q, m1, P1))
            det[h, ll] = (hyps.r[h] * sum(t[0] for t in terms), terms)
    new = []  # per measurement: (e_l, [(w, m, P)])
    for ll in range(M):
        terms = []
        for j in range(len(ppp)):
            q, m1, P1 = _kf(ppp.m[j], ppp.P[j], Z[ll], R)
            terms.append((ppp.w[j] * p_D_ppp[j] * q, m1, P1))
        if beta[ll] > 0:
            terms.append((beta[ll], newborn.m[ll], newborn.P[ll]))
        new.append((sum(t[0] for t in terms), terms))
    hyp_weights, hyp_comps, hyp_card = [], [], []
    for a, row in enumerate(dens.table):
        n = len(row)
        # per target: -2 absent, -1 missed, l detected by z_l
        for states in itertools.product(range(-2, M), repeat=n):
            used = [s for s in states if s >= 0]
            if len(used) != len(set(used)):
                continue
            w = math.exp(dens.log_w[a])
            comps = []
            for i, s in enumerate(states):
                h = row[i]
                if s == -2:
                    w *= 1 - hyps.r[h]
                elif s == -1:
                    miss = [(hyps.w[c] * (1 - p_D_hyp[c]), hyps.m[c], hyps.P[c]) for c in comps_of[h]]
                    total = sum(t[0] for t in miss)
                    w *= hyps.r[h] * total
                    comps += [(t[0] / total, t[1], t[2]) for t in miss]
                else:
                    f, terms = det[h, s]
                    w *= f
                    comps += [(t[0] / (f / hyps.r[h]), t[1], t[2]) for t in terms]
            free = [ll for ll in range(M) if ll not in used]
            for born in itertools.product((False, True), repeat=len(free)):
                w2 = w
                comps2 = list(comps)
                for ll, b in zip(free, born, strict=True):
                    if b:
                        e, terms = new[ll]
                        w2 *= e
                        comps2 += [(t[0] / e, t[1], t[2]) for t in terms]
                    else:
                        w2 *= kappa[ll]
                hyp_weights.append(w2)
                hyp_comps.append(comps2)
                hyp_card.append(sum(1 for s in states if s >= -1) + sum(born))
    W = np.array(hyp_weights) / sum(hyp_weights)
    phd = [((1 - p_D_ppp[j]) * ppp.w[j], ppp.m[j], ppp.P[j]) for j in range(len(ppp))]
    for wt, comps in zip(W, hyp_comps, strict=True):
        phd += [(wt * c[0], c[1], c[2]) for c in comps]
    card = np.zeros(len(dens.table[0]) + M + 1)
    for wt, n in zip(W, hyp_card, strict=True):
        card[n] += wt
    return phd, card


def _density_at(comps, X):
    out = np.zeros(len(X))
    for w, m, P in comps:
        d = X - m
        out += (
            w
            * np.exp(-0.5 * np.einsum("ni,ij,nj->n", d, np.linalg.inv(P), d))
            / math.sqrt((2 * math.pi) ** 4 * np.linalg.det(P))
        )
    return out


def _mix_list(mix):
    return list(zip(mix.w, mix.m, mix.P, strict=True))


def _exhaustive_update(dens, Z, kappa, p_D_ppp, p_D_hyp, newborn, R):
    hyp = Hypotheses(M_max=10**6, w_floor=0.0, r_floor=0.0)
    return update(dens, Z, np.zeros(3), p_D_ppp, p_D_hyp, kappa, LinearPosition(R), newborn=newborn, hyp=hyp)


@pytest.mark.parametrize("seed", range(20))
def test_T38_pmbm_equals_brute_force(seed):
    rng = np.random.default_rng(100 + seed)
    dens, Z, kappa, p_D_ppp, p_D_hyp, newborn = _random_prior(rng)
    R = np.diag([0.8, 0.8])
    up = _exhaustive_update(dens, Z, kappa, p_D_ppp, p_D_hyp, newborn, R)
    phd_ref, card_ref = _brute_force(dens, Z, kappa, p_D_ppp, p_D_hyp, newborn, R)
    phd = _mix_list(up.density.phd())
    X = np.column_stack([rng.normal(5, 2, (40, 2)), rng.normal(0, 0.6, (40, 2))])
    ref_at, got_at = _density_at(phd_ref, X), _density_at(phd, X)
    np.testing.assert_allclose(got_at, ref_at, rtol=1e-10, atol=1e-14)
    mass_ref = sum(c[0] for c in phd_ref)
    assert sum(c[0] for c in phd) == pytest.approx(mass_ref, rel=1e-10, abs=1e-14)
    mean_ref = sum(c[0] * c[1] for c in phd_ref)
    np.testing.assert_allclose(sum(c[0] * c[1] for c in phd), mean_ref, rtol=1e-10, atol=1e-12)
    n_max = len(card_ref) + 8
    card_ref_full = np.convolve(np.pad(card_ref, (0, 9)), poisson.pmf(np.arange(n_max + 1), up.density.ppp.mass))
    np.testing.assert_allclose(up.density.cardinality(n_max), card_ref_full[: n_max + 1], rtol=0, atol=1e-10)


# ---------------------------------------------------------------------------------------------------------------------
# T39: the PMB keeps the first moment


@pytest.mark.parametrize("seed", range(10))
def test_T39_pmb_keeps_the_phd(seed):
    rng = np.random.default_rng(300 + seed)
    dens, Z, kappa, p_D_ppp, p_D_hyp, newborn = _random_prior(rng)
    up = _exhaustive_update(dens, Z, kappa, p_D_ppp, p_D_hyp, newborn, np.diag([0.8, 0.8]))
    pmb = collapse(up.density)
    assert pmb.table.shape[0] == 1 and len(pmb.hyps) == pmb.n_tracks
    X = np.column_stack([rng.normal(5, 2, (40, 2)), rng.normal(0, 0.6, (40, 2))])
    a, b = _mix_list(up.density.phd()), _mix_list(pmb.phd())
    np.testing.assert_allclose(_density_at(b, X), _density_at(a, X), rtol=1e-12, atol=1e-15)
    assert pmb.phd().mass == pytest.approx(up.density.phd().mass, rel=1e-12)


# ---------------------------------------------------------------------------------------------------------------------
# T40: occluded targets stay undetected, not lost

BEHIND = np.array([0.0, 30.0, 0.0, 0.0])  # behind the building box(-50, 10, 25, 50) seen from (10, 0)
OPEN = np.array([35.0, 0.0, 0.0, 0.0])


def _occlusion_filter(occlusion, family="pmbm"):
    """The family's filter as a run builds it in the static+occ (line of sight) or the static mode."""
    cfg = Config()
    filt, _ = build_filter(family, cfg, cfg.sensor_at(), "static+occ" if occlusion else "static")
    assert filt.cfg.occlusion_pd == occlusion and filt.pmb == (family == "pmb")
    return filt


def test_T40_occluded_intensity_keeps_its_weight():
    scene = make_scene()
    scan = make_scan(scene, ego=(10.0, 0.0, 0.0))
    P = np.diag([1.0, 1.0, 0.5, 0.5])
    births = Births(np.array([0.2, 0.2]), np.array([BEHIND, OPEN]), np.array([P, P]), np.zeros(2, np.int8))
    for (occlusion, kept_behind), family in itertools.product(((True, 1.0), (False, 0.02)), ("pmbm", "pmb")):
        filt = _occlusion_filter(occlusion, family)
        filt.step(scan, births)
        ppp = filt.density.ppp
        behind = np.flatnonzero(np.all(ppp.m == BEHIND, axis=1))
        open_ = np.flatnonzero(np.all(ppp.m == OPEN, axis=1))
        assert len(behind) == len(open_) == 1
        assert ppp.w[behind[0]] == pytest.approx(0.2 * kept_behind, rel=1e-12)
        assert ppp.w[open_[0]] == pytest.approx(0.2 * 0.02, rel=1e-12)
        np.testing.assert_array_equal(ppp.P[behind[0]], P)


def test_T40_hidden_track_keeps_its_existence():
    scene = make_scene()
    scan = make_scan(scene, ego=(10.0, 0.0, 0.0))
    P = np.diag([0.3, 0.3, 0.1, 0.1])
    rs = {}
    for occlusion in (True, False):
        filt = _occlusion_filter(occlusion)
        filt.density = PMBMDensity(Mixture.empty(), Tracks.single([0.9], BEHIND, P, [7]), np.zeros(1, np.int64),
                                   np.zeros((1, 1), np.int64), np.zeros(1))  # fmt: skip
        for k in range(3):
            scan.k = k
            res = filt.step(scan, Births.empty())
        rs[occlusion] = filt.density.hyps.r
        assert len(res.labels) == (1 if occlusion else 0)
    assert rs[True][0] == pytest.approx(0.9 * 0.99**3, rel=1e-12)  # survival only
    assert len(rs[False]) == 0 or rs[False][0] < 1e-3  # missed three times in the open: nearly gone


# ---------------------------------------------------------------------------------------------------------------------
# T41: single target, no clutter, linear-Gaussian, p_D = 1 = the Kalman filter


def test_T41_single_target_is_the_kalman_filter():
    sensor = Sensor(lambda_c=0.0, fov_deg=360.0, r_max=200.0)
    cfg = FilterConfig(p_D=1.0)
    R = np.diag([0.5, 0.5])
    filt = PMBMFilter(cfg, sensor, model=LinearPosition(R))
    rng = np.random.default_rng(4)
    x = np.array([10.0, 5.0, 1.0, 0.5])
    m, P = np.array([9.0, 5.5, 0.0, 0.0]), np.diag([4.0, 4.0, 2.0, 2.0])
    births = Births(np.array([0.3]), m[None], P[None], np.zeros(1, np.int8))
    scene = make_scene()
    labels = set()
    for k in range(25):
        if k:
            x = filt.F @ x
            m, P = filt.F @ m, filt.F @ P @ filt.F.T + filt.Q
        z = x[:2] + rng.normal(0, math.sqrt(0.5), 2)
        _, m, P = _kf(m, P, z, R)
        res = filt.step(make_scan(scene, ego=(0.0, 0.0, 0.0), Z=z[None], k=k), births if k == 0 else Births.empty())
        d = filt.density
        assert d.n_tracks == 1 and d.table.shape[0] == 1 and len(d.hyps.w) == 1
        assert d.hyps.r[0] == 1.0
        np.testing.assert_allclose(d.hyps.m[0], m, rtol=0, atol=1e-12 * max(1.0, np.abs(m).max()))
        np.testing.assert_allclose(d.hyps.P[0], P, rtol=1e-12, atol=1e-12)
        labels.update(res.labels.tolist())
        assert len(res.labels) == 1
    assert labels == {1}


# ---------------------------------------------------------------------------------------------------------------------
# two pedestrians crossing: both labels kept


def test_two_pedestrians_crossing_keep_their_labels():
    """Paths crossing in an X, 2 m apart at the closest approach (scan 11-12), default sensor with clutter."""
    scene = make_scene()
    ego = np.array([10.0, 0.0, 0.0])
    sensor = Sensor()
    model = get_birth_model("pubm")(BirthConfig(), sensor, scene, np.random.default_rng(0))
    for pmb in (False, True):
        rng = np.random.default_rng(11)
        filt = PMBMFilter(FilterConfig(), sensor, pmb=pmb)
        truth = np.array([[14.0, -8.0, 0.6, 1.0], [28.0, -10.0, -0.6, 1.0]])
        prev, label_of = None, {0: [], 1: []}
        for k in range(30):
            if k:
                truth = truth @ filt.F.T
            d = truth[:, :2] - ego[:2]
            Z = np.column_stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])])
            Z += rng.normal(0, 1.0, Z.shape) * [sensor.sigma_r, math.radians(sensor.sigma_b)]
            n_c = rng.poisson(sensor.lambda_c)
            Z = np.vstack([Z, np.column_stack([rng.uniform(sensor.r_min, sensor.r_max, n_c),
                                              rng.uniform(-math.pi, math.pi, n_c)])])  # fmt: skip
            Z[:, 1] = wrap(Z[:, 1])
            scan = make_scan(scene, ego=ego, Z=Z, k=k)
            scan.visible_region = scene.sidewalk
            prev = filt.step(scan, model(BirthContext(scan, prev)))
            D = np.hypot(*(prev.X[None, :, :2] - truth[:, None, :2]).transpose(2, 0, 1))
            rows, cols = linear_sum_assignment(np.where(D < 3.0, D, 1e6))
            got = {int(r): int(prev.labels[c]) for r, c in zip(rows, cols, strict=True) if D[r, c] < 3.0}
            for i in (0, 1):
                label_of[i].append(got.get(i))
        for i in (0, 1):
            late = label_of[i][3:]
            assert None not in late, (pmb, i, label_of[i])
            assert len(set(late)) == 1, (pmb, i, label_of[i])
        assert label_of[0][-1] != label_of[1][-1]


# ---------------------------------------------------------------------------------------------------------------------
# every birth model runs inside, unchanged; settings


@pytest.mark.parametrize("name", [*BUILTIN_BIRTH_MODELS, "atbm-prev", "plugin"])
def test_every_birth_model_runs_inside(name):
    scene, scans = _walk_scans(10)
    for pmb in (False, True):
        runs = []
        for _ in range(2):
            if name == "plugin":
                model = OneBirth(BirthConfig(), Sensor(), scene, None)
            else:
                atbm = "prev_scan" if name == "atbm-prev" else "same_scan"
                cfg = BirthConfig(atbm=atbm)
                model = get_birth_model(name.split("-prev")[0])(cfg, Sensor(), scene, np.random.default_rng(0))
            filt = PMBMFilter(FilterConfig(), Sensor(), pmb=pmb)
            prev, out = None, []
            for scan in scans:
                prev = filt.step(scan, model(BirthContext(scan, prev, 0.98)))
                out.append(prev)
            runs.append(out)
        a, b = runs
        assert all(np.array_equal(x.X, y.X) and np.array_equal(x.labels, y.labels) for x, y in zip(a, b, strict=True))
        assert all(len(set(r.labels.tolist())) == len(r.labels) == len(r.X) for r in a)
        if name != "gmbm":  # GMBM's fixed components lie at doors and exits, away from this walker
            assert any(len(r.labels) for r in a)  # the walker is reported
        assert sum(r.n_predicted for r in a) > 0


def test_dynamic_mode_is_refused():
    with pytest.raises(SoabenchError, match="dynamic"):
        PMBMFilter(FilterConfig(), Sensor(), mode="dynamic")


@pytest.mark.parametrize(
    "field,value",
    [("M_max", 0), ("w_floor", 1.0), ("r_floor", -1e-3), ("J_h", 0), ("marginals", "gibbs"), ("w_floor", math.nan)],
)
def test_settings_out_of_range_are_refused(field, value):
    with pytest.raises(SoabenchError, match=f"pmbm.{field}"):
        PMBMConfig(**{field: value}).validate()
