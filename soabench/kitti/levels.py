"""KITTI's own occlusion and truncation levels in the track metrics (docs/user-guide/kitti.md "Occlusion levels";
docs/method.md §9.4).

Each label row of ``label_02`` gives its object's ``occluded`` level (0 fully visible, 1 partly occluded, 2 largely
occluded, 3 unknown) and ``truncated`` level (0 not, 1 partly, 2 fully truncated by the image border) in that frame.
A target counts at the level of each frame: a pedestrian labelled 0 in frame 10 and 2 in frame 11 adds one
truth-frame to level 0 and one to level 2. Per level and filter run:

* ``frames``: the truth-frames of the ground-truth set (§5.1) at that level;
* ``associated``: those with an estimate associated under the delay gate (§5.4's matching): recall at that level;
* ``idsw`` (labelled trackers): identity switches at that level: frames whose associated label differs from the
  last label associated with the same target (CLEAR MOT's rule with §5.4's matching).

**Identity through undetected gaps.** A KITTI target whose label says occluded may still be detected, and one
labelled visible may be missed, so the gaps here are runs of frames in which the target is present and in the FOV
but **not detected**, with a detection on the frame before and the frame after (§9.4's gaps with "detected" in
place of "visible"). Per gap: its length, whether an estimate was associated with the target on every frame of it
(coasted), and, for a labelled tracker associated on both sides, whether the label after the gap is the one before
it (identity kept).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from soabench.metrics import gt_mask
from soabench.tracks.evaluate import estimate_sets
from soabench.tracks.reemergence import NO_LABEL, associated_labels, occlusion_gaps

if TYPE_CHECKING:
    from soabench.config import MetricsConfig
    from soabench.kitti.reader import SequenceScans

#: the levels of each kind, in table order
LEVELS = {"occluded": (0, 1, 2, 3), "truncated": (0, 1, 2)}
LEVEL_NAMES = {
    "occluded": {0: "fully visible", 1: "partly occluded", 2: "largely occluded", 3: "unknown"},
    "truncated": {0: "not truncated", 1: "partly truncated", 2: "fully truncated"},
}


def id_switches(assoc: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(K, P) True where the target's associated label differs from the last label associated with it."""
    last = np.full(assoc.shape[1], NO_LABEL, dtype=np.int64)
    out = np.zeros(assoc.shape, dtype=bool)
    for k in range(len(assoc)):
        m = assoc[k]
        out[k] = m & (last != NO_LABEL) & (labels[k] != last)
        last[m] = labels[k][m]
    return out


def level_split(
    ss: SequenceScans, X: Sequence[np.ndarray], labels: Sequence[np.ndarray] | None, cfg: MetricsConfig
) -> dict:
    """The per-level counts of one filter run (module docstring) and its undetected gaps: ``{"occluded": [...],
    "truncated": [...], "gaps": [...]}``; ``X``/``labels`` as :func:`soabench.tracks.evaluate.evaluate_tracks`."""
    scans = ss.scans
    gt = gt_mask(scans, cfg.gt_set)
    est_xy, est_labels = estimate_sets(scans, X, labels, cfg.gt_set, ss.sensor)
    assoc, lab = associated_labels(est_xy, est_labels, scans.truth_xy, gt, cfg.d_gate)
    switch = id_switches(assoc, lab) if lab is not None else None
    out: dict = {}
    levels = ss.levels or {}
    for kind, values in LEVELS.items():
        lv = levels.get(kind, np.full(gt.shape, -1))
        out[kind] = [
            {
                "level": v,
                "frames": int((gt & (lv == v)).sum()),
                "associated": int((assoc & gt & (lv == v)).sum()),
                "idsw": None if switch is None else int((switch & gt & (lv == v)).sum()),
            }
            for v in values
        ]
    in_view = np.asarray(scans.present, dtype=bool) & np.asarray(scans.in_fov, dtype=bool)
    out["gaps"] = []
    for g in occlusion_gaps(in_view, scans.detected):
        before, after = g.k_a - 1, g.k_b + 1
        kept = None
        if lab is not None and assoc[before, g.target] and assoc[after, g.target]:
            kept = int(lab[after, g.target] == lab[before, g.target])
        coasted = int(assoc[g.k_a : g.k_b + 1, g.target].all())
        out["gaps"].append({"scans": g.k_b - g.k_a + 1, "coasted": coasted, "id_kept": kept})
    return out
