"""``soabench sensitivity``: a finished run again with the gate off and with visible truth, and the table."""

from __future__ import annotations

import argparse
from pathlib import Path

from soabench.cli import common
from soabench.experiment.execution.options import RunOptions


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sensitivity", help="a finished run again with the gate off and with visible truth, and the sensitivity table"
    )
    p.add_argument("--main", type=Path, required=True, metavar="RUN_DIR", help="the finished run (default: none)")
    p.add_argument("--out", type=Path, help="folder of the variant runs and the table (default RUN_DIR_sensitivity)")
    p.add_argument("--trials", type=int, help="trials of each variant run (default: the main run's)")
    p.add_argument("--workers", type=int, help="process workers (default: every core)")
    p.add_argument("--no-progress", action="store_true", help="no progress report")


def handle(args: argparse.Namespace) -> int:
    from soabench.experiment.campaigns.sensitivity_runs import run_sensitivity

    options = RunOptions(workers=args.workers, progress=not args.no_progress)
    outcome = run_sensitivity(args.main, args.out, trials=args.trials, options=options)
    return common.report_outcome(outcome, f"soabench sensitivity --main {args.main} --out {{dir}}")
