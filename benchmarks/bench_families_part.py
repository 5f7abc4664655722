"""CPU time of the families part of ``soabench results`` against the GM-PHD main protocol's.

The families part is two run folders at the main protocol's sizes: ``filters/`` (every birth model in the GM-PHD,
LMB, PMBM and PMB, static and static+occ) and ``filters-lmb-components/`` (the LMB with one Bernoulli per birth
component, static). In one process, one after another, on the same protocol (intersection, λ = 3):

1. the main protocol alone (six birth models x {static, dynamic}, GM-PHD): the ratios' denominator;
2. the two families folders each on its own (as ``soabench run`` makes them);
3. the intersection study alone (main run, clutter sweep, N̂ sweep, sensitivity runs);
4. the study with the two families folders in its trials (how ``soabench results`` runs them): the families part
   costs what 4 adds to 3.

Each figure is the CPU seconds of the call: this process and its finished worker processes. The families part in
the study's trials is a difference of two large figures, so it scatters with the machine's speed from one minute to
the next; the script therefore also prints what the families folders' own records say (``timing.csv``: SUMO, the
sensor and the births, summed over trials, seconds inside the workers), which does not depend on the neighbours.
It checks that the families folders of 2 and 4 hold the same trials.csv, episodes.csv and steps.csv. Example::

    nice -n 10 python benchmarks/bench_families_part.py --trials 20 --duration 100 --workers 2
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import resource
import tempfile
import time
from pathlib import Path

from soabench.config import Config
from soabench.experiment.campaigns.results_suite import FILTERS_KEYS, Settings, ablation_config, filters_config
from soabench.experiment.campaigns.study import Companion, run_study
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.reports.finished import run_experiment

TABLES = ("trials.csv", "episodes.csv", "steps.csv")
#: the stages a folder no longer computes when its trials are the study's (seconds in timing.csv)
SHARED_STAGES = ("t_sumo", "t_sensor", "t_birth")


def shared_seconds(folder: Path) -> dict[str, float]:
    """The folder's seconds of SUMO and the sensor (once per trial in timing.csv: the first row of each trial) and
    of the births (every row), summed over its trials."""
    with (folder / "timing.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    first = {r["trial"]: r for r in reversed(rows)}
    out = {k: sum(float(r[k]) for r in first.values()) for k in ("t_sumo", "t_sensor")}
    out["t_birth"] = sum(float(r["t_birth"]) for r in rows)
    return out


def cpu() -> float:
    """CPU seconds of this process and of its finished children."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def timed(label: str, work) -> float:
    c0, t0 = cpu(), time.perf_counter()
    work()
    c, t = cpu() - c0, time.perf_counter() - t0
    print(f"{label:<44} {c:8.1f} CPU s {t:8.1f} wall s", flush=True)
    return c


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--duration", type=float, default=100.0)
    ap.add_argument("--births-trials", type=int, default=1, help="trials per N̂ point of the study")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    s = Settings(trials=a.trials, duration=a.duration)
    main_cfg = Config()
    main_cfg.experiment = dataclasses.replace(main_cfg.experiment, trials=a.trials, duration=a.duration)
    main_cfg.validate()
    options = RunOptions(workers=a.workers, progress=False)
    study = dict(births_trials=a.births_trials, options=options)
    with tempfile.TemporaryDirectory(prefix="bench_families_part_") as tmp:
        root = Path(tmp)
        alone = {"filters": filters_config(s), "ablation": ablation_config(s)}
        t_main = timed("main protocol", lambda: run_experiment(main_cfg, "intersection", out=root / "main",
                                                                options=options))  # fmt: skip
        t_alone = sum(
            timed(
                f"{name} alone",
                lambda name=name, c=c: run_experiment(c, "intersection", out=root / "alone" / name, options=options),
            )  # fmt: skip
            for name, c in alone.items()
        )
        t_study = timed("study alone", lambda: run_study(main_cfg, "intersection", out=root / "study", **study))
        companions = tuple(Companion(root / "grouped" / name, c, FILTERS_KEYS) for name, c in alone.items())
        t_group = timed(
            "study with the families folders in its trials",
            lambda: run_study(main_cfg, "intersection", out=root / "study2", companions=companions, **study),
        )
        for name in alone:
            for t in TABLES:
                same = (root / "alone" / name / t).read_bytes() == (root / "grouped" / name / t).read_bytes()
                assert same, f"{name}/{t} differs between the folder alone and in the study's trials"
            for way in ("alone", "grouped"):
                secs = shared_seconds(root / way / name)
                print(f"{name} {way}: " + ", ".join(f"{k} {v:.1f} s" for k, v in secs.items()))
    part = t_group - t_study
    print(f"families part on its own:           {t_alone:8.1f} CPU s = {t_alone / t_main:.2f}x the main protocol")
    print(f"families part in the study's trials: {part:8.1f} CPU s = {part / t_main:.2f}x the main protocol")
    print("tables identical between the two ways")


if __name__ == "__main__":
    main()
