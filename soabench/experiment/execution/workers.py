"""Process-pool workers die with their driver and leave Ctrl-C to it.

:func:`init_worker` runs first in every worker process of
:class:`~soabench.experiment.execution.executors.PoolExecutor`:

* on Linux it asks the kernel for SIGKILL when the parent dies (``prctl(PR_SET_PDEATHSIG)`` via ctypes), so a
  driver killed by SIGKILL (or the OOM killer) leaves no orphan simulating on; elsewhere a daemon thread polls
  the parent pid once a second and exits the worker when it changes;
* it ignores SIGINT: Ctrl-C reaches the whole foreground process group, and only the driver should act on it (it
  stops the pool and prints one line with the resume hint), so no worker prints a KeyboardInterrupt traceback;
* given a notes folder, it keeps there one small file per worker saying which trial (and which plugin run) it works
  on (:func:`~soabench.experiment.trial.activity.note_activity`), so the driver can name them when a worker dies
  (:func:`~soabench.experiment.trial.activity.last_activity`).

A Dask LocalCluster's worker processes are started inside :func:`sigint_ignored_by_children` for the same reason.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Iterator

from soabench.experiment.trial.activity import keep_notes_in
from soabench.processes import die_with_parent


def _watch_parent(parent: int, period: float = 1.0) -> None:
    while True:
        time.sleep(period)
        if os.getppid() != parent:
            os._exit(1)


def init_worker(parent: int | None = None, notes: str | None = None) -> None:
    """Initializer of a pool worker; ``parent`` is the pid of the worker's parent, which the worker must not outlive;
    ``notes``: the folder of :func:`~soabench.experiment.trial.activity.note_activity`."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    keep_notes_in(notes)
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
