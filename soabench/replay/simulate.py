"""Re-simulate one trial of a finished run folder, keeping the per-scan state a replay draws
(docs/user-guide/replay.md).

A run keeps no per-scan state; trial n is reproduced exactly from the run's stored configuration and the trial seeds
(seed, n) (docs/method.md §5.8, :mod:`soabench.seeding`): one SUMO run, the scans of one clutter rate, and per birth
model one GM-PHD run of one probability mode. Each model's births per scan are kept (the birth model is wrapped), the
filter's step results and the metrics' delay episodes (§5.4). The recomputed per-trial metrics are compared with
the run's ``trials.csv`` rows and the package versions with ``run.json``'s, so a replay says when it does not show
what the run measured.
"""

from __future__ import annotations

import copy
import csv
import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from soabench import plugins
from soabench import scenario as scenarios  # by attribute: a test may stand in for its simulate
from soabench.birth import LABEL
from soabench.config import FAMILIES, FILTER_FAMILIES, Config, family_label
from soabench.errors import SoabenchError, require
from soabench.experiment.runs.provenance import package_versions
from soabench.experiment.runs.runmeta import validate_run_meta
from soabench.experiment.trial import guard, registry
from soabench.experiment.trial.registry import load_scene_cached
from soabench.folders import check_existing_folder, resolve
from soabench.protocols import TrackerSetup
from soabench.seeding import trial_seeds
from soabench.sensor import observe
from soabench.trackers import FilterTracker, ScanFailure, build_filter, run_tracker

#: per-trial metric columns compared with ``trials.csv`` (the rest are derived from these or are wall times)
CHECKED_COLUMNS = ("delay_mean", "n_episodes", "n_censored", "card_err", "ospa", "gospa", "tp", "fp", "fn")


@dataclass
class ModelReplay:
    """One birth model's filter run over the trial's scans."""

    name: str
    label: str
    births: list[Any]  #: K Births, as the model returned them at each scan
    results: list[Any]  #: K StepResult
    metrics: Any  #: soabench.metrics.TrialMetrics of the run
    row: dict[str, Any]  #: the trials.csv row this run gives


@dataclass
class TrialReplay:
    """Everything one replayed trial shows."""

    run_dir: Path
    trial: int
    clutter: float
    mode: str
    config: Config
    scene: Any
    recording: Any
    scans: Any
    seeds: Any
    models: list[ModelReplay]
    #: one-line notes: version differences, reproduction check against trials.csv
    notes: list[str] = field(default_factory=list)
    #: True when every replayed model's metrics equal the run's trials.csv row
    reproduced: bool | None = None
    #: the filter family the birth models ran in (:data:`soabench.config.FAMILIES`)
    family: str = FILTER_FAMILIES[0]


def read_run(run_dir: str | Path):
    """The validated ``run.json`` of a run folder (:func:`soabench.experiment.runs.runmeta.validate_run_meta`) and its
    raw dict."""
    # imported when called: scipy would slow every start-up
    from soabench.experiment.runs.store import RUN_FILE, RunStore

    path = resolve(run_dir)
    check_existing_folder(path, RUN_FILE, "run")
    store = RunStore(path)
    raw = store.meta()
    return path, validate_run_meta(raw, str(store.run_file)), raw


def _choose(value: Any, allowed: list, flag: str) -> Any:
    """``value`` if the run has it (None: the run's first), else a one-line error naming what it has."""
    if value is None:
        return allowed[0]
    require(value in allowed, f"{flag} {value!r} is not in this run; choose from {', '.join(map(str, allowed))}")
    return value


def replay_trial(
    run_dir: str | Path,
    trial: int,
    models: tuple[str, ...] | None = None,
    mode: str | None = None,
    clutter: float | None = None,
    family: str | None = None,
) -> TrialReplay:
    """Re-simulate trial ``trial`` of the run in ``run_dir`` for ``models`` (default: the run's birth models) in
    filter ``family`` (default: the run's first) and probability ``mode`` (default: the run's first that the family
    defines) at clutter rate ``clutter`` (default: the run's first)."""
    # imported when called: numba, scipy would slow every start-up
    from soabench.experiment.trial.trial import RunKey, make_row
    from soabench.metrics import evaluate

    path, meta, raw = read_run(run_dir)
    cfg = meta.config
    exp = cfg.experiment
    require(
        isinstance(trial, int) and 0 <= trial < exp.trials,
        f"--trial {trial} is not a trial of this run; choose 0 to {exp.trials - 1}",
    )
    require(
        meta.trial_kind == registry.DEFAULT_TRIAL_KIND and meta.scene_loader == registry.DEFAULT_SCENE_LOADER,
        f"run folder {str(path)!r} was made by trial kind {meta.trial_kind!r} / scene loader {meta.scene_loader!r}; "
        "a replay re-simulates the built-in pipeline only",
    )
    names = (*exp.models, *exp.trackers) if models is None else tuple(models)
    for name in names:
        require(name in (*exp.models, *exp.trackers), f"--models {name!r} is not a birth model or tracker of this "
                f"run; choose from {', '.join((*exp.models, *exp.trackers))}")  # fmt: skip
    family = _choose(family, list(exp.filters), "--filter")
    modes = [m for m in exp.probabilities if m in FAMILIES[family].modes]
    require(
        mode is None or mode not in exp.probabilities or mode in modes,
        f"--mode {mode!r} is not defined for the {family_label(family)} filter; choose from {', '.join(modes)}",
    )
    mode = _choose(mode, modes, "--mode")
    named = None if tuple(exp.filters) == FILTER_FAMILIES[:1] else family  # the run's filter column, if it has one
    lam = float(_choose(None if clutter is None else float(clutter), [float(c) for c in exp.clutter], "--clutter"))
    scene, scenario = load_scene_cached(meta.net, meta.polys, meta.scenario)
    seeds = trial_seeds(exp.seed, trial)
    recording = scenarios.simulate(scene, scenario, seeds, duration=exp.duration)
    sensor_cfg = cfg.sensor_at(lam)
    scans = observe(recording, scene, sensor_cfg, seeds.sensor_rngs())
    runs: list[ModelReplay] = []
    for name in names:
        if name not in exp.models:  # a whole tracker: no birth terms of ours to show
            run = _tracker_run(name, cfg, sensor_cfg, scene, scans, seeds, mode)
            births: list[Any] = [None] * len(run.results)
        else:
            cls = plugins.resolve(plugins.BIRTH, name)
            options = {} if plugins.is_builtin_birth(name) else cfg.plugins.get(name, {})
            model = _Recorder(cls(cfg.birth, sensor_cfg, scene, seeds.placement_rng(), **options))
            filt, p_D_b = build_filter(family, cfg, sensor_cfg, mode, seeds.association_rng())
            run = run_tracker(scans, FilterTracker(model, filt, p_D_b))
            births = model.births
        metrics = evaluate(scans, run.results, cfg.metrics, sensor_cfg)
        row = make_row(RunKey(trial, lam, name, mode, named), seeds, cfg.birth.N_hat, metrics, run, 0.0)
        runs.append(ModelReplay(name, LABEL.get(name, name), births, run.results, metrics, row))
    out = TrialReplay(path, trial, lam, mode, cfg, scene, recording, scans, seeds, runs, family=family)
    out.notes.append(_version_note(raw))
    out.reproduced, note = _check_rows(path, out)
    out.notes.append(note)
    return out


def _tracker_run(name: str, cfg: Config, sensor_cfg: Any, scene: Any, scans: Any, seeds: Any, mode: str) -> Any:
    """A whole tracker's run over the scans, built as the trial builds it (its own copy of the configuration, the
    trial's placement generator); each step's track labels, where its Estimates carry them, stay on the result."""

    def check(out: Any, scan: Any, t_step: float) -> Any:
        result = guard.check_estimates(out, scan, t_step)
        labels = getattr(out, "labels", None)
        if labels is not None and getattr(result, "labels", None) is None:
            result.labels = labels  # shown by the replay (soabench.replay.frames.estimate_labels)
        return result

    cls = plugins.resolve(plugins.TRACKER, name)
    own = copy.deepcopy(cfg)
    setup = TrackerSetup(dataclasses.replace(sensor_cfg), scene, seeds.placement_rng(), mode, own)
    try:
        return run_tracker(scans, cls(setup, **own.plugins.get(name, {})), check)
    except ScanFailure as exc:
        raise SoabenchError(f"tracker {name!r} failed at scan {exc.k} of the replay: {exc.message}") from None


class _Recorder:
    """A birth model that keeps what it returned at each scan (the filter sees the very same Births)."""

    def __init__(self, model: Any) -> None:
        self.model = model
        self.name = getattr(model, "name", None)
        self.births: list[Any] = []

    def __call__(self, ctx: Any) -> Any:
        births = self.model(ctx)
        self.births.append(births)
        return births


def _version_note(raw: dict) -> str:
    """One line: the package versions that differ between the run and this replay (or that they agree)."""
    # imported when called: scipy would slow every start-up

    stored = raw.get("versions") if isinstance(raw.get("versions"), dict) else {}
    now = package_versions()
    diffs = [
        f"{k} {stored.get(k)} -> {now.get(k)}" for k in sorted(set(stored) | set(now)) if stored.get(k) != now.get(k)
    ]
    if not diffs:
        return "versions: as in the run"
    return "versions differ from the run's: " + ", ".join(diffs)


def _check_rows(path: Path, rep: TrialReplay) -> tuple[bool | None, str]:
    """Compare each replayed run's metrics with its row of the run's ``trials.csv`` (of the replayed family, in a run
    that names filter families)."""
    from soabench.experiment.trial.trial import FILTER_COLUMN

    table = path / "trials.csv"
    if not table.is_file():
        return None, "reproduction not checked: the run has no trials.csv (unfinished run)"
    want = {m.name for m in rep.models}
    stored: dict[str, dict[str, str]] = {}
    try:
        with table.open(newline="", encoding="utf-8") as fh:
            for r in csv.DictReader(fh):
                try:
                    same = int(r["trial"]) == rep.trial and float(r["clutter"]) == rep.clutter
                except (KeyError, ValueError):
                    continue
                if r.get(FILTER_COLUMN, "") not in ("", rep.family):  # the replayed family's rows (and trackers')
                    continue
                if same and r.get("mode") == rep.mode and r.get("model") in want:
                    stored[r["model"]] = r
    except (OSError, csv.Error, UnicodeDecodeError) as exc:
        raise SoabenchError(f"cannot read {str(table)!r}: {exc}") from None
    bad: list[str] = []
    missing = [m.name for m in rep.models if m.name not in stored]
    for m in rep.models:
        if m.name in stored:
            bad += [f"{m.name} {c}" for c in CHECKED_COLUMNS if not _equal(stored[m.name].get(c), m.row.get(c))]
    if bad:
        return False, "NOT the run's numbers: the replay differs from trials.csv in " + ", ".join(bad[:6])
    if missing:
        return None, "reproduction not checked for " + ", ".join(missing) + " (no row in trials.csv)"
    return True, f"reproduced: {len(rep.models)} model run(s) give the run's trials.csv metrics"


def _equal(text: str | None, value: Any) -> bool:
    """A trials.csv cell equals a recomputed value (NaN equals NaN; floats to 1e-9 relative)."""
    if text is None:
        return False
    try:
        a, b = float(text), float(value)
    except (TypeError, ValueError):
        return str(text) == str(value)
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)
