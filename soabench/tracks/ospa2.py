"""OSPA(2), the OSPA distance between sets of tracks over a sliding window (Beard, Vo & Vo 2020;
docs/method.md §9.3; register row 31).

Over the window of ``window`` scans ending at k, each track (a truth id or an estimate label) has the scans of the
window in which it exists. The base distance of a truth track x and an estimate track y is the mean over the scans
where either exists of ``min(c, |x(t) - y(t)|)`` when both exist and ``c`` when only one does. OSPA(2) at k is the
OSPA of order p with cut-off c (docs/method.md §5.2, :func:`soabench.metrics.ospa`) of the two sets of tracks under
that base distance; the per-sequence value is its mean over every scan (windows without any track contribute 0).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from soabench.errors import require
from soabench.notice import announced
from soabench.tracks.sequence import TrackSequence

#: register row 31: cut-off c (m), order p, window (scans)
OSPA2_C, OSPA2_P, OSPA2_WINDOW = 10.0, 1.0, 10


@dataclass(frozen=True)
class Ospa2:
    """OSPA(2) of one sequence: means over scans of the total and its localisation / cardinality parts (each part
    as in :func:`soabench.metrics.ospa`), and ``series`` (K, 3) of the three per scan."""

    ospa2: float
    loc: float
    card: float
    series: np.ndarray


def ospa2(
    gt_ids: Sequence,
    gt_xy: Sequence,
    est_ids: Sequence,
    est_xy: Sequence,
    c: float = OSPA2_C,
    p: float = OSPA2_P,
    window: int = OSPA2_WINDOW,
) -> Ospa2:
    """OSPA(2) of K scans of truth ids / positions and estimate labels / positions (defaults: register row 31)."""
    return ospa2_of(TrackSequence.of(gt_ids, gt_xy, est_ids, est_xy), c, p, window)


def ospa2_of(seq: TrackSequence, c: float = OSPA2_C, p: float = OSPA2_P, window: int = OSPA2_WINDOW) -> Ospa2:
    """:func:`ospa2` of a checked :class:`TrackSequence` (one compiled loop over the windows,
    :func:`soabench.tracks.kernels.ospa2_scans`)."""
    from soabench.tracks.kernels import ospa2_scans  # numba is imported on first use, not with the package

    require(c > 0 and p >= 1 and window >= 1, f"OSPA(2) needs c > 0, p >= 1, window >= 1 (got {c}, {p}, {window})")
    K = len(seq)
    g, e = seq.gt, seq.est
    args = (g.ids, g.off, g.xy, len(seq.gt_labels), e.ids, e.off, e.xy, len(seq.est_labels), float(c), float(p))
    series = announced("track metrics", ospa2_scans, *args, int(window))
    mean = series.mean(axis=0) if K else np.full(3, np.nan)
    return Ospa2(float(mean[0]), float(mean[1]), float(mean[2]), series)
