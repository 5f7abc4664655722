"""Filter time of one trial as pedestrians and clutter grow: fused cycle and 2-d-tree merge against the array path
with the x-window merge (plain script, not a test).

    python benchmarks/bench_trial_scaling.py [--duration 30] [--peds 6,25,50,100,200] [--clutter 0.5,3,10,30]

One SUMO recording of the shipped intersection per pedestrian count (seeded), one sensor pass per clutter rate; then
the ten filters of the paper protocol (five birth models x {static, dynamic}) run over the same scans twice, with
the same births: ``GMPHDFilter`` as shipped (fused, tree) and ``GMPHDFilter(..., fused=False)`` with
``kernels.merge_groups`` swapped for the x-window (the implementation before issue 19). Both sides run one after the
other in this process, so a load spike of a shared machine hits one configuration, not one side for the whole run;
the script reports the ratio per configuration, and the SUMO and sensor seconds of the trial for scale. The
posterior sizes are checked equal (same counts at every scan) so that both sides do the same work.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

from soabench.birth import get_birth_model
from soabench.birth.base import BirthContext
from soabench.config import Config, filter_config_for_mode
from soabench.gmphd import GMPHDFilter, kernels
from soabench.scenario import load, simulate
from soabench.seeding import trial_seeds
from soabench.sensor import observe

MODELS = ("soa", "pubm", "ubm", "atbm", "gmbm")
MODES = ("static", "dynamic")


def run_filters(cfg: Config, scene, sensor, scans, seeds, fused: bool) -> tuple[float, list[int]]:
    """The ten filters over ``scans``: (filter seconds, birth time excluded; reduced component counts)."""
    total = 0.0
    counts: list[int] = []
    for model in MODELS:
        for mode in MODES:
            filter_cfg, filter_mode, p_D_b = filter_config_for_mode(cfg.filter, mode)
            birth = get_birth_model(model)(cfg.birth, sensor, scene, seeds.placement_rng())
            filt = GMPHDFilter(filter_cfg, sensor, filter_mode, fused=fused)
            prev = None
            for scan in scans.scans:
                births = birth(BirthContext(scan, prev, p_D_b))
                t0 = time.perf_counter()
                prev = filt.step(scan, births)
                total += time.perf_counter() - t0
                counts.append(prev.n_reduced)
    return total, counts


def measure(
    cfg: Config, scene, scenario, n_ped: int, lams: list[float], duration: float, seed: int, quiet: bool = False
) -> list[dict]:
    seeds = trial_seeds(seed, 0)
    sc = dataclasses.replace(scenario, n_pedestrians=n_ped)
    t0 = time.perf_counter()
    rec = simulate(scene, sc, seeds, duration=duration)
    t_sumo = time.perf_counter() - t0
    rows = []
    for lam in lams:
        sensor = dataclasses.replace(cfg.sensor, lambda_c=float(lam))
        t0 = time.perf_counter()
        scans = observe(rec, scene, sensor, seeds.sensor_rngs())
        t_sensor = time.perf_counter() - t0
        t_new, c_new = run_filters(cfg, scene, sensor, scans, seeds, fused=True)
        merge = kernels.merge_groups
        kernels.merge_groups = kernels.merge_groups_window  # the array path looks the kernel up at each call
        try:
            t_old, c_old = run_filters(cfg, scene, sensor, scans, seeds, fused=False)
        finally:
            kernels.merge_groups = merge
        if c_new != c_old:  # both paths are exact; a last-bit difference can still flip a threshold somewhere
            print(f"note: posterior sizes differ somewhere at {n_ped} pedestrians, lambda = {lam}", file=sys.stderr)
        n_meas = float(np.mean([len(s.Z) for s in scans.scans]))
        rows.append(
            dict(peds=n_ped, lam=lam, sumo=t_sumo, sensor=t_sensor, new=t_new, old=t_old, J=max(c_new), M=n_meas)
        )
        r = rows[-1]
        if quiet:
            continue
        print(
            f"| {n_ped:4d} | {lam:5.1f} | {r['M']:6.1f} | {r['J']:5d} | {t_sumo:6.1f} | {t_sensor:6.2f} |"
            f" {t_old:8.2f} | {t_new:7.2f} | {t_old / t_new:5.1f} |",
            flush=True,
        )
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=30.0, help="simulated seconds per trial")
    ap.add_argument("--peds", default="6,25,50,100,200", help="pedestrian counts (clutter 3)")
    ap.add_argument("--clutter", default="0.5,3,10,30", help="clutter rates (6 pedestrians)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="benchmarks/figures/trial_scaling.png")
    ap.add_argument("--replot", action="store_true", help="redraw the figure from the JSON of the last run")
    args = ap.parse_args()
    data = Path(args.out).with_suffix(".json")
    if args.replot:
        saved = json.loads(data.read_text())
        plot(saved["by_ped"], saved["by_lam"], saved["duration"], Path(args.out))
        return 0
    cfg = Config()
    scene, scenario = load("intersection")
    peds = [int(x) for x in args.peds.split(",") if x]
    lams = [float(x) for x in args.clutter.split(",") if x]
    measure(cfg, scene, scenario, 6, [3.0], 5.0, args.seed, quiet=True)  # warm-up: load (or compile) the kernels
    print(f"one {args.duration:g} s trial of the intersection, ten filters (5 birth models x static/dynamic)")
    print("| peds |   lam | mean M | max J | SUMO s | sensor s | array+window s | fused+tree s | ratio |")
    print("|------|-------|--------|-------|--------|----------|----------------|--------------|-------|")
    by_ped = [r for n in peds for r in measure(cfg, scene, scenario, n, [3.0], args.duration, args.seed)]
    by_lam = measure(cfg, scene, scenario, 6, lams, args.duration, args.seed) if lams else []
    data.parent.mkdir(parents=True, exist_ok=True)
    data.write_text(json.dumps(dict(duration=args.duration, by_ped=by_ped, by_lam=by_lam), indent=1))
    plot(by_ped, by_lam, args.duration, Path(args.out))
    print(f"\nfigure: {args.out}")
    return 0


def plot(by_ped: list[dict], by_lam: list[dict], duration: float, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, axes = plt.subplots(1, 2, figsize=(7.2, 3.2), constrained_layout=True)
    for ax, rows, key, xlabel in (
        (axes[0], by_ped, "peds", "pedestrians (clutter λ = 3)"),
        (axes[1], by_lam, "lam", "clutter rate λ per scan (6 pedestrians)"),
    ):
        if not rows:
            ax.set_visible(False)
            continue
        x = [r[key] for r in rows]
        ax.loglog(x, [r["old"] for r in rows], "s-", color="tab:red", ms=4, label="array path, x-window merge")
        ax.loglog(x, [r["new"] for r in rows], "o-", color="tab:blue", ms=4, label="fused cycle, 2-d tree merge")
        ax.loglog(x, [r["sumo"] for r in rows], ":", color="0.4", label="SUMO (same trial)")
        ax.set_xlabel(xlabel)
        ax.grid(True, which="both", alpha=0.25)
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
            axis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
            axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    axes[0].set_ylabel(f"seconds per {duration:g} s trial, 10 filters")
    axes[0].legend(fontsize=7, loc="upper left")
    fig.suptitle(
        "Filter time of one trial, S-OA, PUBM, UBM, ATBM, GMBM x static/dynamic (shared 2-core machine, one run)",
        fontsize=8,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=150)


if __name__ == "__main__":
    sys.exit(main())
