"""Replay pages: the time to draw a trial's page against the time to re-simulate the trial, and the pages' sizes.

Usage: python benchmarks/bench_replay.py [--run results/intersection/main] [--trials 3] [--browser] [--gif] [--mp4]

For each of ``--trials`` trials of the run folder (default: the committed 100-trial x 100 s main run with six birth
models): the re-simulation (:func:`soabench.replay.replay_trial`: SUMO, the sensor, every model's filter run and
its metrics) and the page (:func:`soabench.replay.replay_data` and writing the HTML) are timed in the same process,
and their ratio printed; the report page of the run folder is written to a temporary file (the run folder is not
touched) and its size printed. ``--browser`` also times headless Chromium opening the page (``--dump-dom``, the
browser's start included) and checks that the page's script ran; ``--gif`` and ``--mp4`` time writing the animated
GIF and the MP4 (the ``video`` extra).
"""

from __future__ import annotations

import argparse
import re
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from soabench.experiment.reports.html import write_report
from soabench.replay import replay_data, replay_trial, write_replay
from soabench.replay.animation import write_gif, write_mp4


def _browser_seconds(page: Path) -> float:
    exe = shutil.which("chromium")
    if exe is None:
        raise SystemExit("--browser needs chromium (apt-get install chromium)")
    with tempfile.TemporaryDirectory() as profile:
        t0 = time.perf_counter()
        argv = [exe, "--headless", "--disable-gpu", "--no-sandbox", f"--user-data-dir={profile}",
                "--virtual-time-budget=1000", "--dump-dom", f"{page.resolve().as_uri()}#frame=50"]  # fmt: skip
        dom = subprocess.run(argv, capture_output=True, text=True, timeout=300, check=True).stdout
        seconds = time.perf_counter() - t0
    status = re.search(r'<body[^>]*data-status="([^"]*)"', dom)
    if status is None or status.group(1) != "ok":
        raise SystemExit(f"the page's script did not run: {status.group(1) if status else 'no status'}")
    return seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", default="results/intersection/main", help="a finished run folder")
    ap.add_argument("--trials", type=int, default=3, help="trials 0..N-1 to replay")
    ap.add_argument("--browser", action="store_true", help="also time headless Chromium opening each page")
    ap.add_argument("--gif", action="store_true", help="also time writing each replay's animated GIF")
    ap.add_argument("--mp4", action="store_true", help="also time writing each replay's MP4")
    args = ap.parse_args()

    sims, draws, sizes, opens = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for trial in range(args.trials):
            t0 = time.perf_counter()
            rep = replay_trial(args.run, trial)
            t1 = time.perf_counter()
            page = Path(tmp) / f"trial_{trial}.html"
            size = write_replay(replay_data(rep), page)
            t2 = time.perf_counter()
            sims.append(t1 - t0)
            draws.append(t2 - t1)
            sizes.append(size)
            extra = ""
            if args.browser:
                opens.append(_browser_seconds(page))
                extra = f", browser {opens[-1]:.2f} s"
            if args.gif:
                t3 = time.perf_counter()
                gif_size = write_gif(replay_data(rep), Path(tmp) / f"trial_{trial}.gif")
                extra += f", GIF {time.perf_counter() - t3:.1f} s ({gif_size / 1e6:.2f} MB)"
            if args.mp4:
                t3 = time.perf_counter()
                mp4_size = write_mp4(replay_data(rep), Path(tmp) / f"trial_{trial}.mp4")
                extra += f", MP4 {time.perf_counter() - t3:.1f} s ({mp4_size / 1e6:.2f} MB)"
            print(f"trial {trial}: {len(rep.scans)} scans x {len(rep.models)} models; re-simulate {t1 - t0:.2f} s, "
                  f"page {t2 - t1:.2f} s (ratio {(t2 - t1) / (t1 - t0):.2f}), {size / 1e6:.2f} MB{extra}; "
                  f"{rep.notes[-1]}")  # fmt: skip
        report, report_size = write_report(args.run, Path(tmp) / "report.html")
    ratio = statistics.median(d / s for d, s in zip(draws, sims, strict=True))
    print(f"median page / re-simulation time: {ratio:.2f} (target < 2); page size median "
          f"{statistics.median(sizes) / 1e6:.2f} MB; report page {report_size / 1e6:.2f} MB")  # fmt: skip
    if opens:
        print(f"headless Chromium opens a page (start included): median {statistics.median(opens):.2f} s")


if __name__ == "__main__":
    main()
