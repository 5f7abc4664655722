"""``soabench record``: one trial's ground truth (and its scans) as .npz files (docs/user-guide/outputs.md)."""

from __future__ import annotations

import argparse

from soabench.cli.parsing import add_snapshot_args
from soabench.errors import require


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="write the ground truth (and scans) of one scenario run to .npz")
    add_snapshot_args(p)
    p.add_argument("--duration", type=float, help="seconds (default: the scenario's)")
    p.add_argument(
        "--scans",
        nargs="?",
        const="",
        default=None,
        metavar="FILE",
        help="also write the sensor scans (default file: OUT with .scans.npz)",
    )


def handle(args: argparse.Namespace) -> int:
    from soabench.experiment.trial.snapshot import take_snapshot
    from soabench.folders import check_out_file

    out = check_out_file(args.out, ".npz")
    scans_out = None
    if args.scans is not None:
        scans_out = (
            check_out_file(args.scans, ".npz", "--scans") if args.scans else out.with_name(f"{out.stem}.scans.npz")
        )
        require(scans_out != out, f"--scans {args.scans!r} is the --out file; give the scans their own file")
    snap = take_snapshot(
        args.net, tuple(args.poly), args.scenario, args.config, args.seed, args.trial, args.duration, args.command
    )
    snap.recording.save_npz(out)
    print(f"wrote {out} ({len(snap.recording.t)} steps, {len(snap.recording.ped_ids)} pedestrians)")
    if scans_out is not None:
        scans = snap.scans()
        scans.save_npz(scans_out)
        print(f"wrote {scans_out} ({len(scans)} scans, {sum(len(s.Z) for s in scans.scans)} measurements)")
    return 0
