"""Kernels compiled once per machine before the first trial (soabench/kernel_warmup.py): announced once, a line
every interval off a terminal, a stamp that makes the next run skip it, never fatal."""

from __future__ import annotations

import io
import time

import pytest

from soabench import kernel_warmup as kw


def _quick(modes) -> None:
    pass


def _slow(modes) -> None:
    time.sleep(0.8)


def _broken(modes) -> None:
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


def test_the_stamp_lies_in_the_folder_keyed_by_the_kernel_sources(cache, tmp_path, monkeypatch):
    """An edited kernel source or a new numba needs another compilation: another folder, so another stamp; the same
    sources and versions give the same stamp again."""
    import importlib.metadata

    from soabench import cache as cache_module

    assert kw.stamp_path().parent == cache / f"soabench-{cache_module.kernel_key()}"
    (tmp_path / "kernels.py").write_text("X = 1\n")
    monkeypatch.setattr(cache_module, "PACKAGE_DIR", tmp_path)
    monkeypatch.setattr(cache_module, "KERNEL_MODULES", ("kernels.py",))
    versions = {"numba": "0.60.0"}
    monkeypatch.setattr(importlib.metadata, "version", lambda name: versions[name])

    def stamp():  # the key is computed once per process: forget it, as a new process would
        cache_module.kernel_key.cache_clear()
        return kw.stamp_path()

    try:
        first = stamp()
        (tmp_path / "kernels.py").write_text("X = 2\n")
        edited = stamp()
        versions["numba"] = "0.61.0"
        newer = stamp()
        assert len({first, edited, newer}) == 3 and first.parent.parent == cache
        (tmp_path / "kernels.py").write_text("X = 1\n")
        versions["numba"] = "0.60.0"
        assert stamp() == first
    finally:
        cache_module.kernel_key.cache_clear()  # the real sources' key is computed again after the test


def _config(**experiment):
    import dataclasses

    from soabench.config import Config

    cfg = Config()
    return dataclasses.replace(cfg, experiment=dataclasses.replace(cfg.experiment, **experiment))


def test_a_run_compiles_only_the_kernels_it_calls():
    one = kw.needed([_config(models=("soa",), probabilities=("static",))])
    assert one[kw._fused_steps] == one[kw._predict_update] == ("static",)
    assert kw._lmb_steps not in one and kw._newborn_steps not in one  # no LMB, no newborn terms
    assert kw._pmbm_steps not in one
    assert {kw._reduction, kw._metrics_geometry, kw._track_metrics} <= set(one)
    both = kw.needed([_config(models=("soa",), probabilities=("static",)),
                      _config(models=("pubm",), probabilities=("dynamic",), filters=("gmphd", "lmb"))])  # fmt: skip
    assert both[kw._fused_steps] == ("static", "dynamic") and both[kw._newborn_steps] == ("dynamic",)
    assert kw._lmb_steps in both and kw._pmbm_steps not in both
    pmb = kw.needed([_config(models=("soa",), probabilities=("static",), filters=("pmb",))])
    assert pmb[kw._pmbm_steps] == ("any",) and kw._lmb_steps not in pmb and kw._fused_steps not in pmb
    assert set(kw.needed([{"experiment": {"models": 7}}])) == set(kw.everything())  # unreadable: everything


def test_the_newborn_models_are_those_that_hand_newborn_terms():
    import importlib
    import inspect

    from soabench.plugins import BUILTIN_BIRTH_MODELS

    for name, target in BUILTIN_BIRTH_MODELS.items():
        module = importlib.import_module(target.split(":")[0])
        assert ("births.newborn = " in inspect.getsource(module)) == (name in kw.NEWBORN_MODELS), name


def test_stamps_are_per_group_and_mode(cache, monkeypatch):
    monkeypatch.setattr(kw, "ROUNDS", ((kw._reduction, kw._fused_steps),))
    monkeypatch.setattr(kw, "_run_group", lambda g, modes: None)
    monkeypatch.setattr(kw, "ProcessPoolExecutor", _InProcess)
    log = io.StringIO()
    kw.ensure_compiled([_config(models=("soa",), probabilities=("static",))], stream=log)
    assert kw.stamp_path(kw._fused_steps, "static").exists() and not kw.stamp_path(kw._fused_steps, "dynamic").exists()
    assert kw.ensure_compiled([_config(models=("soa",), probabilities=("static",))], stream=io.StringIO()) == 0.0
    kw.ensure_compiled([_config(models=("soa",), probabilities=("dynamic",))], stream=log)  # only the new mode
    assert kw.stamp_path(kw._fused_steps, "dynamic").exists() and log.getvalue().count(kw.MESSAGE) == 2


class _InProcess:
    """A pool that runs each task when submitted (the stamps, not the processes, are under test)."""

    def __init__(self, max_workers):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def submit(self, fn, *args):
        from concurrent.futures import Future

        fut = Future()
        fut.set_result(fn(*args))
        return fut
