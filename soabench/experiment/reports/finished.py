"""A finished run's report, written by one function for every command and campaign (docs/development.md "Layers").

The run loop (:func:`soabench.experiment.execution.runner.execute`) runs the trials and returns a
:class:`~soabench.experiment.execution.runner.RunOutcome` whose ``finished`` record says that every trial was
attempted; :func:`report_run` then merges the folder's tables (adopting a worker's merge,
:mod:`soabench.experiment.reports.premerge`), writes ``summary.json``, ``summary.md`` and the figures
(:func:`soabench.experiment.reports.report.write_report`) and ``report.html``. :func:`run` is both, the way
``soabench run``, the sweeps' points, the study's parts, the sensitivity runs, the check suites and
``soabench.api.run`` run a run.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Sequence
from typing import Any

from soabench.config import Config
from soabench.errors import Interrupted
from soabench.experiment.execution.executors import PoolExecutor
from soabench.experiment.execution.runner import ALONE, BATCH_FIELDS, Batch, RunOutcome, RunRequest, execute
from soabench.experiment.reports import premerge, report
from soabench.experiment.reports.html import refresh_report
from soabench.experiment.runs.store import merge_args
from soabench.figures.drawing import parallel, pool_open


def run(request: RunRequest, batch: Batch = ALONE) -> RunOutcome:
    """Run (or finish) the run of ``request`` (:func:`~soabench.experiment.execution.runner.execute`) and, once
    every trial was attempted, write its report (:func:`report_run`)."""
    return report_run(execute(request, batch))


def run_experiment(
    config: Config | None, net: str, polys: Sequence[str] = (), scenario: str | None = None, **fields: Any
) -> RunOutcome:
    """:func:`run` of ``RunRequest(config, net, polys, scenario, **fields)``; ``fields`` are the other
    :class:`~soabench.experiment.execution.runner.RunRequest` fields and the
    :class:`~soabench.experiment.execution.runner.Batch` fields (``executor``, ``defer``, ``run_trials``)."""
    batch = Batch(**{k: fields.pop(k) for k in BATCH_FIELDS if k in fields})
    return run(RunRequest(config, net, tuple(polys), scenario, **fields), batch)


def report_run(outcome: RunOutcome) -> RunOutcome:
    """Write the report of a run whose every trial was attempted (``outcome.finished``; nothing otherwise): the
    merged tables, ``summary.json``, ``summary.md`` and the figures, ``report.html``; the outcome then carries the
    summary's Markdown and the failed method runs. Ctrl-C raises :class:`~soabench.errors.Interrupted` naming the
    resume (the trials stay on disk)."""
    finished = outcome.finished
    if finished is None:
        return outcome
    store = finished.store
    try:
        # a study's workers may have merged it already; the figures read the step columns the merge kept
        premerge.merge(store, *merge_args(finished.config), step_columns=finished.figures)
        with _figure_pool(finished.workers, finished.executor):
            outcome.summary_markdown = report.write_report(store.run_dir, figures=finished.figures, store=store)
        refresh_report(store.run_dir)  # report.html: the one page to open in a run folder
        outcome.model_failures = store.model_failures()
    except KeyboardInterrupt:
        raise Interrupted(
            f"interrupted while writing the report of {store.run_dir} (all {outcome.n_done} trials are on disk); "
            f"finish with: soabench run --resume {store.run_dir}"
        ) from None
    outcome.finished = None
    return outcome


@contextlib.contextmanager
def _figure_pool(workers: int | None, executor: Any = None) -> Iterator[None]:
    """The figures of a report written inside the block in parallel (:func:`soabench.figures.drawing.parallel`):
    on ``executor`` when it is a local process pool, else (unless an enclosing ``parallel`` decides already) on a
    pool of ``workers`` processes (None: one per core) opened here and closed on the way out, terminated if the
    block is left by an exception (Ctrl-C)."""
    if isinstance(executor, PoolExecutor) or pool_open():
        with parallel(executor) if isinstance(executor, PoolExecutor) else contextlib.nullcontext():
            yield
        return
    n = int(workers or os.cpu_count() or 1)
    pool = PoolExecutor(n) if n > 1 else None  # its processes start at the first figure
    ok = False
    try:
        with parallel(pool):
            yield
        ok = True
    finally:
        if pool is not None:
            pool.close(abort=not ok)
