"""The test suite's wall time on the machine's cores (pytest-xdist, as ``pytest`` runs it) against serially.

Runs the suite twice in this environment (which must have the test extra: ``pip install -e ".[test]"``), one after
the other with the kernels already compiled: ``pytest -n 0`` (one process) and plain ``pytest`` (the project's
``addopts``: one worker per core, at most four, each test file whole on one worker). Prints each run's wall time,
its CPU time (pytest and its worker processes) and outcome line, and the ratio of the wall times. ``--first
parallel`` swaps the order; ``--select`` passes a subset (e.g. ``-m "not slow"``). Example::

    python benchmarks/bench_tests.py
"""

from __future__ import annotations

import argparse
import os
import resource
import shlex
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def children_cpu() -> float:
    """CPU seconds of this process's finished children (pytest and, through it, its workers)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run(label: str, extra: list[str], select: list[str]) -> float:
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *extra, *select]
    c0, t0 = children_cpu(), time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, children_cpu() - c0
    lines = [ln.strip("= ") for ln in proc.stdout.splitlines() if " passed" in ln or " failed" in ln]
    outcome = lines[-1] if lines else f"exit {proc.returncode}"  # pytest's last line: the counts and its time
    print(f"{label:<10} {wall:8.1f} wall s {cpu:8.1f} CPU s   {outcome}", flush=True)
    if proc.returncode != 0:
        sys.exit(f"{shlex.join(cmd)} failed (exit {proc.returncode}): the timing would not be the suite's")
    return wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", choices=("serial", "parallel"), default="serial", help="which run goes first")
    ap.add_argument("--select", default="", help="pytest arguments selecting the tests (default: all)")
    a = ap.parse_args()
    select = shlex.split(a.select)
    print(f"# {os.cpu_count()} cores, load average {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    runs = {"serial": ["-n", "0"], "parallel": []}
    order = ("serial", "parallel") if a.first == "serial" else ("parallel", "serial")
    wall = {name: run(name, runs[name], select) for name in order}
    print(f"parallel / serial wall time: {wall['parallel'] / wall['serial']:.2f}")


if __name__ == "__main__":
    main()
