"""The PMBM filter cycle and its PMB variant (docs/method.md §10): ``PMBMFilter.step(scan, births)`` once per scan,
the same call as :class:`soabench.gmphd.filter.GMPHDFilter`, so every birth model (built-in or plugin) runs inside
it unchanged.

One cycle at scan k:

1. predict (§10.2): the undetected intensity with the GM-PHD's prediction, plus the birth model's components exactly
   as the GM-PHD appends them; every single-target hypothesis r <- p_S r, density predicted with F, Q;
2. update with Z_k (§10.3, :mod:`soabench.pmbm.update`): the GM-PHD's measurement terms and gate, the birth model's
   newborn terms in each measurement's new track, global hypotheses by Murty's algorithm per cluster;
3. reduce: the intensity with the GM-PHD's prune, merge and cap (T, U, J_max, and ``max_undetected_birth_age``); each
   hypothesis's density with the same merge and prune, at most ``J_h`` components; ``pmb``: the track-oriented
   collapse to one multi-Bernoulli (:mod:`soabench.pmbm.pmb`);
4. estimates (§10.4, estimator 1): in the global hypothesis of highest weight, every track whose hypothesis has
   r > 0.5, at the mean of its heaviest component, labelled.

Labels: the new track of measurement l at a scan gets the run's counter value plus l; the counter then advances by
the number of measurements. Static probabilities (§4.1): p_S, and p_D g(x) at each component mean with the FOV gate,
times line of sight with ``filter.occlusion_pd`` (§4.4); the Beta (dynamic) mode is refused.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from soabench import notice
from soabench.config import FilterConfig, PMBMConfig, Sensor
from soabench.errors import SoabenchError, require
from soabench.geometry import clutter_intensity
from soabench.gmphd import cycle
from soabench.gmphd.inputs import StepInputs, check_step_inputs, newborn_finite, scan_inputs, scan_kappa
from soabench.gmphd.mixture import UNLABELLED, Mixture
from soabench.gmphd.models import cv_model, gate_threshold, measurement_noise, predict_moments
from soabench.gmphd.probabilities import detection_gate, scan_line_of_sight
from soabench.gmphd.reduction import prune_merge_cap
from soabench.lmb.measurement import MeasurementModel, RangeBearingEKF
from soabench.lmb.tracks import Tracks, reduce_components
from soabench.lmb.update import predict as predict_tracks
from soabench.origins import N_SOURCES, origin_counts
from soabench.pmbm import cycle as pmbm_cycle
from soabench.pmbm import kernels
from soabench.pmbm import step as pmbm_step
from soabench.pmbm.density import PMBMDensity
from soabench.pmbm.pmb import collapse
from soabench.pmbm.update import Hypotheses, _max_gap, update
from soabench.types import SOURCE_MEAS, Births, Scan, StepResult, scan_once

#: the probability modes the PMBM family runs (docs/method.md §10.6): static, with or without ``occlusion_pd``
PMBM_MODES = ("static",)
EXTRACT_R = 0.5  #: estimator 1 (§10.4): a track is reported when its hypothesis has r above this
_F64, _I8, _I32 = np.dtype(np.float64), np.dtype(np.int8), np.dtype(np.int32)


_NO_BIRTHS = (np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4, 4)))
_NO_NEWBORN = (np.zeros((0, 4)), np.zeros((0, 4, 4)))
_NO_SOURCE = np.zeros(0, dtype=np.int8)
_NO_EGO = np.zeros(3)  #: the pose the measurement terms take on a dropped scan (every p_D is 0 there)
log = logging.getLogger(__name__)


def _plain(a, dtype: np.dtype, shape: tuple[int, ...]) -> bool:
    """``a`` is a C-contiguous, aligned, writeable array of ``dtype`` and ``shape``: the one type the compiled
    checks and counts below are specialised for (the GM-PHD's and the LMB's calls compile them for it too)."""
    if type(a) is not np.ndarray or a.dtype != dtype or a.shape != shape:
        return False
    flags = a.flags
    return flags.c_contiguous and flags.aligned and flags.writeable


def _plain_copy(a, shape: tuple[int, ...]) -> np.ndarray:
    """``a`` as a plain float64 array of ``shape`` (:func:`_plain`), copied only when it is not one (read only
    within the step)."""
    return a if _plain(a, _F64, shape) else np.array(np.asarray(a, dtype=float).reshape(shape), order="C")


def _plain_births(births: Births) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The birth components (w, m, P) when they are plain arrays (:func:`_plain`), as the compiled calls take them
    (no copy); ``_NO_BIRTHS`` without births; None when they are not plain."""
    J = len(births)
    if J == 0:
        return _NO_BIRTHS
    w, m, P = births.w, births.m, births.P
    if _plain(w, _F64, (J,)) and _plain(m, _F64, (J, 4)) and _plain(P, _F64, (J, 4, 4)):
        return w, m, P
    return None


def _births_finite(births: Births, plain: tuple[np.ndarray, np.ndarray, np.ndarray] | None) -> bool:
    """:func:`soabench.gmphd.inputs.births_finite` (every birth weight, mean and covariance finite, every weight
    >= 0, every newborn term finite), the birth components ``plain`` (:func:`_plain_births` of ``births``) by one
    compiled call (:func:`soabench.gmphd.cycle.births_ok`, the same test). False also when they are not plain:
    :func:`~soabench.gmphd.inputs.check_step_inputs` then decides."""
    if plain is None or not newborn_finite(births.newborn):
        return False
    return plain is _NO_BIRTHS or cycle.births_ok(*plain)


def _origin_counts(ppp: Mixture, hyps: Tracks) -> np.ndarray:
    """:func:`soabench.origins.origin_counts` of the intensity's and the hypotheses' components together: the
    compiled count (:func:`soabench.gmphd.cycle.origin_counts`, the same bins) of each part, added, when the parts
    are plain int8 origins and int32 ages (:func:`_plain`)."""
    parts = ((ppp.origin, ppp.age), (hyps.origin, hyps.age))
    if all(_plain(o, _I8, o.shape[:1]) and _plain(a, _I32, o.shape[:1]) for o, a in parts):
        return cycle.origin_counts(ppp.origin, ppp.age, N_SOURCES) + cycle.origin_counts(hyps.origin, hyps.age,
                                                                                           N_SOURCES)  # fmt: skip
    return origin_counts(np.concatenate([ppp.origin, hyps.origin]), np.concatenate([ppp.age, hyps.age]))


class PMBMFilter:
    """The PMBM filter (``pmb=False``) or the PMB filter (``pmb=True``) of one run (module docstring).

    Args:
        filter_cfg: the GM-PHD's settings it shares: form (EKF or UKF), sigma_a, p_S, p_D, gate, prune_T, merge_U,
            J_max, max_undetected_birth_age (the intensity's reduction), occlusion_pd, nonfinite.
        sensor_cfg: the sensor model (dt, FOV, R, clutter) shared with the simulator (§2.3).
        mode: "static" (the family's probability model; ``static+occ`` is static with ``occlusion_pd``).
        pmbm_cfg: :class:`PMBMConfig` (defaults if None).
        pmb: collapse to one multi-Bernoulli after every update (§10.5).
        model: the measurement model; the GM-PHD's range-bearing EKF/UKF with its gate if None.
        fused: the update's bookkeeping after the global hypotheses in one compiled call (the default); False: the
            array path, the reference it is tested against (:func:`soabench.pmbm.update.update`).

    Attributes:
        density: the posterior PMBM after the last step.
        next_label: the next fresh track label of this run.
        whole: the cycle runs as one or two compiled calls per scan (:mod:`soabench.pmbm.step`): True with ``fused``
            and the built-in EKF sensor; otherwise (UKF, another model) the update's three compiled calls. Both give
            the same bytes.
    """

    def __init__(
        self,
        filter_cfg: FilterConfig,
        sensor_cfg: Sensor,
        mode: str = "static",
        *,
        pmbm_cfg: PMBMConfig | None = None,
        pmb: bool = False,
        model: MeasurementModel | None = None,
        fused: bool = True,
    ) -> None:
        require(
            mode in PMBM_MODES,
            f"probability mode {mode!r} is not supported by the {'PMB' if pmb else 'PMBM'} filter; it runs static "
            "probabilities (with or without occlusion_pd) only",
        )
        filter_cfg.validate()
        sensor_cfg.validate()
        self.cfg, self.sensor, self.mode = filter_cfg, sensor_cfg, mode
        self.pmbm = (pmbm_cfg or PMBMConfig()).validate()
        self.pmb = bool(pmb)
        self.fused = bool(fused)
        self.name = "pmb" if self.pmb else "pmbm"
        self.hyp = Hypotheses(self.pmbm.M_max, self.pmbm.w_floor, self.pmbm.r_floor)
        self.F, self.Q = cv_model(sensor_cfg.dt, filter_cfg.sigma_a)
        R = measurement_noise(sensor_cfg.sigma_r, sensor_cfg.sigma_b)
        gate = gate_threshold(filter_cfg.gate, filter_cfg.gate_prob)
        self.model = model if model is not None else RangeBearingEKF(R, sensor_cfg.r_min, gate, filter_cfg.form)
        self.density = PMBMDensity.empty()
        self.next_label = 1
        self._p_hyp: tuple[PMBMDensity, np.ndarray] | None = None  # the density and its hypothesis probabilities
        # the whole cycle in one or two compiled calls (soabench.pmbm.step) for the built-in EKF sensor model
        self.whole = self.fused and type(self.model) is RangeBearingEKF and self.model.form == "ekf"
        if self.whole:
            self._pack_settings()

    def _pack_settings(self) -> None:
        """The scalars of :mod:`soabench.pmbm.step`'s calls as float arrays, packed once per filter: the FOV gate
        (``FOV_*``), the intensity's reduction (the GM-PHD's ``RED_*``, no extraction) and the update's settings."""
        c, s, h = self.cfg, self.sensor, self.hyp
        fov = np.zeros(5)
        fov[pmbm_step.FOV_R_MIN], fov[pmbm_step.FOV_R_MAX] = s.r_min, s.r_max
        fov[pmbm_step.FOV_HALF], fov[pmbm_step.FOV_LIMITED] = 0.5 * s.fov + 1e-12, float(s.fov_deg < 360.0)
        self._fov_off = fov.copy()
        fov[pmbm_step.FOV_EGO] = 1.0
        self._fov_on = fov
        red = np.zeros(8)
        red[cycle.RED_MAX_AGE] = -1 if c.max_undetected_birth_age is None else int(c.max_undetected_birth_age)
        red[cycle.RED_T], red[cycle.RED_U], red[cycle.RED_J_MAX] = c.prune_T, c.merge_U, int(c.J_max)
        red[cycle.RED_THETA_MIN], red[cycle.RED_N_SOURCES] = c.theta_min, N_SOURCES  # RED_VO_MA 0: no extraction
        self._red_pars = red
        self._pars = np.array([h.M_max, _max_gap(h.w_floor), h.w_floor, h.r_floor, SOURCE_MEAS, c.prune_T, c.merge_U,
                               self.pmbm.J_h, EXTRACT_R], dtype=float)  # fmt: skip
        m = self.model
        self._R, self._r_min, self._gate_thr = _plain_copy(m.R, (2, 2)), float(m.r_min), float(m.gate_thr)
        self._F, self._Q = _plain_copy(self.F, (4, 4)), _plain_copy(self.Q, (4, 4))

    def reset(self) -> None:
        """Forget the posterior and restart the label counter (next step is k = 0 again)."""
        self.density = PMBMDensity.empty()
        self.next_label = 1

    def _p_D(self, m: np.ndarray, ego: np.ndarray | None, scan: Scan) -> np.ndarray:
        """p_D g(m_c) at each component mean (§4.1, §4.4 with ``occlusion_pd``); 0 for a dropped scan."""
        if ego is None:
            return np.zeros(len(m))
        occ = scan.occluders if self.cfg.occlusion_pd else None
        return self.cfg.p_D * detection_gate(m, ego, self.sensor, occ, scan)

    def predict(self, births: Births) -> PMBMDensity:
        """§10.2: the predicted density with the birth components appended to the intensity."""
        return self._predict(births)[0]

    def _predict(self, births: Births) -> tuple[PMBMDensity, np.ndarray, np.ndarray]:
        """:meth:`predict`, and the means and covariances of the predicted intensity's components followed by the
        hypotheses' in one array each (the intensity's are views of them): the GM-PHD's prediction of the
        intensity, then the birth components as :meth:`Mixture.from_arrays` takes them."""
        d, cfg = self.density, self.cfg
        if self.fused:
            return self._predict_compiled(births)
        hyps = predict_tracks(d.hyps, self.F, self.Q, cfg.p_S)
        parts = []  # (w, m, P, origin, n_det, age, label) of the predicted intensity, then of the births
        if len(d.ppp):
            m, P = predict_moments(d.ppp.m, d.ppp.P, self.F, self.Q)
            parts.append((d.ppp.w * cfg.p_S, m, P, d.ppp.origin, d.ppp.n_det, d.ppp.age + 1, d.ppp.label))
        nb = len(births)
        if nb:
            parts.append((
                np.asarray(births.w, dtype=float).reshape(-1), np.asarray(births.m, dtype=float).reshape(nb, 4),
                np.asarray(births.P, dtype=float).reshape(nb, 4, 4),
                np.broadcast_to(np.asarray(births.source, dtype=np.int8), (nb,)), np.zeros(nb, dtype=np.int32),
                np.zeros(nb, dtype=np.int32), np.full(nb, UNLABELLED, dtype=np.int64),
            ))  # fmt: skip
        m_all = np.concatenate([*(x[1] for x in parts), hyps.m])
        P_all = np.concatenate([*(x[2] for x in parts), hyps.P])
        J = len(m_all) - len(hyps.m)
        if not parts:
            ppp = Mixture.empty()
        elif len(parts) == 1:  # its own arrays, as the GM-PHD's prediction and Mixture.from_arrays give them
            w, _, _, origin, n_det, age, label = parts[0]
            ppp = Mixture(w, m_all[:J], P_all[:J], origin.copy(), n_det.copy(), age, None, label.copy())
        else:
            w, _, _, origin, n_det, age, label = (np.concatenate(x) for x in zip(*parts, strict=True))
            ppp = Mixture(w, m_all[:J], P_all[:J], origin, n_det, age, None, label)
        return PMBMDensity(ppp, hyps, d.track, d.table, d.log_w), m_all, P_all

    def _predict_compiled(self, births: Births) -> tuple[PMBMDensity, np.ndarray, np.ndarray]:
        """:meth:`_predict` with the moments in one compiled call (:func:`soabench.pmbm.cycle.predict`)."""
        d, cfg = self.density, self.cfg
        ppp, h, nb = d.ppp, d.hyps, len(births)
        if nb:
            bw, bm, bP = (_plain_copy(x, shape) for x, shape in ((births.w, (nb,)), (births.m, (nb, 4)),
                                                                  (births.P, (nb, 4, 4))))  # fmt: skip
        else:
            bw, bm, bP = _NO_BIRTHS
        w, m_all, P_all = pmbm_cycle.predict(ppp.w, ppp.m, ppp.P, bw, bm, bP, h.m, h.P, self.F, self.Q, float(cfg.p_S))
        J = len(w)
        if nb:
            origin = np.concatenate([ppp.origin, np.broadcast_to(np.asarray(births.source, dtype=np.int8), (nb,))])
            n_det = np.concatenate([ppp.n_det, np.zeros(nb, dtype=np.int32)])
            age = np.concatenate([ppp.age + 1, np.zeros(nb, dtype=np.int32)])
            label = np.concatenate([ppp.label, np.full(nb, UNLABELLED, dtype=np.int64)])
        else:
            origin, n_det, age, label = ppp.origin.copy(), ppp.n_det.copy(), ppp.age + 1, ppp.label.copy()
        pred_ppp = Mixture(w, m_all[:J], P_all[:J], origin, n_det, age, None, label)
        hyps = Tracks(h.r * cfg.p_S, h.label, h.origin, h.age + 1, h.start, h.w, m_all[J:], P_all[J:]) if len(h) else h
        return PMBMDensity(pred_ppp, hyps, d.track, d.table, d.log_w), m_all, P_all

    def _reduce_extract(
        self, post: PMBMDensity, ppp: Mixture
    ) -> tuple[PMBMDensity, np.ndarray, np.ndarray, np.ndarray]:
        """Step 3's reduction of every hypothesis's density and step 4's estimates, compiled (with ``pmb``:
        :func:`soabench.pmbm.step.pmb_posterior`, the collapse, a second reduction and the estimates, as the whole
        cycle runs them; else :func:`soabench.pmbm.kernels.estimates` of the best global hypothesis); the intensity
        ``ppp`` is already reduced. Returns (posterior, X, X_r, labels)."""
        cfg, h = self.cfg, post.hyps
        T, U, J_h = float(cfg.prune_T), float(cfg.merge_U), int(self.pmbm.J_h)
        start, w, m, P = reduce_components(h.start, h.w, h.m, h.P, T, U, J_h)
        if self.pmb:
            *tracks, track, X, X_r, labels = pmbm_step.pmb_posterior(
                post.track, post.table, kernels.global_weights(post.log_w), h.r, h.label, h.origin, h.age, start, w,
                m, P, T, U, J_h, EXTRACT_R,
            )  # fmt: skip
            return PMBMDensity(ppp, Tracks(*tracks), track, track[None, :], np.zeros(1)), X, X_r, labels
        post = PMBMDensity(ppp, Tracks(h.r, h.label, h.origin, h.age, start, w, m, P), post.track, post.table,
                           post.log_w)  # fmt: skip
        row = post.table[int(np.argmax(post.log_w))]
        hyps = post.hyps
        return (post, *kernels.estimates(row, hyps.r, hyps.label, hyps.start, hyps.w, hyps.m, EXTRACT_R))

    def _reduce_extract_arrays(
        self, post: PMBMDensity, ppp: Mixture
    ) -> tuple[PMBMDensity, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_reduce_extract` by the array path (``fused=False``), its reference."""
        cfg, h = self.cfg, post.hyps
        start, w, m, P = reduce_components(h.start, h.w, h.m, h.P, float(cfg.prune_T), float(cfg.merge_U),
                                           int(self.pmbm.J_h))  # fmt: skip
        post = PMBMDensity(ppp, Tracks(h.r, h.label, h.origin, h.age, start, w, m, P), post.track, post.table,
                           post.log_w)  # fmt: skip
        if self.pmb:
            post = collapse(post)
            h = post.hyps
            start, w, m, P = reduce_components(h.start, h.w, h.m, h.P, float(cfg.prune_T), float(cfg.merge_U),
                                               int(self.pmbm.J_h))  # fmt: skip
            post = PMBMDensity(post.ppp, Tracks(h.r, h.label, h.origin, h.age, start, w, m, P), post.track,
                               post.table, post.log_w)  # fmt: skip
        best = int(np.argmax(post.log_w)) if len(post.log_w) else 0
        chosen = post.hyps.select(post.table[best]) if post.n_tracks else Tracks.empty()
        return (post, *chosen.estimates(EXTRACT_R))

    def step(self, scan: Scan, births: Births) -> StepResult:
        """One cycle (module docstring) with the births of ``scan``; returns the labelled estimates
        (``StepResult.labels``) and the cost figures (components of the intensity and of every hypothesis)."""
        kind = f"{self.name}.step"
        if not notice.ready(kind):
            with notice.first_use_notice(kind):
                return self._step(scan, births)
        return self._step(scan, births)

    def _step(self, scan: Scan, births: Births) -> StepResult:
        key = ("filter.scan_inputs", id(scan.Z), id(scan.ego))  # shared with the other filters of the scan
        Z, ego, finite = scan_once(scan, key, lambda: (*scan_inputs(scan.k, scan.Z, scan.ego), (scan.Z, scan.ego)))[:3]
        Z_scan = Z
        plain = _plain_births(births)
        if finite and _births_finite(births, plain):  # what check_step_inputs returns for finite inputs
            checked = StepInputs(Z, ego, births, 0, 0)
        else:
            checked, plain = check_step_inputs(scan.k, Z, ego, births, self.cfg.nonfinite, finite), None
        if self.whole:
            return self._step_whole(scan, checked, Z_scan, plain)
        Z, births, cfg = checked.Z, checked.births, self.cfg
        t0 = time.perf_counter()
        prior = self.density
        pred, m_all, P_all = self._predict(births)
        t1 = time.perf_counter()

        ego_ok = checked.ego
        if Z is Z_scan:  # the scan's own Z, kept alive by its scan_inputs entry: kappa once for every filter
            kappa = scan_kappa(scan, Z, self.sensor)
        else:
            kappa = clutter_intensity(Z, self.sensor)
        J = len(pred.ppp)
        if self.cfg.occlusion_pd and not self.fused:  # the array path: the intensity's means, then the hypotheses'
            p_D = np.concatenate([self._p_D(pred.ppp.m, ego_ok, scan), self._p_D(pred.hyps.m, ego_ok, scan)])
        else:  # the gate is decided per mean: one call on all of them
            p_D = self._p_D(m_all, ego_ok, scan)
        # the prior's hypothesis probabilities are those of the last posterior (the prediction keeps the table)
        p_hyp = self._p_hyp[1] if self._p_hyp is not None and self._p_hyp[0] is prior else None
        up = update(
            pred, Z, ego_ok if ego_ok is not None else np.zeros(3), p_D[:J], p_D[J:], kappa, self.model,
            newborn=births.newborn, label0=self.next_label, hyp=self.hyp, fused=self.fused, stacked=(m_all, P_all),
            p_hyp=p_hyp,
        )  # fmt: skip
        self.next_label += len(Z)
        post = up.density
        t2 = time.perf_counter()

        p_post = post.hypothesis_probabilities()
        sum_w = post.phd_mass(p_post)
        ppp = post.ppp
        if cfg.max_undetected_birth_age is not None and len(ppp):
            keep = ~((ppp.n_det == 0) & (ppp.age > cfg.max_undetected_birth_age))
            if not keep.all():
                ppp = ppp.select(keep)
        red = prune_merge_cap(ppp, cfg.prune_T, cfg.merge_U, cfg.J_max, cfg.theta_min)
        if self.fused:
            reduced, X, X_r, labels = self._reduce_extract(post, red.mix)
        else:
            reduced, X, X_r, labels = self._reduce_extract_arrays(post, red.mix)
        same_table = reduced.table is post.table and reduced.log_w is post.log_w and len(reduced.hyps) == len(post.hyps)
        p_reduced = p_post if same_table else reduced.hypothesis_probabilities()
        post = self.density = reduced
        self._p_hyp = (post, p_reduced)
        t3 = time.perf_counter()
        if not (np.isfinite(post.hyps.r).all() and np.isfinite(X).all() and np.isfinite(post.ppp.w).all()):
            raise self._non_finite(scan)
        n_comp = len(post.ppp) + len(post.hyps.w)
        return StepResult(
            k=scan.k,
            X=X,
            X_w=X_r,
            sum_w=sum_w,
            sum_w_reduced=post.phd_mass(p_reduced),
            n_predicted=len(pred.ppp) + len(pred.hyps.w),
            n_updated=len(up.density.ppp) + len(up.density.hyps.w),
            n_reduced=n_comp,
            cap_hit=bool(red.cap_hit),
            t_predict=t1 - t0,
            t_update=t2 - t1,
            t_reduce=t3 - t2,
            mean_pD=float(cfg.p_D),
            A=np.asarray(up.A, dtype=float),
            kappa=np.asarray(kappa, dtype=float),
            n_pruned=red.n_pruned,
            n_merged=red.n_merged,
            n_pairs=up.n_pairs,
            n_newborn=up.n_newborn,
            n_dropped=checked.n_dropped,
            n_dropped_births=checked.n_dropped_births,
            origin_counts=_origin_counts(post.ppp, post.hyps),
            labels=labels,
        )

    def _non_finite(self, scan: Scan) -> SoabenchError:
        """The error of a step whose posterior or estimates are not finite although its inputs were."""
        return SoabenchError(f"scan {scan.k}: the {self.name.upper()} filter produced a non-finite posterior from "
                             "finite inputs")  # fmt: skip

    def _step_whole(
        self, scan: Scan, checked: StepInputs, Z_scan: np.ndarray, plain: tuple[np.ndarray, ...] | None
    ) -> StepResult:
        """:meth:`_step` by :mod:`soabench.pmbm.step` (its module docstring): the same cycle, the same numbers, in
        two compiled calls (three with the line of sight). The compiled calls read
        the clock between their stages: ``t_predict`` is the prediction with the FOV gate, ``t_update`` the rest up to
        the posterior (line of sight, measurement and detection terms, newborn terms, global hypotheses, posterior),
        ``t_reduce`` the reductions, estimates, the PMB's collapse and the step's bookkeeping. ``plain``: the birth
        components as :func:`_plain_births` found them (None: copied here)."""
        Z, births, cfg = checked.Z, checked.births, self.cfg
        t0 = time.perf_counter()
        d = self.density
        ppp, h = d.ppp, d.hyps
        nb, M, H = len(births), len(Z), len(h)
        if plain is not None:
            bw, bm, bP = plain
        elif nb:
            bw, bm, bP = (_plain_copy(x, shape) for x, shape in ((births.w, (nb,)), (births.m, (nb, 4)),
                                                                  (births.P, (nb, 4, 4))))  # fmt: skip
        else:
            bw, bm, bP = _NO_BIRTHS
        ego = checked.ego
        kappa = scan_kappa(scan, Z, self.sensor) if Z is Z_scan else clutter_intensity(Z, self.sensor)
        kappa = _plain_copy(kappa, (M,))
        Z = _plain_copy(Z, (M, 2))
        # the prior's hypothesis probabilities are those of the last posterior (the prediction keeps the table)
        p_hyp = self._p_hyp[1] if self._p_hyp is not None and self._p_hyp[0] is d else None
        if p_hyp is None:
            p_hyp = d.hypothesis_probabilities() if H and M else np.zeros(H)
        fov, ego_arr = (self._fov_on, _plain_copy(ego, (3,))) if ego is not None else (self._fov_off, _NO_EGO)
        p_S, p_D0 = float(cfg.p_S), float(cfg.p_D)
        r_pred = h.r * p_S
        if cfg.occlusion_pd and ego is not None and scan.occluders:  # the line of sight (§4.4) between the calls
            w_pred, m_all, P_all, g = pmbm_step.predict_gate(ppp.w, ppp.m, ppp.P, bw, bm, bP, h.m, h.P, self._F,
                                                             self._Q, p_S, ego_arr, fov)  # fmt: skip
            t_pred = time.perf_counter() - t0
            idx = np.flatnonzero(g)
            if len(idx):
                g[idx] = scan_line_of_sight(scan, ego, m_all[idx, :2])
            terms = pmbm_step.update_terms(m_all, P_all, g, p_D0, ego_arr, self._R, self._r_min, self._gate_thr, Z,
                                           w_pred, r_pred, h.start, h.w, p_hyp)  # fmt: skip
        else:
            w_pred, m_all, P_all, terms, (t_pred, _) = pmbm_step.front(
                ppp.w, ppp.m, ppp.P, bw, bm, bP, h.m, h.P, self._F, self._Q, p_S, ego_arr, fov, p_D0, self._R,
                self._r_min, self._gate_thr, Z, r_pred, h.start, h.w, p_hyp,
            )  # fmt: skip
        p_D, Ct, Sinv, S, Hj, nu_r, nu_b, log_t, log_e_ppp, log_miss, log_det, log_eta_miss, log_eta_det, log_r, \
            log_l_miss_exact, log_l_miss, log_l_det, A = terms  # fmt: skip

        newborn = births.newborn
        if newborn is not None and M:
            beta = np.asarray(newborn.beta(A, kappa.copy()), dtype=float).reshape(M)
            beta = np.where(beta > 0.0, beta, 0.0)
            nb_m = np.ascontiguousarray(np.asarray(newborn.m, dtype=float).reshape(-1, 4))
            nb_P = np.ascontiguousarray(np.asarray(newborn.P, dtype=float).reshape(-1, 4, 4))
        else:
            beta = np.zeros(M)
            nb_m, nb_P = _NO_NEWBORN
        source = np.array(births.source, dtype=np.int8) if nb else _NO_SOURCE  # a copy: plain, writeable
        if source.shape != (nb,):
            source = np.array(np.broadcast_to(source, (nb,)))
        out = pmbm_step.back(
            beta, kappa, log_t, log_e_ppp, log_miss, log_det, log_eta_miss, log_eta_det, log_r, log_l_miss_exact,
            log_l_miss, log_l_det, p_D, w_pred, m_all, P_all, ppp.origin, ppp.n_det, ppp.age, ppp.label, source,
            d.track, d.table, d.log_w, h.start, h.w, h.label, h.origin, h.age + 1, nb_m, nb_P, Ct, Sinv, S, Hj,
            self._R, nu_r, nu_b, self._red_pars, self._pars, self.next_label, self.pmb,
        )  # fmt: skip
        w_miss, rw, rm, rP, r_origin, r_n_det, r_age, r_label, n_pruned, n_merged, cap_hit = out[:11]
        r, h_label, h_origin, h_age, start, w, m, P, track, table, log_w, X, X_r, labels = out[11:25]
        n_hyp_comp, n_pairs, n_new, counts, finite, p_post, r_post, (_, t_back_reduce) = out[25:]
        self.next_label += M
        t2 = time.perf_counter()

        sum_w = float(w_miss.sum() + p_post @ r_post)
        if cap_hit:
            log.info("J_max = %d hit: the undetected intensity reduced to %d components", cfg.J_max, cfg.J_max)
        post = PMBMDensity(Mixture(rw, rm, rP, r_origin, r_n_det, r_age, None, r_label),
                           Tracks(r, h_label, h_origin, h_age, start, w, m, P), track, table, log_w)  # fmt: skip
        # the PMB keeps one global hypothesis, of weight e^0: each track's hypothesis has probability 1
        p_reduced = np.ones(len(track)) if self.pmb else p_post
        self.density = post
        self._p_hyp = (post, p_reduced)
        t3 = time.perf_counter()
        if not finite:
            raise self._non_finite(scan)
        return StepResult(
            k=scan.k,
            X=X,
            X_w=X_r,
            sum_w=sum_w,
            sum_w_reduced=post.phd_mass(p_reduced),
            n_predicted=len(m_all),
            n_updated=len(w_miss) + int(n_hyp_comp),
            n_reduced=len(rw) + len(post.hyps.w),
            cap_hit=bool(cap_hit),
            t_predict=t_pred,
            t_update=t2 - t0 - t_pred - t_back_reduce,
            t_reduce=t_back_reduce + (t3 - t2),
            mean_pD=float(cfg.p_D),
            A=A,
            kappa=kappa,
            n_pruned=int(n_pruned),
            n_merged=int(n_merged),
            n_pairs=int(n_pairs),
            n_newborn=int(n_new),
            n_dropped=checked.n_dropped,
            n_dropped_births=checked.n_dropped_births,
            origin_counts=counts,
            labels=labels,
        )
