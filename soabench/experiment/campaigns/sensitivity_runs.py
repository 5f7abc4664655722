"""The runs behind the sensitivity table: a finished run's protocol again with one switch changed.

Each variant (:data:`VARIANTS`) is an ordinary run folder ``<out>/<setting>/`` made from the main run's stored
configuration, net and scene files with one option changed
(:data:`soabench.experiment.campaigns.sensitivity.SETTING_CHANGE`),
so it pairs with the main run trial by trial (trial n's seeds depend only on the seed and n). Used by the
``sensitivity/`` part of ``soabench study`` and by ``soabench sensitivity --main RUN_DIR``; both resume an existing
variant and then write ``sensitivity.md`` / ``sensitivity.csv``
(:func:`soabench.experiment.campaigns.sensitivity.write_sensitivity`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from soabench.config import MAX_TRIALS, Config
from soabench.errors import Interrupted, SoabenchError, require
from soabench.experiment.campaigns import sensitivity as sens
from soabench.experiment.execution.executors import open_executor
from soabench.experiment.execution.grouped import run_group
from soabench.experiment.execution.options import RUN_DEFAULTS, RunOptions, check_workers
from soabench.experiment.execution.runner import ALONE, Batch, RunOutcome, RunRequest
from soabench.experiment.reports.finished import run
from soabench.experiment.runs.runmeta import config_differences, validate_run_meta
from soabench.experiment.runs.store import RunStore
from soabench.figures.drawing import parallel
from soabench.folders import FolderLock, check_own_folder, resolve

#: the variant runs, in column order
VARIANTS = ("gate_off", "visible")
#: every entry a sensitivity folder holds
SENSITIVITY_ENTRIES = (*VARIANTS, "sensitivity.md", "sensitivity.csv")


def variant_config(main: Config, key: str, trials: int) -> Config:
    """The main run's configuration with the switch of setting ``key`` changed and ``trials`` trials."""
    section, name, value = sens.SETTING_CHANGE[key]
    cfg = Config.from_dict(main.to_dict())
    setattr(cfg, section, dataclasses.replace(getattr(cfg, section), **{name: value}))
    cfg.experiment = dataclasses.replace(cfg.experiment, trials=trials)
    return cfg.validate()


def run_variants(
    out_dir: Path,
    main_dir: Path,
    *,
    trials: int | None = None,
    follow_main: bool = False,
    options: RunOptions = RUN_DEFAULTS,
    batch: Batch = ALONE,
) -> list[RunOutcome]:
    """Run (or finish) every variant of the run in ``main_dir`` under ``out_dir``.

    ``trials``: trials of a new variant (default: the main run's); for an existing one, more trials than it has
    extend it, fewer are refused. ``follow_main``: without ``trials``, extend an existing variant to the main run's
    trials when the main run has more. An existing variant made from another main protocol is refused (one line
    naming the first differing keys), so the table never pairs runs of different protocols. ``options`` and
    ``batch`` (:class:`~soabench.experiment.execution.runner.Batch`) serve every variant's run.
    """
    main_dir, out_dir = Path(main_dir), Path(out_dir)
    meta = validate_run_meta(RunStore(main_dir).meta(), str(main_dir / "run.json"))
    outcomes = []
    for key in VARIANTS:
        run_dir = out_dir / key
        if not (run_dir / "run.json").is_file():
            cfg = variant_config(meta.config, key, trials or meta.trials)
            request = RunRequest(cfg, meta.net, meta.polys, meta.scenario, out=run_dir, options=options)
            outcomes.append(run(request, batch))
            continue
        stored = validate_run_meta(RunStore(run_dir).meta(), str(run_dir / "run.json"))
        want = variant_config(meta.config, key, stored.trials).to_dict()
        diffs = config_differences(stored.config.to_dict(), want)
        if diffs or (stored.net, stored.polys, stored.scenario) != (meta.net, meta.polys, meta.scenario):
            listed = "; ".join(f"{k}: {old!r} here, {new!r} in the main run" for k, old, new in diffs[:3]) or "scene"
            raise SoabenchError(
                f"{run_dir} was made from another main protocol ({listed}); remove it to re-run it from {main_dir}"
            )
        target = trials if trials is not None else (max(stored.trials, meta.trials) if follow_main else None)
        requested = None
        if target is not None and target != stored.trials:
            require(
                target > stored.trials,
                f"{run_dir} has {stored.trials} trials; {target} would drop finished ones (ask for more or as many)",
            )
            requested = {"experiment.trials": target}
        request = RunRequest(None, meta.net, resume=run_dir, requested=requested, options=options)
        outcomes.append(run(request, batch))
    return outcomes


def _run_variants_grouped(root: Path, main_dir: Path, trials: int | None, options: RunOptions) -> list[RunOutcome]:
    """:func:`run_variants` with the variants' trials together (:mod:`soabench.experiment.execution.grouped`: SUMO
    and the sensor once per trial; each variant runs its own filters, the main run's are not at hand), then their
    reports, figures drawn on the same worker processes."""

    deferred: list = []
    run_variants(root, main_dir, trials=trials, options=options, batch=Batch(defer=deferred))
    pool = open_executor(options.workers, options.scheduler, options.dask_local)
    aborted = True
    try:
        if deferred:
            run_group(deferred, pool, progress=options.progress, label=root.name)
        with parallel(pool):
            runs = run_variants(root, main_dir, trials=trials, options=options, batch=Batch(run_trials=False))
        aborted = False
    finally:
        pool.close(abort=aborted)
    return runs


@dataclass
class SensitivityOutcome:
    """The variant runs of a main run and the table written from them (``soabench sensitivity``)."""

    run_dir: Path
    runs: list[RunOutcome]
    summary_markdown: str

    @property
    def complete(self) -> bool:
        return all(r.complete for r in self.runs)

    @property
    def n_missing(self) -> int:
        return sum(r.n_missing for r in self.runs)


def run_sensitivity(
    main_dir: Path, out: Path | None = None, *, trials: int | None = None, options: RunOptions = RUN_DEFAULTS
) -> SensitivityOutcome:
    """``soabench sensitivity``: the variants of a finished run and its sensitivity table in ``out``.

    ``out`` defaults to ``<main_dir>_sensitivity`` beside the run. Re-running finishes an interrupted one.
    """
    workers = options.workers
    require(
        trials is None or 1 <= trials <= MAX_TRIALS,
        f"--trials {trials} is out of range; allowed: integers in [1, {MAX_TRIALS}]",
    )
    check_workers(workers)
    main_dir = resolve(Path(main_dir))
    require((main_dir / "run.json").is_file(), f"--main {main_dir}: not a run folder (no run.json)")
    meta = validate_run_meta(RunStore(main_dir).meta(), str(main_dir / "run.json"))
    meta.config.gmphd_only(f"`soabench sensitivity` (--main {main_dir})")
    done = len(RunStore(main_dir).done_trials())
    require(
        done >= meta.trials and (main_dir / "trials.csv").is_file(),
        f"--main {main_dir}: the run is not finished ({done} of {meta.trials} trials); "
        f"finish it first: soabench run --resume {main_dir}",
    )
    root = resolve(Path(out) if out is not None else main_dir.with_name(main_dir.name + "_sensitivity"))
    check_own_folder(root, "sensitivity folder", SENSITIVITY_ENTRIES)
    with FolderLock(root, "sensitivity folder"):
        check_own_folder(root, "sensitivity folder", SENSITIVITY_ENTRIES)
        try:
            runs = _run_variants_grouped(root, main_dir, trials, options)
            md = ""
            if all(r.complete for r in runs):
                md = sens.write_sensitivity(root, main_dir, {k: root / k for k in VARIANTS})
        except KeyboardInterrupt:
            raise Interrupted(
                f"interrupted: the sensitivity runs in {root} are incomplete (finished trials are on disk); "
                f"finish with: soabench sensitivity --main {main_dir} --out {root}"
            ) from None
    return SensitivityOutcome(root, runs, md)
