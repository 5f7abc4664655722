"""``soabench atlas``: a campaign over any set of axes (docs/user-guide/atlas.md), into a Parquet dataset."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from soabench.cli import common
from soabench.cli.parsing import add_run_args, csv_list
from soabench.config import FILTER_FAMILIES
from soabench.errors import require
from soabench.tomlfile import read_toml


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "atlas", help="a campaign over scene and method parameters: phase diagrams of S-OA's advantage (Parquet)"
    )
    add_run_args(p)
    p.add_argument(
        "--axis",
        action="append",
        default=[],
        metavar="KEY=V1,V2,...",
        help="an axis: a parameter key (sensor.p_D, birth.N_hat, ...), experiment.clutter, a scenario key "
        "(parking.density, pedestrians.count, vehicles.count), net, filters or birth.N_hat_offset, with its values "
        "(or LO:HI for --sample); repeatable",
    )
    p.add_argument(
        "--design",
        type=Path,
        metavar="FILE.toml",
        help="the axes (and [design] kind, points) in a file (default: none)",
    )
    p.add_argument(
        "--sample",
        choices=["factorial", "sobol", "lhs"],
        help="full factorial of the listed values (default), or a scrambled Sobol / Latin hypercube design",
    )
    p.add_argument(
        "--points", type=int, help="points of a --sample sobol or lhs design (default: none; needed with them)"
    )
    p.add_argument(
        "--filters",
        type=csv_list("filter family", FILTER_FAMILIES),
        help="filter families every birth model runs in at every point (default gmphd)",
    )
    p.add_argument("--steps", action="store_true", help="also store the per-scan rows (steps/; large)")
    p.add_argument("--max-trials", type=int, default=20_000, help="refuse a larger design unless --force")
    p.add_argument("--force", action="store_true", help="run a design of more than --max-trials trials")
    p.add_argument(
        "--dry-run", action="store_true", help="print points, trials and estimated core-hours; run and write nothing"
    )
    p.add_argument("--no-report", action="store_true", help="no phase diagrams or report page at the end")


def handle(args: argparse.Namespace) -> int:
    from soabench.experiment.campaigns.atlas.design import design_from_dict, make_design, parse_axis
    from soabench.experiment.campaigns.atlas.run import AtlasRequest, run_atlas

    for flag, value in (
        ("--poly", args.poly[0] if args.poly else None),
        ("--scenario", args.scenario),
        ("--save-estimates", args.save_estimates or None),
        ("--fail-fast", args.fail_fast or None),
    ):
        require(
            value is None, f"{flag} is not offered by `atlas`: vary the scene with axes (net, parking.density, ...)"
        )
    require(args.out is not None, "--out FOLDER is required: the atlas folder (new, or an atlas to resume)")
    require(args.max_trials >= 1, f"--max-trials {args.max_trials} must be >= 1")
    options = common.run_options(args, None)
    cfg = common.config_from_args(args)
    axes = [parse_axis(a) for a in args.axis]
    kind, n_points = args.sample, args.points
    if args.design is not None:
        require(not axes, "--axis and --design are alternatives: give the axes on the command line or in the file")
        file_axes, opts = design_from_dict(read_toml(args.design, "design file"), str(args.design))
        axes = file_axes
        kind = kind or opts.get("kind")
        n_points = n_points if n_points is not None else opts.get("points")
    design = None
    if axes:
        design = make_design(axes, kind or "factorial", n_points, seed=cfg.experiment.seed)
    else:
        require(kind is None and n_points is None, "--sample/--points need axes (--axis or --design)")
    explicit = common.checks.requested_keys(args, getattr(args, "explicit", set()))
    req = AtlasRequest(
        out=args.out,
        net=args.net,
        design=design,
        config=cfg,
        steps=args.steps,
        max_trials=args.max_trials,
        force=args.force,
        dry_run=args.dry_run,
        report=not args.no_report,
        explicit=explicit,
    )
    if design is None:
        from soabench.experiment.campaigns.atlas.store import is_atlas
        from soabench.folders import resolve

        require(
            is_atlas(resolve(args.out)),
            f"no axes given and {str(args.out)!r} is not an atlas to resume; give --axis KEY=V1,V2,... or --design",
        )
    outcome = run_atlas(req, options)
    if args.dry_run:
        print(outcome.summary_markdown)
        return 0
    if outcome.summary_markdown:
        print(outcome.summary_markdown)
    if outcome.complete:
        print(f"atlas in {outcome.run_dir}")
        return 0
    print(
        f"atlas incomplete: {outcome.n_missing} trial(s) missing in {outcome.run_dir}; finish with: soabench atlas "
        f"--out {outcome.run_dir}",
        file=sys.stderr,
    )
    return 1
