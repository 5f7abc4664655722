"""GM-PHD filter cycle (docs/method.md §2.11). CONTRACT: ``GMPHDFilter`` and ``StepResult`` signatures are fixed.

Usage per trial and (birth model x probability mode)::

    filt = GMPHDFilter(cfg.filter, cfg.sensor_at(), mode="static")      # or "dynamic", "dynamic+occ"
    prev = None
    for scan in scans.scans:
        births = birth_model(BirthContext(scan, prev))
        prev = filt.step(scan, births)                              # predict, append/inject births, update,
                                                                     # reduce, extract

Mode "static": p_S = 0.99, p_D = 0.98 g(x) (§4.1); "dynamic": Beta p_D and Beta p_S (§4.2-4.5); "dynamic+occ":
dynamic with the line-of-sight gate (§4.4). Static mode also honours ``FilterConfig.occlusion_pd``.

Choice [D]: in dynamic mode, appended birth components get the Beta priors (n_D, mu_D0), (n_S, mu_S0); a
measurement-driven newborn (PUBM/ATBM) is born *from* a detection, so it carries the detection-updated p_D Beta
(s_D0 + 1, t_D0) (and n_det = 1), exactly as if a prior-Beta birth component at z had been detected.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from soabench import notice
from soabench.config import PROBABILITY_MODES, FilterConfig, Sensor
from soabench.errors import SoabenchError, require
from soabench.geometry import clutter_intensity
from soabench.gmphd import cycle, reduction
from soabench.gmphd.inputs import StepInputs, check_step_inputs, clutter_kappa, newborn_finite, scan_inputs, scan_kappa
from soabench.gmphd.mixture import Mixture
from soabench.gmphd.models import cv_model, gate_threshold, measurement_noise, predict, update
from soabench.gmphd.probabilities import beta_mean, beta_predict, beta_prior, detection_gate, scan_line_of_sight
from soabench.gmphd.reduction import extract_labelled, prune_merge_cap
from soabench.origins import origin_counts
from soabench.types import (
    SOURCE_MEAS,
    SOURCE_NAMES,
    Births,
    StepResult,
    scan_once,
)

if TYPE_CHECKING:
    from soabench.types import Scan


class GMPHDFilter:
    """The GM-PHD filter cycle of §2.11 for one run: ``step(scan, births)`` once per scan.

    Args:
        filter_cfg: filter settings (form, p_S, p_D, T, U, J_max, gate, extraction, Beta parameters, ...).
        sensor_cfg: sensor model (dt, FOV, R, clutter rate) shared with the simulator (§2.3).
        mode: "static", "dynamic", "dynamic+occ" or "static+occ" (§4.6).
        fused: run the cycle as compiled calls over arrays (:mod:`soabench.gmphd.cycle`); False takes the array
            path of :mod:`soabench.gmphd.models` and :mod:`soabench.gmphd.reduction`, which is the reference the
            fused cycle is tested against (same results to 1e-12).

    Attributes:
        mixture: the current posterior (after reduction); empty at k = 0.
        next_label: the next fresh track label of this run (§2.13): 1 at k = 0, advanced by every birth component,
            every newborn term and every fresh label of an extraction.
    """

    name = "gmphd"

    def __init__(
        self, filter_cfg: FilterConfig, sensor_cfg: Sensor, mode: str = "static", *, fused: bool = True
    ) -> None:
        require(
            mode in PROBABILITY_MODES,
            f"probability mode {mode!r} is not allowed; choose one of {', '.join(map(repr, PROBABILITY_MODES))}",
        )
        filter_cfg.validate()
        sensor_cfg.validate()
        self.cfg = filter_cfg
        self.sensor = sensor_cfg
        self.mode = mode
        self.dynamic = mode.startswith("dynamic")
        self.occlusion = mode.endswith("+occ") or filter_cfg.occlusion_pd
        self.F, self.Q = cv_model(sensor_cfg.dt, filter_cfg.sigma_a)
        self.R = measurement_noise(sensor_cfg.sigma_r, sensor_cfg.sigma_b)
        self.gate_thr = gate_threshold(filter_cfg.gate, filter_cfg.gate_prob)
        self.beta0 = beta_prior(filter_cfg) if self.dynamic else None
        self.beta_newborn = None
        if self.dynamic:
            self.beta_newborn = self.beta0.copy()
            self.beta_newborn[0] += 1.0
        self.mixture = Mixture.empty(self.dynamic)
        self.next_label = 1
        self.fused = bool(fused)
        self._ukf = filter_cfg.form == "ukf"
        self._init_fused()

    def _init_fused(self) -> None:
        """What every fused step passes to :mod:`soabench.gmphd.cycle` and needs no recomputing per step: the
        scalars of the prediction and of the reduction packed as the compiled calls take them (their ``PRED_*`` and
        ``RED_*`` indices) and empty birth arrays. Like R and the gate threshold they are read from the configurations
        once, here."""
        c, s = self.cfg, self.sensor
        pred = np.empty(8)
        pred[cycle.PRED_P_S] = c.p_S
        pred[cycle.PRED_BETA_FACTOR], pred[cycle.PRED_THETA_MIN], pred[cycle.PRED_P_S_MAX] = (
            c.beta_factor,
            c.theta_min,
            c.p_S_max,
        )
        pred[cycle.PRED_R_MIN], pred[cycle.PRED_R_MAX] = s.r_min, s.r_max
        pred[cycle.PRED_HALF_FOV], pred[cycle.PRED_LIMITED] = 0.5 * s.fov + 1e-12, float(s.fov_deg < 360.0)
        self._pred_pars = pred
        red = np.empty(8)
        red[cycle.RED_MAX_AGE] = -1 if c.max_undetected_birth_age is None else int(c.max_undetected_birth_age)
        red[cycle.RED_T], red[cycle.RED_U], red[cycle.RED_J_MAX] = c.prune_T, c.merge_U, int(c.J_max)
        red[cycle.RED_THETA_MIN], red[cycle.RED_EXTRACT_THR] = c.theta_min, c.extract_thr
        red[cycle.RED_VO_MA], red[cycle.RED_N_SOURCES] = float(c.extraction == "vo_ma"), len(SOURCE_NAMES)
        self._red_pars = red
        self._vo_ma = c.extraction == "vo_ma"
        self._p_D = float(c.p_D)
        self._r_min = float(s.r_min)
        self._gate = float(self.gate_thr)
        self._no_births = (np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4, 4)), np.zeros(0, dtype=np.int8))
        self._beta0 = self.beta0 if self.dynamic else np.empty(0)
        self._nb_beta = self.beta_newborn if self.dynamic else np.empty(0)

    def reset(self) -> None:
        """Forget the posterior and restart the label counter (next step is k = 0 again)."""
        self.mixture = Mixture.empty(self.dynamic)
        self.next_label = 1

    def _predict(self, births: Births) -> Mixture:
        """Step 1-2 of §2.11: predict the persistent mixture (§2.5, §4.3) and append the birth components, labelled
        ``next_label``, ``next_label + 1``, ... (§2.13)."""
        mix = self.mixture
        if self.dynamic and len(mix):
            p_S, beta = beta_predict(mix.beta, self.cfg)
            mix = predict(mix, self.F, self.Q, p_S)
            mix.beta = beta
        else:
            mix = predict(mix, self.F, self.Q, self.cfg.p_S)
        if len(births):
            fresh = np.arange(self.next_label, self.next_label + len(births), dtype=np.int64)
            born = Mixture.from_arrays(
                births.w, births.m, births.P, origin=births.source, n_det=0, age=0, beta=self.beta0, label=fresh
            )
            mix = Mixture.concatenate([mix, born]) if len(mix) else born
        return mix

    def step(self, scan: Scan, births: Births) -> StepResult:
        """One cycle of §2.11: predict (dt), append ``births``, update with ``scan.Z`` (incl. ``births.newborn``)
        relative to ``scan.ego``, prune/merge/cap, extract.

        Non-finite inputs raise :class:`~soabench.errors.SoabenchError` or are dropped and counted, as
        ``filter.nonfinite`` says (:mod:`soabench.gmphd.inputs`); a result never holds a NaN."""
        key = ("filter.scan_inputs", id(scan.Z), id(scan.ego))
        Z, ego, finite, _ = scan_once(scan, key, _scan_inputs_of(scan))
        kind = (self.fused, births.newborn is not None)
        if not notice.ready(kind):  # the first step of a kind may compile kernels: never a silent pause
            with notice.first_use_notice(kind):
                return self._step(scan, Z, ego, finite, births)
        return self._step(scan, Z, ego, finite, births)

    def _step(self, scan: Scan, Z: np.ndarray, ego: np.ndarray, finite: bool, births: Births) -> StepResult:
        """Check the inputs (:mod:`soabench.gmphd.inputs`) and run the cycle on the fused or the array path.

        On the fused path with a finite scan the birth components are checked inside the compiled prediction
        (:func:`soabench.gmphd.cycle.births_ok`) and the newborn terms here; only inputs that fail take
        :func:`~soabench.gmphd.inputs.check_step_inputs`, which raises or drops exactly as it does for the array
        path (the compiled check tests the same values: finite, weights >= 0)."""
        if self.fused and finite and newborn_finite(births.newborn):
            res = self._step_fused(scan, Z, ego, births)
            if res is not None:  # None: a birth component is not finite or has a negative weight
                return res
        checked = check_step_inputs(scan.k, Z, ego, births, self.cfg.nonfinite, finite)
        if self.fused and checked.ego is not None:  # a dropped scan (no pose) takes the array path
            res = self._step_fused(scan, checked.Z, checked.ego, checked.births, kappa_once=False)
            if res is None:  # cannot happen: check_step_inputs kept only finite births with w >= 0
                raise RuntimeError(f"scan {scan.k}: checked birth components failed the compiled input check")
            res.n_dropped, res.n_dropped_births = checked.n_dropped, checked.n_dropped_births
            return res
        return self._step_array(scan, checked)

    def _mean_pD(self) -> float:
        """The posterior's weighted mean detection probability: the Beta means in dynamic mode (§4.2; mu_D0 for an
        empty mixture), p_D otherwise. Both paths read it from ``self.mixture`` after the reduction."""
        cfg = self.cfg
        if not self.dynamic:
            return cfg.p_D
        w = self.mixture.w
        return float(w @ beta_mean(self.mixture.sD, self.mixture.tD) / w.sum()) if w.sum() > 0 else cfg.mu_D0

    def _step_array(self, scan: Scan, checked: StepInputs) -> StepResult:
        """:meth:`step` on the array path (:mod:`soabench.gmphd.models`, :mod:`soabench.gmphd.reduction`)."""
        cfg = self.cfg
        Z, births = checked.Z, checked.births
        ego = checked.ego if checked.ego is not None else np.zeros(3)
        t0 = time.perf_counter()
        mix = self._predict(births)
        n_predicted = len(mix) + (len(Z) if births.newborn is not None else 0)
        t1 = time.perf_counter()

        if checked.ego is None:  # a dropped scan: no detection geometry, prediction only
            g = np.zeros(len(mix))
        else:
            g = detection_gate(mix.m, ego, self.sensor, scan.occluders if self.occlusion else None, scan)
        p_D = g * beta_mean(mix.sD, mix.tD) if self.dynamic else g * cfg.p_D
        kappa = clutter_intensity(Z, self.sensor)
        up = update(
            mix,
            Z,
            ego,
            p_D,
            kappa,
            self.R,
            g=g,
            form=cfg.form,
            gate_thr=self.gate_thr,
            r_min=self.sensor.r_min,
            newborn=births.newborn,
            newborn_beta=self.beta_newborn,
            newborn_label0=self.next_label + len(births),
        )
        post = up.mix
        t2 = time.perf_counter()

        if cfg.max_undetected_birth_age is not None and len(post):
            keep = ~((post.n_det == 0) & (post.age > cfg.max_undetected_birth_age))
            if not keep.all():
                post = post.select(keep)
        red = prune_merge_cap(post, cfg.prune_T, cfg.merge_U, cfg.J_max, cfg.theta_min)
        self.mixture = red.mix
        next_label = self.next_label + len(births) + (len(Z) if births.newborn is not None else 0)
        X, X_w, X_label, self.next_label = extract_labelled(red.mix, cfg.extract_thr, cfg.extraction, next_label)
        t3 = time.perf_counter()

        w = red.mix.w
        if not (np.isfinite(w).all() and np.isfinite(X).all()):  # finite inputs must give a finite posterior
            raise SoabenchError(f"scan {scan.k}: the filter produced a non-finite posterior from finite inputs")
        return StepResult(
            k=scan.k,
            X=X,
            X_w=X_w,
            sum_w=float(up.mix.w.sum()),
            sum_w_reduced=float(w.sum()),
            n_predicted=n_predicted,
            n_updated=len(up.mix),
            n_reduced=len(red.mix),
            cap_hit=red.cap_hit,
            t_predict=t1 - t0,
            t_update=t2 - t1,
            t_reduce=t3 - t2,
            mean_pD=self._mean_pD(),
            A=up.A,
            kappa=np.asarray(kappa, dtype=float),
            n_pruned=red.n_pruned,
            n_merged=red.n_merged,
            n_pairs=up.n_pairs,
            n_newborn=up.n_newborn,
            n_dropped=checked.n_dropped,
            n_dropped_births=checked.n_dropped_births,
            origin_counts=origin_counts(red.mix.origin, red.mix.age),
            labels=X_label,
        )

    def _step_fused(
        self, scan: Scan, Z: np.ndarray, ego: np.ndarray, births: Births, kappa_once: bool = True
    ) -> StepResult | None:
        """:meth:`step` as compiled calls (:mod:`soabench.gmphd.cycle`) on finite (checked) ``Z`` and ``ego``
        (contiguous float arrays, :func:`~soabench.gmphd.inputs.scan_inputs`); None, having changed nothing, if a
        birth component is not finite or has a negative weight.

        One call (:func:`~soabench.gmphd.cycle.step`) runs the whole cycle. The line-of-sight gate (shapely) of the
        occlusion-aware mode and the newborn terms' ``beta(A, kappa)`` (caller code) stay in Python, so a step that
        needs either is split around them (:meth:`_step_fused_split`). The stage times are read inside the
        compiled calls.

        ``kappa_once``: ``Z`` is the scan's own (not a subset left by dropping inputs), so kappa is computed once per
        scan for every filter with the same clutter settings."""
        if kappa_once:  # the scan's Z is kept alive by its scan_inputs entry, so its id is a sound key
            kappa = scan_kappa(scan, Z, self.sensor)
        else:
            kappa = self._kappa(Z)
        if births.newborn is not None or (self.occlusion and scan.occluders):
            return self._step_fused_split(scan, Z, ego, births, kappa)
        mix = self.mixture
        status, n_predicted, n_updated, n_pairs, A, reduced, times = cycle.step(
            *_mixture_arrays(mix), self.F, self.Q,
            self._pred_pars, *(_birth_arrays(births) if len(births) else self._no_births), self._beta0, ego,
            self._p_D, Z, self.R, self._r_min, self._gate, kappa, self._ukf, self._red_pars, self.next_label,
        )  # fmt: skip
        if status == cycle.STEP_BAD_BIRTHS:
            return None
        if status == cycle.STEP_NOT_PD:  # UKF with a covariance that is not positive definite: the array path's rule
            return self._step_array(scan, StepInputs(Z, ego, births, 0, 0))
        return self._fused_result(scan, reduced, times[0], times[1], times[2], n_predicted, n_updated, n_pairs, 0,
                                  A, kappa)  # fmt: skip

    def _step_fused_split(
        self, scan: Scan, Z: np.ndarray, ego: np.ndarray, births: Births, kappa: np.ndarray
    ) -> StepResult | None:
        """:meth:`_step_fused` for a step with the line-of-sight gate or newborn terms: predict; the gate; the
        update (with the newborn terms' ``beta`` between its two halves); the reduction with the update's last call."""
        mix = self.mixture
        t0 = time.perf_counter()
        pred = cycle.predict_append(
            *_mixture_arrays(mix), self.F, self.Q,
            self._pred_pars, *(_birth_arrays(births) if len(births) else self._no_births), self._beta0, ego,
            self.next_label,
        )  # fmt: skip
        if not pred[9]:
            return None
        g = pred[8]
        label0 = self.next_label + len(births)  # the first label after the birth components' (§2.13)
        newborn = births.newborn
        n_predicted = len(g) + (len(Z) if newborn is not None else 0)
        if self.occlusion and scan.occluders and g.any():  # line-of-sight gate (§4.4), as detection_gate
            idx = np.flatnonzero(g)
            g[idx] = scan_line_of_sight(scan, ego, pred[1][idx, :2]).reshape(-1)
        t1 = time.perf_counter()

        if newborn is None:
            status, n_updated, n_pairs, A, reduced, times = cycle.update_reduce(
                *pred[:9], self._p_D, Z, ego, self.R, self._r_min, self._gate, kappa, self._ukf, self._red_pars, label0
            )
            if status == cycle.STEP_NOT_PD:
                return self._step_array(scan, StepInputs(Z, ego, births, 0, 0))
            n_newborn, t_update, t_reduce = 0, times[0], times[1]
        else:
            sup = cycle.support(
                pred[0], pred[1], pred[2], pred[6], g, self._p_D, Z, ego, self.R, self._r_min, self._gate, kappa,
                self._ukf,
            )  # fmt: skip
            if not sup[12]:
                return self._step_array(scan, StepInputs(Z, ego, births, 0, 0))
            A = sup[11]
            M = len(Z)
            beta_nb = np.zeros(0)
            if M:  # a copy of kappa: the newborn terms are caller code, and kappa is shared across filters
                beta_nb = np.asarray(newborn.beta(A, kappa.copy()), dtype=float).reshape(M)
                beta_nb = np.where(beta_nb > 0.0, beta_nb, 0.0)  # a newborn term is a non-negative intensity
            t2 = time.perf_counter()
            n_updated, n_pairs, n_newborn, reduced, times = cycle.posterior_reduce(
                *pred[:8],
                sup,
                self.R,
                beta_nb,
                _writable(np.ascontiguousarray(newborn.m, dtype=float).reshape(-1, 4)),
                _writable(np.ascontiguousarray(newborn.P, dtype=float).reshape(-1, 4, 4)),
                self._nb_beta,
                SOURCE_MEAS,
                self._red_pars,
                label0,
            )
            t_update, t_reduce = t2 - t1 + times[0], times[1]
        return self._fused_result(scan, reduced, t1 - t0, t_update, t_reduce, n_predicted, n_updated, n_pairs,
                                  n_newborn, A, kappa)  # fmt: skip

    def _fused_result(
        self,
        scan: Scan,
        reduced: tuple,
        t_predict: float,
        t_update: float,
        t_reduce: float,
        n_predicted: int,
        n_updated: int,
        n_pairs: int,
        n_newborn: int,
        A: np.ndarray,
        kappa: np.ndarray,
    ) -> StepResult:
        """Keep the reduced posterior of a fused step, extract (unless Vo-Ma extraction ran compiled), and report."""
        red, X, X_w, X_label, counts, (sum_w, n_pruned, n_merged, cap_hit, next_label) = reduced
        if cap_hit:
            cfg = self.cfg
            reduction.log.info("J_max = %d hit: %d components reduced to %d", cfg.J_max, n_merged, cfg.J_max)
        self.mixture = Mixture(*red[:6], red[6] if self.dynamic else None, red[7])
        self.next_label = next_label
        if not self._vo_ma:
            t = time.perf_counter()
            X, X_w, X_label, self.next_label = extract_labelled(
                self.mixture, self.cfg.extract_thr, self.cfg.extraction, next_label
            )
            t_reduce += time.perf_counter() - t
        w = red[0]
        return StepResult(
            k=scan.k,
            X=X,
            X_w=X_w,
            sum_w=sum_w,
            sum_w_reduced=float(w.sum()),
            n_predicted=n_predicted,
            n_updated=n_updated,
            n_reduced=len(w),
            cap_hit=cap_hit,
            t_predict=t_predict,
            t_update=t_update,
            t_reduce=t_reduce,
            mean_pD=self._mean_pD(),
            A=A,
            kappa=kappa,
            n_pruned=n_pruned,
            n_merged=n_merged,
            n_pairs=n_pairs,
            n_newborn=n_newborn,
            origin_counts=counts,
            labels=X_label,
        )

    def _kappa(self, Z: np.ndarray) -> np.ndarray:
        """kappa(z_l) of each measurement (:func:`soabench.gmphd.inputs.clutter_kappa`)."""
        return clutter_kappa(Z, self.sensor)


def _scan_inputs_of(scan: Scan) -> Callable[[], tuple]:
    """``make()`` -> :func:`soabench.gmphd.inputs.scan_inputs` of ``scan`` plus the scan's own Z and ego arrays,
    held with the result so that the ids in its cache key (:meth:`soabench.types.Scan.once`) stay theirs."""
    return lambda: (*scan_inputs(scan.k, scan.Z, scan.ego), (scan.Z, scan.ego))


def _birth_arrays(births: Births) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The birth components as :func:`soabench.gmphd.cycle.predict_append` takes them: contiguous w (J_b,),
    m (J_b, 4), P (J_b, 4, 4) float and source codes (J_b,) int8."""
    return (
        np.ascontiguousarray(births.w, dtype=float).reshape(-1),
        np.ascontiguousarray(births.m, dtype=float).reshape(-1, 4),
        np.ascontiguousarray(births.P, dtype=float).reshape(-1, 4, 4),
        np.ascontiguousarray(births.source, dtype=np.int8).reshape(-1),
    )


def _writable(a: np.ndarray) -> np.ndarray:
    """``a`` as a writable array (a copy when ``a`` is read-only, e.g. a birth model's shared scan arrays): numba
    compiles one specialisation per writability, and :func:`soabench.gmphd.cycle.update` hands
    :func:`~soabench.gmphd.cycle.posterior` writable (empty) newborn arrays, so with writable newborn terms the
    newborn step links that same specialisation instead of compiling a second one. The compiled cycle only reads
    them."""
    return a if a.flags.writeable else a.copy()


def _mixture_arrays(mix: Mixture) -> tuple[np.ndarray, ...]:
    """A mixture's arrays as :mod:`soabench.gmphd.cycle` takes them (contiguous, float / int8 / int32; Beta (J, 4)
    or (0, 0); labels int64): no copy for the mixtures the cycle itself produced."""
    return (
        np.ascontiguousarray(mix.w, dtype=float),
        np.ascontiguousarray(mix.m, dtype=float),
        np.ascontiguousarray(mix.P, dtype=float),
        np.ascontiguousarray(mix.origin, dtype=np.int8),
        np.ascontiguousarray(mix.n_det, dtype=np.int32),
        np.ascontiguousarray(mix.age, dtype=np.int32),
        _beta_array(mix.beta),
        np.ascontiguousarray(mix.label, dtype=np.int64),
    )


_NO_BETA = np.empty((0, 0))  #: the ``beta`` of a static-mode mixture in :mod:`soabench.gmphd.cycle`


def _beta_array(beta: np.ndarray | None) -> np.ndarray:
    """A mixture's Beta parameters as the compiled cycle takes them: (J, 4), or (0, 0) in static mode."""
    return _NO_BETA if beta is None else np.ascontiguousarray(beta, dtype=float).reshape(-1, 4)
