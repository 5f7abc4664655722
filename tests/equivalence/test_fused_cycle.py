"""The fused filter cycle (soabench/gmphd/cycle.py) against the array path it replaces (docs/method.md §2.11).

Both run side by side on recorded scans of the shipped intersection (SUMO, sensor with clutter) with every birth
model and probability mode, fed the same births at every scan. One cycle from the same prior must agree to 1e-12
(relative, or absolute below 1) in the posterior, estimates and diagnostics, with identical metadata and counts.
Two exceptions, both from conditioning rather than from the implementation:

* the Beta parameters after a merge (§4.5): theta = mu (1 - mu) / v - 1 with v = E[p^2] - E[p]^2 cancels, so the
  last-bit differences of the weights (numpy's exp/log and BLAS products against compiled loops) grow to about
  1e-12 there; they are checked to 1e-9;
* free-running filters (each from its own previous posterior, over the whole recording) let those differences
  propagate through the recursion: checked to 1e-9, with every count and every piece of metadata still identical.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from shapely.geometry import Polygon

from soabench.birth import get_birth_model
from soabench.config import PROBABILITY_MODES, filter_config_for_mode
from soabench.gmphd import GMPHDFilter, Mixture
from soabench.gmphd.models import h
from soabench.plugins import BUILTIN_BIRTH_MODELS
from soabench.types import BirthContext, Births, NewbornTerms, Scan

TOL = dict(rtol=1e-12, atol=1e-12)
LOOSE = dict(rtol=1e-9, atol=1e-9)


@pytest.fixture(scope="module")
def recorded(recorded_intersection):
    """(config, scene, scans at lambda = 3 and lambda = 10, seeds) of a 30 s trial of the shipped intersection."""
    return recorded_intersection


def assert_same_mixture(a: Mixture, b: Mixture, tol: dict = TOL) -> None:
    assert len(a) == len(b)
    np.testing.assert_allclose(a.w, b.w, **tol)
    np.testing.assert_allclose(a.m, b.m, **tol)
    np.testing.assert_allclose(a.P, b.P, **tol)
    np.testing.assert_array_equal(a.origin, b.origin)
    np.testing.assert_array_equal(a.n_det, b.n_det)
    np.testing.assert_array_equal(a.age, b.age)
    np.testing.assert_array_equal(a.label, b.label)  # §2.13: both paths label alike
    assert (a.beta is None) == (b.beta is None)
    if a.beta is not None:
        np.testing.assert_allclose(a.beta, b.beta, **LOOSE)


def assert_same_step(a, b, tol: dict = TOL) -> None:
    for f in ("k", "n_predicted", "n_updated", "n_reduced", "cap_hit", "n_pruned", "n_merged", "n_pairs", "n_newborn"):
        assert getattr(a, f) == getattr(b, f), f
    for f in ("X", "X_w", "A", "kappa"):
        np.testing.assert_allclose(getattr(a, f), getattr(b, f), **tol, err_msg=f)
    for f in ("sum_w", "sum_w_reduced"):
        assert getattr(a, f) == pytest.approx(getattr(b, f), rel=tol["rtol"], abs=tol["atol"]), f
    assert a.mean_pD == pytest.approx(b.mean_pD, rel=1e-9), "mean_pD"  # reads the merged Beta parameters
    np.testing.assert_array_equal(a.origin_counts, b.origin_counts, err_msg="origin_counts")  # §5.7 by origin
    np.testing.assert_array_equal(a.labels, b.labels, err_msg="labels")  # §2.13
    assert a.labels.dtype == np.int64 and len(a.labels) == len(a.X)
    assert a.origin_counts.sum() == a.n_reduced


@pytest.mark.parametrize("model", list(BUILTIN_BIRTH_MODELS))
@pytest.mark.parametrize("lam", [3.0, 10.0])
def test_fused_equals_array_path_on_recorded_scans(recorded, model, lam):
    cfg, scene, scans_by_lam, seeds = recorded
    sensor, scans = scans_by_lam[lam]
    n_steps = 0
    for mode in PROBABILITY_MODES:
        filter_cfg, filter_mode, p_D_b = filter_config_for_mode(cfg.filter, mode)
        birth = get_birth_model(model)(cfg.birth, sensor, scene, seeds.placement_rng())
        fused = GMPHDFilter(filter_cfg, sensor, filter_mode)  # free-running
        synced = GMPHDFilter(filter_cfg, sensor, filter_mode)  # one cycle from the reference's prior
        ref = GMPHDFilter(filter_cfg, sensor, filter_mode, fused=False)
        assert fused.fused and not ref.fused
        prev = None
        for scan in scans.scans:
            births = birth(BirthContext(scan, prev, p_D_b))
            synced.mixture, synced.next_label = ref.mixture.copy(), ref.next_label
            prev = ref.step(scan, births)
            assert_same_step(synced.step(scan, births), prev)
            assert_same_mixture(synced.mixture, ref.mixture)
            assert_same_step(fused.step(scan, births), prev, LOOSE)
            assert_same_mixture(fused.mixture, ref.mixture, LOOSE)
            n_steps += 1
        assert len(ref.mixture) > 0
    assert n_steps == len(PROBABILITY_MODES) * len(scans.scans)


def random_case(rng: np.random.Generator, J: int, M: int, dynamic: bool):
    """A predicted-looking mixture around the sensor, measurements from some components plus clutter."""
    r = rng.uniform(1.0, 45.0, J)
    b = rng.uniform(-2.0, 2.0, J)
    m = np.column_stack([r * np.cos(b), r * np.sin(b), rng.normal(0, 1, (J, 2))])
    A = rng.normal(0, 0.6, (J, 4, 4))
    P = A @ np.swapaxes(A, 1, 2) + 0.2 * np.eye(4)
    beta = np.column_stack([rng.uniform(1, 50, (J, 4))]) if dynamic else None
    mix = Mixture.from_arrays(10 ** rng.uniform(-4, 0.3, J), m, P, origin=rng.integers(0, 5, J), beta=beta)
    mix.n_det[:] = rng.integers(0, 3, J)
    mix.age[:] = rng.integers(0, 9, J)
    idx = rng.choice(J, min(J, M), replace=False)
    Z = h(m[idx], np.zeros(3)) + rng.normal(0, [0.5, 0.03], (len(idx), 2))
    Z = np.vstack([Z, np.column_stack([rng.uniform(0.5, 50, 3), rng.uniform(-np.pi, np.pi, 3)])])
    return mix, Z


@pytest.mark.parametrize("dynamic", [False, True])
@pytest.mark.parametrize("newborn", [False, True])
def test_fused_equals_array_path_random(dynamic, newborn):
    """Wide, heavy, undetectable (r < r_min, outside the FOV) components, births, newborn terms, the J_max cap,
    the undetected-birth age limit and top-n extraction: the branches a short recording may not reach."""
    from soabench.config import FilterConfig, Sensor

    rng = np.random.default_rng(17 + dynamic + 2 * newborn)
    sensor = Sensor(fov_deg=200.0)
    for extraction, J_max, max_age in (("vo_ma", 1000, None), ("top_n", 40, 3), ("vo_ma", 25, 0)):
        cfg = FilterConfig(J_max=J_max, extraction=extraction, max_undetected_birth_age=max_age)
        mode = "dynamic" if dynamic else "static"
        fused, ref = GMPHDFilter(cfg, sensor, mode), GMPHDFilter(cfg, sensor, mode, fused=False)
        for k in range(6):
            prior, Z = random_case(rng, 60, 8, dynamic)
            if k == 3:
                Z = Z[:0]  # a scan without measurements
            prior.m[0, :2] = [0.1, 0.1]  # r < r_min
            prior.P[1] *= 50.0  # wide
            if k == 0:
                # shared labels, so that extraction meets label conflicts (§2.13)
                prior.label[:] = np.random.default_rng(k).integers(1, 8, len(prior))
                fused.mixture, ref.mixture = prior, prior.copy()
            nb = None
            if newborn:
                Mz = len(Z)
                nb = NewbornTerms(
                    np.column_stack([rng.uniform(-20, 20, (Mz, 2)), np.zeros((Mz, 2))]),
                    np.broadcast_to(np.diag([2.0, 2.0, 1.0, 1.0]), (Mz, 4, 4)).copy(),
                    lambda A, kappa: 0.1 * kappa + 0.01 * A - 0.02,  # some negative: clipped to 0
                )
            nbirth = 5
            births = Births(
                rng.uniform(0.01, 0.2, nbirth),
                np.column_stack([rng.uniform(-30, 30, (nbirth, 2)), np.zeros((nbirth, 2))]),
                np.broadcast_to(np.diag([4.0, 4.0, 1.0, 1.0]), (nbirth, 4, 4)).copy(),
                np.full(nbirth, 2, dtype=np.int8),
                nb,
            )
            scan = Scan(k, float(k), np.zeros(3), Z, None, [], Polygon())
            b = ref.step(scan, births)
            a = fused.step(scan, births)
            assert_same_step(a, b)
            assert_same_mixture(fused.mixture, ref.mixture)


@pytest.mark.parametrize("mode", ["static", "dynamic"])
def test_fused_ukf_equals_array_path(recorded, mode):
    """The UKF form (§2.7) on recorded scans, one cycle from the reference's prior, and free-running."""
    cfg, scene, scans_by_lam, seeds = recorded
    sensor, scans = scans_by_lam[3.0]
    filter_cfg = dataclasses.replace(cfg.filter, form="ukf")
    birth = get_birth_model("pubm")(cfg.birth, sensor, scene, seeds.placement_rng())  # newborn terms too
    fused, synced = GMPHDFilter(filter_cfg, sensor, mode), GMPHDFilter(filter_cfg, sensor, mode)
    ref = GMPHDFilter(filter_cfg, sensor, mode, fused=False)
    prev = None
    for scan in scans.scans:
        births = birth(BirthContext(scan, prev, 0.98))
        synced.mixture, synced.next_label = ref.mixture.copy(), ref.next_label
        prev = ref.step(scan, births)
        assert_same_step(synced.step(scan, births), prev)
        assert_same_mixture(synced.mixture, ref.mixture)
        assert_same_step(fused.step(scan, births), prev, LOOSE)
        assert_same_mixture(fused.mixture, ref.mixture, LOOSE)


def test_fused_ukf_with_a_non_positive_definite_covariance_takes_the_array_path():
    """The array path's jitter retry perturbs every component when one is not positive definite; the fused UKF
    hands such a step to it, so the results are the array path's."""
    from soabench.config import FilterConfig, Sensor

    rng = np.random.default_rng(5)
    cfg = FilterConfig(form="ukf")
    fused, ref = GMPHDFilter(cfg, Sensor()), GMPHDFilter(cfg, Sensor(), fused=False)
    prior, Z = random_case(rng, 40, 6, False)
    prior.P[3] = np.diag([1.0, 1.0, 1.0, -1e-12])  # not positive definite (after prediction still not)
    prior.P[3, 2, 2] = -5.0
    fused.mixture, ref.mixture = prior, prior.copy()
    scan = Scan(0, 0.0, np.zeros(3), Z, None, [], Polygon())
    handed = []
    array_step = fused._step_array
    fused._step_array = lambda *a: handed.append(1) or array_step(*a)
    assert_same_step(fused.step(scan, Births.empty()), ref.step(scan, Births.empty()))
    assert_same_mixture(fused.mixture, ref.mixture)
    assert handed == [1]


def test_first_use_notice_is_one_line_once(capsys):
    import time

    from soabench import notice

    notice._printed.clear()
    with notice.first_use_notice("test-slow", delay=0.01):
        time.sleep(0.3)
    with notice.first_use_notice("test-fast", delay=5.0):
        pass
    with notice.first_use_notice("test-slow-again", delay=0.01):  # a second pause: no second line
        time.sleep(0.3)
    err = capsys.readouterr().err
    first, done = err.splitlines()  # the notice, then the time it took; nothing for the second pause
    assert first == notice.MESSAGE and done.startswith("soabench: compiled in ") and notice.ready("test-slow")
    assert notice.ready("test-fast") and not notice.ready("never-run")


def test_the_notice_waits_longer_on_a_loaded_machine(monkeypatch):
    """Loading cached kernels takes about a second of CPU: on a machine shared many times over that is many seconds
    of wall time, which must not be announced as compiling."""
    import os

    from soabench import notice

    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    monkeypatch.setattr(os, "getloadavg", lambda: (1.0, 1.0, 1.0))
    assert notice.load_delay() == notice.DELAY  # idle: the plain delay
    monkeypatch.setattr(os, "getloadavg", lambda: (20.0, 20.0, 20.0))
    assert notice.load_delay() == 10 * notice.DELAY
