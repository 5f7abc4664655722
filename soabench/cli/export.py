"""``soabench export kitti``: SUMO trials written in the KITTI tracking layout (docs/user-guide/kitti.md)."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from soabench.cli.parsing import add_net_args
from soabench.config import MAX_SEED
from soabench.errors import require


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="write SUMO trials in another format (kitti: the KITTI tracking layout)")
    p.add_argument("format", choices=["kitti"])
    add_net_args(p)
    p.add_argument("--trials", type=int, required=True, help="trials, written as sequences 0000, 0001, ...")
    p.add_argument("--duration", type=float, help="seconds per trial (default: the scenario's)")
    p.add_argument("--seed", type=int, help="base seed (as in `run`, default 0)")
    p.add_argument("--fov-deg", type=float, help="camera horizontal FOV (default: the nominal KITTI camera's)")
    p.add_argument("--out", required=True, help="output folder (KITTI layout)")
    p.add_argument("--lidar", action="store_true", help="also write synthetic velodyne scans and SemanticKITTI labels")


def handle(args: argparse.Namespace) -> int:
    from soabench.kitti.config import load_kitti_config
    from soabench.kitti.export import check_export_size, export_kitti

    check_export_size(args.trials, args.duration)
    cfg, _ = load_kitti_config(args.config)
    if args.seed is not None:
        require(0 <= args.seed <= MAX_SEED, f"--seed {args.seed} is out of range; allowed: integers in [0, {MAX_SEED}]")
        cfg.experiment = dataclasses.replace(cfg.experiment, seed=args.seed)
    out = Path(args.out)
    rows = export_kitti(
        cfg, args.net, tuple(args.poly), args.scenario, args.trials, out, duration=args.duration, fov_deg=args.fov_deg,
        lidar=args.lidar,
    )  # fmt: skip
    print(f"wrote {len(rows)} sequence(s) in the KITTI tracking layout to {out}")
    return 0
