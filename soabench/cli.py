"""The ``soabench`` command line: thin handlers over the pipeline (DESIGN.md).

Subcommands: ``scene`` (Fig. 3 bird's-eye view, optional sensor overlay), ``record`` (ground truth and scans to
.npz), ``birth`` (birth components of one model over the scene), ``run`` (the Monte Carlo protocol), ``sweep``
(clutter, N_hat or occluder-density sensitivity), ``scenes`` (the shipped scenes), ``import osm`` (an OpenStreetMap
extract as a scene folder). ``--net all`` runs a command on every shipped scene. Any error a user can cause prints
one line and exits with status 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from soabench.config import BIRTH_MODEL_NAMES, PROBABILITY_MODES, Config, filter_config_for_mode, load_config
from soabench.errors import SoabenchError, require

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


def _offsets(text: str) -> tuple[int, ...]:
    """``-10:10`` (inclusive range), ``-10:10:2`` (with step) or ``-5,0,5``."""
    try:
        if ":" in text:
            parts = [int(p) for p in text.split(":")]
            require(len(parts) in (2, 3), "")
            lo, hi = parts[0], parts[1]
            step = parts[2] if len(parts) == 3 else 1
            require(step > 0 and hi >= lo, "")
            return tuple(range(lo, hi + 1, step))
        return tuple(int(s) for s in text.split(",") if s.strip())
    except (ValueError, SoabenchError):
        raise argparse.ArgumentTypeError(
            f"offsets {text!r} must be LO:HI, LO:HI:STEP (integers, HI >= LO, STEP > 0) or a comma list of integers"
        ) from None


def _add_net_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--net",
        default="intersection",
        help="shipped scene name, 'all' (every shipped scene), a scene folder or a path to a .net.xml",
    )
    p.add_argument(
        "--poly", action="append", default=[], metavar="FILE", help="polygon file (buildings, obstacles); repeatable"
    )
    p.add_argument("--scenario", metavar="FILE.toml", help="scenario file (default: the shipped net's own)")
    p.add_argument("--config", metavar="FILE.toml", help="parameters (ALGORITHMS.md §7), section by section")


def _add_snapshot_args(p: argparse.ArgumentParser, need_out: bool = True) -> None:
    _add_net_args(p)
    p.add_argument("--seed", type=int, default=0, help="base seed (as in `run`)")
    p.add_argument("--trial", type=int, default=0, help="trial index under the base seed (as in `run`)")
    p.add_argument("--out", required=need_out, help="output file")


def _add_run_args(p: argparse.ArgumentParser) -> None:
    _add_net_args(p)
    p.add_argument("--trials", type=int, help="Monte Carlo trials (default 100)")
    p.add_argument("--duration", type=float, help="seconds per trial (default 100)")
    p.add_argument("--models", type=_csv_list("model", BIRTH_MODEL_NAMES), help="e.g. soa,pubm (default: all five)")
    p.add_argument(
        "--probabilities",
        type=_csv_list("probability mode", PROBABILITY_MODES),
        help="static,dynamic (default) or dynamic+occ",
    )
    p.add_argument("--seed", type=int, help="base seed (default 0)")
    p.add_argument("--workers", type=int, help="process workers (default: every core)")
    p.add_argument("--out", type=Path, help="run folder (default results/<net>/<timestamp>/)")
    p.add_argument("--save-estimates", action="store_true", help="also write the per-scan estimates")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="submit trials to this Dask scheduler")
    p.add_argument("--dask", choices=["local"], help="start a Dask LocalCluster (processes, one thread each)")
    p.add_argument("--fail-fast", action="store_true", help="stop at the first failed trial")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="soabench",
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
    p.add_argument("--model", default="soa", choices=BIRTH_MODEL_NAMES)
    p.add_argument("--probability", default="static", choices=PROBABILITY_MODES)

    p = sub.add_parser("run", help="the Monte Carlo protocol (default: the paper's)")
    _add_run_args(p)
    p.add_argument("--clutter", type=_float_list, help="clutter rate(s) lambda, e.g. 3 or 0.5,3,5 (default 3)")
    p.add_argument("--resume", type=Path, metavar="RUN_DIR", help="finish the missing trials of an earlier run")

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
    p.add_argument("--resume", type=Path, metavar="SWEEP_DIR", help="finish the missing trials of an earlier sweep")

    p = sub.add_parser(
        "study", help="the paper's whole simulation study: main protocol, clutter sweep, N_hat sweep, comparison"
    )
    _add_run_args(p)
    p.add_argument("--sweep-trials", type=int, help="trials of the clutter sweep (default: --trials)")
    p.add_argument("--births-trials", type=int, default=30, help="trials per point of the N_hat sweep (default 30)")

    sub.add_parser("scenes", help="the shipped scenes: size, lanes, pedestrians, occluders, what each tests")
    p = sub.add_parser("import", help="turn an OpenStreetMap extract into a scene folder for --net")
    p.add_argument("kind", choices=["osm"])
    p.add_argument("file", metavar="FILE.osm")
    p.add_argument("--out", required=True, help="scene folder to write")
    return parser


# ------------------------------------------------------------------------------------------------------ helpers
def _config_from_args(args: argparse.Namespace) -> Config:
    """The config file (if any) overlaid by the command-line flags, validated."""
    cfg = load_config(getattr(args, "config", None))
    exp = cfg.experiment
    overrides = {
        "trials": getattr(args, "trials", None),
        "duration": getattr(args, "duration", None),
        "models": getattr(args, "models", None),
        "probabilities": getattr(args, "probabilities", None),
        "clutter": getattr(args, "clutter", None),
        "seed": getattr(args, "seed", None),
    }
    cfg.experiment = dataclasses.replace(exp, **{k: v for k, v in overrides.items() if v is not None})
    return cfg.validate()


def _load_scene(args: argparse.Namespace):
    from soabench.scenario import load

    return load(args.net, tuple(args.poly), args.scenario)


def _snapshot(args: argparse.Namespace, duration: float | None, include_end: bool = False):
    """Scene, scenario, config, trial seeds and the recording up to ``duration`` seconds (None: the scenario's).

    ``include_end``: simulate one SUMO step more so that a sample (and a scan, when ``duration`` is a multiple of
    the sensor period) lies exactly at ``duration``: a snapshot at ``--time 50`` shows the scan at t = 50 s.
    """
    require(args.seed >= 0, f"--seed {args.seed} must be >= 0")
    require(args.trial >= 0, f"--trial {args.trial} must be >= 0")
    cfg = load_config(args.config)
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


def _prepare_out(path: str) -> Path:
    out = Path(path)
    require(
        out.parent == Path("") or out.parent.is_dir(), f"output folder {str(out.parent)!r} does not exist for {path!r}"
    )
    return out


def _save_figure(fig, out: Path) -> None:
    tmp = out.with_name(out.name + ".tmp" + out.suffix)
    fig.savefig(tmp, dpi=150, bbox_inches="tight")
    tmp.replace(out)


# ----------------------------------------------------------------------------------------------------- commands
def cmd_scene(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from soabench.scenario.plots import plot_scene

    out = _prepare_out(args.out)
    scene, _, cfg, seeds, recording = _snapshot(args, args.time, include_end=True)
    fig, ax = plt.subplots(figsize=(11, 6.8))
    if args.sensor:
        from soabench.sensor_plot import draw_sensor_overlay

        scans = _observe(recording, scene, cfg, seeds)
        plot_scene(scene, recording, time=scans.scans[-1].t, ax=ax)  # the scene at the overlaid scan's time
        draw_sensor_overlay(ax, scans, len(scans) - 1, cfg.sensor)
    else:
        plot_scene(scene, recording, time=args.time, ax=ax)
    from soabench.scenario.key import add_scene_key

    add_scene_key(ax)
    _save_figure(fig, out)
    plt.close(fig)
    print(f"wrote {out}")
    return 0


def cmd_record(args: argparse.Namespace) -> int:
    out = _prepare_out(args.out)
    scans_out = None
    if args.scans is not None:
        scans_out = _prepare_out(args.scans) if args.scans else out.with_name(out.stem + ".scans.npz")
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
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from soabench.birth import get_birth_model
    from soabench.birth.base import BirthContext
    from soabench.birth.plots import draw_births
    from soabench.gmphd.filter import GMPHDFilter
    from soabench.scenario.plots import plot_scene

    out = _prepare_out(args.out)
    scene, _, cfg, seeds, recording = _snapshot(args, args.time, include_end=True)
    scans = _observe(recording, scene, cfg, seeds)
    model = get_birth_model(args.model)(cfg.birth, cfg.sensor, scene, seeds.placement_rng())
    filter_cfg, mode, p_D_b = filter_config_for_mode(cfg.filter, args.probability)
    filt = GMPHDFilter(filter_cfg, cfg.sensor, mode)
    prev = None
    births = None
    for scan in scans.scans:  # run the filter up to the snapshot so stateful models see their history
        births = model(BirthContext(scan, prev, p_D_b))
        prev = filt.step(scan, births)
    fig, ax = plt.subplots(figsize=(11, 6.8))
    plot_scene(scene, recording, time=scans.scans[-1].t, ax=ax)
    draw_births(ax, births, scans.scans[-1])
    n_new = 0 if births.newborn is None else len(births.newborn.m)
    ax.set_title(f"{args.model}: {len(births)} birth components, {n_new} newborn terms, t = {scans.scans[-1].t:g} s")
    _save_figure(fig, out)
    plt.close(fig)
    print(f"wrote {out} ({len(births)} components, {n_new} newborn terms)")
    return 0


def _executor_kwargs(args: argparse.Namespace) -> dict:
    require(args.workers is None or args.workers >= 1, f"--workers {args.workers} must be >= 1")
    require(
        not (args.scheduler and args.dask), "--scheduler and --dask local are alternatives; give one of them, not both"
    )
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
    if args.resume is not None:
        require(args.resume.is_dir(), f"--resume {str(args.resume)!r} is not a run folder")
        cfg = None
    else:
        cfg = _config_from_args(args)
    from soabench.experiment.runner import run_experiment

    if cfg is None:
        outcome = run_experiment(None, args.net, tuple(args.poly), args.scenario, resume=args.resume, **kwargs)
    else:
        outcome = run_experiment(cfg, args.net, tuple(args.poly), args.scenario, out=args.out, **kwargs)
    return _report_outcome(outcome)


def _report_outcome(outcome) -> int:
    if getattr(outcome, "summary_markdown", None):
        print(outcome.summary_markdown)
    if outcome.complete:
        print(f"results in {outcome.run_dir}")
        return 0
    print(
        f"run incomplete: {outcome.n_missing} trial(s) missing in {outcome.run_dir}; "
        f"finish with: soabench run --resume {outcome.run_dir}",
        file=sys.stderr,
    )
    return 1


def cmd_sweep(args: argparse.Namespace) -> int:
    kwargs = _executor_kwargs(args)
    if args.resume is not None:
        require(args.resume.is_dir(), f"--resume {str(args.resume)!r} is not a sweep folder")
        from soabench.experiment.sweep import run_sweep

        outcome = run_sweep(args.kind, (), None, args.net, resume=args.resume, **kwargs)
        return _report_outcome(outcome)
    if args.kind == "clutter":
        require(args.offsets is None, "--offsets belongs to `sweep births`; use --values for `sweep clutter`")
        values = args.values or (0.5, 3.0, 5.0)
    elif args.kind == "occlusion":
        require(args.offsets is None, "--offsets belongs to `sweep births`; use --values for `sweep occlusion`")
        values = args.values or (0.0, 4.0, 8.0, 12.0)
    else:
        require(
            args.values is None,
            "--values belongs to `sweep clutter` and `sweep occlusion`; use --offsets for `sweep births`",
        )
        values = args.offsets if args.offsets is not None else tuple(range(-10, 11))
    cfg = _config_from_args(args)
    from soabench.experiment.sweep import run_sweep

    outcome = run_sweep(args.kind, values, cfg, args.net, tuple(args.poly), args.scenario, out=args.out, **kwargs)
    return _report_outcome(outcome)


def cmd_study(args: argparse.Namespace) -> int:
    kwargs = _executor_kwargs(args)
    for flag in ("sweep_trials", "births_trials"):
        value = getattr(args, flag)
        require(value is None or value >= 1, f"--{flag.replace('_', '-')} {value} must be >= 1")
    require(not args.save_estimates, "--save-estimates is not offered by `study`; use `run`")
    require(not args.fail_fast, "--fail-fast is not offered by `study`; use `run`")
    require(args.models is None and args.probabilities is None, "`study` runs the paper's models and modes")
    cfg = _config_from_args(args)
    from soabench.experiment.study import run_study

    for key in ("save_estimates", "fail_fast"):
        kwargs.pop(key)
    outcome = run_study(
        cfg, args.net, out=args.out, sweep_trials=args.sweep_trials, births_trials=args.births_trials, **kwargs
    )
    return _report_outcome(outcome)


def cmd_scenes(args: argparse.Namespace) -> int:
    from soabench.scenario.suite import scenes_table

    print(scenes_table())
    return 0


def cmd_import(args: argparse.Namespace) -> int:
    from soabench.scenario.osm import import_osm

    toml = import_osm(args.file, args.out)
    print(f"wrote scene folder {toml.parent} (use: soabench run --net {toml.parent})")
    return 0


COMMANDS = {
    "scenes": cmd_scenes,
    "import": cmd_import,
    "scene": cmd_scene,
    "record": cmd_record,
    "birth": cmd_birth,
    "run": cmd_run,
    "sweep": cmd_sweep,
    "study": cmd_study,
}


def _join_negative_values(argv: Sequence[str]) -> list[str]:
    """``--offsets -10:10`` -> ``--offsets=-10:10``: argparse would read a value starting with '-' as an option."""
    out: list[str] = []
    it = iter(argv)
    for token in it:
        if token in ("--offsets", "--values", "--clutter"):
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


def _say_derived() -> None:
    """Print the scene loader's info line (what it derived from a network) to stderr, once."""
    import logging

    log = logging.getLogger("soabench")
    if not any(getattr(h, "_soabench", False) for h in log.handlers):
        h = logging.StreamHandler(sys.stderr)
        h.setFormatter(logging.Formatter("soabench: %(message)s"))
        h._soabench = True  # type: ignore[attr-defined]
        log.addHandler(h)
        log.setLevel(logging.INFO)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``soabench`` console script."""
    parser = build_parser()
    args = parser.parse_args(_join_negative_values(sys.argv[1:] if argv is None else argv))
    _say_derived()
    try:
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
    except KeyboardInterrupt:
        print("soabench: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
