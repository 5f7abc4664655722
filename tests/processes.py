"""A process's children and whether a process still runs, read from /proc (Linux): for the tests and the benchmark
that check that no worker outlives its driver."""

from __future__ import annotations

from pathlib import Path


def children(pid: int) -> list[int]:
    """The pids of ``pid``'s child processes (of every thread); empty once it is gone."""
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return out


def alive(pid: int) -> bool:
    """Whether ``pid`` exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except OSError:
        return False
    return state != "Z"
