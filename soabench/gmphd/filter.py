"""GM-PHD filter cycle (docs/method.md §2.11). CONTRACT: ``GMPHDFilter`` and ``StepResult`` signatures are fixed.

Usage per trial and (birth model x probability mode)::

    filt = GMPHDFilter(cfg.filter, cfg.sensor, mode="static")      # or "dynamic", "dynamic+occ"
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
from typing import TYPE_CHECKING, Any

import numpy as np

from soabench.config import PROBABILITY_MODES, FilterConfig, SensorConfig
from soabench.errors import SoabenchError, require
from soabench.geometry import clutter_intensity
from soabench.gmphd import cycle, notice, reduction
from soabench.gmphd.inputs import StepInputs, check_step_inputs, scan_inputs
from soabench.gmphd.mixture import Mixture
from soabench.gmphd.models import cv_model, gate_threshold, measurement_noise, predict, update
from soabench.gmphd.probabilities import beta_mean, beta_predict, beta_prior, detection_gate
from soabench.gmphd.reduction import extract, prune_merge_cap
from soabench.origins import origin_counts
from soabench.types import SOURCE_MEAS, Births, StepResult  # StepResult re-exported: old import path

if TYPE_CHECKING:
    from soabench.types import Scan


class GMPHDFilter:
    """The GM-PHD filter cycle of §2.11 for one run: ``step(scan, births)`` once per scan.

    Args:
        filter_cfg: filter settings (form, p_S, p_D, T, U, J_max, gate, extraction, Beta parameters, ...).
        sensor_cfg: sensor model (dt, FOV, R, clutter rate) shared with the simulator (§2.3).
        mode: "static", "dynamic" or "dynamic+occ" (§4.6).
        fused: run the cycle as compiled calls over arrays (:mod:`soabench.gmphd.cycle`); False takes the array
            path of :mod:`soabench.gmphd.models` and :mod:`soabench.gmphd.reduction`, which is the reference the
            fused cycle is tested against (same results to 1e-12).

    Attributes:
        mixture: the current posterior (after reduction); empty at k = 0.
    """

    def __init__(
        self, filter_cfg: FilterConfig, sensor_cfg: SensorConfig, mode: str = "static", *, fused: bool = True
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
        self.dynamic = mode != "static"
        self.occlusion = mode == "dynamic+occ" or filter_cfg.occlusion_pd
        self.F, self.Q = cv_model(sensor_cfg.dt, filter_cfg.sigma_a)
        self.R = measurement_noise(sensor_cfg.sigma_r, sensor_cfg.sigma_b)
        self.gate_thr = gate_threshold(filter_cfg.gate, filter_cfg.gate_prob)
        self.beta0 = beta_prior(filter_cfg) if self.dynamic else None
        self.beta_newborn = None
        if self.dynamic:
            self.beta_newborn = self.beta0.copy()
            self.beta_newborn[0] += 1.0
        self.mixture = Mixture.empty(self.dynamic)
        self.fused = bool(fused)
        self._ukf = filter_cfg.form == "ukf"
        c = filter_cfg
        self._pars = np.array([c.beta_factor, c.theta_min, c.p_S_max], dtype=float)
        limited = sensor_cfg.fov_deg < 360.0
        self._fov = np.array([sensor_cfg.r_min, sensor_cfg.r_max, 0.5 * sensor_cfg.fov + 1e-12, float(limited)])
        self._beta0 = self.beta0 if self.dynamic else np.empty(0)
        self._nb_beta = self.beta_newborn if self.dynamic else np.empty(0)

    def reset(self) -> None:
        """Forget the posterior (next step is k = 0 again)."""
        self.mixture = Mixture.empty(self.dynamic)

    def _predict(self, births: Births) -> Mixture:
        """Step 1-2 of §2.11: predict the persistent mixture (§2.5, §4.3) and append the birth components."""
        mix = self.mixture
        if self.dynamic and len(mix):
            p_S, beta = beta_predict(mix.beta, self.cfg)
            mix = predict(mix, self.F, self.Q, p_S)
            mix.beta = beta
        else:
            mix = predict(mix, self.F, self.Q, self.cfg.p_S)
        if len(births):
            born = Mixture.from_arrays(
                births.w, births.m, births.P, origin=births.source, n_det=0, age=0, beta=self.beta0
            )
            mix = Mixture.concatenate([mix, born]) if len(mix) else born
        return mix

    def step(self, scan: Scan, births: Births) -> StepResult:
        """One cycle of §2.11: predict (dt), append ``births``, update with ``scan.Z`` (incl. ``births.newborn``)
        relative to ``scan.ego``, prune/merge/cap, extract.

        Non-finite inputs raise :class:`~soabench.errors.SoabenchError` or are dropped and counted, as
        ``filter.nonfinite`` says (:mod:`soabench.gmphd.inputs`); a result never holds a NaN."""
        key = ("filter.scan_inputs", id(scan.Z), id(scan.ego))
        Z, ego, finite, _ = _per_scan(scan, key, _scan_inputs_of(scan))
        checked = check_step_inputs(scan.k, Z, ego, births, self.cfg.nonfinite, finite)
        kind = (self.fused, births.newborn is not None)
        if not notice.ready(kind):  # the first step of a kind may compile kernels: never a silent pause
            with notice.first_use_notice(kind):
                return self._step(scan, checked)
        return self._step(scan, checked)

    def _step(self, scan: Scan, checked: StepInputs) -> StepResult:
        if self.fused and checked.ego is not None:  # a dropped scan (no pose) takes the array path
            res = self._step_fused(scan, checked.Z, checked.ego, checked.births)
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
            g = detection_gate(mix.m, ego, self.sensor, scan.occluders if self.occlusion else None)
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
        )
        post = up.mix
        t2 = time.perf_counter()

        if cfg.max_undetected_birth_age is not None and len(post):
            keep = ~((post.n_det == 0) & (post.age > cfg.max_undetected_birth_age))
            if not keep.all():
                post = post.select(keep)
        red = prune_merge_cap(post, cfg.prune_T, cfg.merge_U, cfg.J_max, cfg.theta_min)
        self.mixture = red.mix
        X, X_w = extract(red.mix, cfg.extract_thr, cfg.extraction)
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
        )

    def _step_fused(self, scan: Scan, Z: np.ndarray, ego: np.ndarray, births: Births) -> StepResult:
        """:meth:`step` as three compiled calls (:mod:`soabench.gmphd.cycle`) on the checked ``Z`` and ``ego``."""
        cfg = self.cfg
        ego = np.ascontiguousarray(ego, dtype=float)
        Z = np.ascontiguousarray(Z, dtype=float).reshape(-1, 2)
        mix = self.mixture
        t0 = time.perf_counter()
        pred = cycle.predict_append(
            np.ascontiguousarray(mix.w, dtype=float),
            np.ascontiguousarray(mix.m, dtype=float),
            np.ascontiguousarray(mix.P, dtype=float),
            np.ascontiguousarray(mix.origin, dtype=np.int8),
            np.ascontiguousarray(mix.n_det, dtype=np.int32),
            np.ascontiguousarray(mix.age, dtype=np.int32),
            _beta_array(mix.beta),
            self.F,
            self.Q,
            float(cfg.p_S),
            self._pars,
            np.ascontiguousarray(births.w, dtype=float).reshape(-1),
            np.ascontiguousarray(births.m, dtype=float).reshape(-1, 4),
            np.ascontiguousarray(births.P, dtype=float).reshape(-1, 4, 4),
            np.ascontiguousarray(births.source, dtype=np.int8).reshape(-1),
            self._beta0,
            ego,
            self._fov,
        )
        g = pred[7]
        newborn = births.newborn
        n_predicted = len(g) + (len(Z) if newborn is not None else 0)
        t1 = time.perf_counter()

        if self.occlusion and scan.occluders and g.any():  # line-of-sight gate (§4.4), as detection_gate
            from soabench.sensor import line_of_sight_past, sight_blockers

            idx = np.flatnonzero(g)
            make = lambda: (sight_blockers(ego[:2], scan.occluders), scan.occluders)  # noqa: E731
            key = ("filter.sight_blockers", id(scan.occluders), len(scan.occluders), ego[0], ego[1])
            blockers = _per_scan(scan, key, make)[0]
            vis = np.asarray(line_of_sight_past(ego[:2], pred[1][idx, :2], blockers), dtype=bool)
            g[idx] = vis.reshape(-1)
        kappa = np.ascontiguousarray(clutter_intensity(Z, self.sensor), dtype=float)
        args = (self.R, float(self.sensor.r_min), float(self.gate_thr), kappa)
        if newborn is None:
            post, A, ok = cycle.update(*pred[:7], g, float(cfg.p_D), Z, ego, *args, self._ukf)
            if not ok:  # UKF with a covariance that is not positive definite: the array path's jitter rule
                return self._step_array(scan, StepInputs(Z, ego, births, 0, 0))
        else:
            sup = cycle.support(pred[0], pred[1], pred[2], pred[6], g, float(cfg.p_D), Z, ego, *args, self._ukf)
            if not sup[12]:
                return self._step_array(scan, StepInputs(Z, ego, births, 0, 0))
            A = sup[11]
            M = len(Z)
            beta_nb = np.zeros(0)
            if M:
                beta_nb = np.asarray(newborn.beta(A, kappa), dtype=float).reshape(M)
                beta_nb = np.where(beta_nb > 0.0, beta_nb, 0.0)  # a newborn term is a non-negative intensity
            post = cycle.posterior(
                *pred[:7],
                sup,
                self.R,
                beta_nb,
                np.ascontiguousarray(newborn.m, dtype=float).reshape(-1, 4),
                np.ascontiguousarray(newborn.P, dtype=float).reshape(-1, 4, 4),
                self._nb_beta,
                SOURCE_MEAS,
            )
        n_updated, n_pairs, n_newborn = len(post[0]), int(post[7]), int(post[8])
        t2 = time.perf_counter()

        max_age = -1 if cfg.max_undetected_birth_age is None else int(cfg.max_undetected_birth_age)
        red, X, X_w, (sum_w, n_pruned, n_merged, cap_hit) = cycle.reduce(
            *post[:7],
            max_age,
            float(cfg.prune_T),
            float(cfg.merge_U),
            int(cfg.J_max),
            float(cfg.theta_min),
            float(cfg.extract_thr),
            cfg.extraction == "vo_ma",
        )
        if cap_hit:
            reduction.log.info("J_max = %d hit: %d components reduced to %d", cfg.J_max, n_merged, cfg.J_max)
        self.mixture = Mixture(*red[:6], red[6] if self.dynamic else None)
        if cfg.extraction != "vo_ma":
            X, X_w = extract(self.mixture, cfg.extract_thr, cfg.extraction)
        t3 = time.perf_counter()

        w = self.mixture.w
        return StepResult(
            k=scan.k,
            X=X,
            X_w=X_w,
            sum_w=float(sum_w),
            sum_w_reduced=float(w.sum()),
            n_predicted=n_predicted,
            n_updated=n_updated,
            n_reduced=len(w),
            cap_hit=bool(cap_hit),
            t_predict=t1 - t0,
            t_update=t2 - t1,
            t_reduce=t3 - t2,
            mean_pD=self._mean_pD(),
            A=A,
            kappa=kappa,
            n_pruned=int(n_pruned),
            n_merged=int(n_merged),
            n_pairs=n_pairs,
            n_newborn=n_newborn,
            origin_counts=origin_counts(self.mixture.origin, self.mixture.age),
        )


def _per_scan(scan: Scan, key: tuple, make: Callable[[], Any]) -> Any:
    """``make()`` computed once per scan for every filter run over it (:meth:`soabench.types.Scan.once`), or now
    for a scan object that cannot keep it."""
    once = getattr(scan, "once", None)
    return make() if once is None else once(key, make)


def _scan_inputs_of(scan: Scan) -> Callable[[], tuple]:
    """``make()`` -> :func:`soabench.gmphd.inputs.scan_inputs` of ``scan`` plus the scan's own Z and ego arrays,
    held with the result so that the ids in its cache key (:meth:`soabench.types.Scan.once`) stay theirs."""
    return lambda: (*scan_inputs(scan.k, scan.Z, scan.ego), (scan.Z, scan.ego))


_NO_BETA = np.empty((0, 0))  #: the ``beta`` of a static-mode mixture in :mod:`soabench.gmphd.cycle`


def _beta_array(beta: np.ndarray | None) -> np.ndarray:
    """A mixture's Beta parameters as the compiled cycle takes them: (J, 4), or (0, 0) in static mode."""
    return _NO_BETA if beta is None else np.ascontiguousarray(beta, dtype=float).reshape(-1, 4)
