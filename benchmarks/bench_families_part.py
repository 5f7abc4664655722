"""CPU time of the families part of ``soabench results`` against the GM-PHD main protocol's.

The families part is two run folders at the main protocol's sizes: ``filters/`` (every birth model in the GM-PHD,
LMB, PMBM and PMB, static and static+occ) and ``filters-lmb-components/`` (the LMB with one Bernoulli per birth
component, static). In one process, one after another, on the same protocol (intersection, λ = 3):

1. the main protocol alone (six birth models x {static, dynamic}, GM-PHD): the ratios' denominator;
2. the two families folders each on its own (as ``soabench run`` makes them);
3. the intersection study alone (main run, clutter sweep, N̂ sweep, sensitivity runs);
4. the study with the two families folders in its trials (how ``soabench results`` runs them): the families part
   costs what 4 adds to 3.

Each figure is the CPU seconds of the call: this process and its finished worker processes, printed also apart
(this process: merges, summaries, pages; its children: the trials and the reports' figures). The families part in
the study's trials is a difference of two large figures, so it scatters with the machine's speed from one minute to
the next; the script therefore also prints what the families folders' own records say (``timing.csv``: SUMO, the
sensor and the births, summed over trials, seconds inside the workers), which does not depend on the neighbours.
It checks that the families folders of 2 and 4 hold the same trials.csv, episodes.csv and steps.csv.
``--rounds N`` repeats 1-4 N times and prints each round's ratio and their median; ``--no-alone`` leaves out 2 (and
the check).

Last, what the part would cost with other step speeds (:func:`counterfactual`): the families folders' filter
steps (``t_filter_total - t_birth`` of ``timing.csv``: every step of a run, the Python around the compiled calls
included, per family and mode) of the LMB, PMBM and PMB replaced by the GM-PHD's steps in the same mode times a
factor: 1 (every family as fast as the GM-PHD: a floor the families' speed cannot beat) and their step targets (LMB
2x, PMBM 3x, PMB 2x). Example::

    nice -n 10 python benchmarks/bench_families_part.py --trials 20 --duration 100 --workers 2
    python benchmarks/bench_families_part.py --rounds 3 --no-alone
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import functools
import resource
import statistics
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


def step_seconds(folder: Path) -> dict[tuple[str, str], float]:
    """The folder's filter steps (t_filter_total - t_birth, seconds inside the workers) summed over its trials and
    birth models, per (family, probability mode)."""
    out: dict[tuple[str, str], float] = {}
    with (folder / "timing.csv").open(newline="") as f:
        for r in csv.DictReader(f):
            key = (r.get("filter") or "gmphd", r["mode"])
            out[key] = out.get(key, 0.0) + float(r["t_filter_total"]) - float(r["t_birth"])
    return out


#: the step targets of the families against the GM-PHD (docs/user-guide/speed.md)
STEP_TARGETS = {"lmb": 2.0, "pmbm": 3.0, "pmb": 2.0}


def counterfactual(part: float, folders: dict[str, dict[tuple[str, str], float]], factor: dict[str, float]) -> float:
    """``part`` (CPU s) with every non-GM-PHD family's steps replaced by ``factor[family]`` times the GM-PHD's
    steps in the same mode (the ``filters`` folder's GM-PHD: the same trials and birth models)."""
    gmphd = {mode: t for (fam, mode), t in folders["filters"].items() if fam == "gmphd"}
    for steps in folders.values():
        for (fam, mode), t in steps.items():
            if fam != "gmphd":
                part += factor[fam] * gmphd[mode] - t
    return part


def cpu() -> tuple[float, float]:
    """CPU seconds of this process and of its finished children (the trials' workers, the figures' processes)."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


def timed(label: str, work) -> tuple[float, float]:
    """CPU seconds of ``work()``: in all, and in this process alone (the rest: its child processes)."""
    (o0, k0), t0 = cpu(), time.perf_counter()
    work()
    (o1, k1), t = cpu(), time.perf_counter() - t0
    own, kids = o1 - o0, k1 - k0
    print(f"{label:<44} {own + kids:8.1f} CPU s {t:8.1f} wall s (this process {own:.1f}, children {kids:.1f})",
          flush=True)  # fmt: skip
    return own + kids, own


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--duration", type=float, default=100.0)
    ap.add_argument("--births-trials", type=int, default=1, help="trials per N̂ point of the study")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=1,
                    help="rounds of the main protocol, the study alone and the study with the folders (the part's "
                         "ratio of each round and their median)")  # fmt: skip
    ap.add_argument("--no-alone", action="store_true",
                    help="skip the families folders on their own (and the check of their tables)")  # fmt: skip
    a = ap.parse_args()
    s = Settings(trials=a.trials, duration=a.duration)
    main_cfg = Config()
    main_cfg.experiment = dataclasses.replace(main_cfg.experiment, trials=a.trials, duration=a.duration)
    main_cfg.validate()
    options = RunOptions(workers=a.workers, progress=False)
    study = dict(births_trials=a.births_trials, options=options)
    folders = {"filters": filters_config(s), "ablation": ablation_config(s)}
    ratios = [one_round(root, folders, main_cfg, options, study, a.no_alone) for root in rounds(a.rounds)]
    print("the part in the study's trials / main protocol, by round: " + ", ".join(f"{x:.2f}x" for x in ratios)
          + f" (median {statistics.median(ratios):.2f}x)")  # fmt: skip


def rounds(n: int):
    """``n`` fresh temporary folders, one after the other (each deleted before the next)."""
    for r in range(n):
        print(f"round {r + 1}", flush=True)
        with tempfile.TemporaryDirectory(prefix="bench_families_part_") as tmp:
            yield Path(tmp)


def one_round(here: Path, folders: dict, main_cfg: Config, options: RunOptions, study: dict, no_alone: bool) -> float:
    """One round in ``here``: the main protocol, the families folders alone (unless ``no_alone``), the study alone
    and with the folders in its trials; prints what it measured and returns the part's ratio to the main protocol."""
    run = functools.partial(run_experiment, net="intersection", options=options)
    t_main = timed("main protocol", functools.partial(run, main_cfg, out=here / "main"))[0]
    if not no_alone:
        t_alone = sum(timed(f"{name} alone", functools.partial(run, c, out=here / "alone" / name))[0]
                      for name, c in folders.items())  # fmt: skip
    study_run = functools.partial(run_study, main_cfg, "intersection", **study)
    t_study, own_study = timed("study alone", functools.partial(study_run, out=here / "study"))
    companions = tuple(Companion(here / "grouped" / name, c, FILTERS_KEYS) for name, c in folders.items())
    t_group, own_group = timed("study with the families folders in its trials",
                               functools.partial(study_run, out=here / "study2", companions=companions))  # fmt: skip
    if not no_alone:
        for name in folders:
            for t in TABLES:
                alone, grouped = (here / way / name / t for way in ("alone", "grouped"))
                assert alone.read_bytes() == grouped.read_bytes(), f"{name}/{t} differs between the two ways"
            for way in ("alone", "grouped"):
                secs = shared_seconds(here / way / name)
                print(f"{name} {way}: " + ", ".join(f"{k} {v:.1f} s" for k, v in secs.items()))
        print("tables identical between the two ways")
        print(f"families part on its own:           {t_alone:8.1f} CPU s = {t_alone / t_main:.2f}x the main protocol")
    steps = {name: step_seconds(here / "grouped" / name) for name in folders}
    for name, st in steps.items():
        print(f"{name} filter steps: " + ", ".join(f"{f} {m} {t:.1f} s" for (f, m), t in sorted(st.items())))
    part = t_group - t_study
    own = own_group - own_study
    print(f"families part in the study's trials: {part:8.1f} CPU s = {part / t_main:.2f}x the main protocol (this "
          f"process {own:.1f}: merges, summaries, pages; children {part - own:.1f}: trials, figures)")  # fmt: skip
    for what, factor in (("every family at the GM-PHD's speed", dict.fromkeys(STEP_TARGETS, 1.0)),
                         ("every family at its step target", STEP_TARGETS)):  # fmt: skip
        t = counterfactual(part, steps, factor)
        print(f"families part in the study's trials, {what}: {t:8.1f} CPU s = {t / t_main:.2f}x")
    return part / t_main


if __name__ == "__main__":
    main()
