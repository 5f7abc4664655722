"""Statistical tests of the synthetic sensor with fixed seeds (docs/method.md §2.3): Poisson clutter uniform over the
FOV, Gaussian measurement noise with the configured sigmas, detection rate p_D of visible targets."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from shapely.geometry import box
from test_sensor import open_scene, static_recording

from soabench.config import Sensor
from soabench.geometry import range_bearing, wrap
from soabench.seeding import trial_seeds
from soabench.sensor import draw_clutter, observe
from soabench.types import CLUTTER, Scans

N_DRAWS = 20000  # scans for the clutter-only statistics (draw_clutter is cheap)
N_SCANS = 1000  # scans for statistics through observe()


def _observe(peds: np.ndarray, cfg: Sensor, ego=(0.0, 0.0, 0.0), occluders=None, seed: int = 7) -> Scans:
    rec = static_recording(peds, N_SCANS, ego=ego)
    return observe(rec, open_scene(occluders), cfg, trial_seeds(seed, 0).sensor_rngs())


def test_clutter_count_is_poisson_with_mean_lambda():
    lam = 3.0
    counts = np.array([len(z) for z in draw_clutter(np.random.default_rng(11), Sensor(lambda_c=lam), N_DRAWS)])
    assert abs(counts.mean() - lam) < 4 * np.sqrt(lam / N_DRAWS)
    assert counts.var() / lam == pytest.approx(1.0, abs=0.05)
    edges = np.arange(9)
    observed = np.array([(counts == c).sum() for c in edges[:-1]] + [(counts >= 8).sum()])
    pmf = stats.poisson.pmf(edges[:-1], lam)
    expected = N_DRAWS * np.append(pmf, 1 - pmf.sum())
    assert stats.chisquare(observed, expected).pvalue > 1e-3


def test_clutter_is_uniform_in_range_and_bearing():
    cfg = Sensor(lambda_c=3.0)
    z = np.concatenate(draw_clutter(np.random.default_rng(12), cfg, N_DRAWS))
    assert stats.kstest(z[:, 0], stats.uniform(cfg.r_min, cfg.r_max - cfg.r_min).cdf).pvalue > 1e-3
    assert stats.kstest(z[:, 1], stats.uniform(-np.pi, 2 * np.pi).cdf).pvalue > 1e-3
    assert np.all((z[:, 1] > -np.pi) & (z[:, 1] <= np.pi))
    # a sector FOV: bearings uniform over [-Theta/2, Theta/2] around the heading
    sector = Sensor(lambda_c=3.0, fov_deg=120.0)
    zs = np.concatenate(draw_clutter(np.random.default_rng(13), sector, N_DRAWS))
    assert np.all(np.abs(zs[:, 1]) <= np.radians(60.0))
    assert stats.kstest(zs[:, 1], stats.uniform(-sector.fov / 2, sector.fov).cdf).pvalue > 1e-3


def test_cartesian_clutter_is_uniform_in_area():
    cfg = Sensor(lambda_c=3.0, clutter_space="cartesian", r_min=2.0)
    r = np.concatenate(draw_clutter(np.random.default_rng(14), cfg, N_DRAWS))[:, 0]
    r2 = stats.uniform(cfg.r_min**2, cfg.r_max**2 - cfg.r_min**2)
    assert stats.kstest(r**2, r2.cdf).pvalue > 1e-3
    assert stats.kstest(r, stats.uniform(cfg.r_min, cfg.r_max - cfg.r_min).cdf).pvalue < 1e-6  # not uniform in r


def test_clutter_through_observe_has_mean_lambda_and_stays_in_the_fov():
    cfg = Sensor(lambda_c=3.0, fov_deg=90.0)
    scans = _observe(np.zeros((0, 2)), cfg, ego=(5.0, -3.0, 2.0))
    counts = np.array([len(s.Z) for s in scans.scans])
    assert all(np.all(src == CLUTTER) for src in scans.source)
    assert abs(counts.mean() - 3.0) < 4 * np.sqrt(3.0 / N_SCANS)
    z = np.concatenate([s.Z for s in scans.scans])
    assert np.all((z[:, 0] >= cfg.r_min) & (z[:, 0] <= cfg.r_max) & (np.abs(z[:, 1]) <= cfg.fov / 2))


def test_measurement_noise_matches_the_configured_sigmas():
    cfg = Sensor(lambda_c=0.0, p_D=1.0, sigma_r=0.8, sigma_b_deg=4.0)
    ego = (1.0, 2.0, 1.0)
    behind = ego[2] + np.pi - 0.01  # the second target is behind the ego: bearing ~ +-pi relative to the heading
    peds = np.array([[21.0, 7.0], [ego[0] + 20 * np.cos(behind), ego[1] + 20 * np.sin(behind)]])
    scans = _observe(peds, cfg, ego=ego)
    r_true, b_true = range_bearing(peds, np.asarray(ego))
    for i in range(2):
        z = np.array([s.Z[src == i][0] for s, src in zip(scans.scans, scans.source, strict=True)])
        e_r = z[:, 0] - r_true[i]
        e_b = wrap(z[:, 1] - b_true[i])
        for err, sigma in ((e_r, cfg.sigma_r), (e_b, cfg.sigma_b)):
            assert abs(err.mean()) < 4 * sigma / np.sqrt(N_SCANS)
            assert err.std() == pytest.approx(sigma, rel=0.1)
            assert stats.kstest(err / sigma, "norm").pvalue > 1e-3
        assert np.all((z[:, 1] > -np.pi) & (z[:, 1] <= np.pi))
    z_behind = np.array([s.Z[src == 1][0, 1] for s, src in zip(scans.scans, scans.source, strict=True)])
    assert (z_behind > 0).any() and (z_behind < 0).any()  # noise wraps across +-pi


def test_detection_rate_of_visible_targets_is_p_D():
    p_D = 0.7
    peds = np.array([[20.0, 5.0], [-10.0, -10.0], [20.0, 0.0]])  # the third hides behind the box
    scans = _observe(peds, Sensor(lambda_c=1.0, p_D=p_D), occluders=[box(9, -1, 11, 1)])
    assert scans.visible[:, :2].all() and not scans.visible[:, 2].any()
    rate = scans.detected[:, :2].mean()
    assert abs(rate - p_D) < 4 * np.sqrt(p_D * (1 - p_D) / (2 * N_SCANS))
    assert not scans.detected[:, 2].any()
    n_target_z = sum(int((src != CLUTTER).sum()) for src in scans.source)
    assert n_target_z == scans.detected.sum()


@pytest.mark.parametrize("p_D", [0.0, 1.0])
def test_detection_probability_extremes(p_D):
    rec = static_recording(np.array([[20.0, 5.0]]), 50)
    scans = observe(rec, open_scene(), Sensor(lambda_c=0.0, p_D=p_D), trial_seeds(0, 0).sensor_rngs())
    assert scans.detected.all() if p_D == 1.0 else not scans.detected.any()
