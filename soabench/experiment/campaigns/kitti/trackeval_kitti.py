"""TrackEval's own KITTI evaluation beside ours (docs/user-guide/kitti.md "TrackEval's KITTI evaluation").

The usual tool scores KITTI tracking in the image: each track is a 2-D box, matched to the label boxes by
intersection over union (at least 0.5), and its KITTI reader (TrackEval's ``Kitti2DBox``) drops from the truth
every pedestrian labelled ``occluded`` above 2 or ``truncated`` above 0, together with the estimates matched to
them, and counts a person sitting as neither hit nor miss (its distractor rule). Our track metrics score every
labelled pedestrian in the field of view in the ground plane. To set the two side by side, each estimate of a
labelled model is written as the KITTI result row of a pedestrian box (the size the export uses) standing at the
estimate, projected with the sequence's camera (:mod:`soabench.experiment.campaigns.kitti.results`), and TrackEval's own
``Evaluator`` runs HOTA, CLEAR and Identity over the cross-validation sequences, its label files copied as they are.
"""

from __future__ import annotations

import contextlib
import io
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from soabench.kitti.reader import KittiSequence, SequenceScans

#: the folder of the run that holds TrackEval's inputs: ``gt/`` (label files, seqmap) and ``trackers/<model>/data/``
TRACKEVAL_DIR = "trackeval"
SEQMAP = "evaluate_tracking.seqmap.training"


def write_inputs(out: Path, seq: KittiSequence, ss: SequenceScans, runs: dict[str, tuple[list, list]]) -> None:
    """Copy the sequence's label file and write each labelled model's estimates as KITTI results (``runs``: model ->
    (X, labels) per frame; :func:`soabench.experiment.campaigns.kitti.results.write_tracking_results`)."""
    from soabench.experiment.campaigns.kitti.results import write_tracking_results

    base = out / TRACKEVAL_DIR
    (base / "gt" / "label_02").mkdir(parents=True, exist_ok=True)
    shutil.copyfile(seq.labels.path, base / "gt" / "label_02" / f"{seq.seq}.txt")
    egos = np.array([s.ego for s in ss.scans.scans], dtype=float).reshape(-1, 3)
    for model, (X, labels) in runs.items():
        write_tracking_results(base / "trackers" / model, int(seq.seq), X, labels, egos, seq.calib, ss.sensor.r_max)


def evaluate(out: Path, sequences: Sequence[str], frames: dict[str, int], models: Sequence[str]) -> dict:
    """TrackEval's KITTI evaluation (class pedestrian, every sequence pooled as TrackEval combines them) of the
    models whose result files exist for every sequence: per model HOTA, DetA, AssA, MOTA, IDF1, IDSW and the truth
    detections it keeps (``gt_dets``); {"error": ...} when TrackEval refuses the inputs."""
    try:
        import trackeval
    except ImportError:
        return {"error": "TrackEval is not installed (pip install trackeval)"}

    base = out / TRACKEVAL_DIR
    gt = base / "gt"
    if not sequences or not (gt / "label_02").is_dir():
        return {}
    (gt / SEQMAP).write_text("".join(f"{s} empty 000000 {frames[s]:06d}\n" for s in sequences), encoding="utf-8")
    trackers = [m for m in models if all((base / "trackers" / m / "data" / f"{s}.txt").is_file() for s in sequences)]
    if not trackers:
        return {}
    quiet = {"PRINT_CONFIG": False}
    dataset = trackeval.datasets.Kitti2DBox({
        "GT_FOLDER": str(gt), "TRACKERS_FOLDER": str(base / "trackers"), "OUTPUT_FOLDER": str(base / "output"),
        "TRACKERS_TO_EVAL": trackers, "CLASSES_TO_EVAL": ["pedestrian"], "SPLIT_TO_EVAL": "training", **quiet,
    })  # fmt: skip
    evaluator = trackeval.Evaluator({
        "USE_PARALLEL": False, "PRINT_RESULTS": False, "PRINT_ONLY_COMBINED": True, "PRINT_CONFIG": False,
        "TIME_PROGRESS": False, "DISPLAY_LESS_PROGRESS": True, "OUTPUT_SUMMARY": False, "OUTPUT_EMPTY_CLASSES": False,
        "OUTPUT_DETAILED": False, "PLOT_CURVES": False, "BREAK_ON_ERROR": False, "RETURN_ON_ERROR": True,
        "LOG_ON_ERROR": None,
    })  # fmt: skip
    metrics = [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR(quiet), trackeval.metrics.Identity(quiet)]
    with contextlib.redirect_stdout(io.StringIO()):
        res, msg = evaluator.evaluate([dataset], metrics)
    out_res = {}
    for m in trackers:
        if msg.get("Kitti2DBox", {}).get(m) != "Success":
            return {"error": str(msg.get("Kitti2DBox", {}).get(m))}
        r = res["Kitti2DBox"][m]["COMBINED_SEQ"]["pedestrian"]
        out_res[m] = {
            "hota": float(np.mean(r["HOTA"]["HOTA"])),
            "deta": float(np.mean(r["HOTA"]["DetA"])),
            "assa": float(np.mean(r["HOTA"]["AssA"])),
            "mota": float(r["CLEAR"]["MOTA"]),
            "idf1": float(r["Identity"]["IDF1"]),
            "idsw": int(r["CLEAR"]["IDSW"]),
            "gt_dets": int(r["CLEAR"]["CLR_TP"] + r["CLEAR"]["CLR_FN"]),
        }
    return out_res
