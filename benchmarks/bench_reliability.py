"""Reliability figures of docs/user-guide/reliability.md, measured.

1. Bad inputs: every case of ``tests/bad_inputs.py`` (command line) and of ``tests/test_hardening_runs.py``
   (poisoned and invalid ``run.json`` files) is tried; a case counts as refused when the command exits with status 2
   and prints exactly one line, no traceback, no trial run, nothing imported from the run folder.
2. Kill/resume cycles: a 16-trial process-pool run (the tests' slow fake trial) is SIGKILLed after some trials,
   resumed, killed again, ... until it completes; after each kill no pool worker may survive; the result must equal
   an uninterrupted serial run byte for byte.
3. Executors: serial, process pool, Dask LocalCluster and an external Dask scheduler run the same 6 trials; the
   CSV files must be byte-identical.
4. Filter steps: random mixtures and scans with NaN/inf injected, ``filter.nonfinite = "drop"``: no NaN anywhere.

Uses the fake trial of the tests (no SUMO), so it takes about a minute::

    python benchmarks/bench_reliability.py
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import bad_inputs  # noqa: E402
import fake_trial as ft  # noqa: E402

import soabench.experiment.report as report  # noqa: E402
import soabench.scenario  # noqa: E402
from soabench.cli import main  # noqa: E402
from soabench.config import Config  # noqa: E402
from soabench.experiment import registry  # noqa: E402
from soabench.experiment.runner import run_experiment  # noqa: E402

CSV_FILES = ("trials.csv", "episodes.csv", "steps.csv")


def _one_line_exit_2(argv: list[str]) -> bool:
    import contextlib
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    lines = err.getvalue().strip().splitlines()
    return code == 2 and len(lines) == 1 and "Traceback" not in err.getvalue()


def bad_inputs_refused(tmp: Path) -> tuple[int, int]:
    """(tried, refused) over the command-line table and the run.json cases."""
    started: list = []

    def no_trial(*a, **k):
        started.append(a)
        raise AssertionError("a trial ran")

    def no_simulation(*a, **k):
        raise AssertionError("a simulation ran")

    saved = registry._TRIAL_KINDS[registry.DEFAULT_TRIAL_KIND], soabench.scenario.simulate
    registry._TRIAL_KINDS[registry.DEFAULT_TRIAL_KIND] = no_trial
    soabench.scenario.simulate = no_simulation
    tried = refused = 0
    try:
        for i, (_name, make, _needle) in enumerate(bad_inputs.CASES):
            d = tmp / f"cli{i}"
            d.mkdir(parents=True)
            tried += 1
            refused += _one_line_exit_2(make(d)) and not started
        from test_hardening_runs import BAD_META, POISONS

        for i, changes in enumerate([*POISONS, *(c for c, _ in BAD_META)]):
            run = tmp / f"meta{i}"
            run_experiment(_cfg(3), "x", out=run, workers=1, trial_fn=ft.fake_trial, load_fn=ft.fake_load,
                           progress=False, figures=False)  # fmt: skip
            meta = json.loads((run / "run.json").read_text())
            for k, v in changes.items():
                meta.pop(k, None) if v is ... else meta.__setitem__(k, v)
            (run / "run.json").write_text(json.dumps(meta))
            tried += 1
            refused += _one_line_exit_2(["run", "--resume", str(run)]) and "poison_marker" not in sys.modules
    finally:
        registry._TRIAL_KINDS[registry.DEFAULT_TRIAL_KIND], soabench.scenario.simulate = saved
    return tried, refused


def _cfg(trials: int) -> Config:
    cfg = Config()
    cfg.experiment = dataclasses.replace(cfg.experiment, trials=trials, duration=20.0, clutter=(0.5, 3.0), seed=11)
    return cfg.validate()


DRIVER = """
import sys
sys.path.insert(0, {tests!r})
import fake_trial as ft
from pathlib import Path
from soabench.config import Config
from soabench.experiment.runner import run_experiment
cfg = Config.from_dict({cfg!r}).validate()
kw = dict(workers=2, trial_fn=ft.slow_trial, load_fn=ft.fake_load, progress=False, figures=False)
if {resume!r}:
    run_experiment(None, "x", resume=Path({out!r}), **kw)
else:
    run_experiment(cfg, "intersection", out=Path({out!r}), **kw)
"""


def _children(pid: int) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return out


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def kill_resume_cycles(tmp: Path, n_trials: int = 16) -> dict:
    cfg = _cfg(n_trials)
    out = tmp / "killed"
    cycles = orphans = 0
    rng = np.random.default_rng(1)
    resume = False
    while True:
        code = DRIVER.format(tests=str(ROOT / "tests"), cfg=cfg.to_dict(), out=str(out), resume=resume)
        proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        have = len(list((out / "trials").glob("*.json"))) if out.exists() else 0
        target = have + int(rng.integers(1, 4))
        while proc.poll() is None and len(list((out / "trials").glob("*.json"))) < target:
            time.sleep(0.05)
        if proc.poll() is not None:  # finished before the kill
            proc.communicate()
            assert proc.returncode == 0
            break
        workers = _children(proc.pid)
        proc.send_signal(signal.SIGKILL)
        proc.communicate()
        cycles += 1
        t0 = time.monotonic()
        while any(_alive(p) for p in workers) and time.monotonic() - t0 < 10:
            time.sleep(0.1)
        orphans += sum(_alive(p) for p in workers)
        for p in workers:
            if _alive(p):
                os.kill(p, signal.SIGKILL)
        resume = True
    ref = tmp / "ref"
    run_experiment(cfg, "intersection", out=ref, workers=1, trial_fn=ft.fake_trial, load_fn=ft.fake_load,
                   progress=False, figures=False)  # fmt: skip
    same = all((out / f).read_bytes() == (ref / f).read_bytes() for f in CSV_FILES)
    return {"cycles": cycles, "orphans": orphans, "identical": same}


def executors(tmp: Path) -> dict:
    from distributed import LocalCluster

    cfg = _cfg(6)
    kw = dict(trial_fn=ft.fake_trial, load_fn=ft.fake_load, progress=False, figures=False)
    runs = {
        "serial": dict(workers=1),
        "process pool (2)": dict(workers=2),
        "Dask LocalCluster (2)": dict(dask_local=True, workers=2),
    }
    out = {}
    for name, ex in runs.items():
        run_experiment(cfg, "intersection", out=tmp / name.split()[0], **ex, **kw)
        out[name] = tmp / name.split()[0]
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        run_experiment(cfg, "intersection", out=tmp / "external", scheduler=cluster.scheduler_address, **kw)
        out["external Dask scheduler"] = tmp / "external"
    ref = out["serial"]
    return {name: all((d / f).read_bytes() == (ref / f).read_bytes() for f in CSV_FILES) for name, d in out.items()}


def filter_steps(n: int = 2000) -> dict:
    from shapely.geometry import Polygon

    from soabench.birth.base import SOURCE_GRID, Births
    from soabench.config import FilterConfig, SensorConfig
    from soabench.gmphd import GMPHDFilter
    from soabench.sensor import Scan

    rng = np.random.default_rng(0)
    filt = GMPHDFilter(FilterConfig(nonfinite="drop", J_max=100), SensorConfig(), "dynamic")
    dropped = nan_results = 0
    for k in range(n):
        M, J = int(rng.integers(0, 10)), int(rng.integers(0, 6))
        Z = np.column_stack([rng.uniform(0, 60, M), rng.uniform(-np.pi, np.pi, M)])
        Z[rng.random(Z.shape) < 0.05] = np.nan
        ego = np.array([rng.normal(0, 5), rng.normal(0, 5), rng.uniform(-np.pi, np.pi)])
        if rng.random() < 0.02:
            ego[1] = np.inf
        m = np.column_stack([rng.uniform(-40, 40, (J, 2)), rng.normal(0, 1, (J, 2))])
        births = Births(np.full(J, 0.05), m, np.tile(np.eye(4) * 4.0, (J, 1, 1)), np.full(J, SOURCE_GRID, np.int8))
        res = filt.step(Scan(k, float(k), ego, Z, None, [], Polygon()), births)
        dropped += res.n_dropped
        mix = filt.mixture
        ok = np.isfinite(res.X).all() and np.isfinite(mix.w).all() and np.isfinite(mix.m).all()
        nan_results += not (ok and np.isfinite(res.sum_w))
    return {"steps": n, "measurements dropped": dropped, "non-finite results": nan_results}


def main_() -> None:
    report.write_report = lambda run_dir, figures=True: "summary"  # the figures are not what is measured here
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        t0 = time.monotonic()
        tried, refused = bad_inputs_refused(tmp / "bad")
        print(f"bad inputs: {refused} of {tried} refused with one line and exit 2 ({time.monotonic() - t0:.1f} s)")
        t0 = time.monotonic()
        kr = kill_resume_cycles(tmp / "kill")
        print(
            f"kill/resume: {kr['cycles']} SIGKILL cycles, {kr['orphans']} orphaned workers, result identical to an "
            f"uninterrupted run: {kr['identical']} ({time.monotonic() - t0:.1f} s)"
        )
        t0 = time.monotonic()
        ex = executors(tmp / "exec")
        print(f"executors byte-identical to serial: {ex} ({time.monotonic() - t0:.1f} s)")
        fs = filter_steps()
        print(f"filter steps with NaN/inf injected (drop): {fs}")


if __name__ == "__main__":
    main_()
