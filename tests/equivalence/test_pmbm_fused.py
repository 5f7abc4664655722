"""The PMBM cycle's compiled calls (soabench/pmbm/cycle.py, kernels.py) against the array path (docs/method.md §10.3).

The compiled calls are the default; the array path (``fused=False``) is their reference. Both filters run free (each
from its own previous posterior) on recorded scans of the shipped intersection, fed the same births: every step
result and the whole posterior density (global table and weights, every hypothesis's existence, label, origin, age
and Gaussian mixture, the undetected intensity) must agree: the discrete outcome exactly, every number to
:data:`RTOL`. Both paths compute the same formulas in the same order; the compiled code's exponentials and
logarithms are the C library's, numpy's are its own vectorised ones, and the two can differ in the last bit.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from soabench.birth import get_birth_model
from soabench.pmbm import PMBMFilter
from soabench.types import BirthContext

STEP_FIELDS = ("k", "X", "X_w", "labels", "sum_w", "sum_w_reduced", "n_predicted", "n_updated", "n_reduced",
               "cap_hit", "A", "kappa", "n_pruned", "n_merged", "n_pairs", "n_newborn", "origin_counts")  # fmt: skip


def _density_arrays(f: PMBMFilter) -> dict[str, np.ndarray]:
    d, h, p = f.density, f.density.hyps, f.density.ppp
    out = {"log_w": d.log_w, "table": d.table, "track": d.track}
    out.update({f"hyps.{k}": getattr(h, k) for k in ("r", "label", "origin", "age", "start", "w", "m", "P")})
    out.update({f"ppp.{k}": getattr(p, k) for k in ("w", "m", "P", "origin", "n_det", "age")})
    return out


RTOL = 1e-9  #: the compiled and array paths' exponentials differ in the last bit; over a run that stays below this


def _same_bits(a, b, what: str) -> None:
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape, what
    assert a.tobytes() == b.tobytes(), what


def _close(a, b, what: str) -> None:
    """Integers, booleans and the discrete structure the same; floats equal to :data:`RTOL`."""
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape, what
    if a.dtype.kind == "f":
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=1e-300, err_msg=what)
    else:
        assert a.tobytes() == b.tobytes(), what


@pytest.mark.parametrize(
    "pmb,model,variant",
    [(False, "soa", "ekf"), (False, "pubm", "ekf"), (True, "atbm", "ekf"), (True, "soa", "ukf"), (False, "ubm", "occ")],
)  # fmt: skip
def test_compiled_update_equals_array_path(recorded_intersection, pmb, model, variant):
    cfg, scene, scans_by_lam, seeds = recorded_intersection
    sensor, scans = scans_by_lam[3.0]
    if variant == "occ":  # static+occ: the line-of-sight detection probability
        filter_cfg = dataclasses.replace(cfg.filter, occlusion_pd=True)
        assert any(s.occluders for s in scans.scans)
    else:
        filter_cfg = dataclasses.replace(cfg.filter, form=variant)
    fused = PMBMFilter(filter_cfg, sensor, pmbm_cfg=cfg.pmbm, pmb=pmb)
    ref = PMBMFilter(filter_cfg, sensor, pmbm_cfg=cfg.pmbm, pmb=pmb, fused=False)
    assert fused.fused and not ref.fused
    birth = get_birth_model(model)(cfg.birth, sensor, scene, seeds.placement_rng())
    prev, n_tracks, n_global = None, 0, 0
    for scan in scans.scans:
        births = birth(BirthContext(scan, prev, cfg.filter.p_D))
        a, prev = fused.step(scan, births), ref.step(scan, births)
        for f in STEP_FIELDS:
            _close(getattr(a, f), getattr(prev, f), f"scan {scan.k}: {f}")
        for (k, x), y in zip(_density_arrays(fused).items(), _density_arrays(ref).values(), strict=True):
            _close(x, y, f"scan {scan.k}: {k}")
        n_tracks = max(n_tracks, ref.density.n_tracks)
        n_global = max(n_global, len(ref.density.log_w))
    assert n_tracks > 5 and len(prev.labels) > 0  # the run had tracks and reported some
    assert pmb or n_global > 1  # the PMBM kept several global hypotheses at some scan


def test_compiled_unique_rows_and_codes_are_numpys():
    """The compiled call's distinct table rows (lexicographic, with the inverse) and distinct codes (both the table
    and the sort branch) are numpy's."""
    from soabench.pmbm.kernels import unique_codes, unique_rows

    rng = np.random.default_rng(5)
    for _ in range(200):
        B, n = int(rng.integers(1, 30)), int(rng.integers(0, 6))
        t = rng.integers(0, 3, (B, n)).astype(np.int64)
        uniq, inv = unique_rows(t)
        if n:
            u_np, inv_np = np.unique(t, axis=0, return_inverse=True)
            np.testing.assert_array_equal(uniq, u_np)
            np.testing.assert_array_equal(inv, inv_np.reshape(B))
        else:
            assert uniq.shape == (1, 0) and not inv.any()
        size = int(rng.choice([10, 100_000]))  # a table of codes present, or (sparse codes) a sort
        code = rng.integers(0, size, (B, max(n, 1))).astype(np.int64)
        u, inv = unique_codes(code, size)
        u_np, inv_np = np.unique(code, return_inverse=True)
        np.testing.assert_array_equal(u, u_np)
        np.testing.assert_array_equal(inv, inv_np.reshape(code.shape))


@pytest.mark.parametrize(
    "pmb,model,variant",
    [(False, "soa", "static"), (False, "pubm", "static"), (True, "atbm", "static"), (True, "ubm", "occ"),
     (False, "soa", "occ"), (False, "ubm-ws", "drop")],
)  # fmt: skip
def test_whole_cycle_equals_three_calls_bit_for_bit(recorded_intersection, pmb, model, variant):
    """The whole cycle in one or two compiled calls (soabench/pmbm/step.py, the default for the EKF sensor) runs the
    three-call path's functions in its order: every step result and the whole posterior the same bytes, free
    running, with newborn terms (PUBM, ATBM), the line of sight and dropped scans (a pose that is not finite)."""
    cfg, scene, scans_by_lam, seeds = recorded_intersection
    sensor, scans = scans_by_lam[3.0]
    filter_cfg = dataclasses.replace(cfg.filter, occlusion_pd=variant == "occ", nonfinite="drop")
    whole = PMBMFilter(filter_cfg, sensor, pmbm_cfg=cfg.pmbm, pmb=pmb)
    calls = PMBMFilter(filter_cfg, sensor, pmbm_cfg=cfg.pmbm, pmb=pmb)
    calls.whole = False
    assert whole.whole
    assert not PMBMFilter(dataclasses.replace(cfg.filter, form="ukf"), sensor).whole  # the UKF takes three calls
    birth = get_birth_model(model)(cfg.birth, sensor, scene, seeds.placement_rng())
    prev, n_tracks = None, 0
    for scan in scans.scans:
        births = birth(BirthContext(scan, prev, cfg.filter.p_D))
        if variant == "drop" and scan.k % 7 == 3:
            scan = dataclasses.replace(scan, ego=np.full(3, np.nan))
        a, prev = whole.step(scan, births), calls.step(scan, births)
        for f in STEP_FIELDS:
            _same_bits(getattr(a, f), getattr(prev, f), f"scan {scan.k}: {f}")
        assert min(a.t_predict, a.t_update, a.t_reduce) > 0.0  # the stages' clock readings, nested in the step
        for (k, x), y in zip(_density_arrays(whole).items(), _density_arrays(calls).values(), strict=True):
            _same_bits(x, y, f"scan {scan.k}: {k}")
        n_tracks = max(n_tracks, calls.density.n_tracks)
    assert n_tracks > 5 and len(prev.labels) > 0
