"""Progress on stderr wherever it goes: a bar on a terminal, periodic lines with an ETA otherwise."""

from __future__ import annotations

import io

import fake_trial as ft

from soabench.experiment.execution import progress as pg
from soabench.experiment.execution.progress import Progress, format_duration


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_lines_off_a_terminal_every_five_percent_or_ten_seconds():
    out, clock = io.StringIO(), Clock()
    bar = Progress(200, 0, True, label="run", stream=out, clock=clock)
    for _ in range(200):
        clock.t += 0.5  # a trial every 0.5 s: 5 % (10 trials, 5 s) comes before 10 s
        bar.update(True)
    bar.close()
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue()
    assert lines[0].startswith("progress: run: 0/200 trials (0%)")
    assert len(lines) == 1 + 200 // 10  # the start, then every 10 trials; the last one is 200/200
    assert lines[1] == "progress: run: 10/200 trials (5%), 5s elapsed, ETA 1m35s"
    assert lines[-1].startswith("progress: run: 200/200 trials (100%)") and "ETA" not in lines[-1]


def test_slow_trials_give_a_line_every_ten_seconds():
    out, clock = io.StringIO(), Clock()
    bar = Progress(1000, 0, True, stream=out, clock=clock)
    for _ in range(8):
        clock.t += pg.LINE_INTERVAL_S / 2  # 2 trials per interval, far below 5 % (50 trials)
        bar.update(ok=False)
    lines = out.getvalue().splitlines()
    assert len(lines) == 1 + 4
    assert lines[-1] == "progress: 8/1000 trials (1%), 8 failed, 40s elapsed, ETA 1h22m"


def test_bar_on_a_terminal_and_silence_when_disabled():
    tty, clock = Tty(), Clock()
    bar = Progress(4, 1, True, stream=tty, clock=clock)  # a resumed run: 1 trial on disk
    clock.t = 30.0
    bar.update(True)
    bar.close()
    text = tty.getvalue()
    assert bar.enabled and text.count("\r") == 2 and text.endswith("\n")
    assert "[###############...............] 2/4 trials (50%), 30s elapsed, ETA 1m00s" in text
    quiet = io.StringIO()
    bar = Progress(4, 0, False, stream=quiet)
    bar.update(True)
    bar.close()
    assert quiet.getvalue() == ""


def test_format_duration():
    assert [format_duration(s) for s in (0, 42.4, 187, 3725)] == ["0s", "42s", "3m07s", "1h02m"]


def test_a_run_with_redirected_stderr_reports_progress(tmp_path, capsys):
    ft.run_fake(ft.small_config(trials=3, duration=20.0, clutter=(3.0,), seed=11), tmp_path / "r", progress=True)
    err = capsys.readouterr().err.splitlines()
    progress = [ln for ln in err if ln.startswith("progress: r: ")]
    assert progress[0].startswith("progress: r: 0/3 trials") and progress[-1].startswith("progress: r: 3/3 trials")
