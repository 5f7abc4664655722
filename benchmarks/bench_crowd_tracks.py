"""The crowd case: one 200-pedestrian trial with the track metrics timed apart (plain script, not a test).

    python benchmarks/bench_crowd_tracks.py [--peds 200] [--duration 100] [--rounds 2] [--baseline DIR]

Each round runs, in a fresh process per side (after a 5 s warm-up trial, so that loading the compiled kernels is
not counted), one ``run_trial`` of the intersection with ``[pedestrians] count = --peds`` (SUMO, sensor, the twelve
filter runs of the paper protocol, their §5 metrics and track metrics, result rows). Printed per side and round:
the trial's wall seconds, its SUMO seconds, their ratio, the twelve runs' filter seconds (``t_filter_total``), the
track metrics' seconds (every :func:`soabench.tracks.evaluate.track_evaluation` call of the trial, timed around the
call: wall and CPU seconds) and their ratio to the filter seconds.

``--baseline DIR`` runs another checkout (``PYTHONPATH=DIR``, e.g. ``git worktree add /tmp/base main``) as the
other side, alternating with this one round by round so that a shared machine's load falls on both alike, and
checks that both wrote the same result tables (rows without their time columns, episodes, steps) bit for bit:
every track number included.
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

TIME_COLUMNS = ("t_birth", "t_predict", "t_update", "t_reduce", "t_metrics", "t_filter_total")


def child(peds: int, duration: float, seed: int) -> dict:
    """One trial in this process (after a warm-up trial); the measurements as a dict."""
    import dataclasses

    import soabench.experiment.trial.trial as trial_module
    from soabench.config import Config
    from soabench.scenario import load, simulate

    cfg = Config()
    scene, scenario = load("intersection")
    exp = dataclasses.replace(cfg.experiment, seed=seed, probabilities=("static", "dynamic"), clutter=(3.0,))
    warm = dataclasses.replace(cfg, experiment=dataclasses.replace(exp, duration=5.0))
    trial_module.run_trial(0, warm, scene, scenario)  # loads (or compiles) the kernels
    cfg = dataclasses.replace(cfg, experiment=dataclasses.replace(exp, duration=duration))
    sc = dataclasses.replace(scenario, n_pedestrians=peds)

    sumo = [0.0]
    tracks = [0.0]

    def timed_simulate(*args, **kwargs):
        t0 = time.perf_counter()
        rec = simulate(*args, **kwargs)
        sumo[0] += time.perf_counter() - t0
        return rec

    tracks_cpu = [0.0]
    track_evaluation = trial_module.track_evaluation

    def timed_tracks(*args, **kwargs):
        t0, c0 = time.perf_counter(), time.process_time()
        out = track_evaluation(*args, **kwargs)
        tracks[0] += time.perf_counter() - t0
        tracks_cpu[0] += time.process_time() - c0
        return out

    trial_module.track_evaluation = timed_tracks
    t0 = time.perf_counter()
    res = trial_module.run_trial(0, cfg, scene, sc, simulate_fn=timed_simulate)
    wall = time.perf_counter() - t0
    rows = res.rows
    tables = [[{k: v for k, v in r.items() if k not in TIME_COLUMNS} for r in rows], res.episodes, res.steps]
    return dict(
        wall=wall,
        sumo=sumo[0],
        filters=sum(r["t_filter_total"] for r in rows),
        tracks=tracks[0],
        tracks_cpu=tracks_cpu[0],
        runs=len(rows),
        digest=hashlib.sha256(json.dumps(tables, default=repr).encode()).hexdigest(),
    )


def measure(args: argparse.Namespace, pythonpath: str | None) -> dict:
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, __file__, "--child", f"{args.peds},{args.duration},{args.seed}"]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise SystemExit(f"the trial failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--peds", type=int, default=200)
    ap.add_argument("--duration", type=float, default=100.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--baseline", default="", help="checkout of another soabench, measured alternately")
    ap.add_argument("--child", default="", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        peds, duration, seed = args.child.split(",")
        print(json.dumps(child(int(peds), float(duration), int(seed))))
        return 0
    sides = [("this", None)] + ([("baseline", str(Path(args.baseline).resolve()))] if args.baseline else [])
    print(f"one {args.duration:g} s intersection trial, {args.peds} pedestrians, twelve filter runs; "
          f"load average {os.getloadavg()[0]:.1f}")  # fmt: skip
    print("| round | side | trial s | SUMO s | trial / SUMO | filters s | track metrics s (CPU s) | tracks / filters |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|")
    digests: dict[str, set[str]] = {name: set() for name, _ in sides}
    for r in range(args.rounds):
        for name, path in sides if r % 2 == 0 else sides[::-1]:
            m = measure(args, path)
            digests[name].add(m["digest"])
            cells = (f"{m['wall']:.1f}", f"{m['sumo']:.1f}", f"{m['wall'] / m['sumo']:.2f}x", f"{m['filters']:.2f}",
                     f"{m['tracks']:.2f} ({m['tracks_cpu']:.2f})", f"{m['tracks'] / m['filters']:.2f}x")  # fmt: skip
            print(f"| {r + 1} | {name} | " + " | ".join(cells) + " |", flush=True)
    print(f"load average at end: {os.getloadavg()[0]:.1f}")
    if len(sides) == 2:
        same = digests["this"] == digests["baseline"] and len(digests["this"]) == 1
        print("result tables of both sides identical" if same else "RESULT TABLES DIFFER between the sides")
        return 0 if same else 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
