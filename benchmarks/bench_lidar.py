"""Building S-OA's semantic regions from segmented scans against the filters on the same sequence (plain script, not
a test).

    python benchmarks/bench_lidar.py [--duration 40] [--out DIR] [--repeat 3]

Exports one SUMO trial of ``--duration`` s (10 Hz: 400 frames for 40 s) with ``soabench export kitti --lidar``,
then times, in this one run:

* ``regions``: :func:`soabench.kitti.lidar.sequence_regions` on all frames, default parameters, no cache (reading the
  .bin/.label files, gap fill, raster, closing, polygons; the compiled loops of :mod:`soabench.kitti.lidar_raster`
  loaded beforehand, as the filter kernels are);
* ``regions (cached)``: the same call reading back the run folder's ``.npz``;
* ``to_scans``: the reader's Scans of the sequence with those regions (Omega_k per frame), and with the export's own
  sidewalk polygons (``--semantics``) for comparison;
* ``filters``: :func:`soabench.experiment.campaigns.kitti.protocol.run_sequence` with S-OA alone and with the
  protocol's four models.

Regions and filters are each timed ``--repeat`` times and the shortest time of each counts (on a shared machine the
longer ones measure the neighbours). It prints each time and the ratios regions / filters.
"""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import tempfile
import time
from pathlib import Path

from soabench.experiment.campaigns.kitti.protocol import run_sequence
from soabench.kitti.config import KittiConfig, kitti_base_config
from soabench.kitti.export import export_kitti
from soabench.kitti.lidar import LidarParams, class_ids, frame_files, frame_regions, read_frame, sequence_regions
from soabench.kitti.reader import open_dataset, read_sequence, sensor_for, to_scans


def _list(times: list[float]) -> str:
    return ", ".join(f"{t:.2f}" for t in times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=40.0, help="seconds of the exported trial (default 40)")
    ap.add_argument("--out", type=Path, help="keep the export here (default: a temporary folder)")
    ap.add_argument("--repeat", type=int, default=3, help="time regions and filters this many times (default 3)")
    args = ap.parse_args()
    if args.repeat < 1:
        ap.error(f"--repeat {args.repeat} must be at least 1")
    tmp = Path(tempfile.mkdtemp(prefix="bench_lidar_"))
    root = args.out or tmp / "export"
    cfg = kitti_base_config()
    if not (root / "velodyne").is_dir():
        export_kitti(cfg, "intersection", (), None, 1, root, duration=args.duration, lidar=True, log=lambda m: None)
    kc = KittiConfig()
    seq = read_sequence(open_dataset(root), "0000")
    names = ("sidewalk", "building")
    cache = tmp / "lidar"
    vel, lab = root / "velodyne", root / "point_labels"
    fov = sensor_for(seq, kc, cfg.sensor_at()).fov_deg
    scan, labels, _ = frame_files(vel, lab, "0000", 1)[0]
    frame_regions(*read_frame(scan, labels), class_ids(names), LidarParams(), cfg.sensor.r_max, fov)  # compile/load
    t_regions = []
    for _ in range(args.repeat):
        shutil.rmtree(cache, ignore_errors=True)
        t0 = time.perf_counter()
        sem, _ = sequence_regions(vel, lab, "0000", seq.n_frames, names, LidarParams(), cfg.sensor.r_max, cache, fov)
        t_regions.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    _, hit = sequence_regions(vel, lab, "0000", seq.n_frames, names, LidarParams(), cfg.sensor.r_max, cache, fov)
    t_cached = time.perf_counter() - t0
    assert hit
    t0 = time.perf_counter()
    ss = to_scans(dataclasses.replace(seq, semantics=sem), kc, cfg.sensor_at())
    t_scans = time.perf_counter() - t0
    t0 = time.perf_counter()
    to_scans(read_sequence(open_dataset(root, None, root / "semantics"), "0000"), kc, cfg.sensor_at())
    t_poly = time.perf_counter() - t0
    n_hat = 6 / 100
    run_sequence(ss, cfg, n_hat, 0, "0000")  # compile the kernels outside the timed calls
    times: dict[str, list[float]] = {}
    for _ in range(args.repeat):
        for models in (("soa",), cfg.experiment.models):
            c = dataclasses.replace(cfg, experiment=dataclasses.replace(cfg.experiment, models=models))
            t0 = time.perf_counter()
            run_sequence(ss, c, n_hat, 0, "0000")
            times.setdefault(",".join(models), []).append(time.perf_counter() - t0)
    best = min(t_regions)
    print(f"{seq.n_frames} frames; regions and filters: the shortest of {args.repeat} repeats")
    print(f"regions (built)  {best:8.2f} s  ({1e3 * best / seq.n_frames:.1f} ms/frame; all: {_list(t_regions)})")
    print(f"regions (cached) {t_cached:8.2f} s")
    print(f"to_scans         {t_scans:8.2f} s  (with the scene's polygons: {t_poly:.2f} s)")
    for m, t in times.items():
        print(f"filters {m:<20s} {min(t):8.2f} s   regions / filters = {best / min(t):.2f}  (all: {_list(t)})")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
