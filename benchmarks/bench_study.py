"""Wall time of ``soabench study`` relative to its main run, with and without the work done once.

In one process, on the same short protocol, one after another:

1. the main run alone (``run_experiment``, six birth models x {static, dynamic}, λ = 3), the ratio's denominator,
   and once more with births per (model, mode) as before;
2. the study as before: its parts one after another (the clutter sweep reruns the main run's λ = 3 filter runs, the
   N̂ sweep runs SUMO and the sensor once per point, the sensitivity runs run SUMO, the sensor and every filter
   again), births per (model, mode, clutter rate, N̂) and every N̂ point's own figures
   (``run_study(grouped=False, all_figures=True)`` with ``run_trial(births_once=False)``);
3. the study as now: the trials of all four parts together (SUMO once per trial, the sensor once per clutter rate,
   each filter run once across parts, the visible-truth run scoring the main run's filter runs), the weight-free
   births of a mode-free model once per scan for every mode, clutter rate and N̂, the N̂ points without figures of
   their own, and every folder's figures drawn one per task on the study's ``--workers`` processes.

The "before" side is what can still be switched off in today's code, not main @ e59db79 as a whole: its parts
one after another also draw their figures on ``--workers`` processes (as ``soabench run`` does), so
compare only the ratios printed by one invocation.

It prints each wall time split into trials (the sessions' wall time) and reports (summaries and figures of every
folder, timed around ``write_report``), the CPU seconds of each call (this process and its finished worker
processes: unlike wall time hardly changed by other work on a shared machine), the ratios study / main run
(before, now) and checks that both studies
wrote the same trials.csv, episodes.csv and steps.csv in every folder. The ``births_once`` switch reaches the trials
of a serial run only (``--workers 1``, the default). Example::

    nice -n 10 python benchmarks/bench_study.py --trials 4 --duration 30 --births-trials 4 [--workers 2]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import resource
import tempfile
import time
from pathlib import Path

from soabench.config import Config
from soabench.experiment.campaigns.study import run_study
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.reports import report as report_module
from soabench.experiment.reports.finished import run_experiment
from soabench.experiment.trial import trial as trial_module


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--net", default="intersection")
    p.add_argument("--trials", type=int, default=4)
    p.add_argument("--duration", type=float, default=30.0)
    p.add_argument("--births-trials", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--out", type=Path, default=None, help="folder for the runs (default: a temporary one)")
    return p.parse_args(argv)


def result_files(root: Path) -> dict[str, str]:
    """Every trials/episodes/steps CSV under ``root`` (they hold no wall-clock column), by relative path."""
    names = ("trials.csv", "episodes.csv", "steps.csv")
    return {str(p.relative_to(root)): p.read_text() for p in sorted(root.rglob("*.csv")) if p.name in names}


def cpu_seconds() -> float:
    """CPU seconds (user + system) of this process and of its finished child processes (the pool workers, reaped
    when a pool closes): unlike wall time, hardly changed by other work on a shared machine."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


CPU: dict[str, float] = {}  # name -> CPU seconds of a timed call


def timed(fn, *args, cpu_key: str = "", **kwargs) -> float:
    t0, c0 = time.perf_counter(), cpu_seconds()
    fn(*args, **kwargs)
    CPU[cpu_key] = cpu_seconds() - c0
    return time.perf_counter() - t0


def trial_seconds(root: Path) -> float:
    """Wall time spent running trials under ``root``: the sessions' wall time, a grouped session counted once."""
    total, seen = 0.0, set()
    for f in root.rglob("sessions/*.json"):
        s = json.loads(f.read_text())
        if "grouped" in str(s.get("executor", "")):
            if s.get("started") in seen:
                continue
            seen.add(s.get("started"))
        total += float(s.get("wall_s", 0.0))
    return total


class ReportClock:
    """Seconds spent in ``write_report`` (summaries and figures, however many processes draw them), summed over the
    folders (reports are written one folder after another)."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self._orig = report_module.write_report

    def __enter__(self) -> ReportClock:
        def timed_report(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return self._orig(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - t0

        report_module.write_report = timed_report
        return self

    def __exit__(self, *exc) -> None:
        report_module.write_report = self._orig


def main(argv=None) -> int:
    a = parse_args(argv)
    cfg = Config()
    cfg.experiment = dataclasses.replace(cfg.experiment, trials=a.trials, duration=a.duration, seed=a.seed)
    cfg.validate()
    root = Path(a.out) if a.out else Path(tempfile.mkdtemp(prefix="bench_study_"))
    kw = dict(options=RunOptions(workers=a.workers, progress=False))
    study_kw = dict(births_trials=a.births_trials, **kw)

    warm = Config.from_dict(cfg.to_dict())  # imports, scene, compiled kernels: paid here, by no measured run
    warm.experiment = dataclasses.replace(warm.experiment, trials=1)
    run_experiment(
        warm, a.net, out=root / "warm_up", options=RunOptions(workers=a.workers, progress=False, figures=False)
    )
    with ReportClock() as r_main:
        t_main = timed(run_experiment, cfg, a.net, out=root / "main_alone", cpu_key="main_alone", **kw)
    defaults = trial_module.run_trial.__kwdefaults__
    defaults["births_once"] = False  # "before": births per (model, mode); reaches the trials of a serial run only
    try:
        with ReportClock() as r_main_before:
            t_main_before = timed(run_experiment, cfg, a.net, out=root / "main_before", cpu_key="main_before", **kw)
        with ReportClock() as r_before:
            t_before = timed(
                run_study,
                cfg,
                a.net,
                out=root / "study_before",
                grouped=False,
                all_figures=True,
                cpu_key="study_before",
                **study_kw,
            )
    finally:
        defaults["births_once"] = True
    with ReportClock() as r_after:
        t_after = timed(run_study, cfg, a.net, out=root / "study_after", cpu_key="study_after", **study_kw)

    before, after = result_files(root / "study_before"), result_files(root / "study_after")
    same = before == after and len(before) > 0
    same = same and result_files(root / "main_alone") == result_files(root / "main_before")
    print(f"protocol: {a.trials} trials x {a.duration:g} s (N̂ sweep {a.births_trials} trials), workers {a.workers}")
    tr = {k: trial_seconds(root / k) for k in ("main_alone", "main_before", "study_before", "study_after")}
    print("                        wall (s)  trials (s)  reports (s)  CPU (s)  wall / main  CPU / main  trials / main")
    for name, t, r, k, t_ref, k_ref in (
        ("main run before", t_main_before, r_main_before.seconds, "main_before", t_main_before, "main_before"),
        ("main run now", t_main, r_main.seconds, "main_alone", t_main, "main_alone"),
        ("study before", t_before, r_before.seconds, "study_before", t_main_before, "main_before"),
        ("study now", t_after, r_after.seconds, "study_after", t_main, "main_alone"),
    ):
        print(
            f"{name:22s} {t:9.1f} {tr[k]:11.1f} {r:12.1f} {CPU[k]:8.1f} {t / t_ref:12.2f} {CPU[k] / CPU[k_ref]:11.2f}"
            f" {tr[k] / tr[k_ref]:14.2f}"
        )
    gain = tr["study_before"] / tr["study_after"]
    print(f"speed-up of the study: wall {t_before / t_after:.2f}x, trials {gain:.2f}x")
    print(
        f"study / main run now: wall {t_after / t_main:.2f}x, CPU {CPU['study_after'] / CPU['main_alone']:.2f}x "
        f"(target: wall <= 3x); of the study's {t_after:.1f} s wall, trials {tr['study_after']:.1f} s, reports and "
        f"figures {r_after.seconds:.1f} s"
    )
    print(f"identical results      {same} ({len(after)} CSV files compared)")
    print(f"folders under {root}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
