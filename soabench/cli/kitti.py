"""``soabench kitti``: the paper's KITTI protocol (k-fold N_hat, Table I, Figs. 6-8) on a KITTI-format folder
(docs/user-guide/kitti.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from soabench.cli.parsing import FILTERS_HELP, csv_list, offsets
from soabench.config import BIRTH_MODEL_NAMES, FILTER_FAMILIES, PROBABILITY_MODES, require_distinct
from soabench.errors import require

#: the options of a new run: ``--resume`` takes them from the run folder and refuses them
NEW_RUN_OPTIONS = (
    "root", "detections", "semantics", "sequences", "out", "config", "models", "nhat_sweep", "classes", "velodyne",
    "point_labels", "lidar_grid", "lidar_closing", "lidar_fill", "filters",
)  # fmt: skip


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("kitti", help="the paper's KITTI protocol (k-fold N_hat, Table I, Figs. 6-8)")
    p.add_argument(
        "--root",
        help="KITTI tracking folder holding label_02/ (and calib/, oxts/); required unless --resume (default: none)",
    )
    p.add_argument("--detections", help="detections, KITTI result or AB3DMOT format (default ROOT/detections)")
    p.add_argument(
        "--semantics",
        help="per-frame bird's-eye semantic polygons per sequence (default: none)",
    )
    p.add_argument(
        "--point-labels", help="SemanticKITTI .label files XXXX/NNNNNN.label: S-OA's region from them (default: none)"
    )
    p.add_argument("--velodyne", help="KITTI scans XXXX/NNNNNN.bin for --point-labels (default ROOT/velodyne)")
    p.add_argument("--lidar-grid", type=float, help="raster cell (m) of the region from points (default 0.5)")
    p.add_argument("--lidar-closing", type=float, help="closing radius (m) of the region from points (default 1.0)")
    p.add_argument("--lidar-fill", type=float, help="longest gap (m) filled along a scan sector (default 8.0)")
    p.add_argument("--sequences", help="e.g. 0000-0020 or 0,3,5 (default: every labelled sequence)")
    p.add_argument("--folds", type=int, default=7, help="cross-validation folds (default 7; at most one per sequence)")
    p.add_argument("--nhat-sweep", type=offsets, help="N_hat offsets per sequence, e.g. -10:10 (default: no sweep)")
    p.add_argument("--models", type=csv_list("model", BIRTH_MODEL_NAMES), help="default soa,pubm,ubm,ubm-ws")
    p.add_argument("--probability", choices=PROBABILITY_MODES, help="probability mode (default static)")
    p.add_argument("--filters", type=csv_list("filter family", FILTER_FAMILIES), help=FILTERS_HELP)
    p.add_argument(
        "--config",
        metavar="FILE.toml",
        help="parameters, plus a [kitti] section (default: the protocol's)",
    )
    p.add_argument("--seed", type=int, help="base seed of the birth placement (default 0)")
    p.add_argument("--classes", type=csv_list("class"), help="tracked classes (default Pedestrian,Cyclist)")
    p.add_argument("--score-min", type=float, help="drop detections scoring below this (default: keep all)")
    p.add_argument("--skip-bad", action="store_true", help="skip (and report) sequences with malformed files")
    p.add_argument("--out", type=Path, help="run folder to create (default: none; needed unless --resume)")
    p.add_argument(
        "--resume",
        type=Path,
        metavar="RUN",
        help="finish an interrupted `soabench kitti` run (default: start a new one)",
    )


def handle(args: argparse.Namespace) -> int:
    from soabench.experiment.campaigns.kitti.protocol import run_kitti
    from soabench.kitti.config import KittiSpec, kitti_run_config
    from soabench.kitti.lidar import lidar_options
    from soabench.kitti.reader import parse_sequences

    if args.resume is not None:
        given = [f for f in NEW_RUN_OPTIONS if getattr(args, f) is not None]
        first = given[0].replace("_", "-") if given else ""
        require(not given, f"--resume takes its settings from the run folder; drop --{first}")
        outcome = run_kitti(None, args.resume, resume=True)
    else:
        require(args.root is not None, "--root DIR is required (a KITTI tracking folder holding label_02/)")
        require(args.out is not None, "--out RUN is required (the run folder to create)")
        cfg, kcfg = kitti_run_config(
            args.config, args.models, args.seed, args.probability, args.classes, args.score_min, args.filters
        )
        if args.nhat_sweep is not None:
            require_distinct("--nhat-sweep offsets", tuple(args.nhat_sweep))
        source = "--point-labels" if args.point_labels is not None else "--semantics" if args.semantics else None
        require(
            source is None or len(kcfg.semantic_classes) > 0,
            f"kitti.semantic_classes = [] names no class of the birth region {source} gives (S-OA's semantic births "
            "would have none); name at least one, e.g. ['sidewalk'] (the default)",
        )
        lidar = lidar_options(
            args.root, args.point_labels, args.velodyne, args.semantics, args.lidar_grid, args.lidar_closing,
            args.lidar_fill, kcfg.semantic_classes + kcfg.occluder_classes,
        )  # fmt: skip
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
            lidar=lidar,
        )
        outcome = run_kitti(spec, args.out)
    if outcome.summary_markdown:
        print(outcome.summary_markdown)
    if outcome.complete:
        print(f"results in {outcome.run_dir}")
        return 0
    print(f"run incomplete; finish with: soabench kitti --resume {outcome.run_dir}", file=sys.stderr)
    return 1
