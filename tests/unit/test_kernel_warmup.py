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
    assert kw.compiled() and kw.stamp_path().parent == cache
    again = io.StringIO()
    assert kw.ensure_compiled(stream=again) == 0.0 and again.getvalue() == ""  # the stamp: nothing to do


def test_a_failing_group_is_not_fatal_and_leaves_no_stamp(cache, monkeypatch):
    monkeypatch.setattr(kw, "ROUNDS", ((_broken, _quick),))
    log = io.StringIO()
    kw.ensure_compiled(stream=log, workers=2)
    assert not kw.compiled()
    assert log.getvalue().count(kw.MESSAGE) == 1 and "compiling ahead failed" in log.getvalue().splitlines()[-1]


def test_the_stamp_changes_with_the_versions_and_the_kernel_sources(cache, tmp_path, monkeypatch):
    """A new numba, a new soabench or an edited kernel source needs another compilation: another stamp."""
    import importlib.metadata

    source = tmp_path / "src" / "house_kernel_source.py"
    source.parent.mkdir()
    source.write_text("X = 1\n")
    monkeypatch.syspath_prepend(str(source.parent))
    monkeypatch.setattr(kw, "KERNEL_MODULES", ("house_kernel_source",))
    versions = {"numba": "0.60.0", "soabench": "0.1.0"}
    monkeypatch.setattr(importlib.metadata, "version", lambda name: versions[name])
    first = kw.stamp_path()
    assert first.name.startswith("soabench-kernels-") and first.name.endswith(".ready") and first.parent == cache
    source.write_text("X = 2\n")
    edited = kw.stamp_path()
    versions["numba"] = "0.61.0"
    numba = kw.stamp_path()
    versions["soabench"] = "0.2.0"
    soabench = kw.stamp_path()
    assert len({first, edited, numba, soabench}) == 4
    source.write_text("X = 1\n")
    versions.update(numba="0.60.0", soabench="0.1.0")
    assert kw.stamp_path() == first  # the same sources and versions: the same stamp
