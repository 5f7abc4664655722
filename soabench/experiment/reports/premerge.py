"""The merges of several finished run folders at once, on the workers of a process pool (the report
phase of ``soabench study``), and the merge a finished run's report starts with (:func:`merge`).

A study ends with about twenty finished folders (main run, clutter points, N̂ points, sensitivity runs). Each one's
report starts with :meth:`~soabench.experiment.runs.store.RunStore.merge` (every trial record read, the step rows
formatted as CSV lines) and, for a folder with figures, hands its tables to the figure workers as arrays
(:func:`~soabench.figures.drawing.save_arrays`). Done in the driver one folder after another, that left the
pool's workers idle for a quarter of the study's wall time.

Inside ``with merged_on(pool, runs):`` every folder of ``runs`` whose trials are all on disk is handed to a worker,
largest first: the worker merges it and saves its tables as arrays. The reports are written as before, each
waiting only for its own folder's merge (so one report's figures are drawn while later folders merge);
:func:`merge` adopts a worker's merge when the folder is as the worker left it (the same finished trials, the same
merged files, by size and modification time), and :func:`~soabench.figures.drawing.draw_all` takes the saved
arrays under the same condition. Anything else (a changed folder, a failed merge task, no process pool) is merged
in the driver as before. A worker runs the driver's code on the same records, so the files are the same byte for
byte.
"""

from __future__ import annotations

import contextlib
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from soabench.experiment.execution.executors import PoolExecutor
from soabench.experiment.reports.tables import load_tables
from soabench.experiment.runs.store import RunStore, merge_args, merged_stamp
from soabench.figures import drawing  # save_arrays by attribute: a test may stand in for it
from soabench.figures.drawing import folder_key, forget_arrays, remember_arrays


@dataclass(frozen=True)
class Merged:
    """A worker's merge of one folder: what it found and wrote."""

    stamp: tuple
    done: tuple[int, ...]
    failures: tuple[dict, ...]
    counts: dict


#: the folders merged by workers in the open :func:`merged_on` block: resolved path -> :class:`Merged`
_MERGED: dict[str, Merged] = {}


@dataclass(frozen=True)
class MergeBatch:
    """The folders to merge as an executor task spec: (run folder, models, modes, whether it draws figures) each,
    and where the tables of those with figures go."""

    folders: tuple[tuple[str, tuple[str, ...], tuple[str, ...], bool], ...]
    tmp: str
    base_seed: int = 0  #: the seed of a failure record (a folder merge has no trial seed of its own)

    @property
    def task_fn(self) -> Any:
        return merge_task


def merge_task(i: int, batch: MergeBatch) -> dict:
    """Worker side: merge folder ``i`` of ``batch``; if it draws figures, save its tables as arrays
    (``<tmp>/<i>.npz``; the step table's columns as the merge kept them, not parsed back from steps.csv)."""

    run_dir, models, modes, figures = batch.folders[i]
    store = RunStore(Path(run_dir))
    done = tuple(store.done_trials())
    counts = store.merge(models, modes, step_columns=figures)
    failures = store.model_failures()
    arrays = Path(batch.tmp) / f"{i}.npz"
    saved = figures and drawing.save_arrays(load_tables(Path(run_dir), steps=store.step_columns()), arrays)
    return {
        "status": "ok",
        "done": list(done),
        "failures": failures,
        "counts": counts,
        "stamp": merged_stamp(run_dir),
        "arrays": str(arrays) if saved else "",
    }


class _Pending:
    """The merge tasks of an open :func:`merged_on` block, collected as the reports ask for their folders."""

    def __init__(self, results: Iterator[tuple[int, dict]], folders: Sequence[tuple]) -> None:
        self.results = results
        self.folders = folders
        self.waiting = {folder_key(f[0]) for f in folders}

    def wait_for(self, key: str) -> None:
        """Collect finished merges until the one of folder ``key`` is in (or failed); no-op for another folder."""
        while key in self.waiting:
            try:
                i, rec = next(self.results)
            except StopIteration:
                self.waiting.clear()
                return
            run_dir = self.folders[i][0]
            done = folder_key(run_dir)
            self.waiting.discard(done)
            if rec.get("status") != "ok":
                continue  # the report merges this folder itself (and says what is wrong with it)
            stamp = tuple(rec["stamp"])
            _MERGED[done] = Merged(stamp, tuple(rec["done"]), tuple(rec["failures"]), dict(rec["counts"]))
            if rec["arrays"]:
                remember_arrays(run_dir, stamp, rec["arrays"])


#: the open :func:`merged_on` blocks, innermost last
_PENDING: list[_Pending] = []


@contextlib.contextmanager
def merged_on(executor: Any, runs: Sequence[Any]) -> Iterator[None]:
    """Merge every complete folder of ``runs`` (:class:`~soabench.experiment.execution.runner.DeferredRun`) on
    ``executor``'s
    workers while the block writes the reports; a no-op unless ``executor`` is a local process pool with more than
    one worker.

    The merges are submitted as the pool takes them (two per worker in flight) and collected when a report asks
    for its folder (:func:`merge` waits for that one), so a report's figures are drawn while the other folders are
    still being merged. Merges not collected by the end of the block are cancelled, and the saved arrays deleted.
    """
    ready = [r for r in runs if len(r.store.done_trials()) == r.n_trials > 0]
    if not (isinstance(executor, PoolExecutor) and executor.n_workers > 1 and len(ready) > 1):
        yield
        return
    with tempfile.TemporaryDirectory(prefix="soabench-merge-") as tmp:
        folders = tuple((str(r.store.run_dir), *merge_args(r.config), bool(r.figures)) for r in ready)
        batch = MergeBatch(folders, tmp)
        size = [
            r.n_trials * len(f[1]) * len(f[2]) * len(r.config.experiment.clutter)
            for r, f in zip(ready, folders, strict=True)
        ]
        order = sorted(range(len(folders)), key=lambda i: -size[i])  # the largest first: no long tail on one worker
        pending = _Pending(executor.results(batch, order), folders)
        _PENDING.append(pending)
        try:
            yield
        finally:
            _PENDING.remove(pending)
            pending.results.close()  # cancels the merges not started (a running one finishes its folder's files)
            for run_dir, *_ in folders:
                _MERGED.pop(folder_key(run_dir), None)
                forget_arrays(run_dir)


def merge(store: RunStore, models: Sequence[str], modes: Sequence[str], step_columns: bool = False) -> dict[str, int]:
    """:meth:`RunStore.merge <soabench.experiment.runs.store.RunStore.merge>` (``step_columns``: keep steps.csv's
    columns
    for the report's figures), or the merge a worker of :func:`merged_on` did of this folder if the folder is as it
    left it (used once)."""
    key = folder_key(store.run_dir)
    for pending in _PENDING:
        pending.wait_for(key)
    hit = _MERGED.pop(key, None)
    if hit is not None and hit.stamp == merged_stamp(store.run_dir) and hit.done == tuple(store.done_trials()):
        store.adopt_merge(hit.done, hit.failures)
        return dict(hit.counts)
    return store.merge(models, modes, step_columns)
