"""The run folder on disk: append-only, atomic per-trial records, merged into CSV files at the end.

Layout of a run folder (``results/<net>/<UTC timestamp>/``)::

    run.json                 written once at start: resolved config (Config.to_dict()), net, polys, scenario,
                             trial count, save_estimates, trial kind and scene loader (registered names, never
                             import paths: :mod:`soabench.experiment.trial.registry`), package versions, and the
                             run's identity ``run_id`` (:func:`run_identity`)
    .lock                    while a process works the folder (:mod:`soabench.folders`)
    trials/trial_00042.json  one record per finished trial (status "ok"): its trial index and ``run_id``, rows,
                             episodes, steps, timing
    failed/trial_00042.json  one record per failed trial: seed, sumo_seed, error, traceback (retried by --resume)
    estimates/trial_00042.json.gz   with --save-estimates: gzipped JSON {"trial": n, "estimates": [...]}, the
                             trial's ``TrialResult.estimates``: one object per extracted estimate (with
                             multiplicity) with keys trial, clutter, model, mode, k (scan), x, y (m), w (weight)
    sessions/session_*.json  wall time, executor and versions of each (resumed) session
    rejected/                records a resume found in trials/ or failed/ that are not that trial of this run
                             (:meth:`RunStore.reject_foreign_records`), moved aside; their trials run again
    trials.csv episodes.csv steps.csv timing.csv   merged, written only once every trial was attempted
    summary.json summary.md figures/*.png           written by :mod:`soabench.experiment.reports.report`

Why one file per trial: each record is written to a temporary file in the same folder, flushed, fsynced and moved
into place with ``os.replace`` (atomic on POSIX), so a record is either absent or whole (every file of the folder
is written and read by :mod:`soabench.experiment.runs.files`). A Ctrl-C, a killed driver or a lost worker loses at most
the trials in flight; ``--resume`` runs exactly the trials without an "ok" record. Appending CSV lines would need
a commit marker and a torn-line repair on restart; separate files do not.

Determinism: records store floats through ``json`` (``float.__repr__``, exact round trip) and the CSVs write
``repr`` of every float, rows sorted by (trial, clutter, model, mode[, target/k]) in the config's order. Wall-clock
columns (``t_*`` and the per-trial SUMO/sensor seconds) go to ``timing.csv`` so that ``trials.csv``,
``episodes.csv`` and ``steps.csv`` are bit-identical for the same seed on any executor (docs/method.md §6 T28).
"""

from __future__ import annotations

import gzip
import hashlib
import json
import os
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from soabench.atomic import to_jsonable, write_bytes_atomic, write_json_atomic
from soabench.errors import BadValue, SoabenchError
from soabench.experiment.runs.files import (
    ReadBack,
    csv_line,
    gc_paused,
    read_json,
    unpack_table,
    write_csv,
    write_lines,
)
from soabench.experiment.trial.trial import (
    EPISODE_KEYS,
    FILTER_COLUMN,
    ROW_ID_KEYS,
    ROW_KEYS,
    ROW_TIME_KEYS,
    STEP_KEYS,
    TIMING_KEYS,
)

RUN_FILE = "run.json"
TRIALS_DIR = "trials"
FAILED_DIR = "failed"
ESTIMATES_DIR = "estimates"
SESSIONS_DIR = "sessions"
REJECTED_DIR = "rejected"
FORMAT_VERSION = 1

# The schemas are those of a TrialResult (:mod:`soabench.experiment.trial.trial`), whose metric names come from
# :mod:`soabench.metrics`: one definition, here only sorted into the files they go to.
#: identifying columns of a result row, in order
KEY_COLUMNS = ROW_ID_KEYS
#: wall-clock columns of a row (seconds), written to ``timing.csv``
TIMING_COLUMNS = ROW_TIME_KEYS
#: metric columns of ``trials.csv`` (docs/method.md §5.2-5.7)
METRIC_COLUMNS = tuple(k for k in ROW_KEYS if k not in KEY_COLUMNS + TIMING_COLUMNS)
TRIAL_COLUMNS = KEY_COLUMNS + METRIC_COLUMNS
EPISODE_COLUMNS = EPISODE_KEYS
STEP_COLUMNS = STEP_KEYS
#: per-trial stage timing (seconds) from ``TrialResult.timing``
TRIAL_TIMING_KEYS = TIMING_KEYS


# --------------------------------------------------------------------------------------------- the store
def trial_name(trial: int) -> str:
    return f"trial_{int(trial):05d}"


_RECORD_NAME = re.compile(r"^trial_(\d{5,})\.json$")


def trial_of_name(name: str) -> int | None:
    """The trial index a record's file name gives (``trial_00042.json`` -> 42); None unless :func:`trial_name`
    would write exactly that name (``trial_-0001.json``, ``trial_2.json`` and ``trial_000042.json`` give None)."""
    m = _RECORD_NAME.match(name)
    if m is None or trial_name(int(m.group(1))) != f"trial_{m.group(1)}":
        return None
    return int(m.group(1))


def run_identity(meta: dict) -> str:
    """A run's identity: SHA-256 of what decides its trials' numbers, everything in ``run.json`` that trial n's
    record depends on (configuration without the trial count, which a resume may raise; network, polygons,
    scenario; trial kind and scene loader). Every trial record carries it, so a record copied in from another run
    (other settings) or saved under another trial's name is recognised as not belonging here."""
    config = {sec: dict(values) for sec, values in (meta.get("config") or {}).items() if isinstance(values, dict)}
    config.get("experiment", {}).pop("trials", None)
    keys = ("net", "polys", "scenario", "trial_kind", "scene_loader")
    what = {"config": config, **{k: meta.get(k) for k in keys}}
    text = json.dumps(what, sort_keys=True, allow_nan=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def merge_args(config: Any) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The (models, modes) a run folder of ``config`` is merged with: its birth models then trackers, its modes."""
    exp = config.experiment
    return (*exp.models, *exp.trackers), tuple(exp.probabilities)


class RunStore:
    """Reads and writes one run folder (layout in the module docstring)."""

    def __init__(self, run_dir: Path):
        self.run_dir = Path(run_dir)
        #: (the merged files' stamp, steps.csv's columns) kept by the last ``merge(..., step_columns=True)``
        self._merged_steps: tuple[tuple, dict[str, np.ndarray]] | None = None
        #: (the finished trials, their model failures) as the last :meth:`merge` read them
        self._merged_failures: tuple[tuple[int, ...], list[dict]] | None = None
        #: run.json's ``run_id`` once read ("" for a folder written before records carried one)
        self._run_id: str | None = None

    # -- run metadata
    @property
    def run_file(self) -> Path:
        return self.run_dir / RUN_FILE

    def exists(self) -> bool:
        return self.run_file.is_file()

    def create(self, meta: dict) -> None:
        """Start a new run folder; refuses a folder that already holds a run."""
        if self.exists():
            raise BadValue(
                "out",
                str(self.run_dir),
                f"already holds a run; finish it with soabench run --resume {self.run_dir}, or give another folder",
            )
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self._run_id = run_identity(meta)
        write_json_atomic(self.run_file, {"format": FORMAT_VERSION, **meta, "run_id": self._run_id})

    def meta(self) -> dict:
        if not self.exists():
            raise SoabenchError(f"{str(self.run_dir)!r} is not a run folder (no {RUN_FILE})")
        meta = read_json(self.run_file)
        if not isinstance(meta, dict) or meta.get("format") != FORMAT_VERSION:
            raise SoabenchError(f"{str(self.run_file)!r} has an unknown format")
        return meta

    def run_id(self) -> str:
        """run.json's ``run_id`` ("" for a run folder made before trial records carried one)."""
        if self._run_id is None:
            rid = self.meta().get("run_id", "")
            if not (isinstance(rid, str) and re.fullmatch(r"[0-9a-f]{64}|", rid)):
                raise SoabenchError(f"{str(self.run_file)!r}: run_id = {rid!r} is not a run identity")
            self._run_id = rid
        return self._run_id

    # -- per-trial records
    def _record_path(self, folder: str, trial: int) -> Path:
        return self.run_dir / folder / f"{trial_name(trial)}.json"

    def record_problem(self, record: Any, trial: int, ok: bool = True, tables: bool = False) -> str | None:
        """Why ``record`` (read from the file of ``trial``) is not trial ``trial`` of this run, or None if it is:
        a JSON object whose ``trial`` is that index, whose ``run_id`` is this run's (folders whose run.json has
        none: not checked) and, for a finished trial (``ok``), whose status is "ok"; with ``tables`` (a resume, before
        it merges records it did not write) also whose packed tables the merge can sort (:func:`_table_problem`)."""
        if not isinstance(record, dict):
            return f"it holds a JSON {type(record).__name__}, not a trial record"
        held = record.get("trial")
        if type(held) is not int or held != trial:
            return f"it holds trial {held!r}"
        if ok and record.get("status") != "ok":
            return f"its status is {record.get('status')!r}, not 'ok'"
        rid = self.run_id()
        if rid and record.get("run_id") != rid:
            return "it was made by another run (other settings: its run_id differs from run.json's)"
        if not (tables and ok):
            return None
        for name, keys in _TABLE_KEYS.items():
            problem = _table_problem(record.get(name), name, trial, keys)
            if problem is not None:
                return problem
        timing, failures = record.get("timing"), record.get("model_failures")
        if timing is not None and not (
            isinstance(timing, dict) and not any(isinstance(v, (list, dict)) for v in timing.values())
        ):
            return "its timing is not a table of stage times"
        if failures is not None and not (isinstance(failures, list) and all(isinstance(f, dict) for f in failures)):
            return "its model_failures is not a list of failure records"
        return None

    def reject_foreign_records(self, n_trials: int | None = None) -> list[str]:
        """Move every file of trials/ and failed/ that is not the record its name says aside into rejected/
        (:meth:`record_problem`; also names :func:`trial_name` never writes); returns one line per file moved.
        A moved trial counts as missing, so a resume runs it again when it is one of the run's ``n_trials``."""
        lines = []
        for folder in (TRIALS_DIR, FAILED_DIR):
            d = self.run_dir / folder
            if not d.is_dir():
                continue
            for p in sorted(d.glob("trial_*.json")):
                trial = trial_of_name(p.name)
                if trial is None:
                    problem = f"{p.name!r} is not a trial record name (trial_NNNNN.json)"
                else:
                    try:
                        problem = self.record_problem(read_json(p), trial, ok=folder == TRIALS_DIR, tables=True)
                    except SoabenchError as exc:
                        problem = str(exc)
                    if problem is not None:
                        problem = f"it is not trial {trial} of this run: {problem}"
                if problem is None:
                    continue
                dest = self.run_dir / REJECTED_DIR / folder / p.name
                dest.parent.mkdir(parents=True, exist_ok=True)
                n = 1
                while dest.exists():
                    dest, n = dest.with_name(f"{p.name}.{n}"), n + 1
                os.replace(p, dest)
                if trial is None:
                    again = ""
                elif n_trials is not None and trial >= n_trials:
                    again = f"; the run has trials 0-{n_trials - 1}, so no trial {trial} runs"
                else:
                    again = f"; trial {trial} runs again"
                lines.append(f"{folder}/{p.name}: {problem}; moved to {dest.relative_to(self.run_dir)}{again}")
        self._merged_failures = None
        return lines

    def write_trial(self, record: dict) -> None:
        """Persist a finished trial (status "ok"), stamped with this run's ``run_id``, and drop an older failure
        record of it."""
        trial = int(record["trial"])
        self._merged_failures = None
        record["run_id"] = self.run_id()
        est = record.pop("estimates", None)
        if est is not None:
            payload = json.dumps(to_jsonable({"trial": trial, "estimates": est}), allow_nan=True).encode()
            write_bytes_atomic(
                self.run_dir / ESTIMATES_DIR / f"{trial_name(trial)}.json.gz", gzip.compress(payload, mtime=0)
            )
        write_json_atomic(self._record_path(TRIALS_DIR, trial), record, compact=True)
        failed = self._record_path(FAILED_DIR, trial)
        if failed.exists():
            failed.unlink()

    def write_failure(self, record: dict) -> None:
        """Persist a failed trial's record (retried by a resume), stamped with this run's ``run_id``."""
        record["run_id"] = self.run_id()
        write_json_atomic(self._record_path(FAILED_DIR, int(record["trial"])), record)

    def _trials_in(self, folder: str) -> list[int]:
        d = self.run_dir / folder
        if not d.is_dir():
            return []
        return sorted(t for t in map(trial_of_name, (p.name for p in d.glob("trial_*.json"))) if t is not None)

    def done_trials(self) -> list[int]:
        return self._trials_in(TRIALS_DIR)

    def failed_trials(self) -> list[int]:
        done = set(self.done_trials())
        return [t for t in self._trials_in(FAILED_DIR) if t not in done]

    def failures(self) -> list[dict]:
        """Failure records (trial, seed, sumo_seed, error) of trials without an ok record, by trial."""
        return [read_json(self._record_path(FAILED_DIR, t)) for t in self.failed_trials()]

    def model_failures(self) -> list[dict]:
        """Failed plugin runs inside finished trials (soabench.experiment.trial.guard.FAILURE_KEYS), by trial (as this
        store's last :meth:`merge` read them if the finished trials are still the same, else from the records)."""
        done = self.done_trials()
        if self._merged_failures is not None and self._merged_failures[0] == tuple(done):
            return [dict(f) for f in self._merged_failures[1]]
        return [f for t in done for f in self.load_trial(t).get("model_failures") or ()]

    def load_trial(self, trial: int) -> dict:
        """The record of finished trial ``trial``; :class:`SoabenchError` if the file is not that trial of this run
        (:meth:`record_problem`: a resume moves such files aside and runs the trial again)."""
        path = self._record_path(TRIALS_DIR, trial)
        record = read_json(path)
        problem = self.record_problem(record, trial)
        if problem is not None:
            raise SoabenchError(
                f"{str(path)!r} is not trial {trial} of this run ({problem}); "
                f"`soabench run --resume {self.run_dir}` moves it aside and runs the trial again"
            )
        return record

    def write_session(self, name: str, info: dict) -> None:
        """Record one session as ``sessions/session_<name>.json``; a second session of the same name (same second,
        same process: a resume right after a fast run) gets a numbered suffix instead of replacing the first."""
        d = self.run_dir / SESSIONS_DIR
        path, n = d / f"session_{name}.json", 1
        while path.exists():
            path, n = d / f"session_{name}_{n:03d}.json", n + 1  # sorts after the first
        write_json_atomic(path, info)

    def sessions(self) -> list[dict]:
        d = self.run_dir / SESSIONS_DIR
        return [read_json(p) for p in sorted(d.glob("session_*.json"))] if d.is_dir() else []

    # -- merge
    def adopt_merge(self, done: Sequence[int], failures: Sequence[dict]) -> None:
        """Take over the merge another process just did of this folder (:mod:`soabench.experiment.reports.premerge`):
        the
        finished trials it merged and the model failures it read, which :meth:`model_failures` then returns."""
        self._merged_failures = (tuple(int(t) for t in done), [dict(f) for f in failures])

    def merge(self, models: Sequence[str], modes: Sequence[str], step_columns: bool = False) -> dict[str, int]:
        """Write trials.csv, episodes.csv, steps.csv and timing.csv from the ok records; returns row counts.

        ``step_columns``: also keep steps.csv's columns as :func:`read_csv` reads them back (:meth:`step_columns`),
        taken from the values the merge formats, so that a report's figures need not parse the file again."""
        self._merged_steps = None
        with gc_paused():
            return self._merge(models, modes, step_columns)

    def _merge(self, models: Sequence[str], modes: Sequence[str], step_columns: bool) -> dict[str, int]:
        order = TableOrder(models, modes)
        key, step_key = order.row, order.step_key
        rows: list[dict] = []
        episodes: list[dict] = []
        steps = _SortedSteps(step_key, columns=step_columns)
        timing: list[dict] = []
        failures: list[dict] = []
        done = self.done_trials()
        for t in done:
            rec = self.load_trial(t)
            failures += [dict(f) for f in rec.get("model_failures") or ()]
            rrows = unpack_table(rec.get("rows"))
            rows += rrows
            episodes += unpack_table(rec.get("episodes"))
            if rec.get("steps"):
                steps.add(rec["steps"])
            timing += timing_rows(rrows, rec.get("timing") or {})
        rows.sort(key=key)
        timing.sort(key=key)
        episodes.sort(key=order.episode)
        if not steps.ok:  # records with other columns, or blocks out of key order: every row sorted at once
            tables = [rec["steps"] for rec in map(self.load_trial, done) if rec.get("steps")]
            step_cols, step_rows = _rows_of(tables, STEP_COLUMNS)
            step_rows.sort(key=step_key(step_cols))
            steps = _SortedSteps(step_key, step_cols, list(map(csv_line, step_rows)), columns=step_columns)
            if steps.columns is not None:
                steps.columns.add(step_rows)
        write_csv(
            self.run_dir / "trials.csv",
            [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows],
            TRIAL_COLUMNS,
        )
        write_csv(self.run_dir / "episodes.csv", episodes, EPISODE_COLUMNS)
        steps.write(self.run_dir / "steps.csv")
        write_csv(self.run_dir / "timing.csv", timing, TIMING_FILE_COLUMNS)
        self._merged_failures = (tuple(done), failures)
        columns = steps.columns.arrays(steps.cols or list(STEP_COLUMNS)) if steps.columns is not None else None
        if columns is not None:
            self._merged_steps = (merged_stamp(self.run_dir), columns)
        return {"trials": len(rows), "episodes": len(episodes), "steps": len(steps.lines)}

    def step_columns(self) -> dict[str, np.ndarray] | None:
        """steps.csv's columns as :func:`read_csv` gives them, kept by this store's last ``merge(...,
        step_columns=True)`` while the merged files are as it wrote them (:func:`merged_stamp`); else None."""
        hit = self._merged_steps
        return hit[1] if hit is not None and hit[0] == merged_stamp(self.run_dir) else None

    def clear_merged(self) -> None:
        """Remove merged outputs of an earlier session (they are rewritten when the run completes)."""
        for name in (
            "trials.csv",
            "episodes.csv",
            "steps.csv",
            "timing.csv",
            "model_failures.csv",
            "summary.json",
            "summary.md",
        ):
            p = self.run_dir / name
            if p.exists():
                p.unlink()


#: the files a merge writes, with run.json: a folder whose :func:`merged_stamp` is unchanged is as its merge left it
MERGED_FILES = ("trials.csv", "episodes.csv", "steps.csv", "timing.csv", RUN_FILE)


#: the packed tables of a trial record and the key columns each row must hold, by the types the merge sorts on
_TABLE_KEYS = {
    "rows": ("trial", "clutter", "model", "mode"),
    "episodes": ("trial", "clutter", "model", "mode", "target", "k0"),
    "steps": ("trial", "clutter", "model", "mode", "k"),
}
_KEY_TYPES: dict[str, tuple[type, ...]] = {
    "trial": (int,), "clutter": (int, float), "model": (str,), "mode": (str,), "target": (str, int, float),
    "k0": (int,), "k": (int,),
}  # fmt: skip


def _table_problem(table: Any, name: str, trial: int, keys: Sequence[str]) -> str | None:
    """Why the packed table ``name`` of trial ``trial``'s record (:func:`pack_table`; absent: none) cannot be
    merged, or None: columns named by strings, rows as long as the columns, key cells of the merge's types (the
    trial cell that trial), every cell a JSON scalar."""
    if table is None:
        return None
    cols = table.get("columns") if isinstance(table, dict) else None
    rows = table.get("rows") if isinstance(table, dict) else None
    if not (isinstance(cols, list) and isinstance(rows, list) and all(isinstance(c, str) for c in cols)):
        return f"its {name} table is not {{columns: [names], rows: [[cells]]}}"
    missing = [k for k in keys if k not in cols]
    if missing or len(set(cols)) != len(cols):
        return f"its {name} table lacks the column {missing[0]!r}" if missing else f"its {name} columns repeat"
    at = [(cols.index(k), _KEY_TYPES[k]) for k in keys]
    it = cols.index("trial")
    for i, r in enumerate(rows):
        if not (isinstance(r, list) and len(r) == len(cols)):
            return f"row {i} of its {name} table is not a list of {len(cols)} cells"
        if any(type(r[j]) not in types for j, types in at) or r[it] != trial:
            return f"row {i} of its {name} table has a key cell of the wrong type or trial"
        if any(isinstance(v, (list, dict)) for v in r):
            return f"row {i} of its {name} table holds a list or a table in a cell"
    return None


def merged_stamp(run_dir: Path | str) -> tuple:
    """Size and modification time of each of :data:`MERGED_FILES` in ``run_dir`` (None for a missing one)."""
    out: list[tuple[int, int] | None] = []
    for name in MERGED_FILES:
        try:
            st = os.stat(Path(run_dir) / name)
        except OSError:
            out.append(None)
            continue
        out.append((st.st_size, st.st_mtime_ns))
    return tuple(out)


#: columns of ``timing.csv``: a row's keys, its wall-clock columns and its trial's stage times
TIMING_FILE_COLUMNS = ("trial", "clutter", "model", "mode", *TIMING_COLUMNS, *(f"t_{k}" for k in TRIAL_TIMING_KEYS))


def timing_rows(rows: Sequence[dict], trial_timing: dict) -> list[dict]:
    """The ``timing.csv`` rows of one trial record: per result row its keys and wall-clock columns, with the
    trial's stage times (``TrialResult.timing``)."""
    return [
        {
            **{c: r.get(c) for c in ("trial", "clutter", "model", "mode")},
            **{c: r.get(c) for c in TIMING_COLUMNS},
            **{f"t_{k}": trial_timing.get(k) for k in TRIAL_TIMING_KEYS},
            **({FILTER_COLUMN: r[FILTER_COLUMN]} if FILTER_COLUMN in r else {}),  # a run that names filter families
        }
        for r in rows
    ]


class TableOrder:
    """The order of the merged tables (module docstring): rows by (trial, clutter, model, mode) with models and modes
    in the config's order (unknown ones after, by name); episodes then by target and k0; steps then by k."""

    def __init__(self, models: Sequence[str], modes: Sequence[str]) -> None:
        self.m_idx = {m: i for i, m in enumerate(models)}
        self.p_idx = {p: i for i, p in enumerate(modes)}

    def key_of(self, trial: Any, clutter: Any, model: Any, mode: Any) -> tuple:
        m_idx, p_idx = self.m_idx, self.p_idx
        return (
            int(trial),
            float(clutter),
            m_idx.get(model, len(m_idx)),
            str(model),
            p_idx.get(mode, len(p_idx)),
            str(mode),
        )

    def row(self, r: dict) -> tuple:
        """Sort key of a trials (or timing) row; rows that differ only in their filter family keep the trial's
        order (the family is no key: a run without the ``filter`` column sorts exactly as before it existed)."""
        return self.key_of(r["trial"], r["clutter"], r["model"], r["mode"])

    def episode(self, r: dict) -> tuple:
        """Sort key of an episode row."""
        return (*self.row(r), float(r["target"]) if _is_num(r["target"]) else 0, str(r["target"]), r["k0"])

    def step_key(self, cols: list[str]) -> Callable[[list], tuple]:
        """Sort key of a step row given as a list over ``cols``."""
        it, ic, im, ip, ik = (cols.index(c) for c in ("trial", "clutter", "model", "mode", "k"))
        key_of = self.key_of
        return lambda r: (*key_of(r[it], r[ic], r[im], r[ip]), r[ik])


class _SortedSteps:
    """steps.csv of a merge, built record by record: each trial's step rows are sorted and formatted as CSV lines as
    they arrive, so the merge holds text instead of every cell as a Python object (a study's clutter folder has
    360 000 rows of 26 cells).

    This equals :func:`_rows_of` over every record followed by one stable sort as long as every record has the same
    columns and each record's sorted block starts at or after the end of the one before (the sort key starts with
    the trial, and the records arrive by trial); otherwise ``ok`` turns False and the caller sorts every row at once.
    """

    def __init__(
        self,
        key: Callable[[list[str]], Callable[[list], tuple]],
        cols: list[str] | None = None,
        lines=None,
        columns: bool = False,
    ) -> None:
        self.key = key
        self.cols = cols
        self.lines: list[str] = lines if lines is not None else []
        self.ok = True
        self._last: tuple | None = None
        #: the columns as :func:`read_csv` will read them back, collected block by block (``columns=True``)
        self.columns: ReadBack | None = ReadBack() if columns else None

    def add(self, table: dict) -> None:
        """Append one record's packed step table (:func:`pack_table`)."""
        if not self.ok:
            return
        cols, rows = _rows_of([table], STEP_COLUMNS)
        if self.cols is None:
            self.cols = cols
        if cols != self.cols:
            self.ok = False
            return
        key = self.key(cols)
        rows.sort(key=key)
        if rows:
            if self._last is not None and key(rows[0]) < self._last:
                self.ok = False
                return
            self._last = key(rows[-1])
        self.lines.extend(map(csv_line, rows))
        if self.columns is not None:
            self.columns.add(rows)

    def write(self, path: Path) -> None:
        """The file: the header and every line (:func:`write_lines`)."""
        write_lines(path, self.cols if self.cols is not None else list(STEP_COLUMNS), self.lines)


def _rows_of(tables: Sequence[dict], columns: Sequence[str]) -> tuple[list[str], list[list]]:
    """The rows of packed tables (:func:`pack_table`) as lists over one column list: ``columns`` plus every other
    key a row holds, sorted; a cell a row lacks is None. What :func:`unpack_table` then :func:`write_csv` would
    write, without a dict per row (the merge of a run's step tables)."""
    present: set[str] = set()
    for tab in tables:
        cols, n = tab["columns"], {len(r) for r in tab["rows"]}
        present.update(cols[: max(n)] if n else ())
    out_cols = list(columns) + sorted(present - set(columns))
    rows: list[list] = []
    for tab in tables:
        cols = tab["columns"]
        if cols == out_cols and all(len(r) == len(cols) for r in tab["rows"]):
            rows.extend(tab["rows"])
            continue
        where = {c: i for i, c in enumerate(cols)}  # the last of a repeated column, as dict(zip(...)) keeps it
        idx = [where.get(c, -1) for c in out_cols]
        rows.extend([r[i] if 0 <= i < len(r) else None for i in idx] for r in tab["rows"])
    return out_cols, rows


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)
