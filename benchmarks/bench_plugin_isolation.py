"""What guarding plugins costs (soabench/experiment/trial/isolate.py): the built-ins' trial time, and the per-scan cost
a
plugin pays for its own thread and its private copy of the scan.

    python benchmarks/bench_plugin_isolation.py [--baseline DIR] [--repeats 5] [--duration 30]

1. **Built-ins**: one trial of S-OA and UBM in both probability modes (no plugin), the median of ``--repeats``
   runs, each in a fresh process after one warm-up trial. With ``--baseline DIR`` the same trial runs with the
   soabench of another checkout (``PYTHONPATH=DIR``), alternating with this one, and the ratio is printed: the
   built-ins run unguarded, so it should be 1 within the noise.
2. **A plugin's overhead per scan**, on the scans of that trial:
:func:`~soabench.experiment.trial.isolate.private_scan`,
   and a call through :class:`~soabench.experiment.trial.isolate.PluginCalls` against a direct call, next to the time
   one
   GM-PHD filter spends per scan.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

TRIAL = """
import json, sys, time
from soabench.config import Config, ExperimentConfig
from soabench.experiment.trial.trial import run_trial
from soabench.scenario import load
scene, scenario = load("intersection")
exp = ExperimentConfig(trials=1, duration={duration}, models=("soa", "ubm"), probabilities=("static", "dynamic"))
cfg = Config(experiment=exp).validate()
run_trial(1, cfg, scene, scenario)  # warm-up: kernels loaded, scene prepared
t0 = time.perf_counter()
res = run_trial(0, cfg, scene, scenario)
filt = sum(r["t_filter_total"] for r in res.rows) / len(res.rows)
print(json.dumps({{"trial_s": time.perf_counter() - t0, "filter_per_scan_s": filt / (len(res.steps) / len(res.rows))}}))
"""


def trial_time(pythonpath: str | None, duration: float) -> dict:
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    out = subprocess.run(
        [sys.executable, "-c", TRIAL.format(duration=duration)], env=env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def per_scan_costs(duration: float, calls: int = 2000) -> dict:
    from soabench.config import Sensor
    from soabench.experiment.trial.isolate import PluginCalls, private_scan
    from soabench.scenario import load, simulate
    from soabench.seeding import trial_seeds
    from soabench.sensor import observe

    scene, scenario = load("intersection")
    seeds = trial_seeds(0, 0)
    scans = observe(simulate(scene, scenario, seeds, duration=duration), scene, Sensor(), seeds.sensor_rngs())
    t0 = time.perf_counter()
    for _ in range(5):
        for s in scans.scans:
            private_scan(s)
    copy_s = (time.perf_counter() - t0) / (5 * len(scans.scans))

    def step(scan):
        return scan

    t0 = time.perf_counter()
    for i in range(calls):
        step(i)
    direct = (time.perf_counter() - t0) / calls
    with PluginCalls(60.0) as call:
        t0 = time.perf_counter()
        for i in range(calls):
            call(step, i)
        guarded = (time.perf_counter() - t0) / calls
    n_obst = statistics.mean(len(s.obstacles) for s in scans.scans)
    return {"copy_s": copy_s, "call_s": guarded - direct, "scans": len(scans.scans), "obstacles": n_obst}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", help="a checkout of the code before (its folder holds soabench/)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--duration", type=float, default=30.0)
    args = ap.parse_args()
    here, base = [], []
    for _ in range(args.repeats):
        here.append(trial_time(None, args.duration))
        if args.baseline:
            base.append(trial_time(args.baseline, args.duration))
    med = statistics.median(r["trial_s"] for r in here)
    print(f"built-ins (soa, ubm x static, dynamic; {args.duration:g} s trial): median {med:.3f} s of {args.repeats}")
    print("  this code:", ", ".join(f"{r['trial_s']:.3f}" for r in here))
    if base:
        med_b = statistics.median(r["trial_s"] for r in base)
        print("  baseline: ", ", ".join(f"{r['trial_s']:.3f}" for r in base))
        best = min(r["trial_s"] for r in here) / min(r["trial_s"] for r in base)
        print(f"  ratio this / baseline: {med / med_b:.3f} (medians), {best:.3f} (fastest runs)")
    filt = statistics.median(r["filter_per_scan_s"] for r in here)
    c = per_scan_costs(args.duration)
    print(f"a plugin's overhead per scan ({c['scans']} scans, {c['obstacles']:.1f} obstacles on average):")
    print(f"  private copy of the scan: {c['copy_s'] * 1e6:.1f} us")
    print(f"  call on the plugin's thread (minus a direct call): {c['call_s'] * 1e6:.1f} us")
    print(f"  one built-in filter run per scan (birth + filter): {filt * 1e6:.0f} us")


if __name__ == "__main__":
    main()
