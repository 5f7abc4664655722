"""Handlers of ``soabench kitti`` and ``soabench export kitti`` (the parser lines live in :mod:`soabench.cli`)."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from soabench.errors import require


def cmd_kitti(args: argparse.Namespace) -> int:
    """The paper's KITTI protocol on a KITTI-format folder (``soabench kitti --root DIR ... --out RUN``)."""
    from soabench.config import require_distinct
    from soabench.kitti.config import KittiSpec, load_kitti_config
    from soabench.kitti.protocol import run_kitti
    from soabench.kitti.reader import parse_sequences

    if args.resume is not None:
        flags = ("root", "detections", "semantics", "sequences", "out", "config", "models", "nhat_sweep", "classes")
        flags += ("velodyne", "point_labels", "lidar_grid", "lidar_closing", "lidar_fill")
        given = [f for f in flags if getattr(args, f) is not None]
        first = given[0].replace("_", "-") if given else ""
        require(not given, f"--resume takes its settings from the run folder; drop --{first}")
        outcome = run_kitti(None, args.resume, resume=True)
    else:
        require(args.root is not None, "--root DIR is required (a KITTI tracking folder holding label_02/)")
        require(args.out is not None, "--out RUN is required (the run folder to create)")
        cfg, kcfg = load_kitti_config(args.config)
        exp = cfg.experiment
        overrides = {"models": args.models, "seed": args.seed}
        if args.probability is not None:
            overrides["probabilities"] = (args.probability,)
        cfg.experiment = dataclasses.replace(exp, **{k: v for k, v in overrides.items() if v is not None})
        cfg.validate()
        if args.nhat_sweep is not None:
            require_distinct("--nhat-sweep offsets", tuple(args.nhat_sweep))
        if args.classes is not None:
            kcfg = dataclasses.replace(kcfg, classes=tuple(args.classes)).validate()
        if args.score_min is not None:
            kcfg = dataclasses.replace(kcfg, score_min=float(args.score_min)).validate()
        spec = KittiSpec(
            root=str(Path(args.root).resolve()),
            detections=str(Path(args.detections).resolve()) if args.detections else None,
            semantics=str(Path(args.semantics).resolve()) if args.semantics else None,
            sequences=parse_sequences(args.sequences) if args.sequences is not None else None,
            folds=args.folds,
            nhat_sweep=list(args.nhat_sweep) if args.nhat_sweep is not None else None,
            skip_bad=args.skip_bad,
            config=cfg,
            kitti=kcfg,
            lidar=lidar_options(args, kcfg),
        )
        outcome = run_kitti(spec, args.out)
    if outcome.summary_markdown:
        print(outcome.summary_markdown)
    if outcome.complete:
        print(f"results in {outcome.run_dir}")
        return 0
    print(f"run incomplete; finish with: soabench kitti --resume {outcome.run_dir}", file=sys.stderr)
    return 1


def cmd_export(args: argparse.Namespace) -> int:
    """``soabench export kitti``: SUMO trials written in the KITTI tracking layout."""
    from soabench.cli_checks import check_time
    from soabench.config import MAX_SEED
    from soabench.kitti.config import load_kitti_config
    from soabench.kitti.export import MAX_EXPORT_TRIALS, export_kitti

    require(
        args.trials is not None and 1 <= args.trials <= MAX_EXPORT_TRIALS,
        f"--trials {args.trials!r} is out of range; allowed: integers in [1, {MAX_EXPORT_TRIALS}] "
        "(sequence ids 0000-9999)",
    )
    check_time("--duration", args.duration)
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


def lidar_options(args: argparse.Namespace, kcfg) -> dict | None:
    """``spec.lidar`` from ``--point-labels DIR [--velodyne DIR] [--lidar-grid M] [--lidar-closing M] [--lidar-fill
    M]`` (None without ``--point-labels``); one line naming the bad value otherwise."""
    from soabench.kitti.lidar import LidarParams, class_ids

    lidar_only = [f for f in ("velodyne", "lidar_grid", "lidar_closing", "lidar_fill") if getattr(args, f) is not None]
    if args.point_labels is None:
        require(not lidar_only, f"--{lidar_only[0].replace('_', '-') if lidar_only else ''} needs --point-labels DIR")
        return None
    require(args.semantics is None, "give either --semantics DIR or --point-labels DIR (two sources of one region)")
    velodyne = Path(args.velodyne) if args.velodyne is not None else Path(args.root) / "velodyne"
    require(velodyne.is_dir(), f"--velodyne {str(velodyne)!r} is not a folder (KITTI scans XXXX/NNNNNN.bin)")
    labels = Path(args.point_labels)
    require(labels.is_dir(), f"--point-labels {str(labels)!r} is not a folder (SemanticKITTI XXXX/NNNNNN.label)")
    class_ids(kcfg.semantic_classes + kcfg.occluder_classes)
    given = {"grid": args.lidar_grid, "closing": args.lidar_closing, "fill": args.lidar_fill}
    params = LidarParams(**{k: float(v) for k, v in given.items() if v is not None}).validate()
    return {"velodyne": str(velodyne.resolve()), "point_labels": str(labels.resolve()), **dataclasses.asdict(params)}
