"""Progress of a run on stderr, wherever it goes: a bar on a terminal, one line at a time otherwise.

On a terminal the bar is redrawn in place (``\\r``) after every trial. When stderr is a file or a pipe (CI, a
cluster job, ``2> log``) a redrawn bar would be one endless line, so a plain line is written instead at the start,
whenever another 5 % of the trials finished or 10 s passed since the last line (whichever comes first, at most one
line per finished trial), and at the end. Every line carries the count, failures, elapsed time and the ETA.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

from soabench.notice import LINE_INTERVAL_S, is_terminal

#: non-terminal output: a line at least every LINE_INTERVAL_S seconds (while trials finish) and whenever this
#: fraction of the trials finished since the last line
LINE_STEP = 0.05
BAR_WIDTH = 30


def format_duration(seconds: float) -> str:
    """``1h02m``, ``3m07s`` or ``42s``."""
    s = max(0, int(round(seconds)))
    if s >= 3600:
        return f"{s // 3600}h{(s % 3600) // 60:02d}m"
    if s >= 60:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s}s"


class Progress:
    """Progress of ``total`` trials of which ``done`` are already on disk (a resumed run).

    Args:
        total, done: trial counts.
        enabled: False: print nothing (``--no-progress``).
        label: whose progress it is, e.g. the run folder's name in a sweep.
        unit: what is counted (an atlas counts chunks: one trial of every point of a scene variant).
        stream: where to write (default ``sys.stderr``); a terminal gets the bar.
        clock: monotonic seconds (tests pass a fake one).
    """

    def __init__(
        self,
        total: int,
        done: int,
        enabled: bool,
        label: str = "",
        stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
        unit: str = "trials",
    ):
        self.total, self.done, self.failed = int(total), int(done), 0
        self.stream = stream if stream is not None else sys.stderr
        self.active = bool(enabled)
        #: True when the in-place bar is drawn (callers end its line before printing)
        self.enabled = self.active and is_terminal(self.stream)
        self.label, self.unit = label, unit
        self._clock = clock
        self._start_done = self.done
        self._t0 = clock()
        self._last_t = self._t0
        self._last_done: int | None = None
        self.draw()

    def update(self, ok: bool) -> None:
        """One more trial finished (``ok`` False: it failed)."""
        self.done += 1
        self.failed += 0 if ok else 1
        self.draw()

    def _eta(self) -> str:
        ran = self.done - self._start_done
        if ran <= 0 or self.done >= self.total:
            return ""
        rem = (self._clock() - self._t0) / ran * (self.total - self.done)
        return f", ETA {format_duration(rem)}"

    def _status(self) -> str:
        pct = 100.0 * self.done / self.total if self.total else 100.0
        fail = f", {self.failed} failed" if self.failed else ""
        head = f"{self.label}: " if self.label else ""
        elapsed = format_duration(self._clock() - self._t0)
        return f"{head}{self.done}/{self.total} {self.unit} ({pct:.0f}%){fail}, {elapsed} elapsed{self._eta()}"

    def draw(self) -> None:
        if not self.active:
            return
        if self.enabled:
            frac = self.done / self.total if self.total else 1.0
            n = int(frac * BAR_WIDTH)
            self.stream.write(f"\r[{'#' * n}{'.' * (BAR_WIDTH - n)}] {self._status()}   ")
            self.stream.flush()
            return
        now = self._clock()
        due = (
            self._last_done is None
            or self.done >= self.total
            or now - self._last_t >= LINE_INTERVAL_S
            or (self.total and (self.done - self._last_done) / self.total >= LINE_STEP)
        )
        if due and self.done != self._last_done:
            self._line(now)

    def _line(self, now: float) -> None:
        self.stream.write(f"progress: {self._status()}\n")
        self.stream.flush()
        self._last_t, self._last_done = now, self.done

    def close(self) -> None:
        """End the bar's line; off a terminal, write the final count unless it was the last line."""
        if not self.active:
            return
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
        elif self.done != self._last_done:
            self._line(self._clock())
