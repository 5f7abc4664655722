"""A one-line notice on stderr while the compiled filter kernels are prepared the first time (DESIGN: no silent
pauses).

The GM-PHD kernels (:mod:`soabench.gmphd.kernels`, :mod:`soabench.gmphd.cycle`) are compiled by numba on their
first call after installation (tens of seconds) and loaded from numba's cache afterwards (about a second). The
first filter step of each kind (fused or array path, with or without newborn terms) in a process runs inside
:func:`first_use_notice`: if it has not returned after ``delay`` seconds, one line says what is happening. A step
that loads cached code in time prints nothing.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Hashable, Iterator
from contextlib import contextmanager

MESSAGE = (
    "soabench: compiling the GM-PHD filter kernels with numba (once after installation, one to two minutes; "
    "cached afterwards) ..."
)
DELAY = 2.0  #: seconds of silence before the notice
_done: set[Hashable] = set()


def ready(key: Hashable) -> bool:
    """True once a step of kind ``key`` has completed in this process."""
    return key in _done


@contextmanager
def first_use_notice(key: Hashable, delay: float | None = None) -> Iterator[None]:
    """Run the block; print :data:`MESSAGE` to stderr once if it is still running after ``delay`` seconds."""
    timer = threading.Timer(DELAY if delay is None else delay, lambda: print(MESSAGE, file=sys.stderr, flush=True))
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        _done.add(key)
