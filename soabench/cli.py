"""The ``soabench`` command line: thin handlers over the pipeline (docs/development.md).

Subcommands: ``scene`` (Fig. 3 bird's-eye view, optional sensor overlay), ``record`` (ground truth and scans to
.npz), ``birth`` (birth components of one model over the scene), ``run`` (the Monte Carlo protocol), ``sweep``
(clutter, N_hat or occluder-density sensitivity), ``scenes`` (the shipped scenes), ``import osm`` (an OpenStreetMap
extract as a scene folder), ``replay`` (one trial of a finished run as an HTML page) and ``report`` (a run
folder's HTML page; both in :mod:`soabench.replay`). ``--net all`` runs a command on every shipped scene. Any error a
user can cause prints one line and exits with status 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from soabench import cli_checks
from soabench.config import (
    BIRTH_MODEL_NAMES,
    FILTER_FAMILIES,
    PROBABILITY_MODES,
    Config,
    filter_config_for_mode,
    load_config,
)
from soabench.errors import Interrupted, SoabenchError, require

EXIT_USAGE = 2


# ----------------------------------------------------------------------------------------------- argument parsing
def _csv_list(kind: str, allowed: Sequence[str] | None = None):
    def parse(text: str) -> tuple[str, ...]:
        items = tuple(s.strip() for s in text.split(",") if s.strip())
        if not items:
            raise argparse.ArgumentTypeError(f"{kind} list {text!r} is empty")
        if allowed is not None:
            bad = [s for s in items if s not in allowed]
            if bad:
                raise argparse.ArgumentTypeError(f"{kind} {bad[0]!r} is unknown; choose from {', '.join(allowed)}")
        return items

    return parse


def _float_list(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of numbers") from None
    if not values:
        raise argparse.ArgumentTypeError(f"{text!r} gives no numbers")
    return values


MAX_OFFSETS = 1001  #: values of one --offsets / --nhat-sweep (e.g. -500:500)
MAX_OFFSET = 10_000  #: largest |offset| (N_hat itself is at most 10000: soabench/config.py)


def _offsets(text: str) -> tuple[int, ...]:
    """``-10:10`` (inclusive range), ``-10:10:2`` (with step) or ``-5,0,5``; at most :data:`MAX_OFFSETS` values,
    each in [-MAX_OFFSET, MAX_OFFSET] (checked before a range is expanded)."""
    try:
        if ":" in text:
            parts = [int(p) for p in text.split(":")]
            require(len(parts) in (2, 3), "")
            lo, hi = parts[0], parts[1]
            step = parts[2] if len(parts) == 3 else 1
            require(step > 0 and hi >= lo, "")
            values: Sequence[int] = range(lo, hi + 1, step)
        else:
            values = [int(s) for s in text.split(",") if s.strip()]
    except (ValueError, SoabenchError):
        raise argparse.ArgumentTypeError(
            f"offsets {text!r} must be LO:HI, LO:HI:STEP (integers, HI >= LO, STEP > 0) or a comma list of integers"
        ) from None
    if not values:
        raise argparse.ArgumentTypeError(f"offsets {text!r} give no value")
    low, high = (values[0], values[-1]) if isinstance(values, range) else (min(values), max(values))
    if len(values) > MAX_OFFSETS or max(-low, high) > MAX_OFFSET:
        raise argparse.ArgumentTypeError(
            f"offsets {text!r} give {len(values)} values from {low} to {high}; allowed: at most "
            f"{MAX_OFFSETS} values, each in [-{MAX_OFFSET}, {MAX_OFFSET}]"
        )
    return tuple(values)


def _add_net_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--net",
        default="intersection",
        help="shipped scene name, 'all' (every shipped scene), a scene folder or a path to a .net.xml",
    )
    p.add_argument(
        "--poly",
        action="append",
        default=[],
        metavar="FILE",
        help="polygon file (buildings, obstacles); repeatable (default: only the scenario's own)",
    )
    p.add_argument(
        "--scenario",
        metavar="FILE.toml",
        help="scenario file (default: the shipped net's own; for a user net, defaults derived from the net)",
    )
    p.add_argument(
        "--config",
        metavar="FILE.toml",
        help="parameters, section by section (docs/method.md §7; default: the built-in defaults, soabench/config.py)",
    )


def _add_snapshot_args(p: argparse.ArgumentParser, need_out: bool = True) -> None:
    _add_net_args(p)
    p.add_argument("--seed", type=int, default=0, help="base seed (as in `run`)")
    p.add_argument("--trial", type=int, default=0, help="trial index under the base seed (as in `run`)")
    p.add_argument("--out", required=need_out, help="output file")


def _add_run_args(p: argparse.ArgumentParser) -> None:
    _add_net_args(p)
    p.add_argument("--trials", type=int, help="Monte Carlo trials (default 100)")
    p.add_argument("--duration", type=float, help="seconds per trial (default 100)")
    p.add_argument(
        "--models",
        type=_csv_list("model"),
        help="birth models: soa,pubm,ubm,ubm-ws,atbm,gmbm (default: all six), installed plugins, or module:Class",
    )
    p.add_argument(
        "--trackers",
        type=_csv_list("tracker"),
        help="whole trackers beside them: stonesoup-gmphd, stonesoup-gnn, installed plugins, or module:Class "
        "(default: none)",
    )
    p.add_argument(
        "--probabilities",
        type=_csv_list("probability mode", PROBABILITY_MODES),
        help="static,dynamic (default) or dynamic+occ",
    )
    p.add_argument("--seed", type=int, help="base seed (default 0)")
    p.add_argument("--workers", type=int, help="process workers (default: every core)")
    p.add_argument("--out", type=Path, help="run folder (default results/<scenario name>/<timestamp>/)")
    p.add_argument("--save-estimates", action="store_true", help="also write the per-scan estimates")
    p.add_argument(
        "--scheduler", metavar="tcp://HOST:PORT", help="submit trials to this Dask scheduler (default: no Dask)"
    )
    p.add_argument(
        "--dask", choices=["local"], help="start a Dask LocalCluster (processes, one thread each; default: no Dask)"
    )
    p.add_argument("--fail-fast", action="store_true", help="stop at the first failed trial")
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress report (default: a bar on a terminal, a line every 10 s or 5%% of the trials otherwise)",
    )


class OneLineParser(argparse.ArgumentParser):
    """A usage error is one line, like every other error: ``soabench: error: <command>: <what> (see ... --help)``."""

    def error(self, message: str):  # type: ignore[override]
        where = self.prog.removeprefix("soabench").strip()
        self.exit(EXIT_USAGE, f"soabench: error: {where + ': ' if where else ''}{message} (see {self.prog} --help)\n")


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """``--help`` shows every option's default: appended as "(default: X)" unless the help text already says it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        unset = any(action.default is v for v in (None, False, argparse.SUPPRESS))  # flags, optional values
        if "default" in text or not action.option_strings or unset:
            return text
        value = ", ".join(map(str, action.default)) if isinstance(action.default, list) else "%(default)s"
        return f"{text} (default: {value or 'none'})"


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="soabench",
        formatter_class=DefaultsHelpFormatter,
        description="Where should a multi-target filter expect new targets to appear? "
        "GM-PHD birth models (S-OA and four baselines) on SUMO scenarios.",
    )
    from soabench import __version__

    parser.add_argument("--version", action="version", version=f"soabench {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("scene", help="bird's-eye view of a scenario (paper Fig. 3)")
    _add_snapshot_args(p)
    p.add_argument("--time", type=float, default=50.0, help="time of the snapshot (s)")
    p.add_argument("--sensor", action="store_true", help="overlay FOV, sight lines, measurements, obstacle cones")

    p = sub.add_parser("record", help="write the ground truth (and scans) of one scenario run to .npz")
    _add_snapshot_args(p)
    p.add_argument("--duration", type=float, help="seconds (default: the scenario's)")
    p.add_argument(
        "--scans",
        nargs="?",
        const="",
        default=None,
        metavar="FILE",
        help="also write the sensor scans (default file: OUT with .scans.npz)",
    )

    p = sub.add_parser("birth", help="birth components of one model over the scene (paper Fig. 2 colours)")
    _add_snapshot_args(p)
    p.add_argument("--time", type=float, default=50.0, help="time of the snapshot (s)")
    p.add_argument("--model", default="soa", help="soa, pubm, ubm, atbm, gmbm, an installed plugin or module:Class")
    p.add_argument("--probability", default="static", choices=PROBABILITY_MODES, help="probability mode")

    p = sub.add_parser("run", help="the Monte Carlo protocol (default: the paper's)")
    _add_run_args(p)
    p.add_argument(
        "--filters",
        type=_csv_list("filter family", FILTER_FAMILIES),
        help="filter families every birth model runs in: gmphd (default), lmb (labelled multi-Bernoulli: static "
        "probabilities only), or both",
    )
    p.add_argument("--clutter", type=_float_list, help="clutter rate(s) lambda, e.g. 3 or 0.5,3,5 (default 3)")
    p.add_argument(
        "--resume", type=Path, metavar="RUN_DIR", help="finish the missing trials of an earlier run (default: new run)"
    )

    p = sub.add_parser("sweep", help="parameter sweeps: clutter rate or expected births N_hat")
    p.add_argument("kind", choices=["clutter", "births", "occlusion"])
    _add_run_args(p)
    p.add_argument(
        "--values",
        type=_float_list,
        help="clutter rates for `sweep clutter` (default 0.5,3,5); parked cars per 100 m of kerb for "
        "`sweep occlusion` (default 0,4,8,12)",
    )
    p.add_argument("--offsets", type=_offsets, help="N_tot offsets for `sweep births` (default -10:10)")
    p.add_argument("--clutter", type=_float_list, help="clutter rate for `sweep births` (default 3)")
    p.add_argument(
        "--all-figures",
        action="store_true",
        help="`sweep births`: also draw every N_tot point's own figures (default: sweep_births.png summarises them; "
        "clutter and occlusion points always get theirs)",
    )
    p.add_argument(
        "--resume",
        type=Path,
        metavar="SWEEP_DIR",
        help="finish the missing trials of an earlier sweep (default: a new sweep)",
    )

    p = sub.add_parser(
        "study",
        help="the paper's whole simulation study: main protocol, clutter sweep, N_hat sweep, sensitivity, comparison",
    )
    _add_run_args(p)
    p.add_argument("--sweep-trials", type=int, help="trials of the clutter sweep (default: --trials)")
    p.add_argument("--births-trials", type=int, default=30, help="trials per point of the N_hat sweep (default 30)")
    p.add_argument(
        "--sensitivity-trials", type=int, help="trials of each sensitivity run (default: the main run's trials)"
    )
    p.add_argument(
        "--all-figures",
        action="store_true",
        help="also draw the figures of the N_hat sweep's points and of the sensitivity runs (default: "
        "births/sweep_births.png and sensitivity/sensitivity.md summarise them)",
    )

    p = sub.add_parser(
        "sensitivity", help="a finished run again with the gate off and with visible truth, and the sensitivity table"
    )
    p.add_argument("--main", type=Path, required=True, metavar="RUN_DIR", help="the finished run (default: none)")
    p.add_argument("--out", type=Path, help="folder of the variant runs and the table (default RUN_DIR_sensitivity)")
    p.add_argument("--trials", type=int, help="trials of each variant run (default: the main run's)")
    p.add_argument("--workers", type=int, help="process workers (default: every core)")
    p.add_argument("--no-progress", action="store_true", help="no progress report")

    p = sub.add_parser("results", help="regenerate all of results/: study, every scene, summary, KITTI")
    from soabench.experiment.results_suite import add_arguments as add_results_arguments

    add_results_arguments(p, _csv_list)

    p = sub.add_parser("kitti", help="the paper's KITTI protocol (k-fold N_hat, Table I, Figs. 6-8)")
    p.add_argument(
        "--root",
        help="KITTI tracking folder holding label_02/ (and calib/, oxts/); required unless --resume (default: none)",
    )
    p.add_argument("--detections", help="detections, KITTI result or AB3DMOT format (default ROOT/detections)")
    p.add_argument(
        "--semantics",
        help="per-frame bird's-eye semantic polygons per sequence (default: none)",
    )
    p.add_argument(
        "--point-labels", help="SemanticKITTI .label files XXXX/NNNNNN.label: S-OA's region from them (default: none)"
    )
    p.add_argument("--velodyne", help="KITTI scans XXXX/NNNNNN.bin for --point-labels (default ROOT/velodyne)")
    p.add_argument("--lidar-grid", type=float, help="raster cell (m) of the region from points (default 0.5)")
    p.add_argument("--lidar-closing", type=float, help="closing radius (m) of the region from points (default 1.0)")
    p.add_argument("--lidar-fill", type=float, help="longest gap (m) filled along a scan sector (default 8.0)")
    p.add_argument("--sequences", help="e.g. 0000-0020 or 0,3,5 (default: every labelled sequence)")
    p.add_argument("--folds", type=int, default=7, help="cross-validation folds (default 7; at most one per sequence)")
    p.add_argument("--nhat-sweep", type=_offsets, help="N_hat offsets per sequence, e.g. -10:10 (default: no sweep)")
    p.add_argument("--models", type=_csv_list("model", BIRTH_MODEL_NAMES), help="default soa,pubm,ubm,ubm-ws")
    p.add_argument("--probability", choices=PROBABILITY_MODES, help="probability mode (default static)")
    p.add_argument(
        "--config",
        metavar="FILE.toml",
        help="parameters, plus a [kitti] section (default: the protocol's)",
    )
    p.add_argument("--seed", type=int, help="base seed of the birth placement (default 0)")
    p.add_argument("--classes", type=_csv_list("class"), help="tracked classes (default Pedestrian,Cyclist)")
    p.add_argument("--score-min", type=float, help="drop detections scoring below this (default: keep all)")
    p.add_argument("--skip-bad", action="store_true", help="skip (and report) sequences with malformed files")
    p.add_argument("--out", type=Path, help="run folder to create (default: none; needed unless --resume)")
    p.add_argument(
        "--resume",
        type=Path,
        metavar="RUN",
        help="finish an interrupted `soabench kitti` run (default: start a new one)",
    )

    p = sub.add_parser("export", help="write SUMO trials in another format (kitti: the KITTI tracking layout)")
    p.add_argument("format", choices=["kitti"])
    _add_net_args(p)
    p.add_argument("--trials", type=int, required=True, help="trials, written as sequences 0000, 0001, ...")
    p.add_argument("--duration", type=float, help="seconds per trial (default: the scenario's)")
    p.add_argument("--seed", type=int, help="base seed (as in `run`, default 0)")
    p.add_argument("--fov-deg", type=float, help="camera horizontal FOV (default: the nominal KITTI camera's)")
    p.add_argument("--out", required=True, help="output folder (KITTI layout)")
    p.add_argument("--lidar", action="store_true", help="also write synthetic velodyne scans and SemanticKITTI labels")

    p = sub.add_parser("check", help="CI mode: short scenarios against per-metric thresholds (exit 1 on regression)")
    p.add_argument("--suite", required=True, metavar="FILE.toml", help="scenarios and thresholds")
    p.add_argument("--out", type=Path, default=Path("check-results"), help="check.json, junit.xml, run folders")
    p.add_argument("--update-baseline", action="store_true", help="rewrite the suite's baseline JSON from this run")
    p.add_argument("--workers", type=int, default=1, help="process workers per run (default 1)")
    p.add_argument(
        "--plugin",
        action="append",
        default=[],
        metavar="MODULE:CLASS",
        help="allow this import-path plugin named by the suite (entry points need nothing); repeatable",
    )

    from soabench.replay.commands import add_replay_parser, add_report_parser

    add_replay_parser(sub, _csv_list)
    add_report_parser(sub)

    sub.add_parser("scenes", help="the shipped scenes: size, lanes, pedestrians, occluders, what each tests")
    p = sub.add_parser("import", help="turn an OpenStreetMap extract into a scene folder for --net")
    p.add_argument("kind", choices=["osm"])
    p.add_argument("file", metavar="FILE.osm")
    p.add_argument("--out", required=True, help="scene folder to write (new or empty)")
    p.add_argument(
        "--force", action="store_true", help="import a file above the size limit (soabench/scenario/osm.py MAX_OSM_MB)"
    )
    for command in sub.choices.values():  # subparsers do not inherit the formatter
        command.formatter_class = DefaultsHelpFormatter
    return parser


# ------------------------------------------------------------------------------------------------------ helpers
def _config_from_args(args: argparse.Namespace) -> Config:
    """The config file (if any) overlaid by the command-line flags, validated."""
    _allow_typed_plugins(args)
    cfg = load_config(getattr(args, "config", None))
    exp = cfg.experiment
    overrides = {
        "trials": getattr(args, "trials", None),
        "duration": getattr(args, "duration", None),
        "models": getattr(args, "models", None),
        "trackers": getattr(args, "trackers", None),
        "probabilities": getattr(args, "probabilities", None),
        "filters": getattr(args, "filters", None),
        "clutter": getattr(args, "clutter", None),
        "seed": getattr(args, "seed", None),
    }
    cfg.experiment = dataclasses.replace(exp, **{k: v for k, v in overrides.items() if v is not None})
    return cfg.validate()


def _allow_typed_plugins(args: argparse.Namespace) -> None:
    """The ``module:Class`` names typed with --models/--trackers join this run's closed list (soabench.plugins)."""
    from soabench import plugins

    plugins.allow_import_paths([*(getattr(args, "models", None) or ()), *(getattr(args, "trackers", None) or ())])


def _load_scene(args: argparse.Namespace):
    from soabench.scenario import load

    return load(args.net, tuple(args.poly), args.scenario)


def _snapshot(args: argparse.Namespace, duration: float | None, include_end: bool = False):
    """Scene, scenario, config, trial seeds and the recording up to ``duration`` seconds (None: the scenario's).

    ``include_end``: simulate one SUMO step more so that a sample (and a scan, when ``duration`` is a multiple of
    the sensor period) lies exactly at ``duration``: a snapshot at ``--time 50`` shows the scan at t = 50 s.
    """
    from soabench.config import MAX_SEED, MAX_TRIALS

    require(
        0 <= args.seed <= MAX_SEED,
        f"--seed {args.seed} must be >= 0"
        if args.seed < 0
        else f"--seed {args.seed} is out of range; allowed: 0 to {MAX_SEED}",
    )
    require(
        0 <= args.trial < MAX_TRIALS,
        f"--trial {args.trial} must be >= 0"
        if args.trial < 0
        else f"--trial {args.trial} is out of range; allowed: 0 to {MAX_TRIALS - 1} (a run's trial indices)",
    )
    cli_checks.check_time("--time/--duration", duration)
    cfg = load_config(args.config)
    cfg.single_clutter_rate(f"`soabench {args.command}`")
    from soabench.scenario import simulate
    from soabench.seeding import trial_seeds

    scene, scenario = _load_scene(args)
    duration = float(scenario.duration) if duration is None else duration
    require(duration > 0, f"--time/--duration {duration!r} must be > 0")
    cfg.sensor.validate(scenario.step_length)
    seeds = trial_seeds(args.seed, args.trial)
    if include_end:
        duration = duration + scenario.step_length
    recording = simulate(scene, scenario, seeds, duration=duration)
    return scene, scenario, cfg, seeds, recording


def _observe(recording, scene, cfg: Config, seeds):
    from soabench.sensor import observe

    return observe(recording, scene, cfg.sensor, seeds.sensor_rngs())


def _prepare_out(path: str, suffix: str, flag: str = "--out") -> Path:
    return cli_checks.check_out_file(path, suffix, flag)


def _save_figure(fig, out: Path) -> None:
    from soabench.plotstyle import save_png

    save_png(fig, out)


# ----------------------------------------------------------------------------------------------------- commands
def cmd_scene(args: argparse.Namespace) -> int:
    from soabench.scenario.plots import plot_scene, scene_figure

    out = _prepare_out(args.out, ".png")
    scene, _, cfg, seeds, recording = _snapshot(args, args.time, include_end=True)
    fig, ax = scene_figure(scene, legend_rows=6 if args.sensor else 3)
    if args.sensor:
        from soabench.sensor_plot import draw_sensor_overlay

        scans = _observe(recording, scene, cfg, seeds)
        plot_scene(scene, recording, time=scans.scans[-1].t, ax=ax)  # the scene at the overlaid scan's time
        draw_sensor_overlay(ax, scans, len(scans) - 1, cfg.sensor)
    else:
        plot_scene(scene, recording, time=args.time, ax=ax)
    _save_figure(fig, out)
    print(f"wrote {out}")
    return 0


def cmd_record(args: argparse.Namespace) -> int:
    out = _prepare_out(args.out, ".npz")
    scans_out = None
    if args.scans is not None:
        scans_out = (
            _prepare_out(args.scans, ".npz", "--scans") if args.scans else out.with_name(out.stem + ".scans.npz")
        )
        require(scans_out != out, f"--scans {args.scans!r} is the --out file; give the scans their own file")
    scene, _, cfg, seeds, recording = _snapshot(args, args.duration)
    recording.save_npz(out)
    print(f"wrote {out} ({len(recording.t)} steps, {len(recording.ped_ids)} pedestrians)")
    if scans_out is not None:
        scans = _observe(recording, scene, cfg, seeds)
        scans.save_npz(scans_out)
        n_meas = sum(len(s.Z) for s in scans.scans)
        print(f"wrote {scans_out} ({len(scans)} scans, {n_meas} measurements)")
    return 0


def cmd_birth(args: argparse.Namespace) -> int:
    from soabench import plugins
    from soabench.birth import LABEL
    from soabench.birth.base import BirthContext
    from soabench.birth.plots import draw_births
    from soabench.experiment.guard import check_births
    from soabench.gmphd.filter import GMPHDFilter
    from soabench.plotstyle import panel_title
    from soabench.scenario.plots import plot_scene, scene_figure

    out = _prepare_out(args.out, ".png")
    plugins.allow_import_paths([args.model])
    cls = plugins.resolve(plugins.BIRTH, args.model)  # an unknown or broken model fails before SUMO runs
    scene, _, cfg, seeds, recording = _snapshot(args, args.time, include_end=True)
    scans = _observe(recording, scene, cfg, seeds)
    options = {} if plugins.is_builtin_birth(args.model) else cfg.plugins.get(args.model, {})
    plugins.check_options(plugins.BIRTH, args.model, cls, options)
    filter_cfg, mode, p_D_b = filter_config_for_mode(cfg.filter, args.probability)
    filt = GMPHDFilter(filter_cfg, cfg.sensor, mode)
    prev = None
    births = None
    try:
        model = cls(cfg.birth, cfg.sensor, scene, seeds.placement_rng(), **options)
        for scan in scans.scans:  # run the filter up to the snapshot so stateful models see their history
            births = model(BirthContext(scan, prev, p_D_b))
            if not plugins.is_builtin_birth(args.model):
                births = check_births(births, scan)
            prev = filt.step(scan, births)
    except Exception as exc:  # a plugin's error is one line naming it; a built-in's is a bug of soabench
        if plugins.is_builtin_birth(args.model):
            raise
        raise plugins.PluginError(f"birth model plugin {args.model!r} failed: {type(exc).__name__}: {exc}") from None
    fig, ax = scene_figure(scene, legend_rows=5)
    plot_scene(scene, recording, time=scans.scans[-1].t, ax=ax)
    draw_births(ax, births, scans.scans[-1])
    n_new = 0 if births.newborn is None else len(births.newborn.m)
    what = f"{LABEL.get(args.model, args.model)}: {len(births)} birth components, {n_new} newborn terms"
    panel_title(ax, None, f"{ax.get_title(loc='left')}; {what}")
    _save_figure(fig, out)
    print(f"wrote {out} ({len(births)} components, {n_new} newborn terms)")
    return 0


def _executor_kwargs(args: argparse.Namespace) -> dict:
    require(args.workers is None or args.workers >= 1, f"--workers {args.workers} must be >= 1")
    require(
        not (args.scheduler and args.dask), "--scheduler and --dask local are alternatives; give one of them, not both"
    )
    cli_checks.check_scheduler_address(args.scheduler)
    return dict(
        workers=args.workers,
        scheduler=args.scheduler,
        dask_local=args.dask == "local",
        fail_fast=args.fail_fast,
        save_estimates=args.save_estimates,
        progress=not args.no_progress,
    )


def cmd_run(args: argparse.Namespace) -> int:
    kwargs = _executor_kwargs(args)
    if args.resume is not None:  # --models/--trackers re-allow the run's import-path plugins (and are compared)
        _allow_typed_plugins(args)
    cfg = _config_from_args(args)  # also validates the flags given with --resume
    from soabench.experiment.runner import run_experiment

    if args.resume is not None:
        require(args.out is None, "--out and --resume are alternatives: --resume continues the run in its folder")
        requested = _requested(args, cfg)
        outcome = run_experiment(
            None, args.net, tuple(args.poly), args.scenario, resume=args.resume, requested=requested, **kwargs
        )
    else:
        outcome = run_experiment(cfg, args.net, tuple(args.poly), args.scenario, out=args.out, **kwargs)
    return _report_outcome(outcome)


def _requested(args: argparse.Namespace, cfg: Config) -> dict:
    """What a resume asked for explicitly (flags, config file keys, net/poly/scenario), for the conflict check."""
    explicit = getattr(args, "explicit", set())
    return cli_checks.requested_values(cfg, cli_checks.requested_keys(args, explicit), args, explicit)


def _report_outcome(outcome, finish: str = "soabench run --resume {dir}") -> int:
    if getattr(outcome, "summary_markdown", None):
        print(outcome.summary_markdown)
    if outcome.complete:
        from soabench.experiment.failures import failed_methods_line, outcome_model_failures

        print(f"results in {outcome.run_dir}")
        failed = failed_methods_line(outcome_model_failures(outcome))
        if failed:  # a requested method is missing from some tables: not a success (docs/user-guide/commands.md)
            print(f"soabench: {failed}", file=sys.stderr)
            return 1
        return 0
    print(
        f"run incomplete: {outcome.n_missing} trial(s) missing in {outcome.run_dir}; "
        f"finish with: {finish.format(dir=outcome.run_dir)}",
        file=sys.stderr,
    )
    return 1


def cmd_sweep(args: argparse.Namespace) -> int:
    kwargs = _executor_kwargs(args)
    if args.resume is not None:
        require(args.out is None, "--out and --resume are alternatives: --resume continues the sweep in its folder")
        _allow_typed_plugins(args)
        from soabench.experiment.sweep import run_sweep

        requested = {"kind": args.kind, **_requested(args, _config_from_args(args))}
        if args.values is not None or args.offsets is not None:
            requested["values"] = list(args.values if args.values is not None else args.offsets)
        outcome = run_sweep(
            args.kind, (), None, args.net, resume=args.resume, requested=requested, figures=_all_figures(args),
            **kwargs,
        )  # fmt: skip
        return _report_outcome(outcome, f"soabench sweep {args.kind} --resume {{dir}}")
    from soabench.experiment.sweep import DEFAULT_VALUES, run_sweep

    if args.kind == "clutter":  # the sweep's points are its clutter rates: λ has no second home here
        given = cli_checks.requested_keys(args, getattr(args, "explicit", set()))
        require(
            "experiment.clutter" not in given,
            "`sweep clutter` takes its clutter rates from --values; drop --clutter and [experiment] clutter",
        )
    if args.kind in ("clutter", "occlusion"):
        require(args.offsets is None, f"--offsets belongs to `sweep births`; use --values for `sweep {args.kind}`")
        values = args.values or DEFAULT_VALUES[args.kind]
    else:
        require(
            args.values is None,
            "--values belongs to `sweep clutter` and `sweep occlusion`; use --offsets for `sweep births`",
        )
        values = args.offsets if args.offsets is not None else DEFAULT_VALUES["births"]
    cfg = _config_from_args(args)

    outcome = run_sweep(
        args.kind, values, cfg, args.net, tuple(args.poly), args.scenario, out=args.out,
        figures=_all_figures(args), **kwargs,
    )  # fmt: skip
    return _report_outcome(outcome, f"soabench sweep {args.kind} --resume {{dir}}")


def _all_figures(args: argparse.Namespace) -> bool | None:
    """``--all-figures``: True; else None (each sweep kind's default, :func:`soabench.experiment.sweep.run_sweep`)."""
    if args.all_figures:
        require(
            args.kind == "births",
            "--all-figures belongs to `sweep births` (clutter and occlusion points always get their figures)",
        )
        return True
    return None


def cmd_study(args: argparse.Namespace) -> int:
    kwargs = _executor_kwargs(args)
    for flag in ("sweep_trials", "births_trials", "sensitivity_trials"):
        value = getattr(args, flag)
        require(value is None or value >= 1, f"--{flag.replace('_', '-')} {value} must be >= 1")
    require(not args.save_estimates, "--save-estimates is not offered by `study`; use `run`")
    require(not args.fail_fast, "--fail-fast is not offered by `study`; use `run`")
    require(args.probabilities is None, "`study` runs the paper's probability modes")
    for flag, value in (("--poly", args.poly[0] if args.poly else None), ("--scenario", args.scenario)):
        require(value is None, f"{flag} {value!r} is not offered by `study`: give a scene folder with --net")
    from soabench import plugins

    extra = tuple(args.models or ())  # plugins ride along with the built-in six (--trackers too)
    bad = [m for m in extra if plugins.is_builtin_birth(m)]
    require(not bad, f"`study` runs the six built-in models; --models {','.join(bad)} adds plugins only")
    args.models = None
    cfg = _config_from_args(args)
    if extra:
        plugins.allow_import_paths(extra)
        cfg.experiment = dataclasses.replace(cfg.experiment, models=(*cfg.experiment.models, *extra))
        cfg.validate()
    from soabench.experiment.study import run_study

    for key in ("save_estimates", "fail_fast"):
        kwargs.pop(key)
    explicit = getattr(args, "explicit", set())
    parts = ("sweep_trials", "births_trials", "sensitivity_trials")
    keys = cli_checks.requested_keys(args, explicit) | {k for k in parts if k in explicit}
    outcome = run_study(
        cfg,
        args.net,
        out=args.out,
        sweep_trials=args.sweep_trials,
        births_trials=args.births_trials,
        sensitivity_trials=args.sensitivity_trials,
        explicit=keys,
        all_figures=args.all_figures,
        **kwargs,
    )
    return _report_outcome(outcome, "soabench study --out {dir}")


def cmd_sensitivity(args: argparse.Namespace) -> int:
    from soabench.config import MAX_TRIALS
    from soabench.experiment.executors import MAX_WORKERS

    require(
        args.trials is None or 1 <= args.trials <= MAX_TRIALS,
        f"--trials {args.trials} is out of range; allowed: integers in [1, {MAX_TRIALS}]",
    )
    require(
        args.workers is None or 1 <= args.workers <= MAX_WORKERS,
        f"--workers {args.workers} is out of range; allowed: integers in [1, {MAX_WORKERS}]",
    )
    from soabench.experiment.sensitivity_runs import run_sensitivity

    outcome = run_sensitivity(
        args.main, args.out, trials=args.trials, workers=args.workers, progress=not args.no_progress
    )
    return _report_outcome(outcome, f"soabench sensitivity --main {args.main} --out {{dir}}")


def cmd_results(args: argparse.Namespace) -> int:
    from soabench.experiment.results_suite import cmd_results as run

    return run(args)


def cmd_kitti(args: argparse.Namespace) -> int:
    from soabench.kitti.commands import cmd_kitti as run

    return run(args)


def cmd_export(args: argparse.Namespace) -> int:
    from soabench.kitti.commands import cmd_export as run

    return run(args)


def cmd_check(args: argparse.Namespace) -> int:
    require(args.workers >= 1, f"--workers {args.workers} must be >= 1")
    from soabench import plugins
    from soabench.experiment.check import run_check

    for name in args.plugin:
        require(":" in name, f"--plugin {name!r} must be MODULE:CLASS (installed entry-point plugins need no --plugin)")
    plugins.allow_import_paths(args.plugin)
    return run_check(args.suite, args.out, update_baseline=args.update_baseline, workers=args.workers)


def cmd_scenes(args: argparse.Namespace) -> int:
    from soabench.scenario.suite import scenes_table

    print(scenes_table())
    return 0


def cmd_import(args: argparse.Namespace) -> int:
    from soabench.scenario.osm import import_osm

    toml = import_osm(args.file, args.out, force=args.force)
    print(f"wrote scene folder {toml.parent} (use: soabench run --net {toml.parent})")
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    from soabench.replay.commands import cmd_replay as run

    return run(args)


def cmd_report(args: argparse.Namespace) -> int:
    from soabench.replay.commands import cmd_report as run

    return run(args)


COMMANDS = {
    "kitti": cmd_kitti,
    "export": cmd_export,
    "scenes": cmd_scenes,
    "import": cmd_import,
    "scene": cmd_scene,
    "record": cmd_record,
    "birth": cmd_birth,
    "run": cmd_run,
    "sweep": cmd_sweep,
    "study": cmd_study,
    "sensitivity": cmd_sensitivity,
    "results": cmd_results,
    "check": cmd_check,
    "replay": cmd_replay,
    "report": cmd_report,
}


def _join_negative_values(argv: Sequence[str]) -> list[str]:
    """``--offsets -10:10`` -> ``--offsets=-10:10``: argparse would read a value starting with '-' as an option."""
    out: list[str] = []
    it = iter(argv)
    for token in it:
        if token in ("--offsets", "--values", "--clutter", "--nhat-sweep"):
            value = next(it, None)
            if (
                value is not None
                and value.startswith("-")
                and len(value) > 1
                and (value[1].isdigit() or value[1] == ".")
            ):
                out.append(f"{token}={value}")
                continue
            out.append(token)
            if value is not None:
                out.append(value)
            continue
        out.append(token)
    return out


class _CurrentStderr(logging.StreamHandler):
    """A log handler writing to ``sys.stderr`` as it is when a record comes (a caller, or a test, may swap it)."""

    def emit(self, record) -> None:
        self.stream = sys.stderr
        super().emit(record)


def _say_derived() -> None:
    """Print the scene loader's info line (what it derived from a network) to stderr, once."""
    import logging

    log = logging.getLogger("soabench")
    if not any(getattr(h, "_soabench", False) for h in log.handlers):
        h = _CurrentStderr()
        h.setFormatter(logging.Formatter("soabench: %(message)s"))
        h._soabench = True  # type: ignore[attr-defined]
        log.addHandler(h)
        log.setLevel(logging.INFO)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``soabench`` console script."""
    parser = build_parser()
    argv = _join_negative_values(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    args.explicit = cli_checks.explicit_dests(parser, argv)
    _say_derived()
    try:
        cli_checks.check_no_empty_paths(argv)
        if getattr(args, "net", None) == "all":
            from soabench.scenario.suite import run_on_all

            return run_on_all(args, COMMANDS[args.command], args.command)
        return COMMANDS[args.command](args)
    except BrokenPipeError:  # e.g. `soabench run | head`: the reader left; say nothing more
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except SoabenchError as exc:
        print(f"soabench: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except Interrupted as exc:  # the message says what is on disk and how to finish
        print(f"soabench: {exc}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print("soabench: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:  # a file system refusal the checks could not foresee (disk full, a race): one line
        where = f" {exc.filename!r}" if getattr(exc, "filename", None) else ""
        print(f"soabench: error: cannot read or write{where}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
