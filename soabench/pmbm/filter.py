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
from soabench.gmphd.probabilities import detection_gate
from soabench.gmphd.reduction import prune_merge_cap
from soabench.lmb.measurement import MeasurementModel, RangeBearingEKF
from soabench.lmb.tracks import Tracks, reduce_components
from soabench.lmb.update import predict as predict_tracks
from soabench.origins import N_SOURCES, origin_counts
from soabench.pmbm import cycle as pmbm_cycle
from soabench.pmbm import kernels
from soabench.pmbm.density import PMBMDensity
from soabench.pmbm.pmb import collapse
from soabench.pmbm.update import Hypotheses, update
from soabench.types import Births, Scan, StepResult, scan_once

#: the probability modes the PMBM family runs (docs/method.md §10.6): static, with or without ``occlusion_pd``
PMBM_MODES = ("static",)
EXTRACT_R = 0.5  #: estimator 1 (§10.4): a track is reported when its hypothesis has r above this
_F64, _I8, _I32 = np.dtype(np.float64), np.dtype(np.int8), np.dtype(np.int32)


_NO_BIRTHS = (np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4, 4)))


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


def _births_finite(births: Births) -> bool:
    """:func:`soabench.gmphd.inputs.births_finite` (every birth weight, mean and covariance finite, every weight
    >= 0, every newborn term finite), the birth components by one compiled call
    (:func:`soabench.gmphd.cycle.births_ok`, the same test) when they are plain arrays (:func:`_plain`). False also
    when they are not: :func:`~soabench.gmphd.inputs.check_step_inputs` then decides."""
    if not newborn_finite(births.newborn):
        return False
    J = len(births)
    if J == 0:
        return True
    w, m, P = births.w, births.m, births.P
    if _plain(w, _F64, (J,)) and _plain(m, _F64, (J, 4)) and _plain(P, _F64, (J, 4, 4)):
        return cycle.births_ok(w, m, P)
    return False


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
        """Step 3's reduction of every hypothesis's density (with ``pmb``: the collapse, compiled, and a second
        reduction) and step 4's estimates (compiled: :func:`soabench.pmbm.kernels.estimates`); the intensity ``ppp``
        is already reduced. Returns (posterior, X, X_r, labels)."""
        cfg, h = self.cfg, post.hyps
        T, U, J_h = float(cfg.prune_T), float(cfg.merge_U), int(self.pmbm.J_h)
        start, w, m, P = reduce_components(h.start, h.w, h.m, h.P, T, U, J_h)
        if self.pmb:
            parts = kernels.collapse(post.track, post.table, np.exp(post.log_w), h.r, h.label, h.origin, h.age, start,
                                     w, m, P)  # fmt: skip
            r, label, origin, age = parts[:4]
            start, w, m, P = reduce_components(*parts[4:], T, U, J_h)
            track = np.arange(len(r), dtype=np.int64)
            post = PMBMDensity(ppp, Tracks(r, label, origin, age, start, w, m, P), track, track[None, :], np.zeros(1))
            row = track
        else:
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
        if finite and _births_finite(births):  # what check_step_inputs returns for finite inputs
            checked = StepInputs(Z, ego, births, 0, 0)
        else:
            checked = check_step_inputs(scan.k, Z, ego, births, self.cfg.nonfinite, finite)
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
            raise SoabenchError(f"scan {scan.k}: the {self.name.upper()} filter produced a non-finite posterior from "
                                "finite inputs")  # fmt: skip
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
