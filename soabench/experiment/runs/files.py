"""A run folder's files as bytes on disk: atomic writes, JSON records, packed tables and CSV tables.

:mod:`soabench.experiment.runs.store` decides what goes into a run folder; this module decides how a file is written
and read back:

* every file is written to a temporary file in the same folder, flushed, fsynced and moved into place
  (``os.replace``, atomic on POSIX), so a reader sees a file whole or not at all;
* JSON records hold plain Python values (:func:`to_jsonable`); floats go through ``float.__repr__``, an exact round
  trip;
* a table of rows travels inside a record as ``{"columns": [...], "rows": [[...], ...]}`` (:func:`pack_table`);
* CSV files write ``repr`` of every float and ``nan`` spelled out (:func:`format_value`), and :func:`read_csv`
  reads every column back as floats where every cell parses, else as text. :class:`ReadBack` builds the columns
  :func:`read_csv` would read from the values a writer formats, so a merge can hand them on without parsing the
  file it just wrote.
"""

from __future__ import annotations

import contextlib
import csv
import gc
import json
import math
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from soabench.atomic import PLAIN_TYPES, to_jsonable, write_chunks_atomic
from soabench.errors import SoabenchError


# ------------------------------------------------------------------------------------- JSON records
def read_json(path: Path) -> Any:
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as exc:  # RecursionError: nested too deeply to read
        raise SoabenchError(f"cannot read {str(path)!r}: {exc}") from None


# ----------------------------------------------------------------------------------------------- packed tables
def pack_table(rows: Sequence[dict], columns: Sequence[str]) -> dict:
    """Column-major-free compact form ``{"columns": [...], "rows": [[...], ...]}``; unknown keys are kept."""
    cols = list(columns)
    extra = sorted({k for r in rows for k in r} - set(cols))
    cols += extra
    plain = PLAIN_TYPES
    return {
        "columns": cols,
        "rows": [[v if type(v) in plain else to_jsonable(v) for v in map(r.get, cols)] for r in rows],
    }


def unpack_table(table: dict | None) -> list[dict]:
    if not table:
        return []
    cols = table["columns"]
    return [dict(zip(cols, r, strict=False)) for r in table["rows"]]


# --------------------------------------------------------------------------------------------------------- CSV
def format_value(v: Any) -> str:
    """CSV text of one value: ``repr`` for floats (exact round trip), ``nan``/``inf`` spelled out, '' for None."""
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "1" if v else "0"
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return "nan" if math.isnan(v) else repr(v)
    if isinstance(v, np.integer):
        return str(int(v))
    return str(v)


def _csv_cell(v: Any) -> str:
    """One CSV cell: :func:`format_value`, quoted when it holds a comma, a quote or a newline (fast path for the
    plain ints and floats that make up most cells)."""
    t = type(v)
    if t is float:
        return "nan" if v != v else repr(v)
    if t is int:
        return str(v)
    s = v if t is str else format_value(v)
    if "," in s or '"' in s or "\n" in s:
        s = '"' + s.replace('"', '""') + '"'
    return s


def csv_line(row: Sequence[Any]) -> str:
    """One CSV line of cells (:func:`_csv_cell`), with the float and int cells formatted inline."""
    return ",".join(
        [
            (repr(v) if v == v else "nan") if type(v) is float else str(v) if type(v) is int else _csv_cell(v)
            for v in row
        ]
    )


def as_lists(rows: Iterable[dict], columns: Sequence[str]) -> tuple[list[str], list[list]]:
    """The column names of a table of dict rows (``columns`` plus any extra keys, sorted) and each row as a list
    over them (None where a row lacks a key): what :func:`write_csv` writes."""
    rows = list(rows)
    cols = list(columns) + sorted({k for r in rows for k in r} - set(columns))
    return cols, [[r.get(c) for c in cols] for r in rows]


def write_csv(path: Path, rows: Iterable[dict], columns: Sequence[str]) -> None:
    """Atomically write ``rows`` (dicts) with ``columns`` (plus any extra keys, sorted) as a CSV file."""
    write_csv_lists(path, *as_lists(rows, columns))


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    """Pause the cyclic garbage collector (if it runs) while tables of millions of cells are built or written.

    Those are lists and strings without reference cycles, but every few hundred allocations of containers start a
    collection that walks all of them: reading or merging a study's step tables took 1.3 to 1.6 times as long.
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def read_csv(path: Path) -> dict[str, np.ndarray]:
    """Read a CSV written by :func:`write_csv` into columns: float arrays where every cell parses, else str arrays.

    Cells are parsed by ``float`` (an empty cell is NaN). A file without quotes, carriage returns or blank lines
    (every file soabench writes unless a cell holds a comma or a quote) is split on newlines and commas directly,
    which gives the cells the :mod:`csv` module gives, a block of rows at a time, so that a study's steps.csv (millions
    of cells) is never held as one Python string per cell; any other file goes through :mod:`csv`.

    A file that is not UTF-8 text or CSV, or has a row of another number of cells than its header (a cut-off or
    edited file; blank lines hold no row), is one line naming it (:class:`SoabenchError`).
    """
    try:
        with gc_paused():
            out = _read_plain(path)
            if out is not None:
                return out
            with open(path, newline="", encoding="utf-8") as fh:
                reader = csv.reader(fh)
                header = next(reader, None)
                if header is None:
                    raise SoabenchError(f"{str(path)!r} is empty")
                data = [r for r in reader if r]
    except UnicodeDecodeError as exc:
        raise SoabenchError(f"{str(path)!r} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except csv.Error as exc:
        raise SoabenchError(f"{str(path)!r} is not a CSV table: {exc}") from None
    for i, r in enumerate(data):
        if len(r) != len(header):
            raise SoabenchError(
                f"{str(path)!r} is damaged: a row ({i + 1} after the header) has {len(r)} cells, the header "
                f"{len(header)} (a cut-off or edited file)"
            )
    return {name: _parse_column([r[j] for r in data]) for j, name in enumerate(header)}


def header_of(path: Path) -> list[str] | None:
    """The column names :func:`read_csv` gives ``path`` (its first line), or None if the file is missing, empty or
    its first line is not a plain header (quotes, a carriage return, a blank line: :func:`read_csv` decides those)."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            line = fh.readline()
    except (OSError, ValueError):
        return None
    line = line[:-1] if line.endswith("\n") else line
    if not line or '"' in line or "\r" in line:
        return None
    return line.split(",")


def _parse_column(cells: Sequence[str]) -> np.ndarray:
    """A float array if every cell parses (an empty cell is NaN), else a str array."""
    try:
        if "" in cells:
            return np.array([float(x) if x != "" else math.nan for x in cells], dtype=float)
        return np.fromiter(map(float, cells), dtype=float, count=len(cells))
    except ValueError:
        return np.array(cells, dtype=str)


class ReadBack:
    """The columns :func:`read_csv` would read from CSV rows written by :func:`csv_line`, built from the rows' values
    as they are written, block by block (the merge's trials).

    A column whose cells are all Python floats and ints reads back as those numbers (``float(repr(x)) == x``,
    ``float(str(n)) == float(n)``, NaN as numpy's NaN); any other block is formatted (:func:`format_value`) and
    parsed by :func:`_parse_column`, exactly as the file's cells are. A column that is numbers in one block and text
    in another is decided only by the whole file (a float block would have to be formatted again), so then
    :meth:`arrays` gives None and the caller reads the file.
    """

    def __init__(self) -> None:
        self.blocks: list[list[np.ndarray]] = []
        self.ok = True

    def add(self, rows: Sequence[Sequence[Any]]) -> None:
        if not self.ok or not rows:
            return
        cols = list(zip(*rows, strict=True))
        if not self.blocks:
            self.blocks = [[] for _ in cols]
        if len(cols) != len(self.blocks):
            self.ok = False
            return
        for j, col in enumerate(cols):
            kinds = set(map(type, col))
            a = _numbers(col) if kinds <= _NUMBER_TYPES else None
            if a is None:  # text, or a cell only its text decides: the cells as the file holds them (unquoted)
                a = _parse_column(list(col) if kinds == {str} else [format_value(v) for v in col])
            self.blocks[j].append(a)

    def arrays(self, header: Sequence[str]) -> dict[str, np.ndarray] | None:
        """The columns by name (``header``: the file's columns, in order), or None when only the file decides."""
        if not self.ok:
            return None
        if not self.blocks:
            return {name: np.zeros(0) for name in header}
        if len(header) != len(self.blocks) or len(set(header)) != len(header):
            return None
        out: dict[str, np.ndarray] = {}
        for name, blocks in zip(header, self.blocks, strict=True):
            kinds = {b.dtype.kind for b in blocks}
            if kinds == {"f"}:
                out[name] = np.concatenate(blocks)
            elif "f" not in kinds:
                out[name] = np.concatenate(blocks)  # str, as wide as the widest cell (np.array of the cells)
            else:
                return None
        return out


_NUMBER_TYPES = frozenset({float, int})


def _numbers(values: Sequence[float | int]) -> np.ndarray | None:
    """Python floats and ints as :func:`_parse_column` reads their CSV text: the same numbers, NaN as
    ``float("nan")``; None for an int beyond the float range (its text reads as inf)."""
    try:
        a = np.array(values, dtype=float)
    except OverflowError:
        return None
    a[np.isnan(a)] = math.nan
    return a


_BLOCK = 20_000  #: rows parsed at a time by :func:`_read_plain`


def _read_plain(path: Path) -> dict[str, np.ndarray] | None:
    """:func:`read_csv` of a file without quotes or carriage returns; None for any other file, or one with a blank
    line or a row with another number of cells than the header (the csv module reads those)."""
    with open(path, newline="", encoding="utf-8") as fh:
        text = fh.read()
    if '"' in text or "\r" in text:
        return None
    lines = text.split("\n")
    del text
    if lines and lines[-1] == "":
        lines.pop()
    if not lines or not all(lines):  # (csv reads a blank line as a row without cells)
        return None
    header, body = lines[0].split(","), lines[1:]
    del lines
    n = len(header)
    floats: list[list[np.ndarray]] = [[] for _ in header]  # the parsed blocks of each column while all parse
    text: dict[int, list[str]] = {}  # column -> its cells, from the block where one did not parse on
    starts: dict[int, int] = {}  # column -> the first row of its cells in ``text``
    for start in range(0, len(body), _BLOCK):
        rows = [ln.split(",") for ln in body[start : start + _BLOCK]]
        if any(len(r) != n for r in rows):
            return None
        for j, col in enumerate(zip(*rows, strict=True)):
            if j in text:
                text[j].extend(col)
                continue
            a = _parse_column(col)
            if a.dtype == float:
                floats[j].append(a)
            else:
                text[j], starts[j] = list(col), start
    out: dict[str, np.ndarray] = {}
    for j, name in enumerate(header):
        if j not in text:
            out[name] = np.concatenate(floats[j]) if floats[j] else np.zeros(0)
            continue
        earlier = [ln.split(",")[j] for ln in body[: starts[j]]]  # blocks that parsed before a later one did not
        out[name] = np.array(earlier + text.pop(j), dtype=str)
    return out


def write_csv_lists(path: Path, columns: Sequence[str], rows: Iterable[Sequence[Any]]) -> None:
    """:func:`write_csv` for rows already given as lists over ``columns``."""
    write_lines(path, columns, list(map(csv_line, rows)))


def write_lines(path: Path, columns: Sequence[str], lines: Sequence[str], block: int = 20_000) -> None:
    """A CSV file of the header ``columns`` and the formatted ``lines``, written atomically a block of lines at a
    time (the file's text is never held whole)."""

    def chunks() -> Iterator[bytes]:
        yield (",".join(columns) + "\n").encode("utf-8")
        for i in range(0, len(lines), block):
            yield ("\n".join(lines[i : i + block]) + "\n").encode("utf-8")

    write_chunks_atomic(path, chunks())
