"""Compaction of an atlas's finished chunks into a few large Parquet parts per table (:mod:`.store`).

A scan's cost follows the number of files (each file's footer and its ninety-odd column schemas), not the rows, so
a finished atlas keeps its rows in parts of up to :data:`PART_ROWS` rows whose row groups (what DuckDB scans in
parallel) are written once they reach :data:`ROW_GROUP_ROWS` rows or :data:`ROW_GROUP_BYTES`. Compaction streams: one
chunk file at a time is read and at most one row group is held, so its memory does not grow with the atlas.

Safe at any moment: each part is written to a temporary name, fsynced and renamed, and its chunk files are removed
only after that; a reader ignores a chunk file a part of its table holds (:func:`.store.table_files`). Tables are
compacted episodes and steps first and trial rows last, so a chunk's completion never depends on a file removed
before its replacement exists. Only complete chunks are compacted, and a resumed atlas skips the chunks a part holds.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from soabench.atomic import open_atomic
from soabench.experiment.campaigns.atlas import store

ROW_GROUP_ROWS = 65_536  #: a row group is written once it holds this many rows ...
ROW_GROUP_BYTES = 4 * 2**20  #: ... or this many uncompressed bytes (what compaction holds in memory, plus one chunk)
PART_ROWS = 1_048_576  #: rows per part at most (a larger table is several parts)


def unified_schema(schemas: Iterable[Any]) -> Any:
    """One schema for chunks whose columns differ (union by name, in order of first appearance): a column of one
    type keeps it, numbers of several types (an all-missing chunk column is float64) become float64, and anything
    else mixed becomes text."""
    import pyarrow as pa

    types: dict[str, list[Any]] = {}
    for schema in schemas:
        for f in schema:
            types.setdefault(f.name, [])
            if f.type not in types[f.name]:
                types[f.name].append(f.type)
    fields = []
    for name, ts in types.items():
        if len(ts) == 1:
            t = ts[0]
        elif all(pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_boolean(t) for t in ts):
            t = pa.float64()
        else:
            t = pa.string()
        fields.append(pa.field(name, t))
    return pa.schema(fields)


def conform(table: Any, schema: Any) -> Any:
    """``table`` with ``schema``'s columns in its order (a column it lacks is missing in its rows)."""
    import pyarrow as pa

    n = table.num_rows
    have = set(table.column_names)
    cols = [table.column(f.name).cast(f.type) if f.name in have else pa.nulls(n, type=f.type) for f in schema]
    return pa.Table.from_arrays(cols, schema=schema)


def _groups(files: list[tuple[tuple[int, int], Path]]) -> Iterator[list[tuple[tuple[int, int], Path]]]:
    """The chunk files in parts of at most :data:`PART_ROWS` rows (a chunk is never split)."""
    import pyarrow.parquet as pq

    group: list[tuple[tuple[int, int], Path]] = []
    rows = 0
    for chunk, path in files:
        n = pq.read_metadata(path).num_rows
        if group and rows + n > PART_ROWS:
            yield group
            group, rows = [], 0
        group.append((chunk, path))
        rows += n
    if group:
        yield group


def write_part(path: Path, files: list[tuple[tuple[int, int], Path]]) -> None:
    """One part holding the chunk files ``files`` ((trial, scene), path), written to a temporary name and renamed."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = unified_schema(pq.read_schema(f) for _, f in files)  # one footer at a time
    schema = schema.with_metadata({store.HOLDS_KEY: store.encode_chunks(c for c, _ in files)})
    with open_atomic(path) as fh, pq.ParquetWriter(fh, schema, compression="zstd") as writer:
        held: list[Any] = []
        n_rows = n_bytes = 0
        for _, f in files:
            held.append(conform(pq.read_table(f), schema))
            n_rows, n_bytes = n_rows + held[-1].num_rows, n_bytes + held[-1].nbytes
            if n_rows >= ROW_GROUP_ROWS or n_bytes >= ROW_GROUP_BYTES:  # one row group out
                writer.write_table(pa.concat_tables(held), row_group_size=ROW_GROUP_ROWS)
                held, n_rows, n_bytes = [], 0, 0
        if held:
            writer.write_table(pa.concat_tables(held), row_group_size=ROW_GROUP_ROWS)


def compact(root: Path) -> dict[str, int]:
    """Gather every complete chunk file that no part holds into new parts, table by table (module docstring);
    returns the chunk files compacted per table. The caller holds the atlas folder's lock."""
    root = Path(root)
    store.clear_partials(root)
    done = store.done_chunks(root)
    out: dict[str, int] = {}
    for table in ("episodes", "steps", "trials"):
        parts, loose = store.table_files(root, table)
        files = [(c, loose[c]) for c in sorted(loose) if c in done]
        if not files:
            continue
        used = {int(store.PART.match(p.name).group(1)) for p in parts}  # type: ignore[union-attr]
        index = max(used, default=-1) + 1
        for group in _groups(files):
            write_part(root / table / store.part_name(index), group)
            for _, f in group:  # only now: the part holds them
                f.unlink()
            index += 1
        out[table] = len(files)
    return out
