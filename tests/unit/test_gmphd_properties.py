"""Property tests of the GM-PHD core (docs/method.md §2.6-2.9, §2.12): for random mixtures and measurement sets,
including targets at r -> 0, far outside the FOV, empty measurement sets and empty mixtures, weights stay
non-negative, covariances symmetric positive definite, and nothing is NaN."""

from __future__ import annotations

import math

import numpy as np
from gmphd_cases import scenes
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon

from soabench.config import FilterConfig, Sensor
from soabench.gmphd import GMPHDFilter, Mixture
from soabench.gmphd.models import cv_model, measurement_noise, predict, update
from soabench.gmphd.probabilities import beta_prior
from soabench.gmphd.reduction import extract, prune_merge_cap
from soabench.types import SOURCE_GRID, Births, NewbornTerms, Scan

R = measurement_noise(1.0, math.radians(5.0))
SETTINGS = settings(max_examples=50, deadline=None)


def assert_healthy(mix: Mixture) -> None:
    assert np.all(np.isfinite(mix.w)) and np.all(mix.w >= 0)
    assert np.all(np.isfinite(mix.m)) and np.all(np.isfinite(mix.P))
    if len(mix):
        np.testing.assert_allclose(mix.P, np.swapaxes(mix.P, 1, 2), rtol=0, atol=1e-9 * np.abs(mix.P).max())
        assert np.all(np.linalg.eigvalsh(mix.P).min(axis=1) > 0)
    if mix.beta is not None:
        assert np.all(np.isfinite(mix.beta)) and np.all(mix.beta > 0)


@SETTINGS
@given(scenes(), st.sampled_from(["ekf", "ukf"]), st.floats(0.0, 0.05), st.booleans())
def test_update_and_reduction_stay_healthy(scene, form, kappa, with_newborn):
    mix, Z, ego, p_D = scene
    newborn = None
    if with_newborn:
        M = len(Z)
        newborn = NewbornTerms(
            np.zeros((M, 4)) + [1.0, 2.0, 0.0, 0.0], np.tile(np.eye(4), (M, 1, 1)), lambda A, k: 0.001 * np.ones(len(A))
        )
    nb_beta = beta_prior(FilterConfig()) if mix.dynamic else None
    up = update(mix, Z, ego, p_D, kappa, R, form=form, newborn=newborn, newborn_beta=nb_beta)
    assert_healthy(up.mix)
    assert len(up.mix) >= len(mix)
    assert np.all(np.isfinite(up.A)) and np.all(up.A >= 0)
    assert not np.any(np.isnan(up.log_L))
    # the mass identity (T1) with the newborn terms, in every random case
    Lk = kappa + up.A + up.beta
    with np.errstate(divide="ignore", invalid="ignore"):
        per_z = np.where(Lk > 0, (up.A + up.beta) / Lk, 0.0)
    expected = np.sum((1 - up.p_D) * mix.w) + per_z.sum()
    np.testing.assert_allclose(up.mix.w.sum(), expected, rtol=1e-9, atol=1e-300)
    red = prune_merge_cap(up.mix, 1e-5, 4.0, 50)
    assert_healthy(red.mix)
    assert len(red.mix) <= 50
    assert red.mix.w.sum() <= up.mix.w.sum() * (1 + 1e-12)
    X, Xw = extract(red.mix)
    assert np.all(np.isfinite(X)) and np.all(Xw > 0.5)


@SETTINGS
@given(scenes(), st.floats(0.0, 1.0))
def test_predict_stays_healthy(scene, p_S):
    mix, _, _, _ = scene
    F, Q = cv_model(1.0, 0.5)
    pred = predict(mix, F, Q, p_S)
    assert_healthy(pred)
    np.testing.assert_allclose(pred.w.sum(), p_S * mix.w.sum(), rtol=1e-12, atol=1e-300)


@SETTINGS
@given(scenes(), st.sampled_from(["static", "dynamic", "dynamic+occ"]), st.sampled_from(["ekf", "ukf"]))
def test_filter_steps_stay_healthy(scene, mode, form):
    mix, Z, ego, _ = scene
    filt = GMPHDFilter(FilterConfig(form=form, J_max=40), Sensor(), mode=mode)
    occ = [
        Polygon(
            [(ego[0] + 5, ego[1] - 1), (ego[0] + 7, ego[1] - 1), (ego[0] + 7, ego[1] + 1), (ego[0] + 5, ego[1] + 1)]
        )
    ]
    births = Births(mix.w, mix.m, mix.P, np.full(len(mix), SOURCE_GRID, dtype=np.int8))
    for k in range(3):
        res = filt.step(Scan(k, float(k), ego, Z if k != 1 else np.zeros((0, 2)), None, occ, Polygon()), births)
        assert_healthy(filt.mixture)
        assert math.isfinite(res.sum_w) and res.sum_w >= 0
        assert res.n_reduced <= 40
        assert np.all(np.isfinite(res.X))
        assert math.isfinite(res.mean_pD)
