"""``soabench replay`` and ``soabench report``: argument parsing and handlers over :mod:`soabench.replay`
(docs/user-guide/replay.md)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from soabench.errors import require


def add_replay_parser(sub: argparse._SubParsersAction, csv_list) -> None:
    """Register ``replay`` (``csv_list``: the CLI's comma-list parser factory)."""
    p = sub.add_parser("replay", help="re-simulate one trial of a finished run as an interactive HTML page")
    p.add_argument("run", metavar="RUN", help="a finished (or resumable) run folder (holds run.json)")
    p.add_argument("--trial", type=int, required=True, help="trial index of the run")
    p.add_argument(
        "--models",
        type=csv_list("model"),
        help="birth models to show side by side (default: the run's; a run's module:Class plugin only when typed here)",
    )
    p.add_argument("--mode", help="probability mode (default: the run's first)")
    p.add_argument("--clutter", type=float, help="clutter rate lambda (default: the run's first)")
    p.add_argument("--out", help="HTML file to write (default RUN/replays/trial_NNNNN.html)")
    p.add_argument("--gif", metavar="FILE.gif", help="also an animated GIF, 5x real time (default: none)")


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


def _replay_out(run_dir: Path, trial: int, out: str | None) -> Path:
    from soabench.cli_checks import check_out_file
    from soabench.replay.report import REPLAYS_DIR, replay_file

    if out is not None:
        return check_out_file(out)
    folder = run_dir / REPLAYS_DIR
    folder.mkdir(exist_ok=True)
    return check_out_file(str(folder / replay_file(trial)))


def write_trial_replay(
    run: str | Path, trial: int, models=None, mode=None, clutter=None, out: str | None = None, gif: str | None = None
):
    """Re-simulate and write one replay page (and a GIF if ``gif``); returns (path, size in bytes, the replay,
    seconds simulating, seconds rendering the page)."""
    from soabench.cli_checks import check_out_file
    from soabench.replay import replay_data, replay_trial, write_replay
    from soabench.replay.simulate import read_run

    run_dir, _, _ = read_run(run)
    gif_out = None if gif is None else check_out_file(gif)
    require(gif_out is None or gif_out.suffix.lower() == ".gif", f"--gif {gif!r} must name a .gif file")
    target = _replay_out(run_dir, trial, out)
    t0 = time.perf_counter()
    rep = replay_trial(run_dir, trial, models, mode, clutter)
    t1 = time.perf_counter()
    data = replay_data(rep)
    size = write_replay(data, target)
    t2 = time.perf_counter()
    if gif_out is not None:
        from soabench.replay.gif import write_gif

        print(f"wrote {gif_out} ({write_gif(data, gif_out) / 1e6:.2f} MB)")
    return target, size, rep, t1 - t0, t2 - t1


def cmd_replay(args: argparse.Namespace) -> int:
    require(args.trial >= 0, f"--trial {args.trial} must be >= 0")
    from soabench import plugins

    # a run's import-path plugin is imported only when typed here (as with run --resume): run.json is data
    plugins.allow_import_paths(args.models or ())
    target, size, rep, t_sim, t_draw = write_trial_replay(
        args.run, args.trial, args.models, args.mode, args.clutter, args.out, args.gif
    )
    for note in rep.notes:
        print(note)
    print(f"wrote {target} ({len(rep.scans)} scans x {len(rep.models)} models, {size / 1e6:.2f} MB; "
          f"simulated in {t_sim:.1f} s, page in {t_draw:.1f} s)")  # fmt: skip
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from soabench.experiment.runs.store import RUN_FILE
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
            target, size, rep, _, _ = write_trial_replay(run_dir, trial)
            print(f"wrote {target} ({size / 1e6:.2f} MB; {rep.notes[-1]})")
    target, size = write_report(run_dir, args.out)
    print(f"wrote {target} ({size / 1e6:.2f} MB)")
    return 0
