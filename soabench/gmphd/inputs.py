"""The filter's API boundary: measurements, ego pose and birth components checked before a cycle.

A NaN or inf in Z_k, in the ego pose or in a birth component would otherwise flow into the means, the weights and
the extracted states (a NaN measurement with PUBM or ATBM builds a NaN newborn). ``filter.nonfinite`` chooses:

* ``"raise"`` (default): :class:`~soabench.errors.SoabenchError` naming the scan and what is not finite. The
  simulated sensor never produces one, so a non-finite value means a broken input upstream, and a benchmark must
  not quietly score a different scan than the one it was given.
* ``"drop"``: non-finite measurements (with their newborn terms) and birth components with a non-finite or negative
  weight, mean or covariance are dropped and counted; a non-finite ego pose drops the whole scan (a missed scan:
  prediction only, no detection). For recorded sensor data, where a dropout is a fact of life.

The cost when everything is finite is one ``np.isfinite(...).all()`` per array (a few microseconds).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from soabench.config import Sensor
from soabench.errors import SoabenchError
from soabench.geometry import clutter_intensity
from soabench.types import Births, NewbornTerms, Scan, scan_once

NONFINITE_POLICIES = ("raise", "drop")


@dataclass
class StepInputs:
    """Inputs of one cycle after the check."""

    Z: np.ndarray  #: (M', 2) finite measurements
    ego: np.ndarray | None  #: (3,) finite pose, or None: the scan was dropped (no detection this cycle)
    births: Births  #: finite birth components with w >= 0 (and the matching newborn terms)
    n_dropped: int  #: measurements dropped (all of them when the pose was not finite)
    n_dropped_births: int  #: birth components dropped


def _finite(a: np.ndarray) -> bool:
    return bool(np.isfinite(a).all())


def _rows_finite(a: np.ndarray, n: int) -> np.ndarray:
    return np.isfinite(np.asarray(a, dtype=float).reshape(n, -1)).all(axis=1)


def _subset_beta(beta, keep: np.ndarray):
    """``beta(A, kappa)`` of the kept newborn terms: the dropped ones see A = 0, kappa = 1 and are discarded."""
    m_full = len(keep)

    def sub(A: np.ndarray, kappa: np.ndarray) -> np.ndarray:
        A_full = np.zeros(m_full)
        k_full = np.ones(m_full)
        A_full[keep] = A
        k_full[keep] = kappa
        return np.asarray(beta(A_full, k_full), dtype=float).reshape(m_full)[keep]

    return sub


def scan_inputs(k: int, Z_in: np.ndarray, ego_in: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(Z, ego, finite)``: the measurements as (M, 2) floats, the pose as (3,) floats (both contiguous, as the
    compiled cycle takes them), and whether both are finite. Depends on the scan alone, so the filter computes it
    once per scan for all its runs (:meth:`soabench.types.Scan.once`). A pose that is not (x, y, theta) raises."""
    Z = np.ascontiguousarray(np.asarray(Z_in, dtype=float).reshape(-1, 2))
    ego = np.asarray(ego_in, dtype=float)
    if ego.shape != (3,):
        raise SoabenchError(f"scan {k}: the ego pose has shape {ego.shape}; expected (x, y, theta)")
    ego = np.ascontiguousarray(ego)
    return Z, ego, _finite(Z) and _finite(ego)


def clutter_kappa(Z: np.ndarray, sensor: Sensor) -> np.ndarray:
    """kappa(z_l) of each measurement (§2.3, :func:`soabench.geometry.clutter_intensity`) as a contiguous array."""
    return np.ascontiguousarray(clutter_intensity(Z, sensor), dtype=float)


def scan_kappa(scan: Scan, Z: np.ndarray, sensor: Sensor) -> np.ndarray:
    """:func:`clutter_kappa` of the scan's own ``Z`` (the one :func:`scan_inputs` returned for it, kept alive by that
    entry of the scan's cache, so its id is a sound key), computed once per scan for every filter, of any family,
    with the same clutter settings. The array is shared: read it, never write it."""
    s = sensor
    key = ("filter.kappa", s.clutter_space, s.lambda_c, s.r_min, s.r_max, s.fov_deg, id(Z))
    return scan_once(scan, key, lambda: clutter_kappa(Z, sensor))


def newborn_finite(nb: NewbornTerms | None) -> bool:
    """Every mean and covariance of the newborn terms ``nb`` finite (True without newborn terms)."""
    return nb is None or (_finite(np.asarray(nb.m, dtype=float)) and _finite(np.asarray(nb.P, dtype=float)))


def births_finite(births: Births) -> bool:
    """Every weight, mean and covariance of ``births`` (and of its newborn terms) finite, every weight >= 0.
    The fused filter cycle checks the birth components in compiled code instead
    (:func:`soabench.gmphd.cycle.births_ok`, the same test) and the newborn terms with :func:`newborn_finite`."""
    ok = _finite(births.w) and _finite(births.m) and _finite(births.P) and bool((births.w >= 0).all())
    return ok and newborn_finite(births.newborn)


def check_step_inputs(
    k: int, Z: np.ndarray, ego: np.ndarray, births: Births, policy: str, scan_finite: bool | None = None
) -> StepInputs:
    """Check (and with ``policy == "drop"`` clean) the inputs of scan ``k``; see the module docstring.

    ``scan_finite``: whether Z and ego are known finite (:func:`scan_inputs`, computed once per scan); None checks
    them here."""
    if ego.shape != (3,):
        raise SoabenchError(f"scan {k}: the ego pose has shape {ego.shape}; expected (x, y, theta)")
    nb = births.newborn
    ok_scan = (_finite(Z) and _finite(ego)) if scan_finite is None else scan_finite
    if ok_scan and births_finite(births):
        return StepInputs(Z, ego, births, 0, 0)
    ok_ego = _finite(ego)

    M, J = len(Z), len(births)
    keep_z = _rows_finite(Z, M) if M else np.zeros(0, dtype=bool)
    if nb is not None and M:
        keep_z &= _rows_finite(nb.m, M) & _rows_finite(nb.P, M)
    keep_b = np.ones(J, dtype=bool)
    if J:
        keep_b = _rows_finite(births.w, J) & _rows_finite(births.m, J) & _rows_finite(births.P, J)
        keep_b &= np.asarray(births.w, dtype=float) >= 0
    if policy != "drop":
        parts = []
        if not ok_ego:
            parts.append(f"the ego pose {np.asarray(ego).tolist()!r} is not a finite (x, y, theta)")
        if M - keep_z.sum():
            parts.append(f"{M - int(keep_z.sum())} of {M} measurements (or their newborn terms) are not finite")
        if J - keep_b.sum():
            parts.append(f"{J - int(keep_b.sum())} of {J} birth components have a non-finite or negative value")
        raise SoabenchError(
            f'scan {k}: {"; ".join(parts)}; set filter.nonfinite = "drop" to drop and count such inputs'
        )

    n_births_dropped = int(J - keep_b.sum())
    if n_births_dropped:
        births = Births(births.w[keep_b], births.m[keep_b], births.P[keep_b], births.source[keep_b], births.newborn)
    if not ok_ego:  # no pose, no detection geometry: the scan is missed as a whole
        births = Births(births.w, births.m, births.P, births.source, None)
        return StepInputs(np.zeros((0, 2)), None, births, M, n_births_dropped)
    n_dropped = int(M - keep_z.sum())
    if n_dropped:
        Z = Z[keep_z]
        if nb is not None:
            nb = NewbornTerms(
                np.asarray(nb.m)[keep_z], np.asarray(nb.P)[keep_z], _subset_beta(nb.beta, keep_z), nb.adaptive
            )
            births = Births(births.w, births.m, births.P, births.source, nb)
    return StepInputs(Z, ego, births, n_dropped, n_births_dropped)
