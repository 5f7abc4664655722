"""Scaling of the Vo-Ma merge (docs/method.md §2.9): grid, 2-d tree and x-sorted window (plain script, not a test).

    python benchmarks/bench_merge_scaling.py [--quick] [--out benchmarks/figures/merge_scaling.png]

The three kernels of ``soabench/gmphd/kernels.py`` get the same mixtures, and the script checks that they return
the same groups before it times them (best of several repetitions, the three alternated, so a loaded machine inflates
all alike). ``merge_groups`` uses the window up to 96 components and the grid above. Mixtures of
J = 100 to 5000 components at constant density: ``clustered`` (blobs of about 40 components around detections, as
after an update) and ``spread`` (uniform), each plain and with 1 % wide components (position variance x 10 to 400,
like coasting or birth components), which widen the window of every pass.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from soabench.gmphd import kernels

SIZES = (100, 200, 500, 1000, 2000, 5000)
CASES = (("clustered", 0.0), ("clustered", 0.01), ("spread", 0.0), ("spread", 0.01))


def mixture(J: int, layout: str, wide: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """J components at a constant density of 0.5 per m^2 (spread) or of 40-component blobs (clustered)."""
    rng = np.random.default_rng(seed)
    side = math.sqrt(J / 0.5)
    if layout == "clustered":
        hubs = rng.uniform(0.0, 6.0 * side, (max(1, J // 40), 2))
        xy = hubs[rng.integers(0, len(hubs), J)] + rng.normal(0.0, 0.8, (J, 2))
    else:
        xy = rng.uniform(0.0, side, (J, 2))
    m = np.column_stack([xy, rng.normal(0.0, 1.0, (J, 2))])
    A = rng.normal(0.0, 0.5, (J, 4, 4))
    P = A @ np.swapaxes(A, 1, 2) + 0.3 * np.eye(4)
    n_wide = int(round(wide * J))
    if n_wide:
        idx = rng.choice(J, n_wide, replace=False)
        P[idx, :2, :2] *= rng.uniform(10.0, 400.0, n_wide)[:, None, None]
    w = 10.0 ** rng.uniform(-4.0, 0.0, J)
    return m, P, np.argsort(-w, kind="stable")


def best_of(fs, reps: int) -> list[float]:
    """Best time of each call, alternated so that a load spike on the shared machine hits all of them."""
    best = [math.inf] * len(fs)
    for _ in range(reps):
        for i, f in enumerate(fs):
            t0 = time.perf_counter()
            f()
            best[i] = min(best[i], time.perf_counter() - t0)
    return best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="sizes up to 1000 only")
    ap.add_argument("--reps", type=int, default=15, help="best-of repetitions")
    ap.add_argument("--out", default="benchmarks/figures/merge_scaling.png", help="figure path")
    args = ap.parse_args()
    sizes = [J for J in SIZES if not args.quick or J <= 1000]
    res: dict[tuple[str, float], list[tuple[int, float, float, int, float]]] = {c: [] for c in CASES}
    print("|  case               |    J | groups | window ms | tree ms | grid ms | window / grid | tree / grid |")
    print("|---------------------|------|--------|-----------|---------|---------|---------------|-------------|")
    for case in CASES:
        for J in sizes:
            m, P, order = mixture(J, *case, seed=J)
            lab_w, cen_w = kernels.merge_groups_window(m, P, order, 4.0)
            lab_t, cen_t = kernels.merge_groups_tree(m, P, order, 4.0)
            lab_g, cen_g = kernels.merge_groups_grid(m, P, order, 4.0)
            same = all(
                np.array_equal(lab_w, lab) and np.array_equal(cen_w, cen)
                for lab, cen in ((lab_t, cen_t), (lab_g, cen_g))
            )
            if not same:
                print(f"DIFFERENT GROUPS at {case}, J = {J}", file=sys.stderr)
                return 1
            t_w, t_t, t_g = best_of(
                [
                    lambda m=m, P=P, o=order: kernels.merge_groups_window(m, P, o, 4.0),
                    lambda m=m, P=P, o=order: kernels.merge_groups_tree(m, P, o, 4.0),
                    lambda m=m, P=P, o=order: kernels.merge_groups_grid(m, P, o, 4.0),
                ],
                args.reps,
            )
            res[case].append((J, t_w, t_t, len(cen_t), t_g))
            name = f"{case[0]}{', 1 % wide' if case[1] else ''}"
            print(
                f"| {name:19s} | {J:4d} | {len(cen_t):6d} | {t_w * 1e3:9.3f} | {t_t * 1e3:7.3f} | {t_g * 1e3:7.3f}"
                f" | {t_w / t_g:13.1f} | {t_t / t_g:11.1f} |"
            )
    plot(res, Path(args.out))
    print(f"\nfigure: {args.out}")
    return 0


def plot(res: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(7.2, 3.2), sharey=True, constrained_layout=True)
    for ax, layout in zip(axes, ("clustered", "spread"), strict=True):
        for (lay, wide), rows in res.items():
            if lay != layout:
                continue
            J = np.array([r[0] for r in rows], dtype=float)
            ls = "--" if wide else "-"
            tag = " (1 % wide)" if wide else ""
            ax.loglog(J, [r[1] * 1e3 for r in rows], ls, color="tab:red", marker="s", ms=4, label=f"x-window{tag}")
            ax.loglog(J, [r[2] * 1e3 for r in rows], ls, color="tab:blue", marker="o", ms=4, label=f"2-d tree{tag}")
            ax.loglog(J, [r[4] * 1e3 for r in rows], ls, color="tab:green", marker="^", ms=4, label=f"grid{tag}")
        rows = res[(layout, 0.0)]
        J = np.array([r[0] for r in rows], dtype=float)
        t0 = rows[0][4] * 1e3
        ax.loglog(J, t0 * (J * np.log(J)) / (J[0] * np.log(J[0])), ":", color="0.4", lw=1, label="∝ J log J")
        ax.loglog(J, t0 * (J / J[0]) ** 2, "-.", color="0.6", lw=1, label="∝ J²")
        ax.set_title(f"{layout} mixtures")
        ax.set_xlabel("components J before merging")
        ax.grid(True, which="major", alpha=0.3)
    axes[0].set_ylabel("merge time per call (ms)")
    axes[1].legend(fontsize=7, loc="upper left")
    fig.suptitle("Vo-Ma merge (U = 4): same groups, x-sorted window, 2-d tree and grid (best of reps)", fontsize=9)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=150)


if __name__ == "__main__":
    sys.exit(main())
