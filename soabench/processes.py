"""A child process that must not outlive its parent (docs/development.md: small helpers every layer may use).

Used by the run's pool workers and by the SUMO watchdog's child: on Linux the kernel sends SIGKILL when the parent
dies (``prctl(PR_SET_PDEATHSIG)`` via ctypes), so a driver killed by SIGKILL (or the OOM killer) leaves no orphan.
"""

from __future__ import annotations

import ctypes
import signal
import sys

PR_SET_PDEATHSIG = 1  #: from <linux/prctl.h>


def die_with_parent() -> bool:
    """Ask Linux to SIGKILL this process when its parent exits; False where that is unavailable."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
    except (OSError, AttributeError):  # pragma: no cover - no libc symbol
        return False
