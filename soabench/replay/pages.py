"""The pages ``soabench replay`` and ``soabench report`` write: one trial's replay (page or video), a run's report with
the replays of its best and worst trials, or an index over a folder of runs (docs/user-guide/replay.md)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from soabench import plugins
from soabench.config import FILTER_FAMILIES
from soabench.errors import require
from soabench.experiment.reports.html import REPLAYS_DIR, extreme_trials, replay_file, write_index, write_report
from soabench.experiment.runs.store import RUN_FILE
from soabench.folders import check_out_file
from soabench.kernel_warmup import ensure_compiled
from soabench.replay.animation import VIDEO_SUFFIXES, require_mp4, write_video
from soabench.replay.frames import replay_data
from soabench.replay.page import write_replay
from soabench.replay.simulate import read_run, replay_trial

PAGE_SUFFIXES = (".html", ".htm")


def _replay_outs(run_dir: Path, trial: int, outs: list[str] | None, family: str | None = None) -> list[Path]:
    """The files to write, each ending in a format we write (checked before any simulation); the default page of a
    family other than the default one is named after it."""
    if not outs:
        folder = run_dir / REPLAYS_DIR
        folder.mkdir(exist_ok=True)
        name = replay_file(trial)
        if family not in (None, FILTER_FAMILIES[0]):
            name = name.replace(".html", f"_{family}.html")
        return [check_out_file(str(folder / name))]
    paths = []
    allowed = (*PAGE_SUFFIXES, *VIDEO_SUFFIXES)
    for out in outs:
        path = check_out_file(out)
        suffix = path.suffix.lower()
        require(
            suffix in allowed, f"--out {out!r} must end in one of {', '.join(allowed)}: the format it is written in"
        )
        if suffix == ".mp4":
            require_mp4()
        paths.append(path)
    return paths


def write_trial_replay(
    run: str | Path,
    trial: int,
    models=None,
    mode=None,
    clutter=None,
    outs: list[str] | None = None,
    family: str | None = None,
):
    """Re-simulate a trial and write each of ``outs`` (default: its page under ``RUN/replays/``); returns (the
    paths and sizes in bytes written, the replay, seconds simulating, seconds writing). A run's ``module:Class``
    plugin is imported only when named in ``models`` (as with ``run --resume``: run.json is data)."""
    require(trial >= 0, f"--trial {trial} must be >= 0")
    plugins.allow_import_paths(models or ())
    run_dir, _, _ = read_run(run)
    targets = _replay_outs(run_dir, trial, outs, family)
    ensure_compiled()  # announced as a run announces it, with its progress lines
    t0 = time.perf_counter()
    rep = replay_trial(run_dir, trial, models, mode, clutter, family)
    t1 = time.perf_counter()
    data = replay_data(rep)
    written = []
    for target in targets:
        write = write_replay if target.suffix.lower() in PAGE_SUFFIXES else write_video
        written.append((target, write(data, target)))
    return written, rep, t1 - t0, time.perf_counter() - t1


def write_pages(run: str | Path, out: str | None = None, replays: bool = False, log: Callable[[str], None] = print):
    """A run folder's ``report.html`` (with ``replays``, first the replay pages of each model's best and worst
    trial); for a folder of runs (a study, results/), each run's report and an ``index.html`` linking them."""
    if not (Path(run) / RUN_FILE).is_file() and Path(run).is_dir():  # a study or results/ folder
        require(out is None, "--out names one run's page; a folder of runs gets index.html and one report each")
        require(not replays, "--replays works on one run folder; give a run folder")
        target, size, runs = write_index(run)
        log(f"wrote {len(runs)} run reports and {target} ({size / 1e6:.2f} MB)")
        return
    run_dir, _, _ = read_run(run)
    if replays:
        trials = sorted({r[w][1] for r in extreme_trials(run_dir) for w in ("best", "worst")})
        for trial in trials:
            ((target, size),), rep, _, _ = write_trial_replay(run_dir, trial)
            log(f"wrote {target} ({size / 1e6:.2f} MB; {rep.notes[-1]})")
    target, size = write_report(run_dir, out)
    log(f"wrote {target} ({size / 1e6:.2f} MB)")
