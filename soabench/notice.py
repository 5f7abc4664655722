"""A one-line notice on stderr while the compiled filter kernels are prepared the first time, instead of a silent
pause.

The GM-PHD kernels (:mod:`soabench.gmphd.kernels`, :mod:`soabench.gmphd.cycle`) are compiled by numba on their
first call after installation (tens of seconds) and loaded from numba's cache afterwards (about a second); so are
the metric and scan-geometry kernels (:mod:`soabench.metrics_kernels`, :mod:`soabench.geometry_kernels`, seconds).
The first filter step of each kind (fused or array path, with or without newborn terms) and the first call of each
of the others in a process run inside :func:`first_use_notice` (:func:`announced`): if it has not returned after
``delay`` seconds, one line says what is happening (once per process), and a second one the seconds it took when it
ends. A call that loads cached code in time prints nothing: the delay grows with the machine's load (loading takes
about a second of CPU, so many seconds of wall time on a machine shared many times over).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable, Hashable, Iterator
from contextlib import contextmanager
from typing import Any, TextIO

#: the one wording of every compile notice (this first-use notice and the run's compile ahead,
#: :mod:`soabench.kernel_warmup`)
MESSAGE = (
    "soabench: compiling the filter, metric and scan-geometry kernels (once per machine and version of the "
    "kernels; cached afterwards) ..."
)
#: off a terminal, a long wait (a run's trials, the kernels' compilation) writes a line at least this often (s)
LINE_INTERVAL_S = 10.0
DELAY = 3.0  #: seconds of silence before the notice on an idle machine (longer than loading cached kernels takes)
_done: set[Hashable] = set()
_printed = threading.Event()  #: the notice is printed at most once per process


def is_terminal(stream: TextIO) -> bool:
    """Whether ``stream`` is a terminal (a redrawn bar) rather than a file or a pipe (a line now and then)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def load_delay() -> float:
    """:data:`DELAY` times the machine's load per core (1-minute load average / cores) when that exceeds 1: the
    wall time that loading the cached kernels can take while other work shares the cores."""
    try:
        per_core = os.getloadavg()[0] / (os.cpu_count() or 1)
    except (AttributeError, OSError):  # no load average (Windows)
        per_core = 1.0
    return DELAY * max(1.0, per_core)


def _print_once() -> None:
    if not _printed.is_set():
        _printed.set()
        print(MESSAGE, file=sys.stderr, flush=True)


def silence() -> None:
    """Never print :data:`MESSAGE` in this process (compilation is announced elsewhere, once per run:
    :mod:`soabench.kernel_warmup`)."""
    _printed.set()


def ready(key: Hashable) -> bool:
    """True once a step of kind ``key`` has completed in this process."""
    return key in _done


@contextmanager
def first_use_notice(key: Hashable, delay: float | None = None) -> Iterator[None]:
    """Run the block; print :data:`MESSAGE` to stderr if it is still running after ``delay`` seconds (default:
    :func:`load_delay`; at most once per process), and then, when the block ends, the seconds it took."""
    t0 = time.monotonic()
    fired = threading.Event()

    def fire() -> None:
        if not _printed.is_set():
            fired.set()
            _print_once()

    timer = threading.Timer(load_delay() if delay is None else delay, fire)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        _done.add(key)
        if fired.is_set():
            took = time.monotonic() - t0
            print(f"soabench: compiled in {took:.0f} s (cached for later runs)", file=sys.stderr, flush=True)


def announced(key: Hashable, fn: Callable[..., Any], *args: Any) -> Any:
    """``fn(*args)``, inside :func:`first_use_notice` until a call of kind ``key`` has completed in this process
    (the compiled metric and scan-geometry kernels: their first call may compile them)."""
    if key in _done:
        return fn(*args)
    with first_use_notice(key):
        return fn(*args)
