"""A run's figures drawn in parallel (a fixed cost of every run): one task per figure on a local process pool.

A report's figures (:func:`soabench.figures.results.figure_jobs`) are independent: each is a builder called with
the run's tables and a few arguments, then written atomically (:func:`soabench.figures.style.save_png`). Inside
``with parallel(executor):`` :func:`draw_all` hands them to the executor's worker processes, one figure per task.
The tables go to the workers once per report as plain arrays in a temporary ``.npz`` file (numbers and text only,
read with ``allow_pickle=False``: data, never code; far cheaper than parsing the CSV files again at the paper's
sizes), or, should a column not be plain, each worker reads the run folder itself; either way each
worker draws the figure exactly as the serial path does, so the PNG files are byte for byte the same however many
processes draw them. :func:`draw_all` returns only once every figure is on disk (the report's ``summary.json`` is
written after it, so a report is never passed off as complete with a figure missing); a figure that fails raises.

Only an executor whose workers are local processes draws (``executor.local``: a Dask worker may not see the run
folder); without one, and for tables not read from a folder, the figures are drawn here one after another.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: the executor figures are drawn on (innermost :func:`parallel`), or None: serial
_ACTIVE: list[Any] = []


@dataclass(frozen=True)
class FigureJob:
    """One figure: ``build(tables, *args)`` returns the :class:`~matplotlib.figure.Figure` written to ``path``."""

    path: Path
    build: Callable[..., Any]
    args: tuple = ()
    #: the drawing time relative to a one-panel figure: the costliest are submitted first, so no worker is left
    #: drawing a large figure alone at the end of a report (the order of the written files does not matter)
    weight: float = 1.0

    def draw(self, tables: Any) -> Path:
        # imported when called: matplotlib would slow every start-up
        from soabench.figures.style import save_png

        return save_png(self.build(tables, *self.args), self.path)


@dataclass(frozen=True)
class FigureBatch:
    """The figures of one run folder as an executor task spec (small and picklable: the tables stay on disk)."""

    run_dir: str
    jobs: tuple[FigureJob, ...]
    #: the tables as arrays (:func:`save_arrays`), or "": read them from ``run_dir``
    arrays: str = ""
    base_seed: int = 0  #: the seed of a failure record (a figure has no trial seed of its own)

    @property
    def task_fn(self) -> Callable[[int, FigureBatch], dict]:
        return draw_task


def _stamp(run_dir: str) -> tuple:
    """The names, sizes and modification times of the folder's files: a changed table changes the stamp."""
    with os.scandir(run_dir) as it:
        return tuple(sorted((e.name, e.stat().st_size, e.stat().st_mtime_ns) for e in it if e.is_file()))


_TABLES: dict[str, tuple[tuple, Any]] = {}  # per worker process: source -> (stamp, tables)
_PARTS = ("trials", "episodes", "steps", "timing")


def save_arrays(tables: Any, path: Path) -> bool:
    """Write the tables' columns and ``run.json`` metadata to ``path`` (``.npz``, no pickled objects); False (and
    nothing written) when a column is not plain numbers or text."""
    import numpy as np

    arrays = {f"{part}/{col}": v for part in _PARTS for col, v in getattr(tables, part).items()}
    if any(v.dtype.hasobject for v in arrays.values()):
        return False
    arrays["meta"] = np.array(json.dumps(tables.meta))
    np.savez(path, **arrays)
    return True


#: tables a merge worker already saved as arrays (:mod:`soabench.experiment.reports.premerge`): resolved run folder ->
#: (:func:`~soabench.experiment.runs.store.merged_stamp` when saved, the ``.npz`` path)
_SAVED: dict[str, tuple[tuple, str]] = {}


def folder_key(run_dir: str | Path) -> str:
    """The key of a run folder in the registries of merged folders (here and
    :mod:`soabench.experiment.reports.premerge`):
    its resolved path, the same however the folder was named."""
    return str(Path(run_dir).resolve())


def remember_arrays(run_dir: str | Path, stamp: tuple, path: str) -> None:
    """Let :func:`draw_all` use ``path`` for the tables of ``run_dir`` while its merged files have ``stamp``."""
    _SAVED[folder_key(run_dir)] = (stamp, path)


def forget_arrays(run_dir: str | Path) -> None:
    _SAVED.pop(folder_key(run_dir), None)


def _saved_arrays(run_dir: Path) -> str:
    """The arrays :func:`remember_arrays` named for ``run_dir`` if its merged files are unchanged since, else ""."""
    # imported when called: scipy would slow every start-up
    from soabench.experiment.runs.store import merged_stamp

    hit = _SAVED.get(folder_key(run_dir))
    return hit[1] if hit is not None and hit[0] == merged_stamp(run_dir) else ""


def load_arrays(path: str, run_dir: str) -> Any:
    """The tables written by :func:`save_arrays` (``allow_pickle=False``: only numbers and text are read)."""
    import numpy as np

    # imported when called: scipy would slow every start-up
    from soabench.experiment.reports.tables import RunTables

    parts: dict[str, Any] = {part: {} for part in _PARTS}
    z = np.load(path, allow_pickle=False)
    meta = json.loads(str(z["meta"]))
    steps = []
    for key in z.files:
        part, _, col = key.partition("/")
        if part == "steps":
            steps.append(col)
        elif col:
            parts[part][col] = z[key]
    parts["steps"] = _NpzColumns(z, "steps/", steps)
    return RunTables(meta=meta, run_dir=Path(run_dir), **parts)


class _NpzColumns(Mapping[str, Any]):
    """The step table's columns in an open ``.npz`` file, each read on first use: a worker drawing one figure reads
    the few columns it plots, not all of a study folder's hundreds of thousands of rows (memory per worker)."""

    def __init__(self, z: Any, prefix: str, columns: list[str]) -> None:
        self._z, self._prefix, self._names = z, prefix, columns
        self._read: dict[str, Any] = {}

    def __getitem__(self, key: str) -> Any:
        if key not in self._read:
            if key not in self._names:
                raise KeyError(key)
            self._read[key] = self._z[self._prefix + key]
        return self._read[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)

    def __contains__(self, key: object) -> bool:
        return key in self._names


def _tables(batch: FigureBatch) -> Any:
    # imported when called: scipy would slow every start-up
    from soabench.experiment.reports.tables import load_tables

    source = batch.arrays or batch.run_dir
    stamp = _stamp(batch.run_dir) if not batch.arrays else ()
    hit = _TABLES.get(source)
    if hit is None or hit[0] != stamp:
        _TABLES.clear()  # one report at a time: a study's reports come folder by folder
        tables = load_arrays(batch.arrays, batch.run_dir) if batch.arrays else load_tables(Path(batch.run_dir))
        hit = _TABLES[source] = (stamp, tables)
    return hit[1]


def draw_task(i: int, batch: FigureBatch) -> dict:
    """Worker side: draw figure ``i`` of ``batch``."""
    path = batch.jobs[i].draw(_tables(batch))
    return {"status": "ok", "path": str(path)}


@contextlib.contextmanager
def parallel(executor: Any) -> Iterator[None]:
    """Draw the figures of every report written inside the block on ``executor`` when its workers are local
    processes that read this machine's files (``executor.local``) and there is more than one; anything else (Dask,
    one worker, None) draws serially."""
    usable = getattr(executor, "local", False) and executor.n_workers > 1
    _ACTIVE.append(executor if usable else None)
    try:
        yield
    finally:
        _ACTIVE.pop()


def pool_open() -> bool:
    """True inside a :func:`parallel` block: it decides where the figures of a report are drawn."""
    return bool(_ACTIVE)


def draw_all(jobs: Sequence[FigureJob], tables: Any) -> list[Path]:
    """Draw ``jobs`` (on the pool of :func:`parallel` if one is open and ``tables`` came from a run folder);
    return their paths in order once every one is written. A failed figure raises :class:`RuntimeError`."""
    exe = _ACTIVE[-1] if _ACTIVE else None
    run_dir = getattr(tables, "run_dir", None)
    if exe is None or run_dir is None or len(jobs) < 2:
        return [job.draw(tables) for job in jobs]
    order = sorted(range(len(jobs)), key=lambda i: -jobs[i].weight)  # stable: equal weights keep their order
    with tempfile.TemporaryDirectory(prefix="soabench-figures-") as tmp:
        arrays = _saved_arrays(run_dir)  # a name per folder and merge: no worker mistakes it for another's
        if not arrays:
            path = Path(tmp) / "tables.npz"  # a new name per report
            arrays = str(path) if save_arrays(tables, path) else ""
        batch = FigureBatch(str(run_dir), tuple(jobs), arrays)
        with contextlib.closing(exe.results(batch, order)) as results:  # closing cancels the rest
            for i, rec in results:
                if rec.get("status") != "ok":
                    error = f"{rec.get('error')}\n{rec.get('traceback', '')}"
                    raise RuntimeError(f"figure {jobs[i].path} failed: {error}")
    return [Path(job.path) for job in jobs]
