"""Reliability figures of docs/user-guide/reliability.md, measured.

1. Bad inputs: every case of the catalogue (``tests/bad_inputs.py``, organised by command, plus
   ``tests/bad_inputs_more.py`` when present) runs in its own forked process with real work stubbed, a time bound
   and a memory bound, and is counted per command as clean (exit 2, one line ``soabench: error: ...`` naming the
   value), traceback, silent (another exit status, real work started, or a write into a foreign folder), hang
   (killed at the time bound) or unclear (exit 2 without one line naming the value); every case that is not clean
   is listed. The poisoned and invalid ``run.json`` files of ``tests/hardening/test_run_folders.py`` are counted too.
2. Kill/resume cycles: a 16-trial process-pool run (the tests' slow fake trial) is SIGKILLed after some trials,
   resumed, killed again, ... until it completes; after each kill no pool worker may survive; the result must equal
   an uninterrupted serial run byte for byte.
3. Executors: serial, process pool, Dask LocalCluster and an external Dask scheduler run the same 6 trials; the
   CSV files must be byte-identical.
4. Filter steps: random mixtures and scans with NaN/inf injected, ``filter.nonfinite = "drop"``: no NaN anywhere.

5. Fuzzing (``--fuzz MINUTES``, on its own): the targets of ``tests/fuzz_targets.py`` (config and scenario TOML,
   run.json, trial records, run CSVs, KITTI text files and .bin/.label scans, plugin births, estimates and labels)
   take turns on random Hypothesis inputs for MINUTES; prints the inputs tried, refused and accepted per target and
   every distinct failure (a traceback, an error of several lines, a wrong result, a file outside the folder) with
   an input that shows it.

Uses the fake trial of the tests (no SUMO), so it takes a few minutes (``--catalogue``: part 1 only)::

    python benchmarks/bench_reliability.py [--catalogue [--timeout S] | --fuzz MINUTES]

``--timeout S`` is the time bound of a catalogue case (default 30 s; on a loaded shared machine a forked case can
wait that long for a core before it starts).
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
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import bad_inputs  # noqa: E402
import fake_trial as ft  # noqa: E402
from processes import alive, children  # noqa: E402

import soabench.experiment.reports.report as report  # noqa: E402
from soabench.cli.main import main  # noqa: E402
from soabench.config import Config  # noqa: E402
from soabench.experiment.execution.options import RunOptions  # noqa: E402
from soabench.experiment.reports.finished import run_experiment  # noqa: E402

CSV_FILES = ("trials.csv", "episodes.csv", "steps.csv")


VERDICTS = ("clean", "traceback", "silent", "hang", "unclear")


def _case_in_child(make, needle: str, case_dir: Path, limit_bytes: int, say_command) -> dict:
    """Run one catalogue case in this (forked) process; return its verdict and first lines."""
    import contextlib
    import io
    import resource
    import traceback

    resource.setrlimit(resource.RLIMIT_AS, (limit_bytes, limit_bytes))
    bad_inputs.work_stubbed(setattr).__enter__()  # for the rest of this forked process
    os.chdir(case_dir)
    out, err = io.StringIO(), io.StringIO()
    started = False
    try:
        argv = make(case_dir)
    finally:
        say_command(bad_inputs.command_of(argv) if "argv" in locals() else "?")
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
        except bad_inputs.WorkStarted:
            code, started = 0, True
        except BaseException:  # noqa: BLE001 - what the catalogue measures
            code = None
            traceback.print_exc()
    started = started or bool(bad_inputs.STARTED)
    verdict = "silent" if started else bad_inputs.verdict(code, out.getvalue(), err.getvalue(), needle)
    if not bad_inputs.foreign_untouched(case_dir):
        verdict = "silent"  # wrote (or probed) into a folder that is not the command's
    return {"verdict": verdict, "code": code, "started": started, "err": err.getvalue()[-2000:]}


def catalogue_counts(tmp: Path, timeout_s: float = 30.0, limit_gb: float = 3.0) -> tuple[dict, list[dict]]:
    """Every case of the catalogue (tests/bad_inputs.py and tests/bad_inputs_more.py) in its own forked process
    (a fresh working folder, real work stubbed), killed after ``timeout_s`` (a hang) with ``limit_gb`` of address
    space. Returns the counts per command and verdict, and one row per case that is not clean."""
    counts: dict[str, dict[str, int]] = {}
    bad: list[dict] = []
    limit = int(limit_gb * 2**30)
    for i, (name, make, needle) in enumerate(bad_inputs.catalogue()):
        d = tmp / f"case{i:04d}"
        d.mkdir(parents=True)
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: its own process group, so a hang's helpers die with it
            os.close(r)
            os.setpgid(0, 0)
            f = os.fdopen(w, "w")

            def say_command(command: str, f=f) -> None:
                f.write(command + "\n")
                f.flush()

            try:
                result = _case_in_child(make, needle, d, limit, say_command)
            except BaseException as exc:  # noqa: BLE001
                result = {"verdict": "traceback", "code": None, "started": False, "err": f"Traceback: {exc!r}"}
            json.dump(result, f, default=str)
            f.close()
            os._exit(0)
        os.close(w)
        t0 = time.monotonic()
        while os.waitpid(pid, os.WNOHANG) == (0, 0):
            if time.monotonic() - t0 > timeout_s:
                os.killpg(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                break
            time.sleep(0.005)
        with os.fdopen(r) as f:
            data = f.read()
        command, _, rest = data.partition("\n")
        result = json.loads(rest) if rest else {"verdict": "hang", "err": f"killed after {timeout_s:g} s"}
        command = command or "?"
        counts.setdefault(command, dict.fromkeys(VERDICTS, 0))[result["verdict"]] += 1
        if result["verdict"] != "clean":
            bad.append({"name": name, "command": command, **result})
    return counts, bad


def run_meta_cases(tmp: Path) -> tuple[int, int]:
    """(tried, refused) over the poisoned and invalid run.json files of tests/hardening/test_run_folders.py."""
    import contextlib
    import io

    sys.path.insert(0, str(ROOT / "tests" / "hardening"))
    from test_run_folders import BAD_META, POISONS

    tried = refused = 0
    for i, changes in enumerate([*POISONS, *(c for c, _ in BAD_META)]):
        run = tmp / f"meta{i}"
        run_experiment(
            _cfg(3),
            "x",
            out=run,
            options=RunOptions(workers=1, progress=False, figures=False),
            trial_fn=ft.fake_trial,
            load_fn=ft.fake_load,
        )
        meta = json.loads((run / "run.json").read_text())
        for k, v in changes.items():
            meta.pop(k, None) if v is ... else meta.__setitem__(k, v)
        (run / "run.json").write_text(json.dumps(meta))
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = main(["run", "--resume", str(run)])
        tried += 1
        refused += code == 2 and len(bad_inputs.messages(err.getvalue())) == 1 and "poison_marker" not in sys.modules
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
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.reports.finished import run_experiment
cfg = Config.from_dict({cfg!r}).validate()
kw = dict(options=RunOptions(workers=2, progress=False, figures=False), trial_fn=ft.slow_trial, load_fn=ft.fake_load)
if {resume!r}:
    run_experiment(None, "x", resume=Path({out!r}), **kw)
else:
    run_experiment(cfg, "intersection", out=Path({out!r}), **kw)
"""


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
        workers = children(proc.pid)
        proc.send_signal(signal.SIGKILL)
        proc.communicate()
        cycles += 1
        t0 = time.monotonic()
        while any(alive(p) for p in workers) and time.monotonic() - t0 < 10:
            time.sleep(0.1)
        orphans += sum(alive(p) for p in workers)
        for p in workers:
            if alive(p):
                os.kill(p, signal.SIGKILL)
        resume = True
    ref = tmp / "ref"
    run_experiment(
        cfg,
        "intersection",
        out=ref,
        options=RunOptions(workers=1, progress=False, figures=False),
        trial_fn=ft.fake_trial,
        load_fn=ft.fake_load,
    )
    same = all((out / f).read_bytes() == (ref / f).read_bytes() for f in CSV_FILES)
    return {"cycles": cycles, "orphans": orphans, "identical": same}


def executors(tmp: Path) -> dict:
    from distributed import LocalCluster

    cfg = _cfg(6)
    kw = dict(trial_fn=ft.fake_trial, load_fn=ft.fake_load)
    quiet = dict(progress=False, figures=False)
    runs = {
        "serial": RunOptions(workers=1, **quiet),
        "process pool (2)": RunOptions(workers=2, **quiet),
        "Dask LocalCluster (2)": RunOptions(dask_local=True, workers=2, **quiet),
    }
    out = {}
    for name, ex in runs.items():
        run_experiment(cfg, "intersection", out=tmp / name.split()[0], options=ex, **kw)
        out[name] = tmp / name.split()[0]
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        run_experiment(
            cfg,
            "intersection",
            out=tmp / "external",
            options=RunOptions(scheduler=cluster.scheduler_address, **quiet),
            **kw,
        )
        out["external Dask scheduler"] = tmp / "external"
    ref = out["serial"]
    return {name: all((d / f).read_bytes() == (ref / f).read_bytes() for f in CSV_FILES) for name, d in out.items()}


def filter_steps(n: int = 2000) -> dict:
    from shapely.geometry import Polygon

    from soabench.config import FilterConfig, Sensor
    from soabench.gmphd import GMPHDFilter
    from soabench.types import SOURCE_GRID, Births, Scan

    rng = np.random.default_rng(0)
    filt = GMPHDFilter(FilterConfig(nonfinite="drop", J_max=100), Sensor(), "dynamic")
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


def fuzz(minutes: float, batch: int = 50) -> dict:
    """Every fuzz target in turn, ``batch`` random inputs at a time, until ``minutes`` have passed; failures are
    recorded (not raised, so the search goes on) and counted once per distinct first line."""
    from fuzz_targets import TARGETS, FuzzFailure, short_id
    from hypothesis import HealthCheck, Phase, given, settings

    stop = time.monotonic() + 60.0 * minutes
    seen = {name: {"ok": 0, "refused": 0, "failed": 0} for name in TARGETS}
    failures: dict[tuple[str, str], dict] = {}
    quick = settings(
        max_examples=batch, derandomize=False, database=None, deadline=None, phases=[Phase.generate],
        suppress_health_check=list(HealthCheck),
    )  # fmt: skip

    def runner(name: str, target) -> Callable[[object], None]:
        def run(value: object) -> None:
            if time.monotonic() >= stop:
                return
            try:
                seen[name][target(value)] += 1
            except FuzzFailure as exc:
                seen[name]["failed"] += 1
                key = (name, short_id(exc))
                if key not in failures:
                    failures[key] = {"count": 0, "detail": str(exc)[-3000:], "input": repr(value)[:600]}
                failures[key]["count"] += 1

        return run

    while time.monotonic() < stop:
        for name, (strategy, target) in TARGETS.items():
            if time.monotonic() < stop:
                quick(given(strategy())(runner(name, target)))()
    return {"seen": seen, "failures": failures}


def main_fuzz(minutes: float) -> None:
    t0 = time.monotonic()
    out = fuzz(minutes)
    total = {k: sum(c[k] for c in out["seen"].values()) for k in ("ok", "refused", "failed")}
    n = sum(total.values())
    print(f"fuzzing: {n} inputs in {time.monotonic() - t0:.0f} s: {total['ok']} accepted, {total['refused']} refused "
          f"with one line, {total['failed']} failed ({len(out['failures'])} distinct failures)")  # fmt: skip
    for name, c in out["seen"].items():
        print(f"  {name:28s} tried {sum(c.values()):7d}  accepted {c['ok']:7d}  refused {c['refused']:7d}  "
              f"failed {c['failed']:5d}")  # fmt: skip
    for (name, first), f in out["failures"].items():
        print(f"\nFAILURE {name} ({f['count']}x): {first}\n  input: {f['input']}\n{f['detail']}")


def main_() -> None:
    if "--fuzz" in sys.argv[1:]:
        main_fuzz(float(sys.argv[sys.argv.index("--fuzz") + 1]))
        return
    report.write_report = lambda run_dir, figures=True, store=None: (
        "summary"
    )  # the figures are not what is measured here
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        t0 = time.monotonic()
        bound = float(sys.argv[sys.argv.index("--timeout") + 1]) if "--timeout" in sys.argv else 30.0
        counts, bad = catalogue_counts(tmp / "bad", timeout_s=bound)
        total = dict.fromkeys(VERDICTS, 0)
        for c in counts.values():
            for k, v in c.items():
                total[k] += v
        n = sum(total.values())
        print(f"bad inputs: {n} cases, " + ", ".join(f"{k} {v}" for k, v in total.items())
              + f" ({time.monotonic() - t0:.1f} s)")  # fmt: skip
        for command, c in sorted(counts.items()):
            print(f"  {command:16s} " + "  ".join(f"{k} {v:3d}" for k, v in c.items()))
        for row in bad:
            first = (bad_inputs.messages(row.get("err") or "") or [""])[-1][:150]
            print(f"  not clean: {row['verdict']:9s} {row['name']}: {first}")
        tried, refused = run_meta_cases(tmp / "meta")
        print(f"run.json files: {refused} of {tried} refused with one line and exit 2")
        if "--catalogue" in sys.argv[1:]:
            return
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
