"""Every filter family's step against the GM-PHD's step at trial sizes, in one run (plain script, not a test).

    python benchmarks/bench_families.py [--peds 6,50] [--duration 100] [--clutter 3] [--seed 0] [--repeat 1]
                                        [--families gmphd,lmb,pmbm,pmb] [--clock wall|cpu] [--mode static|static+occ]

For each pedestrian count: one SUMO trial of the shipped intersection (the paper's sensor), its scans
observed once; for each of the six built-in birth models the births of every scan are computed once with the
GM-PHD in the loop (so the birth model's own time is outside every timing; ATBM prev_scan is not among the six),
then the same scans and births go through each family's filter as a run builds it
(:func:`soabench.trackers.build_filter`, the trial's association stream for the LMB's Gibbs seeds). Each filter
runs the sequence once to warm up (compiling or loading kernels) and then ``--repeat`` times; the best repeat's
total step time is kept. The table gives the mean step time per scan (ms) over the six models and the ratio of each
family's summed time to the GM-PHD's, measured in the same run. ``--clock cpu`` times the process's CPU time
instead of the wall clock: on a shared machine the wall clock also counts the time other processes hold the cores.
``--mode static+occ`` runs every family with the line-of-sight p_D (the births stay those computed with the static
GM-PHD in the loop): the mode that costs the families part of ``soabench results`` most.
"""

from __future__ import annotations

import argparse
import datetime
import functools
import os
import sys
import time

import numpy as np
from bench_lmb import MODELS, births_of, scans_of  # the same trial and births as the LMB's bench
from bench_lmb import run as run_wall  # its timing loop (wall clock)


def run_cpu(make_filter, scans, births, repeat: int) -> tuple[float, float]:
    """:func:`bench_lmb.run` with the process's CPU time as the clock."""
    best, kept = np.inf, 0.0
    for r in range(repeat + 1):
        filt = make_filter()
        n = 0
        t0 = time.process_time()
        for scan, b in zip(scans.scans, births, strict=True):
            n += filt.step(scan, b).n_reduced
        dt = time.process_time() - t0
        if r:
            best = min(best, dt)
        kept = n / len(births)
    return best, kept


def _maker(build_filter, cfg, sensor, seeds, family: str, mode: str = "static"):
    """``make()`` -> a fresh filter of ``family`` in probability ``mode``, as a run builds it."""
    return lambda: build_filter(family, cfg, sensor, mode, seeds.association_rng())[0]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--peds", default="6,50", help="pedestrian counts, comma-separated (6 = the shipped scenario)")
    ap.add_argument("--duration", type=float, default=100.0, help="simulated seconds per trial")
    ap.add_argument("--clutter", type=float, default=3.0, help="clutter rate lambda")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=1, help="timed runs per filter (best kept)")
    ap.add_argument("--families", default="gmphd,lmb,pmbm,pmb", help="families, comma-separated; gmphd first")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall", help="wall clock or the process's CPU time")
    ap.add_argument("--mode", choices=("static", "static+occ"), default="static",
                    help="every family's probability mode (static+occ: the line-of-sight p_D)")  # fmt: skip
    args = ap.parse_args()
    run = run_cpu if args.clock == "cpu" else run_wall

    from soabench.trackers import build_filter

    families = args.families.split(",")
    if families[0] != "gmphd":
        ap.error("--families must start with gmphd (the reference of every ratio)")
    now = f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC"
    load = " ".join(f"{x:.1f}" for x in os.getloadavg())
    head = f"# bench_families {now}, python {sys.version.split()[0]}, {args.clock} clock, {args.mode}"
    print(f"{head}, load average {load}")
    print("peds  M/scan  model   " + "".join(f"{f:>10s} ms {'kept':>6s}" for f in families))
    for peds in (int(p) for p in args.peds.split(",")):
        cfg, scene, sensor, seeds, scans = scans_of(peds, args.duration, args.clutter, args.seed)
        K = len(scans.scans)
        M = np.mean([len(s.Z) for s in scans.scans])

        maker = functools.partial(_maker, build_filter, cfg, sensor, seeds)

        total = dict.fromkeys(families, 0.0)
        for name in MODELS:
            births = births_of(name, cfg, scene, sensor, seeds, scans, maker("gmphd"))
            cells = []
            for fam in families:
                t, kept = run(maker(fam, args.mode), scans, births, args.repeat)
                total[fam] += t
                cells.append(f"{1e3 * t / K:13.2f} {kept:6.1f}")
            print(f"{peds:4d}  {M:6.1f}  {name:7s}" + "".join(cells))
        per_scan = "".join(f"{1e3 * total[f] / (K * len(MODELS)):13.2f} {'':6s}" for f in families)
        print(f"{peds:4d}  {M:6.1f}  mean   " + per_scan)
        ratios = "  ".join(f"{f}/gmphd {total[f] / total['gmphd']:.2f}x" for f in families[1:])
        print(f"{peds:4d}  ratios  {ratios}")
    print(f"# load average at the end {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
