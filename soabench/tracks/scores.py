"""HOTA, CLEAR MOT and the identity metrics of one labelled sequence (docs/method.md §9.3).

* HOTA with DetA, AssA and LocA per localisation threshold alpha in {0.05, ..., 0.95} and their means
  (Luiten et al. 2021);
* CLEAR MOT: MOTA, MOTP, ID switches, fragmentations, mostly tracked / partly tracked / mostly lost
  (Bernardin & Stiefelhagen 2008);
* IDF1 with IDP and IDR (Ristani et al. 2016).

Each follows the arithmetic of TrackEval's ``HOTA``, ``CLEAR`` and ``Identity`` metric classes step for step (the
same Hungarian problems, the same threshold tests with their machine-epsilon margins, the same results on empty
sequences), so the values equal TrackEval's to rounding; tests/unit/test_track_metrics.py holds them to 1e-12 against
TrackEval itself. The scan-by-scan matching is one compiled loop (:mod:`soabench.tracks.kernels`), done once for
all 19 alphas, which are then applied to the stacked matches; benchmarks/bench_track_metrics.py times it against
TrackEval's three ``eval_sequence`` calls.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np
from scipy.optimize import linear_sum_assignment

from soabench.notice import announced
from soabench.tracks.sequence import BLOCK_CELLS, TrackSequence

#: HOTA's localisation thresholds alpha (TrackEval's ``array_labels``)
ALPHAS = np.arange(0.05, 0.99, 0.05)

#: CLEAR and Identity match threshold on S (S >= 0.5 <=> d <= d_gate, register row 30)
THRESHOLD = 0.5

_EPS = np.finfo(float).eps


@dataclass(frozen=True)
class TrackScores:
    """Every track metric of one sequence (docs/method.md §9.3).

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
    alignment, id_potential, id_cells = _global_counts(seq, d_gate, gt_count, tr_count)
    hota_pairs, clear = _scan_matches(seq, d_gate, alignment, nG)
    return TrackScores(
        **_hota(seq, hota_pairs, gt_count, tr_count),
        **clear,
        **_identity(seq, id_potential, id_cells, gt_count, tr_count),
    )


def _global_counts(
    seq: TrackSequence, d_gate: float, gt_count: np.ndarray, tr_count: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """HOTA's global alignment score (nG, nT): the similarity-weighted Jaccard overlap of each truth-track pair
    summed over scans; Identity's potential-match counts (nG, nT) (pairs with S >= :data:`THRESHOLD`) and their
    non-zero cells (truth * nT + track, sorted).

    TrackEval's sums over padded runs of scans (:meth:`TrackSequence.blocks`), in one compiled loop over the pairs
    of non-zero similarity (:func:`soabench.tracks.kernels.global_counts`, the same operations in the same order)."""
    from soabench.tracks.kernels import global_counts

    nG, nT = len(gt_count), len(tr_count)
    potential = np.zeros(nG * nT)
    id_potential = np.zeros(nG * nT)
    g, e = seq.gt, seq.est
    G, E = int(np.diff(g.off).max(initial=0)), int(np.diff(e.off).max(initial=0))
    step = max(1, BLOCK_CELLS // max(1, G * E))
    args = (g.ids, g.off, g.xy, e.ids, e.off, e.xy, float(d_gate), THRESHOLD, step, nT, potential, id_potential)
    on, id_cells = announced("track metrics", global_counts, *args)
    # potential / (gt_count + tr_count - potential) per cell; a cell without overlap is 0 / (a positive count) = 0.0
    on = np.sort(on)
    alignment = np.zeros(nG * nT)
    with np.errstate(invalid="ignore", divide="ignore"):
        alignment[on] = potential[on] / (gt_count[on // nT] + tr_count[on % nT] - potential[on])
    return alignment.reshape(nG, nT), id_potential.reshape(nG, nT), np.sort(id_cells)


@dataclass
class _MatchState:
    """What the scan loop of :func:`_scan_matches` carries from scan to scan (the order of :meth:`arrays` is the
    order :func:`soabench.tracks.kernels.match_scans` unpacks).

    Attributes:
        counts: CLEAR's TP, FN, FP, IDSW and the number of HOTA pairs so far; motp: (1,) sum of matched S.
        gt_seen, gt_matched, frag: per truth, scans present, scans matched, starts of a matched run.
        prev_id: per truth, the estimate last matched to it on any scan before (-1: none).
        prev_scan: per truth, the estimate matched on the previous scan with truth and estimates (-1: none).
        hg, he, hs: HOTA's matches (truth, estimate, S), the first ``counts[4]`` rows.
    """

    counts: np.ndarray
    motp: np.ndarray
    gt_seen: np.ndarray
    gt_matched: np.ndarray
    frag: np.ndarray
    prev_id: np.ndarray
    prev_scan: np.ndarray
    hg: np.ndarray
    he: np.ndarray
    hs: np.ndarray

    @classmethod
    def new(cls, nG: int, n_pairs: int) -> _MatchState:
        f, i = np.zeros(nG), np.full(nG, -1, dtype=np.int64)
        pairs = np.zeros(n_pairs, dtype=np.int64)
        return cls(np.zeros(5, dtype=np.int64), np.zeros(1), f, f.copy(), f.copy(), i, i.copy(), pairs, pairs.copy(),
                   np.zeros(n_pairs))  # fmt: skip

    def arrays(self) -> tuple[np.ndarray, ...]:
        return (self.counts, self.motp, self.gt_seen, self.gt_matched, self.frag, self.prev_id, self.prev_scan,
                self.hg, self.he, self.hs)  # fmt: skip

    def match(self, g: np.ndarray, e: np.ndarray, sim: np.ndarray, cost: np.ndarray, clear_cost: np.ndarray) -> None:
        """One scan with truths ``g`` and estimates ``e``, matched with scipy (a scan the compiled loop leaves to it):
        ``sim`` their similarity, ``cost`` HOTA's ``-(alignment * sim)``, ``clear_cost`` CLEAR's ``-score`` (1000 for
        the previous scan's pair plus ``sim``, 0 below the threshold)."""
        rows, cols = linear_sum_assignment(cost)
        n = self.counts[4]
        self.hg[n : n + len(rows)], self.he[n : n + len(rows)], self.hs[n : n + len(rows)] = (
            g[rows],
            e[cols],
            sim[rows, cols],
        )
        self.counts[4] = n + len(rows)
        score = -clear_cost
        rows, cols = linear_sum_assignment(clear_cost)
        kept = score[rows, cols] > _EPS
        rows, cols = rows[kept], cols[kept]
        mg, me = g[rows], e[cols]
        before = self.prev_id[mg]
        self.counts[3] += int(np.sum((before >= 0) & (me != before)))
        self.gt_seen[g] += 1
        self.gt_matched[mg] += 1
        untracked = self.prev_scan < 0
        self.prev_id[mg] = me
        self.prev_scan[:] = -1
        self.prev_scan[mg] = me
        self.frag += untracked & (self.prev_scan >= 0)
        self.counts[:3] += (len(mg), len(g) - len(mg), len(e) - len(mg))
        self.motp[0] += sum(sim[rows, cols])


def _scan_matches(
    seq: TrackSequence, d_gate: float, alignment: np.ndarray, nG: int
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], dict[str, float | int]]:
    """Scan by scan: HOTA's alignment-weighted Hungarian matches (truth, estimate, S; every alpha is applied
    later) and the CLEAR MOT counts (its matching keeps the previous scan's pairs first). The compiled loop
    (:func:`soabench.tracks.kernels.match_scans`) hands a scan with two equal positions to scipy."""
    from soabench.tracks.kernels import match_scans  # numba is imported on first use, not with the package

    g, e = seq.gt, seq.est
    state = _MatchState.new(nG, int(np.minimum(np.diff(g.off), np.diff(e.off)).sum()))
    t, K = 0, len(seq)
    while t < K:
        args = (t, g.ids, g.off, g.xy, e.ids, e.off, e.xy, float(d_gate), THRESHOLD, alignment, state.arrays())
        t, *costs = announced("track metrics", match_scans, *args)
        if t < K:
            gs, es = slice(g.off[t], g.off[t + 1]), slice(e.off[t], e.off[t + 1])
            state.match(g.ids[gs], e.ids[es], *costs)
            t += 1
    n = state.counts[4]
    tp, fn, fp, idsw = (int(x) for x in state.counts[:4])
    clear = _clear_fields(seq, tp, fn, fp, idsw, float(state.motp[0]), state.gt_seen, state.gt_matched, state.frag, nG)
    return (state.hg[:n], state.he[:n], state.hs[:n]), clear


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
        assa, assre, asspr = _association(mg * nT + me, hit, gt_count, tr_count, tp)
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


def _association(
    cell: np.ndarray, hit: np.ndarray, gt_count: np.ndarray, tr_count: np.ndarray, tp: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """HOTA's AssA, AssRe and AssPr per alpha from the matches' cells (truth * nT + track) and ``hit`` (A, matches).

    Per alpha, TrackEval sums ``count * (count / max(1, union - count))`` (and the recall and precision forms) over
    the dense (nG, nT) array of match counts. The cells with a match at some alpha are sorted once, each alpha's
    counts are found per cell (0 where it has none there, whose terms are 0.0), and the 3 x 19 sums are taken over
    those cells only, in one call of :func:`sparse_np_sum`: numpy's pairwise sum of each dense array bit for bit (a
    zero cell adds nothing)."""
    from soabench.tracks.kernels import sparse_np_sum

    A, nT = len(hit), len(tr_count)
    order = np.argsort(cell, kind="stable")
    cells, first = np.unique(cell[order], return_index=True)
    g, t = cells // nT, cells % nT
    union = gt_count[g] + tr_count[t]
    terms = np.zeros((len(cells), 3, A))
    for a in range(A):
        c = np.add.reduceat(hit[a][order].astype(np.int64), first).astype(float) if len(cells) else np.zeros(0)
        terms[:, 0, a] = c * (c / np.maximum(1, union - c))
        terms[:, 1, a] = c * (c / np.maximum(1, gt_count[g]))
        terms[:, 2, a] = c * (c / np.maximum(1, tr_count[t]))
    sums = announced("track metrics", sparse_np_sum, cells, terms.reshape(len(cells), 3 * A), len(gt_count) * nT)
    out = sums.reshape(3, A) / np.maximum(1.0, tp)
    return out[0], out[1], out[2]


def _identity(
    seq: TrackSequence, potential: np.ndarray, cells: np.ndarray, gt_count: np.ndarray, tr_count: np.ndarray
) -> dict[str, float | int]:
    """IDF1, IDP, IDR: the one-to-one truth-to-track assignment that minimises IDFN + IDFP (Ristani et al. 2016).

    TrackEval poses it as one square assignment over every truth and every track, each with a dummy partner: pairing
    truth g with track t costs their unmatched detections, ``gt_count[g] + tr_count[t] - 2 potential[g, t]``, and
    leaving either unpaired costs its own count. So the minimum is ``sum(gt_count) + sum(tr_count) - 2 M``, with M
    the largest total ``potential`` of a matching of truths to tracks (:func:`_identity_matched`), and IDFN =
    ``sum(gt_count) - M``, IDFP = ``sum(tr_count) - M``: integer counts, equal for every optimal assignment."""
    if seq.n_est_dets == 0 or seq.n_gt_dets == 0:
        return {"idf1": 0.0, "idp": 0.0, "idr": 0.0, "idtp": 0, "idfn": seq.n_gt_dets, "idfp": seq.n_est_dets}
    matched = _identity_matched(potential, cells)
    idfn = int(gt_count.sum() - matched)
    idfp = int(tr_count.sum() - matched)
    idtp = int(gt_count.sum()) - idfn
    return {
        "idf1": idtp / max(1.0, idtp + 0.5 * idfp + 0.5 * idfn),
        "idp": idtp / max(1.0, idtp + idfp),
        "idr": idtp / max(1.0, idtp + idfn),
        "idtp": idtp,
        "idfn": idfn,
        "idfp": idfp,
    }


def _identity_matched(potential: np.ndarray, cells: np.ndarray | None = None) -> float:
    """The largest total of ``potential`` (nG, nT) (counts of scans where a truth and a track match) over the
    one-to-one matchings of truths to tracks; ``cells``: its non-zero cells (truth * nT + track, sorted) if known.

    A pair without a potential match adds nothing, so only the pairs with ``potential > 0`` are listed, each truth
    free to stay unmatched at no gain: one sparse minimum-cost assignment of the negated counts
    (:func:`soabench.tracks.kernels.sparse_assign_rows`). Every term is an integer count, so the sums are exact and
    the total is the same whichever optimal matching is found."""
    from soabench.tracks.kernels import sparse_assign_rows

    nG, nT = potential.shape
    if cells is None:
        cells = np.flatnonzero(potential)
    g, t = cells // nT, cells % nT  # row by row: each truth's pairs together
    if len(g) == 0:
        return 0.0
    off = np.zeros(nG + 1, dtype=np.int64)
    np.cumsum(np.bincount(g, minlength=nG), out=off[1:])
    col = announced("track metrics", sparse_assign_rows, nG, nT, off, t.astype(np.int64), -potential[g, t], 0.0)
    rows = np.flatnonzero(col >= 0)
    return float(potential[rows, col[rows]].sum())
