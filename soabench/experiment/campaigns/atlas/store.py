"""An atlas folder on disk: ``atlas.json``, the scene variants' scenarios and the Parquet dataset (§5.10).

Layout::

    atlas.json                  format, design, points, scene variants, base config, trials, seed, versions
    points.parquet              one row per point: point, scene, the axis columns, its configuration (JSON)
    scenes/s0003.scenario.toml  the scenario of each scene variant that sets scenario keys
    trials/n00012-s0003.parquet one chunk per (trial, scene variant): every row of every point of that variant
    episodes/n00012-s0003.parquet   its delay episodes (the chunk's rows are its trial rows)
    steps/...                   per-scan rows, only when asked for (``--steps``)
    failures/n00012-s0003.json  a chunk whose trial failed (retried on resume)

A chunk is written to a temporary name and renamed, episodes (and steps) first and its trial rows last: a chunk whose
``trials/`` file exists is complete, and a resumed atlas skips it (it is never written twice). Columns: ``point``,
``scene``, one column per axis (the key with ``.`` as ``_``), ``family``, then every column of the run's own table
(``trials.csv``: trial, seed, ..., the track columns; ``episodes.csv`` with whatever fields its episodes carry).
"""

from __future__ import annotations

import io
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from soabench.atomic import write_bytes_atomic
from soabench.errors import require
from soabench.experiment.runs.files import read_json

ATLAS_FILE = "atlas.json"
FORMAT = "soabench-atlas-1"
TABLES = ("trials", "episodes", "steps")
#: every entry an atlas folder holds (anything else: not an atlas's)
ATLAS_ENTRIES = (ATLAS_FILE, "points.parquet", "scenes", *TABLES, "failures", "report", ".soabench.lock")
CHUNK = re.compile(r"^n(\d{5,})-s(\d{4,})\.parquet$")


def chunk_name(trial: int, scene: int) -> str:
    return f"n{trial:05d}-s{scene:04d}.parquet"


def arrow_table(columns: dict[str, list]) -> Any:
    """A pyarrow table of ``columns`` (name -> values); a column of only missing values is float64."""
    import pyarrow as pa

    arrays, names = [], []
    for name, values in columns.items():
        if all(v is None for v in values):
            arrays.append(pa.array(values, type=pa.float64()))
        else:
            try:
                arrays.append(pa.array(values))
            except (pa.ArrowInvalid, pa.ArrowTypeError):  # mixed ints and floats: numbers
                arrays.append(pa.array([None if v is None else float(v) for v in values], type=pa.float64()))
        names.append(name)
    return pa.Table.from_arrays(arrays, names=names)


def parquet_bytes(columns: dict[str, list]) -> bytes:
    import pyarrow.parquet as pq

    sink = io.BytesIO()
    pq.write_table(arrow_table(columns), sink, compression="zstd")
    return sink.getvalue()


def write_chunk(root: Path, trial: int, scene: int, tables: dict[str, dict[str, list] | None]) -> None:
    """Write one chunk (module docstring): each table to a temporary name then renamed, ``trials`` last."""
    name = chunk_name(trial, scene)
    require(not (root / "trials" / name).exists(), f"chunk {name} of {root} is already complete")
    for table in ("episodes", "steps", "trials"):
        cols = tables.get(table)
        if not cols or not any(len(v) for v in cols.values()):  # no rows (a trial without episodes): no file
            continue
        write_bytes_atomic(root / table / name, parquet_bytes(cols))
    failed = root / "failures" / name.replace(".parquet", ".json")
    if failed.exists():
        failed.unlink()


def done_chunks(root: Path) -> set[tuple[int, int]]:
    """(trial, scene) of every complete chunk."""
    out = set()
    folder = root / "trials"
    if folder.is_dir():
        for f in folder.iterdir():
            m = CHUNK.match(f.name)
            if m:
                out.add((int(m.group(1)), int(m.group(2))))
    return out


def clear_partials(root: Path) -> None:
    """Remove temporary files a killed writer left (ours by name) and chunk tables without their trial rows."""
    done = {chunk_name(n, s) for n, s in done_chunks(root)}
    for table in TABLES:
        folder = root / table
        if not folder.is_dir():
            continue
        for f in folder.iterdir():
            if f.name.startswith(".") and f.name.endswith(".tmp"):
                f.unlink()
            elif table != "trials" and CHUNK.match(f.name) and f.name not in done:
                f.unlink()


def is_atlas(root: Path) -> bool:
    meta = root / ATLAS_FILE
    if not meta.is_file():
        return False
    try:
        data = read_json(meta)
    except Exception:
        return False
    return isinstance(data, dict) and data.get("format") == FORMAT


def read_meta(root: Path) -> dict:
    """``atlas.json``, checked to be an atlas's (one line otherwise)."""
    require(is_atlas(root), f"{str(root)!r} is not an atlas folder (no valid {ATLAS_FILE}); give an atlas's folder")
    data = read_json(root / ATLAS_FILE)
    for key, kind in (("points", list), ("scenes", list), ("trials", int), ("config", dict), ("net", str)):
        require(isinstance(data.get(key), kind), f"{root / ATLAS_FILE}: {key} is missing or of the wrong type")
    return data


def columns_of(rows: Iterable[dict], head: dict[str, Any]) -> dict[str, list]:
    """Rows (dicts) as columns: ``head``'s columns (constant per row) first, then every key of the rows in order of
    first appearance (a key a row lacks is missing there)."""
    rows = list(rows)
    keys: dict[str, None] = {}
    for r in rows:
        for k in r:
            if k not in head:
                keys.setdefault(k, None)
    out: dict[str, list] = {k: [] for k in head}
    out.update({k: [] for k in keys})
    for r in rows:
        for k, v in head.items():
            out[k].append(v)
        for k in keys:
            out[k].append(r.get(k))
    return out


def concat_columns(parts: list[dict[str, list]]) -> dict[str, list] | None:
    """One table of several column dicts (a column missing from a part is missing in its rows)."""
    parts = [p for p in parts if p and any(len(v) for v in p.values())]
    if not parts:
        return None
    names: dict[str, None] = {}
    for p in parts:
        for k in p:
            names.setdefault(k, None)
    out: dict[str, list] = {k: [] for k in names}
    for p in parts:
        n = len(next(iter(p.values())))
        for k in names:
            out[k].extend(p.get(k, [None] * n))
    return out
