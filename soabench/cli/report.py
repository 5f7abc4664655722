"""``soabench report``: one self-contained HTML page for a run folder, or an index over a folder of runs
(docs/user-guide/replay.md)."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="one self-contained HTML page for a run folder (RUN/report.html)")
    p.add_argument(
        "run",
        metavar="RUN",
        help="a run folder (holds run.json), or a folder of them (a study, results/): then "
        "each run's report.html and an index.html linking them (and a study's key_figure.png, from its main/)",
    )
    p.add_argument("--out", help="HTML file to write (default RUN/report.html)")
    p.add_argument(
        "--replays",
        action="store_true",
        help="also write the replay pages of each model's best and worst trial into RUN/replays/ and link them",
    )


def handle(args: argparse.Namespace) -> int:
    from soabench.experiment.campaigns.study import key_figure
    from soabench.replay.pages import write_pages

    figure = key_figure(args.run) if args.out is None and not args.replays else None  # a study folder's
    if figure is not None:
        print(f"wrote {figure}")
    write_pages(args.run, args.out, args.replays)
    return 0
