"""Every track measure of one filter run (docs/method.md §9.3, §9.4): the columns a trial adds beside §5's.

:func:`evaluate_tracks` reads the truth of :class:`~soabench.types.Scans` (positions, presence, FOV, line of sight),
the tracker's extracted positions and, if it labels them, their labels, and the §5.4 delay episodes that
:func:`soabench.metrics.evaluate` already built. Truth ids are the pedestrians' track labels (``Scans.ped_labels``);
truth and estimates are the sets of docs/method.md §5.1. The position-only measures (entry and re-emergence delay,
coasted) are computed for every tracker; the label measures (HOTA ... OSPA(2), HOTA per alpha, identity kept) are
None for an unlabelled one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from soabench.errors import SoabenchError
from soabench.metrics import Episode, estimate_mask, gt_mask
from soabench.tracks.gaps import describe_gaps
from soabench.tracks.ospa2 import ospa2_of
from soabench.tracks.reemergence import NO_LABEL, associated_labels, gap_outcomes, occlusion_gaps, reemergence
from soabench.tracks.scores import ALPHAS, scores_of
from soabench.tracks.sequence import ScanRows, TrackSequence, checked

if TYPE_CHECKING:
    from soabench.config import MetricsConfig, SensorConfig
    from soabench.types import Scans

#: per-run columns that need labels (None for an unlabelled tracker), in table order
LABEL_KEYS = (
    "hota", "deta", "assa", "loca", "mota", "motp", "idsw", "frag", "mt", "pt", "ml", "idf1", "idp", "idr",
    "ospa2", "ospa2_loc", "ospa2_card",
)  # fmt: skip

#: per-run columns of the re-emergence measures (§9.4); ``id_kept`` and ``n_id`` are None for an unlabelled tracker
REEMERGENCE_KEYS = (
    "delay_entry_mean", "delay_entry_std", "n_entry", "n_entry_censored",
    "delay_reemergence_mean", "delay_reemergence_std", "n_reemergence", "n_reemergence_censored",
    "coasted", "n_gaps", "id_kept", "n_id",
)  # fmt: skip

#: per-run columns of HOTA at each localisation threshold alpha (TrackEval's HOTA___5 ... HOTA___95); None unlabelled
ALPHA_KEYS = tuple(f"hota_a{round(100 * a):02d}" for a in ALPHAS)

#: every per-run column of this module, in table order
TRACK_KEYS = LABEL_KEYS + REEMERGENCE_KEYS + ALPHA_KEYS

#: per-episode columns of the gap before a re-emergence episode (§9.4, :mod:`soabench.tracks.gaps`): its length in
#: scans and seconds, the occluder kind that hid the target longest, the target's displacement across the gap (m) and
#: whether it exceeds d_gate, the ego's and whether it exceeds EGO_MOVED_M, whether the gap was coasted and whether
#: the identity was kept (NaN: unlabelled tracker or not counted); NaN and no occluder for an entry episode
GAP_KEYS = (
    "gap_scans", "gap_s", "gap_occluder", "gap_moved", "gap_displacement", "gap_ego_moved", "gap_ego_displacement",
    "gap_coasted", "gap_id_kept",
)  # fmt: skip
#: the gap cells of an entry episode (and of a re-emergence's identity kept where it is not counted): NaN numbers,
#: an empty occluder; numbers are floats throughout (1.0 / 0.0 for the flags), so a column never mixes ints and NaN
NO_GAP: dict[str, float | str | None] = {k: None if k == "gap_occluder" else math.nan for k in GAP_KEYS}


def _offsets(counts: np.ndarray) -> np.ndarray:
    """Row offsets (K + 1,) of per-scan row counts (K,)."""
    off = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts, out=off[1:])
    return off


def _estimate_rows(
    scans: Scans, X: Sequence[np.ndarray], labels: Sequence[np.ndarray] | None, gt_set: str, sensor_cfg: SensorConfig
) -> ScanRows:
    """Est_k of every scan stacked (docs/method.md §5.1: restricted to FOV_k unless ``gt_set`` is "scene"; one FOV
    test for all scans, each row with its scan's pose) with their labels (-1 for an unlabelled tracker)."""
    xy = [np.asarray(x, dtype=float).reshape(len(x), -1)[:, :2] if np.size(x) else np.zeros((0, 2)) for x in X]
    counts = np.fromiter((len(x) for x in xy), dtype=np.int64, count=len(xy))
    E = np.concatenate(xy) if xy else np.zeros((0, 2))
    if labels is None:
        ids = np.full(len(E), -1, dtype=np.int64)
    else:
        lab = [np.asarray(v).reshape(-1) if np.size(v) else np.zeros(0, dtype=np.int64) for v in labels]
        n_lab = np.fromiter((len(v) for v in lab), dtype=np.int64, count=len(lab))
        if (n_lab != counts).any():
            k = int(np.flatnonzero(n_lab != counts)[0])
            raise SoabenchError(f"estimates at scan {k}: {n_lab[k]} labels for {counts[k]} estimates")
        ids = np.concatenate(lab) if lab else np.zeros(0, dtype=np.int64)
    scan = np.repeat(np.arange(len(counts)), counts)
    keep = np.ones(len(E), dtype=bool)
    if gt_set != "scene" and len(E):
        egos = np.array([s.ego for s in scans.scans], dtype=float).reshape(-1, 3)
        keep = estimate_mask(E, egos[scan], sensor_cfg, gt_set)
    rows = ScanRows(ids[keep], E[keep], _offsets(np.bincount(scan[keep], minlength=len(counts))))
    return rows if labels is None else checked(rows.ids, rows.xy, rows.off, "estimates")


def estimate_sets(
    scans: Scans, X: Sequence[np.ndarray], labels: Sequence[np.ndarray] | None, gt_set: str, sensor_cfg: SensorConfig
) -> tuple[list[np.ndarray], list[np.ndarray] | None]:
    """Est_k of every scan (docs/method.md §5.1) as positions (K lists of (n_k, 2)) and, for a labelled tracker,
    their labels (None for an unlabelled one): what the track measures match against the truth."""
    est = _estimate_rows(scans, X, labels, gt_set, sensor_cfg)
    return np.split(est.xy, est.off[1:-1]), None if labels is None else np.split(est.ids, est.off[1:-1])


def run_labels(results: Sequence, X: Sequence[np.ndarray]) -> list[np.ndarray] | None:
    """The per-scan labels of a filter run's results (``results[k].labels``, ``X[k]`` its estimates), or None for
    an unlabelled run: a run is labelled when some scan carries labels and every scan with estimates does (a scan
    without estimates may carry none)."""
    labelled = any(r.labels is not None for r in results) and all(
        r.labels is not None or len(x) == 0 for r, x in zip(results, X, strict=True)
    )
    return [np.zeros(0, np.int64) if r.labels is None else r.labels for r in results] if labelled else None


def evaluate_tracks(
    scans: Scans,
    X: Sequence[np.ndarray],
    labels: Sequence[np.ndarray] | None,
    episodes: Sequence[Episode],
    cfg: MetricsConfig,
    sensor_cfg: SensorConfig,
) -> dict[str, float | int | None]:
    """The :data:`TRACK_KEYS` of one filter run: ``X[k]`` the extracted states at scan k (positions first),
    ``labels[k]`` their labels (None: an unlabelled tracker), ``episodes`` the run's §5.4 delay episodes."""
    return track_evaluation(scans, X, labels, episodes, cfg, sensor_cfg)[0]


def track_evaluation(
    scans: Scans,
    X: Sequence[np.ndarray],
    labels: Sequence[np.ndarray] | None,
    episodes: Sequence[Episode],
    cfg: MetricsConfig,
    sensor_cfg: SensorConfig,
    partner: np.ndarray | None = None,
) -> tuple[dict[str, float | int | None], list[dict[str, float | int | str | None]]]:
    """:func:`evaluate_tracks` and, per episode of ``episodes`` in order, its :data:`GAP_KEYS` cells. ``partner``:
    the run's gated matching (:attr:`soabench.metrics.TrialMetrics.partner`, the §5.4 matching these measures read),
    so that it is not done again; None: matched here."""
    gt = gt_mask(scans, cfg.gt_set)
    est = _estimate_rows(scans, X, labels, cfg.gt_set, sensor_cfg)
    est_xy = np.split(est.xy, est.off[1:-1])
    est_labels = None if labels is None else np.split(est.ids, est.off[1:-1])
    gaps = occlusion_gaps(np.asarray(scans.present) & np.asarray(scans.in_fov), scans.visible)
    # the scans reemergence() reads: each gap, the scan before it, and the re-acquisition of the episode after it
    needed = {k for g in gaps for k in range(g.k_a - 1, g.k_b + 1)}
    after_gap = {(g.target, g.k_b + 1) for g in gaps}
    needed |= {e.k_t for e in episodes if not e.censored and (e.target, e.k0) in after_gap}
    if partner is None:
        assoc, assoc_labels = associated_labels(est_xy, est_labels, scans.truth_xy, gt, cfg.d_gate, sorted(needed))
    else:
        assoc, assoc_labels = _partner_labels(partner, est, sorted(needed), labels is not None)
    out: dict[str, float | int | None] = dict.fromkeys(LABEL_KEYS + ALPHA_KEYS)
    if est_labels is not None:
        k, p = np.nonzero(gt)  # GT_k of every scan stacked, in column order (finite positions: gt_mask)
        truth = ScanRows(scans.ped_labels[p], scans.truth_xy[k, p], _offsets(gt.sum(axis=1)))  # truth track ids
        seq = TrackSequence.of_rows(truth, est)
        scores = scores_of(seq, cfg.d_gate)
        s, o = scores.scalars(), ospa2_of(seq)
        out.update({key: s[key] for key in LABEL_KEYS if key in s})
        out.update(zip(ALPHA_KEYS, scores.hota_alpha.tolist(), strict=True))
        out.update(ospa2=o.ospa2, ospa2_loc=o.loc, ospa2_card=o.card)
    out.update(reemergence(episodes, gaps, assoc, assoc_labels, cfg.ddof, cfg.censored).summary())
    return {key: out[key] for key in TRACK_KEYS}, episode_gaps(scans, episodes, gaps, assoc, assoc_labels, cfg.d_gate)


def _partner_labels(
    partner: np.ndarray, est: ScanRows, scans: list[int], labelled: bool
) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`~soabench.tracks.reemergence.associated_labels` of ``scans`` from the gated matching's ``partner``
    (K, P) (the index in Est_k of each target's partner, -1 for none) and the estimates' rows ``est``."""
    assoc = np.zeros(partner.shape, dtype=bool)
    assoc[scans] = partner[scans] >= 0
    if not labelled:
        return assoc, None
    out = np.full(partner.shape, NO_LABEL, dtype=np.int64)
    k, p = np.nonzero(assoc)
    out[k, p] = est.ids[est.off[k] + partner[k, p]]
    return assoc, out


def episode_gaps(
    scans: Scans,
    episodes: Sequence[Episode],
    gaps: Sequence,
    assoc: np.ndarray,
    labels: np.ndarray | None,
    d_gate: float,
) -> list[dict[str, float | int | str | None]]:
    """The :data:`GAP_KEYS` cells of each episode (:data:`NO_GAP` for an entry episode)."""
    outcomes = gap_outcomes(episodes, gaps, assoc, labels)
    described = {
        o.gap: d
        for o, d in zip(
            outcomes.values(), describe_gaps(scans, [o.gap for o in outcomes.values()], d_gate), strict=True
        )
    }
    rows = []
    for e in episodes:
        o = outcomes.get((e.target, e.k0))
        if o is None:
            rows.append(dict(NO_GAP))
            continue
        d = described[o.gap]
        rows.append({
            "gap_scans": float(d.scans), "gap_s": d.seconds, "gap_occluder": d.occluder, "gap_moved": float(d.moved),
            "gap_displacement": d.displacement, "gap_ego_moved": float(d.ego_moved),
            "gap_ego_displacement": d.ego_displacement, "gap_coasted": float(o.coasted),
            "gap_id_kept": math.nan if o.id_kept is None else float(o.id_kept),
        })  # fmt: skip
    return rows
