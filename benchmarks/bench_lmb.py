"""The LMB filter's step against the GM-PHD's step at trial sizes, in one run (plain script, not a test).

    python benchmarks/bench_lmb.py [--peds 6,50] [--duration 100] [--clutter 3] [--seed 0]

For each pedestrian count: one SUMO trial of the shipped intersection (static mode, the paper's sensor), its scans
observed once; for each of the six built-in birth models the births of every scan are computed once (so the birth
model's own time is outside both timings), then the same scans and births go through ``GMPHDFilter.step`` (the fused
default) and ``LMBFilter.step`` (Gibbs seeds from the trial's association stream). Each filter runs the sequence
once to warm up (compiling or loading the kernels) and then ``--repeat`` times; the best repeat's total step time is
reported, with the mean tracks / components kept per scan and the mean measurements per scan. The ratio LMB / GM-PHD
of the summed step times is what the README records.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import functools
import sys
import time

import numpy as np

MODELS = ("soa", "pubm", "ubm", "ubm-ws", "atbm", "gmbm")


def scans_of(peds: int, duration: float, lam: float, seed: int):
    from soabench.config import Config
    from soabench.scenario import load, simulate
    from soabench.seeding import trial_seeds
    from soabench.sensor import observe

    cfg = Config()
    scene, scenario = load("intersection")
    scenario = dataclasses.replace(scenario, n_pedestrians=peds)
    seeds = trial_seeds(seed, 0)
    rec = simulate(scene, scenario, seeds, duration=duration)
    sensor = cfg.sensor_at(lam)
    return cfg, scene, sensor, seeds, observe(rec, scene, sensor, seeds.sensor_rngs())


def births_of(name: str, cfg, scene, sensor, seeds, scans, make_filter) -> list:
    """The births of every scan, with the previous step of ``make_filter()`` in the context (ATBM prev_scan)."""
    from soabench import plugins
    from soabench.types import BirthContext

    model = plugins.resolve(plugins.BIRTH, name)(cfg.birth, sensor, scene, seeds.placement_rng())
    filt, prev, out = make_filter(), None, []
    for scan in scans.scans:
        out.append(model(BirthContext(scan, prev, cfg.filter.p_D)))
        prev = filt.step(scan, out[-1])
    return out


def run(make_filter, scans, births, repeat: int) -> tuple[float, float]:
    """(best total step time over ``repeat`` runs after one warm-up, mean components or tracks per scan)."""
    best, kept = np.inf, 0.0
    for r in range(repeat + 1):
        filt = make_filter()
        n = 0
        t0 = time.perf_counter()
        for scan, b in zip(scans.scans, births, strict=True):
            n += filt.step(scan, b).n_reduced
        dt = time.perf_counter() - t0
        if r:
            best = min(best, dt)
        kept = n / len(births)
    return best, kept


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--peds", default="6,50", help="pedestrian counts, comma-separated (6 = the shipped scenario)")
    ap.add_argument("--duration", type=float, default=100.0, help="simulated seconds per trial")
    ap.add_argument("--clutter", type=float, default=3.0, help="clutter rate lambda")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per filter (best kept)")
    args = ap.parse_args()

    from soabench.gmphd.filter import GMPHDFilter
    from soabench.lmb import LMBFilter

    print(f"# bench_lmb {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, python {sys.version.split()[0]}")
    print("peds  M/scan  model    GM-PHD ms  comps   LMB ms  tracks  LMB/GM-PHD")
    for peds in (int(p) for p in args.peds.split(",")):
        cfg, scene, sensor, seeds, scans = scans_of(peds, args.duration, args.clutter, args.seed)
        M = np.mean([len(s.Z) for s in scans.scans])

        gm = functools.partial(GMPHDFilter, cfg.filter, sensor, "static")
        lmb = functools.partial(LMBFilter, cfg.filter, sensor, N_hat=cfg.birth.N_hat)
        lmb = functools.partial(lambda make, s: make(rng=s.association_rng()), lmb, seeds)

        tot_gm = tot_lmb = 0.0
        for name in MODELS:
            t_gm_births = births_of(name, cfg, scene, sensor, seeds, scans, gm)
            t_lmb_births = births_of(name, cfg, scene, sensor, seeds, scans, lmb)
            t_gm, n_gm = run(gm, scans, t_gm_births, args.repeat)
            t_lmb, n_lmb = run(lmb, scans, t_lmb_births, args.repeat)
            tot_gm, tot_lmb = tot_gm + t_gm, tot_lmb + t_lmb
            print(
                f"{peds:4d}  {M:6.1f}  {name:7s} {1e3 * t_gm:9.1f} {n_gm:6.1f} {1e3 * t_lmb:8.1f} {n_lmb:7.1f}"
                f"  {t_lmb / t_gm:9.2f}x"
            )
        print(f"{peds:4d}  {M:6.1f}  all     {1e3 * tot_gm:9.1f}        {1e3 * tot_lmb:8.1f}"
              f"          {tot_lmb / tot_gm:9.2f}x")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
