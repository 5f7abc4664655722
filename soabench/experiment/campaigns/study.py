"""The paper's simulation study as one command: ``soabench study``.

Four parts, each an ordinary (resumable) run or sweep folder under ``OUT`` (default ``results/<net>/``):

* ``main/``: the main protocol (docs/method.md §5.8): six birth models x {static, dynamic}, lambda = 3;
* ``clutter/``: the clutter sweep lambda in {0.5, 3, 5} with precision curves (paper Fig. 5h);
* ``births/``: the N_hat sensitivity sweep N_tot = N_true + {-10..10} (clipped at 1) for S-OA, PUBM and both UBMs;
* ``sensitivity/``: the main protocol again (same trials, duration, seed, models, modes and clutter, read from
  ``main/run.json``) once with the χ² gate off (``gate_off/``) and once scored against visible pedestrians
  (``visible/``), then ``sensitivity.md`` / ``sensitivity.csv``: every headline number under each setting
  (:mod:`soabench.experiment.campaigns.sensitivity`).

``comparison.md`` then puts every headline number of the paper (§5.9) beside ours with paired Wilcoxon tests and
bootstrap intervals (:mod:`soabench.experiment.reports.paper`). Re-running the command on a finished folder re-reports
it;
on an interrupted one it finishes the missing trials.

The four parts run together (:mod:`soabench.experiment.execution.grouped`): trial n runs SUMO once, the sensor once per
clutter rate and every filter run once for all parts (the clutter sweep's λ = 3 runs are the main run's; the
sensitivity runs share the recording and the scans), then writes each part's record into its own folder, so every
folder is what running the parts one after another gives. The reports of all folders are then drawn on the same
worker processes, one figure per task (:mod:`soabench.figures.drawing`).

Run folders outside the study whose trials are its main protocol's (same scene, seed and duration; ``soabench
results`` passes its filter-family runs) join the group as :class:`Companion` folders: their trials reuse the
study's SUMO recording, scans and births, and they are resumed, checked and reported like any run.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from soabench import plugins
from soabench.atomic import write_text_atomic
from soabench.birth import CORE_MODELS
from soabench.config import FILTER_FAMILIES, Config, family_label
from soabench.errors import Interrupted, require
from soabench.experiment.campaigns import sensitivity as sens
from soabench.experiment.campaigns.families import config_families, family_rows, paper_family_rows
from soabench.experiment.campaigns.sensitivity_runs import VARIANTS, run_variants
from soabench.experiment.campaigns.sweep import DEFAULT_VALUES, SweepOutcome, SweepRequest, sweep
from soabench.experiment.execution.executors import open_executor
from soabench.experiment.execution.grouped import run_group
from soabench.experiment.execution.options import RUN_DEFAULTS, RunOptions
from soabench.experiment.execution.runner import ALONE, Batch, RunOutcome, RunRequest, net_name
from soabench.experiment.reports import paper
from soabench.experiment.reports.finished import run
from soabench.experiment.reports.headline import KEY_METRICS, headline
from soabench.experiment.reports.html import write_index
from soabench.experiment.reports.premerge import merged_on
from soabench.experiment.reports.report import families, family_tables, paper_protocol_mismatch
from soabench.experiment.reports.tables import load_tables
from soabench.experiment.runs.runmeta import flatten_config
from soabench.experiment.runs.store import RunStore
from soabench.figures.drawing import parallel
from soabench.folders import FolderLock, check_own_folder, resolve
from soabench.tracks.report import render_hota, track_stats

#: every entry a study folder holds (a folder holding anything else is not a study's and is refused)
STUDY_ENTRIES = ("main", "clutter", "births", "sensitivity", "comparison.md", "key_figure.png", "index.html")


@dataclass
class StudyOutcome:
    """The three parts of a study and where its comparison was written."""

    run_dir: Path
    main: RunOutcome
    clutter: SweepOutcome
    births: SweepOutcome
    summary_markdown: str
    sensitivity: tuple[RunOutcome, ...] = ()
    companions: tuple[RunOutcome, ...] = ()  #: one per :attr:`StudyRequest.companions`, in order

    @property
    def complete(self) -> bool:
        """Every part of the study complete (its companions have their own outcomes)."""
        parts = (self.main, self.clutter, self.births, *self.sensitivity)
        return all(p.complete for p in parts)

    @property
    def n_missing(self) -> int:
        return sum(p.n_missing for p in (self.main, self.clutter, self.births, *self.sensitivity))


@dataclass(frozen=True)
class Companion:
    """A run folder outside the study that runs the study's main protocol trials (same scene, seed, duration and
    trial indices) with another configuration, in the study's group (module docstring).

    ``keys``: the dotted config keys a stored folder must share with ``config`` to be resumed (more trials extend
    it, :mod:`~soabench.experiment.runs.runmeta`)."""

    folder: Path
    config: Config
    keys: tuple[str, ...]

    def run(self, net: str, options: RunOptions, batch: Batch = ALONE) -> RunOutcome:
        """Start the folder, or resume it when it holds a run (``keys`` compared); ``batch``: the study's group, or
        the folder on its own."""
        if (self.folder / "run.json").is_file():
            requested = {k: v for k, v in flatten_config(self.config.to_dict()).items() if k in self.keys}
            return run(RunRequest(None, net, resume=self.folder, requested=requested, options=options), batch)
        return run(RunRequest(self.config, net, out=self.folder, options=options), batch)


def with_plugin_models(config: Config, extra: tuple[str, ...]) -> Config:
    """The study's configuration with plugin birth models ``extra`` beside the six built-in ones (a built-in name
    is refused: the study runs those already)."""
    bad = [m for m in extra if plugins.is_builtin_birth(m)]
    require(not bad, f"`study` runs the six built-in models; --models {','.join(bad)} adds plugins only")
    if not extra:
        return config
    plugins.allow_import_paths(extra)
    config.experiment = dataclasses.replace(config.experiment, models=(*config.experiment.models, *extra))
    return config.validate()


def check_part_trials(sweep_trials: int | None, births_trials: int | None, sensitivity_trials: int | None) -> None:
    """Each part's number of trials, when given, is at least 1."""
    for flag, value in (
        ("sweep_trials", sweep_trials), ("births_trials", births_trials), ("sensitivity_trials", sensitivity_trials)
    ):  # fmt: skip
        require(value is None or value >= 1, f"--{flag.replace('_', '-')} {value} must be >= 1")


def _with_experiment(cfg: Config, **changes) -> Config:
    out = Config.from_dict(cfg.to_dict())
    out.experiment = dataclasses.replace(out.experiment, **changes)
    return out.validate()


@dataclass(frozen=True)
class PartTrials:
    """Trials of the study's parts beside the main protocol's (``config.experiment.trials``)."""

    sweep: int | None = None  #: the clutter sweep (default: as many as the main protocol)
    births: int = 30  #: per N_tot point of the N_hat sweep, static only (21 offsets make it the costliest part)
    sensitivity: int | None = None  #: each sensitivity run (default: as many as the main run has)


@dataclass(frozen=True)
class StudyRequest:
    """What a study is asked to do; ``config.experiment`` gives trials, duration and seed of the main protocol.

    ``explicit``: the dotted config keys the user asked for (command-line flags, config file keys; ``trials`` of a
    part only when its own flag was given: ``sweep_trials``, ``births_trials``, ``sensitivity_trials``). On a re-run
    each part compares them with its stored configuration and refuses differences, except more trials (see
    :mod:`~soabench.experiment.runs.runmeta`); empty compares nothing. ``grouped``: False runs the parts one after
    another (the same results, slower; for benchmarks). ``options``: how every part runs
    (:class:`~soabench.experiment.execution.options.RunOptions`; fail_fast and save_estimates are not the study's:
    refused); ``options.figures`` True also draws the figures of every N̂ point and of both sensitivity runs (by
    default ``births/sweep_births.png`` and ``sensitivity/sensitivity.md`` summarise those folders, which get tables
    and summaries only). ``companions``: run folders outside the study that run its main protocol's trials with
    other settings, in its group (:class:`Companion`).
    """

    config: Config
    net: str = "intersection"
    out: Path | None = None
    trials: PartTrials = PartTrials()
    options: RunOptions = RUN_DEFAULTS
    explicit: frozenset[str] = frozenset()
    grouped: bool = True
    companions: tuple[Companion, ...] = ()


def run_study(
    config: Config,
    net: str = "intersection",
    *,
    sweep_trials: int | None = None,
    births_trials: int = 30,
    sensitivity_trials: int | None = None,
    explicit: set[str] | None = None,
    **fields: Any,
) -> StudyOutcome:
    """:func:`study` of a :class:`StudyRequest` (``fields``: ``out``, ``options``, ``grouped``, ``companions``)."""
    trials = PartTrials(sweep_trials, births_trials, sensitivity_trials)
    return study(StudyRequest(config, net, trials=trials, explicit=frozenset(explicit or ()), **fields))


def study(request: StudyRequest) -> StudyOutcome:
    """Run (or finish) the study: its parts, then the comparison with the paper, the sensitivity table and the
    index page."""
    options, config = request.options, request.config
    require(not options.save_estimates, "--save-estimates is not offered by `study`; use `run`")
    require(not options.fail_fast, "--fail-fast is not offered by `study`; use `run`")
    require(
        FILTER_FAMILIES[0] in config.experiment.filters,
        f"experiment.filters = {list(config.experiment.filters)!r}: `study` compares with the paper in the "
        f"{family_label(FILTER_FAMILIES[0])} family; add {FILTER_FAMILIES[0]} (--filters "
        f"{','.join((FILTER_FAMILIES[0], *config.experiment.filters))})",
    )
    root = resolve(request.out if request.out is not None else Path("results") / net_name(request.net))
    check_own_folder(root, "study folder", STUDY_ENTRIES)
    parts = _Parts(request, root)
    with FolderLock(root, "study folder"):
        check_own_folder(root, "study folder", STUDY_ENTRIES)  # again, under the lock
        try:
            main, clutter, births, sensitivity, companions = (
                parts.run_grouped() if request.grouped else parts.run_serial()
            )
            md = _finish(root, main, sensitivity)
        except KeyboardInterrupt:
            raise Interrupted(
                f"interrupted: the study in {root} is incomplete (finished trials are on disk); "
                f"finish with: soabench study --out {root}"
            ) from None
    return StudyOutcome(root, main, clutter, births, md, tuple(sensitivity), tuple(companions))


#: main, clutter sweep, N̂ sweep, sensitivity runs, companion runs
_AllParts = tuple[RunOutcome, SweepOutcome, SweepOutcome, list[RunOutcome], list[RunOutcome]]


class _Parts:
    """The parts of one study in ``root``: main run, clutter sweep, N̂ sweep, sensitivity runs (each created,
    checked and resumed as usual)."""

    def __init__(self, request: StudyRequest, root: Path):
        self.request, self.root = request, root
        config, trials, options = request.config, request.trials, request.options
        self.clutter_cfg = _with_experiment(config, trials=trials.sweep or config.experiment.trials)
        self.births_cfg = _with_experiment(config, trials=trials.births, models=CORE_MODELS, probabilities=("static",))
        all_figures = options.figures is True
        self.options = dataclasses.replace(options, figures=None)  # main run, clutter sweep: their own defaults
        self.births_options = dataclasses.replace(options, figures=True if all_figures else None)
        self.sens_options = dataclasses.replace(options, figures=all_figures)
        self.main_dir, self.clutter_dir, self.births_dir = root / "main", root / "clutter", root / "births"
        self.sens_dir = root / "sensitivity"
        # the sensitivity runs follow --trials like the clutter sweep
        self.follow = trials.sensitivity is None and "experiment.trials" in request.explicit

    def requested(self, cfg: Config, trials_key: str | None, skip: tuple[str, ...] = ()) -> dict:
        """What a re-run asks of a part: the explicit keys (``trials_key`` standing for its trials) in ``cfg``."""
        explicit = self.request.explicit
        keys = {k for k in explicit if k != "experiment.trials" and k not in skip}
        if trials_key in explicit:
            keys.add("experiment.trials")
        flat = flatten_config(cfg.to_dict())
        return {k: flat[k] for k in keys if k in flat}

    def main(self, batch: Batch) -> RunOutcome:
        net, main_dir = self.request.net, self.main_dir
        if (main_dir / "run.json").is_file():
            req = self.requested(self.request.config, "experiment.trials")
            return run(RunRequest(None, net, resume=main_dir, requested=req, options=self.options), batch)
        return run(RunRequest(self.request.config, net, out=main_dir, options=self.options), batch)

    def clutter(self, batch: Batch) -> SweepOutcome:
        net, folder, explicit = self.request.net, self.clutter_dir, self.request.explicit
        if (folder / "sweep.json").is_file():
            trials_key = "experiment.trials" if "sweep_trials" in explicit else None
            if self.request.trials.sweep is None and "experiment.trials" in explicit:
                trials_key = "experiment.trials"  # the clutter sweep follows --trials by default
            req = self.requested(self.clutter_cfg, trials_key, skip=("experiment.clutter",))
            return sweep(SweepRequest("clutter", (), RunRequest(None, net, resume=folder, requested=req,
                                                                options=self.options)), batch)  # fmt: skip
        part = RunRequest(self.clutter_cfg, net, out=folder, options=self.options)
        return sweep(SweepRequest("clutter", DEFAULT_VALUES["clutter"], part), batch)

    def births(self, batch: Batch) -> SweepOutcome:
        net, folder, grouped = self.request.net, self.births_dir, self.request.grouped
        if (folder / "sweep.json").is_file():
            trials_key = "experiment.trials" if "births_trials" in self.request.explicit else None
            req = self.requested(self.births_cfg, trials_key, skip=("experiment.models", "experiment.probabilities"))
            part = RunRequest(None, net, resume=folder, requested=req, options=self.births_options)
            return sweep(SweepRequest("births", (), part, grouped=grouped), batch)
        part = RunRequest(self.births_cfg, net, out=folder, options=self.births_options)
        return sweep(SweepRequest("births", DEFAULT_VALUES["births"], part, grouped=grouped), batch)

    def sensitivity(self, batch: Batch) -> list[RunOutcome]:
        return run_variants(self.sens_dir, self.main_dir, trials=self.request.trials.sensitivity,
                            follow_main=self.follow, options=self.sens_options, batch=batch)  # fmt: skip

    def all(self, batch: Batch) -> _AllParts:
        main, clutter, births = self.main(batch), self.clutter(batch), self.births(batch)
        sensitivity = self.sensitivity(batch)
        companions = [c.run(self.request.net, self.options, batch) for c in self.request.companions]
        return main, clutter, births, sensitivity, companions

    def run_serial(self) -> _AllParts:
        """The parts one after another."""
        return self.all(ALONE)

    def run_grouped(self) -> _AllParts:
        """The parts' trials together (:mod:`soabench.experiment.execution.grouped`) on one pool, then the reports
        of the parts that attempted every trial, each folder merged by a worker first."""
        deferred: list = []
        self.all(Batch(defer=deferred))
        options = self.request.options
        pool = open_executor(options.workers, options.scheduler, options.dask_local)  # the trials', then the figures'
        aborted = True
        try:
            if deferred:
                run_group(deferred, pool, progress=options.progress, label=self.root.name)
            with parallel(pool), merged_on(pool, deferred):
                parts = self.all(Batch(run_trials=False))
            aborted = False
            return parts
        finally:
            pool.close(abort=aborted)


def _finish(root: Path, main: RunOutcome, sensitivity: Sequence[RunOutcome]) -> str:
    """The comparison with the paper, the sensitivity table (once their runs are complete) and the index page;
    the study's closing lines."""
    main_dir, sens_dir = root / "main", root / "sensitivity"
    md = ""
    if main.complete:  # the paper's numbers only beside the paper's protocol on the shipped intersection
        mismatch = paper_protocol_mismatch(RunStore(main_dir).meta())
        md = f"No comparison with the paper: {mismatch}.\n" if mismatch else write_comparison(root)
    if main.complete and all(o.complete for o in sensitivity):
        variants = {k: sens_dir / k for k in VARIANTS}
        sens.write_sensitivity(sens_dir, main_dir, variants)
        where = sens_dir / "sensitivity.md"
        md += f"\nSensitivity to the gate, the truth set and the probability mode: {where}\n"
    index = write_index(root)[0]  # and each run's report.html (a run kept from before may have none)
    md += f"\nEvery part on one page: {index}\n"
    return md


def _precision_table(rows: list[dict]) -> str:
    prec = paper.precision_by_clutter(rows)
    lams = sorted({k[2] for k in prec})
    models = [m for m in ("soa", *paper.BASELINES) if any(k[1] == m for k in prec)]
    lines = ["| mode | model | " + " | ".join(f"λ = {lam:g}" for lam in lams) + " |", "|---|---|" + "---:|" * len(lams)]
    for mode in [m for m in ("static", "dynamic") if any(k[0] == m for k in prec)]:
        for m in models:
            cells = [f"{prec[(mode, m, lam)]:.3f}" if (mode, m, lam) in prec else "n/a" for lam in lams]
            lines.append(f"| {mode} | {paper.LABEL[m]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _ratio_table(rows: list[dict]) -> str:
    ratios = paper.component_ratios(rows)
    models = ["soa", *paper.BASELINES]
    lines = ["| mode | " + " | ".join(paper.LABEL[m] for m in models) + " |", "|---|" + "---:|" * len(models)]
    for mode in ("static", "dynamic"):
        if any(k[0] == mode for k in ratios):
            lines.append(
                f"| {mode} | " + " | ".join(f"{ratios.get((mode, m), float('nan')):.2f}" for m in models) + " |"
            )
    return "\n".join(lines)


def _tracks_table(rows: list[dict]) -> list[str]:
    """HOTA, IDF1 and ID switches per clutter rate, model and mode of the main protocol (nothing without labels)."""
    out = []
    for key in dict.fromkeys((r["clutter"], r["model"], r["mode"]) for r in rows):
        sel = [r for r in rows if (r["clutter"], r["model"], r["mode"]) == key]
        st = track_stats(lambda name, sel=sel: np.array([r.get(name, math.nan) for r in sel], dtype=float))
        out.append((f"{key[0]:g}", paper.LABEL.get(key[1], key[1]), key[2], st))
    return render_hota("λ", out)


def key_figure(root: Path) -> Path | None:
    """The README's key figure, ``key_figure.png`` of a study folder: the forest plot of S-OA's paired differences
    on the main protocol at λ = 3 (delay, cardinality error, OSPA, precision; :mod:`soabench.figures.forest`), drawn
    from ``main/`` (its GM-PHD family). None when the folder holds no finished main run with S-OA at λ = 3."""
    # imported when called: matplotlib would slow every start-up
    from soabench.figures.forest import forest_figure
    from soabench.figures.style import save_png

    main = Path(root) / "main"
    if not (main / "trials.csv").is_file() or not (main / "run.json").is_file():
        return None
    tables = load_tables(main)
    tables = family_tables(tables, families(tables)[0])
    if "soa" not in tables.models or len(tables.models) < 2 or paper.PAPER_CLUTTER not in tables.clutters:
        return None
    return save_png(forest_figure(headline(tables, paper.PAPER_CLUTTER), KEY_METRICS), Path(root) / "key_figure.png")


def write_comparison(root: Path) -> str:
    """``comparison.md``: the paper's headline numbers beside ours, from the committed CSV files alone (in the
    GM-PHD family, the paper's filter; the Tracks tables per filter family)."""
    root = Path(root)
    all_rows = paper.read_rows(root / "main" / "trials.csv")
    main_rows = paper_family_rows(all_rows)
    families = config_families(RunStore(root / "main").meta()["config"])
    parts = [
        "# The paper's simulation study on the shipped intersection: paper vs soabench",
        "",
        "Generated by `soabench study` from `main/trials.csv`, `clutter/points/*/trials.csv` and `births/`"
        + ("." if families == [None] else "; the paper's numbers in its filter family, the GM-PHD."),
        "",
        "## Main protocol (λ = 3)",
        "",
        paper.markdown(main_rows),
        "",
        "### Mean posterior components relative to S-OA (paper: UBM ≈ 5-6 × S-OA on KITTI; S-OA lowest)",
        "",
        _ratio_table(main_rows),
    ]
    for family in families:
        hota = _tracks_table(family_rows(all_rows, family))
        if hota:
            title = "Tracks" if family is None else f"Tracks, {family_label(family)}"
            parts += ["", f"### {title} (docs/method.md §9.3): mean ± σ over trials; — for a tracker without labels"]
            parts += ["", *hota]
    clutter_rows = [
        r
        for f in sorted((root / "clutter" / "points").glob("*/trials.csv"))
        for r in paper_family_rows(paper.read_rows(f))
    ]
    if clutter_rows:
        parts += [
            "",
            "## Precision under clutter (paper Fig. 5h: ATBM falls sharply from λ = 0.5 to 5, S-OA stays high)",
            "",
            "Mean per-trial precision of the extracted estimates (gated Hungarian matching, 5 m).",
            "",
            _precision_table(clutter_rows),
        ]
    key_figure(root)
    births_md = root / "births" / "sweep.md"
    if births_md.is_file():
        parts += ["", "## Sensitivity to N_hat (paper §V.C)", "", births_md.read_text(encoding="utf-8").strip()]
    md = "\n".join(parts) + "\n"
    write_text_atomic(root / "comparison.md", md)
    return md
