"""The Monte Carlo harness: trials on process workers or Dask, persisted per trial, resumable (docs/method.md §5.8).

``execute`` runs trials ``0 .. trials-1`` of a config; trial n's seeds depend only on ``(seed, n)``
(:mod:`soabench.seeding`), never on the worker or the order, so serial, process-pool and Dask runs write
bit-identical ``trials.csv``/``episodes.csv``/``steps.csv``. libsumo is a process singleton (docs/user-guide/sumo.md):
every executor runs one trial at a time per process (a lock guards a worker that was started with several threads).

Executors: ``workers=1`` runs in this process; ``workers=N`` a ``ProcessPoolExecutor`` of N processes; ``scheduler``
an existing Dask scheduler; ``dask_local`` a Dask ``LocalCluster(processes=True, threads_per_worker=1)``.
Each worker process loads the scene once (a per-process cache). Results are written by this (driver) process, one
atomic file per finished trial (:mod:`soabench.experiment.runs.store`), so workers need no shared file system.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import socket
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from soabench import plugins
from soabench.atomic import to_jsonable, write_json_atomic
from soabench.config import Config
from soabench.errors import Interrupted, require
from soabench.experiment.execution.executors import failure_record, open_executor
from soabench.experiment.execution.options import RUN_DEFAULTS, RunOptions
from soabench.experiment.execution.progress import Progress
from soabench.experiment.runs.files import pack_table
from soabench.experiment.runs.provenance import REPRODUCTION_TOLERANCE, package_versions, platform_info
from soabench.experiment.runs.runmeta import RunMeta, check_requested, validate_run_meta
from soabench.experiment.runs.store import (
    EPISODE_COLUMNS,
    RUN_FILE,
    STEP_COLUMNS,
    TIMING_COLUMNS,
    TRIAL_COLUMNS,
    RunStore,
)
from soabench.experiment.trial import registry
from soabench.experiment.trial.activity import OWN_CODE, note_activity
from soabench.experiment.trial.guard import failure_message
from soabench.folders import FolderLock, check_existing_folder, check_new_folder, resolve
from soabench.kernel_warmup import ensure_compiled
from soabench.scenario.derive import said_by_the_driver
from soabench.seeding import trial_seeds

TrialFn = Callable[..., Any]
LoadFn = Callable[..., Any]


# ------------------------------------------------------------------------------------------------ outcome
@dataclass
class RunOutcome:
    """What a run (or a resumed run) ended with.

    ``complete`` is True when every trial has a result. When every trial was attempted but some failed, the
    CSV files, summary and figures cover the successful trials and list the failures, ``complete`` is False and
    ``n_missing`` counts the failed trials (``--resume`` retries them). When trials were never attempted
    (``--fail-fast``) no CSV or summary is written. Ctrl-C (at any stage, the report included) raises
    :class:`~soabench.errors.Interrupted`, a ``KeyboardInterrupt`` whose message says how to resume; the trials
    finished so far stay on disk.
    """

    run_dir: Path
    complete: bool
    n_done: int
    n_missing: int
    failures: list[dict] = field(default_factory=list)
    summary_markdown: str = ""
    #: failed method runs inside finished trials (:mod:`soabench.experiment.runs.failures`), once every trial was
    #: attempted
    model_failures: list[dict] = field(default_factory=list)
    #: the run to report, once every trial was attempted (None otherwise, and once reported): the layer above writes
    #: its summary, figures and report.html (:func:`soabench.experiment.reports.finished.report_run`)
    finished: FinishedRun | None = None


@dataclass(frozen=True)
class FinishedRun:
    """A run folder whose every trial was attempted, with what its report needs: the folder's store, the run's
    configuration, whether figures are drawn, and where (``workers`` local processes, None for one per core;
    ``executor``: the campaign's open executor, whose process pool draws them when it is one)."""

    store: RunStore
    config: Config
    figures: bool
    workers: int | None
    executor: Any = None


# ------------------------------------------------------------------------------------------------ one trial
@dataclass(frozen=True)
class TaskSpec:
    """Everything a worker needs to run any trial of a run (small and picklable): the run's record (what its
    ``run.json`` says, :class:`~soabench.experiment.runs.runmeta.RunMeta`) and the trial kind and scene loader it
    names, as callables."""

    meta: RunMeta
    trial_fn: TrialFn | None = None
    load_fn: LoadFn | None = None
    #: import paths of plugins typed on the driver's command line (soabench.plugins: the closed list)
    plugin_paths: tuple[str, ...] = ()

    @functools.cached_property
    def config(self) -> dict:
        """The run's configuration as plain data (each worker builds its :class:`Config` from it)."""
        return self.meta.config.to_dict()

    @property
    def base_seed(self) -> int:
        """``experiment.seed`` of the run (a failure record's seed)."""
        return int(self.meta.config.experiment.seed)

    @property
    def task_fn(self) -> Callable[[int, TaskSpec], dict]:
        """What an executor runs per trial (:mod:`soabench.experiment.execution.executors`)."""
        return run_trial_task


_SUMO_LOCK = threading.Lock()


def _default_trial_fn() -> TrialFn:
    return registry.trial_kind(registry.DEFAULT_TRIAL_KIND)


def uses_kernels(spec: TaskSpec) -> bool:
    """True when the trials of ``spec`` are soabench's own (which run the compiled kernels; another trial kind
    may not)."""
    return spec.trial_fn is None or spec.trial_fn is _default_trial_fn()


def _where() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def run_trial_task(trial: int, spec: TaskSpec) -> dict:
    """Run one trial in this process and return its record; an exception becomes a failure record."""
    base_seed = spec.base_seed
    t0 = time.perf_counter()
    note_activity(trial, OWN_CODE)
    try:
        with _SUMO_LOCK:
            plugins.allow_import_paths(spec.plugin_paths)
            config = Config.from_dict(spec.config)
            with said_by_the_driver():  # the driver loaded this scene and said what it derived
                scene, scenario = registry.load_scene_cached(spec.meta.net, spec.meta.polys, spec.meta.scenario,
                                                             spec.load_fn)  # fmt: skip
            fn = spec.trial_fn or _default_trial_fn()
            result = fn(trial, config, scene, scenario, save_estimates=spec.meta.save_estimates)
    except Exception as exc:  # a failed trial must not stop the run
        rec = failure_record(trial, base_seed, f"{type(exc).__name__}: {exc}", traceback.format_exc())
        rec["worker"] = _where()
        return rec
    seeds = trial_seeds(base_seed, trial)
    record = {
        "trial": int(trial),
        "status": "ok",
        "seed": base_seed,
        "sumo_seed": int(seeds.sumo_seed),
        "rows": pack_table(result.rows, TRIAL_COLUMNS + TIMING_COLUMNS),
        "episodes": pack_table(result.episodes, EPISODE_COLUMNS),
        "steps": pack_table(result.steps, STEP_COLUMNS),
        "timing": to_jsonable(dict(getattr(result, "timing", {}) or {})),
        "worker": _where(),
        "elapsed": time.perf_counter() - t0,
    }
    if getattr(result, "failures", None):
        record["model_failures"] = to_jsonable(result.failures)
    est = getattr(result, "estimates", None)
    if spec.meta.save_estimates and est is not None:
        record["estimates"] = to_jsonable(est)
    return record


class TodoTrials:
    """Trials ``0 .. n-1`` without an ok record, generated lazily (no list of a huge count is built)."""

    def __init__(self, n_trials: int, done: set[int]):
        self.n_trials = int(n_trials)
        self.done = {t for t in done if 0 <= t < n_trials}

    def __len__(self) -> int:
        return self.n_trials - len(self.done)

    def __iter__(self) -> Iterator[int]:
        return (t for t in range(self.n_trials) if t not in self.done)


def check_against_scenario(config: Config, scenario_cfg: Any) -> None:
    """Cross-checks of a config against its scenario, once at load (before any folder is written): sensor.dt must
    be a multiple of the SUMO step."""
    step = getattr(scenario_cfg, "step_length", None)
    if step is not None:
        config.sensor.validate(float(step))


def _utc_stamp() -> str:
    return datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")


def net_name(net: str) -> str:
    """``intersection`` for a shipped name, the file stem (without .net.xml) for a path."""
    name = Path(str(net)).name
    for suffix in (".net.xml.gz", ".net.xml", ".xml"):
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return name


def scenario_name(net: str, scenario_cfg: Any) -> str:
    """The name a run is filed and labelled under: the scenario's (``[scenario] name``, else what
    :func:`soabench.scenario.load` derived from the scenario file or network), else the network's."""
    return str(getattr(scenario_cfg, "name", "") or "") or net_name(net)


def default_run_dir(net: str, root: Path = Path("results")) -> Path:
    """``results/<net>/<UTC timestamp>/`` (a suffix keeps it unique)."""
    base = root / net_name(net) / _utc_stamp()
    path, i = base, 1
    while path.exists():
        path = base.with_name(f"{base.name}-{i}")
        i += 1
    return path


def _scenario_info(scenario_cfg: Any) -> Any:
    if dataclasses.is_dataclass(scenario_cfg) and not isinstance(scenario_cfg, type):
        try:
            return to_jsonable(dataclasses.asdict(scenario_cfg))
        except Exception:  # pragma: no cover - exotic fields
            return repr(scenario_cfg)
    return None if scenario_cfg is None else repr(scenario_cfg)


# ------------------------------------------------------------------------------------------------ the run
@dataclass(frozen=True)
class RunRequest:
    """What a run is asked to do: a new run of ``config`` on a scene, or the rest of an earlier run (``resume``).

    Attributes:
        config: the resolved configuration; None with ``resume``, which reads the run's own.
        net, polys, scenario: passed to :func:`soabench.scenario.load` (ignored with ``resume``).
        out: run folder (default ``results/<net>/<UTC timestamp>/``); resolved, and refused unless new or empty.
        resume: an earlier run folder: run only its trials without a result, with its stored config. Every value of
            its ``run.json`` is validated; its trial kind and scene loader are names looked up in
            :mod:`~soabench.experiment.trial.registry` (nothing from the folder is imported).
        requested: with ``resume``, what the caller asked for (dotted keys such as ``experiment.clutter``, ``net``,
            ``polys``, ``scenario``); every value that differs from the stored run is refused, except more
            ``experiment.trials``, which extends the run (see :mod:`~soabench.experiment.runs.runmeta`).
        options: how the trials run and what is written beside the tables (:class:`RunOptions`; figures None:
            drawn); with ``resume``, ``save_estimates`` is the run's own (asking for it on a run without is refused).
        trial_fn: ``run_trial(trial, config, scene, scenario, *, save_estimates)``; must be importable by
            worker processes (a module-level function). Default: the registered trial kind ``soabench``
            (:func:`soabench.experiment.trial.trial.run_trial`); run.json records its registered name.
        load_fn: ``load(net, polys, scenario) -> (SceneMap, ScenarioConfig)``; default: scene loader ``sumo``.
    """

    config: Config | None
    net: str
    polys: tuple[str, ...] = ()
    scenario: str | None = None
    out: Path | None = None
    resume: Path | None = None
    requested: Mapping[str, Any] | None = None
    options: RunOptions = RUN_DEFAULTS
    trial_fn: TrialFn | None = None
    load_fn: LoadFn | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "polys", tuple(str(p) for p in self.polys))

    def task_spec(self) -> TaskSpec:
        """What a worker needs to run any trial of this (resolved) run."""
        return TaskSpec(self.meta(), self.trial_fn, self.load_fn, plugins.session_import_paths())

    def meta(self) -> RunMeta:
        """The record of this (resolved) run, as its ``run.json`` holds it."""
        assert self.config is not None
        return RunMeta(
            self.config, str(self.net), self.polys, self.scenario, bool(self.options.save_estimates),
            self.config.experiment.trials, registry.trial_kind_name(self.trial_fn),
            registry.scene_loader_name(self.load_fn),
        )  # fmt: skip


@dataclass(frozen=True)
class Batch:
    """How a campaign runs one of its runs among others (the default, :data:`ALONE`: a run on its own).

    Attributes:
        executor: an open executor (from :func:`open_executor`) to reuse, e.g. across the points of a sweep.
        defer: a list: create (or check) the folder, append its :class:`DeferredRun` (the trials to run) instead of
            running them, and return (:mod:`soabench.experiment.execution.grouped` runs several folders' trials
            together).
        run_trials: False: run no trial; report if every trial was attempted (after a grouped run).
    """

    executor: Any = None
    defer: list | None = None
    run_trials: bool = True


ALONE = Batch()
#: the keywords of :func:`soabench.experiment.reports.finished.run_experiment` that are :class:`Batch` fields
BATCH_FIELDS = tuple(f.name for f in dataclasses.fields(Batch))


@dataclass
class DeferredRun:
    """A checked run folder whose trials ``todo`` are to be run by :mod:`soabench.experiment.execution.grouped`."""

    store: RunStore
    spec: TaskSpec
    todo: frozenset[int]
    n_trials: int
    config: Config
    figures: bool  #: whether its report draws figures


def execute(request: RunRequest, batch: Batch = ALONE) -> RunOutcome:
    """Run (or finish, with ``request.resume``) the trials of the Monte Carlo protocol of ``request.config`` on its
    scene: the run loop.

    Returns:
        A :class:`RunOutcome`; once every trial was attempted, its ``finished`` record is the run to report (the
        layer above writes the summary, figures and report.html: :mod:`soabench.experiment.reports.finished`).
        One process at a time works a run folder (a lock; the second gets an error naming the holder).
    """
    locks: list[FolderLock] = []  # held until the report is written
    try:
        if request.resume is not None:
            run_dir = resolve(request.resume)
            check_existing_folder(run_dir, RUN_FILE, "run")
            locks.append(FolderLock(run_dir).acquire())
            store = RunStore(run_dir)
            request = _resumed(store, request)
        else:
            require(request.config is not None, "run_experiment needs a config (or resume=RUN_DIR)")
            config = Config.from_dict(request.config.to_dict()).validate()
            out = request.out
            if out is None:  # filed under the scenario's name, so the scene is loaded first
                _, scenario_cfg = registry.load_scene_cached(
                    request.net, request.polys, request.scenario, request.load_fn
                )
                out = default_run_dir(scenario_name(request.net, scenario_cfg))
            run_dir = resolve(out)
            check_new_folder(run_dir, RUN_FILE, "run", f"finish it with soabench run --resume {run_dir}")
            store = RunStore(run_dir)
            request = dataclasses.replace(request, config=config, out=run_dir)
        return _run_locked(store, request, locks, batch)
    finally:
        for lock in locks:
            lock.release()


def _resumed(store: RunStore, request: RunRequest) -> RunRequest:
    """The request of a resumed run: its stored configuration, scene, trial kind and scene loader, the trials it
    is asked for (more extend the run; any other difference is refused)."""
    run_dir = store.run_dir
    raw = store.meta()
    meta = validate_run_meta(raw, str(store.run_file))
    if request.requested:
        stored = {"net": meta.net, "polys": list(meta.polys), "scenario": meta.scenario}
        stored.update({f"{sec}.{k}": v for sec, d in meta.config.to_dict().items() for k, v in d.items()})
        more = check_requested(stored, dict(request.requested), f"run folder {str(run_dir)!r}")
        if more is not None:  # safe: trial n's seeds depend only on (seed, n)
            raw["config"]["experiment"]["trials"] = more
            raw["trials"] = more
            write_json_atomic(store.run_file, raw)
            meta = validate_run_meta(raw, str(store.run_file))
    require(
        meta.save_estimates or not request.options.save_estimates,
        f"--save-estimates does not apply to --resume of {str(run_dir)!r}: the run was started without it, "
        "so its finished trials have no estimates; start a new run with --save-estimates --out",
    )
    for line in store.reject_foreign_records(meta.trials):  # copies, strays: moved aside, their trials rerun
        print(f"soabench: {line}", file=sys.stderr)
    return dataclasses.replace(
        request, config=meta.config, net=meta.net, polys=meta.polys, scenario=meta.scenario,
        options=dataclasses.replace(request.options, save_estimates=meta.save_estimates),
        trial_fn=request.trial_fn or registry.trial_kind(meta.trial_kind),
        load_fn=request.load_fn or registry.scene_loader(meta.scene_loader),
    )  # fmt: skip


def _run_locked(store: RunStore, request: RunRequest, locks: list[FolderLock], batch: Batch) -> RunOutcome:
    """The body of :func:`execute` once the folder is checked (and, for a resume, locked); ``request`` is resolved
    (its configuration validated or read from the run)."""
    config, options = request.config, request.options
    assert config is not None
    resumed = request.resume is not None
    figures = options.figures is not False
    plugins.preflight(config)  # a plugin that cannot be imported or configured stops the run before any trial
    n_trials = config.experiment.trials
    hint = f"finish with: soabench run --resume {store.run_dir}"

    # validate the network and the config against it before starting workers (a bad path or a dt that is no
    # multiple of the SUMO step is a user error, not 100 failed trials)
    _, scenario_cfg = registry.load_scene_cached(request.net, request.polys, request.scenario, request.load_fn)
    check_against_scenario(config, scenario_cfg)
    done = set(store.done_trials()) if resumed else set()
    foreign = sorted(t for t in done if t >= n_trials)
    require(not foreign, f"{str(store.run_dir)!r} holds trial {foreign[:1]} beyond its {n_trials} trials: foreign")
    todo = TodoTrials(n_trials, done) if batch.run_trials else TodoTrials(0, set())
    # connect to the executor before creating the run folder (an unreachable scheduler leaves nothing behind)
    own_executor = batch.executor is None and len(todo) > 0 and batch.defer is None
    exe = (
        open_executor(options.workers, options.scheduler, options.dask_local, n_trials=len(todo))
        if own_executor
        else batch.executor
    )
    interrupted = stopped = False
    try:
        if not resumed:
            locks.append(FolderLock(store.run_dir).acquire())  # creates the folder; execute releases it
            check_new_folder(store.run_dir, RUN_FILE, "run", f"finish it with soabench run --resume {store.run_dir}")
            store.create(_run_file(request, scenario_cfg))
        if len(todo) and batch.defer is not None:  # run later, together with other folders' trials
            batch.defer.append(DeferredRun(store, request.task_spec(), frozenset(todo), n_trials, config, figures))
            return RunOutcome(store.run_dir, False, len(done), n_trials - len(done), store.failures(), "")
        if len(todo):
            interrupted, stopped, times = _run_trials(
                store, exe, request.task_spec(), todo, n_trials, len(done), options.fail_fast, options.progress
            )
            session = {"executor": exe.name, "n_workers": getattr(exe, "n_workers", 1), "trials_run": len(todo),
                       "resumed": resumed, "interrupted": interrupted, "stopped_fail_fast": stopped,
                       "versions": package_versions(), **times}  # fmt: skip
            store.write_session(f"{_utc_stamp()}-{os.getpid()}", session)
    except KeyboardInterrupt:
        interrupted = True
        raise Interrupted(
            f"interrupted: {len(store.done_trials())} of {n_trials} trials on disk in {store.run_dir}; {hint}"
        ) from None
    finally:
        if own_executor:
            exe.close(abort=interrupted or stopped)

    if interrupted:
        done = store.done_trials()
        raise Interrupted(f"interrupted: {len(done)} of {n_trials} trials on disk in {store.run_dir}; {hint}")
    return _ended(store, request, batch, stopped)


def _ended(store: RunStore, request: RunRequest, batch: Batch, stopped: bool) -> RunOutcome:
    """What the run's folder holds once its trials ran: the finished run to report when every trial was attempted
    (not when some were never attempted, ``--fail-fast`` ``stopped``, or the trials are deferred to a group)."""
    config, options = request.config, request.options
    assert config is not None
    n_trials = config.experiment.trials
    done = set(store.done_trials())
    failures = store.failures()
    failed_set = {int(f["trial"]) for f in failures}
    n_missing = n_trials - len(done)
    unattempted = n_missing - len(failed_set - done)
    outcome = RunOutcome(store.run_dir, n_missing == 0, len(done), n_missing, failures, "")
    if unattempted or stopped or batch.defer is not None:  # deferring: the report follows the group
        return outcome
    local = not (options.scheduler or options.dask_local)  # figures on local processes
    figures = options.figures is not False
    outcome.finished = FinishedRun(store, config, figures, options.workers if local else None, batch.executor)
    return outcome


def _run_file(request: RunRequest, scenario_cfg: Any) -> dict:
    """The ``run.json`` of a new run (:mod:`soabench.experiment.runs.runmeta` reads it back)."""
    meta = request.meta()
    return {
        "created": _utc_stamp(),
        "net": meta.net,
        "net_name": scenario_name(meta.net, scenario_cfg),
        "polys": list(meta.polys),
        "scenario": meta.scenario,
        "scenario_config": _scenario_info(scenario_cfg),
        "trials": meta.trials,
        "save_estimates": meta.save_estimates,
        "trial_kind": meta.trial_kind,
        "scene_loader": meta.scene_loader,
        "config": meta.config.to_dict(),
        "versions": package_versions(),
        "platform": platform_info(),
        "reproduction_tolerance": REPRODUCTION_TOLERANCE,
    }


def _run_trials(
    store: RunStore,
    exe: Any,
    spec: TaskSpec,
    todo: list[int],
    n_trials: int,
    n_done: int,
    fail_fast: bool,
    progress: bool,
) -> tuple[bool, bool, dict]:
    """Run ``todo`` on ``exe``, persisting each result as it arrives.

    Returns (interrupted by Ctrl-C, stopped by fail-fast, {"started", "wall_s"}).
    """
    interrupted = stopped = False
    store.clear_merged()
    t_start = time.time()
    if uses_kernels(spec):  # once per machine: before the progress line, so that its ETA counts trials only
        ensure_compiled([spec.config])
    bar = Progress(n_trials, n_done, progress, label=store.run_dir.name)
    gen = exe.results(spec, todo)
    try:
        for _, rec in gen:
            if rec.get("status") == "ok":
                store.write_trial(rec)
                bar.update(True)
                _print_model_failures(rec, bar)
                if fail_fast and rec.get("model_failures"):  # a requested method has no row in this trial
                    stopped = True
                    break
            else:
                store.write_failure(rec)
                bar.update(False)
                _print_failure(rec, bar)
                if fail_fast:
                    stopped = True
                    break
    except KeyboardInterrupt:
        interrupted = True
    finally:
        gen.close()
        bar.close()
        wall = time.time() - t_start
    return interrupted, stopped, {"started": t_start, "wall_s": wall}


def _print_model_failures(rec: dict, bar: Progress) -> None:
    """One line per failed plugin run of a trial (soabench.experiment.trial.guard)."""

    for f in rec.get("model_failures") or ():
        if bar.enabled:
            sys.stderr.write("\n")
        print(f"soabench: {failure_message(f)}", file=sys.stderr)


def _print_failure(rec: dict, bar: Progress) -> None:
    if bar.enabled:
        sys.stderr.write("\n")
    print(
        f"trial {rec['trial']} failed (seed {rec['seed']}, sumo_seed {rec['sumo_seed']}): {rec['error']}",
        file=sys.stderr,
    )
