"""SQL over an atlas or any run folder with DuckDB, embedded (docs/user-guide/atlas.md, "Queries").

:func:`connect` opens an in-memory DuckDB database whose views are the folder's tables:

* an atlas (``atlas.json``): ``trials``, ``episodes``, ``steps`` (when stored) over its Parquet parts and the chunks
  no part holds yet (:func:`.store.dataset_files`), and ``points`` (one row per design point);
* a run folder (``run.json``): ``trials``, ``episodes``, ``steps`` over its CSV files;
* a folder holding run folders (a sweep, a study, results/): the same tables over every run folder below it, with a
  ``run`` column naming the run folder (its path relative to the folder).

The connection may read only inside the folder (DuckDB's ``allowed_directories``, external access off, the
configuration locked): a query cannot read or write files elsewhere or install extensions.
"""

from __future__ import annotations

import io
import math
import re
from pathlib import Path
from typing import Any

from soabench.atomic import write_bytes_atomic
from soabench.errors import SoabenchError, require
from soabench.experiment.campaigns.atlas import store

RUN_TABLES = {"trials": "trials.csv", "episodes": "episodes.csv", "steps": "steps.csv"}
MAX_PRINTED = 200  #: rows printed on the terminal (``--out`` writes them all)


def _sql_text(s: str) -> str:
    return "'" + s.replace("'", "''") + "'"


def _sql_list(paths: list[Path]) -> str:
    return "[" + ", ".join(_sql_text(str(p)) for p in paths) + "]"


def tables_of(root: Path) -> dict[str, str]:
    """Each table's DuckDB source expression for the folder ``root`` (module docstring); refuses a folder that is
    neither an atlas nor holds a run."""
    root = Path(root).resolve()
    require(root.is_dir(), f"{str(root)!r} is not a folder; give an atlas or a run folder")
    out: dict[str, str] = {}
    if (root / store.ATLAS_FILE).exists():
        store.read_meta(root)  # one line if atlas.json is not an atlas's
        for table in store.TABLES:
            files = store.dataset_files(root, table)  # its parts and the chunk files no part holds
            if files:
                out[table] = f"read_parquet({_sql_list(files)}, union_by_name = true)"
        out["points"] = f"read_parquet({_sql_text(str(root / 'points.parquet'))})"
        return out
    if (root / "run.json").is_file():
        for table, name in RUN_TABLES.items():
            if (root / name).is_file():
                out[table] = f"read_csv({_sql_text(str(root / name))}, header = true, auto_detect = true)"
        return out
    runs = sorted(p.parent for p in root.rglob("run.json"))
    require(
        bool(runs),
        f"{str(root)!r} is neither an atlas (atlas.json) nor a run folder (run.json), and holds no run folder",
    )
    for table, name in RUN_TABLES.items():
        files = [r / name for r in runs if (r / name).is_file()]
        if files:
            prefix = len(str(root)) + 1
            out[table] = (
                f"(SELECT regexp_replace(substr(filename, {prefix + 1}), '/[^/]*$', '') AS run, * EXCLUDE (filename) "
                f"FROM read_csv({_sql_list(files)}, header = true, auto_detect = true, union_by_name = true, "
                "filename = true))"
            )
    return out


def connect(path: str | Path, only: Any = None, threads: int | None = None) -> Any:
    """A DuckDB connection with the folder's tables as views (module docstring); ``only``: the names of the tables
    to open (None: all). DuckDB reads every file's schema when it creates a view, so a query opens only the tables it
    names. ``threads``: DuckDB's threads (None: its default, every core); one thread sums in the files' row order,
    so averages are the same bit for bit from run to run."""
    import duckdb

    root = Path(path).resolve()
    tables = tables_of(root)
    if only is not None:
        tables = {k: v for k, v in tables.items() if k in set(only)}
    con = duckdb.connect()
    if threads is not None:
        con.execute(f"SET threads = {int(threads)}")
    con.execute("SET allowed_directories = ?", [[str(root) + "/"]])
    con.execute("SET enable_external_access = false")
    con.execute("SET lock_configuration = true")
    for name, source in tables.items():
        con.execute(f"CREATE VIEW {name} AS SELECT * FROM {source}")
    return con


def run_query(path: str | Path, sql: str) -> Any:
    """The result of ``sql`` over the folder's tables, as a pyarrow table; a failing query is one line."""
    import duckdb

    require(isinstance(sql, str) and sql.strip() != "", 'the SQL is empty; give a query such as "SELECT ..."')

    names = {w.lower() for w in re.findall(r"[A-Za-z_]+", sql)}
    con = connect(path, only=[t for t in (*store.TABLES, "points") if t in names])
    try:
        rel = con.sql(sql)
        if rel is None:
            raise SoabenchError("the SQL returned no table; give a query (SELECT ...)")
        fetch = getattr(rel, "to_arrow_table", None) or rel.arrow  # DuckDB 2 named it to_arrow_table
        return fetch()
    except duckdb.Error as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise SoabenchError(f"the SQL failed: {first}") from None
    finally:
        con.close()


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.6g}"
    return str(v)


def format_table(table: Any, limit: int = MAX_PRINTED) -> str:
    """An aligned text table of the first ``limit`` rows (and how many more there are)."""
    names = list(table.column_names)
    rows = [[_cell(v) for v in r.values()] for r in table.slice(0, limit).to_pylist()]
    widths = [max([len(n), *(len(r[i]) for r in rows)]) for i, n in enumerate(names)]
    lines = ["  ".join(n.rjust(w) for n, w in zip(names, widths, strict=True))]
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    more = table.num_rows - len(rows)
    if more > 0:
        lines.append(f"... {more} more row(s); write them all with --out FILE.csv or FILE.parquet")
    lines.append(f"({table.num_rows} row(s))")
    return "\n".join(lines)


def write_result(table: Any, out: Path) -> None:
    """``out``: ``.csv`` or ``.parquet`` (by suffix), written whole or not at all."""

    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    suffix = Path(out).suffix.lower()
    require(suffix in (".csv", ".parquet"), f"--out {str(out)!r}: allowed: a .csv or .parquet file")
    sink = io.BytesIO()
    if suffix == ".csv":
        pacsv.write_csv(table, sink)
    else:
        pq.write_table(table, sink, compression="zstd")
    write_bytes_atomic(Path(out), sink.getvalue())
