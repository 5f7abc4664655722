"""``soabench scene``: the bird's-eye view of one trial's scene at a time (paper Fig. 3), optionally under the
sensor overlay."""

from __future__ import annotations

import argparse

from soabench.cli.parsing import add_snapshot_args


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("scene", help="bird's-eye view of a scenario (paper Fig. 3)")
    add_snapshot_args(p)
    p.add_argument("--time", type=float, default=50.0, help="time of the snapshot (s)")
    p.add_argument("--sensor", action="store_true", help="overlay FOV, sight lines, measurements, obstacle cones")


def handle(args: argparse.Namespace) -> int:
    from soabench.experiment.trial.snapshot import take_snapshot
    from soabench.figures.sensor import scene_snapshot_figure
    from soabench.figures.style import save_png
    from soabench.folders import check_out_file

    out = check_out_file(args.out, ".png")
    snap = take_snapshot(
        args.net, tuple(args.poly), args.scenario, args.config, args.seed, args.trial, args.time, args.command, True
    )
    scans = snap.scans() if args.sensor else None
    save_png(scene_snapshot_figure(snap.scene, snap.recording, args.time, scans, snap.config.sensor), out)
    print(f"wrote {out}")
    return 0
