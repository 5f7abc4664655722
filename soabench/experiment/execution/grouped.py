"""Several run folders' trials run together: one task per trial index (docs/method.md §5.8, common random numbers).

A study (main run, clutter sweep, N̂ sweep) and an N̂ sweep are run folders whose trial n has the same seeds, so the
same SUMO recording, the same scans at the same clutter rate and, for equal settings, the same filter runs. Each
folder is first checked and created as usual (a run with ``Batch(defer=LIST)`` appends a
:class:`~soabench.experiment.execution.runner.DeferredRun`); :func:`run_group` then submits one task per trial index
that
runs every folder's trial n in one process with one :class:`~soabench.experiment.trial.trial.TrialShare`: SUMO once, the
sensor once per clutter rate, a (model x mode x clutter) run once however many folders hold it (the main run's
λ = 3 runs are the clutter sweep's). Every folder still receives its own trial record, written as it arrives, so a
killed group resumes folder by folder like any run, and the results are those of running each folder on its own.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from soabench.config import FILTER_FAMILIES
from soabench.experiment.execution.progress import Progress
from soabench.experiment.execution.runner import (
    DeferredRun,
    TaskSpec,
    _print_failure,
    _print_model_failures,
    _utc_stamp,
    run_trial_task,
    uses_kernels,
)
from soabench.experiment.runs.provenance import package_versions
from soabench.experiment.trial import registry
from soabench.experiment.trial import trial as trial_module
from soabench.experiment.trial.trial import TrialShare, _config_key, filter_config_key
from soabench.folders import FolderLock
from soabench.kernel_warmup import ensure_compiled


@dataclass(frozen=True)
class GroupSpec:
    """The folders of a group, as worker task specs, and the trials each still needs (small and picklable)."""

    members: tuple[TaskSpec, ...]
    todo: tuple[frozenset[int], ...]

    @property
    def base_seed(self) -> int:
        """The first folder's base seed (it names a trial lost with its worker)."""
        return self.members[0].base_seed

    @property
    def task_fn(self) -> Any:
        return run_group_task


def run_group_task(trial: int, group: GroupSpec) -> dict:
    """Trial ``trial`` of every folder that needs it, sharing one :class:`~soabench.experiment.trial.trial.TrialShare`.

    Returns ``{"status": "group", "trial", "records": {folder index: trial record}, "shared": counts}``; a folder's
    failure is its own failure record (the others keep theirs). Folders with a custom trial kind run unshared.
    """

    builtin = registry.trial_kind(registry.DEFAULT_TRIAL_KIND) is registry._builtin_trial
    share = TrialShare(keep_filter_runs=rescored(group.members))
    records: dict[int, dict] = {}
    for i, spec in enumerate(group.members):
        if trial not in group.todo[i]:
            continue
        if spec.trial_fn is None and builtin:  # the built-in trial kind: run_trial, with the share
            spec = dataclasses.replace(spec, trial_fn=functools.partial(trial_module.run_trial, share=share))
        records[i] = run_trial_task(trial, spec)
    return {"status": "group", "trial": int(trial), "records": records, "shared": dict(share.counts)}


def rescored(members: Sequence[TaskSpec]) -> bool:
    """True when two folders hold the same filter run under different run keys: configs that differ only in
    ``metrics`` (the study's visible-truth run and its main run), or a folder that names the GM-PHD among several
    families beside a default-family folder of the same filter config (the families folders of ``soabench results``
    and the study's main run). Their filter runs are then kept and scored per folder instead of run twice (memory
    only where it pays)."""

    run_keys: dict[tuple[str, str], set[tuple[str, bool]]] = {}
    for m in members:
        config = m.config  # plain data: a default-family run leaves experiment.filters out
        families = tuple(config["experiment"].get("filters", FILTER_FAMILIES[:1]))
        run_key = (_config_key(config), families != FILTER_FAMILIES[:1])  # what a run key holds besides the run
        for family in families:
            run_keys.setdefault((family, filter_config_key(config, family)), set()).add(run_key)
    return any(len(keys) > 1 for keys in run_keys.values())


def group_trials(deferred: Sequence[DeferredRun]) -> list[int]:
    """Every trial index some folder of the group still needs, in order."""
    return sorted(set().union(*(d.todo for d in deferred))) if deferred else []


def _write_record(d: DeferredRun, r: dict, bar: Progress, fail_fast: bool) -> bool:
    """Write one folder's trial record (or failure) as it arrives; True when ``fail_fast`` stops the group."""
    if r.get("status") == "ok":
        d.store.write_trial(r)
        bar.update(True)
        _print_model_failures(r, bar)
        return fail_fast and bool(r.get("model_failures"))
    d.store.write_failure(r)
    bar.update(False)
    _print_failure(r, bar)
    return fail_fast


def _write_sessions(deferred: Sequence[DeferredRun], ran: Sequence[int], session: dict) -> None:
    """The session record of every folder that ran trials in this group (``session``: what they share)."""
    for d, n in zip(deferred, ran, strict=True):
        if n:
            own = {"trials_run": n, "resumed": d.n_trials - len(d.todo) > 0, "versions": package_versions()}
            record = {k: {**session, **own}[k] for k in SESSION_KEYS}
            d.store.write_session(f"{_utc_stamp()}-{os.getpid()}", record)


#: the keys of a group's session record, in their order in the file
SESSION_KEYS = ("executor", "n_workers", "trials_run", "resumed", "interrupted", "stopped_fail_fast", "versions",
                "started", "wall_s")  # fmt: skip


def run_group(
    deferred: Sequence[DeferredRun], exe: Any, *, fail_fast: bool = False, progress: bool = True, label: str = ""
) -> tuple[bool, dict[str, int]]:
    """Run the trials of ``deferred`` on the open executor ``exe``, one task per trial index; write each folder's
    record as it arrives (each folder locked meanwhile). Returns (stopped by ``fail_fast``, summed share counts).

    Ctrl-C propagates as ``KeyboardInterrupt`` after the finished records are on disk (the caller names the resume
    command).
    """

    if not deferred:
        return False, {}
    group = GroupSpec(tuple(d.spec for d in deferred), tuple(d.todo for d in deferred))
    trials = group_trials(deferred)
    total = sum(d.n_trials for d in deferred)
    done0 = total - sum(len(d.todo) for d in deferred)
    counts: dict[str, int] = {}
    ran = [0] * len(deferred)
    locks = [FolderLock(d.store.run_dir) for d in deferred]
    stopped = False
    t_start = time.time()
    try:
        for lock in locks:
            lock.acquire()
        for d in deferred:
            d.store.clear_merged()
        if any(uses_kernels(d.spec) for d in deferred):  # before the progress line: its ETA counts trials only
            ensure_compiled([d.spec.config for d in deferred if uses_kernels(d.spec)])
        bar = Progress(total, done0, progress, label=label)
        gen = exe.results(group, trials)
        try:
            for t, rec in gen:
                per_folder = rec.get("records") if rec.get("status") == "group" else None
                for key, v in (rec.get("shared") or {}).items():
                    counts[key] = counts.get(key, 0) + int(v)
                for i, d in enumerate(deferred):
                    if t not in d.todo:
                        continue
                    r = per_folder[i] if per_folder is not None else rec  # a lost worker: every folder's failure
                    ran[i] += 1
                    stopped = _write_record(d, r, bar, fail_fast) or stopped
                if stopped:
                    break
        finally:
            gen.close()
            bar.close()
            wall = time.time() - t_start
            session = {"executor": f"{exe.name} (grouped: {len(deferred)} folders)",
                       "n_workers": getattr(exe, "n_workers", 1), "interrupted": sys.exc_info()[0] is KeyboardInterrupt,
                       "stopped_fail_fast": stopped, "started": t_start, "wall_s": wall}  # fmt: skip
            _write_sessions(deferred, ran, session)
    finally:
        for lock in locks:
            lock.release()
    return stopped, counts
