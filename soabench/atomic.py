"""Files written whole or not at all, and plain values for JSON (docs/development.md: helpers every layer may use).

Every file is written to a temporary file in the same folder, flushed, fsynced and moved into place (``os.replace``,
atomic on POSIX), so a reader sees a file whole or not at all; JSON holds plain Python values (:func:`to_jsonable`),
floats through ``float.__repr__``, an exact round trip.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

PLAIN_TYPES = frozenset({int, float, str, bool, type(None)})  #: types ``json`` writes as they are


def to_jsonable(obj: Any) -> Any:
    """Plain Python values for ``json``: numpy scalars and arrays, tuples, dataclass-free containers."""
    if type(obj) in PLAIN_TYPES:
        return obj
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj)
    if isinstance(obj, (str, type(None))):
        return obj
    if isinstance(obj, Path):
        return str(obj)
    return repr(obj)


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def current_umask() -> int:
    """The process's file-creation mask (read by setting it and putting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary file in the same folder, fsync, then ``os.replace``.

    The file gets the mode any other new file gets (0666 minus the user's umask): ``mkstemp`` creates its
    temporary file private (0600), which would otherwise survive the rename.
    """
    write_chunks_atomic(path, (data,))


def write_chunks_atomic(path: Path, chunks: Iterable[bytes]) -> None:
    """:func:`write_bytes_atomic` of the concatenated ``chunks``, written one after another (a large file is never
    held whole in memory)."""
    with open_atomic(path) as fh:
        for chunk in chunks:
            fh.write(chunk)


@contextlib.contextmanager
def open_atomic(path: Path) -> Iterator[BinaryIO]:
    """A binary file to write ``path`` through (a temporary file in the same folder, hidden and ending in ``.tmp``):
    when the block ends it is fsynced and moved into place; if the block raises, it is removed and ``path`` is
    untouched."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        if hasattr(os, "fchmod"):  # POSIX
            os.fchmod(fd, 0o666 & ~current_umask())
        with os.fdopen(fd, "wb") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    _fsync_dir(path.parent)


def write_text_atomic(path: Path, text: str) -> None:
    write_bytes_atomic(path, text.encode("utf-8"))


def _json_default(obj: Any) -> Any:
    """What ``json`` cannot write itself, as :func:`to_jsonable` converts it (numpy scalars and arrays, paths)."""
    return to_jsonable(obj)


def _compact_json(obj: Any) -> str:
    """``obj`` as compact JSON, the text of ``json.dumps(to_jsonable(obj), ...)``: json's C encoder walks the plain
    values itself (a trial record holds hundreds of thousands of them) and asks :func:`to_jsonable` only for the
    others. Mappings whose keys are not all str take the walk through :func:`to_jsonable` (json would write a bool
    or None key differently)."""
    if not _str_keys(obj):
        return json.dumps(to_jsonable(obj), allow_nan=True, separators=(",", ":"))
    return json.dumps(obj, allow_nan=True, separators=(",", ":"), default=_json_default)


def _str_keys(obj: Any) -> bool:
    """True if every dict in the nested dicts of ``obj`` has str keys (lists are not searched: records keep their
    tables as lists of plain rows)."""
    if isinstance(obj, dict):
        return all(type(k) is str and _str_keys(v) for k, v in obj.items())
    return True


def write_json_atomic(path: Path, obj: Any, compact: bool = False) -> None:
    """``obj`` as JSON (``compact``: no indentation or spaces, for the large per-trial records)."""
    if compact:
        text = _compact_json(obj)
    else:
        text = json.dumps(to_jsonable(obj), indent=1, allow_nan=True)
    write_text_atomic(path, text + "\n")
