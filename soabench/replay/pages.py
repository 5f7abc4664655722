"""The pages ``soabench replay`` and ``soabench report`` write: one trial's replay (and GIF), a run's report with
the replays of its best and worst trials, or an index over a folder of runs (docs/user-guide/replay.md)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from soabench import plugins
from soabench.errors import require
from soabench.experiment.runs.ownership import check_out_file
from soabench.experiment.runs.store import RUN_FILE
from soabench.replay.frames import replay_data
from soabench.replay.gif import write_gif
from soabench.replay.page import write_replay
from soabench.replay.report import REPLAYS_DIR, extreme_trials, replay_file, write_index, write_report
from soabench.replay.simulate import read_run, replay_trial


def _replay_out(run_dir: Path, trial: int, out: str | None) -> Path:
    if out is not None:
        return check_out_file(out)
    folder = run_dir / REPLAYS_DIR
    folder.mkdir(exist_ok=True)
    return check_out_file(str(folder / replay_file(trial)))


def write_trial_replay(
    run: str | Path,
    trial: int,
    models=None,
    mode=None,
    clutter=None,
    out: str | None = None,
    gif: str | None = None,
    log: Callable[[str], None] = print,
):
    """Re-simulate and write one replay page (and a GIF if ``gif``); returns (path, size in bytes, the replay,
    seconds simulating, seconds rendering the page). A run's ``module:Class`` plugin is imported only when named in
    ``models`` (as with ``run --resume``: run.json is data)."""
    require(trial >= 0, f"--trial {trial} must be >= 0")
    plugins.allow_import_paths(models or ())
    run_dir, _, _ = read_run(run)
    gif_out = None if gif is None else check_out_file(gif)
    require(gif_out is None or gif_out.suffix.lower() == ".gif", f"--gif {gif!r} must name a .gif file")
    target = _replay_out(run_dir, trial, out)
    t0 = time.perf_counter()
    rep = replay_trial(run_dir, trial, models, mode, clutter)
    t1 = time.perf_counter()
    data = replay_data(rep)
    size = write_replay(data, target)
    t2 = time.perf_counter()
    if gif_out is not None:
        log(f"wrote {gif_out} ({write_gif(data, gif_out) / 1e6:.2f} MB)")
    return target, size, rep, t1 - t0, t2 - t1


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
            target, size, rep, _, _ = write_trial_replay(run_dir, trial, log=log)
            log(f"wrote {target} ({size / 1e6:.2f} MB; {rep.notes[-1]})")
    target, size = write_report(run_dir, out)
    log(f"wrote {target} ({size / 1e6:.2f} MB)")
