"""Evaluation of one filter run against the truth (docs/method.md §5; register rows 5, 6, 20, 22, 23).

Building blocks (pure functions of point sets, all distances 2-D Euclidean in metres):

* :func:`ospa` (§5.2) and :func:`gospa` (§5.6, alpha = 2) with their decompositions;
* :func:`gated_assignment` (§5.4 step 1), shared by the delay metric and precision/recall (§5.5);
* :func:`delay_episodes` and :func:`delay_summary` (§5.4): visibility episodes, first detection k_d, first gated
  association k_t, censoring, the lower-bound variant;
* :func:`evaluate`: every metric of one filter run (one birth model x probability mode x clutter rate of a trial).

Metrics never touch SUMO or the filter: they read :class:`~soabench.types.Scans` (truth flags) and the filter's
:class:`~soabench.types.StepResult` list.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import astuple, dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import linear_sum_assignment

from soabench.errors import SoabenchError, require
from soabench.geometry import fov_mask
from soabench.notice import announced
from soabench.origins import ORIGIN_KEYS, origin_counts_of

if TYPE_CHECKING:
    from soabench.config import MetricsConfig, SensorConfig
    from soabench.types import Scans, StepResult

#: cost of a pair beyond the gate in the gated Hungarian assignment (§5.4 step 1)
GATE_COST = 1e6

#: keys of :attr:`TrialMetrics.summary` (per-trial scalars of one filter run)
SUMMARY_KEYS = (
    "delay_mean",
    "delay_std",
    "delay_mean_lb",
    "delay_std_lb",
    "n_episodes",
    "n_censored",
    "card_err",
    "card_err_sumw",
    "ospa",
    "ospa_loc",
    "ospa_card",
    "gospa",
    "gospa_loc",
    "gospa_missed",
    "gospa_false",
    "precision",
    "recall",
    "tp",
    "fp",
    "fn",
    "mean_components",
    "max_components",
    "mean_predicted",
    "mean_updated",
    "cap_hits",
    "mean_pD",
    "t_predict",
    "t_update",
    "t_reduce",
)

#: the wall-clock keys of :attr:`TrialMetrics.summary` (seconds the filter stages took): they differ between two runs
#: of the same trial, so :meth:`TrialMetrics.values` and equality leave them out
TIMING_KEYS = ("t_predict", "t_update", "t_reduce")

#: keys of :attr:`TrialMetrics.series` (one value per scan k)
SERIES_KEYS = (
    "n_gt",
    "n_est",
    "tp",
    "fp",
    "fn",
    "ospa",
    "gospa",
    "card_err",
    "sum_w",
    "n_components",
    *ORIGIN_KEYS,  # n_components split by birth origin and age (soabench.origins, §5.7)
)


# ---------------------------------------------------------------------------------------------------------------------
# point-set distances


def _points(X: np.ndarray | Sequence, what: str = "a point set") -> np.ndarray:
    """(n, 2) float array of the (x, y) of ``X`` (rows may carry more columns, e.g. velocities); SoabenchError
    naming ``what`` if a position is NaN or infinite (the truth of an absent walker is NaN: select the truth set
    first, :func:`gt_mask`)."""
    A = np.asarray(X, dtype=float)
    if A.size == 0:
        return np.zeros((0, 2))
    P = A.reshape(len(A), -1)[:, :2]
    if not np.isfinite(P).all():
        bad = int(np.flatnonzero(~np.isfinite(P).all(axis=1))[0])
        raise SoabenchError(
            f"{what} holds a NaN or infinite position (row {bad}); keep only the targets of the truth set, e.g. "
            "scans.truth_xy[k][soabench.metrics.gt_mask(scans)[k]] (an absent walker's position is NaN)"
        )
    return P


def pairwise_distances(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """(m, n) Euclidean distances between the rows of ``X`` (m, 2) and ``Y`` (n, 2).

    sqrt(dx^2 + dy^2) per pair: the same floating-point operations as ``np.linalg.norm`` of the differences
    along the last axis (a sum of two squares has one rounding whatever its order), without its (m, n, 2) temporaries.
    """
    dx = X[:, 0, None] - Y[None, :, 0]
    dy = X[:, 1, None] - Y[None, :, 1]
    return np.sqrt(dx * dx + dy * dy)


def _distances(X: np.ndarray, Y: np.ndarray, D: np.ndarray | None) -> np.ndarray:
    """``D`` if given (the caller's distances between the rows of ``X`` and ``Y``), else computed."""
    return pairwise_distances(X, Y) if D is None else D


def ospa(
    X: np.ndarray, Y: np.ndarray, c: float = 100.0, p: float = 1.0, D: np.ndarray | None = None
) -> tuple[float, float, float]:
    """OSPA_p^(c)(X, Y) and its localisation and cardinality parts (§5.2, Schuhmacher, Vo & Vo 2008).

    The assignment is solved with ``linear_sum_assignment`` on the m x n matrix min(c, D)^p (m <= n). With
    ``loc = (sum assigned d^p / n)^(1/p)`` and ``card = (c^p (n - m) / n)^(1/p)``, ``total^p = loc^p + card^p``.
    OSPA(empty, empty) = 0; OSPA(empty, Y) = c. ``D``: the (len X, len Y) distances if the caller has them.

    Returns:
        ``(total, loc, card)``.
    """
    X, Y = _points(X, "ospa's X"), _points(Y, "ospa's Y")
    if len(X) > len(Y):
        X, Y = Y, X
        D = None if D is None else D.T
    m, n = len(X), len(Y)
    if n == 0:
        return 0.0, 0.0, 0.0
    card_p = c**p * (n - m) / n
    loc_p = 0.0
    if m > 0:
        C = np.minimum(_distances(X, Y, D), c) ** p
        rows, cols = linear_sum_assignment(C)
        loc_p = float(C[rows, cols].sum()) / n
    return (loc_p + card_p) ** (1.0 / p), loc_p ** (1.0 / p), card_p ** (1.0 / p)


def gospa(
    X: np.ndarray, Y: np.ndarray, c: float = 5.0, p: float = 1.0, D: np.ndarray | None = None
) -> tuple[float, float, float, float]:
    """GOSPA with alpha = 2 (§5.6, Rahmathullah, García-Fernández & Svensson 2017) and its decomposition.

    ``X`` is the ground truth, ``Y`` the estimates. The assignment is solved on min(D, c)^p; only assigned pairs
    with d < c count as assigned (a pair at d >= c costs c^p = c^p/2 + c^p/2 either way). The parts are in p-th
    power units and add up: ``total^p = loc + missed + false`` with

    * loc = sum of d^p over assigned pairs with d < c,
    * missed = (c^p / 2) x (truths not assigned below c),
    * false = (c^p / 2) x (estimates not assigned below c).

    GOSPA(empty, empty) = 0 and GOSPA(empty, n points) = (n c^p / 2)^(1/p); it is not normalised by max(m, n).
    ``D``: the (len X, len Y) distances if the caller has them.

    Returns:
        ``(total, loc, missed, false)``.
    """
    X, Y = _points(X, "gospa's X (the truth)"), _points(Y, "gospa's Y (the estimates)")
    n_assigned, loc = 0, 0.0
    if len(X) and len(Y):
        D = _distances(X, Y, D)
        rows, cols = linear_sum_assignment(np.minimum(D, c) ** p)
        d = D[rows, cols]
        kept = d < c
        n_assigned = int(kept.sum())
        loc = float((d[kept] ** p).sum())
    half = 0.5 * c**p
    missed = half * (len(X) - n_assigned)
    false = half * (len(Y) - n_assigned)
    return (loc + missed + false) ** (1.0 / p), loc, missed, false


def gated_assignment(est: np.ndarray, gt: np.ndarray, d_gate: float, D: np.ndarray | None = None) -> np.ndarray:
    """Gated Hungarian matching of estimates to ground truth (§5.4 step 1, §5.5).

    Cost = Euclidean distance, with entries > ``d_gate`` set to :data:`GATE_COST`; only assigned pairs with
    distance <= ``d_gate`` are kept. ``D``: the (len est, len gt) distances if the caller has them.

    Returns:
        (n_pairs, 2) int array of (estimate index, ground-truth index) rows, sorted by estimate index.
    """
    est, gt = _points(est, "gated_assignment's est"), _points(gt, "gated_assignment's gt")
    if len(est) == 0 or len(gt) == 0:
        return np.zeros((0, 2), dtype=int)
    D = _distances(est, gt, D)
    rows, cols = linear_sum_assignment(np.where(D > d_gate, GATE_COST, D))
    kept = D[rows, cols] <= d_gate
    return np.column_stack([rows[kept], cols[kept]]).astype(int)


# ---------------------------------------------------------------------------------------------------------------------
# tracking delay (§5.4)


@dataclass(frozen=True)
class Episode:
    """One visibility episode of a target that was detected in it (§5.4).

    Attributes:
        target: pedestrian index (column of the (K, P) flags).
        k0: first step of the episode; k_end: its last step (inclusive).
        k_d: first detection in the episode.
        k_t: first step >= k_d starting ``confirm_n`` consecutive associated steps inside the episode; -1 if censored.
        delay: (k_t - k_d) dt in seconds; NaN if censored.
        delay_lb: ``delay``, or the lower bound (k_end - k_d + 1) dt if censored.
        censored: no initiation inside the episode.
    """

    target: int
    k0: int
    k_end: int
    k_d: int
    k_t: int
    delay: float
    delay_lb: float
    censored: bool


def visibility_runs(vis: np.ndarray, g_min: int = 1) -> list[tuple[int, int]]:
    """Episodes of one target: maximal runs of ``vis`` (K,), joined when fewer than ``g_min`` steps apart (§5.4.2).

    Returns:
        ``[(k0, k_end), ...]`` with inclusive ends; a joined episode spans its inner invisible gap.
    """
    v = np.concatenate([[False], np.asarray(vis, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(v.astype(np.int8)))
    starts, ends = edges[0::2], edges[1::2] - 1
    runs: list[tuple[int, int]] = []
    for k0, k1 in zip(starts.tolist(), ends.tolist(), strict=True):
        if runs and k0 - runs[-1][1] - 1 < g_min:
            runs[-1] = (runs[-1][0], k1)
        else:
            runs.append((k0, k1))
    return runs


def first_confirmed(assoc: np.ndarray, start: int, end: int, confirm_n: int = 1) -> int:
    """First k in [start, end] with ``assoc`` true on k .. k + confirm_n - 1, all <= end (§5.4 steps 4, 6).

    Returns -1 when there is none (a censored episode).
    """
    if end - start + 1 < confirm_n:
        return -1
    a = np.asarray(assoc[start : end + 1], dtype=np.int64)
    window = np.convolve(a, np.ones(confirm_n, dtype=np.int64), mode="valid")
    hits = np.flatnonzero(window == confirm_n)
    return int(start + hits[0]) if len(hits) else -1


def delay_episodes(
    vis: np.ndarray,
    det: np.ndarray,
    assoc: np.ndarray,
    dt: float,
    g_min: int = 1,
    confirm_n: int = 1,
) -> list[Episode]:
    """Tracking-delay episodes k_delay = k_t - k_d (§5.4) from (K, P) boolean flags.

    ``vis``: present, in the FOV and line-of-sight visible; ``det``: a measurement originated from the target;
    ``assoc``: the target has a gated partner among the estimates (:func:`gated_assignment`). Episodes without a
    detection are not counted and not returned; episodes with a detection but no initiation are censored.
    """
    vis, det, assoc = (np.asarray(a, dtype=bool) for a in (vis, det, assoc))
    require(vis.shape == det.shape == assoc.shape, "vis, det and assoc must have the same (K, P) shape")
    episodes: list[Episode] = []
    for i in range(vis.shape[1]):
        for k0, k_end in visibility_runs(vis[:, i], g_min):
            detected = np.flatnonzero(det[k0 : k_end + 1, i])
            if len(detected) == 0:
                continue
            k_d = k0 + int(detected[0])
            k_t = first_confirmed(assoc[:, i], k_d, k_end, confirm_n)
            censored = k_t < 0
            delay = math.nan if censored else (k_t - k_d) * dt
            delay_lb = (k_end - k_d + 1) * dt if censored else delay
            episodes.append(Episode(i, k0, k_end, k_d, k_t, delay, delay_lb, censored))
    return episodes


def _mean_std(x: np.ndarray, ddof: int) -> tuple[float, float]:
    """Mean and std (NaN when there are too few values for ``ddof``)."""
    mean = float(np.mean(x)) if len(x) else math.nan
    std = float(np.std(x, ddof=ddof)) if len(x) > ddof else math.nan
    return mean, std


def delay_summary(episodes: Sequence[Episode], ddof: int = 0, censored: str = "exclude") -> dict[str, float | int]:
    """Per-trial k̄_delay and σ_k_delay (§5.4 step 7).

    ``delay_mean``/``delay_std`` follow ``censored``: "exclude" (censored episodes left out, the default) or
    "lower_bound" (censored episodes enter with their lower bound). ``delay_mean_lb``/``delay_std_lb`` always use
    the lower-bound variant. Means are NaN when no episode counts. ``n_episodes`` counts every detected episode,
    censored ones included.
    """
    require(censored in ("exclude", "lower_bound"), f"censored = {censored!r}; choose 'exclude' or 'lower_bound'")
    counted = np.array([e.delay for e in episodes if not e.censored], dtype=float)
    lower = np.array([e.delay_lb for e in episodes], dtype=float)
    mean_lb, std_lb = _mean_std(lower, ddof)
    mean, std = _mean_std(counted, ddof) if censored == "exclude" else (mean_lb, std_lb)
    return {
        "delay_mean": mean,
        "delay_std": std,
        "delay_mean_lb": mean_lb,
        "delay_std_lb": std_lb,
        "n_episodes": len(episodes),
        "n_censored": sum(e.censored for e in episodes),
    }


# ---------------------------------------------------------------------------------------------------------------------
# evaluation sets (§5.1)


def gt_mask(scans: Scans, gt_set: str = "fov") -> np.ndarray:
    """(K, P) membership of GT_k (§5.1).

    "fov": present and in FOV_k (occluded targets count); "visible": line-of-sight visible; "scene": present.
    """
    present = np.asarray(scans.present, dtype=bool) & np.isfinite(scans.truth_xy).all(axis=-1)
    if gt_set == "fov":
        return present & np.asarray(scans.in_fov, dtype=bool)
    if gt_set == "visible":
        return present & np.asarray(scans.visible, dtype=bool)
    require(gt_set == "scene", f"gt_set = {gt_set!r}; choose 'fov', 'visible' or 'scene'")
    return present


def estimate_positions(X: np.ndarray, ego: np.ndarray, sensor_cfg: SensorConfig, gt_set: str = "fov") -> np.ndarray:
    """Est_k (§5.1): extracted positions (with multiplicity), restricted to FOV_k unless ``gt_set`` is "scene"."""
    E = _points(X)
    return E[estimate_mask(E, ego, sensor_cfg, gt_set)]


def estimate_mask(X: np.ndarray, ego: np.ndarray, sensor_cfg: SensorConfig, gt_set: str = "fov") -> np.ndarray:
    """(n,) which rows of ``X`` are in Est_k (§5.1): ``X[estimate_mask(...)]`` has the rows of
    :func:`estimate_positions`, so that per-estimate data (labels) can be restricted the same way."""
    E = _points(X)
    if gt_set == "scene" or len(E) == 0:
        return np.ones(len(E), dtype=bool)
    return fov_mask(E, ego, sensor_cfg)


# ---------------------------------------------------------------------------------------------------------------------
# one filter run


@dataclass
class TrialMetrics:
    """Every metric of one filter run (§5).

    Attributes:
        summary: per-trial scalars, keys :data:`SUMMARY_KEYS` (Python floats/ints; NaN where undefined).
        episodes: the delay episodes (§5.4).
        series: per-step arrays, keys :data:`SERIES_KEYS`, each of length K.
        partner: (K, P) per scan and target, the index in Est_k of the estimate the gated matching (§5.4 step 1)
            pairs with the target, -1 for none (None: not kept); what the track measures read the labels from.
    """

    summary: dict[str, float | int]
    episodes: list[Episode] = field(default_factory=list)
    series: dict[str, np.ndarray] = field(default_factory=dict)
    partner: np.ndarray | None = None

    def __getitem__(self, key: str) -> float | int:
        """``summary[key]``: ``metrics["ospa"]``."""
        return self.summary[key]

    def values(self) -> dict[str, float | int]:
        """The summary without its wall-clock keys (:data:`TIMING_KEYS`): what the same trial gives every time.

        Example:
            >>> m = TrialMetrics({"ospa": 3.0, "t_update": 0.2})
            >>> m.values()
            {'ospa': 3.0}
        """
        return {k: v for k, v in self.summary.items() if k not in TIMING_KEYS}

    def __eq__(self, other: object) -> bool:
        """Equal metrics: the same :meth:`values` (NaN equal to NaN), episodes and per-scan series; the filter's
        stage times are left out, so two runs of the same trial compare equal."""
        if not isinstance(other, TrialMetrics):
            return NotImplemented
        a, b = self.values(), other.values()
        episodes = [astuple(e) for e in self.episodes], [astuple(e) for e in other.episodes]
        return (
            a.keys() == b.keys()
            and all(_same(a[k], b[k]) for k in a)
            and len(episodes[0]) == len(episodes[1])
            and all(_same(x, y) for e, f in zip(*episodes, strict=True) for x, y in zip(e, f, strict=True))
            and self.series.keys() == other.series.keys()
            and all(np.array_equal(self.series[k], other.series[k], equal_nan=True) for k in self.series)
        )

    __hash__ = None  # type: ignore[assignment]  # mutable: equal by value

    def __repr__(self) -> str:
        s = self.summary
        shown = ("ospa", "gospa", "card_err", "precision", "recall", "delay_mean", "n_episodes")
        body = ", ".join(f"{k}={s[k]:.4g}" if isinstance(s[k], float) else f"{k}={s[k]}" for k in shown if k in s)
        K = len(next(iter(self.series.values()))) if self.series else 0
        return f"TrialMetrics({body}; {len(s)} summary keys, {len(self.episodes)} episodes, {K} scans)"


def _same(a: object, b: object) -> bool:
    """``a == b``, NaN equal to NaN."""
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


def _mean(a: np.ndarray) -> float:
    """Mean over all steps (NaN for an empty run)."""
    return float(np.mean(a)) if len(a) else math.nan


def _ratio(num: float, den: float) -> float:
    return num / den if den > 0 else math.nan


def _step_costs(results: Sequence[StepResult]) -> dict[str, float | int]:
    """Component counts and stage times of the filter (§5.7); times are totals over the run (s)."""
    n_red = np.array([r.n_reduced for r in results], dtype=float)
    return {
        "mean_components": float(n_red.mean()) if len(n_red) else math.nan,
        "max_components": int(n_red.max()) if len(n_red) else 0,
        "mean_predicted": float(np.mean([r.n_predicted for r in results])) if results else math.nan,
        "mean_updated": float(np.mean([r.n_updated for r in results])) if results else math.nan,
        "cap_hits": int(sum(bool(r.cap_hit) for r in results)),
        "mean_pD": float(np.mean([r.mean_pD for r in results])) if results else math.nan,
        "t_predict": float(sum(r.t_predict for r in results)),
        "t_update": float(sum(r.t_update for r in results)),
        "t_reduce": float(sum(r.t_reduce for r in results)),
    }


def evaluate(
    scans: Scans,
    results: Sequence[StepResult],
    cfg: MetricsConfig,
    sensor_cfg: SensorConfig,
    *,
    compiled: bool = True,
) -> TrialMetrics:
    """All metrics of one filter run: ``results[k]`` is the filter output at ``scans.scans[k]`` (§5.1-5.7).

    Per step: GT_k and Est_k (§5.1), the gated matching (TP/FP/FN and ``assoc``), OSPA (c, p from ``cfg``), GOSPA,
    the cardinality error and its Σw variant (Σw = ``sum_w``, the posterior mass after the update). Per trial:
    means over all K steps (both-empty steps contribute 0), precision/recall from the summed counts, and the delay
    episodes built from ``scans.visible``, ``scans.detected`` and ``assoc``.

    ``compiled``: with OSPA and GOSPA of order p = 1 (the defaults), the per-scan matchings of the whole run are one
    compiled call (:func:`soabench.metrics_kernels.run_matchings`, the same numbers); False, or another order, runs
    :func:`gated_assignment`, :func:`ospa` and :func:`gospa` scan by scan.
    """
    K = len(scans.scans)
    require(len(results) == K, f"{len(results)} filter results for {K} scans")
    gt = gt_mask(scans, cfg.gt_set)
    s = {key: np.zeros(K) for key in SERIES_KEYS}
    if compiled and cfg.ospa_p == 1.0 and cfg.gospa_p == 1.0:
        partner, ospa_parts, gospa_parts = _matchings_compiled(scans, results, gt, cfg, sensor_cfg, s)
    else:
        partner, ospa_parts, gospa_parts = _matchings(scans, results, gt, cfg, sensor_cfg, s)
    assoc = partner >= 0
    origins = np.zeros((K, len(ORIGIN_KEYS)), dtype=np.int64)
    for k, res in enumerate(results):
        s["sum_w"][k], s["n_components"][k] = res.sum_w, res.n_reduced
        origins[k] = origin_counts_of(res)
    s.update(zip(ORIGIN_KEYS, origins.T, strict=True))
    s["fp"] = s["n_est"] - s["tp"]
    s["fn"] = s["n_gt"] - s["tp"]
    s["ospa"], s["gospa"] = ospa_parts[:, 0], gospa_parts[:, 0]
    s["card_err"] = np.abs(s["n_est"] - s["n_gt"])
    episodes = delay_episodes(scans.visible, scans.detected, assoc, scans.dt, cfg.g_min, cfg.confirm_n)
    tp, fp, fn = (int(s[key].sum()) for key in ("tp", "fp", "fn"))
    summary: dict[str, float | int] = {
        **delay_summary(episodes, cfg.ddof, cfg.censored),
        "card_err": _mean(s["card_err"]),
        "card_err_sumw": _mean(np.abs(s["sum_w"] - s["n_gt"])),
        "ospa": _mean(ospa_parts[:, 0]),
        "ospa_loc": _mean(ospa_parts[:, 1]),
        "ospa_card": _mean(ospa_parts[:, 2]),
        "gospa": _mean(gospa_parts[:, 0]),
        "gospa_loc": _mean(gospa_parts[:, 1]),
        "gospa_missed": _mean(gospa_parts[:, 2]),
        "gospa_false": _mean(gospa_parts[:, 3]),
        "precision": _ratio(tp, tp + fp),
        "recall": _ratio(tp, tp + fn),
        "tp": tp,
        "fp": fp,
        "fn": fn,
        **_step_costs(results),
    }
    series = {key: s[key].astype(float if key in ("ospa", "gospa", "sum_w") else int) for key in SERIES_KEYS}
    return TrialMetrics({key: summary[key] for key in SUMMARY_KEYS}, episodes, series, partner)


def _matchings(
    scans: Scans,
    results: Sequence[StepResult],
    gt: np.ndarray,
    cfg: MetricsConfig,
    sensor_cfg: SensorConfig,
    s: dict[str, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scan by scan: GT_k, Est_k, the gated matching, OSPA and GOSPA; fills ``s`` (n_gt, n_est, tp) and returns
    ``(partner (K, P), ospa parts (K, 3), gospa parts (K, 4))`` (:attr:`TrialMetrics.partner`)."""
    K = len(results)
    partner = np.full(gt.shape, -1, dtype=np.int64)
    ospa_parts = np.zeros((K, 3))
    gospa_parts = np.zeros((K, 4))
    for k, (scan, res) in enumerate(zip(scans.scans, results, strict=True)):
        E = estimate_positions(res.X, scan.ego, sensor_cfg, cfg.gt_set)
        s["tp"][k] = _score_scan(k, E, scans.truth_xy, gt, cfg, partner, ospa_parts, gospa_parts)
        s["n_gt"][k], s["n_est"][k] = gt[k].sum(), len(E)
    return partner, ospa_parts, gospa_parts


def _score_scan(
    k: int,
    E: np.ndarray,
    truth_xy: np.ndarray,
    gt: np.ndarray,
    cfg: MetricsConfig,
    partner: np.ndarray,
    ospa_parts: np.ndarray,
    gospa_parts: np.ndarray,
) -> int:
    """Scan k's gated matching, OSPA and GOSPA with numpy and scipy: fills row k of ``partner`` (each target's
    gated estimate, its index in ``E``), ``ospa_parts`` and ``gospa_parts``; returns the number of gated pairs (TP)."""
    gt_idx = np.flatnonzero(gt[k])
    G = truth_xy[k, gt_idx]
    D = pairwise_distances(_points(E), _points(G))  # once for the three matchings of the step
    pairs = gated_assignment(E, G, cfg.d_gate, D)
    partner[k, gt_idx[pairs[:, 1]]] = pairs[:, 0]
    ospa_parts[k] = ospa(E, G, cfg.ospa_c, cfg.ospa_p, D)
    gospa_parts[k] = gospa(G, E, cfg.gospa_c, cfg.gospa_p, D.T)
    return len(pairs)


def _matchings_compiled(
    scans: Scans,
    results: Sequence[StepResult],
    gt: np.ndarray,
    cfg: MetricsConfig,
    sensor_cfg: SensorConfig,
    s: dict[str, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_matchings` for p = 1 as one compiled call: Est_k of every scan stacked (the FOV test of
    :func:`estimate_positions` over all of them at once, each with its scan's pose)."""
    # imported when called: numba would slow every start-up
    from soabench.metrics_kernels import run_matchings

    X = [_points(res.X) for res in results]
    counts = np.fromiter((len(x) for x in X), dtype=np.int64, count=len(X))
    E = np.concatenate(X) if len(X) else np.zeros((0, 2))
    if cfg.gt_set != "scene" and len(E):
        ego = np.repeat(np.array([scan.ego for scan in scans.scans], dtype=float).reshape(-1, 3), counts, axis=0)
        keep = fov_mask(E, ego, sensor_cfg)
        E = E[keep]
        counts = np.bincount(np.repeat(np.arange(len(counts)), counts)[keep], minlength=len(counts))
    e_off = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts, out=e_off[1:])
    G = np.ascontiguousarray(scans.truth_xy, dtype=float)
    E = np.ascontiguousarray(E, dtype=float)
    args = (float(cfg.d_gate), float(GATE_COST), float(cfg.ospa_c), float(cfg.gospa_c))
    gt_c = np.ascontiguousarray(gt, dtype=bool)
    tp, partner, ospa_parts, gospa_parts, redo = announced("metrics", run_matchings, E, e_off, G, gt_c, *args)
    for k in np.flatnonzero(redo):  # coinciding points: scipy's choice among the optimal assignments (_matchings)
        tp[k] = _score_scan(k, E[e_off[k] : e_off[k + 1]], G, gt, cfg, partner, ospa_parts, gospa_parts)
    s["n_gt"][:] = gt.sum(axis=1)
    s["n_est"][:] = counts
    s["tp"][:] = tp
    return partner, ospa_parts, gospa_parts
