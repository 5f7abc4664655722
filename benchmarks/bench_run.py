"""Wall time of a Monte Carlo run, broken down by stage (SUMO, sensor, each filter model x mode, metrics).

Runs :func:`soabench.experiment.reports.finished.run_experiment` (default: the paper's full protocol, 100 trials x 100
s,
five birth models x {static, dynamic}, lambda = 3, every core) and prints, from the run's ``timing.csv`` and
session records: the wall time, the CPU seconds summed over trials per stage and their share, and the per-trial
mean. Example (a small real run, then the fake trial function of the tests)::

    python benchmarks/bench_run.py --trials 4 --duration 30 --workers 2
    python benchmarks/bench_run.py --trials 20 --duration 100 --fake
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from soabench.config import BIRTH_MODEL_NAMES, PROBABILITY_MODES, Config
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.reports.finished import run_experiment
from soabench.experiment.runs.files import read_csv
from soabench.experiment.runs.store import RunStore

STAGES = ("birth", "predict", "update", "reduce", "metrics")
#: the stages timed inside the filter loop, whose wall time is ``t_filter_total`` (metrics are timed after it)
LOOP_STAGES = ("birth", "predict", "update", "reduce")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--net", default="intersection")
    p.add_argument("--trials", type=int, default=100)
    p.add_argument("--duration", type=float, default=100.0)
    p.add_argument("--models", default=",".join(BIRTH_MODEL_NAMES))
    p.add_argument("--probabilities", default="static,dynamic")
    p.add_argument("--clutter", default="3")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=None, help="default: every core")
    p.add_argument("--dask", action="store_true", help="use a Dask LocalCluster instead of a process pool")
    p.add_argument("--out", type=Path, default=None, help="run folder (default: a new temporary folder)")
    p.add_argument("--fake", action="store_true", help="the tests' fake trial function (no SUMO, no filter)")
    return p.parse_args(argv)


def breakdown(run_dir: Path) -> str:
    """The timing table of a finished run."""
    tm = read_csv(run_dir / "timing.csv")
    sessions = RunStore(run_dir).sessions()
    wall = sum(s.get("wall_s", 0.0) for s in sessions)
    trials = np.unique(tm["trial"]).size
    first = np.unique(tm["trial"], return_index=True)[1]
    rows: list[tuple[str, float]] = [
        ("SUMO (libsumo run)", float(np.nansum(tm["t_sumo"][first]))),
        ("sensor (all lambda)", float(np.nansum(tm["t_sensor"][first]))),
    ]
    keys = list(dict.fromkeys(zip(tm["model"], tm["mode"], strict=True)))
    for model, mode in keys:
        m = (tm["model"] == model) & (tm["mode"] == mode)
        for stage in STAGES:
            rows.append((f"{model}/{mode} {stage}", float(np.nansum(tm[f"t_{stage}"][m]))))
        total = float(np.nansum(tm["t_filter_total"][m]))
        other = total - sum(float(np.nansum(tm[f"t_{s}"][m])) for s in LOOP_STAGES)
        rows.append((f"{model}/{mode} other (extraction, bookkeeping)", other))
    cpu = sum(v for _, v in rows)
    workers = max((s.get("n_workers", 1) for s in sessions), default=1)
    lines = [
        f"run {run_dir}: {trials} trials, wall {wall:.2f} s on {workers} worker(s), "
        f"stage CPU sum {cpu:.2f} s (parallel efficiency {cpu / max(wall * workers, 1e-9):.0%})",
        "",
        f"{'stage':48s} {'sum (s)':>10s} {'share':>7s} {'per trial (ms)':>15s}",
    ]
    for name, v in rows:
        lines.append(f"{name:48s} {v:10.3f} {v / max(cpu, 1e-12):7.1%} {1000 * v / max(trials, 1):15.2f}")
    return "\n".join(lines)


def main(argv=None) -> int:
    args = parse_args(argv)
    cfg = Config()
    cfg.experiment = dataclasses.replace(
        cfg.experiment,
        trials=args.trials,
        duration=args.duration,
        models=tuple(s for s in args.models.split(",") if s),
        probabilities=tuple(s for s in args.probabilities.split(",") if s and s in PROBABILITY_MODES),
        clutter=tuple(float(s) for s in args.clutter.split(",") if s),
        seed=args.seed,
    )
    cfg.validate()
    out = args.out or Path(tempfile.mkdtemp(prefix="soabench-bench-")) / "run"
    kwargs = {}
    if args.fake:
        sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
        import fake_trial

        kwargs = {"trial_fn": fake_trial.fake_trial, "load_fn": fake_trial.fake_load}
    t0 = time.perf_counter()
    outcome = run_experiment(
        cfg, args.net, out=out, options=RunOptions(workers=args.workers, dask_local=args.dask, figures=False), **kwargs
    )
    t_run = time.perf_counter() - t0
    if not outcome.complete:
        print(f"run incomplete: {outcome.n_missing} trials missing, failures: {outcome.failures}", file=sys.stderr)
        return 1
    print(breakdown(outcome.run_dir))
    print(f"\nrun_experiment returned after {t_run:.2f} s (includes scene load, merge and summary)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
