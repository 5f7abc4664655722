"""``soabench replay``: one trial of a finished run re-simulated as an interactive HTML page or a video
(docs/user-guide/replay.md)."""

from __future__ import annotations

import argparse

from soabench.cli.parsing import csv_list


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="re-simulate one trial of a finished run as an interactive HTML page or a video")
    p.add_argument("run", metavar="RUN", help="a finished (or resumable) run folder (holds run.json)")
    p.add_argument("--trial", type=int, required=True, help="trial index of the run")
    p.add_argument(
        "--models",
        type=csv_list("model"),
        help="birth models and trackers to show side by side (default: the run's; a run's module:Class plugin only "
        "when typed here)",
    )
    p.add_argument("--filter", help="filter family the birth models run in (default: the run's first)")
    p.add_argument("--mode", help="probability mode (default: the run's first that the filter family defines)")
    p.add_argument("--clutter", type=float, help="clutter rate lambda (default: the run's first)")
    p.add_argument(
        "--out",
        action="append",
        metavar="FILE",
        help="file to write, its format by its ending: .html the interactive page, .mp4 a video (needs the video "
        "extra), .gif an animated GIF (videos at 5x real time); repeatable (default RUN/replays/trial_NNNNN.html)",
    )


def handle(args: argparse.Namespace) -> int:
    from soabench.replay.pages import write_trial_replay

    written, rep, t_sim, t_draw = write_trial_replay(
        args.run, args.trial, args.models, args.mode, args.clutter, args.out, args.filter
    )
    for note in rep.notes:
        print(note)
    for target, size in written:
        print(f"wrote {target} ({len(rep.scans)} scans x {len(rep.models)} models, {size / 1e6:.2f} MB)")
    print(f"simulated in {t_sim:.1f} s, written in {t_draw:.1f} s")
    return 0
