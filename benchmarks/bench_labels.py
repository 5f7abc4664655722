"""The cost of carrying track labels (docs/method.md §2.13) in the GM-PHD filter: fused step and protocol.

    python benchmarks/bench_labels.py --baseline DIR [--duration 300] [--rounds 3] [--trials 4]

``DIR`` is a checkout of the code before labels (e.g. ``git worktree add /tmp/base <commit>``); this checkout is
the one installed. Both are measured in this one run, interleaved (baseline, labelled, baseline, labelled, ...) so
that a slower or faster moment of a shared machine hits both alike, and each child process imports its own tree
(``PYTHONPATH``, run from a temporary folder). Before timing, each tree compiles (or loads) its kernels in an
untimed child.

* **Fused step.** One trial of the intersection (SUMO, lambda = 3, ``--duration`` s) is recorded once and saved;
  a child loads the scans and runs every birth model x {static, dynamic} over them, timing ``GMPHDFilter.step``
  alone (the births are computed outside the timed calls, once, and replayed in ``--reps`` passes) and keeping,
  scan by scan, the fastest of the passes. Reported: the summed step time of each tree and their ratio (labelled /
  baseline), per mode and over all configurations, taking for each tree the best of its ``--rounds`` children.
* **Protocol.** ``soabench run --trials T --duration D --workers 1`` with each tree, ``--rounds`` times each,
  interleaved: the ratio of the smallest CPU times (user + system of the command and its workers; on a shared
  machine less noisy than the wall time, which is printed too), and whether ``trials.csv`` of the two trees is
  identical byte for byte (the labels must not move a number: T30).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: the child of the fused-step measurement: argv = [scans .npz, reps]; prints {"model/mode": seconds}, each the sum
#: over scans of the fastest of ``reps`` timed calls of that scan's step (the same prior and births every pass: a
#: pass replays the first pass's births into a fresh filter), so that a pause of a shared machine in one pass does
#: not count
_STEP_CHILD = r"""
import json, sys, time
import numpy as np
from soabench.birth import get_birth_model
try:
    from soabench.plugins import BUILTIN_BIRTH_MODELS as MODELS
except ImportError:  # a baseline checkout from before the built-in birth models moved to soabench.plugins
    from soabench.birth import REGISTRY as MODELS
from soabench.types import BirthContext
from soabench.config import Config, filter_config_for_mode
from soabench.gmphd import GMPHDFilter
from soabench.scenario import load
from soabench.seeding import trial_seeds
from soabench.types import Scans

scans = Scans.load_npz(sys.argv[1])
reps = int(sys.argv[2])
cfg = Config()
scene, _ = load("intersection")
seeds = trial_seeds(0, 1)
out = {}
for model in MODELS:
    for mode in ("static", "dynamic"):
        fcfg, fmode, p_D_b = filter_config_for_mode(cfg.filter, mode)
        birth = get_birth_model(model)(cfg.birth, scans.sensor, scene, seeds.placement_rng())
        filt = GMPHDFilter(fcfg, scans.sensor, fmode)
        prev, births, best = None, [], []
        for scan in scans.scans:
            births.append(birth(BirthContext(scan, prev, p_D_b)))
            t = time.perf_counter()
            prev = filt.step(scan, births[-1])
            best.append(time.perf_counter() - t)
        for _ in range(reps - 1):
            filt = GMPHDFilter(fcfg, scans.sensor, fmode)
            for k, scan in enumerate(scans.scans):
                t = time.perf_counter()
                filt.step(scan, births[k])
                best[k] = min(best[k], time.perf_counter() - t)
        out[f"{model}/{mode}"] = float(np.sum(best))
print(json.dumps(out))
"""
_CLI = "import runpy; runpy.run_module('soabench', run_name='__main__')"  #: ``python -m soabench`` of either tree


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--baseline", type=Path, required=True, help="checkout of the code before labels")
    p.add_argument("--duration", type=float, default=300.0, help="seconds of the recorded trial (fused step)")
    p.add_argument("--reps", type=int, default=10, help="passes per configuration in one child (fastest per scan)")
    p.add_argument("--rounds", type=int, default=3, help="interleaved children per tree")
    p.add_argument("--trials", type=int, default=4, help="trials of the protocol run")
    p.add_argument("--run-duration", type=float, default=100.0, help="seconds per trial of the protocol run")
    p.add_argument("--no-protocol", action="store_true", help="the fused step only")
    return p.parse_args(argv)


def _env(tree: Path | None) -> dict:
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = str(tree.resolve())
    return env


def _child(code: str, args: list[str], tree: Path | None, cwd: str) -> tuple[str, float, float]:
    """Run ``code`` with ``tree`` first on the path: (its stdout, wall seconds, CPU seconds of it and its children)."""
    cpu0 = sum(resource.getrusage(resource.RUSAGE_CHILDREN)[:2])
    t = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", code, *args], env=_env(tree), cwd=cwd, check=True,
                          capture_output=True, text=True)  # fmt: skip
    wall = time.perf_counter() - t
    return done.stdout, wall, sum(resource.getrusage(resource.RUSAGE_CHILDREN)[:2]) - cpu0


def _record(path: Path, duration: float, cwd: str) -> None:
    code = (
        "import sys, dataclasses\n"
        "from soabench.config import Config\n"
        "from soabench.scenario import load, simulate\n"
        "from soabench.seeding import trial_seeds\n"
        "from soabench.sensor import observe\n"
        "scene, scenario = load('intersection')\n"
        "cfg = Config()\n"
        "seeds = trial_seeds(0, 1)\n"
        "rec = simulate(scene, scenario, seeds, duration=float(sys.argv[2]))\n"
        "observe(rec, scene, cfg.sensor_at(), seeds.sensor_rngs()).save_npz(sys.argv[1])\n"
    )
    _child(code, [str(path), str(duration)], None, cwd)


def _ratio(a: float, b: float) -> str:
    return f"{a / b:.3f}" if b > 0 else "n/a"


def main(argv=None) -> int:
    args = parse_args(argv)
    trees = {"baseline": args.baseline, "labelled": None}
    with tempfile.TemporaryDirectory(prefix="soabench-labels-") as tmp:
        scans = Path(tmp) / "trial.scans.npz"
        _record(scans, args.duration, tmp)
        for tree in trees.values():  # compile or load each tree's kernels (untimed)
            _child(_STEP_CHILD, [str(scans), "1"], tree, tmp)
        best: dict[str, dict[str, float]] = {name: {} for name in trees}
        for _ in range(args.rounds):
            for name, tree in trees.items():
                times = json.loads(_child(_STEP_CHILD, [str(scans), str(args.reps)], tree, tmp)[0])
                for key, t in times.items():
                    best[name][key] = min(best[name].get(key, float("inf")), t)
        base, lab = best["baseline"], best["labelled"]
        with np.load(scans) as z:
            n_scans = len(z["k"])
        print(f"fused step, one {args.duration:g} s trial ({n_scans} scans), best of {args.rounds} x {args.reps}")
        print(f"{'model/mode':16s} {'baseline (ms)':>14s} {'labelled (ms)':>14s} {'ratio':>7s}")
        for key in base:
            print(f"{key:16s} {1e3 * base[key]:14.2f} {1e3 * lab[key]:14.2f} {_ratio(lab[key], base[key]):>7s}")
        for mode in ("static", "dynamic"):
            b = sum(v for k, v in base.items() if k.endswith("/" + mode))
            a = sum(v for k, v in lab.items() if k.endswith("/" + mode))
            print(f"{'all/' + mode:16s} {1e3 * b:14.2f} {1e3 * a:14.2f} {_ratio(a, b):>7s}")
        b, a = sum(base.values()), sum(lab.values())
        print(f"{'all':16s} {1e3 * b:14.2f} {1e3 * a:14.2f} {_ratio(a, b):>7s}")
        if args.no_protocol:
            return 0
        run = ["run", "--net", "intersection", "--trials", str(args.trials), "--duration", str(args.run_duration)]
        run += ["--workers", "1", "--no-progress"]
        walls: dict[str, list[float]] = {name: [] for name in trees}
        cpus: dict[str, list[float]] = {name: [] for name in trees}
        for name, tree in trees.items():  # warm: kernels of the whole run (untimed)
            _child(_CLI, [*run[:3], "--trials", "1", "--duration", "5", "--workers", "1", "--no-progress", "--out",
                          f"{tmp}/warm_{name}"], tree, tmp)  # fmt: skip
        for r in range(args.rounds):
            for name, tree in trees.items():
                _, wall, cpu = _child(_CLI, [*run, "--out", f"{tmp}/{name}_{r}"], tree, tmp)
                walls[name].append(wall)
                cpus[name].append(cpu)
        same = all(
            (Path(tmp) / f"baseline_{r}" / "trials.csv").read_bytes()
            == (Path(tmp) / f"labelled_{r}" / "trials.csv").read_bytes()
            for r in range(args.rounds)
        )
        wb, wl = min(walls["baseline"]), min(walls["labelled"])
        cb, cl = min(cpus["baseline"]), min(cpus["labelled"])
        print(f"protocol: soabench run --trials {args.trials} --duration {args.run_duration:g} --workers 1, best of "
              f"{args.rounds}: CPU baseline {cb:.1f} s, labelled {cl:.1f} s, ratio {_ratio(cl, cb)}; wall baseline "
              f"{wb:.1f} s, labelled {wl:.1f} s, ratio {_ratio(wl, wb)}")  # fmt: skip
        print(f"trials.csv identical byte for byte: {same}")
        return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
