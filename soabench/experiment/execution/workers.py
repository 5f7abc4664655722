"""Process-pool workers die with their driver and leave Ctrl-C to it.

:func:`init_worker` runs first in every worker process of
:class:`~soabench.experiment.execution.executors.PoolExecutor`:

* on Linux it asks the kernel for SIGKILL when the parent dies (``prctl(PR_SET_PDEATHSIG)`` via ctypes), so a
  driver killed by SIGKILL (or the OOM killer) leaves no orphan simulating on; elsewhere a daemon thread polls
  the parent pid once a second and exits the worker when it changes;
* it ignores SIGINT: Ctrl-C reaches the whole foreground process group, and only the driver should act on it (it
  stops the pool and prints one line with the resume hint), so no worker prints a KeyboardInterrupt traceback;
* given a notes folder, it keeps there one small file per worker saying which trial (and which plugin run) it works
  on (:func:`note_activity`), so the driver can name them when a worker dies (:func:`last_activity`).

A Dask LocalCluster's worker processes are started inside :func:`sigint_ignored_by_children` for the same reason.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import threading
import time
from collections.abc import Iterator

from soabench.processes import die_with_parent

#: what a worker notes while no plugin runs
OWN_CODE = "soabench's own code (no plugin was running)"
_NOTES: list[str | None] = [None]  #: this worker's notes folder (None: not a pool worker, nothing is noted)


def _watch_parent(parent: int, period: float = 1.0) -> None:
    while True:
        time.sleep(period)
        if os.getppid() != parent:
            os._exit(1)


def init_worker(parent: int | None = None, notes: str | None = None) -> None:
    """Initializer of a pool worker; ``parent`` is the pid of the worker's parent, which the worker must not outlive;
    ``notes``: the folder of :func:`note_activity`."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _NOTES[0] = notes
    parent = os.getppid() if parent is None else parent
    armed = die_with_parent()
    if os.getppid() != parent:  # the parent died before the request took effect
        os._exit(1)
    if not armed:
        threading.Thread(target=_watch_parent, args=(parent,), daemon=True, name="soabench-parent-watch").start()


@contextlib.contextmanager
def sigint_ignored_by_children() -> Iterator[None]:
    """Ignore SIGINT while worker processes are started (e.g. a Dask LocalCluster's), so they inherit the ignored
    disposition (it survives fork and exec, and Python then installs no KeyboardInterrupt handler): Ctrl-C stays
    the driver's business, and no worker prints a traceback. Restored on exit; a no-op outside the main thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def note_activity(trial: int, doing: str) -> None:
    """Note that this worker now runs ``doing`` in trial ``trial`` (a no-op outside a pool worker with notes)."""
    folder = _NOTES[0]
    if folder is None:
        return
    try:
        with open(os.path.join(folder, str(os.getpid())), "w", encoding="utf-8") as f:
            f.write(json.dumps({"trial": int(trial), "doing": doing}))
    except OSError:  # a note is a courtesy; the trial does not depend on it
        pass


def last_activity(folder: str, pid: int) -> dict | None:
    """What worker ``pid`` noted last (``{"trial", "doing"}``), or None."""
    try:
        with open(os.path.join(folder, str(pid)), encoding="utf-8") as f:
            note = json.loads(f.read())
    except (OSError, ValueError):
        return None
    return note if isinstance(note, dict) and isinstance(note.get("trial"), int) else None
