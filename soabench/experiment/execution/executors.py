"""Executors: where the tasks of a run go (docs/method.md §5.8): this process, a local process pool, or Dask.

Every executor has ``results(spec, items)``, yielding ``(item, record)`` as tasks finish, and ``close(abort)``.
A task spec names its task function as ``spec.task_fn`` (a trial of a run folder:
:class:`soabench.experiment.execution.runner.TaskSpec`; a group of run folders:
:mod:`soabench.experiment.execution.grouped`; a
report's figures: :mod:`soabench.figures.drawing`) and is small and picklable; the executor calls
``spec.task_fn(item, spec)`` in a worker. libsumo is a process singleton (docs/user-guide/sumo.md): every executor
runs one task at a time per process. A task that raises, or a worker that dies, becomes a failure record of that
item (:func:`failure_record`); the run goes on.
"""

from __future__ import annotations

import logging
import os
import shutil
import signal
import socket
import tempfile
import time
import traceback
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from soabench.errors import SoabenchError, require
from soabench.experiment.execution.options import check_scheduler_address, check_workers
from soabench.experiment.execution.workers import init_worker, sigint_ignored_by_children
from soabench.experiment.trial.activity import last_activity
from soabench.seeding import trial_seeds


def failure_record(trial: int, base_seed: int, error: str, tb: str = "") -> dict:
    """A failed trial: its seeds (to reproduce it with ``--seed S --trial N``) and the error."""
    seeds = trial_seeds(base_seed, trial)
    return {
        "trial": int(trial),
        "status": "failed",
        "seed": int(base_seed),
        "sumo_seed": int(seeds.sumo_seed),
        "error": error,
        "traceback": tb,
    }


class SerialExecutor:
    """Trials one after another in this process."""

    name = "serial"
    n_workers = 1
    local = True  #: its workers run on this machine and read its files

    def results(self, spec: Any, trials: Sequence[int]) -> Iterator[tuple[int, dict]]:
        for t in trials:
            yield t, spec.task_fn(t, spec)

    def close(self, abort: bool = False) -> None:
        pass


def _exit_code(proc: Any, timeout: float = 5.0, settle: float = 1.0) -> int | None:
    """The exit code of a pool's worker process once it ended (None: still running after ``timeout`` s). The pool's
    own thread may reap the process first: its status then reaches the shared process object a moment after the
    join returns, so a dead worker's code is read again for up to ``settle`` s rather than reported as running."""
    proc.join(timeout=timeout)
    until = time.monotonic() + settle
    while proc.exitcode is None and time.monotonic() < until:
        time.sleep(0.01)
    return proc.exitcode


class PoolExecutor:
    """A ``ProcessPoolExecutor`` of one-thread processes; at most ``2 * workers`` trials in flight."""

    name = "process-pool"
    local = True  #: its workers run on this machine and read its files

    def __init__(self, workers: int):
        self.n_workers = int(workers)
        self._pool: ProcessPoolExecutor | None = None
        self._generation = 0  # incremented whenever a broken pool is replaced
        self._notes: str | None = None  # the workers' notes folder (soabench.experiment.trial.activity.note_activity)
        self._procs: dict[int, Any] = {}  # pid -> process of the current pool (its exit code names a death)
        self._lost: dict[int, dict[int, str]] = {}  # pool generation -> trial -> why it was lost

    def _get_pool(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._notes = tempfile.mkdtemp(prefix="soabench-workers-")
            self._procs = {}
            self._pool = ProcessPoolExecutor(
                max_workers=self.n_workers, initializer=init_worker, initargs=(None, self._notes)
            )
        return self._pool

    def _submit(self, spec: Any, t: int) -> Any:
        fut = self._get_pool().submit(spec.task_fn, t, spec)
        self._procs.update(getattr(self._pool, "_processes", None) or {})
        return fut

    def _lost_trials(self) -> dict[int, str]:
        """Why each trial in flight was lost when the pool broke: the worker that died (its exit code or signal)
        and what it was running, from the workers' notes; a trial whose worker the pool stopped afterwards says so."""
        notes = {}
        for pid, proc in self._procs.items():
            code = _exit_code(proc)
            note = last_activity(self._notes, pid) if self._notes else None
            if note is not None:
                notes[pid] = (code, note)
        stopped = -signal.SIGTERM  # what the pool does to the other workers once one died
        died = [f"trial {n['trial']} ({n['doing']})" for code, n in notes.values() if code != stopped]
        out = {}
        for code, note in notes.values():
            t = note["trial"]
            if code == stopped and died:
                out[t] = f"lost when a worker process died (the worker of {died[0]}); the pool stopped this one"
            else:
                how = "still running" if code is None else _exit_text(code)
                out[t] = f"worker process died ({how}) in trial {t} while running {note['doing']}"
        return out

    def results(self, spec: Any, trials: Sequence[int]) -> Iterator[tuple[int, dict]]:
        base_seed = int(spec.base_seed)
        queue = iter(trials)  # consumed lazily: a huge to-do list is never built in memory
        pending: dict = {}  # future -> (trial, pool generation)
        exhausted = False
        try:
            while not exhausted or pending:
                while not exhausted and len(pending) < 2 * self.n_workers:
                    t = next(queue, None)
                    if t is None:
                        exhausted = True
                        break
                    try:
                        fut = self._submit(spec, t)
                    except BrokenProcessPool:  # the pool broke since the last submit: start a fresh one
                        self.close(abort=True)
                        fut = self._submit(spec, t)
                    pending[fut] = (t, self._generation)
                done, _ = wait(list(pending), return_when=FIRST_COMPLETED)
                for fut in sorted(done, key=lambda f: pending[f][0]):
                    t, gen = pending.pop(fut)
                    try:
                        rec = fut.result()
                    except BrokenProcessPool:  # a worker died: every trial in flight on that pool is lost
                        if gen == self._generation:
                            self._lost[gen] = self._lost_trials()
                            self.close(abort=True)
                        why = self._lost.get(gen, {}).get(t, f"worker process died in trial {t} (BrokenProcessPool)")
                        rec = failure_record(t, base_seed, why)
                    except Exception as exc:
                        rec = failure_record(t, base_seed, f"{type(exc).__name__}: {exc}", traceback.format_exc())
                    yield t, rec
        finally:
            for fut in pending:
                fut.cancel()

    def close(self, abort: bool = False) -> None:
        pool, self._pool = self._pool, None
        if pool is None:
            return
        self._generation += 1
        if abort:
            procs = list(getattr(pool, "_processes", {}).values())  # the pool's own children, by process object
            pool.shutdown(wait=False, cancel_futures=True)
            for p in procs:
                if p.is_alive():
                    p.terminate()
            for p in procs:
                p.join(timeout=5)
        else:
            pool.shutdown(wait=True)
        if self._notes is not None:
            shutil.rmtree(self._notes, ignore_errors=True)
            self._notes = None


def _exit_text(code: int) -> str:
    """``killed by signal SIGKILL`` or ``exit code 3`` for a process's exit code."""
    if code < 0:
        try:
            return f"killed by signal {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


class DaskExecutor:
    """Trials as Dask futures on a distributed cluster (existing scheduler or a LocalCluster we start)."""

    name = "dask"
    local = False  #: its workers may run elsewhere and not see this machine's files

    def __init__(self, scheduler: str | None = None, local_workers: int | None = None):
        try:
            import distributed
        except ImportError:
            raise SoabenchError(
                "a Dask executor (a scheduler, or Dask local workers) needs Dask distributed, which is not "
                "installed: pip install soabench[dask]"
            ) from None
        self._distributed = distributed
        self._cluster = None
        if scheduler is None:
            n = int(local_workers or os.cpu_count() or 1)
            with sigint_ignored_by_children():  # Ctrl-C is the driver's: no worker tracebacks
                self._cluster = distributed.LocalCluster(
                    n_workers=n,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    # the cluster's own logs stay quiet: a worker whose heartbeat meets the scheduler already closed
                    # (after Ctrl-C, on a loaded machine) logs an error with a traceback; a trial that fails on a
                    # worker is reported by the run itself (its failure record)
                    silence_logs=logging.CRITICAL,
                )
            self.address = self._cluster.scheduler_address
            self.name = f"dask-local({n})"
        else:
            self.address = scheduler
            self.name = f"dask({scheduler})"
            _probe_scheduler(scheduler)
        try:
            self.client = distributed.Client(self.address, timeout="30s", set_as_default=False)
        except OSError as exc:
            self.close()
            raise SoabenchError(f"cannot connect to the Dask scheduler {self.address!r}: {exc}") from None
        self.n_workers = max(1, len(self.client.scheduler_info().get("workers", {})))

    def results(self, spec: Any, trials: Sequence[int]) -> Iterator[tuple[int, dict]]:
        base_seed = int(spec.base_seed)
        token = f"{os.getpid()}-{time.time_ns()}"
        futures = {}
        queue = iter(trials)  # submitted in a window of 4 per worker: a huge to-do list is never built in memory
        done_iter = self._distributed.as_completed(loop=self.client.loop)

        def submit_next() -> None:
            t = next(queue, None)
            if t is not None:
                f = self.client.submit(spec.task_fn, t, spec, key=f"soabench-trial-{t:05d}-{token}", pure=False)
                futures[f.key] = (f, t)
                done_iter.add(f)

        for _ in range(max(8, 4 * self.n_workers)):
            submit_next()
        try:
            for fut in done_iter:
                _, t = futures.pop(fut.key)
                submit_next()
                try:
                    rec = fut.result()
                except Exception as exc:  # KilledWorker, lost connection, ...
                    rec = failure_record(t, base_seed, f"{type(exc).__name__}: {exc}")
                yield t, rec
        finally:
            left = [f for f, _ in futures.values()]
            if left:
                try:
                    self.client.cancel(left)
                except Exception:  # pragma: no cover - best effort on shutdown
                    pass

    def close(self, abort: bool = False) -> None:
        client = getattr(self, "client", None)
        if client is not None:
            client.close()
            self.client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None


def _probe_scheduler(address: str, timeout: float = 10.0) -> None:
    """A plain TCP connect to a ``tcp://`` scheduler first: a refused or unroutable address fails in a moment
    with one line, instead of Dask's connection retries until its timeout."""
    scheme, _, rest = address.rpartition("://")
    if scheme not in ("", "tcp"):
        return
    host, _, port = rest.rpartition(":")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except (OSError, ValueError) as exc:
        raise SoabenchError(f"cannot connect to the Dask scheduler {address!r}: {exc}") from None


def open_executor(workers: int | None = None, scheduler: str | None = None, dask_local: bool = False, n_trials=None):
    """The executor for the given options (see the module docstring); the caller must ``close()`` it."""
    require(not (scheduler and dask_local), "--scheduler and --dask local are alternatives; give one of them")
    check_workers(workers)
    check_scheduler_address(scheduler)
    if scheduler or dask_local:
        return DaskExecutor(scheduler=scheduler, local_workers=workers)
    n = workers or os.cpu_count() or 1
    if n_trials is not None:
        n = min(n, max(1, n_trials))
    return SerialExecutor() if n == 1 else PoolExecutor(n)
