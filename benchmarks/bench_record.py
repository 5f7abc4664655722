"""Time recording one 100 s scenario of the shipped intersection with libsumo.

Usage: python benchmarks/bench_record.py [--net intersection] [--repeat 5] [--model jupedsim]
Prints the scene-load time and the median / min wall time of ``simulate`` over ``--repeat`` seeds.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

from soabench.scenario import load, simulate
from soabench.seeding import trial_seeds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--net", default="intersection")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--model", default=None, help="pedestrian model (default: the scenario's)")
    ap.add_argument("--duration", type=float, default=None)
    args = ap.parse_args()

    t0 = time.perf_counter()
    scene, sc = load(args.net)
    t_load = time.perf_counter() - t0
    if args.model:
        sc = dataclasses.replace(sc, pedestrian_model=args.model)
    times = []
    for seed in range(args.repeat):
        t0 = time.perf_counter()
        rec = simulate(scene, sc, trial_seeds(seed, 0), duration=args.duration)
        times.append(time.perf_counter() - t0)
    T = len(rec.t)
    print(f"net={args.net} model={sc.pedestrian_model} steps={T} ({T * sc.step_length:.0f} s simulated)")
    print(f"load (scene map): {t_load:.3f} s")
    print(f"simulate: median {statistics.median(times):.3f} s, min {min(times):.3f} s over {args.repeat} seeds")


if __name__ == "__main__":
    main()
