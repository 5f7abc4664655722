"""Kernels compiled once per machine before the first trial (soabench/kernel_warmup.py): announced once, a line
every interval off a terminal, a stamp that makes the next run skip it, never fatal."""

from __future__ import annotations

import io
import time

import pytest

from soabench import kernel_warmup as kw


def _quick() -> None:
    pass


def _slow() -> None:
    time.sleep(0.8)


def _broken() -> None:
    raise RuntimeError("a group that fails")


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "cache").mkdir()
    return tmp_path / "cache"


def test_compiles_once_announces_once_and_lines_off_a_terminal(cache, monkeypatch):
    monkeypatch.setattr(kw, "ROUNDS", ((_slow, _quick), (_quick,)))
    monkeypatch.setattr(kw, "LINE_INTERVAL_S", 0.3)
    log = io.StringIO()  # not a terminal
    took = kw.ensure_compiled(stream=log, workers=2)
    lines = log.getvalue().splitlines()
    assert took > 0.7
    assert lines.count(kw.MESSAGE) == 1 and lines[0] == kw.MESSAGE
    assert any(ln.startswith("soabench: compiling, ") for ln in lines[1:-1])
    assert lines[-1].startswith("soabench: kernels compiled in ")
    assert kw.compiled() and kw.stamp_path().parent.parent == cache
    again = io.StringIO()
    assert kw.ensure_compiled(stream=again) == 0.0 and again.getvalue() == ""  # the stamp: nothing to do


def test_a_failing_group_is_not_fatal_and_leaves_no_stamp(cache, monkeypatch):
    monkeypatch.setattr(kw, "ROUNDS", ((_broken, _quick),))
    log = io.StringIO()
    kw.ensure_compiled(stream=log, workers=2)
    assert not kw.compiled()
    assert log.getvalue().count(kw.MESSAGE) == 1 and "compiling ahead failed" in log.getvalue().splitlines()[-1]


def test_the_stamp_lies_in_the_folder_keyed_by_the_kernel_sources(cache):
    from soabench.cache import kernel_key

    assert kw.stamp_path().parent == cache / f"soabench-{kernel_key()}"
    assert kw.stamp_path() == kw.stamp_path()  # the same sources give the same stamp
