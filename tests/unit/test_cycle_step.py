"""One compiled call per scan (soabench/gmphd/cycle.py ``step``) and the clock it times its stages with.

``cycle.step`` composes the stage kernels (predict_append, update, reduce) inside one call; it must give what the
three separate calls give, bit for bit, on recorded scans, and its stage times must be readings of the clock of
``time.perf_counter``.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from soabench.birth import get_birth_model
from soabench.config import Config, filter_config_for_mode
from soabench.gmphd import GMPHDFilter, cycle
from soabench.gmphd.clock import monotonic
from soabench.gmphd.filter import _birth_arrays, _mixture_arrays
from soabench.types import BirthContext


def test_compiled_clock_reads_perf_counter():
    before = time.perf_counter()
    now = monotonic()
    after = time.perf_counter()
    assert before <= now <= after


@pytest.fixture(scope="module")
def recorded():
    from soabench.scenario import load, simulate
    from soabench.seeding import trial_seeds
    from soabench.sensor import observe

    scene, scenario = load("intersection")
    cfg = Config()
    seeds = trial_seeds(7, 1)
    rec = simulate(scene, scenario, seeds, duration=20.0)
    return cfg, scene, observe(rec, scene, cfg.sensor_at(), seeds.sensor_rngs()), seeds


def _same(a, b):
    """Equal arrays / scalars / nested tuples, bit for bit (NaN-free values)."""
    if isinstance(a, tuple):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _same(x, y)
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape
        assert np.array_equal(a.view(np.uint8), np.ascontiguousarray(b).view(np.uint8))
    else:
        assert a == b


@pytest.mark.parametrize("mode", ["static", "dynamic"])
@pytest.mark.parametrize("form", ["ekf", "ukf"])
def test_one_call_equals_the_stage_calls(recorded, mode, form):
    cfg, scene, scans, seeds = recorded
    fcfg, fmode, _ = filter_config_for_mode(cfg.filter, mode)
    filt = GMPHDFilter(dataclasses.replace(fcfg, form=form), cfg.sensor_at(), mode=fmode)
    birth = get_birth_model("soa")(cfg.birth, cfg.sensor_at(), scene, seeds.placement_rng())
    prev, checked = None, 0
    for scan in scans.scans:
        births = birth(BirthContext(scan, prev))
        Z = np.ascontiguousarray(scan.Z, dtype=float).reshape(-1, 2)
        ego = np.ascontiguousarray(scan.ego, dtype=float)
        kappa = filt._kappa(Z)
        mix = _mixture_arrays(filt.mixture)
        b = _birth_arrays(births) if len(births) else filt._no_births
        common = (filt._p_D, Z, filt.R, filt._r_min, filt._gate, kappa, filt._ukf)
        label0 = filt.next_label
        pred = cycle.predict_append(*mix, filt.F, filt.Q, filt._pred_pars, *b, filt._beta0, ego, label0)
        post, A, ok = cycle.update(*pred[:9], *common[:2], ego, *common[2:])
        red = cycle.reduce(*post[:8], filt._red_pars, label0 + len(b[0]))
        status, n_pred, n_up, n_pairs, A1, red1, times = cycle.step(
            *mix, filt.F, filt.Q, filt._pred_pars, *b, filt._beta0, ego, *common, filt._red_pars, label0
        )
        assert ok and status == cycle.STEP_OK
        assert (n_pred, n_up, n_pairs) == (len(pred[0]), len(post[0]), post[8])
        _same(A1, A)
        _same(red1, red)
        assert times.shape == (3,) and (times >= 0.0).all()
        res = filt.step(scan, births)  # the filter's own step takes the one call and keeps its reduced posterior
        _same(res.X, red[1])
        _same(filt.mixture.w, red[0][0])
        _same(filt.mixture.label, red[0][7])
        _same(res.labels, red[3])
        assert min(res.t_predict, res.t_update, res.t_reduce) >= 0.0
        prev, checked = res, checked + 1
    assert checked == len(scans.scans) > 10


def test_bad_births_change_nothing(recorded):
    cfg, scene, scans, seeds = recorded
    filt = GMPHDFilter(cfg.filter, cfg.sensor_at(), mode="static")
    birth = get_birth_model("soa")(cfg.birth, cfg.sensor_at(), scene, seeds.placement_rng())
    scan = scans.scans[3]
    births = birth(BirthContext(scan, None))
    b = list(_birth_arrays(births))
    b[0] = b[0].copy()
    b[0][0] = -1.0  # a negative birth weight: the compiled check stops before predicting
    Z = np.ascontiguousarray(scan.Z, dtype=float).reshape(-1, 2)
    ego = np.ascontiguousarray(scan.ego, dtype=float)
    out = cycle.step(
        *_mixture_arrays(filt.mixture), filt.F, filt.Q, filt._pred_pars, *b, filt._beta0, ego, filt._p_D, Z,
        filt.R, filt._r_min, filt._gate, filt._kappa(Z), filt._ukf, filt._red_pars, filt.next_label,
    )  # fmt: skip
    assert out[0] == cycle.STEP_BAD_BIRTHS and len(out[5][0][0]) == 0


def test_the_newborn_step_hands_posterior_the_types_the_update_does(monkeypatch):
    """numba compiles a function once per argument types, writability included: the update without newborn terms
    hands the compiled posterior writable (empty) newborn arrays, so the newborn step must too (a birth model's
    read-only newborn terms are copied), or posterior and everything it calls would be compiled a second time."""
    import numba
    import shapely

    from soabench import kernel_warmup as kw
    from soabench.types import NewbornTerms, Scan

    seen = []
    real = cycle.posterior_reduce
    monkeypatch.setattr(cycle, "posterior_reduce", lambda *args: seen.append(args) or real(*args))
    cfg = Config()
    f = GMPHDFilter(cfg.filter, cfg.sensor_at(), "static")
    Z, ego = kw._scan_arrays()
    nb_m, nb_P = np.zeros((2, 4)), np.repeat(np.eye(4)[None], 2, axis=0)
    nb_m.flags.writeable = nb_P.flags.writeable = False  # as a birth model may share them
    births = kw._births()
    births.newborn = NewbornTerms(nb_m, nb_P, lambda A, kappa: 0.1 + 0 * A)
    f.step(Scan(0, 0.0, ego, Z, kw._no_obstacles(), [], shapely.box(0, 0, 1, 1)), births)
    assert len(seen) == 1
    passed = [numba.typeof(a) for a in seen[0][11:13]]  # nb_m, nb_P
    assert passed == [numba.typeof(np.empty((0, 4))), numba.typeof(np.empty((0, 4, 4)))]
    assert nb_m.flags.writeable is False  # the caller's arrays are left as they were
