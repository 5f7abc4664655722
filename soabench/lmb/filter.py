"""The LMB filter cycle (docs/method.md "LMB filter"): ``LMBFilter.step(scan, births)`` once per scan, the same
call as :class:`soabench.gmphd.filter.GMPHDFilter`, so every birth model (built-in or plugin) runs inside it.

One cycle at scan k:

1. predict the tracks (r <- p_S r, CV motion) and add the birth tracks (:mod:`soabench.lmb.birth`,
   docs/method.md "LMB filter", birth): one Bernoulli per merge group of the birth model's Gaussian components (or
   one per component with ``[lmb] birth_mapping = "components"``), and Bernoullis at the previous scan's
   measurements when the model gives newborn terms;
2. joint update with Z_k (:mod:`soabench.lmb.update`): association costs, exact marginals where a cluster has at
   most ``max_hypotheses`` valid hypotheses (maps of measurements to tracks, absent and missed summed), Gibbs
   sampling beyond (:mod:`soabench.lmb.gibbs`, docs/method.md "LMB filter", association), the LMB approximation
   of the GLMB posterior;
3. per track: prune, merge and cap its Gaussian components (the GM-PHD's Vo-Ma kernels); drop tracks with
   r < ``prune_r``, keep the ``max_tracks`` most probable;
4. estimates: the tracks with r > ``extract_r``, labelled.

Static probabilities only (§4.1): p_S, and p_D g(x) at each component mean with the FOV gate (times line of sight
with ``filter.occlusion_pd``); the dynamic (Beta) modes are refused.
"""

from __future__ import annotations

import math
import time

import numpy as np

from soabench import notice
from soabench.config import FilterConfig, LMBConfig, Sensor
from soabench.errors import SoabenchError, require
from soabench.geometry import clutter_intensity, measurement_volume
from soabench.gmphd import cycle
from soabench.gmphd.inputs import StepInputs, check_step_inputs, newborn_finite, scan_inputs
from soabench.gmphd.models import cv_model, gate_threshold, measurement_noise
from soabench.gmphd.probabilities import detection_gate, scan_line_of_sight
from soabench.lmb import cycle as lmb_cycle
from soabench.lmb.birth import (
    EXPLAINED_TOL,
    adaptive_existence,
    gm_birth,
    group_birth,
    intensity_existence,
    measurement_birth,
)
from soabench.lmb.measurement import MeasurementModel, RangeBearingEKF
from soabench.lmb.tracks import Tracks, reduce_components
from soabench.lmb.update import predict, update
from soabench.origins import N_SOURCES
from soabench.types import SOURCE_MEAS, Births, Scan, StepResult, scan_once

#: the probability modes the LMB filter runs (docs/method.md §4.6): static only
LMB_MODES = ("static",)

_NO_EGO = np.zeros(3)  #: the pose passed for a dropped scan (p_D is 0 there)
_NO_NEWBORN = (np.empty((0, 4)), np.empty((0, 4, 4)), np.empty(0))
_NO_BETA = np.empty(0)  #: the beta argument of an adaptive birth's newborn existences (unread)
_NO_BIRTHS = (np.empty(0), np.empty((0, 4)), np.empty((0, 4, 4)), np.empty(0, dtype=np.int8))


def _birth_arrays(births: Births) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The birth components as :func:`soabench.lmb.cycle.predict_births` takes them: contiguous writeable w (J_b,),
    m (J_b, 4), P (J_b, 4, 4) float and source codes int8 (one compiled specialisation whatever the model hands).
    The model's own arrays when they already are that (the cycle only reads them, within the step), else copies."""
    return (
        _plain(births.w, _F64, ()),
        _plain(births.m, _F64, (4,)),
        _plain(births.P, _F64, (4, 4)),
        _plain(births.source, _I8, ()),
    )


_F64, _I8 = np.dtype(np.float64), np.dtype(np.int8)


def _plain(a, dtype: np.dtype, tail: tuple[int, ...]) -> np.ndarray:
    """``a`` as a C-contiguous, writeable, aligned array of ``dtype`` and shape (-1, *tail) (the type the cycle is
    compiled for): itself when it is one, else a copy reshaped."""
    if type(a) is np.ndarray and a.dtype == dtype and a.shape[1:] == tail and a.ndim == 1 + len(tail):
        flags = a.flags
        if flags.c_contiguous and flags.writeable and flags.aligned:
            return a
    return np.array(a, dtype=dtype).reshape(-1, *tail)


def _newborn_finite(nb) -> bool:
    """:func:`~soabench.gmphd.inputs.newborn_finite`, by one compiled call (:func:`soabench.lmb.cycle.all_finite`)
    when the newborn means and covariances are contiguous float arrays of shapes (M, 4) and (M, 4, 4)."""
    if nb is None:
        return True
    m, P = nb.m, nb.P
    if _contiguous(m, (4,)) and _contiguous(P, (4, 4)) and m.flags.writeable == P.flags.writeable:
        return lmb_cycle.all_finite(m, P)
    return newborn_finite(nb)


def _contiguous(a, tail: tuple[int, ...]) -> bool:
    """``a`` is a C-contiguous aligned float64 array of shape (-1, *tail)."""
    return (
        type(a) is np.ndarray and a.dtype == _F64 and a.ndim == 1 + len(tail) and a.shape[1:] == tail
        and a.flags.c_contiguous and a.flags.aligned
    )  # fmt: skip


class LMBFilter:
    """The LMB filter of one run (module docstring).

    Args:
        filter_cfg: the GM-PHD's filter settings it shares: form (EKF or UKF), sigma_a, p_S, p_D, gate, prune_T
            and merge_U (applied to each track's components), occlusion_pd, nonfinite.
        sensor_cfg: the sensor model (dt, FOV, R, clutter) shared with the simulator (§2.3).
        mode: "static" (the only mode: the LMB has no Beta probabilities).
        lmb_cfg: :class:`LMBConfig` (defaults if None).
        N_hat: lambda_B of the adaptive birth (expected births per scan, ``birth.N_hat``).
        rng: the generator of the Gibbs sampler's seeds (one draw per scan); the trial's association stream
            (:meth:`soabench.seeding.TrialSeeds.association_rng`) in the harness, a fixed seed if None.
        model: the measurement model; the GM-PHD's range-bearing EKF with its gate if None.
        fused: run the cycle as compiled calls (:mod:`soabench.lmb.cycle`, the default) when the model is the
            GM-PHD's range-bearing sensor; False runs the array path, the reference it is tested against. The two
            differ in the last bits (numpy's exp/log and BLAS against the C library's and loops in index order);
            no discrete decision of the filter rests on those bits (a measurement with 1 - r_U at most
            :data:`soabench.lmb.birth.EXPLAINED_TOL` counts as explained), so their labels and counts agree over
            whole runs (benchmarks/README.md, "The LMB filter's step").

    Attributes:
        tracks: the posterior tracks after the last step.
    """

    name = "lmb"

    def __init__(
        self,
        filter_cfg: FilterConfig,
        sensor_cfg: Sensor,
        mode: str = "static",
        *,
        lmb_cfg: LMBConfig | None = None,
        N_hat: float = 0.06,
        rng: np.random.Generator | None = None,
        model: MeasurementModel | None = None,
        fused: bool = True,
    ) -> None:
        require(
            mode in LMB_MODES,
            f"probability mode {mode!r} is not supported by the LMB filter; it runs static probabilities only",
        )
        filter_cfg.validate()
        sensor_cfg.validate()
        self.cfg, self.sensor, self.mode = filter_cfg, sensor_cfg, mode
        self.lmb = (lmb_cfg or LMBConfig()).validate()
        self.N_hat = float(N_hat)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.F, self.Q = cv_model(sensor_cfg.dt, filter_cfg.sigma_a)
        R = measurement_noise(sensor_cfg.sigma_r, sensor_cfg.sigma_b)
        gate = gate_threshold(filter_cfg.gate, filter_cfg.gate_prob)
        self.model = model if model is not None else RangeBearingEKF(R, sensor_cfg.r_min, gate, filter_cfg.form)
        self.fused = bool(fused) and model is None
        self._R = np.ascontiguousarray(R, dtype=float)
        self._ukf = filter_cfg.form == "ukf"
        s, c, lmb = sensor_cfg, filter_cfg, self.lmb
        pred = np.zeros(8)  # the GM-PHD's prediction scalars (soabench.gmphd.cycle.PRED_*): component weights kept
        pred[cycle.PRED_P_S] = 1.0
        pred[cycle.PRED_R_MIN], pred[cycle.PRED_R_MAX] = s.r_min, s.r_max
        pred[cycle.PRED_HALF_FOV], pred[cycle.PRED_LIMITED] = 0.5 * s.fov + 1e-12, float(s.fov_deg < 360.0)
        self._pred_pars = pred
        up = np.zeros(10)
        up[lmb_cycle.UP_R_MIN], up[lmb_cycle.UP_GATE], up[lmb_cycle.UP_MAX_HYP] = s.r_min, gate, lmb.max_hypotheses
        up[lmb_cycle.UP_PRUNE_R], up[lmb_cycle.UP_MAX_TRACKS] = lmb.prune_r, lmb.max_tracks
        up[lmb_cycle.UP_PRUNE_T], up[lmb_cycle.UP_MERGE_U] = c.prune_T, c.merge_U
        up[lmb_cycle.UP_MAX_COMP], up[lmb_cycle.UP_EXTRACT_R] = lmb.max_components, lmb.extract_r
        up[lmb_cycle.UP_EXACT] = float(lmb.association == "exact")
        self._up_pars = up
        #: kappa of every measurement in polar clutter (soabench.geometry.clutter_intensity), None in cartesian
        self._kappa_polar = s.lambda_c / measurement_volume(s) if s.clutter_space == "polar" else None
        self.tracks = Tracks.empty()
        #: newborn terms (m, P) of the previous scan's measurements and their birth existences r_B
        self._newborn: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def reset(self) -> None:
        """Forget the posterior (next step is k = 0 again)."""
        self.tracks = Tracks.empty()
        self._newborn = None

    def _p_D(self, m: np.ndarray, ego: np.ndarray | None, scan: Scan) -> np.ndarray:
        """p_D g(m_c) at each component mean (§4.1, §4.4 with ``occlusion_pd``); 0 for a dropped scan."""
        if ego is None:
            return np.zeros(len(m))
        occ = scan.occluders if self.cfg.occlusion_pd else None
        return self.cfg.p_D * detection_gate(m, ego, self.sensor, occ, scan)

    def step(self, scan: Scan, births: Births) -> StepResult:
        """One cycle (module docstring) with the births of ``scan``; returns the labelled estimates
        (``StepResult.labels``) and the cost figures (tracks as components). The first step in a process may
        compile the kernels: never a silent pause (:mod:`soabench.notice`)."""
        if not notice.ready("lmb.step"):
            with notice.first_use_notice("lmb.step"):
                return self._step(scan, births)
        return self._step(scan, births)

    def _step(self, scan: Scan, births: Births) -> StepResult:
        """Check the inputs (:mod:`soabench.gmphd.inputs`) and run the cycle on the fused or the array path.

        On the fused path with a finite scan, the birth components are checked by the compiled
        :func:`soabench.gmphd.cycle.births_ok` (finite, weights >= 0: the test of
        :func:`~soabench.gmphd.inputs.births_finite`) and the newborn terms here; inputs that fail it take
        :func:`~soabench.gmphd.inputs.check_step_inputs`, which raises or drops as it does for the array path."""
        key = ("filter.scan_inputs", id(scan.Z), id(scan.ego))  # shared with the GM-PHD runs of the scan
        Z, ego, finite = scan_once(scan, key, lambda: (*scan_inputs(scan.k, scan.Z, scan.ego), (scan.Z, scan.ego)))[:3]
        if self.fused and finite and _newborn_finite(births.newborn):
            arrays = _birth_arrays(births) if len(births) else _NO_BIRTHS
            if cycle.births_ok(*arrays[:3]):
                seed = int(self.rng.integers(2**32))  # one draw per scan, used or not (as below)
                result = self._step_fused(scan, StepInputs(Z, ego, births, 0, 0), seed, arrays)
                if result is not None:
                    return result
                return self._step_array(scan, StepInputs(Z, ego, births, 0, 0), seed)
        checked: StepInputs = check_step_inputs(scan.k, Z, ego, births, self.cfg.nonfinite, finite)
        seed = int(self.rng.integers(2**32))  # one draw per scan, used or not: the stream never depends on the data
        if self.fused:
            result = self._step_fused(scan, checked, seed)
            if result is not None:
                return result
        return self._step_array(scan, checked, seed)

    def _newborn_existence(self, births: Births, Z: np.ndarray, r_U: np.ndarray, A: np.ndarray, kappa: np.ndarray):
        """The newborn terms (m, P) of this scan's measurements and their birth existences r_B for the next scan
        (:mod:`soabench.lmb.birth`), or None when the model gives no newborn terms."""
        nb = births.newborn
        if nb is None or not len(Z):
            return None
        lmb = self.lmb
        m_nb, P_nb = np.array(nb.m, dtype=float).reshape(-1, 4), np.array(nb.P, dtype=float).reshape(-1, 4, 4)
        r_max = float(lmb.r_B_max)
        if nb.adaptive or lmb.birth_mapping == "components":
            r_B = lmb_cycle.newborn_existence(r_U, _NO_BETA, kappa, self.N_hat, r_max, EXPLAINED_TOL, True)
        else:
            beta = np.ascontiguousarray(nb.beta(A, kappa), dtype=float)
            if beta.shape == r_U.shape:  # one term per measurement, as the newborn terms' contract says
                r_B = lmb_cycle.newborn_existence(r_U, beta, kappa, self.N_hat, r_max, EXPLAINED_TOL, False)
            else:  # anything numpy broadcasts
                r_B = np.ascontiguousarray(intensity_existence(r_U, beta, kappa, r_max), dtype=float)
        return m_nb, P_nb, r_B

    def _step_fused(
        self, scan: Scan, checked: StepInputs, seed: int, arrays: tuple[np.ndarray, ...] | None = None
    ) -> StepResult | None:
        """:meth:`step` as two compiled calls (:mod:`soabench.lmb.cycle`): prediction and birth, then the update,
        the reduction and the extraction; the line-of-sight gate (``occlusion_pd``) and the newborn terms'
        ``beta(A, kappa)`` stay in Python between them. None (nothing changed) when a UKF covariance is not positive
        definite: the array path's rule decides that step. ``arrays``: the checked births' :func:`_birth_arrays`,
        when the caller has them."""
        Z, births, ego = checked.Z, checked.births, checked.ego
        lmb, k, tr = self.lmb, int(scan.k), self.tracks
        t0 = time.perf_counter()
        if self._newborn is not None:
            nb_m, nb_P, nb_r = self._newborn
        else:
            nb_m, nb_P, nb_r = _NO_NEWBORN
        if arrays is None:
            arrays = _birth_arrays(births) if len(births) else _NO_BIRTHS
        bw, bm, bP, bsrc = arrays
        pred = lmb_cycle.predict_births(
            tr.r, tr.label, tr.origin, tr.age, tr.start, tr.w, tr.m, tr.P, self.F, self.Q, self._pred_pars,
            float(self.cfg.p_S), bw, bm, bP, bsrc, lmb.birth_mapping != "components", float(lmb.r_B_max),
            float(self.cfg.merge_U), int(lmb.max_components), nb_m, nb_P, nb_r, SOURCE_MEAS, k, len(births),
            ego if ego is not None else _NO_EGO,
        )  # fmt: skip
        g = pred[8]
        if ego is None:
            p_D = np.zeros(len(g))
        else:
            if self.cfg.occlusion_pd and scan.occluders and g.any():  # line of sight (§4.4), as detection_gate
                idx = np.flatnonzero(g)
                g[idx] = scan_line_of_sight(scan, ego, pred[6][idx, :2]).reshape(-1)
            p_D = self.cfg.p_D * g
        kappa = clutter_intensity(Z, self.sensor) if self._kappa_polar is None else np.full(len(Z), self._kappa_polar)
        t1 = time.perf_counter()
        ok, post, X, X_r, labels, r_U, A, sums, info, counts, times = lmb_cycle.update_reduce(
            *pred[:8], p_D, Z, ego if ego is not None else _NO_EGO, self._R, kappa, self._ukf, self._up_pars,
            np.uint32(seed), N_SOURCES,
        )  # fmt: skip
        if not ok:
            return None
        self.tracks = Tracks(*post)
        self._newborn = self._newborn_existence(births, Z, r_U, A, kappa)
        sum_r, sum_kept = sums.tolist()
        # sum_kept sums the posterior's r: a NaN or an infinity among them makes it non-finite, so only a non-finite
        # sum needs the elementwise test
        if not ((math.isfinite(sum_kept) or np.isfinite(self.tracks.r).all()) and np.isfinite(X).all()):
            raise SoabenchError(f"scan {scan.k}: the LMB filter produced a non-finite posterior from finite inputs")
        n_updated, n_pruned, cap_hit, n_pairs = info.tolist()[:4]
        t_update, t_reduce = times.tolist()
        return StepResult(
            k=scan.k,
            X=X,
            X_w=X_r,
            sum_w=sum_r,
            sum_w_reduced=sum_kept,
            n_predicted=len(pred[0]),
            n_updated=n_updated,
            n_reduced=len(self.tracks),
            cap_hit=bool(cap_hit),
            t_predict=t1 - t0,
            t_update=t_update,
            t_reduce=t_reduce,
            mean_pD=float(self.cfg.p_D),
            A=A,
            kappa=np.asarray(kappa, dtype=float),
            n_pruned=n_pruned,
            n_merged=len(self.tracks.w),
            n_pairs=n_pairs,
            n_newborn=0 if self._newborn is None else len(Z),
            n_dropped=checked.n_dropped,
            n_dropped_births=checked.n_dropped_births,
            origin_counts=counts,
            labels=labels,
        )

    def _step_array(self, scan: Scan, checked: StepInputs, seed: int) -> StepResult:
        """:meth:`step` on the array path (numpy around the compiled kernels): the reference of the fused cycle."""
        Z, births = checked.Z, checked.births
        lmb, k = self.lmb, int(scan.k)
        t0 = time.perf_counter()

        if lmb.birth_mapping == "components":
            born = gm_birth(births, k, lmb.r_B_max)
        else:
            born = group_birth(births, k, lmb.r_B_max, float(self.cfg.merge_U), int(lmb.max_components))
        parts = [predict(self.tracks, self.F, self.Q, self.cfg.p_S), born]
        if self._newborn is not None:
            m_nb, P_nb, r_B = self._newborn
            parts.append(measurement_birth(m_nb, P_nb, r_B, self.F, self.Q, k, len(births)))
        pred = Tracks.concatenate(parts)
        t1 = time.perf_counter()

        ego_ok = checked.ego
        p_D = self._p_D(pred.m, ego_ok, scan)
        kappa = clutter_intensity(Z, self.sensor)
        up = update(
            pred, Z, ego_ok if ego_ok is not None else np.zeros(3), p_D, kappa, self.model,
            max_hyp=lmb.max_hypotheses, seed=seed, exact=lmb.association == "exact",
        )  # fmt: skip
        # A such that rho = A / (kappa + A) = r_U: what a model reading the previous step (ATBM prev_scan) needs
        with np.errstate(divide="ignore", invalid="ignore"):
            A = np.where(up.r_U < 1.0, kappa * up.r_U / np.maximum(1.0 - up.r_U, 1e-300), np.inf)
        A = np.where(np.isfinite(A), A, np.finfo(float).max)
        nb = births.newborn
        self._newborn = None
        if nb is not None and len(Z):
            m_nb, P_nb = np.asarray(nb.m, dtype=float).reshape(-1, 4), np.asarray(nb.P, dtype=float).reshape(-1, 4, 4)
            if nb.adaptive or lmb.birth_mapping == "components":
                r_B = adaptive_existence(up.r_U, self.N_hat, lmb.r_B_max)
            else:
                r_B = intensity_existence(up.r_U, nb.beta(A, kappa), kappa, lmb.r_B_max)
            self._newborn = (m_nb, P_nb, r_B)
        t2 = time.perf_counter()

        post = up.tracks
        n_updated = len(post.w)
        sum_r = float(post.r.sum())
        keep = np.flatnonzero(post.r >= lmb.prune_r)
        cap_hit = len(keep) > lmb.max_tracks
        if cap_hit:
            keep = np.sort(keep[np.argsort(-post.r[keep], kind="stable")[: lmb.max_tracks]])
        post = post.select(keep)
        start, w, m, P = reduce_components(
            post.start, post.w, post.m, post.P, float(self.cfg.prune_T), float(self.cfg.merge_U),
            int(lmb.max_components),
        )  # fmt: skip
        self.tracks = Tracks(post.r, post.label, post.origin, post.age, start, w, m, P)
        X, X_r, labels = self.tracks.estimates(lmb.extract_r)
        t3 = time.perf_counter()
        if not (np.isfinite(self.tracks.r).all() and np.isfinite(X).all()):
            raise SoabenchError(f"scan {scan.k}: the LMB filter produced a non-finite posterior from finite inputs")

        return StepResult(
            k=scan.k,
            X=X,
            X_w=X_r,
            sum_w=sum_r,
            sum_w_reduced=float(self.tracks.r.sum()),
            n_predicted=len(pred),
            n_updated=n_updated,
            n_reduced=len(self.tracks),
            cap_hit=bool(cap_hit),
            t_predict=t1 - t0,
            t_update=t2 - t1,
            t_reduce=t3 - t2,
            mean_pD=float(self.cfg.p_D),
            A=A,
            kappa=np.asarray(kappa, dtype=float),
            n_pruned=len(keep),
            n_merged=len(self.tracks.w),
            n_pairs=up.n_pairs,
            n_newborn=0 if self._newborn is None else len(Z),
            n_dropped=checked.n_dropped,
            n_dropped_births=checked.n_dropped_births,
            origin_counts=cycle.origin_counts(self.tracks.origin, self.tracks.age, N_SOURCES),
            labels=labels,
        )
