"""Stone Soup bridge (``pip install "soabench[stonesoup]"``): its trackers in our harness, our scenes in its world.

Both directions share one conversion. A scan's measurement z = (r, b) (range, bearing relative to the ego heading)
becomes a Stone Soup ``Detection`` with state vector ``[Bearing(b), r]`` and its own
``CartesianToBearingRange`` measurement model (``mapping=(0, 2)`` on Stone Soup's state order
[x, v_x, y, v_y], ``translation_offset`` = the ego position, ``rotation_offset`` = the ego heading, noise
diag(sigma_b^2, sigma_r^2)); scan k happens at ``EPOCH + t_k`` seconds.

* Into the harness: ``--trackers stonesoup-gmphd,stonesoup-gnn`` run :class:`StoneSoupGMPHD` (Stone Soup's
  ``PointProcessMultiTargetTracker``: GM-PHD with an EKF, one wide birth component on the sensor) and
  :class:`StoneSoupGNN` (``MultiTargetTracker`` with global-nearest-neighbour assignment, a
  ``MultiMeasurementInitiator`` and an ``UpdateTimeStepsDeleter``); their estimates go through the same metrics
  as ours, labelled (docs/method.md §2.13): Stone Soup's track ids (GNN) and component tags (GM-PHD) are uuid
  strings, numbered 1, 2, ... per run in order of first appearance (:class:`TrackLabels`).
* Out of the harness: :func:`to_stonesoup` gives a run's scans and truth (by default the truth set of our tables,
  docs/method.md §5.1) as Stone Soup detections (``TrueDetection`` linked to the walker's ``GroundTruthPath``, or
  ``Clutter``) and ground-truth paths, for Stone Soup's trackers and metric managers; :func:`from_stonesoup` turns
  the tracks back into our per-scan estimates (with the track ids), scored by ``soabench.api.evaluate``.

Stone Soup's conventions are its own (docs/method.md has ours): its GM-PHD gives the birth component no
missed-detection term, caps a merged weight at 1, and evaluates the likelihood on the raw bearing difference.
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from soabench.config import MetricsConfig
from soabench.errors import SoabenchError, require, require_type
from soabench.geometry import fov_mask
from soabench.protocols import TrackerSetup
from soabench.trackers import check_scan
from soabench.types import CLUTTER, Estimates, Scan, Scans

try:
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.deleter.time import UpdateTimeStepsDeleter
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.gaussianmixture import GaussianMixtureHypothesiser
    from stonesoup.initiator.simple import MultiMeasurementInitiator
    from stonesoup.measures import Mahalanobis, SquaredMahalanobis
    from stonesoup.mixturereducer.gaussianmixture import GaussianMixtureReducer
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.kalman import ExtendedKalmanPredictor
    from stonesoup.tracker.pointprocess import PointProcessMultiTargetTracker
    from stonesoup.tracker.simple import MultiTargetTracker
    from stonesoup.types.angle import Bearing
    from stonesoup.types.array import CovarianceMatrix, StateVector
    from stonesoup.types.detection import Clutter, Detection, TrueDetection
    from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
    from stonesoup.types.state import GaussianState, TaggedWeightedGaussianState
    from stonesoup.updater.kalman import ExtendedKalmanUpdater
    from stonesoup.updater.pointprocess import PHDUpdater
except ImportError as exc:  # one line for the user instead of a traceback
    raise SoabenchError(
        f'the Stone Soup bridge needs Stone Soup: pip install "soabench[stonesoup]" ({type(exc).__name__}: {exc})'
    ) from None

#: time of scan 0 in Stone Soup's clock (scan k is at EPOCH + t_k)
EPOCH = datetime.datetime(2000, 1, 1)
#: our state [x, y, v_x, v_y] in Stone Soup's order [x, v_x, y, v_y] (an involution: the same index maps back)
SS_ORDER = [0, 2, 1, 3]
#: squared-Mahalanobis gate of 99.9 % for 2 degrees of freedom (our filter's default gate)
GATE_999 = -2.0 * math.log(1e-3)


def measurement_model(ego: np.ndarray, sigma_r: float, sigma_b: float) -> CartesianToBearingRange:
    """Stone Soup's range-bearing model of a sensor at ``ego`` = (x, y, theta), noise (sigma_r m, sigma_b rad)."""
    x, y, theta = (float(v) for v in ego)
    return CartesianToBearingRange(
        ndim_state=4,
        mapping=(0, 2),
        noise_covar=CovarianceMatrix(np.diag([sigma_b**2, sigma_r**2])),
        translation_offset=StateVector([x, y]),
        rotation_offset=StateVector([0.0, 0.0, theta]),
    )


def scan_time(scan: Scan) -> datetime.datetime:
    return EPOCH + datetime.timedelta(seconds=float(scan.t))


def scan_detections(
    scan: Scan, sigma_r: float, sigma_b: float, paths: list[Any] | None = None, source: np.ndarray | None = None
) -> set[Detection]:
    """The measurements of ``scan`` as Stone Soup detections (one measurement model per scan).

    With ``paths`` (one GroundTruthPath per walker) and ``source`` (walker index per measurement, -1 for clutter),
    target-originated measurements become ``TrueDetection`` linked to their path and the rest ``Clutter``.
    """
    model = measurement_model(scan.ego, sigma_r, sigma_b)
    t = scan_time(scan)
    out: set[Detection] = set()
    Z = np.asarray(scan.Z, dtype=float).reshape(-1, 2)
    for i, (r, b) in enumerate(Z):
        sv = StateVector([Bearing(b), r])
        if paths is None or source is None:
            out.add(Detection(sv, timestamp=t, measurement_model=model))
        elif int(source[i]) == CLUTTER:
            out.add(Clutter(sv, timestamp=t, measurement_model=model))
        else:
            out.add(TrueDetection(sv, timestamp=t, measurement_model=model, groundtruth_path=paths[int(source[i])]))
    return out


@dataclass
class StoneSoupFeed:
    """A run's scans in Stone Soup's terms (see :func:`to_stonesoup`)."""

    detections: list[tuple[datetime.datetime, set[Detection]]]  #: (time, detections) per scan, in order
    truths: set[GroundTruthPath]  #: one path per walker, over the scans where it is present

    def __iter__(self) -> Iterator[tuple[datetime.datetime, set[Detection]]]:
        """Iterate like a Stone Soup detector: ``(time, detections)`` per scan."""
        return iter(self.detections)


def to_stonesoup(
    scans: Scans, sigma_r: float | None = None, sigma_b: float | None = None, gt_set: str = "fov"
) -> StoneSoupFeed:
    """Our scans and truth as Stone Soup detections and ground-truth paths.

    Args:
        scans: a run's :class:`~soabench.types.Scans` (``soabench.api.simulate_trial`` or ``Scans.load_npz``).
        sigma_r, sigma_b: the sensor's range (m) and bearing (rad) noise stds put into each detection's measurement
            model; default: the scans' own sensor settings (``scans.sensor``).
        gt_set: the truth the paths hold, the truth set of our tables (docs/method.md §5.1): ``"fov"`` (default:
            present and inside the field of view), ``"visible"`` (line of sight too) or ``"scene"`` (present).

    Returns:
        A :class:`StoneSoupFeed`: ``feed.detections`` (or iterate the feed) gives ``(time, set of detections)`` per
        scan, target-originated ones as ``TrueDetection`` linked to their walker's path, the rest as ``Clutter``;
        ``feed.truths`` gives one ``GroundTruthPath`` per walker of the set (``id`` = the walker's id) with states
        [x, v_x, y, v_y] at the scans where the walker is in the set, velocities by finite differences over the
        scans where it is present. Hand them to Stone Soup's metric managers (OSPA, SIAP, ...) with your tracker's
        tracks, or turn the tracks back into our estimates with :func:`from_stonesoup`.

    Example::

        from soabench.bridges.stonesoup import to_stonesoup
        feed = to_stonesoup(Scans.load_npz("run.scans.npz"))
        for time, detections in feed:
            ...
    """
    # imported when called: scipy would slow every start-up
    from soabench.metrics import gt_mask

    require_type(scans, Scans, "to_stonesoup's scans", "simulate them with soabench.api.simulate_trial")
    if sigma_r is None or sigma_b is None:
        require(
            scans.sensor is not None,
            "these Scans carry no sensor settings (Scans.sensor): give sigma_r (m) and sigma_b (rad)",
        )
        sigma_r = scans.sensor.sigma_r if sigma_r is None else sigma_r
        sigma_b = scans.sensor.sigma_b if sigma_b is None else sigma_b
    in_set = gt_mask(scans, gt_set)
    K, P = scans.truth_xy.shape[:2]
    dt = float(scans.dt)
    paths = [GroundTruthPath(id=str(scans.ped_ids[p])) for p in range(P)]
    xy = np.asarray(scans.truth_xy, dtype=float)
    present = np.asarray(scans.present, dtype=bool)
    for p in range(P):
        for k in np.flatnonzero(in_set[:, p]):
            prev = k - 1 if k > 0 and present[k - 1, p] else k
            nxt = k + 1 if k + 1 < K and present[k + 1, p] else k
            v = (xy[nxt, p] - xy[prev, p]) / (dt * (nxt - prev)) if nxt > prev else np.zeros(2)
            state = StateVector([xy[k, p, 0], v[0], xy[k, p, 1], v[1]])
            paths[p].append(GroundTruthState(state, timestamp=scan_time(scans.scans[k])))
    detections = [
        (scan_time(scan), scan_detections(scan, sigma_r, sigma_b, paths, scans.source[i]))
        for i, scan in enumerate(scans.scans)
    ]
    return StoneSoupFeed(detections, {p for p in paths if len(p)})


class StoneSoupEstimates(NamedTuple):
    """Stone Soup tracks as our per-scan estimates (:func:`from_stonesoup`)."""

    estimates: list[Estimates]  #: one per scan: the states the tracks hold at the scan's time, in our order
    labels: list[np.ndarray]  #: one (n_k,) str array per scan: the track id of each row of the scan's estimates


def from_stonesoup(tracks: Iterable[Any], scans: Scans) -> StoneSoupEstimates:
    """Stone Soup tracks as one :class:`~soabench.types.Estimates` per scan, for :func:`soabench.api.evaluate`.

    Args:
        tracks: Stone Soup ``Track`` objects (or any sequences of states with ``timestamp`` and a 4-dimensional
            ``state_vector`` [x, v_x, y, v_y], and an ``id``): every track the tracker held, including those it has
            deleted since. Each state must lie at a scan's time (scan k at ``EPOCH + t_k``, as :func:`to_stonesoup`
            dates the detections).
        scans: the scans the tracks were made from.

    Returns:
        ``(estimates, labels)``: per scan, the states the tracks hold at its time in our order [x, y, v_x, v_y]
        (a track's whole history counts, the states before its confirmation too) and the track id of each row.
        Each estimate is labelled (``Estimates.labels``, docs/method.md §2.13): the track ids numbered 1, 2, ... by
        the first scan they appear in (within a scan, by state).
    """

    require_type(scans, Scans, "from_stonesoup's scans", "give the Scans the tracks were made from")
    times = {scan_time(scan): k for k, scan in enumerate(scans.scans)}
    rows: list[list[np.ndarray]] = [[] for _ in scans.scans]
    ids: list[list[str]] = [[] for _ in scans.scans]
    for track in tracks:
        label = str(getattr(track, "id", ""))
        for state in getattr(track, "states", track):
            k = times.get(getattr(state, "timestamp", None))
            require(
                k is not None,
                f"track {label!r} holds a state at {getattr(state, 'timestamp', None)}, which is no scan's time; "
                f"scan k is at EPOCH + t_k ({EPOCH})",
            )
            x = np.asarray(state.state_vector, dtype=float).ravel()
            require(len(x) == 4, f"track {label!r} holds a {len(x)}-dimensional state; [x, vx, y, vy] is required")
            rows[k].append(x[SS_ORDER])
            ids[k].append(label)
    number: dict[str, int] = {}
    for r, i in zip(rows, ids, strict=True):
        for n in sorted(range(len(r)), key=lambda n: tuple(r[n])):
            number.setdefault(i[n], len(number) + 1)
    estimates = [
        Estimates(np.array(r).reshape(-1, 4), labels=np.array([number[x] for x in i], dtype=np.int64))
        for r, i in zip(rows, ids, strict=True)
    ]
    return StoneSoupEstimates(estimates, [np.array(i, dtype=str) for i in ids])


def estimate_set(tracks: Iterable[Any], scans: Scans, gt_set: str = "fov") -> list[Any]:
    """The track states our metrics score (Est_k of docs/method.md §5.1): those inside the field of view of their
    scan's sensor pose unless ``gt_set`` is ``"scene"``. With :func:`to_stonesoup`'s truths (same ``gt_set``) and
    ``Euclidean(mapping=(0, 2))`` (positions only; Stone Soup's default measure also reads the velocities), Stone
    Soup's ``OSPAMetric`` gives our per-scan OSPA."""

    by_time = {scan_time(scan): scan for scan in scans.scans}
    out = []
    for track in tracks:
        for state in getattr(track, "states", track):
            scan = by_time.get(state.timestamp)
            if scan is None:
                continue
            xy = np.asarray(state.state_vector, dtype=float).ravel()[[0, 2]].reshape(1, 2)
            if gt_set == "scene" or fov_mask(xy, np.asarray(scan.ego, dtype=float), scans.sensor)[0]:
                out.append(state)
    return out


def stonesoup_ospa(
    tracks: Iterable[Any], scans: Scans, c: float | None = None, p: float | None = None, gt_set: str = "fov"
) -> np.ndarray:
    """Stone Soup's own OSPA (``OSPAMetric``) per scan, on the sets our metrics score: the truth of
    :func:`to_stonesoup` and the track states of :func:`estimate_set` (same ``gt_set``), positions only
    (``Euclidean(mapping=(0, 2))``; Stone Soup's default measure also reads the velocities). A scan where both sets
    are empty is 0, as ours. ``c``, ``p``: the cut-off (m) and order, default our ``[metrics]`` ospa_c and ospa_p
    (docs/method.md §5.2). Equal to ``soabench.api.evaluate(scans, from_stonesoup(tracks, scans).estimates)
    .series["ospa"]``."""
    from stonesoup.measures import Euclidean
    from stonesoup.metricgenerator.ospametric import OSPAMetric

    require_type(scans, Scans, "stonesoup_ospa's scans", "give the Scans the tracks were made from")
    default = MetricsConfig()
    metric = OSPAMetric(
        c=default.ospa_c if c is None else c, p=default.ospa_p if p is None else p, measure=Euclidean(mapping=(0, 2))
    )
    estimated = estimate_set(tracks, scans, gt_set)
    truth = [state for path in to_stonesoup(scans, gt_set=gt_set).truths for state in path]
    value = metric.compute_over_time(estimated, [0] * len(estimated), truth, [0] * len(truth))
    by_time = {m.timestamp: m.value for m in value.value}
    return np.array([by_time.get(scan_time(scan), 0.0) for scan in scans.scans], dtype=float)


class TrackLabels:
    """Stone Soup's track ids or component tags (uuid strings) as int64 labels 1, 2, ... in order of first
    appearance, for one run (docs/method.md §2.13)."""

    def __init__(self) -> None:
        self.ids: dict[str, int] = {}
        self.next = 1

    def fresh(self) -> int:
        """A label no id has had."""
        self.next += 1
        return self.next - 1

    def of(self, key: str) -> int:
        """The label of ``key`` (a fresh one the first time)."""
        if key not in self.ids:
            self.ids[key] = self.fresh()
        return self.ids[key]

    def unique(self, keys: list[str], w: np.ndarray) -> np.ndarray:
        """The labels of one scan's estimates with ids ``keys``: where several share an id (a GM-PHD's updated and
        missed-detection copies of one tagged component), the heaviest (``w``; ties: the first) keeps its label and
        each other one gets a fresh label for this scan."""
        out = np.empty(len(keys), dtype=np.int64)
        seen: set[int] = set()
        for i in np.argsort(-np.asarray(w, dtype=float), kind="stable"):
            label = self.of(keys[i])
            if label in seen:
                label = self.fresh()
            seen.add(label)
            out[i] = label
        return out


def _first_seen(tracks: Iterable[Any], labels: TrackLabels) -> list[Any]:
    """``tracks`` (a set: no fixed order) in a fixed order: known tracks by label, then new ones by their current
    state vector, so that labels are numbered the same way in every run."""
    known = sorted((t for t in tracks if str(t.id) in labels.ids), key=lambda t: labels.ids[str(t.id)])
    new = sorted(
        (t for t in tracks if str(t.id) not in labels.ids),
        key=lambda t: tuple(np.asarray(t.state.state_vector, dtype=float).ravel()),
    )
    return known + new


def _state_array(states: list[Any]) -> np.ndarray:
    """(n, 4) in our order [x, y, v_x, v_y] from Stone Soup states."""
    if not states:
        return np.zeros((0, 4))
    X = np.array([np.asarray(s.state_vector, dtype=float).ravel() for s in states])
    return X[:, SS_ORDER]


class _Base:
    """What both Stone Soup trackers share: the sensor, the CV transition and the EKF."""

    name = "stonesoup"

    def __init__(self, setup: TrackerSetup) -> None:
        s, f = setup.sensor, setup.config.filter
        self.sigma_r, self.sigma_b = float(s.sigma_r), float(s.sigma_b)
        self.sensor = s
        q = float(f.sigma_a) ** 2
        self.transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
        self.predictor = ExtendedKalmanPredictor(self.transition)
        self.updater = ExtendedKalmanUpdater(measurement_model=None)  # each detection carries its own model

    def _detections(self, scan: Scan) -> tuple[datetime.datetime, set[Detection]]:
        return scan_time(scan), scan_detections(scan, self.sigma_r, self.sigma_b)


class StoneSoupGMPHD(_Base):
    """Stone Soup's GM-PHD tracker (``PointProcessMultiTargetTracker``) as a soabench tracker.

    Settings come from the run's configuration: p_S, p_D (static), the gate, prune/merge thresholds, J_max and the
    extraction threshold of ``[filter]``, sigma_a of the CV model, the clutter density lambda_c / ((r_max - r_min)
    Theta) in (bearing, range) of ``[sensor]``. Stone Soup's GM-PHD takes one birth component: at each scan it is
    centred mid-range ahead of the sensor ((r_min + r_max) / 2 along the heading; the range-bearing Jacobian is
    singular on the sensor itself) with position std ``birth_sigma`` (default r_max / 2) and velocity std
    ``[birth] sigma_v_birth``, weight ``[birth] N_hat`` (expected births per scan).

    Options (``[plugins.stonesoup-gmphd]``): ``birth_sigma`` (m).
    """

    name = "stonesoup-gmphd"

    def __init__(self, setup: TrackerSetup, birth_sigma: float | None = None) -> None:
        super().__init__(setup)
        f, b = setup.config.filter, setup.config.birth
        s = self.sensor
        kappa = s.lambda_c / ((s.r_max - s.r_min) * s.fov)
        hyp = GaussianMixtureHypothesiser(
            DistanceHypothesiser(self.predictor, self.updater, SquaredMahalanobis(), missed_distance=GATE_999),
            order_by_detection=True,
        )
        phd = PHDUpdater(self.updater, clutter_spatial_density=kappa, prob_detection=f.p_D, prob_survival=f.p_S)
        reducer = GaussianMixtureReducer(
            prune_threshold=f.prune_T, merge_threshold=f.merge_U, max_number_components=f.J_max
        )
        self.birth_sigma = float(birth_sigma) if birth_sigma is not None else s.r_max / 2.0
        self.birth_ahead = (s.r_min + s.r_max) / 2.0
        self.birth_velocity_var = float(b.sigma_v_birth) ** 2
        self.birth = TaggedWeightedGaussianState(
            StateVector([0.0, 0.0, 0.0, 0.0]),
            CovarianceMatrix(np.diag([self.birth_sigma**2, self.birth_velocity_var] * 2)),
            weight=float(b.N_hat),
            tag=TaggedWeightedGaussianState.BIRTH,
        )
        self.tracker = PointProcessMultiTargetTracker(
            detector=None,
            updater=phd,
            hypothesiser=hyp,
            reducer=reducer,
            extraction_threshold=float(f.extract_thr),
            birth_component=self.birth,
        )
        self.labels = TrackLabels()

    def step(self, scan: Scan) -> Estimates:
        check_scan(scan)
        x, y, theta = (float(v) for v in scan.ego)
        d = self.birth_ahead  # not on the sensor itself: the range-bearing Jacobian is singular there
        self.birth.state_vector = StateVector([x + d * math.cos(theta), 0.0, y + d * math.sin(theta), 0.0])
        time, dets = self._detections(scan)
        self.tracker.update_tracker(time, dets)
        mix = list(self.tracker.gaussian_mixture)
        states = self.tracker.extracted_target_states
        w = np.array([float(c.weight) for c in states])
        return Estimates(
            _state_array(states),
            w=w,
            n_components=len(mix),
            cardinality=float(sum(float(c.weight) for c in mix)),
            labels=self.labels.unique([str(c.tag) for c in states], w),
        )


class StoneSoupGNN(_Base):
    """Stone Soup's ``MultiTargetTracker``: global nearest neighbour (``GNNWith2DAssignment`` over a Mahalanobis
    ``DistanceHypothesiser``), a ``MultiMeasurementInitiator`` (a track is confirmed after ``min_points``
    associated detections, each new track starts from the inverse measurement with velocity std
    ``[birth] sigma_v_birth``) and an ``UpdateTimeStepsDeleter`` (a track ends after ``delete_after`` scans without
    a detection). The estimates are the confirmed tracks' current states.

    Options (``[plugins.stonesoup-gnn]``): ``min_points`` (default 2), ``delete_after`` (default 3), ``gate``
    (Mahalanobis distance, default 3).
    """

    name = "stonesoup-gnn"

    def __init__(self, setup: TrackerSetup, min_points: int = 2, delete_after: int = 3, gate: float = 3.0) -> None:
        super().__init__(setup)
        hyp = DistanceHypothesiser(self.predictor, self.updater, Mahalanobis(), missed_distance=float(gate))
        associator = GNNWith2DAssignment(hyp)
        v2 = float(setup.config.birth.sigma_v_birth) ** 2
        prior = GaussianState(StateVector([0.0, 0.0, 0.0, 0.0]), CovarianceMatrix(np.diag([1.0, v2, 1.0, v2])))
        initiator = MultiMeasurementInitiator(
            prior_state=prior,
            deleter=UpdateTimeStepsDeleter(int(delete_after)),
            data_associator=associator,
            updater=self.updater,
            min_points=int(min_points),
        )
        self.tracker = MultiTargetTracker(
            initiator=initiator,
            deleter=UpdateTimeStepsDeleter(int(delete_after)),
            detector=None,
            data_associator=associator,
            updater=self.updater,
        )
        self.labels = TrackLabels()

    def step(self, scan: Scan) -> Estimates:
        check_scan(scan)
        time, dets = self._detections(scan)
        _, tracks = self.tracker.update_tracker(time, dets)
        ordered = _first_seen(tracks, self.labels)
        labels = np.array([self.labels.of(str(t.id)) for t in ordered], dtype=np.int64)
        n_holding = len(getattr(self.tracker.initiator, "holding_tracks", ()))
        return Estimates(_state_array([t.state for t in ordered]), n_components=len(tracks) + n_holding, labels=labels)
