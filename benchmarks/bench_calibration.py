"""How many runs ``soabench check --calibrate N`` needs: the spread of its proposed bounds from one calibration to
the next, for several N, from one long series of repetitions of a suite.

Usage: python benchmarks/bench_calibration.py [--suite examples/check/suite.toml] [--runs 120] [--out DIR]

Runs the suite's scenarios ``--runs`` times on fresh seeds exactly as ``--calibrate`` does (repetition r: every seed
plus r x ``CALIBRATION_SEED_STRIDE``; so the proposal of ``--calibrate N`` is that of the first N repetitions), then
splits the series into independent calibrations of N runs (N = 3, 5, 10, 20, 40) and prints, per N, how far the
proposed bound moves between them: its standard deviation as a share of its margin (the bound's distance from the
mean, from all the runs), and how much further out it lies on average than the bound from all the runs (the t
factor of few runs). The repetitions' values are kept in ``DIR/repetitions.json`` (a second call reuses them).
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from soabench.experiment.campaigns.check import CALIBRATION_SEED_STRIDE, load_suite, propose, run_suite

SIZES = (3, 5, 10, 20, 40)


def bounds(suite, repetitions: list[dict[str, float]]) -> dict[tuple[str, str], tuple[float, float]]:
    """(key, side) -> (proposed bound, its margin) for every absolute bound of the suite."""
    out = {}
    for p in propose(suite, repetitions):
        side = p.threshold.split(" =")[0]
        if side in ("min", "max"):
            out[(p.key, side)] = (p.low, p.mean - p.low) if side == "min" else (p.high, p.high - p.mean)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", default="examples/check/suite.toml")
    ap.add_argument("--runs", type=int, default=120)
    ap.add_argument("--out", default=None, help="folder for the repetitions (default: a temporary one)")
    args = ap.parse_args()
    suite = load_suite(args.suite)
    out = Path(args.out or tempfile.mkdtemp(prefix="bench-calibration-"))
    out.mkdir(parents=True, exist_ok=True)
    store = out / "repetitions.json"
    reps: list[dict[str, float]] = json.loads(store.read_text()) if store.is_file() else []
    took = []
    for r in range(len(reps), args.runs):
        t0 = time.perf_counter()
        reps.append(run_suite(suite, out / "runs", 1, seed_offset=r * CALIBRATION_SEED_STRIDE).values)
        took.append(time.perf_counter() - t0)
        store.write_text(json.dumps(reps))
    if took:
        print(f"{len(took)} repetitions, median {statistics.median(took):.1f} s each")
    ref = bounds(suite, reps)
    print(f"{len(reps)} repetitions of {suite.name}; bounds from all of them:")
    for (key, side), (b, m) in ref.items():
        print(f"  {side} {key}: {b:.4g} (margin {m:.3g})")
    print("N  calibrations  sd(bound)/margin median [range]  further out than with all runs (median)")
    for n in SIZES:
        blocks = [reps[i : i + n] for i in range(0, len(reps) - n + 1, n)]
        if len(blocks) < 2:
            continue
        per = [bounds(suite, b) for b in blocks]
        sd, out_by = [], []
        for k, (b_all, margin) in ref.items():
            b = np.array([p[k][0] for p in per])
            sd.append(b.std(ddof=1) / margin)
            out_by.append((1 if k[1] == "max" else -1) * (b.mean() - b_all) / margin)
        print(f"{n:<3d}{len(blocks):^14d}{np.median(sd):.2f} [{min(sd):.2f}, {max(sd):.2f}]"
              f"{np.median(out_by):>28.0%}")  # fmt: skip


if __name__ == "__main__":
    main()
