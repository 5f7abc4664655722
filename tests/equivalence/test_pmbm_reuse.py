"""Values the PMBM/PMB step computes once and reuses, against computing them afresh (docs/method.md §10.3).

The step keeps the hypothesis probabilities of its posterior for the next update (the prediction keeps the global
table), stacks the predicted intensity, the births and the hypotheses once, evaluates the FOV gate on all the means
in one call, and sums the per-track log terms without ``reduceat`` when every track has one component. Each must
give the same bits as the plain computation.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from soabench.birth import get_birth_model
from soabench.gmphd.mixture import Mixture
from soabench.gmphd.models import predict as predict_mixture
from soabench.gmphd.probabilities import detection_gate
from soabench.lmb.update import _segment_logsumexp
from soabench.lmb.update import predict as predict_tracks
from soabench.pmbm import PMBMFilter
from soabench.types import BirthContext, Births

STEP_FIELDS = ("k", "X", "X_w", "labels", "sum_w", "sum_w_reduced", "n_predicted", "n_updated", "n_reduced",
               "cap_hit", "A", "kappa", "n_pruned", "n_merged", "n_pairs", "n_newborn", "origin_counts")  # fmt: skip


def _same_bits(a, b, what: str) -> None:
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape, what
    assert a.tobytes() == b.tobytes(), what


def _mixture_fields(mix: Mixture) -> tuple:
    return mix.w, mix.m, mix.P, mix.origin, mix.n_det, mix.age, mix.label


def _reference_predict(f: PMBMFilter, births):
    """The prediction as the GM-PHD's mixture functions build it, and the means/covariances stacked after it."""
    d, cfg = f.density, f.cfg
    ppp = predict_mixture(d.ppp, f.F, f.Q, cfg.p_S)
    if len(births):
        born = Mixture.from_arrays(births.w, births.m, births.P, origin=births.source)
        ppp = Mixture.concatenate([ppp, born]) if len(ppp) else born
    hyps = predict_tracks(d.hyps, f.F, f.Q, cfg.p_S)
    return ppp, hyps, np.concatenate([ppp.m, hyps.m]), np.concatenate([ppp.P, hyps.P])


@pytest.mark.parametrize("pmb,model", [(False, "pubm"), (True, "soa")])
def test_reused_values_equal_recomputed(recorded_intersection, pmb, model):
    """A filter whose posterior is replaced by an equal copy before every step (so nothing is reused from the last
    step) gives the same bits as one that reuses; the reused hypothesis probabilities are the posterior's; the
    stacked prediction is the mixture functions'."""
    cfg, scene, scans_by_lam, seeds = recorded_intersection
    sensor, scans = scans_by_lam[3.0]
    reuse = PMBMFilter(cfg.filter, sensor, pmbm_cfg=cfg.pmbm, pmb=pmb)
    fresh = PMBMFilter(cfg.filter, sensor, pmbm_cfg=cfg.pmbm, pmb=pmb)
    birth = get_birth_model(model)(cfg.birth, sensor, scene, seeds.placement_rng())
    prev, n_global, cases = None, 0, set()
    for scan in scans.scans:
        births = birth(BirthContext(scan, prev, cfg.filter.p_D))
        for b in (births, Births.empty()):  # with and without birth components
            ref_ppp, ref_hyps, ref_m, ref_P = _reference_predict(reuse, b)
            pred, m_all, P_all = reuse._predict(b)
            cases.add((len(reuse.density.ppp) > 0, len(b) > 0, len(reuse.density.hyps) > 0))
            for name, x, y in zip("w m P origin n_det age label".split(), _mixture_fields(pred.ppp),
                                  _mixture_fields(ref_ppp), strict=True):  # fmt: skip
                _same_bits(x, y, f"scan {scan.k}: ppp.{name}")
            for name in ("r", "label", "origin", "age", "start", "w", "m", "P"):
                _same_bits(getattr(pred.hyps, name), getattr(ref_hyps, name), f"scan {scan.k}: hyps.{name}")
            _same_bits(m_all, ref_m, f"scan {scan.k}: stacked means")
            _same_bits(P_all, ref_P, f"scan {scan.k}: stacked covariances")

        fresh.density = dataclasses.replace(fresh.density)  # an equal density, another object: nothing reused
        a, prev = reuse.step(scan, births), fresh.step(scan, births)
        for name in STEP_FIELDS:
            _same_bits(getattr(a, name), getattr(prev, name), f"scan {scan.k}: {name}")
        for name in ("log_w", "table", "track"):
            _same_bits(getattr(reuse.density, name), getattr(fresh.density, name), f"scan {scan.k}: {name}")
        for name in ("r", "w", "m", "P"):
            _same_bits(getattr(reuse.density.hyps, name), getattr(fresh.density.hyps, name), f"scan {scan.k}: {name}")
        held, p_hyp = reuse._p_hyp
        assert held is reuse.density
        _same_bits(p_hyp, reuse.density.hypothesis_probabilities(), f"scan {scan.k}: hypothesis probabilities")
        n_global = max(n_global, len(reuse.density.log_w))
    assert pmb or n_global > 1  # the PMBM kept several global hypotheses at some scan
    assert any(c[2] for c in cases)  # predictions with tracks
    if model == "soa":  # every case of the stacking: an intensity or not, birth components or not
        assert {c[:2] for c in cases} == {(False, False), (False, True), (True, False), (True, True)}


@pytest.mark.parametrize("fov_deg", [360.0, 90.0])
def test_fov_gate_on_stacked_means_is_per_mean(recorded_intersection, fov_deg):
    """The FOV gate of all the means in one call equals the gates of the intensity's and the hypotheses' means
    apart, including means on the range and bearing limits."""
    cfg, _, scans_by_lam, _ = recorded_intersection
    sensor = dataclasses.replace(scans_by_lam[3.0][0], fov_deg=fov_deg)
    rng = np.random.default_rng(3)
    ego = np.array([2.0, -1.0, 0.4])
    for n_a, n_b in ((0, 5), (1, 1), (7, 0), (13, 40), (200, 3)):
        m = rng.normal(0.0, 30.0, (n_a + n_b, 4))
        r = rng.choice([sensor.r_min, sensor.r_max, 10.0], n_a + n_b)
        b = ego[2] + rng.choice([0.5 * sensor.fov, -0.5 * sensor.fov, 0.1], n_a + n_b)
        edge = rng.random(n_a + n_b) < 0.5  # half of the means on a limit (as computed from the pose)
        m[edge, 0] = ego[0] + r[edge] * np.cos(b[edge])
        m[edge, 1] = ego[1] + r[edge] * np.sin(b[edge])
        whole = detection_gate(m, ego, sensor)
        parts = np.concatenate([detection_gate(m[:n_a], ego, sensor), detection_gate(m[n_a:], ego, sensor)])
        _same_bits(whole, parts, f"{n_a} + {n_b} means")
        assert 0 < whole.sum() < len(whole) or len(whole) < 3


def _segment_logsumexp_reduceat(x, start):
    """The per-segment log-sum-exp by ``reduceat`` whatever the segments (the general path)."""
    seg = start[:-1]
    mx = np.maximum.reduceat(x, seg, axis=0)
    shift = np.where(np.isfinite(mx), mx, 0.0)
    owner = np.repeat(np.arange(len(seg)), np.diff(start))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(np.add.reduceat(np.exp(x - shift[owner]), seg, axis=0)) + shift


def test_segment_logsumexp_of_one_row_segments_is_the_reduceats():
    """With every segment one row the sums skip ``reduceat``: the same bits as with it, for finite, -inf, NaN and
    -0.0 entries, in one and two dimensions; and segments of several rows still take it."""
    rng = np.random.default_rng(8)
    special = np.array([-np.inf, np.nan, -0.0, 0.0, -745.0, 709.0, 1e-300])
    for n in (1, 2, 5, 33):
        for shape in ((n,), (n, 4)):
            x = rng.normal(0.0, 50.0, shape)
            x.flat[rng.integers(0, x.size, x.size // 2 + 1)] = rng.choice(special, x.size // 2 + 1)
            with np.errstate(invalid="ignore"):
                got = _segment_logsumexp(x, np.arange(n + 1, dtype=np.int64))
                _same_bits(got, _segment_logsumexp_reduceat(x, np.arange(n + 1, dtype=np.int64)), f"{shape}")
            if n > 1:  # one segment of two rows: the general path
                start = np.concatenate([[0, 2], np.arange(3, n + 1)]).astype(np.int64)
                with np.errstate(invalid="ignore"):
                    _same_bits(_segment_logsumexp(x, start), _segment_logsumexp_reduceat(x, start), f"{shape} mixed")
