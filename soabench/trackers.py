"""Trackers: one of our filter families with a birth model and a probability mode is one; plugins and bridges are
others.

:class:`FilterTracker` wraps the cycle of docs/method.md §2.11 (birth from the context at k, then ``filter.step``)
around a filter of any family (:data:`soabench.config.FAMILIES`, built by :func:`build_filter`) behind the
:class:`~soabench.protocols.Tracker` shape. :func:`run_tracker` runs any tracker over the scans of a run
and returns one :class:`~soabench.types.StepResult` per scan, the form the metrics read: a foreign tracker's
:class:`~soabench.types.Estimates` are checked (:mod:`soabench.experiment.trial.guard`) and converted by
:func:`step_result_from`.
"""

from __future__ import annotations

import importlib
import math
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from soabench.config import FAMILIES, filter_config_for_mode
from soabench.errors import require, require_type
from soabench.protocols import FamilySetup, Filter, Tracker
from soabench.types import BirthContext, Births, Estimates, Scan, Scans, StepResult

if TYPE_CHECKING:
    from soabench.config import Config, Sensor

__all__ = [
    "FilterTracker",
    "GMPHDTracker",
    "TrackerRun",
    "build_filter",
    "family_builder",
    "run_tracker",
    "step_result_from",
]


def family_builder(family: str) -> Callable[[FamilySetup], Filter]:
    """The builder of filter family ``family`` named by its registry line (:data:`soabench.config.FAMILIES`);
    imported here, when a run builds its first filter (the families' compiled kernels would slow every start-up)."""
    require(family in FAMILIES, f"filter family {family!r} is not allowed; choose one of {', '.join(FAMILIES)}")
    module, _, attr = FAMILIES[family].build.partition(":")
    return getattr(importlib.import_module(module), attr)


def build_filter(
    family: str, config: Config, sensor: Sensor, mode: str, rng: np.random.Generator | None = None
) -> tuple[Filter, float]:
    """One run's filter of ``family`` in probability ``mode``, and the detection probability p_D_b its birth
    models read (:func:`soabench.config.filter_config_for_mode`); ``rng``: the trial's association stream (a fixed
    seed if None). A mode the family does not define is refused with one line."""
    fam = FAMILIES.get(family)
    require(fam is not None, f"filter family {family!r} is not allowed; choose one of {', '.join(FAMILIES)}")
    require(
        mode in fam.modes,
        f"probability mode {mode!r} is not defined for the {fam.label} filter; it runs {', '.join(fam.modes)}",
    )
    filter_cfg, filter_mode, p_D_b = filter_config_for_mode(config.filter, mode)
    rng = rng if rng is not None else np.random.default_rng(0)
    setup = FamilySetup(config, sensor, mode, filter_cfg, filter_mode, rng)
    return family_builder(family)(setup), p_D_b


class FilterTracker:
    """One of our filter families + one birth model + one probability mode, as a tracker.

    Args:
        birth_model: a built birth model (``model(ctx) -> Births``).
        filt: a built filter of any family (:func:`build_filter`; a :class:`~soabench.gmphd.filter.GMPHDFilter`,
            an :class:`~soabench.lmb.LMBFilter`, ...), its mode fixed.
        p_D_b: detection probability of a newborn (``soabench.config.filter_config_for_mode``).
        check_births: optional check of each scan's births (plugins are checked, built-ins are not).

    Attributes:
        t_birth: wall time spent in the birth model so far (s).
    """

    def __init__(
        self,
        birth_model: Callable[[BirthContext], Births],
        filt: Any,
        p_D_b: float,
        check_births: Callable[[Births, Scan], Births] | None = None,
    ) -> None:
        self.birth_model = birth_model
        self.filt = filt
        self.p_D_b = p_D_b
        self.check_births = check_births
        self.prev: StepResult | None = None
        self.t_birth = 0.0

    @property
    def name(self) -> str:
        """The filter family's name (``filt.name``)."""
        return str(getattr(self.filt, "name", "gmphd"))

    def __repr__(self) -> str:
        model = getattr(self.birth_model, "name", None) or type(self.birth_model).__name__
        mode = getattr(self.filt, "mode", "?")
        return f"FilterTracker(family {self.name!r}, birth model {model!r}, mode {mode!r}, p_D_b={self.p_D_b:g})"

    def step(self, scan: Scan) -> StepResult:
        """Birth from the context at k, then one filter cycle (predict, birth, update, reduce, extract)."""
        check_scan(scan)
        tb = time.perf_counter()
        births = self.birth_model(BirthContext(scan, self.prev, self.p_D_b))
        if self.check_births is not None:
            births = self.check_births(births, scan)
        self.t_birth += time.perf_counter() - tb
        self.prev = self.filt.step(scan, births)
        return self.prev


#: the former name of :class:`FilterTracker` (our GM-PHD was its only family), kept for user code
GMPHDTracker = FilterTracker


def check_scan(scan: Any) -> None:
    """WrongTypeError unless ``scan`` looks like one :class:`Scan` (a tracker steps through scans one at a time)."""
    if isinstance(scan, Scan) or (hasattr(scan, "Z") and hasattr(scan, "ego")):
        return
    hint = "step through them one at a time: for scan in scans: tracker.step(scan)" if isinstance(scan, Scans) else ""
    require_type(scan, Scan, "a tracker's step(scan) argument", hint)


def step_result_from(est: Estimates, k: int, t_step: float) -> StepResult:
    """The :class:`StepResult` the metrics read, from a checked :class:`Estimates` of scan ``k``.

    Positions pad to (n, 4) with zero velocity when only (n, 2) were given; the step time goes to ``t_update``;
    the component count is ``est.n_components`` (else the number of estimates); the cardinality is
    ``est.cardinality`` (else NaN); GM-PHD-only diagnostics (p_D, A, kappa) are NaN or empty; the track labels
    are ``est.labels`` (None: unlabelled).
    """
    X = np.asarray(est.X, dtype=float)
    if X.shape[1] == 2:
        X = np.hstack([X, np.zeros((len(X), 2))])
    w = np.full(len(X), math.nan) if est.w is None else np.asarray(est.w, dtype=float).reshape(-1)
    n_comp = len(X) if est.n_components is None else int(est.n_components)
    card = math.nan if est.cardinality is None else float(est.cardinality)
    return StepResult(
        k=k,
        X=X,
        X_w=w,
        sum_w=card,
        sum_w_reduced=card,
        n_predicted=n_comp,
        n_updated=n_comp,
        n_reduced=n_comp,
        cap_hit=False,
        t_predict=0.0,
        t_update=t_step,
        t_reduce=0.0,
        mean_pD=math.nan,
        A=np.zeros(0),
        kappa=np.zeros(0),
        labels=None if est.labels is None else np.asarray(est.labels, dtype=np.int64).reshape(-1),
    )


@dataclass
class TrackerRun:
    """The step results of one tracker run and its wall-clock birth and total times (s)."""

    results: list[StepResult]
    t_birth: float
    t_total: float


class ScanFailure(Exception):
    """A tracker or birth model raised, or returned something unusable, at scan ``k`` (wraps the cause)."""

    def __init__(self, k: int, message: str, tb: str = "") -> None:
        super().__init__(message)
        self.k = k
        self.message = message
        self.traceback = tb


def run_tracker(
    scans: Scans, tracker: Tracker | FilterTracker, check: Callable[[Any, Scan, float], StepResult] | None = None
) -> TrackerRun:
    """Run ``tracker.step`` over every scan in order; one :class:`StepResult` per scan.

    ``check(out, scan, t_step)`` validates a plugin's output and converts :class:`Estimates` to a
    :class:`StepResult` (without ``check``, ``step`` must return StepResults: our GM-PHD). With ``check`` given,
    any exception at scan k becomes a :class:`ScanFailure` naming k (with its traceback), so the caller can record it
    and keep the other runs of the trial.

    Example:
        >>> import soabench.api as sb
        >>> _, scans = sb.simulate_trial("arterial", duration=5)
        >>> run = sb.run_tracker(scans, sb.make_tracker("soa", "arterial"))
        >>> len(run.results) == len(scans)
        True
    """
    results: list[StepResult] = []
    t0 = time.perf_counter()
    for scan in scans.scans:
        ts = time.perf_counter()
        if check is None:
            results.append(tracker.step(scan))
            continue
        try:
            out = tracker.step(scan)
            dt = time.perf_counter() - ts
            results.append(check(out, scan, dt))
        except ScanFailure:
            raise
        except Exception as exc:
            raise ScanFailure(scan.k, f"{type(exc).__name__}: {exc}", traceback.format_exc()) from exc
    return TrackerRun(results, float(getattr(tracker, "t_birth", 0.0)), time.perf_counter() - t0)
