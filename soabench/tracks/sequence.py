"""A labelled tracking sequence on plain arrays: per-scan truth ids and positions, estimate labels and positions
(docs/method.md §9.3).

:class:`TrackSequence` checks the input once (equal scan counts, one id per row, no id twice in a scan, finite
positions) and maps the ids to contiguous indices 0..n-1 in sorted order, the form TrackEval's metrics take. The
similarity of a truth and an estimate at one scan is ``S = max(0, 1 - d / (2 d_gate))`` (2-D distance d in metres,
register row 30), so S >= 0.5 exactly when d <= d_gate, the delay gate of docs/method.md §5.4.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from soabench.errors import SoabenchError
from soabench.metrics import pairwise_distances

#: at most this many (scan, truth, estimate) cells of padded similarity are held at once
BLOCK_CELLS = 1_000_000


def similarity(gt_xy: np.ndarray, est_xy: np.ndarray, d_gate: float) -> np.ndarray:
    """(n_gt, n_est) similarity ``max(0, 1 - d / (2 d_gate))`` of every truth-estimate pair (register row 30)."""
    return np.maximum(0.0, 1.0 - pairwise_distances(gt_xy, est_xy) / (2.0 * d_gate))


@dataclass(frozen=True)
class ScanRows:
    """The rows of every scan stacked: ids (N,) int64, positions (N, 2), scan k's rows ``off[k]:off[k+1]``."""

    ids: np.ndarray
    xy: np.ndarray
    off: np.ndarray


def _flat(ids: Sequence, xy: Sequence, what: str) -> ScanRows:
    """Stack per-scan ids and positions (extra columns such as velocities dropped) and :func:`checked` them."""
    if len(ids) != len(xy):
        raise SoabenchError(f"{what}: {len(ids)} scans of ids but {len(xy)} scans of positions")
    id_list = [np.asarray(i).reshape(-1) for i in ids]
    xy_list = [np.asarray(p, dtype=float) for p in xy]
    xy_list = [p.reshape(len(p), -1)[:, :2] if p.size else np.zeros((0, 2)) for p in xy_list]
    n = np.fromiter((len(i) for i in id_list), dtype=np.int64, count=len(id_list))
    m = np.fromiter((len(p) for p in xy_list), dtype=np.int64, count=len(xy_list))
    if (n != m).any():
        k = int(np.flatnonzero(n != m)[0])
        raise SoabenchError(f"{what} at scan {k}: {n[k]} ids for {m[k]} positions; give one id per row")
    off = np.zeros(len(n) + 1, dtype=np.int64)
    np.cumsum(n, out=off[1:])
    flat_ids = np.concatenate(id_list) if len(id_list) else np.zeros(0, dtype=np.int64)
    flat_xy = np.concatenate(xy_list) if len(xy_list) else np.zeros((0, 2))
    return checked(flat_ids, flat_xy, off, what)


def checked(ids: np.ndarray, xy: np.ndarray, off: np.ndarray, what: str) -> ScanRows:
    """Stacked rows (scan k's are ``off[k]:off[k + 1]``) after the checks: integer ids, no id twice in a scan,
    finite positions; one clear SoabenchError naming ``what`` and the scan otherwise."""
    if ids.size and not np.issubdtype(ids.dtype, np.integer):
        raise SoabenchError(f"{what}: ids of dtype {ids.dtype}; ids must be integers (int64)")
    ids = ids.astype(np.int64)
    scan = np.repeat(np.arange(len(off) - 1), np.diff(off))
    order = np.lexsort((ids, scan))
    twice = (np.diff(ids[order]) == 0) & (np.diff(scan[order]) == 0)
    if twice.any():
        k = int(scan[order][np.flatnonzero(twice)[0]])
        raise SoabenchError(f"{what} at scan {k}: an id appears twice; ids must be unique within a scan")
    if not np.isfinite(xy).all():
        k = int(scan[np.flatnonzero(~np.isfinite(xy).all(axis=1))[0]])
        raise SoabenchError(f"{what} at scan {k}: a NaN or infinite position; give finite (x, y) in metres")
    return ScanRows(ids, xy, off)


@dataclass(frozen=True)
class TrackSequence:
    """One labelled sequence, checked and indexed (docs/method.md §9.3).

    Attributes:
        gt, est: every scan's rows stacked; their ``ids`` are contiguous indices 0..n-1.
        gt_labels, est_labels: the original id of each contiguous index (sorted).
    """

    gt: ScanRows
    est: ScanRows
    gt_labels: np.ndarray
    est_labels: np.ndarray

    @classmethod
    def of(cls, gt_ids: Sequence, gt_xy: Sequence, est_ids: Sequence, est_xy: Sequence) -> TrackSequence:
        """From per-scan truth ids and positions and estimate labels and positions (K scans each)."""
        if len(gt_ids) != len(est_ids):
            raise SoabenchError(f"{len(gt_ids)} scans of truth but {len(est_ids)} scans of estimates")
        return cls.of_rows(_flat(gt_ids, gt_xy, "truth"), _flat(est_ids, est_xy, "estimates"))

    @classmethod
    def of_rows(cls, g: ScanRows, e: ScanRows) -> TrackSequence:
        """From stacked truth and estimate rows of equal scan counts, already :func:`checked`."""
        if len(g.off) != len(e.off):
            raise SoabenchError(f"{len(g.off) - 1} scans of truth but {len(e.off) - 1} scans of estimates")
        g_lab, g_idx = np.unique(g.ids, return_inverse=True)
        e_lab, e_idx = np.unique(e.ids, return_inverse=True)
        return cls(
            ScanRows(g_idx.astype(np.int64), g.xy, g.off), ScanRows(e_idx.astype(np.int64), e.xy, e.off), g_lab, e_lab
        )

    def __len__(self) -> int:
        return len(self.gt.off) - 1

    @property
    def n_gt_dets(self) -> int:
        return len(self.gt.ids)

    @property
    def n_est_dets(self) -> int:
        return len(self.est.ids)

    @property
    def gt_ids(self) -> list[np.ndarray]:
        """Per scan, the contiguous truth indices."""
        return np.split(self.gt.ids, self.gt.off[1:-1])

    @property
    def est_ids(self) -> list[np.ndarray]:
        """Per scan, the contiguous estimate indices."""
        return np.split(self.est.ids, self.est.off[1:-1])

    def blocks(self, d_gate: float) -> Iterator[tuple[range, np.ndarray, np.ndarray, np.ndarray]]:
        """Runs of scans with their padded arrays, at most :data:`BLOCK_CELLS` similarity cells at a time.

        Yields:
            ``(scans, S, g, e)``: ``S`` (B, G, E) similarities (0 in padding; scan t's matrix is
            ``S[t - scans.start, :n_gt(t), :n_est(t)]``, equal to :func:`similarity` of that scan), ``g`` (B, G) and
            ``e`` (B, E) contiguous ids, -1 in padding.
        """
        n_g, n_e = np.diff(self.gt.off), np.diff(self.est.off)
        G, E = int(n_g.max(initial=0)), int(n_e.max(initial=0))
        step = max(1, BLOCK_CELLS // max(1, G * E))
        for start in range(0, len(self), step):
            scans = range(start, min(len(self), start + step))
            g, gx = _padded(self.gt, scans, G)
            e, ex = _padded(self.est, scans, E)
            dx = gx[:, :, None, 0] - ex[:, None, :, 0]
            dy = gx[:, :, None, 1] - ex[:, None, :, 1]
            S = np.maximum(0.0, 1.0 - np.sqrt(dx * dx + dy * dy) / (2.0 * d_gate))
            S[(g[:, :, None] < 0) | (e[:, None, :] < 0)] = 0.0
            yield scans, S, g, e

    def similarities(self, d_gate: float) -> list[np.ndarray]:
        """Per scan, the (n_gt, n_est) similarity matrix of :func:`similarity`."""
        return [
            similarity(
                self.gt.xy[self.gt.off[k] : self.gt.off[k + 1]],
                self.est.xy[self.est.off[k] : self.est.off[k + 1]],
                d_gate,
            )
            for k in range(len(self))
        ]

    def trackeval_data(self, d_gate: float) -> dict:
        """The ``data`` dict that TrackEval's ``eval_sequence`` methods take (ids contiguous, similarities S)."""
        return {
            "num_timesteps": len(self),
            "num_gt_ids": len(self.gt_labels),
            "num_tracker_ids": len(self.est_labels),
            "num_gt_dets": self.n_gt_dets,
            "num_tracker_dets": self.n_est_dets,
            "gt_ids": self.gt_ids,
            "tracker_ids": self.est_ids,
            "similarity_scores": self.similarities(d_gate),
        }


def _padded(rows: ScanRows, scans: range, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(B, width) ids (-1 in padding) and (B, width, 2) positions (0 in padding) of ``scans``."""
    n = np.diff(rows.off[scans.start : scans.stop + 1])
    ids = np.full((len(scans), width), -1, dtype=np.int64)
    xy = np.zeros((len(scans), width, 2))
    lo, hi = rows.off[scans.start], rows.off[scans.stop]
    b = np.repeat(np.arange(len(scans)), n)
    j = np.arange(hi - lo) - np.repeat(rows.off[scans.start : scans.stop] - lo, n)
    ids[b, j] = rows.ids[lo:hi]
    xy[b, j] = rows.xy[lo:hi]
    return ids, xy
