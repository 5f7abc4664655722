"""Re-emergence after occlusion (docs/method.md §9.4).

An *occlusion gap* of a target is a maximal run of scans k_a..k_b in which it is present and inside the FOV but
not line-of-sight visible, with the target visible at k_a - 1 and at k_b + 1. The tracking-delay episode
(docs/method.md §5.4, :func:`soabench.metrics.delay_episodes`) that starts at k_b + 1 is a *re-emergence* episode;
every other episode is an *entry* episode (the target entered the FOV, left a building, or was visible at k = 0).

Per filter run:

* the §5.4 delay of entry and of re-emergence episodes, each with its σ and censored count
  (:func:`soabench.metrics.delay_summary`);
* *coasted*: the fraction of gaps in which some estimate is associated (§5.4 matching) with the target on every
  scan of the gap;
* *identity kept* (labelled trackers only): over re-emergence episodes whose target was associated at k_a - 1 and
  re-acquired at k_t, the fraction in which the label at k_t equals the label at k_a - 1, with that count. An
  unlabelled tracker has None here, never a number.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from soabench.errors import require
from soabench.metrics import Episode, delay_summary, gated_assignment

#: label of "no estimate associated" in the (K, P) label array of :func:`associated_labels`
NO_LABEL = -1


@dataclass(frozen=True)
class Gap:
    """One occlusion gap: target (column of the (K, P) flags), first and last occluded scan (inclusive)."""

    target: int
    k_a: int
    k_b: int


def occlusion_gaps(in_view: np.ndarray, visible: np.ndarray) -> list[Gap]:
    """Occlusion gaps from (K, P) flags: ``in_view`` = present and inside the FOV, ``visible`` = present, inside
    the FOV and line-of-sight visible (``Scans.present & Scans.in_fov`` and ``Scans.visible``)."""
    in_view, visible = np.asarray(in_view, dtype=bool), np.asarray(visible, dtype=bool)
    require(in_view.shape == visible.shape, "in_view and visible must have the same (K, P) shape")
    if visible.ndim != 2 or not visible.size:
        return []
    K = len(visible)
    # every target's hidden runs at once (the runs of visibility_runs): a run starts where the padded flags step up
    # and ends before they step down; both lists come out target by target in scan order, so they pair up
    hidden = np.zeros((visible.shape[1], K + 2), dtype=np.int8)
    hidden[:, 1:-1] = (in_view & ~visible).T
    step = np.diff(hidden, axis=1)
    target, k_a = np.nonzero(step == 1)
    k_b = np.nonzero(step == -1)[1] - 1
    inner = (k_a >= 1) & (k_b + 1 < K)
    target, k_a, k_b = target[inner], k_a[inner], k_b[inner]
    seen = visible[k_a - 1, target] & visible[k_b + 1, target]
    return [Gap(i, a, b) for i, a, b in zip(target[seen].tolist(), k_a[seen].tolist(), k_b[seen].tolist(), strict=True)]


def associated_labels(
    est_xy: Sequence[np.ndarray],
    est_labels: Sequence[np.ndarray] | None,
    gt_xy: np.ndarray,
    gt: np.ndarray,
    d_gate: float,
    scans: Iterable[int] | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """The §5.4 matching of every scan: ``assoc`` (K, P) (the target has a gated partner) and, for a labelled
    tracker, the partner's label (K, P) (:data:`NO_LABEL` where ``assoc`` is False, a filler only: read a label
    where ``assoc`` is True); None for an unlabelled one.

    ``est_xy[k]`` are Est_k (restricted like the truth, docs/method.md §5.1), ``gt_xy`` (K, P, 2) the truth
    positions and ``gt`` (K, P) the truth set GT_k. ``scans``: match only these scans (every scan when None) and
    leave the others unassociated, e.g. the scans :func:`reemergence` reads (gaps, the scan before each, each k_t).
    """
    gt = np.asarray(gt, dtype=bool)
    assoc = np.zeros(gt.shape, dtype=bool)
    labels = None if est_labels is None else np.full(gt.shape, NO_LABEL, dtype=np.int64)
    for k in range(len(gt)) if scans is None else scans:
        idx = np.flatnonzero(gt[k])
        pairs = gated_assignment(est_xy[k], gt_xy[k, idx], d_gate)
        assoc[k, idx[pairs[:, 1]]] = True
        if labels is not None:
            labels[k, idx[pairs[:, 1]]] = np.asarray(est_labels[k], dtype=np.int64)[pairs[:, 0]]
    return assoc, labels


@dataclass(frozen=True)
class Reemergence:
    """The re-emergence measures of one filter run (module docstring).

    Attributes:
        entry, reemergence: :func:`soabench.metrics.delay_summary` of the entry and the re-emergence episodes.
        n_gaps: occlusion gaps; n_coasted: those covered by an associated estimate on every scan.
        coasted: n_coasted / n_gaps (NaN without a gap).
        n_id: re-emergence episodes associated before the gap and re-acquired (None: unlabelled tracker).
        id_kept: the fraction of them that kept their label (None: unlabelled; NaN: n_id = 0).
    """

    entry: dict[str, float | int]
    reemergence: dict[str, float | int]
    n_gaps: int
    n_coasted: int
    coasted: float
    n_id: int | None
    id_kept: float | None

    def summary(self) -> dict[str, float | int | None]:
        """Flat per-trial columns: delay_entry_mean, ..., n_reemergence_censored, coasted, n_gaps, id_kept, n_id."""
        out: dict[str, float | int | None] = {}
        for kind, s in (("entry", self.entry), ("reemergence", self.reemergence)):
            out[f"delay_{kind}_mean"] = s["delay_mean"]
            out[f"delay_{kind}_std"] = s["delay_std"]
            out[f"n_{kind}"] = s["n_episodes"]
            out[f"n_{kind}_censored"] = s["n_censored"]
        out.update(coasted=self.coasted, n_gaps=self.n_gaps, id_kept=self.id_kept, n_id=self.n_id)
        return out


def reemergence(
    episodes: Sequence[Episode],
    gaps: Sequence[Gap],
    assoc: np.ndarray,
    labels: np.ndarray | None,
    ddof: int = 0,
    censored: str = "exclude",
) -> Reemergence:
    """Split ``episodes`` (:func:`soabench.metrics.delay_episodes`) into entry and re-emergence episodes by
    ``gaps`` (:func:`occlusion_gaps`) and score them; ``assoc`` and ``labels`` as :func:`associated_labels` returns
    them (``labels`` None for an unlabelled tracker); ``ddof`` and ``censored`` as :func:`delay_summary`."""
    assoc = np.asarray(assoc, dtype=bool)
    gap_before = {(g.target, g.k_b + 1): g for g in gaps}
    reem = [e for e in episodes if (e.target, e.k0) in gap_before]
    entry = [e for e in episodes if (e.target, e.k0) not in gap_before]
    n_coasted = sum(bool(assoc[g.k_a : g.k_b + 1, g.target].all()) for g in gaps)
    n_id: int | None = None
    id_kept: float | None = None
    if labels is not None:
        kept = [k for k in (_kept(e, gap_before[(e.target, e.k0)], assoc, labels) for e in reem) if k is not None]
        n_id = len(kept)
        id_kept = float(np.mean(kept)) if kept else math.nan
    return Reemergence(
        entry=delay_summary(entry, ddof, censored),
        reemergence=delay_summary(reem, ddof, censored),
        n_gaps=len(gaps),
        n_coasted=n_coasted,
        coasted=n_coasted / len(gaps) if gaps else math.nan,
        n_id=n_id,
        id_kept=id_kept,
    )


def _kept(e: Episode, gap: Gap, assoc: np.ndarray, labels: np.ndarray) -> bool | None:
    """Whether re-emergence episode ``e`` after ``gap`` kept its label; None when it does not count (the target was
    not associated before the gap, or the episode is censored)."""
    k_before = gap.k_a - 1
    if not assoc[k_before, e.target] or e.censored:
        return None
    return bool(labels[e.k_t, e.target] == labels[k_before, e.target])


@dataclass(frozen=True)
class GapOutcome:
    """What became of one re-emergence episode's gap: ``gap``, whether it was coasted, and whether the identity was
    kept (None: unlabelled tracker, or the episode does not count for identity kept)."""

    gap: Gap
    coasted: bool
    id_kept: bool | None


def gap_outcomes(
    episodes: Sequence[Episode], gaps: Sequence[Gap], assoc: np.ndarray, labels: np.ndarray | None
) -> dict[tuple[int, int], GapOutcome]:
    """Per re-emergence episode (keyed by its (target, k0)) the :class:`GapOutcome` that :func:`reemergence` counts
    into ``coasted`` and ``id_kept``."""
    assoc = np.asarray(assoc, dtype=bool)
    gap_before = {(g.target, g.k_b + 1): g for g in gaps}
    out = {}
    for e in episodes:
        g = gap_before.get((e.target, e.k0))
        if g is not None:
            kept = None if labels is None else _kept(e, g, assoc, labels)
            out[(e.target, e.k0)] = GapOutcome(g, bool(assoc[g.k_a : g.k_b + 1, g.target].all()), kept)
    return out
