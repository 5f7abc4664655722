"""Detection and survival probabilities: the static mode and the Beta "dynamic" mode (docs/method.md §4).

* :func:`detection_gate` is g(x) of §4.1/§4.4 at the component means: the FOV indicator, times the line-of-sight
  indicator when ``occlusion_pd`` is on (:func:`scan_line_of_sight`: the scan's sight blockers built once for
  every run over it).
* :func:`beta_inflate`, :func:`beta_survival_predict` are the Beta prediction of §4.2 (p_D) and §4.3 (p_S).
* :func:`beta_moment_match` is the Beta merge of §4.5.

The Beta detection update itself (missed: t <- t + g; detected: s <- s + 1) is applied inside
:func:`soabench.gmphd.models.update`, where the (j, l) pairs are formed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from soabench.config import FilterConfig, SensorConfig
from soabench.geometry import fov_mask
from soabench.sensor import line_of_sight, line_of_sight_past, sight_blockers
from soabench.types import scan_once

_TINY = 1e-300


def detection_gate(
    m: np.ndarray, ego: np.ndarray, sensor_cfg: SensorConfig, occluders: list | None = None, scan: Any = None
) -> np.ndarray:
    """g(m_j) (J,) in {0, 1}: 1[m_j in FOV_k] (§4.1; includes r >= r_min), times line of sight (§4.4) if given.

    ``occluders`` (shapely polygons) switches on the ``occlusion_pd`` gate: a mean whose segment from the sensor
    runs through an occluder (more than 1e-9 m inside it; grazing is visible) gets g = 0
    (:func:`soabench.sensor.line_of_sight`). With the ``scan`` they are that scan's occluders, tested through
    :func:`scan_line_of_sight` (the same result).
    """
    m = np.asarray(m, dtype=float).reshape(-1, 4)
    g = fov_mask(m[:, :2], ego, sensor_cfg)
    if occluders and g.any():
        idx = np.flatnonzero(g)
        if scan is not None:
            vis = scan_line_of_sight(scan, ego, m[idx, :2])
        else:
            vis = np.asarray(line_of_sight(np.asarray(ego[:2], dtype=float), m[idx, :2], occluders), dtype=bool)
        g[idx] = vis.reshape(-1)
    return g.astype(float)


def scan_line_of_sight(scan: Any, ego: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) bool: :func:`soabench.sensor.line_of_sight` of ``points`` from the pose ``ego`` against
    ``scan.occluders``, with the occluders that can hide a point from that pose (:func:`soabench.sensor.sight_blockers`)
    prepared once per scan and pose and shared by every run over the scan (docs/method.md §5.8): the same result as
    testing them afresh, without rebuilding them in every filter of every birth model."""
    ego = np.asarray(ego, dtype=float)
    make = lambda: (sight_blockers(ego[:2], scan.occluders), scan.occluders)  # noqa: E731
    key = ("filter.sight_blockers", id(scan.occluders), len(scan.occluders), ego[0], ego[1])
    blockers = scan_once(scan, key, make)[0]
    return np.asarray(line_of_sight_past(ego[:2], points, blockers), dtype=bool)


def beta_mean(s: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Point estimate s / (s + t) of a Beta(s, t) probability (§4.2)."""
    return s / (s + t)


def beta_var(s: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Variance s t / ((s + t)^2 (s + t + 1)) of Beta(s, t)."""
    n = s + t
    return s * t / (n * n * (n + 1.0))


def beta_inflate(s: np.ndarray, t: np.ndarray, f: float, theta_min: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean-preserving variance inflation of §4.2 (Vo's ``beta_factor``), with the guard theta >= theta_min.

    mu = s/(s+t); theta = mu(1-mu)/min(f var, mu(1-mu)) - 1; theta <- max(theta, theta_min); (theta mu, theta(1-mu)).
    """
    mu = beta_mean(s, t)
    v = mu * (1.0 - mu)
    theta = v / np.maximum(np.minimum(f * beta_var(s, t), v), _TINY) - 1.0
    theta = np.maximum(theta, theta_min)
    return theta * mu, theta * (1.0 - mu)


def beta_survival_predict(
    sS: np.ndarray, tS: np.ndarray, f: float, theta_min: float, p_S_max: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Survival part of the dynamic prediction (§4.3): returns (weight factor, sS', tS').

    w <- w sS/(sS+tS); sS <- sS + 1; inflate (f, theta_min); cap the mean at p_S_max keeping sS + tS.
    """
    factor = beta_mean(sS, tS)
    s, t = beta_inflate(sS + 1.0, tS, f, theta_min)
    n = s + t
    over = s > p_S_max * n
    s = np.where(over, p_S_max * n, s)
    t = np.where(over, (1.0 - p_S_max) * n, t)
    return factor, s, t


def beta_predict(beta: np.ndarray, cfg: FilterConfig) -> tuple[np.ndarray, np.ndarray]:
    """Dynamic-mode prediction of the Beta columns (sD, tD, sS, tS) (J, 4): returns (p_S factor (J,), new beta).

    p_D: inflation only (§4.2); p_S: size-biased update, inflation and cap (§4.3).
    """
    out = np.empty_like(beta)
    out[:, 0], out[:, 1] = beta_inflate(beta[:, 0], beta[:, 1], cfg.beta_factor, cfg.theta_min)
    factor, out[:, 2], out[:, 3] = beta_survival_predict(
        beta[:, 2], beta[:, 3], cfg.beta_factor, cfg.theta_min, cfg.p_S_max
    )
    return factor, out


def beta_prior(cfg: FilterConfig) -> np.ndarray:
    """Birth Beta parameters (sD, tD, sS, tS) = (n_D mu_D0, n_D (1-mu_D0), n_S mu_S0, n_S (1-mu_S0)) (§4.2, §4.3)."""
    return np.array(
        [cfg.n_D * cfg.mu_D0, cfg.n_D * (1.0 - cfg.mu_D0), cfg.n_S * cfg.mu_S0, cfg.n_S * (1.0 - cfg.mu_S0)]
    )


def beta_moment_match(
    w_sum: np.ndarray, w_mu: np.ndarray, w_second: np.ndarray, theta_min: float
) -> tuple[np.ndarray, np.ndarray]:
    """Beta merge by weighted moment matching (§4.5), from group sums.

    Args: ``w_sum = sum w_i``, ``w_mu = sum w_i mu_i``, ``w_second = sum w_i (var_i + mu_i^2)`` per group.
    mu = w_mu / w_sum; v = w_second / w_sum - mu^2; theta = max(mu(1-mu)/v - 1, theta_min); (theta mu, theta(1-mu)).
    """
    mu = w_mu / w_sum
    v = np.maximum(w_second / w_sum - mu * mu, _TINY)
    theta = np.maximum(mu * (1.0 - mu) / v - 1.0, theta_min)
    return theta * mu, theta * (1.0 - mu)
