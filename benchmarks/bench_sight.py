"""The line-of-sight test, compiled against GEOS, per call at the filters' and the sensor's sizes (plain script).

    python benchmarks/bench_sight.py [--peds 6,200] [--duration 30] [--reps 5]

For each pedestrian count: one SUMO trial of the shipped intersection and its scans (the paper's sensor, lambda =
3, seed 0). The calls are recorded as a run makes them: every line-of-sight test of a GM-PHD, an LMB and a PMBM run
in ``static+occ`` with S-OA's and UBM's births (the gate at the predicted means, one call per step and filter), and
the sensor's visibility test of every scan (the pedestrians in the FOV). Each call is then timed ``--reps`` times
in one process with :func:`soabench.sensor.line_of_sight_past` (the compiled test, GEOS for the pairs it leaves
open) and :func:`soabench.sensor._line_of_sight_reference` (GEOS for every pair): the filters' calls with the
scan's blockers built once and shared (as :func:`soabench.gmphd.probabilities.scan_line_of_sight` shares them), the
sensor's with fresh blockers per call (as :func:`soabench.sensor.observe` makes them). Both sides' decisions are
compared element for element first; printed: CPU microseconds per call, the ratio, and the pairs that went to GEOS.
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time

import numpy as np
from bench_lmb import births_of, scans_of


def filter_calls(cfg, scene, sensor, seeds, scans) -> list[tuple[np.ndarray, np.ndarray, list]]:
    """(ego, points, occluders) of every line-of-sight call of the static+occ runs, in the order made."""
    import soabench.gmphd.probabilities as prob
    from soabench.trackers import build_filter

    calls = []
    real = prob.line_of_sight_past

    def record(ego, points, blockers):
        calls.append((np.array(ego[:2], dtype=float), np.array(points, dtype=float).reshape(-1, 2), blockers.occ))
        return real(ego, points, blockers)

    prob.line_of_sight_past = record
    try:
        for family in ("gmphd", "lmb", "pmbm"):
            for name in ("soa", "ubm"):
                make = lambda fam=family: build_filter(fam, cfg, sensor, "static+occ", seeds.association_rng())[0]  # noqa: E731
                births_of(name, cfg, scene, sensor, seeds, scans, make)
    finally:
        prob.line_of_sight_past = real
    return calls


def sensor_calls(sensor, scans) -> list[tuple[np.ndarray, np.ndarray, list]]:
    """(ego, pedestrians in the FOV, occluders) of every scan: the sensor's own visibility test."""
    from soabench.geometry import fov_mask

    calls = []
    for k, scan in enumerate(scans.scans):
        xy = scans.truth_xy[k]
        ok = np.isfinite(xy).all(axis=1)
        ok[ok] = fov_mask(xy[ok], scan.ego, sensor)
        calls.append((np.asarray(scan.ego[:2], dtype=float), xy[ok], list(scan.occluders)))
    return calls


def timed(calls, shared: bool, reps: int) -> tuple[float, float, int]:
    """(compiled, GEOS) CPU microseconds per call, and the pairs the compiled test handed to GEOS."""
    from soabench.sensor import _line_of_sight_reference, line_of_sight_past, sight_blockers

    fast = [sight_blockers(e, o) for e, _, o in calls]
    slow = [sight_blockers(e, o) for e, _, o in calls]
    for (e, p, _), bf, bs in zip(calls, fast, slow, strict=True):  # same decisions; the shared blockers warmed
        if not np.array_equal(line_of_sight_past(e, p, bf), _line_of_sight_reference(e, p, bs)):
            raise SystemExit("the compiled test and GEOS disagree")
    fell_back = sum(b.fallback_pairs for b in fast)
    out = []
    for fn, blockers in ((line_of_sight_past, fast), (_line_of_sight_reference, slow)):
        t0 = time.process_time()
        for _ in range(reps):
            for (e, p, o), b in zip(calls, blockers, strict=True):
                fn(e, p, b if shared else sight_blockers(e, o))
        out.append((time.process_time() - t0) / (reps * len(calls)) * 1e6)
    return out[0], out[1], fell_back


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--peds", default="6,200", help="pedestrian counts, comma-separated (6 = the shipped scenario)")
    ap.add_argument("--duration", type=float, default=30.0, help="simulated seconds per trial")
    ap.add_argument("--reps", type=int, default=5, help="timed passes over the recorded calls")
    ap.add_argument("--sensor-only", action="store_true", help="time the sensor's calls only (no filter runs)")
    args = ap.parse_args()

    print(f"# bench_sight {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, python {sys.version.split()[0]}")
    print("peds  calls     number  points  occluders  compiled us  GEOS us  GEOS/compiled  pairs to GEOS")
    for peds in (int(p) for p in args.peds.split(",")):
        cfg, scene, sensor, seeds, scans = scans_of(peds, args.duration, 3.0, 0)
        kinds = [("sensor", sensor_calls(sensor, scans), False)]
        if not args.sensor_only:
            kinds.insert(0, ("filters", filter_calls(cfg, scene, sensor, seeds, scans), True))
        for label, calls, shared in kinds:
            fast, slow, fell_back = timed(calls, shared, args.reps)
            pts = np.mean([len(p) for _, p, _ in calls])
            occ = np.mean([len(o) for *_, o in calls])
            print(f"{peds:4d}  {label:8s} {len(calls):6d} {pts:7.1f} {occ:10.1f} {fast:12.1f} {slow:8.1f}"
                  f" {slow / fast:13.1f}x {fell_back:14d}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
