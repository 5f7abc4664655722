"""soabench: a SUMO-driven benchmark of GM-PHD birth models (S-OA and four baselines).

Pipeline (docs/development.md): scenario -> Recording -> sensor -> Scans -> gmphd + birth -> Estimates -> metrics
-> TrialResult -> experiment (trials, sweeps, tables, figures).

Subpackages that live in their own folders of the repository: :mod:`soabench.baselines` (``baselines/``, the four
baseline birth models) and :mod:`soabench.nets` (``sumo_nets/``, the shipped networks). An install maps them
(pyproject ``package-dir``); in a source checkout used without installing it (``PYTHONPATH=.``, or
``python -m pytest`` from the root next to a non-editable install) :func:`_map_checkout_folders` does.
"""

import importlib.abc
import importlib.util
import sys
from pathlib import Path

__version__ = "0.1.0"

#: subpackage -> folder of the repository root (as pyproject.toml's [tool.setuptools.package-dir])
CHECKOUT_FOLDERS = {"soabench.baselines": "baselines", "soabench.nets": "sumo_nets"}


class _CheckoutFinder(importlib.abc.MetaPathFinder):
    """Finds ``soabench.baselines`` / ``soabench.nets`` in the checkout's folders; last on ``sys.meta_path``, so an
    install's own mapping wins."""

    def __init__(self, root: Path):
        self.root = root

    def find_spec(self, fullname, path=None, target=None):
        folder = CHECKOUT_FOLDERS.get(fullname)
        init = self.root / folder / "__init__.py" if folder else None
        if init is None or not init.is_file():
            return None
        return importlib.util.spec_from_file_location(fullname, init, submodule_search_locations=[str(init.parent)])


def _map_checkout_folders() -> None:
    root = Path(__file__).resolve().parent.parent
    if not (root / "pyproject.toml").is_file():  # an installed copy: setuptools placed the subpackages
        return
    if not any(isinstance(f, _CheckoutFinder) and f.root == root for f in sys.meta_path):
        sys.meta_path.append(_CheckoutFinder(root))


_map_checkout_folders()
