"""Checks on what a plugin hands the harness, and the record of a plugin that failed (docs/user-guide/tracker.md).

A plugin's output is checked at every scan before anything uses it: :func:`check_births` (shapes, numeric dtypes,
finite values, weights in [0, :data:`BIRTH_W_MAX`], means within :data:`BIRTH_M_MAX`, symmetric positive definite
covariances; newborn terms: one per measurement, positive definite covariances and a ``beta`` that returns (M,)
finite non-negative values) and :func:`check_estimates` (an :class:`~soabench.types.Estimates`, not
None, (n, 2) or (n, 4) finite states, optional track labels: (n,) distinct integers). A failed check or an exception
raises, :func:`soabench.trackers.run_tracker` names the scan, and the trial keeps every other run and records
this one in :func:`failure_row` form: no row of metrics is written for a run that failed, so no zero or NaN can
pass for a result.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from soabench.trackers import step_result_from
from soabench.types import Births, Estimates, NewbornTerms, Scan, StepResult

#: columns of a failed-run record (``model_failures`` of a trial record, ``model_failures.csv`` of a run)
FAILURE_KEYS = ("trial", "clutter", "model", "mode", "kind", "k", "error")


class PluginOutputError(ValueError):
    """A plugin returned something the harness cannot use."""


def _array(value: Any, what: str, shape: tuple[int | None, ...]) -> np.ndarray:
    """``value`` as a float array of ``shape`` (None: any length), numeric and finite, or PluginOutputError."""
    if value is None:
        raise PluginOutputError(f"{what} is None")
    a = np.asarray(value)
    if a.dtype == object or not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
        raise PluginOutputError(f"{what} has dtype {a.dtype}; a real-valued numeric array is required")
    ok = a.ndim == len(shape) and all(s is None or s == n for s, n in zip(shape, a.shape, strict=False))
    if not ok:
        want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        raise PluginOutputError(f"{what} has shape {a.shape}; {want} is required")
    a = a.astype(float)
    if not np.all(np.isfinite(a)):
        raise PluginOutputError(f"{what} holds NaN or infinite values")
    return a


def _labels(value: Any, what: str, n: int) -> np.ndarray | None:
    """Optional track labels: None, or (n,) distinct integers (one per estimate) as int64; PluginOutputError
    otherwise."""
    if value is None:
        return None
    a = np.asarray(value)
    if a.shape != (n,) or not (np.issubdtype(a.dtype, np.integer) and not np.issubdtype(a.dtype, np.bool_)):
        raise PluginOutputError(
            f"{what} has shape {a.shape} and dtype {a.dtype}; ({n},) integers are required (one track label per "
            "estimate), or None for no labels"
        )
    if a.dtype == np.uint64 and a.size and int(a.max()) > np.iinfo(np.int64).max:
        raise PluginOutputError(f"{what} holds a label above {np.iinfo(np.int64).max}; labels must fit in int64")
    a = a.astype(np.int64)
    if n > 1:
        s = np.sort(a)
        dup = s[1:][s[1:] == s[:-1]]
        if len(dup):
            raise PluginOutputError(
                f"{what} gives label {int(dup[0])} to more than one estimate of the scan; a label names one track, "
                "so the labels of one scan must differ"
            )
    return a


#: the largest birth weight accepted from a plugin: the expected number of targets born in one component per scan
BIRTH_W_MAX = 100.0
#: the largest |value| of a birth mean (m, m/s) and eigenvalue of a birth covariance (m^2, (m/s)^2) accepted: beyond
#: them the filter's squares overflow
BIRTH_M_MAX = 1e7
BIRTH_P_MAX = 1e12


def check_births(births: Any, scan: Scan, plugin: str | None = None) -> Births:
    """The plugin's :class:`Births` of scan k, checked (see the module docstring); PluginOutputError otherwise, its
    message starting with the birth model's name when ``plugin`` gives it."""
    try:
        return _checked_births(births, scan)
    except PluginOutputError as exc:
        if plugin is None:
            raise
        raise PluginOutputError(f"birth model {plugin!r} at scan {scan.k}: {exc}") from None


def _spd(P: np.ndarray, what: str) -> None:
    """Each of the (J, 4, 4) ``P`` is symmetric with eigenvalues in (0, BIRTH_P_MAX]; PluginOutputError otherwise."""
    if not len(P):
        return
    if not np.allclose(P, np.swapaxes(P, 1, 2), rtol=1e-9, atol=1e-12):
        raise PluginOutputError(f"{what} holds a covariance that is not symmetric")
    eig = np.linalg.eigvalsh(P)
    j = int(np.argmin(eig[:, 0]))
    if eig[j, 0] <= 0:
        raise PluginOutputError(
            f"{what}[{j}] is not positive definite (smallest eigenvalue {eig[j, 0]:g}); a covariance must be > 0"
        )
    j = int(np.argmax(eig[:, -1]))
    if eig[j, -1] > BIRTH_P_MAX:
        raise PluginOutputError(f"{what}[{j}] has an eigenvalue of {eig[j, -1]:g}; at most {BIRTH_P_MAX:g} is allowed")


def _checked_births(births: Any, scan: Scan) -> Births:
    if births is None:
        raise PluginOutputError("the birth model returned None; return Births (Births.empty() for none)")
    if not isinstance(births, Births):
        raise PluginOutputError(f"the birth model returned {type(births).__name__}; soabench.api.Births is required")
    w = _array(births.w, "Births.w", (None,))
    J = len(w)
    m = _array(births.m, "Births.m", (J, 4))
    P = _array(births.P, "Births.P", (J, 4, 4))
    source = np.asarray(births.source)
    if source.shape != (J,) or not np.issubdtype(source.dtype, np.integer):
        raise PluginOutputError(f"Births.source has shape {source.shape} and dtype {source.dtype}; ({J},) int needed")
    if np.any(w < 0):
        raise PluginOutputError(f"Births.w has negative weights (min {w.min():g})")
    if np.any(w > BIRTH_W_MAX):
        raise PluginOutputError(
            f"Births.w[{int(np.argmax(w))}] = {w.max():g}; a birth weight is the expected number of targets born in "
            f"its component per scan, in [0, {BIRTH_W_MAX:g}]"
        )
    if np.any(np.abs(m) > BIRTH_M_MAX):
        j = int(np.argmax(np.abs(m).max(axis=1)))
        raise PluginOutputError(f"Births.m[{j}] = {m[j].tolist()}; means must lie within +-{BIRTH_M_MAX:g} (m, m/s)")
    _spd(P, "Births.P")
    newborn = births.newborn
    if newborn is not None:
        newborn = _check_newborn(newborn, len(np.asarray(scan.Z).reshape(-1, 2)))
    return Births(w, m, P, source.astype(np.int8), newborn)


def _check_newborn(nb: Any, M: int) -> NewbornTerms:
    if not isinstance(nb, NewbornTerms):
        raise PluginOutputError(f"Births.newborn is {type(nb).__name__}; soabench.api.NewbornTerms is required")
    m = _array(nb.m, "NewbornTerms.m", (M, 4))
    P = _array(nb.P, "NewbornTerms.P", (M, 4, 4))
    _spd(P, "NewbornTerms.P")
    if not callable(nb.beta):
        raise PluginOutputError("NewbornTerms.beta is not callable: beta(A, kappa) -> (M,) is required")
    beta = nb.beta

    def checked_beta(A: np.ndarray, kappa: np.ndarray) -> np.ndarray:
        out = _array(beta(A, kappa), "NewbornTerms.beta(A, kappa)", (M,))
        if np.any(out < 0):
            raise PluginOutputError(f"NewbornTerms.beta(A, kappa) is negative (min {out.min():g})")
        return out

    return NewbornTerms(m, P, checked_beta, adaptive=nb.adaptive is True)


def check_estimates(out: Any, scan: Scan, t_step: float) -> StepResult:
    """A tracker's output at scan k as the :class:`StepResult` the metrics read; PluginOutputError if unusable."""
    if isinstance(out, StepResult):
        X = _array(out.X, "StepResult.X", (None, 4))
        _labels(out.labels, "StepResult.labels", len(X))
        return out
    if out is None:
        raise PluginOutputError("the tracker returned None; return Estimates (Estimates.empty() for no target)")
    if not isinstance(out, Estimates):
        raise PluginOutputError(f"the tracker returned {type(out).__name__}; soabench.api.Estimates is required")
    X = np.asarray(out.X)
    if X.ndim != 2 or X.shape[1] not in (2, 4):
        raise PluginOutputError(f"Estimates.X has shape {X.shape}; (n, 2) positions or (n, 4) states are required")
    X = _array(X, "Estimates.X", (None, X.shape[1]))
    w = None if out.w is None else _array(out.w, "Estimates.w", (len(X),))
    if w is not None and np.any(w < 0):
        raise PluginOutputError(f"Estimates.w has negative values (min {w.min():g})")
    n_comp = out.n_components
    if n_comp is not None and not (isinstance(n_comp, (int, np.integer)) and n_comp >= 0):
        raise PluginOutputError(f"Estimates.n_components = {n_comp!r} must be an integer >= 0 or None")
    card = out.cardinality
    if card is not None and not (np.isfinite(card) and card >= 0):
        raise PluginOutputError(f"Estimates.cardinality = {card!r} must be a finite number >= 0 or None")
    labels = _labels(out.labels, "Estimates.labels", len(X))
    return step_result_from(Estimates(X, w, n_comp, card, labels), scan.k, t_step)


def failure_row(
    trial: int, clutter: float, model: str, mode: str, kind: str, k: int | None, error: str, tb: str = ""
) -> dict:
    """One failed run (``k`` None: it failed before the first scan, e.g. in its constructor); ``tb``, the plugin's
    traceback, is kept in the trial record (``trials/trial_NNNNN.json``), not in the tables."""
    return {
        "trial": int(trial),
        "clutter": float(clutter),
        "model": model,
        "mode": mode,
        "kind": kind,
        "k": -1 if k is None else int(k),
        "error": error,
        "traceback": tb,
    }


def failure_message(rec: dict) -> str:
    """One line naming the plugin, the trial and the scan."""
    where = "before the first scan" if rec["k"] < 0 else f"at scan {rec['k']}"
    return (
        f"{rec['kind']} plugin {rec['model']!r} failed in trial {rec['trial']} {where} "
        f"(clutter {rec['clutter']:g}, mode {rec['mode']}): {rec['error']}; its other runs and every other model's "
        "results are kept"
    )
