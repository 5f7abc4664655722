"""A tracker's labelled estimates written as KITTI tracking results (the devkit's result format: the label columns
and a score), so that KITTI's own evaluation code (TrackEval's KITTI 2-D box reader) scores them against the
``label_02`` files of the same export (docs/method.md §9.3).

Each estimate becomes a pedestrian box (the export's pedestrian size) standing at the estimated position, turned
along the estimated velocity (rotation_y 0 at rest), written only when the camera sees it, exactly as the export
writes a pedestrian of the truth (:func:`soabench.kitti.export.pedestrian_row`); its track id is the estimate's
label and its score the estimate's weight (1 without weights).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from soabench.atomic import write_text_atomic
from soabench.errors import require
from soabench.kitti.export import pedestrian_row

#: folder of a tracker's result files inside a TrackEval trackers folder (``<trackers>/<name>/data/XXXX.txt``)
RESULTS_DATA_DIR = "data"


def tracking_rows(
    frame: int, X: np.ndarray, labels: np.ndarray, ego: np.ndarray, calib, r_max: float, w: np.ndarray | None = None
) -> list[str]:
    """KITTI result rows of frame ``frame``: ``X`` (n, 4) estimated states [x, y, vx, vy] (world, m and m/s) or
    (n, 2) positions, ``labels`` (n,) their int track ids, ``w`` (n,) their scores."""
    if len(labels) == 0:  # a frame without estimates
        return []
    X = np.asarray(X, dtype=float).reshape(len(labels), -1)
    require(X.shape[1] in (2, 4), f"estimates of shape {X.shape}: give (n, 2) positions or (n, 4) states")
    rows = []
    for i, label in enumerate(np.asarray(labels, dtype=np.int64)):
        heading = math.atan2(X[i, 3], X[i, 2]) if X.shape[1] == 4 and (X[i, 2] or X[i, 3]) else math.nan
        score = 1.0 if w is None else float(w[i])
        row = pedestrian_row(frame, int(label), X[i, :2], heading, ego, calib, r_max, 0, score)
        if row is not None:
            rows.append(row)
    return rows


def write_tracking_results(
    folder: Path,
    sequence: int,
    X: Sequence[np.ndarray],
    labels: Sequence[np.ndarray],
    egos: np.ndarray,
    calib,
    r_max: float,
    w: Sequence[np.ndarray] | None = None,
) -> int:
    """Write ``folder/data/%04d.txt`` for one sequence (frame k from ``X[k]``, ``labels[k]``, ``egos[k]``); returns
    the number of rows written."""
    rows = []
    for k, (x, lab) in enumerate(zip(X, labels, strict=True)):
        rows += tracking_rows(k, x, lab, egos[k], calib, r_max, None if w is None else w[k])
    write_text_atomic(Path(folder) / RESULTS_DATA_DIR / f"{sequence:04d}.txt", "\n".join(rows) + "\n" if rows else "")
    return len(rows)
