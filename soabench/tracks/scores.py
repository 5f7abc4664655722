"""HOTA, CLEAR MOT and the identity metrics of one labelled sequence (docs/method.md, "Track metrics").

* HOTA with DetA, AssA and LocA per localisation threshold alpha in {0.05, ..., 0.95} and their means
  (Luiten et al. 2021);
* CLEAR MOT: MOTA, MOTP, ID switches, fragmentations, mostly tracked / partly tracked / mostly lost
  (Bernardin & Stiefelhagen 2008);
* IDF1 with IDP and IDR (Ristani et al. 2016).

Each follows the arithmetic of TrackEval's ``HOTA``, ``CLEAR`` and ``Identity`` metric classes step for step (the
same Hungarian problems, the same threshold tests with their machine-epsilon margins, the same results on empty
sequences), so the values equal TrackEval's to rounding; tests/test_track_metrics.py holds them to 1e-12 against
TrackEval itself. The scan-by-scan work that TrackEval repeats for each of its 19 alphas is done once here and the
alphas are applied to the stacked matches, which makes one call several times cheaper than TrackEval's three
``eval_sequence`` calls (benchmarks/bench_track_metrics.py).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, fields

import numpy as np
from scipy.optimize import linear_sum_assignment

from soabench.tracks.sequence import TrackSequence

#: HOTA's localisation thresholds alpha (TrackEval's ``array_labels``)
ALPHAS = np.arange(0.05, 0.99, 0.05)

#: CLEAR and Identity match threshold on S (S >= 0.5 <=> d <= d_gate, register row 30)
THRESHOLD = 0.5

_EPS = np.finfo(float).eps


@dataclass(frozen=True)
class TrackScores:
    """Every track metric of one sequence (docs/method.md, "Track metrics").

    Attributes:
        hota, deta, assa, loca: means over :data:`ALPHAS` of the per-alpha arrays ``*_alpha``.
        detre_alpha, detpr_alpha, assre_alpha, asspr_alpha: HOTA's detection and association recall / precision.
        mota, motp, moda: CLEAR MOT (MOTP = mean similarity of the matches).
        idsw, frag, mt, pt, ml, clr_tp, clr_fn, clr_fp: CLEAR counts.
        idf1, idp, idr, idtp, idfn, idfp: identity metrics and their counts.
    """

    hota: float
    deta: float
    assa: float
    loca: float
    hota_alpha: np.ndarray
    deta_alpha: np.ndarray
    assa_alpha: np.ndarray
    loca_alpha: np.ndarray
    detre_alpha: np.ndarray
    detpr_alpha: np.ndarray
    assre_alpha: np.ndarray
    asspr_alpha: np.ndarray
    mota: float
    motp: float
    moda: float
    idsw: int
    frag: int
    mt: int
    pt: int
    ml: int
    clr_tp: int
    clr_fn: int
    clr_fp: int
    idf1: float
    idp: float
    idr: float
    idtp: int
    idfn: int
    idfp: int

    def scalars(self) -> dict[str, float | int]:
        """The scalar fields (per-alpha arrays left out), in declaration order."""
        return {f.name: getattr(self, f.name) for f in fields(self) if not f.name.endswith("_alpha")}


def track_scores(gt_ids: Sequence, gt_xy: Sequence, est_ids: Sequence, est_xy: Sequence, d_gate: float) -> TrackScores:
    """HOTA, CLEAR MOT and identity metrics of K scans: ``gt_ids[k]`` (n,) int truth ids and ``gt_xy[k]`` (n, 2)
    their positions, ``est_ids[k]`` (m,) int estimate labels and ``est_xy[k]`` (m, 2) their positions; similarity
    ``S = max(0, 1 - d / (2 d_gate))``."""
    return scores_of(TrackSequence.of(gt_ids, gt_xy, est_ids, est_xy), d_gate)


def scores_of(seq: TrackSequence, d_gate: float) -> TrackScores:
    """:func:`track_scores` of a checked :class:`TrackSequence`."""
    nG, nT = len(seq.gt_labels), len(seq.est_labels)
    gt_count = np.bincount(seq.gt.ids, minlength=nG).astype(float)
    tr_count = np.bincount(seq.est.ids, minlength=nT).astype(float)
    alignment, id_potential = _global_counts(seq, d_gate, gt_count, tr_count)
    hota_pairs, clear = _scan_matches(seq, d_gate, alignment, nG)
    return TrackScores(
        **_hota(seq, hota_pairs, gt_count, tr_count),
        **clear,
        **_identity(seq, id_potential, gt_count, tr_count),
    )


def _global_counts(
    seq: TrackSequence, d_gate: float, gt_count: np.ndarray, tr_count: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """HOTA's global alignment score (nG, nT): the similarity-weighted Jaccard overlap of each truth-track pair
    summed over scans; and Identity's potential-match counts (nG, nT) (pairs with S >= :data:`THRESHOLD`)."""
    nG, nT = len(gt_count), len(tr_count)
    potential = np.zeros(nG * nT)
    id_potential = np.zeros(nG * nT)
    for _, S, g, e in seq.blocks(d_gate):
        denom = S.sum(axis=1)[:, None, :] + S.sum(axis=2)[:, :, None] - S
        iou = np.zeros_like(S)
        np.divide(S, denom, out=iou, where=denom > _EPS)
        valid = (g[:, :, None] >= 0) & (e[:, None, :] >= 0)
        cell = (g[:, :, None] * nT + e[:, None, :])[valid]
        potential += np.bincount(cell, weights=iou[valid], minlength=nG * nT)
        id_potential += np.bincount(cell, weights=S[valid] >= THRESHOLD, minlength=nG * nT)
    potential = potential.reshape(nG, nT)
    with np.errstate(invalid="ignore", divide="ignore"):
        alignment = potential / (gt_count[:, None] + tr_count[None, :] - potential)
    return alignment, id_potential.reshape(nG, nT)


def _scans(seq: TrackSequence, d_gate: float) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Scan by scan: contiguous truth ids, estimate ids and their (n_gt, n_est) similarities."""
    n_g, n_e = np.diff(seq.gt.off), np.diff(seq.est.off)
    for scans, S, g, e in seq.blocks(d_gate):
        for b, t in enumerate(scans):
            yield g[b, : n_g[t]], e[b, : n_e[t]], S[b, : n_g[t], : n_e[t]]


def _scan_matches(
    seq: TrackSequence, d_gate: float, alignment: np.ndarray, nG: int
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], dict[str, float | int]]:
    """Scan by scan: HOTA's alignment-weighted Hungarian matches (gt index, estimate index, S; every alpha is
    applied later) and the CLEAR MOT counts (its matching keeps the previous scan's pairs first)."""
    hg, he, hs = [], [], []
    tp = fn = fp = idsw = 0
    motp_sum = 0.0
    gt_seen = np.zeros(nG)
    gt_matched = np.zeros(nG)
    frag_count = np.zeros(nG)
    prev_id = np.full(nG, -1, dtype=np.int64)  # last estimate matched to each truth, any scan before
    prev_scan_id = np.full(nG, -1, dtype=np.int64)  # estimate matched on the previous scan with both sets non-empty
    for g, e, sim in _scans(seq, d_gate):
        if len(g) == 0:
            fp += len(e)
            continue
        if len(e) == 0:
            fn += len(g)
            gt_seen[g] += 1
            continue
        rows, cols = linear_sum_assignment(-(alignment[g[:, None], e[None, :]] * sim))
        hg.append(g[rows])
        he.append(e[cols])
        hs.append(sim[rows, cols])
        score = 1000.0 * (e[None, :] == prev_scan_id[g[:, None]]) + sim
        score[sim < THRESHOLD - _EPS] = 0
        rows, cols = linear_sum_assignment(-score)
        kept = score[rows, cols] > _EPS
        rows, cols = rows[kept], cols[kept]
        mg, me = g[rows], e[cols]
        before = prev_id[mg]
        idsw += int(np.sum((before >= 0) & (me != before)))
        gt_seen[g] += 1
        gt_matched[mg] += 1
        untracked = prev_scan_id < 0
        prev_id[mg] = me
        prev_scan_id[:] = -1
        prev_scan_id[mg] = me
        frag_count += untracked & (prev_scan_id >= 0)
        tp += len(mg)
        fn += len(g) - len(mg)
        fp += len(e) - len(mg)
        motp_sum += float(np.sum(sim[rows, cols]))
    pairs = (
        np.concatenate(hg) if hg else np.zeros(0, dtype=np.int64),
        np.concatenate(he) if he else np.zeros(0, dtype=np.int64),
        np.concatenate(hs) if hs else np.zeros(0),
    )
    return pairs, _clear_fields(seq, tp, fn, fp, idsw, motp_sum, gt_seen, gt_matched, frag_count, nG)


def _clear_fields(
    seq: TrackSequence,
    tp: int,
    fn: int,
    fp: int,
    idsw: int,
    motp_sum: float,
    gt_seen: np.ndarray,
    gt_matched: np.ndarray,
    frag_count: np.ndarray,
    nG: int,
) -> dict[str, float | int]:
    """MOTA, MOTP, MODA and the CLEAR counts; TrackEval's values for an empty truth or estimate sequence."""
    if seq.n_est_dets == 0 or seq.n_gt_dets == 0:
        zero = {"mota": 0.0, "motp": 0.0, "moda": 0.0, "idsw": 0, "frag": 0, "mt": 0, "pt": 0, "clr_tp": 0}
        return {**zero, "ml": nG, "clr_fn": seq.n_gt_dets, "clr_fp": seq.n_est_dets}
    seen = gt_seen > 0
    ratio = gt_matched[seen] / gt_seen[seen]
    mt = int(np.sum(ratio > 0.8))
    pt = int(np.sum(ratio >= 0.2)) - mt
    denom = max(1.0, tp + fn)
    return {
        "mota": (tp - fp - idsw) / denom,
        "motp": motp_sum / max(1.0, tp),
        "moda": (tp - fp) / denom,
        "idsw": idsw,
        "frag": int(np.sum(frag_count[frag_count > 0] - 1)),
        "mt": mt,
        "pt": pt,
        "ml": nG - mt - pt,
        "clr_tp": tp,
        "clr_fn": fn,
        "clr_fp": fp,
    }


def _hota(
    seq: TrackSequence,
    pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
    gt_count: np.ndarray,
    tr_count: np.ndarray,
) -> dict[str, float | np.ndarray]:
    """HOTA, DetA, AssA, LocA (and recall / precision parts) per alpha from the stacked per-scan matches."""
    A = len(ALPHAS)
    zeros = np.zeros(A)
    if seq.n_est_dets == 0 or seq.n_gt_dets == 0:
        out = {f"{k}_alpha": zeros.copy() for k in ("hota", "deta", "assa", "detre", "detpr", "assre", "asspr")}
        out["loca_alpha"] = np.ones(A)
    else:
        mg, me, ms = pairs
        nT = len(tr_count)
        hit = ms[None, :] >= ALPHAS[:, None] - _EPS  # (A, n_matches)
        tp = hit.sum(axis=1).astype(float)
        loc = np.array([ms[h].sum() for h in hit])
        cell = mg * nT + me
        assa, assre, asspr = np.zeros(A), np.zeros(A), np.zeros(A)
        union = gt_count[:, None] + tr_count[None, :]
        for a in range(A):
            count = np.bincount(cell[hit[a]], minlength=len(gt_count) * nT).reshape(len(gt_count), nT).astype(float)
            den = max(1.0, tp[a])
            assa[a] = np.sum(count * (count / np.maximum(1, union - count))) / den
            assre[a] = np.sum(count * (count / np.maximum(1, gt_count[:, None]))) / den
            asspr[a] = np.sum(count * (count / np.maximum(1, tr_count[None, :]))) / den
        fn = seq.n_gt_dets - tp
        fp = seq.n_est_dets - tp
        deta = tp / np.maximum(1, tp + fn + fp)
        out = {
            "hota_alpha": np.sqrt(deta * assa),
            "deta_alpha": deta,
            "assa_alpha": assa,
            "loca_alpha": np.maximum(1e-10, loc) / np.maximum(1e-10, tp),
            "detre_alpha": tp / np.maximum(1, tp + fn),
            "detpr_alpha": tp / np.maximum(1, tp + fp),
            "assre_alpha": assre,
            "asspr_alpha": asspr,
        }
    means = {k: float(np.mean(out[f"{k}_alpha"])) for k in ("hota", "deta", "assa", "loca")}
    return {**means, **out}


def _identity(
    seq: TrackSequence, potential: np.ndarray, gt_count: np.ndarray, tr_count: np.ndarray
) -> dict[str, float | int]:
    """IDF1, IDP, IDR: the one-to-one truth-to-track assignment that minimises IDFN + IDFP (Ristani et al. 2016)."""
    if seq.n_est_dets == 0 or seq.n_gt_dets == 0:
        return {"idf1": 0.0, "idp": 0.0, "idr": 0.0, "idtp": 0, "idfn": seq.n_gt_dets, "idfp": seq.n_est_dets}
    nG, nT = len(gt_count), len(tr_count)
    n = nG + nT
    fp_mat = np.zeros((n, n))
    fn_mat = np.zeros((n, n))
    fp_mat[nG:, :nT] = 1e10
    fn_mat[:nG, nT:] = 1e10
    fn_mat[:nG, :nT] = gt_count[:, None]
    fn_mat[np.arange(nG), nT + np.arange(nG)] = gt_count
    fp_mat[:nG, :nT] = tr_count[None, :]
    fp_mat[nG + np.arange(nT), np.arange(nT)] = tr_count
    fn_mat[:nG, :nT] -= potential
    fp_mat[:nG, :nT] -= potential
    rows, cols = linear_sum_assignment(fn_mat + fp_mat)
    idfn = int(fn_mat[rows, cols].sum())
    idfp = int(fp_mat[rows, cols].sum())
    idtp = int(gt_count.sum()) - idfn
    return {
        "idf1": idtp / max(1.0, idtp + 0.5 * idfp + 0.5 * idfn),
        "idp": idtp / max(1.0, idtp + idfp),
        "idr": idtp / max(1.0, idtp + idfn),
        "idtp": idtp,
        "idfn": idfn,
        "idfp": idfp,
    }
