"""``soabench birth``: one birth model's components over one trial's scene at a time (paper Fig. 2 colours)."""

from __future__ import annotations

import argparse

from soabench.cli.parsing import add_snapshot_args
from soabench.config import PROBABILITY_MODES


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("birth", help="birth components of one model over the scene (paper Fig. 2 colours)")
    add_snapshot_args(p)
    p.add_argument("--time", type=float, default=50.0, help="time of the snapshot (s)")
    p.add_argument("--model", default="soa", help="soa, pubm, ubm, atbm, gmbm, an installed plugin or module:Class")
    p.add_argument("--probability", default="static", choices=PROBABILITY_MODES, help="probability mode")


def handle(args: argparse.Namespace) -> int:
    from soabench.birth import LABEL
    from soabench.experiment.trial.snapshot import births_at_end, check_birth_model, take_snapshot
    from soabench.figures.births import births_snapshot_figure
    from soabench.figures.style import save_png
    from soabench.folders import check_out_file

    out = check_out_file(args.out, ".png")
    check_birth_model(args.model)  # an unknown or broken model fails before SUMO runs
    snap = take_snapshot(
        args.net, tuple(args.poly), args.scenario, args.config, args.seed, args.trial, args.time, args.command, True
    )
    births, scan = births_at_end(snap, snap.scans(), args.model, args.probability)
    label = LABEL.get(args.model, args.model)
    save_png(births_snapshot_figure(snap.scene, snap.recording, births, scan, label), out)
    n_new = 0 if births.newborn is None else len(births.newborn.m)
    print(f"wrote {out} ({len(births)} components, {n_new} newborn terms)")
    return 0
