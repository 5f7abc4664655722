"""The crowd case: one 200-pedestrian trial with the track metrics timed apart (plain script, not a test).

    python benchmarks/bench_crowd_tracks.py [--peds 200] [--duration 100] [--rounds 2] [--baseline DIR]
    python benchmarks/bench_crowd_tracks.py --scans FILE.npz [--rounds 2] [--baseline DIR]

Each round runs, in a fresh process per side (after a 5 s warm-up trial, so that loading the compiled kernels is
not counted), one ``run_trial`` of the intersection with ``[pedestrians] count = --peds`` (SUMO, sensor, the twelve
filter runs of the paper protocol, their §5 metrics and track metrics, result rows). Printed per side and round:
the trial's wall seconds, its SUMO seconds, their ratio, the twelve runs' filter seconds (``t_filter_total``), the
track metrics' seconds (every :func:`soabench.tracks.evaluate.track_evaluation` call of the trial, timed around the
call: wall and CPU seconds) and their ratio to the filter seconds.

``--scans FILE.npz`` leaves SUMO and the sensor out: the scans of one such trial (lambda = 3, seed 0) are recorded
into FILE once (if it does not exist) and every child runs the trial's twelve filter runs, their §5 metrics and
track metrics on them (``run_trial`` with the recorded scans as its observation). Printed: the CPU seconds of the
filter runs (births included: the trial's CPU less its metrics and track metrics) and of the track metrics, their
ratio, and the wall seconds of both (``t_filter_total``; the track metrics' calls).

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


def child(peds: int, duration: float, seed: int, scans_path: str = "") -> dict:
    """One trial in this process (after a warm-up trial); the measurements as a dict."""
    import dataclasses

    import soabench.experiment.trial.trial as trial_module
    from soabench.config import Config
    from soabench.scenario import load, simulate
    from soabench.types import Scans

    cfg = Config()
    scene, scenario = load("intersection")
    exp = dataclasses.replace(cfg.experiment, seed=seed, probabilities=("static", "dynamic"), clutter=(3.0,))
    warm = dataclasses.replace(cfg, experiment=dataclasses.replace(exp, duration=5.0))
    trial_module.run_trial(0, warm, scene, scenario)  # loads (or compiles) the kernels
    cfg = dataclasses.replace(cfg, experiment=dataclasses.replace(exp, duration=duration))
    sc = dataclasses.replace(scenario, n_pedestrians=peds)
    recorded = Scans.load_npz(scans_path) if scans_path else None

    sumo = [0.0]
    tracks = [0.0]
    tracks_cpu = [0.0]
    metrics_cpu = [0.0]

    def timed_simulate(*args, **kwargs):
        t0 = time.perf_counter()
        rec = None if recorded is not None else simulate(*args, **kwargs)
        sumo[0] += time.perf_counter() - t0
        return rec

    track_evaluation, evaluate = trial_module.track_evaluation, trial_module.evaluate

    def timed_tracks(*args, **kwargs):
        t0, c0 = time.perf_counter(), time.process_time()
        out = track_evaluation(*args, **kwargs)
        tracks[0] += time.perf_counter() - t0
        tracks_cpu[0] += time.process_time() - c0
        return out

    def timed_metrics(*args, **kwargs):
        c0 = time.process_time()
        out = evaluate(*args, **kwargs)
        metrics_cpu[0] += time.process_time() - c0
        return out

    trial_module.track_evaluation, trial_module.evaluate = timed_tracks, timed_metrics
    observe = {} if recorded is None else {"observe_fn": lambda *args, **kwargs: recorded}
    t0, c0 = time.perf_counter(), time.process_time()
    res = trial_module.run_trial(0, cfg, scene, sc, simulate_fn=timed_simulate, **observe)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    rows = res.rows
    tables = [[{k: v for k, v in r.items() if k not in TIME_COLUMNS} for r in rows], res.episodes, res.steps]
    return dict(
        wall=wall,
        sumo=sumo[0],
        filters=sum(r["t_filter_total"] for r in rows),
        filters_cpu=cpu - tracks_cpu[0] - metrics_cpu[0],
        tracks=tracks[0],
        tracks_cpu=tracks_cpu[0],
        runs=len(rows),
        digest=hashlib.sha256(json.dumps(tables, default=repr).encode()).hexdigest(),
    )


def record(path: Path, peds: int, duration: float, seed: int) -> None:
    """The scans of the crowd trial (lambda = 3) into ``path``."""
    import dataclasses

    from soabench.config import Config
    from soabench.scenario import load, simulate
    from soabench.seeding import trial_seeds
    from soabench.sensor import observe

    scene, scenario = load("intersection")
    seeds = trial_seeds(seed, 0)
    rec = simulate(scene, dataclasses.replace(scenario, n_pedestrians=peds), seeds, duration=duration)
    observe(rec, scene, Config().sensor_at(3.0), seeds.sensor_rngs()).save_npz(path)


def measure(args: argparse.Namespace, pythonpath: str | None) -> dict:
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath + os.pathsep + env.get("PYTHONPATH", "")
    scans = str(Path(args.scans).resolve()) if args.scans else ""
    cmd = [sys.executable, __file__, "--child", f"{args.peds},{args.duration},{args.seed},{scans}"]
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
    ap.add_argument("--scans", default="", help="recorded scans (.npz; recorded if missing): SUMO left out")
    ap.add_argument("--baseline", default="", help="checkout of another soabench, measured alternately")
    ap.add_argument("--child", default="", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        peds, duration, seed, scans = args.child.split(",", 3)
        print(json.dumps(child(int(peds), float(duration), int(seed), scans)))
        return 0
    if args.scans and not Path(args.scans).exists():
        record(Path(args.scans), args.peds, args.duration, args.seed)
    sides = [("this", None)] + ([("baseline", str(Path(args.baseline).resolve()))] if args.baseline else [])
    print(f"one {args.duration:g} s intersection trial, {args.peds} pedestrians, twelve filter runs"
          f"{' on recorded scans' if args.scans else ''}; load average {os.getloadavg()[0]:.1f}")  # fmt: skip
    if args.scans:
        print("| round | side | filters CPU s | track metrics CPU s | tracks / filters (CPU) | filters wall s | "
              "track metrics wall s | tracks / filters (wall) |")  # fmt: skip
    else:
        print("| round | side | trial s | SUMO s | trial / SUMO | filters s | track metrics s (CPU s) | "
              "tracks / filters |")  # fmt: skip
    print("|---:|---|---:|---:|---:|---:|---:|---:|")
    digests: dict[str, set[str]] = {name: set() for name, _ in sides}
    for r in range(args.rounds):
        for name, path in sides if r % 2 == 0 else sides[::-1]:
            m = measure(args, path)
            digests[name].add(m["digest"])
            if args.scans:
                cpu = m["tracks_cpu"] / m["filters_cpu"]
                cells = (f"{m['filters_cpu']:.2f}", f"{m['tracks_cpu']:.2f}", f"{cpu:.2f}x", f"{m['filters']:.2f}",
                         f"{m['tracks']:.2f}", f"{m['tracks'] / m['filters']:.2f}x")  # fmt: skip
            else:
                cells = (f"{m['wall']:.1f}", f"{m['sumo']:.1f}", f"{m['wall'] / m['sumo']:.2f}x",
                         f"{m['filters']:.2f}", f"{m['tracks']:.2f} ({m['tracks_cpu']:.2f})",
                         f"{m['tracks'] / m['filters']:.2f}x")  # fmt: skip
            print(f"| {r + 1} | {name} | " + " | ".join(cells) + " |", flush=True)
    print(f"load average at end: {os.getloadavg()[0]:.1f}")
    if len(sides) == 2:
        same = digests["this"] == digests["baseline"] and len(digests["this"]) == 1
        print("result tables of both sides identical" if same else "RESULT TABLES DIFFER between the sides")
        return 0 if same else 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
