"""A finished run's CSV files as columns: the data the report and the figures both read (docs/method.md §5.8).

Both :mod:`soabench.experiment.reports.report` (summary tables) and :mod:`soabench.figures.results` (figures) import
from
here, so neither imports the other's module to get at the data.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from soabench.errors import SoabenchError
from soabench.experiment.runs.files import header_of, read_csv
from soabench.experiment.runs.store import RunStore


@dataclass
class RunTables:
    """The merged CSV files of a run, as columns (numeric columns are float arrays)."""

    trials: dict[str, np.ndarray]
    episodes: dict[str, np.ndarray]
    steps: Mapping[str, np.ndarray]  #: a :class:`LazyTable` when read from a run folder
    timing: dict[str, np.ndarray]
    meta: dict
    #: the run folder the tables were read from (None for tables built in memory)
    run_dir: Path | None = None

    @property
    def models(self) -> list[str]:
        present = set(self.trials.get("model", []))
        return [m for m in tables_models(self.meta["config"]["experiment"]) if m in present]

    @property
    def modes(self) -> list[str]:
        present = set(self.trials.get("mode", []))
        return [p for p in self.meta["config"]["experiment"]["probabilities"] if p in present]

    @property
    def clutters(self) -> list[float]:
        return sorted({float(c) for c in self.trials.get("clutter", [])})


def _empty(columns: Sequence[str]) -> dict[str, np.ndarray]:
    return {c: np.array([]) for c in columns}


class LazyTable(Mapping[str, np.ndarray]):
    """A CSV file's columns (:func:`~soabench.experiment.runs.files.read_csv`), read on first use.

    steps.csv holds a row per scan of every filter run (up to hundreds of thousands of rows per run folder) and only
    the figures read it: a report written without figures never parses it.
    """

    def __init__(self, path: Path, columns: dict[str, np.ndarray] | None = None) -> None:
        self.path = path
        #: the columns, once read (or as given: what :func:`read_csv` gives the file, e.g. kept by its merge)
        self._columns: dict[str, np.ndarray] | None = columns

    @property
    def columns(self) -> dict[str, np.ndarray]:
        if self._columns is None:
            self._columns = read_csv(self.path) if self.path.is_file() else {}
        return self._columns

    def __getitem__(self, key: str) -> np.ndarray:
        return self.columns[key]

    def __contains__(self, key: object) -> bool:
        """Whether the file has column ``key``, from its header alone while the columns are not read yet (the
        figure list asks before any figure reads the table, and the figures may be drawn by other processes)."""
        if self._columns is None:
            header = header_of(self.path)
            if header is not None:
                return key in header
        return key in self.columns

    def __iter__(self) -> Iterator[str]:
        return iter(self.columns)

    def __len__(self) -> int:
        return len(self.columns)


def load_tables(run_dir: Path, steps: dict[str, np.ndarray] | None = None) -> RunTables:
    """Read a run's merged CSV files and its run.json (steps.csv when first used, :class:`LazyTable`).

    ``steps``: steps.csv's columns as :func:`read_csv` would give them, when the caller has them already
    (:meth:`RunStore.step_columns <soabench.experiment.runs.store.RunStore.step_columns>`)."""
    run_dir = Path(run_dir)
    meta = RunStore(run_dir).meta()
    path = run_dir / "trials.csv"
    if not path.is_file():
        raise SoabenchError(f"{str(run_dir)!r} has no trials.csv (the run is not finished: soabench run --resume)")
    tables: dict[str, Any] = {}
    for name in ("trials", "episodes", "timing"):
        p = run_dir / f"{name}.csv"
        tables[name] = read_csv(p) if p.is_file() else _empty(())
    tables["steps"] = LazyTable(run_dir / "steps.csv", steps)
    return RunTables(meta=meta, run_dir=run_dir, **tables)


def select(table: dict[str, np.ndarray], **where: Any) -> np.ndarray:
    """Boolean mask of the rows where every ``column == value``."""
    n = len(next(iter(table.values()))) if table else 0
    mask = np.ones(n, dtype=bool)
    for col, val in where.items():
        if col not in table:
            return np.zeros(n, dtype=bool)
        mask &= table[col] == val
    return mask


def tables_models(exp: dict) -> list[str]:
    """Every model and tracker a run's experiment section names, in order (birth models, then trackers)."""
    return [*exp["models"], *exp.get("trackers", ())]
