"""A Dask LocalCluster whose worker processes can import the tests' helpers (fake_trial.py, plugin_fixtures.py)."""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from contextlib import contextmanager

from repo_paths import TESTS


@contextmanager
def local_cluster(n_workers: int) -> Iterator[str]:
    """``n_workers`` worker processes of one thread each, with tests/ on their PYTHONPATH; yields the scheduler's
    address and closes the cluster (and restores PYTHONPATH) on exit."""
    import distributed

    old = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = str(TESTS) + (os.pathsep + old if old else "")
    cluster = distributed.LocalCluster(
        n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=logging.ERROR
    )
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()
        if old is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = old
