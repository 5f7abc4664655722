"""The atlas at scale (docs/user-guide/atlas.md), measured in one run:

1. **Throughput per core** of real trials: an atlas (parking density x clutter, 60 s, three birth models, static)
   against the plain protocol doing the same work (one `run` per parking density with the three clutter rates, which
   shares SUMO and the scans the same way), on the same executor; ratio = atlas point-trials per core-second /
   plain point-trials per core-second.
2. **Peak memory** of an atlas of N1 and N2 trials (default 1,000 and 10,000), each in a fresh process on one core,
   with a synthetic trial kind that returns rows of the real schema (``soabench.experiment.runs.store`` columns,
   three models, episodes) instantly, so the measurement is the atlas's own pipeline (plan, tasks, chunks, report)
   and not SUMO.
3. **DuckDB** over the whole dataset: a GROUP BY over the N2-trial atlas, and over a generated dataset of 10^6 trial
   rows (what 10^5 trials x 10 models give), best of 3.

    python benchmarks/bench_atlas.py --trials 4 --mem 1000,10000 --rows 1000000 --workers 2
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MODELS = ("soa", "pubm", "ubm")
QUERY = "SELECT point, model, avg(delay_mean) AS delay, avg(ospa) AS ospa, count(*) AS n FROM trials GROUP BY ALL"


def peak_mb() -> float:
    """This process's peak resident memory (MB): Linux's VmHWM, which starts afresh at exec (``ru_maxrss`` keeps the
    peak of the process that forked it, here the throughput measurement's)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


# ------------------------------------------------------------------------------------------------ synthetic trial
def synthetic_trial(trial, config, scene, scenario, *, save_estimates=False):
    """Rows of the real schema with numbers from the seeds, for the memory measurement (no SUMO, no filter)."""
    import numpy as np

    from soabench.experiment.runs.store import EPISODE_COLUMNS, TIMING_COLUMNS, TRIAL_COLUMNS
    from soabench.experiment.trial.trial import TrialResult

    exp = config.experiment
    rng = np.random.default_rng([exp.seed, trial, int(1000 * config.sensor.p_D)])
    out = TrialResult(trial, exp.seed, int(rng.integers(2**31)))
    for m in exp.models:
        for lam in exp.clutter:
            row = {c: float(rng.random()) for c in TRIAL_COLUMNS + TIMING_COLUMNS}
            row.update(trial=trial, seed=exp.seed, sumo_seed=out.sumo_seed, clutter=float(lam), model=m, mode="static")
            out.rows.append(row)
            for t in range(10):
                ep = {c: float(rng.random()) for c in EPISODE_COLUMNS}
                ep.update(trial=trial, clutter=float(lam), model=m, mode="static", target=t, censored=0)
                out.episodes.append(ep)
    return out


def synthetic_load(net, polys=(), scenario=None):
    return "scene", None


def _register() -> None:
    from soabench.experiment.trial import registry

    if "bench-synthetic" not in registry.trial_kinds():
        registry.register_trial_kind("bench-synthetic", synthetic_trial)
        registry.register_scene_loader("bench-none", synthetic_load)


def memory_child(n_trials: int, out: Path) -> None:
    """Run an atlas of ``n_trials`` synthetic trials in this process; print its peak RSS (MB) and times as JSON."""
    from soabench.config import Config
    from soabench.experiment.campaigns.atlas.design import make_design, parse_axis
    from soabench.experiment.campaigns.atlas.run import AtlasRequest, run_atlas
    from soabench.experiment.execution.options import RunOptions

    _register()
    from soabench.experiment.trial.trial import TrialResult  # noqa: F401 - its imports, before the peak

    import_mb = peak_mb()  # what the imports take
    points = 10
    cfg = Config()
    cfg.experiment = dataclasses.replace(
        cfg.experiment, trials=n_trials // points, duration=60.0, models=MODELS, probabilities=("static",)
    )
    design = make_design([parse_axis("sensor.p_D=" + ",".join(f"{0.5 + 0.05 * i:.2f}" for i in range(points)))])
    req = AtlasRequest(
        out=out, design=design, config=cfg.validate(), force=True, trial_kind="bench-synthetic",
        scene_loader="bench-none",
    )  # fmt: skip
    req.report = False
    t0 = time.perf_counter()
    o = run_atlas(req, RunOptions(workers=1, progress=False), log=lambda m: None)
    wall = time.perf_counter() - t0
    peak = peak_mb()  # the trials, their chunks, the compaction
    files = {t: len(list((out / t).iterdir())) for t in ("trials", "episodes")}
    print(json.dumps({"trials": o.n_done, "complete": o.complete, "wall_s": wall, "peak_mb": peak, "files": files,
                      "import_mb": import_mb}))  # fmt: skip


def report_child(out: Path) -> None:
    """Draw the report of the atlas in ``out`` in this process; print its peak RSS (MB) and time as JSON."""
    from soabench.experiment.campaigns.atlas.report import write_report

    import_mb = peak_mb()
    t0 = time.perf_counter()
    write_report(out)
    report_s = time.perf_counter() - t0
    peak = peak_mb()  # DuckDB's scans, the statistics, the figures
    print(json.dumps({"report_s": report_s, "report_peak_mb": peak, "report_import_mb": import_mb}))


# ------------------------------------------------------------------------------------------------ measurements
def throughput(trials: int, workers: int, tmp: Path) -> dict:
    from soabench.config import Config
    from soabench.experiment.campaigns.atlas.design import make_design, parse_axis
    from soabench.experiment.campaigns.atlas.run import AtlasRequest, run_atlas
    from soabench.experiment.campaigns.occlusion import base_scenario, dump_toml
    from soabench.experiment.execution.options import RunOptions
    from soabench.experiment.reports.finished import run_experiment
    from soabench.kernel_warmup import ensure_compiled

    ensure_compiled()
    densities, clutter = (0.0, 8.0), (0.5, 3.0, 5.0)
    cfg = Config()
    cfg.experiment = dataclasses.replace(
        cfg.experiment, trials=trials, duration=60.0, models=MODELS, probabilities=("static",), clutter=clutter
    )
    cfg.validate()
    opts = RunOptions(workers=workers, progress=False, figures=False)
    # the plain protocol: one run per parking density, its clutter rates sharing SUMO and the scans
    t0 = time.perf_counter()
    for d in densities:
        data = {k: dict(v) for k, v in base_scenario("intersection", None).items()}
        data.setdefault("parking", {})["density"] = d
        scen = tmp / f"plain_{d:g}.scenario.toml"
        scen.write_text(dump_toml(data))
        run_experiment(cfg, "intersection", (), str(scen), out=tmp / f"plain_{d:g}", options=opts)
    plain = time.perf_counter() - t0
    design = make_design([parse_axis("parking.density=0,8"), parse_axis("experiment.clutter=0.5,3,5")])
    one = Config.from_dict(cfg.to_dict())
    one.experiment = dataclasses.replace(one.experiment, clutter=(3.0,))
    t0 = time.perf_counter()
    o = run_atlas(
        AtlasRequest(out=tmp / "atlas", design=design, config=one.validate(), report=False), opts, log=lambda m: None
    )
    atlas = time.perf_counter() - t0
    n = len(densities) * len(clutter) * trials
    assert o.complete and o.n_done == n
    return {
        "point_trials": n,
        "workers": workers,
        "plain_s": plain,
        "atlas_s": atlas,
        "plain_per_core_s": n / (plain * workers),
        "atlas_per_core_s": n / (atlas * workers),
        "ratio": plain / atlas,
        "shared": o.shared,
    }


def memory(sizes: list[int], tmp: Path) -> list[dict]:
    out = []
    for n in sizes:
        folder = tmp / f"mem_{n}"
        env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
        row = {"folder": str(folder)}
        for child in (["--memory-child", str(n)], ["--report-child"]):  # each in a fresh process
            res = subprocess.run(
                [sys.executable, __file__, *child, "--out", str(folder)],
                capture_output=True, text=True, env=env, check=True,
            )  # fmt: skip
            row.update(json.loads(res.stdout.strip().splitlines()[-1]))
        out.append(row)
    return out


def duckdb_times(atlas: Path, rows: int, tmp: Path) -> dict:
    """The GROUP BY over the (compacted) synthetic atlas, over the committed intersection atlas as chunks and
    compacted (a copy), and over ``rows`` generated trial rows as 100 chunk files and compacted."""
    import numpy as np

    from soabench.experiment.campaigns.atlas.compact import compact
    from soabench.experiment.campaigns.atlas.query import connect, run_query
    from soabench.experiment.campaigns.atlas.store import parquet_bytes
    from soabench.experiment.runs.store import TIMING_COLUMNS, TRIAL_COLUMNS

    def best(path: Path) -> tuple[float, int]:
        times, n = [], 0
        for _ in range(3):
            t0 = time.perf_counter()
            n = run_query(path, QUERY).num_rows
            times.append(time.perf_counter() - t0)
        return min(times), n

    def n_rows(path: Path) -> int:
        con = connect(path, only=["trials"])
        try:
            return int(con.execute("SELECT count(*) FROM trials").fetchone()[0])
        finally:
            con.close()

    def n_files(path: Path) -> int:
        return len(list((path / "trials").glob("*.parquet")))

    def timed_compact(path: Path) -> float:
        t0 = time.perf_counter()
        compact(path)
        return time.perf_counter() - t0

    out: dict = {"atlas_rows": n_rows(atlas), "atlas_files": n_files(atlas)}
    out["atlas_query_s"], _ = best(atlas)
    committed = ROOT / "results" / "atlas" / "intersection"
    if (committed / "atlas.json").is_file():
        copy = tmp / "committed"
        shutil.copytree(committed, copy, ignore=shutil.ignore_patterns("report"))
        out.update(committed_rows=n_rows(copy), committed_files=n_files(copy))
        out["committed_query_s"], _ = best(copy)
        out["committed_compact_s"] = timed_compact(copy)
        out["committed_compacted_files"] = n_files(copy)
        out["committed_compacted_query_s"], _ = best(copy)
        shutil.rmtree(copy)
    # a generated dataset of `rows` trial rows: 100 chunks, 10 models, 1000 points
    gen = tmp / "generated"
    shutil.copytree(atlas, gen, ignore=shutil.ignore_patterns("trials", "episodes", "report"))
    (gen / "trials").mkdir()
    rng = np.random.default_rng(0)
    per = rows // 100
    models = [f"m{i}" for i in range(10)]
    for c in range(100):
        cols = {"point": (rng.integers(0, 1000, per)).tolist(), "scene": [0] * per, "sensor_p_D": [0.9] * per}
        cols["family"] = ["gmphd"] * per
        for name in TRIAL_COLUMNS + TIMING_COLUMNS:
            if name == "model":
                cols[name] = [models[i % 10] for i in range(per)]
            elif name == "mode":
                cols[name] = ["static"] * per
            else:
                cols[name] = rng.random(per).tolist()
        (gen / "trials" / f"n{c:05d}-s0000.parquet").write_bytes(parquet_bytes(cols))
    out["generated_rows"], out["generated_files"] = per * 100, n_files(gen)
    out["generated_mb"] = sum(f.stat().st_size for f in (gen / "trials").iterdir()) / 2**20
    out["generated_query_s"], out["generated_groups"] = best(gen)
    out["generated_compact_s"] = timed_compact(gen)
    out["generated_compacted_files"] = n_files(gen)
    out["generated_compacted_query_s"], _ = best(gen)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=4, help="trials per point of the throughput measurement")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--mem", default="1000,10000", help="trials of the two memory measurements")
    ap.add_argument("--rows", type=int, default=1_000_000, help="rows of the generated DuckDB dataset (0: none)")
    ap.add_argument("--skip-throughput", action="store_true")
    ap.add_argument("--memory-child", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--report-child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.memory_child:
        memory_child(args.memory_child, args.out)
        return
    if args.report_child:
        report_child(args.out)
        return
    tmp = Path(tempfile.mkdtemp(prefix="bench-atlas-"))
    try:
        report = {}
        if not args.skip_throughput:
            report["throughput"] = throughput(args.trials, args.workers, tmp)
            print(json.dumps(report["throughput"]), flush=True)
        report["memory"] = memory([int(s) for s in args.mem.split(",")], tmp)
        print(json.dumps(report["memory"]), flush=True)
        if args.rows:
            report["duckdb"] = duckdb_times(Path(report["memory"][-1]["folder"]), args.rows, tmp)
            print(json.dumps(report["duckdb"]), flush=True)
        if "throughput" in report:
            t = report["throughput"]
            print(
                f"throughput: atlas {t['atlas_per_core_s']:.3f} vs plain {t['plain_per_core_s']:.3f} point-trials per "
                f"core-second ({t['point_trials']} point-trials, {t['workers']} workers): ratio {t['ratio']:.2f}"
            )
        for m in report["memory"]:
            print(
                f"memory: {m['trials']} trials ({m['files']['trials']} trials file(s) after compaction): run and "
                f"compaction peak {m['peak_mb']:.0f} MB ({m['wall_s']:.1f} s), report peak {m['report_peak_mb']:.0f} "
                f"MB ({m['report_s']:.1f} s); imports alone {m['import_mb']:.0f} and {m['report_import_mb']:.0f} MB"
            )
        d = report.get("duckdb")
        if d:
            print(f"duckdb: synthetic atlas, {d['atlas_rows']} rows in {d['atlas_files']} file(s): "
                  f"{d['atlas_query_s'] * 1000:.0f} ms")  # fmt: skip
            if "committed_rows" in d:
                print(
                    f"duckdb: committed atlas, {d['committed_rows']} rows: {d['committed_files']} chunk files "
                    f"{d['committed_query_s'] * 1000:.0f} ms; compacted ({d['committed_compact_s']:.1f} s) into "
                    f"{d['committed_compacted_files']} file(s) {d['committed_compacted_query_s'] * 1000:.0f} ms"
                )
            print(
                f"duckdb: generated, {d['generated_rows']} rows ({d['generated_mb']:.0f} MB): {d['generated_files']} "
                f"chunk files {d['generated_query_s'] * 1000:.0f} ms; compacted ({d['generated_compact_s']:.1f} s) "
                f"into {d['generated_compacted_files']} file(s) {d['generated_compacted_query_s'] * 1000:.0f} ms"
            )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
