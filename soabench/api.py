"""The public API of soabench in one place: ``import soabench.api as sb`` (walk-through: docs/user-guide/python.md).

Four calls cover a study from a notebook:

* :func:`simulate_trial`: one trial's truth (:class:`Recording`) and sensor scans (:class:`Scans`), as trial n of
  ``soabench run --seed S`` sees them;
* :func:`make_tracker`: a tracker with ``step(scan)``: a birth model in our GM-PHD filter (S-OA and the
  baselines, an entry point or your class) or a whole tracker (Stone Soup's, an entry point or your class);
* :func:`evaluate`: the metrics of one run (docs/method.md §5) from its per-scan :class:`Estimates` or
  :class:`StepResult`: the numbers of a row of ``trials.csv``;
* :func:`run`: the Monte Carlo protocol (§5.8) in memory, a :class:`RunResult` holding the rows ``soabench run``
  writes to ``trials.csv``, ``episodes.csv`` and ``steps.csv``.

:func:`to_stonesoup` and :func:`from_stonesoup` carry scans, truth and tracks to and from Stone Soup (the
``stonesoup`` extra); :func:`stonesoup_ospa` is Stone Soup's own OSPA on our sets, to compare with ours.
:func:`load_scene` and :func:`draw_scene` draw a scene, a scan and a tracker's estimates on matplotlib axes.

The data that flows (:mod:`soabench.types`): :class:`Recording`; :class:`Scans` / :class:`Scan`;
:class:`Births` and :class:`NewbornTerms` from a :class:`BirthContext`; :class:`Estimates` (any tracker) and
:class:`StepResult` (our GM-PHD). The two extension points (:mod:`soabench.protocols`): :class:`BirthModel` and
:class:`Tracker` (built from a :class:`TrackerSetup`); :class:`FilterTracker` is one of our filter families
(:data:`FAMILIES`: ``"gmphd"``, ``"lmb"``, ...) with a birth model as a tracker; :func:`build_components`,
:func:`births_from`, :func:`isotropic` and :class:`FOVRule` help write birth models (§3.0). Plugins register by
entry point (groups :data:`BIRTH_GROUP`, :data:`TRACKER_GROUP`) or are named as ``module:Class``;
:func:`resolve` turns a name of a kind (:data:`BIRTH_MODEL`, :data:`TRACKER`) into its class.

Wrong input fails at this boundary with one line (a ``ValueError``; a ``TypeError`` too for an object of the wrong
kind), e.g. a :class:`Scans` passed to ``step``, NaN truth rows, or Stone Soup-ordered states ([x, vx, y, vy],
:data:`ORDER_STONESOUP`) where ours ([x, y, vx, vy], :data:`ORDER_SOABENCH`) are expected.
"""

import dataclasses as _dc
import importlib as _importlib
from collections.abc import Sequence as _Sequence
from pathlib import Path as _Path
from typing import TYPE_CHECKING as _TYPE_CHECKING
from typing import Any as _Any

from soabench import boundary as _boundary
from soabench import plugins as _plugins
from soabench import scenario as _scenarios  # by attribute: a test may stand in for its simulate
from soabench.birth.base import FOVRule, births_from, build_components, isotropic
from soabench.boundary import ORDER_SOABENCH, ORDER_STONESOUP
from soabench.config import FAMILIES, Config
from soabench.errors import require as _require
from soabench.errors import require_type as _require_type
from soabench.errors import require_value as _require_value
from soabench.experiment.trial.guard import check_births as _check_births
from soabench.experiment.trial.registry import load_scene_cached as _load_scene_cached
from soabench.plugins import BIRTH_GROUP, TRACKER_GROUP
from soabench.protocols import BirthModel, Tracker, TrackerSetup
from soabench.seeding import trial_seeds as _trial_seeds
from soabench.trackers import FilterTracker, GMPHDTracker, run_tracker
from soabench.trackers import build_filter as _build_filter
from soabench.types import (
    CLUTTER,
    SOURCE_FOV,
    SOURCE_GM,
    SOURCE_GRID,
    SOURCE_MEAS,
    SOURCE_NAMES,
    SOURCE_OCCL,
    SOURCE_SEM,
    BirthContext,
    Births,
    Estimates,
    NewbornTerms,
    Obstacles,
    Recording,
    Scan,
    Scans,
    StepResult,
)

if _TYPE_CHECKING:  # at run time imported on first use (module __getattr__)
    from soabench.experiment.execution.memory import RunResult
    from soabench.metrics import TrialMetrics

BIRTH_MODEL = _plugins.BIRTH  #: plugin kind of a birth model (:func:`resolve`): ``"birth model"``
TRACKER = _plugins.TRACKER  #: plugin kind of a whole tracker (:func:`resolve`): ``"tracker"``

__all__ = [
    "BIRTH_GROUP",
    "BIRTH_MODEL",
    "CLUTTER",
    "ORDER_SOABENCH",
    "ORDER_STONESOUP",
    "SOURCE_FOV",
    "SOURCE_GM",
    "SOURCE_GRID",
    "SOURCE_MEAS",
    "SOURCE_NAMES",
    "SOURCE_OCCL",
    "SOURCE_SEM",
    "TRACKER",
    "TRACKER_GROUP",
    "BirthContext",
    "BirthModel",
    "Births",
    "Config",
    "Estimates",
    "FOVRule",
    "FAMILIES",
    "FilterTracker",
    "GMPHDTracker",
    "NewbornTerms",
    "Obstacles",
    "Recording",
    "RunResult",
    "Scan",
    "Scans",
    "StepResult",
    "Tracker",
    "TrackerSetup",
    "TrialMetrics",
    "births_from",
    "build_components",
    "evaluate",
    "draw_scene",
    "from_stonesoup",
    "isotropic",
    "load_scene",
    "make_tracker",
    "occlusion_gaps",
    "resolve",
    "run",
    "run_tracker",
    "simulate_trial",
    "stonesoup_ospa",
    "to_stonesoup",
]


#: public classes imported on first use (their modules load the metrics and the harness, seconds of imports that a
#: plugin importing this module does not need)
_LAZY = {"RunResult": "soabench.experiment.execution.memory", "TrialMetrics": "soabench.metrics"}


def __getattr__(name: str) -> _Any:
    if name in _LAZY:
        return getattr(_importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'soabench.api' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The public names only (tab completion in a notebook lists what is meant to be used)."""
    return sorted(__all__)


def resolve(kind: str, name: str) -> type:
    """The class registered under ``name`` as a plugin of ``kind`` (:data:`BIRTH_MODEL` or :data:`TRACKER`).

    ``name`` is a built-in (``"soa"``, ``"stonesoup-gmphd"``, ...), an installed entry point or an import path
    ``module:Class`` (allowed here as if typed on the command line). A kind other than the two, or a name unknown for
    the kind, is one line naming what is allowed.

    Example:
        >>> import soabench.api as sb
        >>> sb.resolve(sb.BIRTH_MODEL, "pubm").__name__
        'PartiallyUniformBirth'
    """
    _plugins.check_kind(kind)
    _plugins.allow_import_paths([name] if isinstance(name, str) else [])
    return _plugins.resolve(kind, name)


def simulate_trial(
    net: str = "intersection",
    seed: int = 0,
    trial: int = 0,
    duration: float | None = None,
    config: "Config | dict | str | _Path | None" = None,
) -> tuple[Recording, Scans]:
    """The truth and the sensor scans of trial ``trial`` of ``soabench run --seed seed`` (docs/method.md §5.8).

    Args:
        net: a shipped scene (``"intersection"``, ``"tjunction"``, ``"arterial"``, ``"grid_block"``), a scene
            folder or the path of a ``.net.xml``.
        seed, trial: the base seed and the trial index; trial n's random streams depend only on ``(seed, n)``.
        duration: seconds to simulate (default: the configuration's ``experiment.duration``, 100 s).
        config: a :class:`Config`, a dict of sections, a TOML path or None (defaults); its ``[sensor]`` section
            makes the scans, at the first clutter rate of ``experiment.clutter``.

    Returns:
        ``(recording, scans)``: the same values trial ``trial`` of a run with this configuration and its first
        clutter rate uses.

    Example:
        >>> import soabench.api as sb
        >>> recording, scans = sb.simulate_trial("arterial", seed=0, trial=0, duration=5)
        >>> len(scans), scans.truth_xy.shape[0]
        (5, 5)
    """
    from soabench.experiment.execution.runner import check_against_scenario
    from soabench.sensor import observe

    cfg = _boundary.as_config(config)
    _require_value(_is_int(seed) and seed >= 0, "seed", seed, "must be an integer >= 0")
    _require_value(_is_int(trial) and trial >= 0, "trial", trial, "must be an integer >= 0")
    if duration is not None:
        cfg = Config.from_dict({"experiment": {"duration": duration}}, base=cfg).validate()
    scene, scenario = _load_scene_cached(str(net), (), None)
    check_against_scenario(cfg, scenario)
    seeds = _trial_seeds(seed, trial)
    recording = _scenarios.simulate(scene, scenario, seeds, duration=cfg.experiment.duration)
    return recording, observe(recording, scene, cfg.sensor_at(), seeds.sensor_rngs())


def _is_int(v: _Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def make_tracker(
    name_or_class: "str | type",
    scene_or_net: _Any = "intersection",
    config: "Config | dict | str | _Path | None" = None,
    mode: str = "static",
    seed: int = 0,
    trial: int = 0,
    filter: str | None = None,
    **options: _Any,
) -> _Any:
    """A tracker with ``step(scan)``, built as the harness builds the run of ``name_or_class`` in trial ``trial``.

    Args:
        name_or_class: a birth model (``"soa"``, ``"pubm"``, ``"ubm"``, ``"ubm-ws"``, ``"atbm"``, ``"gmbm"``, an
            installed entry point, ``"module:Class"`` or the class itself), which runs in one of our filter
            families; or a whole tracker (``"stonesoup-gmphd"``, ``"stonesoup-gnn"``, an entry point,
            ``"module:Class"`` or a class with a ``step`` method).
        scene_or_net: the scene the birth model reads (a SceneMap, or a network name or path).
        config: a :class:`Config`, a dict of sections, a TOML path or None (defaults).
        mode: the probability mode (``"static"``, ``"static+occ"``, ``"dynamic"``, ``"dynamic+occ"``;
            docs/method.md §4.6), one the family defines.
        seed, trial: the run's placement generator (and a family's association stream) are trial ``trial``'s of
            base seed ``seed``.
        filter: the filter family the birth model runs in (:data:`FAMILIES`: ``"gmphd"``, ``"lmb"``, ...). None:
            the one the configuration's ``experiment.filters`` names (the GM-PHD by default); a configuration
            naming several is refused, as is one that names others than ``filter``.
        options: a plugin's own options (default: the configuration's ``[plugins.<name>]`` table).

    The configuration's ``[sensor]``, ``[birth]``, ``[filter]``, ``[plugins.<name>]`` sections and the family's own
    (``[lmb]``, ...) shape the tracker, ``experiment.filters`` picks its family (above); the rest of ``[experiment]``
    and ``[metrics]`` describe a run and its scoring (:func:`run`, :func:`evaluate`), not one tracker.

    Returns:
        A :class:`FilterTracker` for a birth model (``step`` returns :class:`StepResult`, labelled), else the
        tracker (``step`` returns :class:`Estimates`). Stepping it through :func:`simulate_trial`'s scans gives the
        step results of that run of ``soabench run``.

    Example:
        >>> import soabench.api as sb
        >>> _, scans = sb.simulate_trial("arterial", duration=5)
        >>> tracker = sb.make_tracker("soa", "arterial")
        >>> results = [tracker.step(scan) for scan in scans]
        >>> type(results[0]).__name__, len(results) == len(scans)
        ('StepResult', True)
    """

    cfg, family = _boundary.family_config(config, filter)
    kind, name, cls = _boundary.plugin(name_or_class)
    scene = _boundary.as_scene(scene_or_net)
    seeds = _trial_seeds(seed, trial)
    rng = seeds.placement_rng()
    builtin = kind == BIRTH_MODEL and isinstance(name_or_class, str) and _plugins.is_builtin_birth(name)
    _require(
        not (builtin and options), f"{name} is a built-in birth model: set its options in the config's [birth] section"
    )
    options = options or dict(cfg.plugins.get(name, {}))
    _plugins.check_options(kind, name, cls, options)
    if kind == TRACKER:
        return cls(TrackerSetup(cfg.sensor_at(), scene, rng, mode, cfg), **options)
    filt, p_D_b = _build_filter(family, cfg, cfg.sensor_at(), mode, seeds.association_rng())
    birth_model = cls(cfg.birth, cfg.sensor_at(), scene, rng, **options)
    return FilterTracker(birth_model, filt, p_D_b, check_births=None if builtin else _named_check(name))


def _named_check(plugin: str) -> _Any:
    """The births check of a plugin birth model, its errors naming ``plugin``."""

    return lambda births, scan: _check_births(births, scan, plugin)


def evaluate(
    scans: Scans,
    estimates: _Sequence[_Any],
    config: "Config | dict | str | _Path | None" = None,
    order: str | None = None,
) -> "TrialMetrics":
    """Every metric of one run (docs/method.md §5): the numbers of its row in ``trials.csv``.

    Args:
        scans: the run's scans (with their sensor settings, which set the FOV of the estimate set, §5.1).
        estimates: one entry per scan: :class:`Estimates`, :class:`StepResult` (our filter's) or an (n, 2) / (n, 4)
            array; checked as the harness checks a tracker's output.
        config: its ``[metrics]`` section (OSPA/GOSPA cut-offs, truth set, gate, ...); a :class:`Config`, a dict,
            a TOML path, or None for the defaults.
        order: the column order of four-column states: :data:`ORDER_SOABENCH` ``"x,y,vx,vy"`` or
            :data:`ORDER_STONESOUP` ``"x,vx,y,vy"``. None: ours, refused with one line if the states fit the truth
            far better read in Stone Soup's order.

    Returns:
        A :class:`TrialMetrics`: ``summary`` (``m["ospa"]``, the columns of a ``trials.csv`` row), the delay
        ``episodes`` and the per-scan ``series`` (the columns of ``steps.csv``). When the estimates carry labels
        (``Estimates.labels`` on every scan with estimates), ``summary`` also holds the track columns of
        docs/method.md §9.3-9.4 (``m["hota"]``, ``m["idf1"]``, ``m["idsw"]``, ... as in ``trials.csv``).

    Example:
        >>> import soabench.api as sb
        >>> _, scans = sb.simulate_trial("arterial", duration=5)
        >>> tracker = sb.make_tracker("soa", "arterial")
        >>> m = sb.evaluate(scans, [tracker.step(scan) for scan in scans])
        >>> 0.0 <= m["ospa"] <= 100.0, len(m.series["ospa"]) == len(scans)
        (True, True)
    """
    from soabench.metrics import evaluate as _evaluate
    from soabench.tracks.evaluate import evaluate_tracks, run_labels

    results = _boundary.step_results(scans, estimates, order)
    _require(scans.sensor is not None, "these Scans carry no Sensor (Scans.sensor); set it to the sensor's settings")
    cfg = _boundary.metrics_config(config)
    metrics = _evaluate(scans, results, cfg, scans.sensor)
    X = [r.X for r in results]
    labels = run_labels(results, X)
    if labels is not None:
        metrics.summary.update(evaluate_tracks(scans, X, labels, metrics.episodes, cfg, scans.sensor))
    return metrics


def occlusion_gaps(scans: Scans, d_gate: float = 5.0) -> list[dict[str, _Any]]:
    """The occlusion gaps of ``scans``, described (docs/method.md §9.4): per gap (a pedestrian present and in the
    FOV but out of line of sight on scans ``k_a`` .. ``k_b``, seen before and after) its ``target`` column,
    ``k_a``, ``k_b``, length in ``scans`` and ``seconds``, the ``occluder`` kind that hid it longest ("parked",
    "vehicle", "building", "other"), its ``displacement`` across the gap (m) and whether that exceeds ``d_gate``
    (``moved``), and the ego's (``ego_displacement``, ``ego_moved``). The ``gap_*`` columns of ``episodes.csv``
    give the same for each re-emergence episode of a run, with its coasted and identity-kept outcome.

    Example:
        >>> import soabench.api as sb
        >>> _, scans = sb.simulate_trial("arterial", duration=20)
        >>> gaps = sb.occlusion_gaps(scans)
        >>> all(g["k_b"] >= g["k_a"] and g["occluder"] in ("parked", "vehicle", "building", "other") for g in gaps)
        True
    """

    from soabench.tracks.gaps import describe_gaps
    from soabench.tracks.reemergence import occlusion_gaps as _gaps

    _require(isinstance(scans, Scans), f"scans must be a Scans, not {type(scans).__name__}")
    gaps = _gaps(scans.present & scans.in_fov, scans.visible)
    return [
        {"target": g.target, "k_a": g.k_a, "k_b": g.k_b, **_dc.asdict(d)}
        for g, d in zip(gaps, describe_gaps(scans, gaps, float(d_gate)), strict=True)
    ]


def run(
    config: "Config | dict | str | _Path | None" = None,
    *,
    net: str = "intersection",
    models: "str | _Sequence[str | type] | None" = None,
    trackers: "str | _Sequence[str | type] | None" = None,
    trials: int | None = None,
    duration: float | None = None,
    seed: int | None = None,
    probabilities: "str | _Sequence[str] | None" = None,
    clutter: "float | _Sequence[float] | None" = None,
    workers: int | None = 1,
    executor: _Any = None,
    out: "str | _Path | None" = None,
    progress: bool = False,
) -> "RunResult":
    """The Monte Carlo protocol (docs/method.md §5.8) of ``config`` on ``net``, as ``soabench run`` runs it.

    Args:
        config: a :class:`Config`, a dict of sections, a TOML path or None (defaults); the keywords below
            override its ``[experiment]`` section as the command-line flags do.
        net: a shipped scene, a scene folder or a ``.net.xml`` path.
        models: birth models (names or classes; a comma-separated string is split); trackers: whole trackers.
        trials, duration, seed, probabilities, clutter: the protocol's size, seconds per trial, base seed,
            probability modes and clutter rates.
        workers: processes (1: this process); executor: an executor of :mod:`soabench.experiment.execution.executors` to
            reuse (e.g. a Dask one).
        out: also write the run folder ``soabench run --out`` writes (run.json, trial records, the CSV files and
            the report); None (default): nothing is written.
        progress: report progress on stderr.

    Returns:
        A :class:`RunResult`: ``trials``, ``episodes``, ``steps`` (and ``timing``) as numpy record arrays holding
        the values of the CSV files ``soabench run`` writes for the same configuration, ``.to_pandas(name)`` with
        pandas, ``.write_csv(folder)`` for the files themselves (the same bytes).

    Example:
        >>> import soabench.api as sb
        >>> result = sb.run(net="arterial", trials=1, duration=5, models="soa,ubm", probabilities="static")
        >>> sorted(set(result.trials["model"].tolist()))
        ['soa', 'ubm']
    """
    from soabench.experiment.execution.memory import run_in_memory, with_experiment

    cfg = with_experiment(
        _boundary.as_config(config),
        models=_boundary.as_names(models, "models"),
        trackers=_boundary.as_names(trackers, "trackers"),
        trials=trials,
        duration=duration,
        seed=seed,
        probabilities=_boundary.as_names(probabilities, "probabilities"),
        clutter=[clutter] if isinstance(clutter, (int, float)) else clutter,
    )
    if out is None:
        return run_in_memory(cfg, str(net), workers=workers, executor=executor, progress=progress)
    from soabench.experiment.execution.memory import from_run_folder
    from soabench.experiment.execution.options import RunOptions
    from soabench.experiment.execution.runner import Batch, RunRequest
    from soabench.experiment.reports.finished import run as run_request

    options = RunOptions(workers=workers, progress=progress, figures=False)
    outcome = run_request(RunRequest(cfg, str(net), out=_Path(out), options=options), Batch(executor=executor))
    return from_run_folder(outcome.run_dir, cfg, str(net))


def load_scene(net: str = "intersection") -> _Any:
    """The map of a scene: roads, sidewalks, walking areas, crossings, buildings with their doors and parked cars
    (a :class:`~soabench.scenario.scene.SceneMap`, the one :func:`simulate_trial` and the birth models read).

    Args:
        net: a shipped scene (``"intersection"``, ``"tjunction"``, ``"arterial"``, ``"grid_block"``), a scene
            folder or the path of a ``.net.xml``.

    Example:
        >>> import soabench.api as sb
        >>> scene = sb.load_scene("intersection")
        >>> scene.bounds
        (-50.0, -50.0, 120.0, 50.0)
    """
    _require_value(isinstance(net, (str, _Path)), "net", net, "must be a scene name or a path, e.g. 'intersection'")
    return _boundary.as_scene(net)


def draw_scene(
    ax: _Any, scene: _Any, scan: "Scan | None" = None, estimates: "Estimates | StepResult | None" = None
) -> _Any:
    """Draw a scene on a matplotlib ``ax`` as the replay and ``soabench scene`` draw it: roads, sidewalks,
    crossings, buildings and doors, parked cars; with ``scan``, its visible sidewalk Ω_k, the sensor pose and the
    measurements Z_k in the world frame; with ``estimates``, a tracker's positions (and track labels). Returns ``ax``
    (metres, the legend under the map).

    Args:
        ax: a matplotlib Axes.
        scene: a scene from :func:`load_scene`, or a network name or path.
        scan: one :class:`Scan` (e.g. ``scans[k]`` of :func:`simulate_trial`).
        estimates: a tracker's output at that scan: one :class:`Estimates`, or the :class:`StepResult` of one of
            our filters.

    Example:
        >>> import matplotlib.pyplot as plt
        >>> import soabench.api as sb
        >>> recording, scans = sb.simulate_trial("arterial", duration=5)
        >>> fig, ax = plt.subplots(figsize=(10, 6))
        >>> sb.draw_scene(ax, sb.load_scene("arterial"), scan=scans[4]) is ax
        True
        >>> fig.savefig("scan4.png")  # doctest: +SKIP
    """
    from matplotlib.axes import Axes

    from soabench.figures.scene import plot_scene
    from soabench.figures.sensor import draw_scan

    _require_type(ax, Axes, "ax", "give a matplotlib Axes, e.g. from plt.subplots()")
    scene = _boundary.as_scene(scene)
    if scan is not None:
        _require_type(scan, Scan, "scan", "give one Scan, e.g. scans[k]")
    if estimates is not None:
        _require_type(
            estimates, (Estimates, StepResult), "estimates", "give one tracker output at that scan, e.g. results[k]"
        )
    plot_scene(scene, ax=ax)
    if scan is not None:
        draw_scan(ax, scan, estimates)
    return ax


def to_stonesoup(scans: Scans, sigma_r: float | None = None, sigma_b: float | None = None, gt_set: str = "fov") -> _Any:
    """Scans and truth as Stone Soup detections and ground-truth paths (``pip install "soabench[stonesoup]"``).

    The noise defaults to the scans' own sensor settings; the paths hold the truth set of our tables
    (``gt_set``: ``"fov"``, present and in the field of view, the default; ``"visible"``; ``"scene"``, every
    present walker; docs/method.md §5.1). See :func:`soabench.bridges.stonesoup.to_stonesoup`.

    Example:
        >>> import soabench.api as sb
        >>> _, scans = sb.simulate_trial("arterial", duration=5)
        >>> feed = sb.to_stonesoup(scans)
        >>> len(feed.detections) == len(scans)
        True
    """
    from soabench.bridges.stonesoup import to_stonesoup as _to

    return _to(scans, sigma_r, sigma_b, gt_set=gt_set)


def stonesoup_ospa(
    tracks: _Any, scans: Scans, c: float | None = None, p: float | None = None, gt_set: str = "fov"
) -> _Any:
    """Stone Soup's own OSPA per scan, on the sets our metrics score, to compare with ``evaluate(...).series["ospa"]``
    (``pip install "soabench[stonesoup]"``). See :func:`soabench.bridges.stonesoup.stonesoup_ospa`.

    Example:
        >>> import numpy as np
        >>> import soabench.api as sb
        >>> from stonesoup.types.state import State
        >>> from stonesoup.types.track import Track
        >>> _, scans = sb.simulate_trial("arterial", duration=5)
        >>> times = [t for t, _ in sb.to_stonesoup(scans)]  # the scans' timestamps, as a Stone Soup tracker sees them
        >>> tracks = [Track([State([1.0, 0.5, 2.0, -0.5], timestamp=t) for t in times], id="t1")]
        >>> theirs = sb.stonesoup_ospa(tracks, scans)
        >>> ours = sb.evaluate(scans, sb.from_stonesoup(tracks, scans).estimates).series["ospa"]
        >>> bool(np.allclose(theirs, ours))
        True
    """
    from soabench.bridges.stonesoup import stonesoup_ospa as _ospa

    return _ospa(tracks, scans, c, p, gt_set)


def from_stonesoup(tracks: _Any, scans: Scans) -> _Any:
    """Stone Soup tracks as one :class:`Estimates` per scan (states in our order) and their track ids:
    ``estimates, labels = from_stonesoup(tracks, scans)``. See :func:`soabench.bridges.stonesoup.from_stonesoup`.

    Example:
        >>> import soabench.api as sb
        >>> from stonesoup.types.state import State
        >>> from stonesoup.types.track import Track
        >>> _, scans = sb.simulate_trial("arterial", duration=5)
        >>> t2, _ = sb.to_stonesoup(scans).detections[2]  # scan 2's timestamp
        >>> track = Track([State([1.0, 0.5, 2.0, -0.5], timestamp=t2)], id="t7")
        >>> estimates, labels = sb.from_stonesoup([track], scans)
        >>> estimates[2].X.tolist(), labels[2].tolist()
        ([[1.0, 2.0, 0.5, -0.5]], ['t7'])
    """
    from soabench.bridges.stonesoup import from_stonesoup as _from

    return _from(tracks, scans)
