"""Every track measure of one filter run (docs/method.md §9.3, §9.4): the columns a trial adds beside §5's.

:func:`evaluate_tracks` reads the truth of :class:`~soabench.sensor.Scans` (positions, presence, FOV, line of sight),
the tracker's extracted positions and, if it labels them, their labels, and the §5.4 delay episodes that
:func:`soabench.metrics.evaluate` already built. Truth ids are the pedestrian columns of the scans; truth and
estimates are the sets of docs/method.md §5.1. The position-only measures (entry and re-emergence delay, coasted)
are computed for every tracker; the label measures (HOTA ... OSPA(2), HOTA per alpha, identity kept) are None for an
unlabelled one.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from soabench.metrics import Episode, estimate_mask, gt_mask
from soabench.tracks.ospa2 import ospa2_of
from soabench.tracks.reemergence import associated_labels, occlusion_gaps, reemergence
from soabench.tracks.scores import ALPHAS, scores_of
from soabench.tracks.sequence import TrackSequence

if TYPE_CHECKING:
    from soabench.config import MetricsConfig, SensorConfig
    from soabench.sensor import Scans

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
    gt = gt_mask(scans, cfg.gt_set)
    keep = [estimate_mask(x, scan.ego, sensor_cfg, cfg.gt_set) for x, scan in zip(X, scans.scans, strict=True)]
    est_xy = [np.asarray(x, dtype=float).reshape(len(m), -1)[m, :2] for x, m in zip(X, keep, strict=True)]
    est_labels = None if labels is None else [np.asarray(lab)[m] for lab, m in zip(labels, keep, strict=True)]
    gaps = occlusion_gaps(np.asarray(scans.present) & np.asarray(scans.in_fov), scans.visible)
    needed = {k for g in gaps for k in range(g.k_a - 1, g.k_b + 1)}
    needed |= {e.k_t for e in episodes if not e.censored}
    assoc, assoc_labels = associated_labels(est_xy, est_labels, scans.truth_xy, gt, cfg.d_gate, sorted(needed))
    out: dict[str, float | int | None] = dict.fromkeys(LABEL_KEYS + ALPHA_KEYS)
    if est_labels is not None:
        gt_ids = [np.flatnonzero(row) for row in gt]
        seq = TrackSequence.of(gt_ids, [scans.truth_xy[k, i] for k, i in enumerate(gt_ids)], est_labels, est_xy)
        scores = scores_of(seq, cfg.d_gate)
        s, o = scores.scalars(), ospa2_of(seq)
        out.update({key: s[key] for key in LABEL_KEYS if key in s})
        out.update(zip(ALPHA_KEYS, scores.hota_alpha.tolist(), strict=True))
        out.update(ospa2=o.ospa2, ospa2_loc=o.loc, ospa2_card=o.card)
    out.update(reemergence(episodes, gaps, assoc, assoc_labels, cfg.ddof, cfg.censored).summary())
    return {key: out[key] for key in TRACK_KEYS}
