"""The fused LMB cycle (soabench/lmb/cycle.py) against the array path (docs/method.md "LMB filter").

The fused cycle is the default; the array path (``fused=False``) is its reference. Both run
side by side on recorded scans of the shipped intersection with every birth model, fed the same births
and drawing the same Gibbs seeds. One cycle from the same prior must agree to 1e-12 (relative, or absolute below 1)
in the tracks, estimates and diagnostics, with identical labels and counts: numpy's exp/log and BLAS products against
the compiled loops differ in the last bits only (A_l is compared as the share A_l / (kappa_l + A_l) = r_U(z_l) that
birth models read: near r_U = 1 the last bit of 1 - r_U sets A_l itself). Free-running filters (each from its
own previous posterior) let those differences travel through the recursion: checked to 1e-9, every count and label
identical (no birth hinges on the last bit of 1 - r_U: soabench.lmb.birth.EXPLAINED_TOL).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from shapely.geometry import Polygon

from soabench.birth import get_birth_model
from soabench.config import FilterConfig, LMBConfig, Sensor
from soabench.lmb import LMBFilter, Tracks
from soabench.plugins import BUILTIN_BIRTH_MODELS
from soabench.types import BirthContext, Births, Scan

TOL = dict(rtol=1e-12, atol=1e-12)
LOOSE = dict(rtol=1e-9, atol=1e-9)


def assert_same_tracks(a: Tracks, b: Tracks, tol: dict = TOL) -> None:
    assert len(a) == len(b)
    np.testing.assert_array_equal(a.label, b.label)
    np.testing.assert_array_equal(a.origin, b.origin)
    np.testing.assert_array_equal(a.age, b.age)
    np.testing.assert_array_equal(a.start, b.start)
    for f in ("r", "w", "m", "P"):
        np.testing.assert_allclose(getattr(a, f), getattr(b, f), **tol, err_msg=f)


def assert_same_step(a, b, tol: dict = TOL) -> None:
    for f in ("k", "n_predicted", "n_updated", "n_reduced", "cap_hit", "n_pruned", "n_merged", "n_pairs", "n_newborn"):
        assert getattr(a, f) == getattr(b, f), f
    for f in ("X", "X_w", "kappa"):
        np.testing.assert_allclose(getattr(a, f), getattr(b, f), **tol, err_msg=f)
    # A_l = kappa r_U / (1 - r_U) is ill-conditioned where z_l is surely a track's (r_U -> 1: a last-bit change of
    # 1 - r_U changes A by its own relative size); what a birth model reads is rho = A / (kappa + A) = r_U
    rho = lambda s: s.A / (s.kappa + s.A)  # noqa: E731
    np.testing.assert_allclose(rho(a), rho(b), **tol, err_msg="A / (kappa + A)")
    for f in ("sum_w", "sum_w_reduced"):
        assert getattr(a, f) == pytest.approx(getattr(b, f), rel=tol["rtol"], abs=tol["atol"]), f
    np.testing.assert_array_equal(a.labels, b.labels, err_msg="labels")
    np.testing.assert_array_equal(a.origin_counts, b.origin_counts, err_msg="origin_counts")
    assert a.labels.dtype == np.int64 and len(a.labels) == len(a.X)


def _filters(filter_cfg, sensor, lmb_cfg, N_hat):
    make = lambda fused: LMBFilter(filter_cfg, sensor, lmb_cfg=lmb_cfg, N_hat=N_hat,  # noqa: E731
                                   rng=np.random.default_rng(7), fused=fused)  # fmt: skip
    return make(True), make(True), make(False)  # free-running, synced to the reference's prior, reference


def _run(scans, birth, free, synced, ref, p_D):
    prev = None
    for scan in scans.scans:
        births = birth(BirthContext(scan, prev, p_D))
        synced.tracks, synced._newborn = ref.tracks, ref._newborn
        prev = ref.step(scan, births)
        assert_same_step(synced.step(scan, births), prev)
        assert_same_tracks(synced.tracks, ref.tracks)
        assert_same_step(free.step(scan, births), prev, LOOSE)
        assert_same_tracks(free.tracks, ref.tracks, LOOSE)
    assert len(ref.tracks) > 0


@pytest.mark.parametrize("model", list(BUILTIN_BIRTH_MODELS))
def test_fused_lmb_equals_array_path_on_recorded_scans(recorded_intersection, model):
    cfg, scene, scans_by_lam, seeds = recorded_intersection
    sensor, scans = scans_by_lam[3.0]
    free, synced, ref = _filters(cfg.filter, sensor, cfg.lmb, cfg.birth.N_hat)
    assert free.fused and not ref.fused
    birth = get_birth_model(model)(cfg.birth, sensor, scene, seeds.placement_rng())
    _run(scans, birth, free, synced, ref, cfg.filter.p_D)


@pytest.mark.parametrize(
    "variant", ["components", "ukf", "occlusion", "clutter"], ids=lambda v: v
)  # fmt: skip
def test_fused_lmb_equals_array_path_variants(recorded_intersection, variant):
    """The old birth mapping, the UKF form, the line-of-sight gate and heavy clutter (large Gibbs clusters)."""
    cfg, scene, scans_by_lam, seeds = recorded_intersection
    sensor, scans = scans_by_lam[10.0 if variant == "clutter" else 3.0]
    filter_cfg, lmb_cfg = cfg.filter, cfg.lmb
    if variant == "components":
        lmb_cfg = dataclasses.replace(lmb_cfg, birth_mapping="components")
    if variant == "ukf":
        filter_cfg = dataclasses.replace(filter_cfg, form="ukf")
    if variant == "occlusion":
        filter_cfg = dataclasses.replace(filter_cfg, occlusion_pd=True)
        assert any(s.occluders for s in scans.scans)
    free, synced, ref = _filters(filter_cfg, sensor, lmb_cfg, cfg.birth.N_hat)
    model = "soa" if variant in ("occlusion", "clutter") else "pubm"
    birth = get_birth_model(model)(cfg.birth, sensor, scene, seeds.placement_rng())
    _run(scans, birth, free, synced, ref, cfg.filter.p_D)


def test_fused_ukf_with_a_non_positive_definite_covariance_takes_the_array_path():
    """A UKF step with a covariance that is not positive definite is the array path's (its jitter rule)."""
    rng = np.random.default_rng(3)
    cfg = FilterConfig(form="ukf")
    fused = LMBFilter(cfg, Sensor(), lmb_cfg=LMBConfig(), rng=np.random.default_rng(1), fused=True)
    ref = LMBFilter(cfg, Sensor(), lmb_cfg=LMBConfig(), rng=np.random.default_rng(1), fused=False)
    P = np.broadcast_to(np.diag([2.0, 2.0, 1.0, 1.0]), (3, 4, 4)).copy()
    P[1] = np.diag([1.0, 1.0, -5.0, 1.0])
    m = np.column_stack([rng.uniform(5, 20, (3, 2)), np.zeros((3, 2))])
    prior = Tracks.single(np.array([0.9, 0.6, 0.3]), m, P, np.arange(3))
    fused.tracks, ref.tracks = prior, prior
    Z = np.column_stack([np.hypot(m[:, 0], m[:, 1]), np.arctan2(m[:, 1], m[:, 0])])
    scan = Scan(0, 0.0, np.zeros(3), Z, None, [], Polygon())
    handed = []
    array_step = fused._step_array
    fused._step_array = lambda *a: handed.append(1) or array_step(*a)
    assert_same_step(fused.step(scan, Births.empty()), ref.step(scan, Births.empty()))
    assert_same_tracks(fused.tracks, ref.tracks)
    assert handed == [1]
