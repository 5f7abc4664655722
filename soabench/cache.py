"""Where numba keeps the compiled filter kernels: a per-user cache folder, never the installed package.

numba's ``cache=True`` writes its index and machine code (``.nbi``/``.nbc``) next to the source by default, i.e.
into ``site-packages/soabench/gmphd/__pycache__`` after ``pip install .``. Those files survive ``pip uninstall``
and a later ``pip install -e .``; the left-over ``site-packages/soabench`` folder then becomes a namespace package
that shadows the editable install. So before numba is imported, :func:`configure_numba_cache` points
``NUMBA_CACHE_DIR`` at a per-user folder (docs/user-guide/install.md):

* ``NUMBA_CACHE_DIR`` when the user set it (left untouched);
* else ``$XDG_CACHE_HOME/soabench/numba`` (``XDG_CACHE_HOME`` when it is an absolute path);
* else ``%LOCALAPPDATA%\\soabench\\numba`` on Windows, ``~/.cache/soabench/numba`` elsewhere.

By default numba files each source under a sub-folder named after the source's own path, so the same kernels moved
to another path (``pip install .``, then ``pip install -e .`` of the same code) compile again. soabench's kernels
are filed instead by what they are (:class:`KernelCacheLocator`): under ``soabench-<key>/``, with ``key`` a hash of
the source of every module in :data:`KERNEL_MODULES` (and numba's and Python's versions), whatever path they were
imported from. A change to any kernel source gives a new key and so a fresh folder: every kernel compiles again,
including those that inline a changed kernel from another module (numba's own freshness check looks only at the
function's own file). Several versions share the cache folder side by side. Deleting the folder is always safe: the
next import recompiles.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import os
import sys
import tempfile
from pathlib import Path

ENV_VAR = "NUMBA_CACHE_DIR"

#: the package's modules with compiled kernels, relative to the package folder (their sources key the cache folder)
KERNEL_MODULES = (
    "gmphd/clock.py",
    "gmphd/kernels.py",
    "gmphd/cycle.py",
    "metrics_kernels.py",
    "geometry_kernels.py",
    "tracks/kernels.py",
    "lmb/gibbs.py",
    "lmb/tracks.py",
    "lmb/cycle.py",
    "kitti/lidar_raster.py",
    "pmbm/murty.py",
    "pmbm/search.py",
    "pmbm/association.py",
    "pmbm/kernels.py",
    "pmbm/cycle.py",
    "pmbm/step.py",
)

PACKAGE_DIR = Path(__file__).resolve().parent


def default_cache_dir() -> Path:
    """The per-user folder for soabench's compiled kernels (ignores ``NUMBA_CACHE_DIR``)."""
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    if xdg and os.path.isabs(xdg):
        base = Path(xdg)
    elif sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        base = Path(os.environ["LOCALAPPDATA"])
    else:
        base = Path.home() / ".cache"
    return base / "soabench" / "numba"


def configure_numba_cache() -> Path:
    """Set ``NUMBA_CACHE_DIR`` (unless the user did) before the kernels are compiled; return the folder in use.

    Called by every kernel module before it imports numba; also puts :class:`KernelCacheLocator` first in numba's
    list of cache locators. The environment variable also reaches the
    worker processes of a run. If numba was already imported (its configuration read the environment then), its
    ``config.CACHE_DIR`` is set too, so the kernels decorated afterwards use the folder. When the per-user folder
    cannot be created (read-only home), a folder under the system temporary directory is used instead.
    """
    _use_kernel_locator()
    user = os.environ.get(ENV_VAR)
    if user:
        return Path(user)
    path = default_cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        path = Path(tempfile.gettempdir()) / f"soabench-numba-{_user_tag()}"
        path.mkdir(parents=True, exist_ok=True)
    os.environ[ENV_VAR] = str(path)
    numba_config = sys.modules.get("numba.core.config")
    if numba_config is not None:
        numba_config.CACHE_DIR = str(path)
    return path


def _user_tag() -> str:
    try:
        return str(os.getuid())
    except AttributeError:  # pragma: no cover - Windows
        return os.environ.get("USERNAME", "user")


@functools.lru_cache(maxsize=1)
def kernel_key() -> str:
    """16 hex digits of a hash of every :data:`KERNEL_MODULES` source (content, not path) and numba's and Python's
    versions: the name of the cache sub-folder of this soabench's kernels."""
    h = hashlib.sha256()
    for name in KERNEL_MODULES:
        h.update(name.encode() + b"\0" + (PACKAGE_DIR / name).read_bytes() + b"\0")
    h.update(importlib.metadata.version("numba").encode() + b"\0" + sys.version.encode())
    return h.hexdigest()[:16]


def kernel_folder() -> Path:
    """Where this soabench's kernels are cached: ``soabench-<kernel_key>`` in the cache folder in use."""
    return configure_numba_cache() / f"soabench-{kernel_key()}"


@functools.lru_cache(maxsize=1)
def _use_kernel_locator() -> None:
    """Put :class:`KernelCacheLocator` first in numba's list of cache locators (once per process)."""
    from numba.core.caching import CacheImpl

    if _locator_class() not in CacheImpl._locator_classes:
        CacheImpl._locator_classes.insert(0, _locator_class())


@functools.lru_cache(maxsize=1)
def _locator_class() -> type:
    """:class:`KernelCacheLocator`, defined on first use (numba is imported by then, not with this module)."""
    from numba.core import config
    from numba.core.caching import _CacheLocator, _SourceFileBackedLocatorMixin

    class KernelCacheLocator(_SourceFileBackedLocatorMixin, _CacheLocator):
        """numba's cache locator for soabench's kernels: ``<cache folder>/soabench-<key>/<module path>``, the same
        for every path the package is imported from (numba checks each file's content as well)."""

        def __init__(self, py_func, py_file):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            module = Path(py_file).resolve().relative_to(PACKAGE_DIR).with_suffix("")
            self._cache_path = str(Path(config.CACHE_DIR) / f"soabench-{kernel_key()}" / ".".join(module.parts))

        def get_cache_path(self):
            return self._cache_path

        @classmethod
        def from_function(cls, py_func, py_file):
            if not config.CACHE_DIR or not Path(py_file).resolve().is_relative_to(PACKAGE_DIR):
                return None
            return super().from_function(py_func, py_file)

    return KernelCacheLocator
