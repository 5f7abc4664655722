"""Owned run folders: resolved paths, refused stale or foreign folders, one process per folder (a lock).

* Every path is resolved (:meth:`pathlib.Path.resolve`) before any check, so ``/x/missing/../run`` is ``/x/run``
  and is refused when ``/x/run`` already holds a run.
* A new run needs a folder that does not exist or is empty; a folder with content but without the run's own file
  (e.g. ``trials/`` and no ``run.json``: a half-copied or foreign folder) is refused, never adopted.
* A command whose folder holds parts of known names (a study's ``main/``, ``clutter/``, ...; a check's
  ``check.json``, ``runs/``) writes only into a folder that is absent, empty or holds nothing but those names
  (:func:`check_own_folder`): anything else there is someone else's and the folder is refused.
* :class:`FolderLock` holds ``fcntl.flock`` on ``<folder>/.lock`` for the whole session; the file names the holder
  (pid, host, start time). A second process gets one clear error naming the holder. The kernel drops the lock
  when its holder dies, however it dies (SIGKILL included), so a stale ``.lock`` left behind is detected by taking
  the lock: a dead holder never blocks a resume. The lock file is removed on release.
"""

from __future__ import annotations

import json
import os
import socket
import tempfile
from collections.abc import Iterable
from datetime import datetime, timezone
from pathlib import Path

from soabench.errors import BadValue, SoabenchError, require

try:  # POSIX (SUMO's platforms for this project: Linux, macOS)
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

LOCK_FILE = ".lock"


def resolve(path: str | os.PathLike) -> Path:
    """``path`` made absolute with symlinks and ``..`` resolved (before any existence check)."""
    try:
        return Path(path).expanduser().resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop, an unreadable component
        raise SoabenchError(f"cannot resolve the path {str(path)!r}: {exc}") from None


def probe_writable(folder: Path, message: str) -> None:
    """Create and remove a temporary file in ``folder`` (permission bits do not tell for root or read-only mounts)."""
    try:
        fd, name = tempfile.mkstemp(prefix=".soabench-probe-", dir=folder)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        raise SoabenchError(f"{message} is not writable ({exc.strerror or exc})") from None


def check_writable_target(path: Path, what: str) -> None:
    """``path`` may be created as a folder: it is a folder already, or its first existing ancestor is a writable
    folder (not a file)."""
    if path.exists():
        require(path.is_dir(), f"{what} {str(path)!r} is a file, not a folder; give a folder path")
        probe_writable(path, f"{what} {str(path)!r}")
        return
    parent = path.parent
    while not parent.exists():
        parent = parent.parent
    require(parent.is_dir(), f"{what} {str(path)!r} lies under {str(parent)!r}, which is a file, not a folder")
    probe_writable(parent, f"{what} {str(path)!r}: the folder {str(parent)!r}")


def check_new_folder(path: Path, marker: str, what: str, resume_hint: str) -> None:
    """``path`` (resolved) may receive a new run/sweep: absent or empty; a folder holding ``marker`` already holds a
    run (``resume_hint`` says how to finish it); any other content is a stale or foreign folder. A folder refused
    is refused before the writability probe, so nothing is created in it, even for a moment."""
    if path.is_dir():
        if (path / marker).is_file():
            raise BadValue("out", str(path), f"already holds a {what}; {resume_hint}, or give another folder")
        content = sorted(p.name for p in path.iterdir() if p.name != LOCK_FILE)
        if content:
            shown = ", ".join(content[:4]) + (", ..." if len(content) > 4 else "")
            raise BadValue(
                "out",
                str(path),
                f"is not empty ({shown}) but holds no {marker}: a stale or foreign folder is never adopted; give a "
                "new or empty folder",
            )
    check_writable_target(path, what)


def check_own_folder(path: Path, what: str, own: Iterable[str]) -> None:
    """``path`` (resolved) may be written by a command whose entries all have one of the names ``own``: it is
    absent, empty, or holds nothing else (the command's own folder, re-run to finish or refresh it). Any other entry
    belongs to someone else, and the folder is refused before anything is written (or probed)."""
    if path.is_dir():
        names = set(own) | {LOCK_FILE}
        foreign = sorted(p.name for p in path.iterdir() if p.name not in names)
        if foreign:
            shown = ", ".join(foreign[:4]) + (", ..." if len(foreign) > 4 else "")
            raise BadValue(
                "out",
                str(path),
                f"is not empty ({shown}) and is not a {what}: a folder that is not ours is never written into; give "
                "a new or empty folder",
            )
    check_writable_target(path, what)


def check_existing_folder(path: Path, marker: str, what: str) -> None:
    """``path`` (resolved) is a folder holding ``marker`` (for ``--resume``)."""
    require(path.is_dir(), f"{str(path)!r} is not a {what} folder (no such folder)")
    require((path / marker).is_file(), f"{str(path)!r} is not a {what} folder (no {marker})")


def _holder_text(info: dict) -> str:
    return f"pid {info.get('pid', '?')} on {info.get('host', '?')} (since {info.get('since', '?')})"


class FolderLock:
    """An exclusive, non-blocking lock on one folder for one process (context manager).

    ``acquire`` raises :class:`SoabenchError` naming the holder when another live process holds it.
    """

    def __init__(self, folder: Path, what: str = "run folder"):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_FILE
        self.what = what
        self._fd: int | None = None

    def acquire(self) -> FolderLock:
        if fcntl is None:  # pragma: no cover - no flock: no lock (documented)
            return self
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SoabenchError(
                f"the {self.what} {str(self.folder)!r} is not writable ({exc.strerror or exc})"
            ) from None
        for _ in range(10):
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise SoabenchError(
                    f"the {self.what} {str(self.folder)!r} is not writable ({exc.strerror or exc})"
                ) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                info = self._read_holder(fd)
                os.close(fd)
                raise SoabenchError(
                    f"{self.what} {str(self.folder)!r} is in use by {_holder_text(info)}; "
                    "wait for it to finish (a dead holder's lock is released by the system)"
                ) from None
            # the file we locked must still be the one at the path (a releasing holder unlinks it)
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                self._fd = fd
                self._write_holder()
                return self
            os.close(fd)
        raise SoabenchError(f"cannot lock the {self.what} {str(self.folder)!r}: it keeps changing")  # pragma: no cover

    @staticmethod
    def _read_holder(fd: int) -> dict:
        try:
            data = os.pread(fd, 4096, 0).decode("utf-8", "replace")
            info = json.loads(data)
            return info if isinstance(info, dict) else {}
        except (OSError, ValueError, RecursionError):
            return {}

    def _write_holder(self) -> None:
        info = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "since": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        }
        data = (json.dumps(info) + "\n").encode()
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, data, 0)

    def release(self) -> None:
        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            os.unlink(self.path)  # while still holding the lock: a waiter re-checks the inode
        except OSError:
            pass
        os.close(fd)

    def __enter__(self) -> FolderLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def check_out_file(path: str, suffix: str | None = None, flag: str = "--out") -> Path:
    """An output file path: resolved, not a folder, in an existing writable folder, ending in ``suffix`` (the
    format it is written in) when given."""
    require(bool(path), f"{flag} needs a file name")
    try:
        out = Path(path).expanduser().resolve()
    except (OSError, RuntimeError) as exc:
        raise SoabenchError(f"cannot resolve {flag} {path!r}: {exc}") from None
    require(not out.is_dir(), f"{flag} {path!r} is a folder; give a file name")
    require(
        suffix is None or out.suffix.lower() == suffix,
        f"{flag} {path!r} must end in {suffix}: the file is written in that format",
    )
    parent = out.parent
    if not parent.exists():
        anc = parent
        while not anc.exists():
            anc = anc.parent
        require(anc.is_dir(), f"{flag} {path!r} lies under {str(anc)!r}, which is a file, not a folder")
        raise SoabenchError(f"output folder {str(parent)!r} does not exist for {path!r}")
    require(parent.is_dir(), f"{flag} {path!r} lies under {str(parent)!r}, which is a file, not a folder")
    probe_writable(parent, f"{flag} {path!r}: the folder {str(parent)!r}")
    return out
