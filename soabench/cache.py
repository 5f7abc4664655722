"""Where numba keeps the compiled filter kernels: a per-user cache folder, never the installed package.

numba's ``cache=True`` writes its index and machine code (``.nbi``/``.nbc``) next to the source by default, i.e.
into ``site-packages/soabench/gmphd/__pycache__`` after ``pip install .``. Those files survive ``pip uninstall``
and a later ``pip install -e .``; the left-over ``site-packages/soabench`` folder then becomes a namespace package
that shadows the editable install. So before numba is imported, :func:`configure_numba_cache` points
``NUMBA_CACHE_DIR`` at a per-user folder (docs/user-guide/install.md):

* ``NUMBA_CACHE_DIR`` when the user set it (left untouched);
* else ``$XDG_CACHE_HOME/soabench/numba`` (``XDG_CACHE_HOME`` when it is an absolute path);
* else ``%LOCALAPPDATA%\\soabench\\numba`` on Windows, ``~/.cache/soabench/numba`` elsewhere.

numba files each source under a sub-folder named after the source's own path, so several installs (or checkouts)
share the folder without mixing their kernels. Deleting the folder is always safe: the next import recompiles.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

ENV_VAR = "NUMBA_CACHE_DIR"


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

    Called by :mod:`soabench.gmphd.kernels` before it imports numba. The environment variable also reaches the
    worker processes of a run. If numba was already imported (its configuration read the environment then), its
    ``config.CACHE_DIR`` is set too, so the kernels decorated afterwards use the folder. When the per-user folder
    cannot be created (read-only home), a folder under the system temporary directory is used instead.
    """
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
