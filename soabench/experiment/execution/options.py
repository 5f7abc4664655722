"""How runs are executed (docs/user-guide/commands.md, docs/user-guide/cluster.md): one :class:`RunOptions` for a
run, a sweep's points, a study's parts and the sensitivity runs, built once by the command line or the Python API
and passed down. What is run is the :class:`~soabench.config.Config`."""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass

from soabench.errors import require, require_value

#: ``[scheme://]host:port``; the schemes Dask's communication layer speaks over a network
SCHEDULER_ADDRESS = re.compile(
    r"^(?:(?P<scheme>tcp|tls|ws|wss|ucx)://)?(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9.-]{0,252})):(?P<port>\d{1,5})$"
)


def _is_host(host: str) -> bool:
    """A host name (with a letter), a dotted-quad IPv4 or a bracketed IPv6 address: a bare number such as ``3``
    (which the resolver would read as 0.0.0.3) is not."""
    literal = host.strip("[]")
    if host.startswith("[") or not any(c.isalpha() for c in literal):
        try:
            ipaddress.ip_address(literal)
        except ValueError:
            return False
    return True


MAX_WORKERS = 1024  #: upper bound of ``workers`` (processes or LocalCluster workers on one machine)


def check_workers(workers: int | None) -> None:
    """``workers`` is None (every core) or a number of processes in [1, :data:`MAX_WORKERS`]."""
    require_value(
        workers is None or (isinstance(workers, int) and not isinstance(workers, bool) and 1 <= workers <= MAX_WORKERS),
        "workers",
        workers,
        f"is out of range; allowed: integers in [1, {MAX_WORKERS}]",
    )


def check_scheduler_address(address: str | None) -> None:
    """Refuse a malformed ``--scheduler`` at once (instead of a connection timeout later)."""
    if address is None:
        return
    m = SCHEDULER_ADDRESS.match(address.strip())
    ok = m is not None and 1 <= int(m.group("port")) <= 65535 and _is_host(m.group("host"))
    require_value(ok, "scheduler", address, "is not a scheduler address; expected tcp://HOST:PORT (port 1-65535)")


@dataclass(frozen=True)
class RunOptions:
    """How runs are executed and what they write beside their tables: one object for a run, a sweep's points, a
    study's parts and the sensitivity runs alike. What is run is the :class:`~soabench.config.Config`."""

    workers: int | None = None  #: process workers (None: every core; 1: this process); with dask_local, its workers
    scheduler: str | None = None  #: address of an existing Dask scheduler (``tcp://HOST:PORT``)
    dask_local: bool = False  #: start a Dask LocalCluster (processes, one thread per worker)
    fail_fast: bool = False  #: stop at the first failed trial or failed method run (trials in flight are recorded)
    save_estimates: bool = False  #: also store the per-scan estimates (``estimates/``, format in :mod:`.store`)
    progress: bool = True  #: report progress on stderr (a bar on a terminal, periodic lines otherwise)
    #: draw each run folder's figures (``write_report`` can draw them later from the CSV files); None: each kind
    #: of folder's default (a run and the points of a clutter or occlusion sweep: drawn; the points of an N̂ sweep
    #: and a study's sensitivity runs: not, their summary figure and table stand for them)
    figures: bool | None = None

    def validate(self) -> RunOptions:
        """One line naming the first bad option (as the front end that was given it names it)."""
        check_workers(self.workers)
        require(
            not (self.scheduler and self.dask_local),
            "--scheduler and --dask local are alternatives; give one of them, not both",
        )
        check_scheduler_address(self.scheduler)
        return self


RUN_DEFAULTS = RunOptions()  #: every option at its default: a run on every core, with progress and figures
