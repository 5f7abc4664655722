"""One trial of the shipped intersection as pedestrians and clutter grow: the whole trial against its own SUMO time,
and the filter seconds of the paper protocol's twelve runs (plain script, not a test).

    python benchmarks/bench_trial_scaling.py [--duration 100] [--peds 6,25,50,100,200] [--clutter 0.5,3,10,30]
        [--baseline DIR]

A configuration is one ``run_trial`` of the product (SUMO, sensor, births, the twelve filter runs of the paper
protocol: S-OA, PUBM, UBM (FOV), UBM (workspace), ATBM and GMBM x {static, dynamic}, their metrics and result
rows), in a fresh process after a 5 s warm-up trial, so that the one-off loading of the compiled kernels is not
counted. Reported per configuration: the trial's wall and CPU seconds, its SUMO seconds (the floor: the trial cannot
be faster than its simulation), the ratio trial / SUMO, and the filter seconds (the runs' ``t_filter_total``,
births included) and metric seconds of the twelve runs.

``--baseline DIR`` measures the same configurations with the soabench of another checkout too (``PYTHONPATH=DIR``,
for example ``git worktree add /tmp/base <commit>``): both sides run one after the other per configuration, so that
a load spike of a shared machine hits one configuration, not one side for the whole run, and the script checks that
both produced the same result tables (rows without their time columns, episodes, steps), bit for bit.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

MODES = ("static", "dynamic")
TIME_COLUMNS = ("t_birth", "t_predict", "t_update", "t_reduce", "t_metrics", "t_filter_total")


def child(peds: int, lam: float, duration: float, seed: int) -> dict:
    """One trial in this process (after a warm-up trial); the measurements as a dict."""
    import dataclasses

    import numpy as np

    import soabench.sensor
    from soabench.config import Config
    from soabench.experiment.trial.trial import run_trial
    from soabench.scenario import load, simulate

    cfg = Config()
    scene, scenario = load("intersection")
    exp = dataclasses.replace(cfg.experiment, seed=seed, probabilities=MODES, clutter=(float(lam),))
    warm = dataclasses.replace(cfg, experiment=dataclasses.replace(exp, duration=5.0))
    run_trial(0, warm, scene, scenario)  # loads (or compiles) the kernels
    cfg = dataclasses.replace(cfg, experiment=dataclasses.replace(exp, duration=duration))
    sc = dataclasses.replace(scenario, n_pedestrians=peds)

    sumo_cpu = [0.0]
    n_meas: list[int] = []

    def timed_simulate(*args, **kwargs):
        c0 = time.process_time()
        rec = simulate(*args, **kwargs)
        sumo_cpu[0] += time.process_time() - c0
        return rec

    observe = soabench.sensor.observe

    def counting_observe(*args, **kwargs):  # the default sensor path (its geometry sharing), counted
        scans = observe(*args, **kwargs)
        n_meas.extend(len(s.Z) for s in scans.scans)
        return scans

    soabench.sensor.observe = counting_observe
    c0, t0 = time.process_time(), time.perf_counter()
    res = run_trial(0, cfg, scene, sc, simulate_fn=timed_simulate)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    rows = res.rows
    tables = [[{k: v for k, v in r.items() if k not in TIME_COLUMNS} for r in rows], res.episodes, res.steps]
    return dict(
        peds=peds,
        lam=lam,
        runs=len(rows),
        wall=wall,
        cpu=cpu,
        sumo=res.timing["sumo"],
        sumo_cpu=sumo_cpu[0],
        sensor=res.timing["sensor"],
        filters=sum(r["t_filter_total"] for r in rows),
        births=sum(r["t_birth"] for r in rows),
        metrics=sum(r["t_metrics"] for r in rows),
        M=float(np.mean(n_meas)) if n_meas else 0.0,
        J=max(r["max_components"] for r in rows),
        J_updated=max(r["mean_updated"] for r in rows),
        digest=hashlib.sha256(json.dumps(tables, default=repr).encode()).hexdigest(),
        soabench=str(Path(soabench.sensor.__file__).parent),
    )


def measure(peds: int, lam: float, args: argparse.Namespace, pythonpath: str | None) -> dict:
    """One configuration in a fresh process (``pythonpath``: another checkout's soabench)."""
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, __file__, "--child", f"{peds},{lam},{args.duration},{args.seed}"]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise SystemExit(f"trial at {peds} pedestrians, lambda = {lam} failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=100.0, help="simulated seconds per trial")
    ap.add_argument("--peds", default="6,25,50,100,200", help="pedestrian counts (clutter 3)")
    ap.add_argument("--clutter", default="0.5,3,10,30", help="clutter rates (6 pedestrians)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--baseline", default="", help="checkout of an older soabench to measure side by side")
    ap.add_argument("--out", default="benchmarks/figures/trial_scaling.png")
    ap.add_argument("--replot", action="store_true", help="redraw the figure from the JSON of the last run")
    ap.add_argument("--child", default="", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        peds, lam, duration, seed = args.child.split(",")
        print(json.dumps(child(int(peds), float(lam), float(duration), int(seed))))
        return 0
    data = Path(args.out).with_suffix(".json")
    if args.replot:
        saved = json.loads(data.read_text())
        plot(saved, Path(args.out))
        return 0
    configs = [(int(p), 3.0) for p in args.peds.split(",") if p]
    configs += [(6, float(x)) for x in args.clutter.split(",") if x and (6, float(x)) not in configs]
    sides = [("new", None)] + ([("baseline", str(Path(args.baseline).resolve()))] if args.baseline else [])
    print(f"one {args.duration:g} s trial of the intersection, twelve filter runs (6 birth models x static/dynamic)")
    print("| peds | lam | mean M | max J | side | trial s | SUMO s | trial / SUMO | CPU ratio | filters s | metric s |")
    print("|-----:|----:|-------:|------:|------|--------:|-------:|-------------:|----------:|----------:|---------:|")
    results: dict[str, list[dict]] = {name: [] for name, _ in sides}
    identical = True
    for peds, lam in configs:
        for name, path in sides:
            r = measure(peds, lam, args, path)
            results[name].append(r)
            print(
                f"| {peds:4d} | {lam:4g} | {r['M']:6.1f} | {r['J']:5d} | {name} | {r['wall']:7.1f} | {r['sumo']:6.1f}"
                f" | {r['wall'] / r['sumo']:12.2f} | {r['cpu'] / r['sumo_cpu']:9.2f} | {r['filters']:9.2f}"
                f" | {r['metrics']:8.2f} |",
                flush=True,
            )
        if len(sides) == 2 and results["new"][-1]["digest"] != results["baseline"][-1]["digest"]:
            identical = False
            print(f"DIFFERENT RESULTS at {peds} pedestrians, lambda = {lam}", file=sys.stderr)
    saved = dict(duration=args.duration, seed=args.seed, identical=identical, **results)
    data.parent.mkdir(parents=True, exist_ok=True)
    data.write_text(json.dumps(saved, indent=1))
    plot(saved, Path(args.out))
    if len(sides) == 2:
        print("results of both sides identical" if identical else "RESULTS DIFFER between the sides")
    print(f"\nfigure: {args.out}")
    return 0 if identical else 1


def plot(saved: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    new, base = saved["new"], saved.get("baseline") or []
    fig, axes = plt.subplots(1, 3, figsize=(7.2, 2.9), constrained_layout=True)
    panels = (
        (axes[0], lambda r: r["lam"] == 3.0, "peds", "pedestrians (clutter λ = 3)"),
        (axes[1], lambda r: r["peds"] == 6, "lam", "clutter rate λ per scan (6 pedestrians)"),
    )
    for ax, keep, key, xlabel in panels:
        rows = sorted((r for r in new if keep(r)), key=lambda r: r[key])
        brows = sorted((r for r in base if keep(r)), key=lambda r: r[key])
        x = [r[key] for r in rows]
        ax.loglog(x, [r["wall"] for r in rows], "o-", color="tab:blue", ms=4, label="whole trial")
        ax.loglog(x, [r["filters"] for r in rows], "s-", color="tab:green", ms=4, label="12 filter runs")
        if brows:
            xb = [r[key] for r in brows]
            ax.loglog(xb, [r["wall"] for r in brows], "o--", color="tab:blue", ms=3, mfc="none", alpha=0.7)
            ax.loglog(xb, [r["filters"] for r in brows], "s--", color="tab:green", ms=3, mfc="none", alpha=0.7)
        ax.loglog(x, [r["sumo"] for r in rows], ":", color="0.3", label="SUMO (same trial)")
        ax.set_xlabel(xlabel, fontsize=8)
        ax.grid(True, which="major", alpha=0.3)
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
            axis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
            axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.tick_params(labelsize=7)
    axes[0].set_ylabel(f"seconds per {saved['duration']:g} s trial", fontsize=8)
    handles, labels = axes[0].get_legend_handles_labels()
    if base:
        from matplotlib.lines import Line2D

        handles.append(Line2D([], [], ls="--", color="0.4", marker="o", mfc="none", ms=3))
        labels.append("dashed, open: before")
    axes[0].legend(handles, labels, fontsize=6.5, loc="upper left")
    ax = axes[2]
    for rows, side, color, mfc, ls in ((new, "now", "tab:blue", None, "-"), (base, "before", "0.45", "none", "--")):
        rows = sorted((r for r in rows if r["lam"] == 3.0), key=lambda r: r["peds"])
        if not rows:
            continue
        x = [r["peds"] for r in rows]
        ax.semilogx(
            x, [r["wall"] / r["sumo"] for r in rows], "o" + ls, color=color, ms=4, mfc=mfc, label=f"{side}, wall"
        )
        ax.semilogx(x, [r["cpu"] / r["sumo_cpu"] for r in rows], "x:", color=color, ms=4, label=f"{side}, CPU")
    ax.axhline(2.0, color="tab:red", lw=1, ls="--", label="target 2x")
    ax.set_xlabel("pedestrians (clutter λ = 3)", fontsize=8)
    ax.set_ylabel("whole trial / its SUMO time", fontsize=8)
    ax.set_ylim(bottom=1.0)
    ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.grid(True, which="major", alpha=0.3)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=6.5)
    fig.suptitle(
        f"One {saved['duration']:g} s trial of the intersection: S-OA, PUBM, UBM (FOV), UBM (workspace), ATBM, GMBM"
        " x static/dynamic\n"
        "(shared 2-core machine, one run per point; dashed / grey: the code before, same run)",
        fontsize=7.5,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=150)


if __name__ == "__main__":
    sys.exit(main())
