"""The paper protocol against its SUMO floor: wall time, SUMO seconds / cores, and peak memory.

Runs ``soabench run --net intersection`` (default: the paper protocol, 100 trials x 100 s, every default birth model
x {static, dynamic}, lambda = 3, one worker per core) as a child process and prints

* the SUMO floor: the SUMO seconds of its trials (``timing.csv``, ``t_sumo``) divided by the workers: the wall time
  of a run that did nothing but SUMO, perfectly parallel;
* the trials phase (the session's ``wall_s``: first trial submitted to last trial on disk) and the whole command
  (start-up, scene, trials, merge, summary and figures) against that floor;
* the CPU seconds inside trials per stage (SUMO, sensor, filters incl. births, metrics);
* peak memory: the largest resident set of the driver and of any one worker (``ru_maxrss`` of RUSAGE_CHILDREN), and
  the largest sum over the process tree (sampled from /proc every 0.2 s) of the proportional set sizes (each page
  shared by forked processes counted once in all) and of the resident sets (shared pages counted in each).

``--study`` then runs ``soabench study`` on the same protocol (its N̂ sweep at its default 30 trials per point) the
same way and prints its wall time, CPU seconds (the child and its workers) and peak memory against the main run's,
and checks that the study's ``main/`` tables are the main run's byte for byte.

``--pythonpath DIR`` runs another checkout (e.g. ``git worktree add /tmp/base <commit>``) so that before and after
are measured side by side in one session; its compiled kernels are warmed first by a one-trial run (not timed).
Examples::

    python benchmarks/bench_protocol.py                       # the paper protocol, this checkout
    python benchmarks/bench_protocol.py --pythonpath /tmp/base
    python benchmarks/bench_protocol.py --trials 4 --duration 20
    python benchmarks/bench_protocol.py --study               # and the study against this main run
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

_CLI = "import sys; from soabench.cli.main import main; sys.exit(main())"
#: the command run in a child that reports its own and its (waited) workers' ru_maxrss to the file in argv[1]
_CLI_RUSAGE = (
    "import json, resource, sys\n"
    "from soabench.cli.main import main\n"
    "path = sys.argv.pop(1)\n"
    "try:\n"
    "    rc = main()\n"
    "finally:\n"
    "    ru = [resource.getrusage(w).ru_maxrss for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]\n"
    "    import soabench\n"
    "    open(path, 'w').write(json.dumps([*ru, soabench.__file__]))\n"
    "sys.exit(rc)\n"
)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--net", default="intersection")
    p.add_argument("--trials", type=int, default=100)
    p.add_argument("--duration", type=float, default=100.0)
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    p.add_argument("--pythonpath", type=Path, default=None, help="checkout to run instead of the installed soabench")
    p.add_argument("--out", type=Path, default=None, help="run folder (default: a new temporary folder)")
    p.add_argument("--study", action="store_true", help="then run `soabench study` and compare it with the run")
    return p.parse_args(argv)


def children_cpu() -> float:
    """CPU seconds (user + system) of this process's waited children and their waited children."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _tree_memory(root: int) -> tuple[int, int]:
    """Resident set and proportional set size (bytes) summed over ``root`` and its descendants, from /proc (0 where
    unreadable). The resident sets of forked workers count the pages they share with the driver once per process;
    the proportional set sizes (``smaps_rollup``) split each shared page among its processes, so their sum is the
    memory the run really holds."""
    children: dict[int, list[int]] = {}
    rss: dict[int, int] = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
            ppid, pages = int(fields[1]), int(fields[21])
        except (OSError, IndexError, ValueError):
            continue
        children.setdefault(ppid, []).append(int(d))
        rss[int(d)] = pages * os.sysconf("SC_PAGE_SIZE")
    total, pss, todo = 0, 0, [root]
    while todo:
        pid = todo.pop()
        total += rss.get(pid, 0)
        pss += _pss(pid)
        todo.extend(children.get(pid, ()))
    return total, pss


def _pss(pid: int) -> int:
    """The process's proportional set size (bytes), 0 where unreadable."""
    try:
        with open(f"/proc/{pid}/smaps_rollup") as fh:
            for line in fh:
                if line.startswith("Pss:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def run_command(cmd: list[str], env: dict, rusage_file: Path) -> tuple[float, int, int, int, int]:
    """Run ``cmd``; (wall s, largest tree RSS sum, largest tree PSS sum, ru_maxrss of the driver and of its
    largest worker) in bytes."""
    t0 = time.perf_counter()
    # run in the run folder's parent: ``python -c`` puts the working directory first on sys.path, so a child started
    # in a checkout would import that checkout's soabench whatever PYTHONPATH says
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, cwd=rusage_file.parent)
    peak = [0, 0]
    done = threading.Event()

    def sample() -> None:
        while not done.wait(0.2):
            rss, pss = _tree_memory(proc.pid)
            peak[0], peak[1] = max(peak[0], rss), max(peak[1], pss)

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    rc = proc.wait()
    wall = time.perf_counter() - t0
    done.set()
    th.join()
    if rc != 0:
        raise SystemExit(f"{' '.join(cmd)} failed with exit code {rc}")
    driver, worker, package = json.loads(rusage_file.read_text())
    print(f"the command imported soabench from {Path(package).parent}", file=sys.stderr)
    return wall, peak[0], peak[1], driver * 1024, worker * 1024


def summarise(
    run_dir: Path, wall_cmd: float, peak_tree: int, peak_pss: int, maxrss_driver: int, maxrss_worker: int
) -> dict:
    """The numbers of one finished run folder (timing.csv, the session record) and the measured wall and memory."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from soabench.experiment.runs.files import read_csv

    tm = read_csv(run_dir / "timing.csv")
    first = np.unique(tm["trial"], return_index=True)[1]
    sessions = [json.loads(p.read_text()) for p in sorted((run_dir / "sessions").glob("*.json"))]
    workers = max(int(s.get("n_workers", 1)) for s in sessions)
    wall_trials = sum(float(s["wall_s"]) for s in sessions)
    sumo = float(np.nansum(tm["t_sumo"][first]))
    sensor = float(np.nansum(tm["t_sensor"][first]))
    filters = float(np.nansum(tm["t_filter_total"]))
    births = float(np.nansum(tm["t_birth"]))
    metrics = float(np.nansum(tm["t_metrics"]))
    floor = sumo / workers
    return {
        "trials": int(len(first)),
        "workers": workers,
        "sumo_s": sumo,
        "floor_s": floor,
        "trials_wall_s": wall_trials,
        "command_wall_s": wall_cmd,
        "trials_ratio": wall_trials / floor,
        "command_ratio": wall_cmd / floor,
        "sensor_s": sensor,
        "filters_s": filters,
        "births_s": births,
        "metrics_s": metrics,
        "rest_s": wall_trials * workers - (sumo + sensor + filters + metrics),
        "peak_tree_mb": peak_tree / 2**20,
        "peak_tree_pss_mb": peak_pss / 2**20,
        "maxrss_driver_mb": maxrss_driver / 2**20,
        "maxrss_worker_mb": maxrss_worker / 2**20,
    }


def report(s: dict) -> str:
    return "\n".join(
        [
            f"{s['trials']} trials on {s['workers']} worker(s): SUMO {s['sumo_s']:.1f} CPU-s -> floor "
            f"{s['floor_s']:.1f} s",
            f"trials phase  {s['trials_wall_s']:7.1f} s  = {s['trials_ratio']:.2f}x the floor",
            f"whole command {s['command_wall_s']:7.1f} s  = {s['command_ratio']:.2f}x the floor",
            f"CPU-s inside trials: SUMO {s['sumo_s']:.1f}, sensor {s['sensor_s']:.1f}, filters {s['filters_s']:.1f} "
            f"(births {s['births_s']:.1f}), metrics {s['metrics_s']:.1f}; rest of workers x trials wall "
            f"{s['rest_s']:.1f} (worker start-up, rows, transport, idle)",
            f"peak memory of the process tree (sampled every 0.2 s): {s['peak_tree_pss_mb']:.0f} MB proportional set "
            f"size ({s['peak_tree_mb']:.0f} MB summing resident sets, which count pages shared with the forked "
            f"workers in each); ru_maxrss driver {s['maxrss_driver_mb']:.0f} MB, largest worker "
            f"{s['maxrss_worker_mb']:.0f} MB",
        ]
    )


def main(argv=None) -> int:
    args = parse_args(argv)
    env = dict(os.environ)
    if args.pythonpath is not None:
        env["PYTHONPATH"] = str(args.pythonpath.resolve())
        with tempfile.TemporaryDirectory(prefix="soabench-warm-") as tmp:  # compile or load its kernels (untimed)
            warm = [sys.executable, "-c", _CLI, "run", "--net", args.net, "--trials", "1", "--duration", "5"]
            subprocess.run(
                [*warm, "--workers", "1", "--no-progress", "--out", f"{tmp}/run"], env=env, check=True, cwd=tmp
            )
    out = (args.out or Path(tempfile.mkdtemp(prefix="soabench-protocol-")) / "run").resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    rusage_file = out.parent / f"{out.name}.rusage.json"
    cmd = [sys.executable, "-c", _CLI_RUSAGE, str(rusage_file), "run", "--net", args.net, "--trials", str(args.trials)]
    cmd += ["--duration", str(args.duration), "--workers", str(args.workers), "--no-progress", "--out", str(out)]
    cpu0 = children_cpu()
    wall, peak, pss, driver, worker = run_command(cmd, env, rusage_file)
    cpu_main = children_cpu() - cpu0
    s = summarise(out, wall, peak, pss, driver, worker)
    print(f"soabench from {args.pythonpath or 'this environment'}; run folder {out}")
    print(report(s))
    print(json.dumps(s))
    if not args.study:
        return 0
    study_dir = out.parent / f"{out.name}_study"
    cmd = [sys.executable, "-c", _CLI_RUSAGE, str(rusage_file), "study", "--net", args.net, "--trials"]
    cmd += [str(args.trials), "--duration", str(args.duration), "--workers", str(args.workers), "--no-progress"]
    cpu0 = children_cpu()
    wall_s, peak_s, pss_s, driver_s, worker_s = run_command([*cmd, "--out", str(study_dir)], env, rusage_file)
    cpu_study = children_cpu() - cpu0
    sessions = [json.loads(p.read_text()) for p in study_dir.rglob("sessions/*.json")]
    trials_s = sum(float(x["wall_s"]) for x in {x["started"]: x for x in sessions}.values())  # a group once
    same = all((out / f).read_bytes() == (study_dir / "main" / f).read_bytes() for f in ("trials.csv", "episodes.csv"))
    print(f"study folder {study_dir}")
    print("                 wall (s)  trials (s)  CPU (s)  peak tree PSS (MB)  tree RSS (MB)  largest process (MB)")
    for name, w, t, c, q, p, m in (
        ("main run", wall, s["trials_wall_s"], cpu_main, pss, peak, max(driver, worker)),
        ("study", wall_s, trials_s, cpu_study, pss_s, peak_s, max(driver_s, worker_s)),
    ):
        print(f"{name:15s} {w:9.1f} {t:11.1f} {c:8.1f} {q / 2**20:19.0f} {p / 2**20:14.0f} {m / 2**20:21.0f}")
    print(
        f"study / main run: wall {wall_s / wall:.2f}x (target <= 3x), trials {trials_s / s['trials_wall_s']:.2f}x, "
        f"CPU {cpu_study / cpu_main:.2f}x; the study's main/ tables equal the main run's: {same}"
    )
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
