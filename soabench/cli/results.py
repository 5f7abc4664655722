"""``soabench results``: every part of results/ from one command, each part resumable."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from soabench.cli.parsing import csv_list
from soabench.experiment.campaigns.results_suite import Settings, run_results
from soabench.experiment.execution.options import RunOptions


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "results", help="regenerate all of results/: study, filter families, every scene, summary, KITTI"
    )
    d = Settings()
    p.add_argument("--out", type=Path, default=Path("results"), help="results folder (default results)")
    p.add_argument("--scenes", type=csv_list("scene"), help="shipped scenes of the summary (default: every one)")
    p.add_argument(
        "--trials", type=int, default=d.trials, help="trials of the intersection study's main protocol and families run"
    )
    p.add_argument("--duration", type=float, default=d.duration, help="seconds per SUMO trial")
    p.add_argument("--seed", type=int, default=d.seed, help="base seed of every part")
    p.add_argument("--births-trials", type=int, default=d.births_trials, help="trials per point of the N_hat sweep")
    p.add_argument(
        "--scene-trials",
        type=int,
        default=d.scene_trials,
        help="trials of the main protocol of each other scene's study",
    )
    p.add_argument("--density-trials", type=int, default=d.density_trials, help="trials per scene for its density")
    p.add_argument(
        "--kitti-scenes",
        type=csv_list("scene"),
        default=",".join(d.kitti_scenes),
        help="scenes exported in the KITTI layout, or none",
    )
    p.add_argument("--kitti-sequences", type=int, default=d.kitti_sequences, help="KITTI sequences per scene")
    p.add_argument("--kitti-duration", type=float, default=d.kitti_duration, help="seconds per KITTI sequence")
    p.add_argument("--kitti-folds", type=int, default=d.kitti_folds, help="cross-validation folds of N_hat")
    p.add_argument(
        "--atlas-scenes",
        type=csv_list("scene"),
        default=",".join(d.atlas_scenes),
        help="scenes of the atlas part (parking x pedestrians x clutter x p_D), or none",
    )
    p.add_argument("--atlas-trials", type=int, default=d.atlas_trials, help="trials per atlas point")
    p.add_argument("--workers", type=int, help="process workers (default: every core)")
    p.add_argument("--no-progress", action="store_true", help="no progress report")


def handle(args: argparse.Namespace) -> int:

    settings = Settings(
        scenes=tuple(args.scenes) if args.scenes else None,
        trials=args.trials,
        duration=args.duration,
        seed=args.seed,
        births_trials=args.births_trials,
        scene_trials=args.scene_trials,
        density_trials=args.density_trials,
        kitti_scenes=() if tuple(args.kitti_scenes) == ("none",) else tuple(args.kitti_scenes),
        kitti_sequences=args.kitti_sequences,
        kitti_duration=args.kitti_duration,
        kitti_folds=args.kitti_folds,
        atlas_scenes=() if tuple(args.atlas_scenes) == ("none",) else tuple(args.atlas_scenes),
        atlas_trials=args.atlas_trials,
    )
    o = run_results(args.out, settings, options=RunOptions(workers=args.workers, progress=not args.no_progress))
    rows = [
        f"| {k} | {v} | {f'{o.seconds[k]:.0f}' if k in o.seconds else 'in the study'} |" for k, v in o.parts.items()
    ]
    print("\n".join(["| part | result | wall time (s) |", "|---|---|---:|", *rows]))
    if o.complete:
        print(f"results in {o.run_dir}")
        return 0
    print(
        f"results incomplete ({o.n_missing} trial(s) missing); finish with: soabench results --out {o.run_dir} "
        "(and the same options)",
        file=sys.stderr,
    )
    return 1
