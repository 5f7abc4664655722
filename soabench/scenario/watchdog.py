"""A SUMO run that cannot hang: libsumo in a forked child, watched for progress (docs/user-guide/sumo.md "Stalls").

libsumo runs inside the calling process's C++ code, where neither Ctrl-C nor a timer can interrupt a call that never
returns (SUMO 1.28's jupedsim, for one, never returns from inserting a pedestrian on some networks).
:func:`run_watched` therefore runs the simulation in a forked child process that reports its progress (a counter
in a shared page, bumped after every SUMO step and insertion) and sends its result back through a pipe. A child
whose counter stands still for :func:`stall_timeout` seconds is killed, and the caller gets a
:class:`~soabench.errors.SoabenchError` whose one line names where SUMO stopped, so a run records the trial as
failed and goes on. The child computes exactly what the caller would have (same code, same seeds, the result
pickled losslessly), so results are bit-identical to an unwatched run.

Where ``fork`` does not exist (Windows) the simulation runs in the calling process, unwatched.
"""

from __future__ import annotations

import math
import mmap
import os
import pickle
import select
import signal
import struct
import time
import traceback
import warnings
from collections.abc import Callable
from typing import Any

from soabench.errors import SoabenchError
from soabench.processes import die_with_parent

#: environment variable holding the stall limit in seconds (``inf`` waits for ever).
STALL_ENV = "SOABENCH_SUMO_TIMEOUT"
#: default stall limit (s): loading a large OSM network takes seconds, a normal SUMO step milliseconds.
DEFAULT_STALL_S = 60.0

#: what the child is doing when it reports progress (the stall message names the last one).
STARTING, INSERTING, STEPPING = 0, 1, 2
_PHASES = {STARTING: "starting (loading the network)", INSERTING: "inserting vehicles and pedestrians"}
_STATE = struct.Struct("ddd")  # progress counter, phase, simulated time (s)


def stall_timeout() -> float:
    """The stall limit in seconds: ``$SOABENCH_SUMO_TIMEOUT`` if set (a positive number or ``inf``), else
    :data:`DEFAULT_STALL_S`."""
    text = os.environ.get(STALL_ENV, "").strip()
    if not text:
        return DEFAULT_STALL_S
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not value > 0:
        raise SoabenchError(f"{STALL_ENV} = {text!r} is not allowed; give a number of seconds > 0 (or inf)")
    return value


class Progress:
    """The child's side: :meth:`beat` after every unit of work (a SUMO step, an insertion)."""

    def __init__(self, page: mmap.mmap | None = None):
        self._page = page
        self._count = 0.0

    def beat(self, phase: int, t: float = 0.0) -> None:
        """Report progress in ``phase`` at simulated time ``t`` (s)."""
        if self._page is not None:
            self._count += 1.0
            _STATE.pack_into(self._page, 0, self._count, float(phase), float(t))


def _where(phase: int, t: float) -> str:
    return f"at simulated t = {t:.1f} s" if phase == STEPPING else f"while {_PHASES.get(phase, 'starting')}"


def run_watched(fn: Callable[..., Any], args: tuple, describe: str, hint: str = "") -> Any:
    """``fn(*args, progress=Progress)`` in a forked child; its result, or its error re-raised here.

    Args:
        fn: the simulation; it calls ``progress.beat`` after every unit of work.
        args: its arguments (the child inherits them; nothing is pickled on the way in).
        describe: what runs, for messages (e.g. ``"SUMO on 'grid.net.xml' (pedestrian model 'jupedsim')"``).
        hint: appended to the stall message (what to change so it does not stall).

    Raises:
        SoabenchError: the child raised one (same message), made no progress for :func:`stall_timeout` seconds,
            or died without a result.
    """
    limit = stall_timeout()
    if not hasattr(os, "fork"):  # pragma: no cover - Windows
        return fn(*args, progress=Progress())

    page = mmap.mmap(-1, _STATE.size)  # anonymous and shared: the child's writes are seen here
    read_fd, write_fd = os.pipe()
    with warnings.catch_warnings():  # the child runs only SUMO and numpy; it takes no lock another thread holds
        warnings.simplefilter("ignore", DeprecationWarning)
        pid = os.fork()
    if pid == 0:  # the child
        _child(read_fd, write_fd, page, fn, args, die_with_parent)
    os.close(write_fd)
    finished = False
    try:
        data = _collect(read_fd, page, limit, describe, hint)
        finished = True
    finally:
        os.close(read_fd)
        page.close()
        ended = _reap(pid, kill=not finished)
    if not data:
        raise SoabenchError(f"{describe} stopped without a result (the SUMO process ended with {ended})")
    kind, *rest = pickle.loads(data)  # our own child's bytes: never data read from a file
    if kind == "ok":
        return rest[0]
    if kind == "soabench":
        raise SoabenchError(rest[0])
    raise RuntimeError(f"{rest[0]} (in the SUMO process)\n{rest[1]}")


def _child(
    read_fd: int, write_fd: int, page: mmap.mmap, fn: Callable[..., Any], args: tuple, pdeathsig: Callable[[], bool]
) -> None:
    """Run ``fn`` and write its pickled outcome to ``write_fd``; never returns (``os._exit``)."""
    code = 0
    try:
        os.close(read_fd)
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's; it kills this process
        pdeathsig()  # dies with its parent (Linux)
        try:
            out: tuple = ("ok", fn(*args, progress=Progress(page)))
        except SoabenchError as exc:
            out = ("soabench", str(exc))
        except BaseException as exc:
            out = ("error", f"{type(exc).__name__}: {exc}", traceback.format_exc())
        data = memoryview(pickle.dumps(out, protocol=pickle.HIGHEST_PROTOCOL))
        while data:
            data = data[os.write(write_fd, data) :]
    except BaseException:
        code = 1
    finally:
        os._exit(code)


def _collect(fd: int, page: mmap.mmap, limit: float, describe: str, hint: str) -> bytes:
    """Read the child's result; kill it when its progress counter stands still for ``limit`` seconds."""
    chunks: list[bytes] = []
    seen, last = -1.0, time.monotonic()
    while True:
        ready, _, _ = select.select([fd], [], [], 0.2)
        now = time.monotonic()
        if ready:
            chunk = os.read(fd, 1 << 20)
            if not chunk:
                return b"".join(chunks)
            chunks.append(chunk)
            last = now
            continue
        count, phase, t = _STATE.unpack_from(page, 0)
        if count != seen:
            seen, last = count, now
        elif now - last > limit:
            raise SoabenchError(
                f"{describe} made no progress for {limit:g} s {_where(int(phase), t)} and was stopped"
                + (f"; {hint}" if hint else "")
                + f" (wait longer with {STALL_ENV}=SECONDS)"
            )


def _reap(pid: int, kill: bool) -> str:
    """Wait for the child (killed first if ``kill``), so no zombie is left; how it ended, in words."""
    if kill:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:  # pragma: no cover - already gone
            pass
    _, status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        return f"signal {signal.Signals(os.WTERMSIG(status)).name}"
    return f"exit status {os.waitstatus_to_exitcode(status)}"
