"""``soabench replay`` and ``soabench report``: argument parsing and handlers over :mod:`soabench.replay`
(docs/user-guide/replay.md)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from soabench.errors import require


def add_replay_parser(sub: argparse._SubParsersAction, csv_list) -> None:
    """Register ``replay`` (``csv_list``: the CLI's comma-list parser factory)."""
    p = sub.add_parser("replay", help="re-simulate one trial of a finished run as an interactive HTML page or a video")
    p.add_argument("run", metavar="RUN", help="a finished (or resumable) run folder (holds run.json)")
    p.add_argument("--trial", type=int, required=True, help="trial index of the run")
    p.add_argument(
        "--models",
        type=csv_list("model"),
        help="birth models and trackers to show side by side (default: the run's; a run's module:Class plugin only "
        "when typed here)",
    )
    p.add_argument("--mode", help="probability mode (default: the run's first)")
    p.add_argument("--clutter", type=float, help="clutter rate lambda (default: the run's first)")
    p.add_argument(
        "--out",
        action="append",
        metavar="FILE",
        help="file to write, its format by its ending: .html the interactive page, .mp4 a video (needs the video "
        "extra), .gif an animated GIF (videos at 5x real time); repeatable (default RUN/replays/trial_NNNNN.html)",
    )


def add_report_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``report``."""
    p = sub.add_parser("report", help="one self-contained HTML page for a run folder (RUN/report.html)")
    p.add_argument(
        "run",
        metavar="RUN",
        help="a run folder (holds run.json), or a folder of them (a study, results/): then "
        "each run's report.html and an index.html linking them",
    )
    p.add_argument("--out", help="HTML file to write (default RUN/report.html)")
    p.add_argument(
        "--replays",
        action="store_true",
        help="also write the replay pages of each model's best and worst trial into RUN/replays/ and link them",
    )


PAGE_SUFFIXES = (".html", ".htm")


def _replay_outs(run_dir: Path, trial: int, outs: list[str] | None) -> list[Path]:
    """The files to write, each ending in a format we write (checked before any simulation)."""
    from soabench.cli_checks import check_out_file
    from soabench.replay.animation import VIDEO_SUFFIXES, require_mp4
    from soabench.replay.report import REPLAYS_DIR, replay_file

    if not outs:
        folder = run_dir / REPLAYS_DIR
        folder.mkdir(exist_ok=True)
        return [check_out_file(str(folder / replay_file(trial)))]
    paths = []
    for out in outs:
        path = check_out_file(out)
        suffix = path.suffix.lower()
        allowed = (*PAGE_SUFFIXES, *VIDEO_SUFFIXES)
        require(
            suffix in allowed, f"--out {out!r} must end in one of {', '.join(allowed)}: the format it is written in"
        )
        if suffix == ".mp4":
            require_mp4()
        paths.append(path)
    return paths


def write_trial_replay(
    run: str | Path, trial: int, models=None, mode=None, clutter=None, outs: list[str] | None = None
):
    """Re-simulate a trial and write each of ``outs`` (default: its page under ``RUN/replays/``); returns (the
    paths and sizes in bytes written, the replay, seconds simulating, seconds writing)."""
    from soabench.replay import replay_data, replay_trial, write_replay
    from soabench.replay.animation import write_video
    from soabench.replay.simulate import read_run

    run_dir, _, _ = read_run(run)
    targets = _replay_outs(run_dir, trial, outs)
    t0 = time.perf_counter()
    rep = replay_trial(run_dir, trial, models, mode, clutter)
    t1 = time.perf_counter()
    data = replay_data(rep)
    written = []
    for target in targets:
        write = write_replay if target.suffix.lower() in PAGE_SUFFIXES else write_video
        written.append((target, write(data, target)))
    return written, rep, t1 - t0, time.perf_counter() - t1


def cmd_replay(args: argparse.Namespace) -> int:
    require(args.trial >= 0, f"--trial {args.trial} must be >= 0")
    from soabench import plugins

    # a run's import-path plugin is imported only when typed here (as with run --resume): run.json is data
    plugins.allow_import_paths(args.models or ())
    written, rep, t_sim, t_draw = write_trial_replay(
        args.run, args.trial, args.models, args.mode, args.clutter, args.out
    )
    for note in rep.notes:
        print(note)
    for target, size in written:
        print(f"wrote {target} ({len(rep.scans)} scans x {len(rep.models)} models, {size / 1e6:.2f} MB)")
    print(f"simulated in {t_sim:.1f} s, written in {t_draw:.1f} s")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from soabench.experiment.store import RUN_FILE
    from soabench.replay.report import extreme_trials, write_index, write_report
    from soabench.replay.simulate import read_run

    if not (Path(args.run) / RUN_FILE).is_file() and Path(args.run).is_dir():  # a study or results/ folder
        require(args.out is None, "--out names one run's page; a folder of runs gets index.html and one report each")
        require(not args.replays, "--replays works on one run folder; give a run folder")
        target, size, runs = write_index(args.run)
        print(f"wrote {len(runs)} run reports and {target} ({size / 1e6:.2f} MB)")
        return 0
    run_dir, meta, _ = read_run(args.run)
    if args.replays:
        trials = sorted({r[w][1] for r in extreme_trials(run_dir) for w in ("best", "worst")})
        for trial in trials:
            ((target, size),), rep, _, _ = write_trial_replay(run_dir, trial)
            print(f"wrote {target} ({size / 1e6:.2f} MB; {rep.notes[-1]})")
    target, size = write_report(run_dir, args.out)
    print(f"wrote {target} ({size / 1e6:.2f} MB)")
    return 0
