"""Every filter family's step against the GM-PHD's step at trial sizes, in one run (plain script, not a test).

    python benchmarks/bench_families.py [--peds 6,50] [--duration 100] [--clutter 3] [--seed 0] [--repeat 1]
                                        [--families gmphd,lmb,pmbm,pmb]

For each pedestrian count: one SUMO trial of the shipped intersection (static mode, the paper's sensor), its scans
observed once; for each of the six built-in birth models the births of every scan are computed once with the
GM-PHD in the loop (so the birth model's own time is outside every timing; ATBM prev_scan is not among the six),
then the same scans and births go through each family's filter as a run builds it
(:func:`soabench.trackers.build_filter`, the trial's association stream for the LMB's Gibbs seeds). Each filter
runs the sequence once to warm up (compiling or loading kernels) and then ``--repeat`` times; the best repeat's
total step time is kept. The table gives the mean step time per scan (ms) over the six models and the ratio of each
family's summed time to the GM-PHD's, measured in the same run.
"""

from __future__ import annotations

import argparse
import datetime
import functools
import sys

import numpy as np
from bench_lmb import MODELS, births_of, run, scans_of  # the same trial, births and timing loop as the LMB's bench


def _maker(build_filter, cfg, sensor, seeds, family: str):
    """``make()`` -> a fresh filter of ``family`` in static mode, as a run builds it."""
    return lambda: build_filter(family, cfg, sensor, "static", seeds.association_rng())[0]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--peds", default="6,50", help="pedestrian counts, comma-separated (6 = the shipped scenario)")
    ap.add_argument("--duration", type=float, default=100.0, help="simulated seconds per trial")
    ap.add_argument("--clutter", type=float, default=3.0, help="clutter rate lambda")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=1, help="timed runs per filter (best kept)")
    ap.add_argument("--families", default="gmphd,lmb,pmbm,pmb", help="families, comma-separated; gmphd first")
    args = ap.parse_args()

    from soabench.trackers import build_filter

    families = args.families.split(",")
    if families[0] != "gmphd":
        ap.error("--families must start with gmphd (the reference of every ratio)")
    print(f"# bench_families {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, python {sys.version.split()[0]}")
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
                t, kept = run(maker(fam), scans, births, args.repeat)
                total[fam] += t
                cells.append(f"{1e3 * t / K:13.2f} {kept:6.1f}")
            print(f"{peds:4d}  {M:6.1f}  {name:7s}" + "".join(cells))
        per_scan = "".join(f"{1e3 * total[f] / (K * len(MODELS)):13.2f} {'':6s}" for f in families)
        print(f"{peds:4d}  {M:6.1f}  mean   " + per_scan)
        ratios = "  ".join(f"{f}/gmphd {total[f] / total['gmphd']:.2f}x" for f in families[1:])
        print(f"{peds:4d}  ratios  {ratios}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
