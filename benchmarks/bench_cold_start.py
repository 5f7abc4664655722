"""Cold start against warm start: a command on a machine whose kernel cache is empty, and the same command again.

A fresh ``NUMBA_CACHE_DIR`` stands for a fresh machine (or a CI job without a cache step): the first command
compiles the numba kernels (:mod:`soabench.kernel_warmup`), the second loads them. Each round runs, as separate
processes, ``soabench check --suite examples/check/suite.toml`` cold then warm, and a short ``soabench run`` of two
trials on two workers cold then warm, alternating, so that a machine shared with other work loads both alike.
Printed per round: wall seconds and CPU seconds (the command and every process it started) of each, and the ratios
cold / warm.
Example::

    python benchmarks/bench_cold_start.py --rounds 2
    PYTHONPATH=/path/to/other/checkout python benchmarks/bench_cold_start.py   # another version of soabench
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=1, help="cold/warm pairs of each command (default 1)")
    p.add_argument("--suite", default=str(ROOT / "examples" / "check" / "suite.toml"))
    p.add_argument("--duration", type=float, default=20.0, help="seconds of the one-trial run (default 20)")
    p.add_argument("--trials", type=int, default=2, help="trials of the run, on two workers (default 2)")
    p.add_argument("--skip-run", action="store_true", help="only the check")
    p.add_argument("--skip-check", action="store_true", help="only the run")
    return p.parse_args(argv)


def timed(cmd: list[str], env: dict[str, str]) -> tuple[float, float]:
    """(wall s, CPU s of the command and its children) of one command; exits on failure."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in (0, 1):  # check: 1 = a threshold failed, still a complete run
        sys.exit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def cold_warm(name: str, make_cmd, work: Path) -> tuple[tuple[float, float], tuple[float, float]]:
    """The command once with an empty kernel cache, then once more with the cache it left."""
    cache = work / f"cache-{name}"
    shutil.rmtree(cache, ignore_errors=True)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    cold = timed(make_cmd(work / f"{name}-cold"), env)
    warm = timed(make_cmd(work / f"{name}-warm"), env)
    return cold, warm


def main(argv=None) -> int:
    args = parse_args(argv)
    cli = [sys.executable, "-m", "soabench.cli"]
    commands = {
        "check": lambda out: [*cli, "check", "--suite", args.suite, "--out", str(out)],
        "run": lambda out: [*cli, "run", "--net", "intersection", "--trials", str(args.trials), "--workers", "2",
                            "--duration", str(args.duration), "--out", str(out), "--no-progress"],
    }  # fmt: skip
    if args.skip_run:
        del commands["run"]
    if args.skip_check:
        del commands["check"]
    print(f"cores: {os.cpu_count()}; load average at start: {os.getloadavg()[0]:.1f}")
    print(f"{'command':12s} {'round':>5s} {'cold wall':>9s} {'warm wall':>9s} {'ratio':>6s} "
          f"{'cold CPU':>8s} {'warm CPU':>8s} {'ratio':>6s}")  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="soabench-cold-") as tmp:
        for r in range(args.rounds):
            for name, make in commands.items():
                (cw, cc), (ww, wc) = cold_warm(name.replace(" ", "-"), make, Path(tmp) / f"r{r}")
                print(f"{name:12s} {r + 1:5d} {cw:8.1f}s {ww:8.1f}s {cw / ww:5.1f}x {cc:7.1f}s {wc:7.1f}s "
                      f"{cc / wc:5.1f}x", flush=True)  # fmt: skip
    print(f"load average at end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
