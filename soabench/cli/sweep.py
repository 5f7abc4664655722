"""``soabench sweep clutter|births|occlusion``: one parameter swept over the protocol, each value a run folder."""

from __future__ import annotations

import argparse
from pathlib import Path

from soabench.cli import checks, common
from soabench.cli.parsing import add_filters_arg, add_run_args, float_list, offsets
from soabench.errors import require


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sweep", help="parameter sweeps: clutter rate or expected births N_hat")
    p.add_argument("kind", choices=["clutter", "births", "occlusion"])
    add_run_args(p)
    add_filters_arg(p)
    p.add_argument(
        "--values",
        type=float_list,
        help="clutter rates for `sweep clutter` (default 0.5,3,5); parked cars per 100 m of kerb for "
        "`sweep occlusion` (default 0,4,8,12)",
    )
    p.add_argument("--offsets", type=offsets, help="N_tot offsets for `sweep births` (default -10:10)")
    p.add_argument("--clutter", type=float_list, help="clutter rate for `sweep births` (default 3)")
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


def _all_figures(args: argparse.Namespace) -> bool | None:
    """``--all-figures``: True; else None (each sweep kind's default,
    :func:`~soabench.experiment.campaigns.sweep.run_sweep`)."""
    if args.all_figures:
        require(
            args.kind == "births",
            "--all-figures belongs to `sweep births` (clutter and occlusion points always get their figures)",
        )
        return True
    return None


def handle(args: argparse.Namespace) -> int:
    from soabench.experiment.campaigns.sweep import SweepRequest, sweep, sweep_values
    from soabench.experiment.execution.runner import RunRequest

    options = common.run_options(args, _all_figures(args))
    finish = f"soabench sweep {args.kind} --resume {{dir}}"
    if args.resume is not None:
        require(args.out is None, "--out and --resume are alternatives: --resume continues the sweep in its folder")
        common.allow_typed_plugins(args)
        cfg = common.config_from_args(args)
        requested = {"kind": args.kind, **common.requested(args, cfg)}
        if args.values is not None or args.offsets is not None:
            requested["values"] = list(args.values if args.values is not None else args.offsets)
        run = RunRequest(None, args.net, resume=args.resume, requested=requested, options=options)
        return common.report_outcome(sweep(SweepRequest(args.kind, (), run)), finish)
    given = checks.requested_keys(args, getattr(args, "explicit", set()))
    values = sweep_values(args.kind, args.values, args.offsets, given)
    cfg = common.config_from_args(args)
    run = RunRequest(cfg, args.net, tuple(args.poly), args.scenario, out=args.out, options=options)
    return common.report_outcome(sweep(SweepRequest(args.kind, values, run)), finish)
