"""Compiled filter kernels are cached in a per-user folder, never inside the installed package."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import soabench
from soabench.cache import configure_numba_cache, default_cache_dir

PROBE = (
    "import soabench.gmphd.kernels as k, numba.core.config as c; "
    "assert k.wrap(4.0) < 3.15; print(c.CACHE_DIR)"  # compiles (and caches) one kernel
)


def _python(env_update: dict, drop=("NUMBA_CACHE_DIR",)) -> str:
    env = {k: v for k, v in os.environ.items() if k not in drop}
    env.update(env_update)
    done = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_kernels_are_cached_in_the_user_cache_not_in_the_package(tmp_path):
    package = Path(soabench.__file__).parent
    started = time.time() - 1
    printed = _python({"XDG_CACHE_HOME": str(tmp_path / "xdg")})
    expected = tmp_path / "xdg" / "soabench" / "numba"
    assert Path(printed) == expected
    assert list(expected.rglob("*wrap*.nbi")) and list(expected.rglob("*wrap*.nbc"))
    fresh = [p for p in package.rglob("*.nb[ic]") if p.stat().st_mtime >= started]
    assert fresh == []


def test_a_users_numba_cache_dir_is_left_alone(tmp_path):
    mine = tmp_path / "mine"
    assert Path(_python({"NUMBA_CACHE_DIR": str(mine)}, drop=())) == mine
    assert list(mine.rglob("*.nbi"))


def test_default_cache_dir_follows_xdg_then_home(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "c"))
    assert default_cache_dir() == tmp_path / "c" / "soabench" / "numba"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/path")  # not absolute: ignored (XDG spec)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert default_cache_dir() == tmp_path / "home" / ".cache" / "soabench" / "numba"


def test_configure_sets_the_variable_only_when_unset(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "user"))
    assert configure_numba_cache() == tmp_path / "user"
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "x"))
    import numba.core.config as numba_config

    monkeypatch.setattr(numba_config, "CACHE_DIR", numba_config.CACHE_DIR)  # restored after the test
    assert configure_numba_cache() == tmp_path / "x" / "soabench" / "numba"
    assert os.environ["NUMBA_CACHE_DIR"] == str(tmp_path / "x" / "soabench" / "numba")
    assert numba_config.CACHE_DIR == os.environ["NUMBA_CACHE_DIR"]  # numba was imported already: set there too
    assert (tmp_path / "x" / "soabench" / "numba").is_dir()


CACHE_PROBE = (
    "import soabench.gmphd.kernels as k; k.wrap(4.0); "
    "print(sum(k.wrap.stats.cache_hits.values()), sum(k.wrap.stats.cache_misses.values()), k.__file__)"
)


def _copy_of_the_package(dest: Path) -> Path:
    import shutil

    shutil.copytree(Path(soabench.__file__).parent, dest / "soabench", ignore=shutil.ignore_patterns("__pycache__"))
    return dest


def _hits_misses(path: Path, cache: Path) -> tuple[int, int]:
    env = {**os.environ, "PYTHONPATH": str(path), "NUMBA_CACHE_DIR": str(cache)}
    done = subprocess.run(
        [sys.executable, "-c", CACHE_PROBE], env=env, cwd=path, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    hits, misses, origin = done.stdout.split()
    assert Path(origin).is_relative_to(path)  # the copy was imported
    return int(hits), int(misses)


def test_the_cache_follows_the_kernel_sources_not_their_path(tmp_path):
    """The same sources at another path (pip install ., then pip install -e .) load what the first compiled; a
    change to any kernel source, the kernel's own or another module's, compiles again."""
    cache = tmp_path / "cache"
    first = _copy_of_the_package(tmp_path / "installed")
    second = _copy_of_the_package(tmp_path / "editable")
    assert _hits_misses(first, cache) == (0, 1)  # compiled
    assert _hits_misses(second, cache) == (1, 0)  # loaded, from another path
    other = second / "soabench" / "metrics_kernels.py"
    other.write_text(other.read_text() + "\n# a changed kernel source\n")
    assert _hits_misses(second, cache) == (0, 1)  # compiled again
    assert _hits_misses(first, cache) == (1, 0)  # the unchanged sources keep their own
    own = first / "soabench" / "gmphd" / "kernels.py"  # the module of the kernel the probe calls
    own.write_text(own.read_text() + "\n# a changed kernel source\n")
    assert _hits_misses(first, cache) == (0, 1)


def test_every_module_with_kernels_keys_the_cache():
    """A module that compiles with numba and is missing from KERNEL_MODULES would not renew the cache folder when it
    changes (a kernel inlined from it elsewhere would stay stale)."""
    from soabench.cache import KERNEL_MODULES

    package = Path(soabench.__file__).parent
    using = {
        p.relative_to(package).as_posix()
        for p in package.rglob("*.py")
        if "from numba import" in p.read_text() or "@njit" in p.read_text()
    }
    assert using == set(KERNEL_MODULES)
