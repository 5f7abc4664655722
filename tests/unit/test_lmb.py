"""LMB filter (docs/method.md "LMB filter"): T35 (against an exhaustive delta-GLMB), T36 (against the Bernoulli
filter's closed form), label continuity (as T31), the birth mapping (register row 33), determinism of the Gibbs
sampler, and every built-in birth model inside the filter."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import shapely
from test_baselines import make_scan, make_scene

from soabench.baselines.partially_uniform import inverse_measurement_terms
from soabench.birth import get_birth_model
from soabench.config import BirthConfig, FilterConfig, Sensor
from soabench.errors import SoabenchError
from soabench.geometry import wrap
from soabench.gmphd.models import cv_model, measurement_noise
from soabench.lmb import LinearPosition, LMBConfig, LMBFilter, RangeBearingEKF, Tracks, label_pairs, make_labels
from soabench.lmb.birth import adaptive_existence, gm_birth
from soabench.lmb.gibbs import association_marginals
from soabench.lmb.update import update
from soabench.plugins import BUILTIN_BIRTH_MODELS
from soabench.seeding import trial_seeds
from soabench.types import SOURCE_GM, BirthContext, Births, NewbornTerms, Obstacles, Scan

EGO = np.array([0.0, 0.0, 0.3])


# ---------------------------------------------------------------------------------------------------------------------
# an independent reference: per-component likelihoods and Kalman posteriors, the delta-GLMB by enumeration


def _component_update(m, P, z, R, kind):
    """(q, m', P') of one Gaussian N(m, P) and one measurement: linear position or range-bearing EKF about m."""
    if kind == "linear":
        H = np.zeros((2, 4))
        H[0, 0] = H[1, 1] = 1.0
        nu = z - m[:2]
    else:
        dx, dy = m[0] - EGO[0], m[1] - EGO[1]
        r = math.hypot(dx, dy)
        H = np.array([[dx / r, dy / r, 0, 0], [-dy / r**2, dx / r**2, 0, 0]])
        nu = z - np.array([r, math.atan2(dy, dx) - EGO[2]])
        nu[1] = wrap(nu[1])
    S = H @ P @ H.T + R
    q = math.exp(-0.5 * nu @ np.linalg.solve(S, nu)) / (2 * math.pi * math.sqrt(np.linalg.det(S)))
    K = P @ H.T @ np.linalg.inv(S)
    A = np.eye(4) - K @ H
    return q, m + K @ nu, A @ P @ A.T + K @ R @ K.T


def _glmb_reference(r, comps, p_D, Z, kappa, R, kind):
    """Exhaustive delta-GLMB update of the LMB {(r_i, sum_c w_c N(m_c, P_c))}: every label set I and every
    association of I (missed or a distinct measurement); returns the existence probability and the spatial mean of
    each track, and the number of associations of positive weight once existence is summed out: the distinct maps
    of measurements to tracks (a track absent or missed counts as "no measurement") among the hypotheses (I, theta)
    of positive weight."""
    N, M = len(r), len(Z)
    r_out = np.zeros(N)
    mean_out = np.zeros((N, 4))
    total = 0.0
    maps = set()
    for I in itertools.product((0, 1), repeat=N):
        w_I = np.prod([r[i] if I[i] else 1 - r[i] for i in range(N)])
        labels = [i for i in range(N) if I[i]]
        for theta in itertools.product(range(M + 1), repeat=len(labels)):
            used = [t for t in theta if t > 0]
            if len(used) != len(set(used)):
                continue
            w = w_I
            means = {}
            for i, t in zip(labels, theta, strict=True):
                psi, mean = 0.0, np.zeros(4)
                for wc, m, P in comps[i]:
                    if t == 0:
                        a = wc * (1 - p_D)
                        psi, mean = psi + a, mean + a * m
                    else:
                        q, m1, _ = _component_update(m, P, Z[t - 1], R, kind)
                        a = wc * p_D * q / kappa[t - 1]
                        psi, mean = psi + a, mean + a * m1
                w *= psi
                means[i] = mean / psi if psi > 0 else mean
            if w == 0:
                continue
            given = dict(zip(labels, theta, strict=True))
            maps.add(tuple(given.get(i, 0) for i in range(N)))
            total += w
            for i in labels:
                r_out[i] += w
                mean_out[i] += w * means[i]
    return r_out / total, mean_out / np.maximum(r_out, 1e-300)[:, None], len(maps)


def _random_case(seed, kind):
    """<= 3 tracks of 1-2 components near each other, <= 3 measurements near them (all hypotheses of weight
    well above 1e-6, so that a long Gibbs run visits them all)."""
    rng = np.random.default_rng(seed)
    N, M = int(rng.integers(1, 4)), int(rng.integers(0, 4))
    centre = np.array([12.0, 6.0])
    r = rng.uniform(0.2, 0.9, N)
    comps = []
    for _ in range(N):
        nc = int(rng.integers(1, 3))
        w = rng.dirichlet(np.ones(nc))
        cs = []
        for c in range(nc):
            m = np.r_[centre + rng.normal(0, 1.0, 2), rng.normal(0, 0.5, 2)]
            L = rng.normal(0, 0.4, (4, 4))
            cs.append((w[c], m, L @ L.T + np.diag([2.0, 2.0, 0.5, 0.5])))
        comps.append(cs)
    if kind == "linear":
        R = np.diag([1.5, 1.5])
        Z = centre + rng.normal(0, 1.5, (M, 2))
    else:
        R = measurement_noise(1.0, math.radians(5.0))
        xy = centre + rng.normal(0, 1.0, (M, 2))
        Z = np.column_stack([np.hypot(xy[:, 0], xy[:, 1]), wrap(np.arctan2(xy[:, 1], xy[:, 0]) - EGO[2])])
    kappa = rng.uniform(0.005, 0.02, M) * (1.0 if kind == "linear" else 20.0)  # q / kappa about 1
    return r, comps, 0.5, Z.reshape(M, 2), kappa, R


def _tracks_of(r, comps):
    n = np.array([len(c) for c in comps])
    start = np.concatenate([[0], np.cumsum(n)]).astype(np.int64)
    w = np.array([c[0] for cs in comps for c in cs])
    m = np.array([c[1] for cs in comps for c in cs])
    P = np.array([c[2] for cs in comps for c in cs])
    N = len(r)
    return Tracks(np.asarray(r), make_labels(0, np.arange(N)), np.zeros(N, np.int8), np.zeros(N, np.int32),
                  start, w, m, P)  # fmt: skip


def _model(kind, R):
    return LinearPosition(R) if kind == "linear" else RangeBearingEKF(R, 0.5, math.inf)


def _track_means(tracks):
    owner = tracks.owner()
    return np.array([np.sum(tracks.w[owner == i, None] * tracks.m[owner == i], axis=0) for i in range(len(tracks))])


@pytest.mark.parametrize("kind", ["linear", "range-bearing"])
@pytest.mark.parametrize("seed", range(12))
def test_T35_update_equals_exhaustive_delta_glmb(kind, seed):
    r, comps, p_D, Z, kappa, R = _random_case(seed, kind)
    r_ref, mean_ref, n_ref = _glmb_reference(r, comps, p_D, Z, kappa, R, kind)
    tracks = _tracks_of(r, comps)
    pD = np.full(len(tracks.w), p_D)
    for force_gibbs, max_hyp in ((False, 1000), (True, 20000)):  # enumeration; a long Gibbs run
        up = update(tracks, Z, EGO, pD, kappa, _model(kind, R), max_hyp=max_hyp, seed=seed, force_gibbs=force_gibbs)
        assert len(up.tracks) == len(r)  # every track keeps r > 0
        np.testing.assert_allclose(up.tracks.r, r_ref, rtol=0, atol=1e-9)
        np.testing.assert_allclose(_track_means(up.tracks), mean_ref, rtol=0, atol=1e-9)
        sums = np.add.reduceat(up.tracks.w, up.tracks.start[:-1])
        np.testing.assert_allclose(sums, 1.0, atol=1e-12)
        if up.n_gibbs == 0:  # enumerated: the clusters' hypotheses multiply to the delta-GLMB's (single cluster here)
            assert not force_gibbs or len(Z) == 0
    # one cluster when every measurement lies in every gate: its associations are the delta-GLMB's, existence summed
    if len(Z):
        assert up.n_hyp == n_ref and up.n_gibbs == 1


def test_T35_gibbs_visits_every_hypothesis_of_a_coupled_cluster():
    """3 tracks, 3 measurements all in every gate: 34 associations (sum_k C(3,k) 3!/(3-k)!; absent and missed
    summed); a Gibbs run of 5000 sweeps visits all of them and its marginals equal the exact ones to 1e-12."""
    rng = np.random.default_rng(7)
    logc = np.log(rng.uniform(0.2, 1.0, (3, 5)))
    m_enum, n_enum, g_enum = association_marginals(logc, 1000, np.uint32(1), False)
    m_gibbs, n_gibbs, g_gibbs = association_marginals(logc, 5000, np.uint32(1), True)
    assert (n_enum, g_enum, n_gibbs, g_gibbs) == (34, 0, 34, 1)
    np.testing.assert_allclose(m_gibbs, m_enum, rtol=0, atol=1e-12)
    np.testing.assert_allclose(m_enum.sum(axis=1), 1.0, atol=1e-12)
    # a short run misses hypotheses: its marginals are those of the visited set only
    m_short, n_short, _ = association_marginals(logc, 5, np.uint32(1), True)
    assert n_short < 34


def test_gibbs_is_deterministic_in_its_seed():
    rng = np.random.default_rng(3)
    logc = np.log(rng.uniform(0.01, 1.0, (8, 8)))
    a = association_marginals(logc, 200, np.uint32(11), True)
    b = association_marginals(logc, 200, np.uint32(11), True)
    c = association_marginals(logc, 200, np.uint32(12), True)
    assert a[1] == b[1] and np.array_equal(a[0], b[0])
    assert not np.array_equal(a[0], c[0])


# ---------------------------------------------------------------------------------------------------------------------
# T36: one Bernoulli, linear-Gaussian, against the Bernoulli filter's closed form


def _bernoulli_closed_form(r, m, P, F, Q, p_S, p_D, Z, kappa, R):
    """Bernoulli filter (Ristic, Vo, Vo & Farina 2013) with a Gaussian density and a linear position sensor:
    returns r' and the posterior Gaussian mixture [(w, m, P)]."""
    r, m, P = p_S * r, F @ m, F @ P @ F.T + Q
    H = np.zeros((2, 4))
    H[0, 0] = H[1, 1] = 1.0
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    A = np.eye(4) - K @ H
    P1 = A @ P @ A.T + K @ R @ K.T
    if len(Z) and not kappa.any():  # no clutter: the one measurement is the target's (the limit kappa -> 0)
        (z,) = Z
        return 1.0, [(1.0, m + K @ (z - H @ m), P1)]
    terms = [(1 - p_D, m, P)]
    for z, kap in zip(Z, kappa, strict=True):
        nu = z - H @ m
        q = math.exp(-0.5 * nu @ np.linalg.solve(S, nu)) / (2 * math.pi * math.sqrt(np.linalg.det(S)))
        terms.append((p_D * q / kap, m + K @ nu, P1))
    delta = 1 - sum(t[0] for t in terms)  # = p_D - p_D sum q / kappa
    r_new = r * (1 - delta) / (1 - r * delta)
    tot = sum(t[0] for t in terms)
    return r_new, [(t[0] / tot, t[1], t[2]) for t in terms]


def _scan(k, Z, ego=(0.0, 0.0, 0.0)):
    return Scan(k, float(k), np.asarray(ego, dtype=float), np.asarray(Z, dtype=float).reshape(-1, 2),
                Obstacles.empty(), [], shapely.Polygon())  # fmt: skip


@pytest.mark.parametrize("clutter", [False, True])
def test_T36_single_bernoulli_equals_closed_form(clutter):
    lam = 2.0 if clutter else 0.0
    sensor = Sensor(lambda_c=lam, fov_deg=360.0, r_max=100.0)
    # no merging, and pruning only of the ~1e-300 weights the clutter floor leaves: the exact mixture
    fcfg = FilterConfig(p_D=0.9, p_S=0.97, merge_U=1e-12, prune_T=1e-100)
    R = np.diag([0.8, 1.3])
    filt = LMBFilter(fcfg, sensor, lmb_cfg=LMBConfig(max_components=1000, prune_r=0.0), model=LinearPosition(R))
    m0 = np.array([10.0, 5.0, 1.0, -0.5])
    P0 = np.diag([2.0, 2.0, 1.0, 1.0])
    filt.tracks = Tracks.single([0.6], m0[None], P0[None], make_labels(0, [0]))
    F, Q = cv_model(sensor.dt, fcfg.sigma_a)
    rng = np.random.default_rng(5)
    r, mix = 0.6, [(1.0, m0, P0)]
    x = m0.copy()
    for k in range(1, 4 if clutter else 8):
        x = F @ x
        detected = clutter or k % 3 != 0
        Z = [x[:2] + rng.normal(0, 1, 2)] if detected else []
        if clutter:
            Z += list(x[:2] + rng.uniform(-4, 4, (int(rng.integers(0, 3)), 2)))
        Z = np.array(Z).reshape(-1, 2)
        kappa = np.full(len(Z), lam / sensor_volume(sensor))
        assert len(mix) == 1  # the closed form below propagates one Gaussian; the clutter case runs one step
        r, mix = _bernoulli_closed_form(r, mix[0][1], mix[0][2], F, Q, fcfg.p_S, fcfg.p_D, Z, kappa, R)
        res = filt.step(_scan(k, Z), Births.empty())
        t = filt.tracks
        assert len(t) == 1 and t.label[0] == make_labels(0, [0])[0]
        assert abs(t.r[0] - r) <= 1e-12
        got = sorted(zip(t.w, t.m.tolist(), t.P.tolist(), strict=True), key=lambda c: c[1])
        want = sorted(((w, m.tolist(), P.tolist()) for w, m, P in mix if w > 0), key=lambda c: c[1])
        assert len(got) == len(want)
        for (w1, m1, P1), (w2, m2, P2) in zip(got, want, strict=True):
            assert abs(w1 - w2) <= 1e-12
            np.testing.assert_allclose(m1, m2, rtol=0, atol=1e-12)
            np.testing.assert_allclose(P1, P2, rtol=0, atol=1e-12)
        if not clutter:
            assert (r == 1.0) == detected  # no clutter: a measurement is the target's
            mix = [max(mix, key=lambda c: c[0])]
        assert list(res.labels) == ([t.label[0]] if r > 0.5 else [])
        if clutter:
            break


def sensor_volume(sensor):
    from soabench.geometry import measurement_volume

    return measurement_volume(sensor)


# ---------------------------------------------------------------------------------------------------------------------
# label continuity (as T31)


@pytest.mark.parametrize("birth", ["adaptive", "gm"])
def test_one_target_keeps_one_label(birth):
    """One target, p_D = 1, no clutter, a constant-velocity walk of 30 scans: one estimate with one label from the
    scan of initiation to the end."""
    sensor = Sensor(lambda_c=0.0, p_D=1.0)
    fcfg = FilterConfig(p_D=1.0)
    filt = LMBFilter(fcfg, sensor, rng=np.random.default_rng(0))
    R = measurement_noise(sensor.sigma_r, sensor.sigma_b)
    rng = np.random.default_rng(1)
    x = np.array([8.0, -6.0, 0.9, 0.5])
    labels = []
    for k in range(30):
        x = x + np.r_[x[2:] * sensor.dt, rng.normal(0, 0.1, 2)]
        z = np.array([math.hypot(x[0], x[1]), math.atan2(x[1], x[0])]) + rng.multivariate_normal(np.zeros(2), R)
        scan = _scan(k, z[None])
        if birth == "adaptive":
            m, P = inverse_measurement_terms(scan.Z, scan.ego, sensor, 1.0)
            births = Births.empty()
            births.newborn = NewbornTerms(m, P, lambda A, kappa: np.zeros(1), adaptive=True)
        else:  # a fixed Gaussian at the start point, every scan (as GMBM)
            births = Births(np.array([0.06]), np.array([[8.0, -6.0, 0.0, 0.0]]),
                            np.diag([9.0, 9.0, 1.0, 1.0])[None], np.array([SOURCE_GM], dtype=np.int8))  # fmt: skip
        res = filt.step(scan, births)
        assert len(res.X) == len(res.labels) <= 1
        if len(res.X):
            labels.append((k, int(res.labels[0])))
            assert np.hypot(*(res.X[0, :2] - x[:2])) < 5.0
    k0 = labels[0][0]
    assert k0 <= 2 and [k for k, _ in labels] == list(range(k0, 30))
    assert len({lab for _, lab in labels}) == 1
    ((kb, jb),) = label_pairs([labels[0][1]])
    assert (kb, jb) == ((1, 0) if birth == "adaptive" else (0, 0))


# ---------------------------------------------------------------------------------------------------------------------
# birth mapping (register row 33), the adaptive birth, refusals, seeds


def test_gm_birth_mapping():
    b = Births(np.array([0.7, 0.01, 0.0]), np.arange(12.0).reshape(3, 4), np.stack([np.eye(4)] * 3),
               np.array([0, 3, 4], dtype=np.int8))  # fmt: skip
    t = gm_birth(b, 7, 0.5)
    assert t.r.tolist() == [0.5, 0.01]  # min(w, 0.5); a zero weight is no Bernoulli
    assert label_pairs(t.label).tolist() == [[7, 0], [7, 1]]
    assert t.origin.tolist() == [0, 3] and t.start.tolist() == [0, 1, 2]
    assert np.array_equal(t.m, b.m[:2]) and np.array_equal(t.P, b.P[:2])


def test_adaptive_existence_is_reuter_eq75():
    r_U = np.array([0.9, 0.0, 0.5, 1.0])
    got = adaptive_existence(r_U, 0.06, 0.5)
    np.testing.assert_allclose(got, 0.06 * np.array([0.1, 1.0, 0.5, 0.0]) / 1.6, rtol=1e-15)
    assert adaptive_existence(r_U, 100.0, 0.5).max() == 0.5
    assert not adaptive_existence(np.ones(3), 0.06, 0.5).any()


def test_dynamic_modes_are_refused():
    for mode in ("dynamic", "dynamic+occ"):
        with pytest.raises(SoabenchError, match="not supported by the LMB filter"):
            LMBFilter(FilterConfig(), Sensor(), mode)


@pytest.mark.parametrize("bad", ["nan_w", "neg_w", "inf_m", "nan_P"])
def test_bad_birth_components_raise_or_drop_as_the_array_path(bad):
    """A birth component that is not finite or has a negative weight: the fused step raises with the scan's message
    (``filter.nonfinite = "raise"``), or with "drop" gives what the step gives without that component, counted;
    the array path does the same."""
    w = np.array([0.05, 0.02, 0.03])
    m = np.array([[8.0, -6.0, 0.0, 0.0], [30.0, 4.0, 0.0, 0.0], [-12.0, 9.0, 0.0, 0.0]])
    P = np.stack([np.diag([9.0, 9.0, 1.0, 1.0])] * 3)
    src = np.full(3, SOURCE_GM, dtype=np.int8)
    w_bad, m_bad, P_bad = w.copy(), m.copy(), P.copy()
    if bad == "nan_w":
        w_bad[1] = np.nan
    elif bad == "neg_w":
        w_bad[1] = -0.01
    elif bad == "inf_m":
        m_bad[1, 2] = np.inf
    else:
        P_bad[1, 3, 3] = np.nan
    keep = [0, 2]
    scan = _scan(0, [[10.0, -0.6], [33.0, 0.2]])
    for fused in (True, False):
        filt = LMBFilter(FilterConfig(), Sensor(), rng=np.random.default_rng(0), fused=fused)
        with pytest.raises(SoabenchError, match="scan 0: 1 of 3 birth components"):
            filt.step(scan, Births(w_bad, m_bad, P_bad, src))
        dropped = LMBFilter(FilterConfig(nonfinite="drop"), Sensor(), rng=np.random.default_rng(0), fused=fused)
        ref = LMBFilter(FilterConfig(), Sensor(), rng=np.random.default_rng(0), fused=fused)
        got = dropped.step(scan, Births(w_bad, m_bad, P_bad, src))
        want = ref.step(scan, Births(w[keep], m[keep], P[keep], src[keep]))
        assert got.n_dropped_births == 1 and want.n_dropped_births == 0
        assert np.array_equal(dropped.tracks.r, ref.tracks.r) and np.array_equal(dropped.tracks.m, ref.tracks.m)
        assert np.array_equal(got.X, want.X) and np.array_equal(got.labels, want.labels)


@pytest.mark.parametrize("bad", ["nan_r", "inf_x", "inf_sum", None])
def test_fused_step_raises_on_a_non_finite_posterior_only(bad, monkeypatch):
    """The fused step's posterior check: a NaN existence or an infinite estimate raises with the scan's message; a
    non-finite sum of finite existences (the elementwise test decides then) and a plain step do not."""
    from soabench.lmb import filter as lmb_filter

    compiled = lmb_filter.lmb_cycle.update_reduce

    def spoiled(*args):
        out = compiled(*args)
        post, X, sums = out[1], out[2], out[7]
        if bad == "nan_r":
            post[0][0] = np.nan
            sums[1] = np.nan
        elif bad == "inf_x":
            X[0, 0] = np.inf
        elif bad == "inf_sum":
            sums[1] = np.inf
        return out

    monkeypatch.setattr(lmb_filter.lmb_cycle, "update_reduce", spoiled)
    filt = LMBFilter(FilterConfig(), Sensor(), rng=np.random.default_rng(0))
    filt.tracks = Tracks.single([0.9], [[10.0, 0.0, 0.0, 0.0]], [np.diag([1.0, 1.0, 0.5, 0.5])], make_labels(0, [0]))
    scan = _scan(1, [[10.0, 0.0]])
    if bad in ("nan_r", "inf_x"):
        with pytest.raises(SoabenchError, match="scan 1: the LMB filter produced a non-finite posterior"):
            filt.step(scan, Births.empty())
    else:
        res = filt.step(scan, Births.empty())
        assert len(res.X) == 1 and np.isfinite(filt.tracks.r).all()
        assert res.sum_w_reduced == (math.inf if bad == "inf_sum" else filt.tracks.r.sum())


def test_association_stream_leaves_the_other_streams_alone():
    s = trial_seeds(42, 3)
    a = s.association_rng().integers(2**32, size=4)
    assert np.array_equal(a, trial_seeds(42, 3).association_rng().integers(2**32, size=4))
    assert not np.array_equal(a, trial_seeds(42, 4).association_rng().integers(2**32, size=4))
    root = np.random.SeedSequence([42, 3])
    scenario, sensor, placement, _ = root.spawn(4)
    assert np.array_equal(s.scenario.generate_state(4), scenario.generate_state(4))
    assert np.array_equal(s.placement.generate_state(4), placement.generate_state(4))


# ---------------------------------------------------------------------------------------------------------------------
# every built-in birth model runs inside the LMB filter, bit-identically twice


def _walk_scans(K=12):
    rng = np.random.default_rng(2)
    scene = make_scene()
    region = scene.sidewalk.intersection(shapely.Point(10, 0).buffer(50))
    x = np.array([20.0, 7.5, -1.0, 0.0])
    scans = []
    for k in range(K):
        x = x + np.r_[x[2:], 0, 0]
        dx, dy = x[0] - 10.0, x[1]
        Z = [[math.hypot(dx, dy) + rng.normal(), math.atan2(dy, dx) + rng.normal(0, 0.08)]]
        Z += list(np.column_stack([rng.uniform(1, 50, 2), rng.uniform(-math.pi, math.pi, 2)]))
        scan = make_scan(scene, Z=Z, k=k)
        scan.visible_region = region
        scans.append(scan)
    return scene, scans


def _run(name, scene, scans, seed=0, atbm="same_scan", mapping="groups"):
    cfg = BirthConfig(atbm=atbm)
    model = get_birth_model(name)(cfg, Sensor(), scene, np.random.default_rng(0))
    filt = LMBFilter(FilterConfig(), Sensor(), N_hat=cfg.N_hat, rng=np.random.default_rng(seed),
                     lmb_cfg=LMBConfig(birth_mapping=mapping))  # fmt: skip
    prev, out = None, []
    for scan in scans:
        prev = filt.step(scan, model(BirthContext(scan, prev, 0.98)))
        out.append(prev)
    return out


@pytest.mark.parametrize("name", [*BUILTIN_BIRTH_MODELS, "atbm-prev"])
def test_every_builtin_birth_model_runs_inside(name):
    scene, scans = _walk_scans()
    model, atbm = (name, "same_scan") if name != "atbm-prev" else ("atbm", "prev_scan")
    a = _run(model, scene, scans, atbm=atbm)
    b = _run(model, scene, scans, atbm=atbm)
    assert all(np.array_equal(x.X, y.X) and np.array_equal(x.labels, y.labels) for x, y in zip(a, b, strict=True))
    assert all(r.n_reduced <= LMBConfig().max_tracks and len(r.labels) == len(r.X) for r in a)
    assert all(len(set(r.labels.tolist())) == len(r.labels) for r in a)  # labels are distinct within a scan
    assert sum(r.n_predicted for r in a) > 0  # births arrived


def test_ukf_form_agrees_with_ekf():
    """filter.form = "ukf" reaches the LMB's measurement model; on a well-localised track both forms agree closely."""
    R = measurement_noise(1.0, math.radians(5.0))
    t = Tracks.single(
        [0.5], np.array([[12.0, 6.0, 0.5, 0.0]]), np.diag([0.5, 0.5, 1.0, 1.0])[None], make_labels(0, [0])
    )
    Z = np.array([[math.hypot(12.3, 6.1), math.atan2(6.1, 12.3)]])
    ups = [
        update(t, Z, np.zeros(3), np.full(1, 0.9), np.full(1, 0.01), RangeBearingEKF(R, 0.5, 13.8, f))
        for f in ("ekf", "ukf")
    ]
    assert abs(ups[0].tracks.r[0] - ups[1].tracks.r[0]) < 1e-3
    np.testing.assert_allclose(ups[0].tracks.m, ups[1].tracks.m, atol=0.05)
    from soabench.gmphd.models import ukf_terms

    assert LMBFilter(FilterConfig(form="ukf"), Sensor()).model._terms is ukf_terms


@pytest.mark.parametrize("bad", ["nan_m", "inf_P", "none", "read_only"])
def test_newborn_terms_are_checked_on_the_fused_path_as_on_the_array_path(bad):
    """Newborn terms with a non-finite mean or covariance: the fused step (its compiled check of contiguous float
    arrays) raises as the array path does; finite ones, writeable or read-only, pass on both and give the same
    labels and counts."""
    m = np.array([[10.0, -6.0, 0.0, 0.0], [33.0, 7.0, 0.0, 0.0]])
    P = np.stack([np.diag([1.0, 1.0, 4.0, 4.0])] * 2)
    if bad == "nan_m":
        m[1, 0] = np.nan
    elif bad == "inf_P":
        P[0, 2, 2] = np.inf
    elif bad == "read_only":
        m.flags.writeable = P.flags.writeable = False
    scan = _scan(0, [[12.0, -0.5], [34.0, 0.2]])
    outcomes = []
    for fused in (True, False):
        filt = LMBFilter(FilterConfig(), Sensor(), rng=np.random.default_rng(0), fused=fused)
        births = Births(np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4, 4)), np.zeros(0, dtype=np.int8))
        births.newborn = NewbornTerms(m, P, lambda A, kappa: np.full(len(kappa), 0.5), adaptive=True)
        try:
            got = filt.step(scan, births)
            outcomes.append(("ok", got.n_newborn, tuple(got.labels), tuple(filt._newborn[2])))
        except SoabenchError as err:
            outcomes.append(("raised", str(err)))
    assert outcomes[0] == outcomes[1]
    assert (outcomes[0][0] == "raised") == (bad in ("nan_m", "inf_P"))
