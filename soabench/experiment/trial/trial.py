"""One Monte Carlo trial: seed -> Recording -> Scans -> every (birth model x probability mode) filter -> metrics.

Common random numbers (docs/method.md §5.8, docs/development.md): one SUMO run per trial; per clutter rate lambda one
:class:`~soabench.types.Scans`, observed with freshly created sensor generators so detections and noise are identical
across lambda; every filter run of that lambda consumes the very same Scans, and every filter run re-creates the
placement generator, so all runs see the same birth-placement stream.

Work done once (docs/method.md §5.8): a birth model whose births read only the scan (class attribute
``mode_free = True``: S-OA, UBM, UBM (workspace), GMBM) is called once per scan for every probability mode (PUBM
and ATBM scale by p_D,b or read the previous step, so they run per mode). Such a model splits its births into
weight-free ``candidates(ctx)``, which read only the scan's geometry, and ``weigh(cfg, candidates)``, which applies
N_hat: the candidates of a scan are computed once for every clutter rate and N_hat of the trial. The sensor's
geometry of each scan (line of sight, O_k, Omega_k) is computed once for every lambda. A :class:`TrialShare`
carries the SUMO recording, the scans per sensor setting and the finished filter runs of one trial index across
the run folders of a study or sweep
(:mod:`soabench.experiment.execution.grouped`), so each is computed once.

The result is a :class:`TrialResult` of plain Python scalars (cheap to pickle, ready to be written as CSV rows).
Its schemas are the module constants :data:`ROW_KEYS`, :data:`EPISODE_KEYS`, :data:`STEP_KEYS`,
:data:`ESTIMATE_KEYS` and :data:`TIMING_KEYS`.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from soabench import plugins
from soabench import scenario as scenarios  # by attribute: a test may stand in for its simulate
from soabench.config import FAMILIES, FAMILY_MODES, FILTER_FAMILIES, filter_config_for_mode
from soabench.errors import require
from soabench.experiment.trial import guard, isolate
from soabench.experiment.trial.activity import OWN_CODE, note_activity
from soabench.experiment.trial.isolate import PluginFailed, private_scan
from soabench.metrics import SERIES_KEYS, SUMMARY_KEYS, TrialMetrics, evaluate
from soabench.origins import ORIGIN_KEYS
from soabench.protocols import TrackerSetup
from soabench.seeding import TrialSeeds, trial_seeds
from soabench.sensor import observe
from soabench.trackers import FilterTracker, ScanFailure, build_filter, run_tracker
from soabench.trackers import TrackerRun as FilterRun  # the step results and times of one run
from soabench.tracks.evaluate import GAP_KEYS, NO_GAP, TRACK_KEYS, run_labels, track_evaluation

if TYPE_CHECKING:
    from soabench.config import Config, SensorConfig
    from soabench.scenario.config import ScenarioConfig
    from soabench.scenario.scene import SceneMap
    from soabench.types import BirthContext, Recording, Scans, StepResult

#: identifying columns of a row
ROW_ID_KEYS = ("trial", "seed", "sumo_seed", "clutter", "N_hat", "model", "mode")
#: wall-clock columns of a row (seconds per filter run; the filter stages are sums over the K steps)
ROW_TIME_KEYS = ("t_birth", "t_predict", "t_update", "t_reduce", "t_metrics", "t_filter_total")
#: every column of a row, in order: ids, the metrics of :data:`soabench.metrics.SUMMARY_KEYS`, wall-clock times
ROW_KEYS = ROW_ID_KEYS + tuple(k for k in SUMMARY_KEYS if k not in ROW_TIME_KEYS) + ROW_TIME_KEYS + TRACK_KEYS
#: columns of an episode row (§5.4); k_t = -1 and delay = NaN when censored; then the gap before a re-emergence
#: episode (§9.4, empty for an entry episode)
EPISODE_KEYS = (
    "trial",
    "clutter",
    "model",
    "mode",
    "target",
    "k0",
    "k_end",
    "k_d",
    "k_t",
    "delay",
    "delay_lb",
    "censored",
    *GAP_KEYS,
)
#: columns of a step row (one per filter run and scan k): the run's keys, k, and the metrics' per-scan series
STEP_KEYS = ("trial", "clutter", "model", "mode", "k", *SERIES_KEYS)
#: columns of an estimate row (``save_estimates``): one per extracted estimate (with multiplicity)
ESTIMATE_KEYS = ("trial", "clutter", "model", "mode", "k", "x", "y", "w")
#: keys of :attr:`TrialResult.timing` (seconds per trial; "sensor" sums every clutter rate)
TIMING_KEYS = ("sumo", "sensor")

_INT_STEP_KEYS = frozenset({"n_gt", "n_est", "tp", "fp", "fn", "card_err", "n_components", *ORIGIN_KEYS})


@dataclass
class TrialResult:
    """Everything one trial produced, as lists of dicts of Python scalars (schemas: module constants)."""

    trial: int
    seed: int
    sumo_seed: int
    rows: list[dict[str, Any]] = field(default_factory=list)
    episodes: list[dict[str, Any]] = field(default_factory=list)
    steps: list[dict[str, Any]] = field(default_factory=list)
    timing: dict[str, float] = field(default_factory=dict)
    estimates: list[dict[str, Any]] | None = None
    #: runs of a plugin that failed (schema :data:`soabench.experiment.trial.guard.FAILURE_KEYS`); they have no rows
    failures: list[dict[str, Any]] = field(default_factory=list)


@dataclass(frozen=True)
class RunRecords:
    """What one finished filter run added to a :class:`TrialResult`: its row, episodes, steps and estimates."""

    row: dict[str, Any]
    episodes: list[dict[str, Any]]
    steps: list[dict[str, Any]]
    estimates: list[dict[str, Any]] | None


@dataclass(frozen=True)
class TableSizes:
    """The length of each table of a :class:`TrialResult` at one moment: a run's records are what follows."""

    rows: int
    episodes: int
    steps: int
    estimates: int
    failures: int

    @classmethod
    def of(cls, out: TrialResult) -> TableSizes:
        return cls(len(out.rows), len(out.episodes), len(out.steps), len(out.estimates or ()), len(out.failures))

    def one_run_since(self, out: TrialResult) -> RunRecords | None:
        """The records of the one run that finished since (one row, no failure), else None."""
        if len(out.failures) != self.failures or len(out.rows) != self.rows + 1:
            return None
        estimates = None if out.estimates is None else out.estimates[self.estimates :]
        return RunRecords(out.rows[self.rows], out.episodes[self.episodes :], out.steps[self.steps :], estimates)


#: the column naming a run's filter family (docs/method.md "LMB filter"); written only by runs whose
#: ``experiment.filters`` is not the default ``("gmphd",)``, as the last column of every table
FILTER_COLUMN = "filter"


@dataclass(frozen=True)
class RunKey:
    """Identity of one filter run inside a trial; ``family``: its filter family when the run names families
    (``experiment.filters`` not the default), else None (no ``filter`` column)."""

    trial: int
    clutter: float
    model: str
    mode: str
    family: str | None = None

    def as_dict(self) -> dict[str, Any]:
        d = {"trial": self.trial, "clutter": self.clutter, "model": self.model, "mode": self.mode}
        if self.family is not None:
            d[FILTER_COLUMN] = self.family
        return d


@dataclass
class TrialShare:
    """Work of one trial index shared by several configs (the run folders of a study or a sweep).

    A config's trial reads the recording, the scans and the finished filter runs from here when an earlier config
    of the same trial index computed them with identical inputs; the keys hold every input the value depends on
    (seed, trial, duration; the sensor setting; the full config except ``experiment``), so a hit is bit-identical
    to recomputing it (common random numbers, :mod:`soabench.seeding`).
    """

    recordings: dict[tuple, Any] = field(default_factory=dict)
    scans: dict[tuple, Any] = field(default_factory=dict)
    #: recording key -> the sensor's lambda-independent geometry of every scan (``soabench.sensor.observe``)
    geometry: dict[tuple, dict] = field(default_factory=dict)
    #: run key -> (row, episodes, steps, estimates) of a finished built-in (model x mode) run
    runs: dict[tuple, RunRecords] = field(default_factory=dict)
    #: keep every finished filter run (its step results) so a config with the same filter run (one that differs
    #: only in ``metrics`` or in the families it names) scores it again instead of re-running the filter (set by a
    #: group with such folders, :func:`soabench.experiment.execution.grouped.rescored`)
    keep_filter_runs: bool = False
    #: filter key (the run key with the config of :func:`filter_config_key`) -> the finished filter run
    #: (``keep_filter_runs``)
    filter_runs: dict[tuple, Any] = field(default_factory=dict)
    #: births key (the scans' geometry, the birth config but N_hat, the model) -> scan index -> the weight-free birth
    #: candidates of a mode-free model (``candidates``/``weigh``): one set for every clutter rate and N_hat
    birth_candidates: dict[tuple, dict[int, Any]] = field(default_factory=dict)
    #: what was computed and what was reused (recording, scans, runs), for tests and benchmarks
    counts: dict[str, int] = field(default_factory=dict)

    def count(self, what: str) -> None:
        self.counts[what] = self.counts.get(what, 0) + 1


class _BirthsOnce:
    """A mode-free birth model called once per scan; every probability mode's run reads the same births.

    The model is built on the first call that needs it (a lambda whose runs all come from a :class:`TrialShare`
    builds none). With ``candidates`` (scan index -> weight-free candidates, shared through
    :attr:`TrialShare.birth_candidates`), a model that splits its births into ``candidates(ctx)`` and the static
    ``weigh(cfg, candidates)`` computes the candidates of a scan once for every clutter rate and N_hat of the trial
    and only weighs them here with this config's N_hat; the result equals ``model(ctx)`` bit for bit.
    """

    def __init__(
        self,
        build: Callable[[], Callable[[BirthContext], Any]],
        weigh: Callable[[Any], Any] | None = None,
        candidates: dict[int, Any] | None = None,
        count: Callable[[str], None] | None = None,
    ) -> None:
        self.build = build
        self.model: Callable[[BirthContext], Any] | None = None
        #: (weigh, the shared candidates) when both are given, else None: the model is called for each scan
        self.shared = (weigh, candidates) if weigh is not None and candidates is not None else None
        self.count = count or (lambda what: None)
        self._births: dict[int, Any] = {}
        self._scans: list[Any] = []  # keeps the scans alive: ids are unique while they are held

    def _model(self) -> Any:
        if self.model is None:
            self.model = self.build()
        return self.model

    def __call__(self, ctx: BirthContext) -> Any:
        key = id(ctx.scan)
        if key not in self._births:
            if self.shared is not None:
                weigh, candidates = self.shared
                k = int(ctx.scan.k)
                c = candidates.get(k)
                if c is None:
                    c = candidates[k] = self._model().candidates(ctx)
                    self.count("birth_candidates")
                else:
                    self.count("birth_candidates_reused")
                self._births[key] = weigh(c)
            else:
                self._births[key] = self._model()(ctx)
            self._scans.append(ctx.scan)
        return self._births[key]


def _config_key(config: Config | dict, without: tuple[str, ...] = ()) -> str:
    """Every config section a run depends on (all but ``experiment`` and ``without``), as canonical text.

    A filter run does not read ``metrics`` (only its scoring does, :func:`soabench.metrics.evaluate`), so
    ``without=("metrics",)`` keys the filter run alone.
    """
    d = dict(config if isinstance(config, dict) else config.to_dict())
    for section in ("experiment", *without):
        d.pop(section, None)
    return json.dumps(d, sort_keys=True, default=repr)


def filter_config_key(config: Config | dict, family: str) -> str:
    """The config sections a filter run of ``family`` reads, as canonical text: all but ``experiment``, ``metrics``
    and the other families' sections (:data:`soabench.config.FAMILIES`). A GM-PHD run of a folder that names
    several families and one of a default-family folder (whose config leaves the families' sections out) get the
    same key when their shared sections agree: they are the same filter run."""
    others = {f.section for f in FAMILIES.values() if f.section is not None} - {FAMILIES[family].section}
    return _config_key(config, without=("metrics", *sorted(others)))


# ---------------------------------------------------------------------------------------------------------------------
# one filter run


def run_filter(
    scans: Scans,
    birth_model: Callable[[BirthContext], Any],
    filt: Any,
    p_D_b: float,
) -> FilterRun:
    """Run the filter cycle (§2.11) over every scan: birth from the context at k, then ``filt.step``."""

    return run_tracker(scans, FilterTracker(birth_model, filt, p_D_b))


# ---------------------------------------------------------------------------------------------------------------------
# rows


def _scalar(v: Any) -> Any:
    """A Python scalar (numpy ints, floats and bools converted)."""
    return v.item() if hasattr(v, "item") else v


def make_row(
    key: RunKey,
    seeds: TrialSeeds,
    N_hat: float,
    metrics: TrialMetrics,
    run: FilterRun,
    t_metrics: float,
    tracks: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """One row of :data:`ROW_KEYS` for a filter run; ``tracks``: its track columns (:func:`evaluate_tracks`; None:
    every track column empty)."""
    row: dict[str, Any] = {
        "trial": key.trial,
        "seed": seeds.base_seed,
        "sumo_seed": seeds.sumo_seed,
        "clutter": key.clutter,
        "N_hat": float(N_hat),
        "model": key.model,
        "mode": key.mode,
    }
    row.update({k: _scalar(v) for k, v in metrics.summary.items()})
    row.update({"t_birth": run.t_birth, "t_metrics": t_metrics, "t_filter_total": run.t_total})
    row.update(tracks or dict.fromkeys(TRACK_KEYS))
    out = {k: row[k] for k in ROW_KEYS}
    if key.family is not None:
        out[FILTER_COLUMN] = key.family
    return out


def episode_rows(
    key: RunKey, metrics: TrialMetrics, gaps: Sequence[dict[str, Any]] | None = None
) -> list[dict[str, Any]]:
    """One row of :data:`EPISODE_KEYS` per delay episode; ``gaps``: each episode's :data:`GAP_KEYS` cells
    (:func:`~soabench.tracks.evaluate.track_evaluation`; None: :data:`~soabench.tracks.evaluate.NO_GAP`)."""
    base = key.as_dict()
    head = {k: _scalar(base[k]) for k in EPISODE_KEYS if k in base}
    own = [k for k in EPISODE_KEYS if k not in base and k not in GAP_KEYS]  # the Episode's fields, read as they are
    tail = {FILTER_COLUMN: base[FILTER_COLUMN]} if FILTER_COLUMN in base else {}
    gaps = gaps if gaps is not None else [NO_GAP] * len(metrics.episodes)
    return [
        {**head, **{k: _scalar(getattr(e, k)) for k in own}, **{k: _scalar(g[k]) for k in GAP_KEYS}, **tail}
        for e, g in zip(metrics.episodes, gaps, strict=True)
    ]


def step_rows(key: RunKey, metrics: TrialMetrics) -> list[dict[str, Any]]:
    """One row of :data:`STEP_KEYS` per scan k."""
    base = key.as_dict()
    K = len(metrics.series["n_gt"]) if metrics.series else 0
    names = STEP_KEYS[5:]
    tail = {FILTER_COLUMN: base.pop(FILTER_COLUMN)} if FILTER_COLUMN in base else {}
    # each series as a list of Python ints or floats (tolist() of a cast array: the values int() / float() give)
    cols = [
        [int(v) for v in metrics.series[c].tolist()] if c in _INT_STEP_KEYS else _float_list(metrics.series[c])
        for c in names
    ]
    keys = ("k", *names)
    return [{**base, **dict(zip(keys, vals, strict=True)), **tail} for vals in zip(range(K), *cols, strict=False)]


def _float_list(series: Any) -> list[float]:
    """The series' values as Python floats, as ``float(v)`` of each element gives them."""
    a = np.asarray(series)
    if a.dtype == np.float64:
        return a.tolist()
    return [float(v) for v in a.tolist()]


def estimate_rows(key: RunKey, results: Sequence[StepResult]) -> list[dict[str, Any]]:
    """One row of :data:`ESTIMATE_KEYS` per extracted estimate (unrestricted, with multiplicity)."""
    base = key.as_dict()
    tail = {FILTER_COLUMN: base.pop(FILTER_COLUMN)} if FILTER_COLUMN in base else {}
    rows = []
    for k, res in enumerate(results):
        w = list(res.X_w) if len(res.X_w) == len(res.X) else [float("nan")] * len(res.X)
        for (x, y), wi in zip(res.X[:, :2].tolist(), w, strict=True):
            rows.append({**base, "k": k, "x": x, "y": y, "w": float(wi), **tail})
    return rows


# ---------------------------------------------------------------------------------------------------------------------
# the trial


def _default_simulate() -> Callable[..., Recording]:
    return scenarios.simulate


def _default_observe() -> Callable[..., Scans]:

    return observe


def _default_birth_factory() -> Callable[[str], type]:

    return lambda name: plugins.resolve(plugins.BIRTH, name)


def run_trial(
    trial: int,
    config: Config,
    scene: SceneMap,
    scenario: ScenarioConfig,
    *,
    save_estimates: bool = False,
    simulate_fn: Callable[..., Recording] | None = None,
    observe_fn: Callable[..., Scans] | None = None,
    filter_cls: type | None = None,
    birth_factory: Callable[[str], type] | None = None,
    share: TrialShare | None = None,
    births_once: bool = True,
) -> TrialResult:
    """Trial ``trial`` of the protocol (§5.8) with ``config.experiment`` models, probabilities, clutter, seed, duration.

    One SUMO run (``simulate_fn(scene, scenario, seeds, duration=...)``); per clutter rate one
    ``observe_fn(recording, scene, sensor_cfg, seeds.sensor_rngs())``; per (model, mode) a fresh birth model
    ``birth_factory(model)(birth_cfg, sensor_cfg, scene, seeds.placement_rng())`` and a fresh filter of each
    family of ``experiment.filters`` (:func:`soabench.trackers.build_filter`), then
    :func:`soabench.metrics.evaluate`. The keyword-only callables default to the real pipeline; tests inject fakes
    through them (``filter_cls(filter_cfg, sensor_cfg, mode)`` replaces the default family's filter).

    ``births_once``: a mode-free birth model is called once per scan for every probability mode (module docstring);
    False builds one per (model, mode) as before (the results are the same; tests compare both). ``share``: a
    :class:`TrialShare` to read and fill (the runs of a study or sweep); None computes everything here.
    """
    require(isinstance(trial, int) and trial >= 0, f"trial = {trial!r} must be an integer >= 0")
    seeds = trial_seeds(config.experiment.seed, trial)
    fns = _Pipeline.of(simulate_fn, observe_fn, filter_cls, birth_factory)
    out = TrialResult(trial, seeds.base_seed, seeds.sumo_seed, estimates=[] if save_estimates else None)
    share = share if share is not None else TrialShare()
    steps = _TrialSteps(trial, config, scene, scenario, seeds, fns, share, out, save_estimates)
    recorded = steps.record()
    for lam in config.experiment.clutter:
        observed = steps.observe(recorded, lam)
        for model in config.experiment.models:
            steps.run_model(model, observed, births_once)
        steps.run_trackers(observed)
    return out


@dataclass(frozen=True)
class _Pipeline:
    """The stages of a trial: the real pipeline's, or the fakes a test injects; ``key`` names them in the share
    keys (the defaults are one key whatever object builds them)."""

    simulate: Callable[..., Recording]
    observe: Callable[..., Scans]
    filter_cls: type | None
    birth_factory: Callable[[str], type]
    key: tuple

    @classmethod
    def of(cls, simulate_fn: Any, observe_fn: Any, filter_cls: Any, birth_factory: Any) -> _Pipeline:
        key = tuple("default" if f is None else f for f in (simulate_fn, observe_fn, filter_cls, birth_factory))
        return cls(simulate_fn or _default_simulate(), observe_fn or _default_observe(), filter_cls,
                   birth_factory or _default_birth_factory(), key)  # fmt: skip

    @property
    def real_sensor(self) -> bool:
        return self.key[1] == "default"


@dataclass(frozen=True)
class _Recorded:
    """The SUMO recording of a trial and its key in the :class:`TrialShare`."""

    recording: Recording
    key: tuple


@dataclass(frozen=True)
class _Observed:
    """The scans of one clutter rate, with the keys their filter runs and birth candidates are shared under."""

    lam: float
    sensor_cfg: Any
    scans: Scans
    key: tuple
    candidates_key: tuple


@dataclass
class _TrialSteps:
    """The named steps of :func:`run_trial`: the recording, the scans per clutter rate, each birth model's filter
    runs in every probability mode and family, the whole trackers; each reads the :class:`TrialShare` first and
    appends its rows to ``out``."""

    trial: int
    config: Config
    scene: SceneMap
    scenario: ScenarioConfig
    seeds: TrialSeeds
    fns: _Pipeline
    share: TrialShare
    out: TrialResult
    save_estimates: bool

    def __post_init__(self) -> None:
        self.cfg_key = _config_key(self.config)
        self.filter_cfg_keys = {f: filter_config_key(self.config, f) for f in self.config.experiment.filters}
        self.birth_key = _birth_key(self.config)

    def record(self) -> _Recorded:
        """One SUMO run per trial (or the share's)."""
        exp, share = self.config.experiment, self.share
        key = (
            self.seeds.base_seed,
            self.trial,
            float(exp.duration),
            id(self.scene),
            id(self.scenario),
            self.fns.key[0],
        )
        t0 = time.perf_counter()
        if key in share.recordings:
            recording = share.recordings[key]
            share.count("recording_reused")
        else:
            recording = share.recordings[key] = self.fns.simulate(self.scene, self.scenario, self.seeds,
                                                                  duration=exp.duration)  # fmt: skip
            share.count("recording")
        self.out.timing["sumo"] = time.perf_counter() - t0
        self.out.timing["sensor"] = 0.0
        return _Recorded(recording, key)

    def observe(self, recorded: _Recorded, lam: float) -> _Observed:
        """The scans at clutter rate ``lam`` (or the share's); the real sensor computes its geometry once for every
        lambda."""
        share, seeds = self.share, self.seeds
        sensor_cfg = self.config.sensor_at(lam)
        key = (recorded.key, repr(sensor_cfg), self.fns.key[1])
        t0 = time.perf_counter()
        if key in share.scans:
            scans = share.scans[key]
            share.count("scans_reused")
        else:
            if self.fns.real_sensor:
                geometry = share.geometry.setdefault(recorded.key, {})
                scans = self.fns.observe(recorded.recording, self.scene, sensor_cfg, seeds.sensor_rngs(),
                                         geometry=geometry)  # fmt: skip
            else:
                scans = self.fns.observe(recorded.recording, self.scene, sensor_cfg, seeds.sensor_rngs())
            share.scans[key] = scans
            share.count("scans")
        self.out.timing["sensor"] += time.perf_counter() - t0
        # the sensor's geometry is the same for every lambda when the real sensor observed the scans
        candidates_key = (recorded.key, repr(sensor_cfg.settings)) if self.fns.real_sensor else key
        return _Observed(float(lam), sensor_cfg, scans, key, candidates_key)

    def run_model(self, model: str, observed: _Observed, births_once: bool) -> None:
        """Birth model ``model`` in every probability mode and filter family (its births once for every mode when
        ``births_once`` and the model's births read only the scan)."""
        births = None
        if births_once:
            births_key = (observed.candidates_key, self.birth_key, model, self.fns.key[3])
            candidates = self.share.birth_candidates.setdefault(births_key, {})
            births = _births_once(model, self.config, observed.sensor_cfg, self.scene, self.seeds,
                                  self.fns.birth_factory, candidates, self.share.count)  # fmt: skip
        exp = self.config.experiment
        for mode, family in family_runs(exp.probabilities, exp.filters):
            self.run_filter(RunKey(self.trial, observed.lam, model, mode, family), observed, births)

    def run_filter(self, key: RunKey, observed: _Observed, births: _BirthsOnce | None) -> None:
        """One (model, mode, family) filter run: replayed from the share, scored again from a kept filter run (the
        same filter run in a config that differs in ``metrics`` or in the families it names,
        :func:`filter_config_key`), or run; a finished built-in run is kept for reuse."""
        share, out, fn_key = self.share, self.out, self.fns.key
        run_key = (observed.key, self.cfg_key, key.model, key.mode, key.family, self.save_estimates, *fn_key[2:])
        cached = share.runs.get(run_key)
        if cached is not None:
            _replay(cached, out)
            share.count("runs_reused")
            return
        before = TableSizes.of(out)
        family = key.family or FILTER_FAMILIES[0]  # named or not, the default family's run is the same filter run
        filter_key = (observed.key, self.filter_cfg_keys[family], key.model, key.mode, family, *fn_key[2:])
        kept = share.filter_runs.get(filter_key)
        if kept is not None:  # the same filter run under another run key (metrics, families named): score it only
            _record(key, self.config, observed.sensor_cfg, observed.scans, self.seeds, kept, out)
            share.count("runs_rescored")
        else:
            run = self.run_one(key, observed, births)
            share.count("runs")
            if share.keep_filter_runs and run is not None:
                share.filter_runs[filter_key] = run
        finished = before.one_run_since(out)
        if finished is not None:  # a finished built-in run: reusable
            share.runs[run_key] = finished

    def run_one(self, key: RunKey, observed: _Observed, births: _BirthsOnce | None = None) -> FilterRun | None:
        """One (model x mode) filter run on the scans; appends its row, episodes, steps (and estimates) to ``out``.

        ``births``: the model's births shared by every probability mode (:func:`_births_once`); None builds the
        model. Returns the finished run of a built-in model (a study may score it again,
        :attr:`TrialShare.filter_runs`), None for a plugin's.

        A built-in birth model runs unguarded (an exception fails the trial: a bug of soabench). A plugin is checked
        at every scan (:mod:`soabench.experiment.trial.guard`); if it fails, the run is recorded in ``out.failures``
        and the trial goes on with the other runs.
        """
        config, sensor_cfg, scans, seeds, out = self.config, observed.sensor_cfg, observed.scans, self.seeds, self.out
        birth_factory, filter_cls = self.fns.birth_factory, self.fns.filter_cls
        if plugins.is_builtin_birth(key.model):
            birth_model = (
                births
                if births is not None
                else birth_factory(key.model)(config.birth, sensor_cfg, self.scene, seeds.placement_rng())
            )
            filt, p_D_b = _filter(key, config, sensor_cfg, seeds, filter_cls)
            run = run_tracker(scans, FilterTracker(birth_model, filt, p_D_b))
            _record(key, config, sensor_cfg, scans, seeds, run, out)
            return run

        def build() -> FilterTracker:
            cls = birth_factory(key.model)
            options = config.plugins.get(key.model, {})
            own_cfg, own_sensor = dataclasses.replace(config.birth), dataclasses.replace(sensor_cfg)
            birth_model = cls(own_cfg, own_sensor, self.scene, seeds.placement_rng(), **options)
            filt, p_D_b = _filter(key, config, sensor_cfg, seeds, filter_cls)
            return FilterTracker(_PrivateScans(birth_model), filt, p_D_b, check_births=guard.check_births)

        run = _guarded(key, plugins.BIRTH, build, scans, guard.check_estimates, out, config.experiment.plugin_budget)
        if run is not None:
            _record(key, config, sensor_cfg, scans, seeds, run, out)
        return None

    def run_trackers(self, observed: _Observed) -> None:
        """Every whole tracker of ``experiment.trackers`` in every probability mode."""
        for tracker in self.config.experiment.trackers:
            for mode in self.config.experiment.probabilities:
                key = RunKey(self.trial, observed.lam, tracker, mode)
                _run_one_tracker(
                    key, self.config, observed.sensor_cfg, self.scene, observed.scans, self.seeds, self.out
                )


def family_runs(modes: Sequence[str], families: Sequence[str]) -> list[tuple[str, str | None]]:
    """The (probability mode, filter family) of each run of a birth model, mode by mode and family by family in the
    config's orders; a family runs only the modes it supports (:data:`soabench.config.FAMILY_MODES`: the LMB runs
    static probabilities only; its other cells read "—"). The family is None for the default families
    (``("gmphd",)``): such a run writes no ``filter`` column."""
    if tuple(families) == FILTER_FAMILIES[:1]:
        return [(mode, None) for mode in modes]
    return [(mode, fam) for mode in modes for fam in families if mode in FAMILY_MODES[fam]]


def _births_once(
    model: str,
    config: Config,
    sensor_cfg: SensorConfig,
    scene: SceneMap,
    seeds: TrialSeeds,
    birth_factory: Callable[[str], type],
    candidates: dict[int, Any] | None = None,
    count: Callable[[str], None] | None = None,
) -> _BirthsOnce | None:
    """One birth model for every probability mode of a lambda, if it is a built-in whose births read only the scan.

    It gets a fresh placement generator like every per-mode model would (:mod:`soabench.seeding`), so its births
    are those each mode's own model would draw. ``candidates``: the trial's shared weight-free candidates of this
    model (:attr:`TrialShare.birth_candidates`), used if the class has ``candidates`` and ``weigh``.
    """

    if not plugins.is_builtin_birth(model):
        return None
    cls = birth_factory(model)
    if not getattr(cls, "mode_free", False):
        return None
    weigh = None
    if callable(getattr(cls, "candidates", None)) and callable(getattr(cls, "weigh", None)):
        weigh = functools.partial(cls.weigh, config.birth)
    return _BirthsOnce(lambda: cls(config.birth, sensor_cfg, scene, seeds.placement_rng()), weigh, candidates, count)


def _birth_key(config: Config) -> str:
    """The birth config as canonical text without ``N_hat`` (weight-free candidates do not read it)."""
    d = dict(config.to_dict()["birth"])
    d.pop("N_hat", None)
    return json.dumps(d, sort_keys=True, default=repr)


def _replay(cached: RunRecords, out: TrialResult) -> None:
    """Append a finished run's row, episodes, steps (and estimates) from a :class:`TrialShare` to ``out``."""
    out.rows.append(dict(cached.row))
    out.episodes.extend(dict(e) for e in cached.episodes)
    out.steps.extend(dict(s) for s in cached.steps)
    if out.estimates is not None and cached.estimates is not None:
        out.estimates.extend(dict(e) for e in cached.estimates)


def _filter(
    key: RunKey, config: Config, sensor_cfg: SensorConfig, seeds: TrialSeeds, filter_cls: type | None
) -> tuple[Any, float]:
    """The run's filter of its family (the default family when the run names none) and p_D_b; an injected
    ``filter_cls`` (tests) replaces the default family's filter."""
    family = key.family or FILTER_FAMILIES[0]
    if filter_cls is not None and family == FILTER_FAMILIES[0]:
        filter_cfg, filter_mode, p_D_b = filter_config_for_mode(config.filter, key.mode)
        return filter_cls(filter_cfg, sensor_cfg, filter_mode), p_D_b
    return build_filter(family, config, sensor_cfg, key.mode, seeds.association_rng())


class _PrivateScans:
    """A plugin birth model that reads a private copy of each scan
    (:func:`soabench.experiment.trial.isolate.private_scan`);
    the filter around it reads the scan itself."""

    def __init__(self, model: Callable[[BirthContext], Any]) -> None:
        self.model = model

    def __call__(self, ctx: BirthContext) -> Any:

        return self.model(dataclasses.replace(ctx, scan=private_scan(ctx.scan)))


class _Isolated:
    """A guarded run's tracker whose every step runs through ``calls`` (:class:`~soabench.experiment.trial.isolate.
    PluginCalls`); ``private``: hand it a private copy of each scan (a plugin tracker; a plugin birth model inside our
    GM-PHD gets its copy from :class:`_PrivateScans`)."""

    def __init__(self, tracker: Any, calls: Any, private: bool) -> None:
        self.tracker, self.calls, self.private = tracker, calls, private

    @property
    def t_birth(self) -> float:
        return float(getattr(self.tracker, "t_birth", 0.0))

    def step(self, scan: Any) -> Any:

        try:
            return self.calls(self.tracker.step, private_scan(scan) if self.private else scan)
        except PluginFailed as exc:
            raise ScanFailure(scan.k, exc.message, exc.traceback) from None


def _run_one_tracker(
    key: RunKey,
    config: Config,
    sensor_cfg: SensorConfig,
    scene: SceneMap,
    scans: Scans,
    seeds: TrialSeeds,
    out: TrialResult,
) -> None:
    """One (tracker x mode) run on ``scans``, guarded like a plugin birth model (:meth:`_TrialSteps.run_one`)."""

    def build() -> Any:
        cls = plugins.resolve(plugins.TRACKER, key.model)
        own = copy.deepcopy(config)  # the plugin's own: nothing it changes reaches another run
        setup = TrackerSetup(dataclasses.replace(sensor_cfg), scene, seeds.placement_rng(), key.mode, own)
        return cls(setup, **own.plugins.get(key.model, {}))

    run = _guarded(key, plugins.TRACKER, build, scans, guard.check_estimates, out, config.experiment.plugin_budget)
    if run is not None:
        _record(key, config, sensor_cfg, scans, seeds, run, out)


def _guarded(
    key: RunKey,
    kind: str,
    build: Callable[[], Any],
    scans: Scans,
    check: Callable[..., Any],
    out: TrialResult,
    budget: float,
) -> Any:
    """Build and run a plugin through :class:`~soabench.experiment.trial.isolate.PluginCalls` (its own thread,
    ``budget``
    seconds per call, a private copy of each scan); on failure append a failure record (with the plugin's traceback)
    to ``out`` and return None."""

    k: int | None = None
    note_activity(key.trial, f"{kind} plugin {key.model!r} (clutter {key.clutter:g}, mode {key.mode})")
    try:
        where = f"trial {key.trial}, clutter {key.clutter:g}, mode {key.mode}"
        with isolate.PluginCalls(budget, f"{kind} {key.model!r}", where) as calls:
            tracker = calls(build)
            return run_tracker(scans, _Isolated(tracker, calls, private=kind == plugins.TRACKER), check)
    except isolate.PluginFailed as exc:  # in its constructor
        error, tb = exc.message, exc.traceback
    except ScanFailure as exc:
        k, error, tb = exc.k, exc.message, exc.traceback
    finally:
        note_activity(key.trial, OWN_CODE)
    out.failures.append(guard.failure_row(key.trial, key.clutter, key.model, key.mode, kind, k, error, tb))
    return None


def _record(
    key: RunKey,
    config: Config,
    sensor_cfg: SensorConfig,
    scans: Scans,
    seeds: TrialSeeds,
    run: Any,
    out: TrialResult,
) -> None:
    """Evaluate a finished run and append its row, episodes, steps (and estimates) to ``out``."""
    t0 = time.perf_counter()
    metrics = evaluate(scans, run.results, config.metrics, sensor_cfg)
    t_metrics = time.perf_counter() - t0
    X = [r.X for r in run.results]
    labels = run_labels(run.results, X)
    tracks, gaps = track_evaluation(scans, X, labels, metrics.episodes, config.metrics, sensor_cfg, metrics.partner)
    out.rows.append(make_row(key, seeds, config.birth.N_hat, metrics, run, t_metrics, tracks))
    out.episodes.extend(episode_rows(key, metrics, gaps))
    out.steps.extend(step_rows(key, metrics))
    if out.estimates is not None:
        out.estimates.extend(estimate_rows(key, run.results))
