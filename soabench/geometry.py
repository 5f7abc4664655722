"""Shared sensor geometry (docs/method.md §2.1, §2.3): one definition used by the simulator, the filter and the
birth models, so that "the filter model equals the simulator model".
"""

from __future__ import annotations

import numpy as np

from soabench.config import Sensor, SensorConfig


def wrap(a: np.ndarray | float) -> np.ndarray:
    """Map angles to (-pi, pi] (§2.1 ``wrap``)."""
    a = np.asarray(a, dtype=float)
    if a.ndim == 0:
        out = np.mod(a + np.pi, 2.0 * np.pi) - np.pi
        return np.where(out == -np.pi, np.pi, out)
    out = a + np.pi  # the same operations as above, in place on one new array
    np.mod(out, 2.0 * np.pi, out=out)
    out -= np.pi
    out[out == -np.pi] = np.pi
    return out


def range_bearing(xy: np.ndarray, ego: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """h(x) without noise (§2.3): range r and bearing b = wrap(atan2(dy, dx) - theta_e) of points ``xy`` (..., 2).

    ``ego``: one pose (3,), or one pose per point (..., 3) broadcast against ``xy``."""
    e = np.asarray(ego, dtype=float)
    d = np.asarray(xy, dtype=float)[..., :2] - e[..., :2]
    r = np.hypot(d[..., 0], d[..., 1])
    b = wrap(np.arctan2(d[..., 1], d[..., 0]) - e[..., 2])
    return r, b


def fov_mask(xy: np.ndarray, ego: np.ndarray, cfg: SensorConfig, inset: float = 0.0) -> np.ndarray:
    """FOV_k membership (§2.3): r_min + inset <= r <= r_max - inset and |b| <= Theta/2, for points (..., 2).

    ``ego``: one pose (3,), or one pose per point (..., 3) broadcast against ``xy``."""
    if cfg.fov_deg >= 360.0:  # the range alone decides (the bearing of range_bearing is not needed)
        d = np.asarray(xy, dtype=float)[..., :2] - np.asarray(ego, dtype=float)[..., :2]
        r = np.hypot(d[..., 0], d[..., 1])
        return (r >= cfg.r_min + inset) & (r <= cfg.r_max - inset)
    r, b = range_bearing(xy, ego)
    ok = (r >= cfg.r_min + inset) & (r <= cfg.r_max - inset)
    ok &= np.abs(b) <= 0.5 * cfg.fov + 1e-12
    return ok


def polar_to_world(Z: np.ndarray, ego: np.ndarray) -> np.ndarray:
    """Inverse measurement (§3.2): world (x, y) of (range, bearing) rows ``Z`` (M, 2) seen from ``ego``."""
    Z = np.asarray(Z, dtype=float).reshape(-1, 2)
    phi = Z[:, 1] + float(ego[2])
    return np.column_stack([ego[0] + Z[:, 0] * np.cos(phi), ego[1] + Z[:, 0] * np.sin(phi)])


def inverse_measurement_cov(Z: np.ndarray, ego: np.ndarray, cfg: SensorConfig) -> np.ndarray:
    """Position covariance J R J^T (M, 2, 2) of the inverse measurement of each row of ``Z`` (§3.2, T20)."""
    Z = np.asarray(Z, dtype=float).reshape(-1, 2)
    phi = Z[:, 1] + float(ego[2])
    r = Z[:, 0]
    c, s = np.cos(phi), np.sin(phi)
    J = np.stack([np.stack([c, -r * s], -1), np.stack([s, r * c], -1)], -2)
    R = np.diag([cfg.sigma_r**2, cfg.sigma_b**2])
    return J @ R @ np.swapaxes(J, -1, -2)


def measurement_volume(cfg: SensorConfig) -> float:
    """|V_z| = (r_max - r_min) * Theta in m*rad (§2.3)."""
    return (cfg.r_max - cfg.r_min) * cfg.fov


def fov_area(cfg: SensorConfig) -> float:
    """Cartesian FOV area A = Theta (r_max^2 - r_min^2) / 2 (§2.3, §3.2 variant ``cart``)."""
    return 0.5 * cfg.fov * (cfg.r_max**2 - cfg.r_min**2)


def clutter_intensity(Z: np.ndarray, cfg: Sensor) -> np.ndarray:
    """kappa(z_l) for each row of ``Z`` (M, 2) (§2.3).

    ``polar``: lambda / |V_z| (uniform in (r, b)); ``cartesian``: lambda * r / A (uniform in area).
    """
    Z = np.asarray(Z, dtype=float).reshape(-1, 2)
    if cfg.clutter_space == "polar":
        return np.full(len(Z), cfg.lambda_c / measurement_volume(cfg))
    return cfg.lambda_c * Z[:, 0] / fov_area(cfg)
