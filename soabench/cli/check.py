"""``soabench check``: CI mode, short scenarios against per-metric thresholds (docs/user-guide/ci.md)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("check", help="CI mode: short scenarios against per-metric thresholds (exit 1 on regression)")
    p.add_argument("--suite", required=True, metavar="FILE.toml", help="scenarios and thresholds")
    p.add_argument("--out", type=Path, default=Path("check-results"), help="check.json, junit.xml, run folders")
    p.add_argument("--update-baseline", action="store_true", help="rewrite the suite's baseline JSON from this run")
    p.add_argument("--workers", type=int, default=1, help="process workers per run (default 1)")
    p.add_argument(
        "--calibrate",
        type=int,
        metavar="N",
        help="run the scenarios N times on fresh seeds and propose each threshold from the 95%% bounds of a further "
        "run (calibration.json); checks nothing (default: none, check the thresholds)",
    )
    p.add_argument(
        "--plugin",
        action="append",
        default=[],
        metavar="MODULE:CLASS",
        help="allow this import-path plugin named by the suite (entry points need nothing); repeatable",
    )


def handle(args: argparse.Namespace) -> int:
    from soabench.errors import require
    from soabench.experiment.campaigns.check import run_calibration, run_check

    if args.calibrate is not None:
        require(not args.update_baseline, "--calibrate and --update-baseline are alternatives: calibrate first")
        return run_calibration(args.suite, args.out, args.calibrate, workers=args.workers, plugin_paths=args.plugin)
    return run_check(
        args.suite, args.out, update_baseline=args.update_baseline, workers=args.workers, plugin_paths=args.plugin
    )
