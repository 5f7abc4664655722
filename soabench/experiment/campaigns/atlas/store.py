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
``trials/`` file exists is complete, and a resumed atlas skips it (it is never written twice).

**Compaction** (:mod:`.compact`) gathers finished chunks into a few large *parts* per table,
``trials/part-00000.parquet``, each with row groups sized for scans and, in its Parquet metadata, the chunks it
holds. A part is written to a temporary name and renamed; only then are the chunk files it holds removed. A chunk is
complete when its trial rows are a chunk file or held by a ``trials/`` part, and a chunk file that a part of its
table holds is ignored by every reader (:func:`table_files`) and removed on the next open: a compaction killed at any
moment leaves a valid dataset, and none of its rows counted twice. Columns: ``point``,
``scene``, one column per axis (the key with ``.`` as ``_``), ``family``, then every column of the run's own table
(``trials.csv``: trial, seed, ..., the track columns; ``episodes.csv`` with whatever fields its episodes carry).
"""

from __future__ import annotations

import io
import json
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
PART = re.compile(r"^part-(\d{5,})\.parquet$")
#: the key of a part's Parquet metadata that lists the chunks it holds
HOLDS_KEY = b"soabench.chunks"


def chunk_name(trial: int, scene: int) -> str:
    return f"n{trial:05d}-s{scene:04d}.parquet"


def part_name(index: int) -> str:
    return f"part-{index:05d}.parquet"


def encode_chunks(chunks: Iterable[tuple[int, int]]) -> bytes:
    """(trial, scene) pairs as compact JSON: per scene variant, its trials as inclusive ranges."""
    by_scene: dict[int, list[int]] = {}
    for n, s in chunks:
        by_scene.setdefault(int(s), []).append(int(n))
    out: dict[str, list[list[int]]] = {}
    for s, trials in sorted(by_scene.items()):
        ranges: list[list[int]] = []
        for n in sorted(set(trials)):
            if ranges and ranges[-1][1] == n - 1:
                ranges[-1][1] = n
            else:
                ranges.append([n, n])
        out[str(s)] = ranges
    return json.dumps(out, separators=(",", ":")).encode()


def decode_chunks(data: bytes) -> set[tuple[int, int]]:
    """The pairs of :func:`encode_chunks`."""
    out = set()
    for s, ranges in json.loads(data).items():
        for lo, hi in ranges:
            out.update((n, int(s)) for n in range(int(lo), int(hi) + 1))
    return out


def part_chunks(path: Path) -> set[tuple[int, int]]:
    """The chunks a part holds (its footer only is read); a part without the list is refused in one line."""
    import pyarrow.parquet as pq

    meta = pq.read_schema(path).metadata or {}
    require(HOLDS_KEY in meta, f"{path} is not an atlas part (its metadata lists no chunks); remove it or restore it")
    return decode_chunks(meta[HOLDS_KEY])


def table_files(root: Path, table: str) -> tuple[dict[Path, set[tuple[int, int]]], dict[tuple[int, int], Path]]:
    """The parts of ``table`` (path -> the chunks it holds) and its chunk files that no part holds ((trial, scene)
    -> path): together, every row of the table exactly once."""
    parts: dict[Path, set[tuple[int, int]]] = {}
    loose: dict[tuple[int, int], Path] = {}
    folder = root / table
    if not folder.is_dir():
        return parts, loose
    for f in sorted(folder.iterdir()):
        if PART.match(f.name):
            parts[f] = part_chunks(f)
        else:
            m = CHUNK.match(f.name)
            if m:
                loose[(int(m.group(1)), int(m.group(2)))] = f
    held = set().union(*parts.values()) if parts else set()
    return parts, {c: f for c, f in loose.items() if c not in held}


def dataset_files(root: Path, table: str) -> list[Path]:
    """Every file a reader of ``table`` reads: its parts, then the chunk files no part holds."""
    parts, loose = table_files(root, table)
    return [*parts, *(loose[c] for c in sorted(loose))]


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
    """(trial, scene) of every complete chunk: its trial rows are a chunk file or held by a part."""
    parts, loose = table_files(root, "trials")
    return set(loose).union(*parts.values())


def clear_partials(root: Path) -> None:
    """Remove temporary files a killed writer left (ours by name), chunk tables without their trial rows, and chunk
    files a part of their table already holds (a compaction killed before it removed them)."""
    done = done_chunks(root)
    for table in TABLES:
        folder = root / table
        if not folder.is_dir():
            continue
        parts, loose = table_files(root, table)
        keep = set(loose.values())
        for f in folder.iterdir():
            m = CHUNK.match(f.name)
            if f.name.startswith(".") and f.name.endswith(".tmp"):
                f.unlink()
            elif m and f not in keep:  # held by a part
                f.unlink()
            elif m and table != "trials" and (int(m.group(1)), int(m.group(2))) not in done:
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
