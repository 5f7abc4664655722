"""Tiny hand-made KITTI tracking folders for the KITTI tests (no SUMO): one pedestrian walking across the camera."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def label_row(frame: int, tid: int, typ: str, x: float, z: float, occluded: int = 0, score: float | None = None) -> str:
    """A label (or, with ``score``, a tracking-result) row at camera position (x, 1.65, z)."""
    row = f"{frame} {tid} {typ} 0 {occluded} 0.0 -1 -1 -1 -1 1.75 0.6 0.8 {x!r} 1.65 {z!r} 0.0"
    return row if score is None else f"{row} {score!r}"


def write_sequence(root: Path, seq: str, n_frames: int = 12, shift: float = 0.0, oxts: bool = True) -> None:
    """Sequence ``seq``: pedestrian 0 walks across at 15 m, a car parked at 25 m; detections = the truth + clutter."""
    for d in ("label_02", "detections", "oxts"):
        (root / d).mkdir(parents=True, exist_ok=True)
    labels, dets = [], []
    for k in range(n_frames):
        x = -3.0 + 0.5 * k + shift
        labels.append(label_row(k, 0, "Pedestrian", x, 15.0))
        labels.append(f"{k} 1 Car 0 0 0.0 -1 -1 -1 -1 1.5 1.8 4.2 3.0 1.65 25.0 0.0")
        labels.append(f"{k} -1 DontCare -1 -1 -10 1 2 3 4 -1 -1 -1 -1000 -1000 -1000 -10")
        dets.append(label_row(k, -1, "Pedestrian", x, 15.0, score=0.9))
        if k % 3 == 0:
            dets.append(label_row(k, -1, "Pedestrian", 6.0, 30.0, score=0.2))
    (root / "label_02" / f"{seq}.txt").write_text("\n".join(labels) + "\n")
    (root / "detections" / f"{seq}.txt").write_text("\n".join(dets) + "\n")
    if oxts:
        rows = [" ".join(["49.0", "8.43", "0"] + ["0"] * 22 + ["4", "10", "4", "4", "6"])] * n_frames
        (root / "oxts" / f"{seq}.txt").write_text("\n".join(rows) + "\n")


def write_dataset(root: Path, n: int = 3, n_frames: int = 12) -> Path:
    for i in range(n):
        write_sequence(root, f"{i:04d}", n_frames=n_frames, shift=float(i))
    return root


def ab3dmot_rows(result_text: str) -> str:
    """The rows of a KITTI tracking-result detection file in AB3DMOT's comma-separated format."""
    ids = {"Pedestrian": 1, "Car": 2, "Cyclist": 3}
    out = []
    for line in result_text.splitlines():
        t = line.split()
        if not t:
            continue
        cols = [t[0], str(ids[t[2]]), *t[6:10], t[17], *t[10:17], t[5]]
        out.append(",".join(cols))
    return "\n".join(out) + "\n"


def finite(a: np.ndarray) -> np.ndarray:
    return a[np.isfinite(a)]
