"""How the harness calls a plugin: on a thread of its own, within a time budget, with a private copy of the scan.

A plugin (a birth model or tracker that is not one of the six built-in birth models; docs/user-guide/own-tracker.md,
"When a plugin fails") can fail in ways an ``except Exception`` does not see. Each guarded run
(:func:`soabench.experiment.trial.trial.run_trial`) therefore makes its calls through a :class:`PluginCalls`:

* every call (the constructor, each scan's step) runs on a daemon thread of the run and must return within
  ``experiment.plugin_budget`` seconds; a call that takes longer fails the run (the thread is abandoned, and asked
  to stop at its next Python instruction);
* whatever the plugin raises (``SystemExit`` from ``sys.exit``, ``KeyboardInterrupt``, any exception) and a call of
  ``os._exit`` on its thread become a :class:`PluginFailed` with the plugin's traceback, so the trial records the run
  as failed and goes on; a real Ctrl-C reaches the waiting thread, not the plugin's, and still stops the run;
* what the plugin prints goes to stderr, so stdout carries only the command's own output (the summary);
* the scan it is given is a private copy (:func:`private_scan`): whatever it changes, every other method of the
  trial reads the scan the sensor produced (common random numbers, docs/method.md §5.8).

The built-in birth models are called directly (no thread, no copy): an error there is a bug of soabench.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import queue
import sys
import threading
import traceback
from collections.abc import Callable
from typing import Any

import numpy as np

_REAL_EXIT = os._exit
_PLUGIN_THREADS: set[int] = set()  #: idents of the threads that run plugin calls in this process
_CACHE_KEYS = ("_once", "_occluder_index")  #: per-scan caches of a Scan, never handed to a plugin


class PluginFailed(Exception):
    """A plugin call raised, tried to end the process, or ran past its budget; ``traceback`` is the plugin's."""

    def __init__(self, message: str, tb: str = "") -> None:
        super().__init__(message)
        self.message = message
        self.traceback = tb


class PluginExit(BaseException):
    """Raised in place of ``os._exit(code)`` on a plugin's thread (the process must outlive the plugin)."""


class _PluginTimeout(BaseException):
    """Raised asynchronously on a plugin's thread that ran past its budget (stops a loop of Python code)."""


def _guarded_exit(code: int) -> None:
    """``os._exit`` while plugins run: a plugin's thread gets :class:`PluginExit`, every other caller exits."""
    if threading.get_ident() in _PLUGIN_THREADS:
        raise PluginExit(f"the plugin called os._exit({code})")
    _REAL_EXIT(code)


def _guard_exit() -> None:
    """Route ``os._exit`` through :func:`_guarded_exit` in this process (idempotent)."""
    if os._exit is not _guarded_exit:
        os._exit = _guarded_exit


# a forked child (a pool worker, or a process a plugin forks) runs none of its parent's plugin calls: its os._exit
# exits unless it starts plugin threads of its own
os.register_at_fork(after_in_child=_PLUGIN_THREADS.clear)


def _describe(exc: BaseException) -> str:
    if isinstance(exc, SystemExit):
        return f"the plugin called sys.exit({exc.code!r})"
    if isinstance(exc, KeyboardInterrupt):
        return "the plugin raised KeyboardInterrupt"
    if isinstance(exc, PluginExit):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"


class _Thread(threading.Thread):
    """A daemon thread that runs the calls it is handed, one at a time, and hands back (ok, value or exception)."""

    def __init__(self, name: str) -> None:
        super().__init__(daemon=True, name=name)
        self.jobs: queue.SimpleQueue = queue.SimpleQueue()
        self.results: queue.SimpleQueue = queue.SimpleQueue()

    def run(self) -> None:
        _PLUGIN_THREADS.add(threading.get_ident())
        try:
            while (job := self.jobs.get()) is not None:
                fn, args = job
                try:
                    self.results.put((True, fn(*args)))
                except BaseException as exc:  # noqa: BLE001 - everything a plugin raises is its failure
                    self.results.put((False, exc))
                del job, fn, args
        except _PluginTimeout:  # the stop request arrived after the call: nobody waits for this thread any more
            pass
        finally:
            _PLUGIN_THREADS.discard(threading.get_ident())


class PluginCalls:
    """The calls of one plugin run (see the module docstring); use as a context manager.

    Args:
        budget: seconds each call may take (0: no limit).
        label: what the plugin is, for its thread's name (e.g. ``tracker 'pkg:T'``).
        where: which run it is (e.g. ``trial 3, clutter 3, mode static``), for the line said on stderr the moment a
            call passes its budget (the failure record follows at the end of the trial).
    """

    def __init__(self, budget: float, label: str = "plugin", where: str = "") -> None:
        self.budget = float(budget)
        self.label = label
        self.where = where
        self._thread: _Thread | None = None

    def __enter__(self) -> PluginCalls:
        _guard_exit()
        self._thread = _Thread(f"soabench {self.label}")
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._thread is not None:
            self._thread.jobs.put(None)  # ends the thread once its call returns (at once when it is idle)
            self._thread = None

    def __call__(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)`` on the plugin's thread; :class:`PluginFailed` if it raised, exited or ran out of time."""
        thread = self._thread
        if thread is None:
            raise PluginFailed(f"the {self.label} was stopped by an earlier failure")
        thread.jobs.put((fn, args))
        with contextlib.redirect_stdout(sys.stderr):
            try:
                ok, value = thread.results.get(timeout=self.budget if self.budget > 0 else None)
            except queue.Empty:
                run = f" ({self.where})" if self.where else ""
                print(
                    f"soabench: {self.label}{run} passed its budget of {self.budget:g} s (experiment.plugin_budget) "
                    "in one call: stopped; this run of it fails, the trial goes on",
                    file=sys.stderr,
                    flush=True,
                )
                where = self._abandon(thread)
                raise PluginFailed(
                    f"the call took longer than its budget of {self.budget:g} s (experiment.plugin_budget)", where
                ) from None
        if ok:
            return value
        tb = "".join(traceback.format_exception(value))
        raise PluginFailed(_describe(value), tb)

    def _abandon(self, thread: _Thread) -> str:
        """Leave a thread that ran past its budget: ask it to stop at its next Python instruction, never wait.
        Returns where it was (its stack, as a traceback reads)."""
        self._thread = None
        frame = sys._current_frames().get(thread.ident or -1)
        where = "".join(["Stack of the plugin's call when its budget ran out:\n", *traceback.format_stack(frame)])
        if thread.ident is not None:
            ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(thread.ident), ctypes.py_object(_PluginTimeout))
        thread.jobs.put(None)
        return where if frame is not None else ""


def _private(value: Any) -> Any:
    """A copy of ``value`` that shares nothing mutable with it: arrays and lists copied, dataclasses rebuilt."""
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, list):
        return [_private(v) for v in value]
    if isinstance(value, tuple):
        return tuple(_private(v) for v in value)
    if hasattr(type(value), "__dataclass_fields__"):  # a dataclass instance (Obstacles)
        return _rebuilt(value)
    return value  # numbers, strings, shapely geometries and deferred regions (immutable to a reader)


def _rebuilt(obj: Any, skip: tuple[str, ...] = ()) -> Any:
    new = object.__new__(type(obj))
    new.__dict__.update({k: _private(v) for k, v in obj.__dict__.items() if k not in skip})
    return new


def private_scan(scan: Any) -> Any:
    """A copy of ``scan`` for one plugin: equal field by field, sharing no array, list or cache with the original,
    so nothing the plugin changes reaches another method. Omega_k is handed over as it is (deferred or built; a
    shapely geometry cannot be changed)."""
    if not hasattr(scan, "__dict__"):
        return scan
    return _rebuilt(scan, _CACHE_KEYS)
