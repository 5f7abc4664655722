"""A Monte Carlo run held in memory: the tables a run folder's CSV files hold, as numpy record arrays
(docs/method.md §5.8).

:func:`run_in_memory` runs the trials of a config on the same executors as
:func:`~soabench.experiment.execution.runner.execute` (trial n's seeds depend only on ``(seed, n)``) and merges
their records with the run folder's own order (:class:`~soabench.experiment.runs.store.TableOrder`), so
:class:`RunResult` holds the rows of ``trials.csv``, ``episodes.csv`` and ``steps.csv`` value for value;
:meth:`RunResult.write_csv` writes them with the run folder's
writer, byte for byte. Nothing is written to disk unless asked.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from soabench import plugins
from soabench.config import Config
from soabench.errors import SoabenchError, require
from soabench.experiment.execution.executors import open_executor
from soabench.experiment.execution.progress import Progress
from soabench.experiment.execution.runner import TaskSpec, check_against_scenario
from soabench.experiment.runs.files import as_lists, format_value, unpack_table, write_csv_lists
from soabench.experiment.runs.runmeta import RunMeta
from soabench.experiment.runs.store import (
    EPISODE_COLUMNS,
    STEP_COLUMNS,
    TIMING_COLUMNS,
    TIMING_FILE_COLUMNS,
    TRIAL_COLUMNS,
    RunStore,
    TableOrder,
    _rows_of,
    merge_args,
    timing_rows,
)
from soabench.experiment.trial.registry import DEFAULT_SCENE_LOADER, DEFAULT_TRIAL_KIND, load_scene_cached

#: the tables of a :class:`RunResult`, as the CSV files of a run folder are named (``<name>.csv``)
TABLES = ("trials", "episodes", "steps", "timing")


def record_array(columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> np.recarray:
    """A numpy record array of ``rows`` (lists over ``columns``): a column of Python ints is int64, of bools bool,
    of numbers float64 (a missing cell NaN), anything else str (each cell as the CSV file spells it)."""
    arrays = []
    for j in range(len(columns)):
        cells = [r[j] for r in rows]
        kinds = {type(v) for v in cells}
        if kinds <= {bool, np.bool_} and cells:
            arrays.append(np.array(cells, dtype=bool))
        elif kinds <= {int} and cells:
            arrays.append(np.array(cells, dtype=np.int64))
        elif kinds <= {int, float, type(None)}:
            arrays.append(np.array([np.nan if v is None else v for v in cells], dtype=np.float64))
        else:
            arrays.append(np.array([format_value(v) for v in cells], dtype=str))
    return np.rec.fromarrays(arrays, names=list(columns)) if rows else _empty(columns)


def _empty(columns: Sequence[str]) -> np.recarray:
    return np.rec.fromarrays([np.zeros(0) for _ in columns], names=list(columns))


@dataclass(repr=False)
class RunResult:
    """The tables of a Monte Carlo run (the CSV files of a run folder, docs/user-guide/outputs.md), in memory.

    Attributes:
        trials: one row per (trial, clutter, model, mode): ``trials.csv``.
        episodes: one row per delay episode (§5.4): ``episodes.csv``.
        steps: one row per run and scan k: ``steps.csv``.
        timing: wall-clock seconds per run and trial stage: ``timing.csv`` (varies from run to run).
        config: the resolved configuration of the run.
        net: the network (name or path) the run simulated.
        failures: the trials that failed (trial, seed, sumo_seed, error); they have no rows.
        model_failures: the plugin runs that failed inside finished trials (``model_failures.csv``).
        run_dir: the run folder when the run was asked to write one (``out=``), else None.
    """

    trials: np.recarray
    episodes: np.recarray
    steps: np.recarray
    timing: np.recarray
    config: Config
    net: str
    failures: list[dict] = field(default_factory=list)
    model_failures: list[dict] = field(default_factory=list)
    run_dir: Path | None = None

    @property
    def complete(self) -> bool:
        """Every trial has a result."""
        return not self.failures

    def table(self, name: str) -> np.recarray:
        """The table ``name`` (one of :data:`TABLES`)."""
        require(name in TABLES, f"table {name!r} is unknown; choose one of {', '.join(TABLES)}")
        return getattr(self, name)

    def to_pandas(self, name: str = "trials") -> Any:
        """The table ``name`` (one of :data:`TABLES`) as a pandas DataFrame (pandas must be installed)."""
        table = self.table(name)
        try:
            import pandas
        except ImportError:
            raise SoabenchError(
                "to_pandas needs pandas, which is not installed: pip install pandas (the tables are numpy record "
                "arrays without it)"
            ) from None
        return pandas.DataFrame.from_records(table)

    def write_csv(self, folder: str | Path) -> list[Path]:
        """Write ``trials.csv``, ``episodes.csv`` and ``steps.csv`` into ``folder`` (created if needed) with the
        run folder's writer: the same bytes ``soabench run`` writes for the same config. Returns the paths."""
        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        paths = []
        for name in ("trials", "episodes", "steps"):
            table = getattr(self, name)
            path = out / f"{name}.csv"
            write_csv_lists(path, list(table.dtype.names), (list(map(_cell, r)) for r in table.tolist()))
            paths.append(path)
        return paths

    def __repr__(self) -> str:
        exp = self.config.experiment
        models = ", ".join([*exp.models, *exp.trackers])
        n = len({int(t) for t in self.trials["trial"]}) if len(self.trials) else 0
        status = "" if self.complete else f", {len(self.failures)} failed trials"
        return (
            f"RunResult({self.net!r}, {n} trials x {len(exp.clutter)} clutter x [{models}] x "
            f"[{', '.join(exp.probabilities)}]: {len(self.trials)} trial rows, {len(self.episodes)} episodes, "
            f"{len(self.steps)} steps{status})"
        )


def _cell(v: Any) -> Any:
    """A record array's value as the row held it before (a numpy scalar as the Python scalar, a str column's cell
    as its text): what :func:`~soabench.experiment.runs.files.csv_line` formats."""
    return v.item() if isinstance(v, np.generic) else v


def collect(records: Iterable[dict], models: Sequence[str], modes: Sequence[str]) -> dict[str, np.recarray]:
    """The merged tables of a run's ok trial records, in the run folder's order (:class:`TableOrder`)."""
    order = TableOrder(models, modes)
    rows: list[dict] = []
    episodes: list[dict] = []
    timing: list[dict] = []
    steps: list[dict] = []
    for rec in sorted(records, key=lambda r: int(r["trial"])):
        own = unpack_table(rec.get("rows"))
        rows += own
        episodes += unpack_table(rec.get("episodes"))
        timing += timing_rows(own, rec.get("timing") or {})
        if rec.get("steps"):
            steps.append(rec["steps"])
    rows.sort(key=order.row)
    timing.sort(key=order.row)
    episodes.sort(key=order.episode)
    step_cols, step_rows = _rows_of(steps, STEP_COLUMNS)
    step_rows.sort(key=order.step_key(step_cols))
    trials = [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows]
    return {
        "trials": record_array(*as_lists(trials, TRIAL_COLUMNS)),
        "episodes": record_array(*as_lists(episodes, EPISODE_COLUMNS)),
        "steps": record_array(step_cols, step_rows),
        "timing": record_array(*as_lists(timing, TIMING_FILE_COLUMNS)),
    }


def run_in_memory(
    config: Config,
    net: str,
    polys: Sequence[str] = (),
    scenario: str | None = None,
    *,
    workers: int | None = 1,
    executor: Any = None,
    progress: bool = False,
) -> RunResult:
    """Every trial of ``config`` on ``net``, on ``executor`` (else one opened for ``workers``), merged in memory.

    The checks before the first trial are those of a run folder's (plugins import and take their options, the
    sensor period fits the SUMO step); a failed trial is listed in :attr:`RunResult.failures` and has no rows.
    """

    config = Config.from_dict(config.to_dict()).validate()
    plugins.preflight(config)
    polys = tuple(str(p) for p in polys)
    _, scenario_cfg = load_scene_cached(net, polys, scenario)
    check_against_scenario(config, scenario_cfg)
    n_trials = config.experiment.trials
    meta = RunMeta(config, str(net), polys, scenario, False, n_trials, DEFAULT_TRIAL_KIND, DEFAULT_SCENE_LOADER)
    spec = TaskSpec(meta, plugin_paths=plugins.session_import_paths())
    exe = executor if executor is not None else open_executor(workers, n_trials=n_trials)
    records: list[dict] = []
    failures: list[dict] = []
    bar = Progress(n_trials, 0, progress, label=str(net))
    finished = False
    try:
        for _, rec in exe.results(spec, range(n_trials)):
            ok = rec.get("status") == "ok"
            (records if ok else failures).append(rec)
            bar.update(ok)
        finished = True
    finally:
        bar.close()
        if executor is None:
            exe.close(abort=not finished)  # Ctrl-C: stop the trials in flight instead of waiting for them
    tables = collect(records, *merge_args(config))
    model_failures = [
        dict(f) for rec in sorted(records, key=lambda r: r["trial"]) for f in rec.get("model_failures") or ()
    ]
    failures = [{k: f.get(k) for k in ("trial", "seed", "sumo_seed", "error")} for f in failures]
    if failures:
        first = min(failures, key=lambda f: f["trial"])
        warnings.warn(
            f"{len(failures)} of {n_trials} trials failed (trial {first['trial']}: {first['error']}); their rows are "
            "missing, RunResult.failures lists them",
            stacklevel=3,
        )
    return RunResult(
        config=config,
        net=str(net),
        failures=sorted(failures, key=lambda f: f["trial"]),
        model_failures=model_failures,
        **tables,
    )


def with_experiment(config: Config, **overrides: Any) -> Config:
    """A copy of ``config`` whose ``[experiment]`` section takes the given values (None: keep), checked as a
    configuration file's would be, and validated."""
    given = {k: v for k, v in overrides.items() if v is not None}
    return Config.from_dict({"experiment": given} if given else {}, base=config).validate()


def from_run_folder(run_dir: Path, config: Config, net: str) -> RunResult:
    """The :class:`RunResult` of a run folder, from its trial records (the rows its CSV files were merged from)."""

    store = RunStore(run_dir)
    records = [store.load_trial(t) for t in store.done_trials()]
    failures = [{k: f.get(k) for k in ("trial", "seed", "sumo_seed", "error")} for f in store.failures()]
    return RunResult(
        config=config,
        net=net,
        failures=failures,
        model_failures=store.model_failures(),
        run_dir=Path(run_dir),
        **collect(records, *merge_args(config)),
    )
