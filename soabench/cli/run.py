"""``soabench run``: the Monte Carlo protocol (docs/method.md §5.8), new or resumed."""

from __future__ import annotations

import argparse
from pathlib import Path

from soabench.cli import common
from soabench.cli.parsing import add_filters_arg, add_run_args, float_list
from soabench.errors import require


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="the Monte Carlo protocol (default: the paper's)")
    add_run_args(p)
    p.add_argument("--clutter", type=float_list, help="clutter rate(s) lambda, e.g. 3 or 0.5,3,5 (default 3)")
    add_filters_arg(p)
    p.add_argument(
        "--resume", type=Path, metavar="RUN_DIR", help="finish the missing trials of an earlier run (default: new run)"
    )


def handle(args: argparse.Namespace) -> int:
    from soabench.experiment.execution.runner import RunRequest
    from soabench.experiment.reports.finished import run

    options = common.run_options(args)
    if args.resume is not None:  # --models/--trackers re-allow the run's import-path plugins (and are compared)
        common.allow_typed_plugins(args)
    cfg = common.config_from_args(args)  # also validates the flags given with --resume
    if args.resume is not None:
        require(args.out is None, "--out and --resume are alternatives: --resume continues the run in its folder")
        requested = common.requested(args, cfg)
        request = RunRequest(
            None, args.net, tuple(args.poly), args.scenario, resume=args.resume, requested=requested, options=options
        )
    else:
        request = RunRequest(cfg, args.net, tuple(args.poly), args.scenario, out=args.out, options=options)
    outcome = run(request)
    return common.report_outcome(outcome, short=True)
