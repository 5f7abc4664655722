"""Birth models: the S-OA model here, the four baselines in :mod:`soabench.baselines` (repository folder
``baselines/``).

The built-in names and their classes are :data:`soabench.plugins.BUILTIN_BIRTH_MODELS`; a new model is one file
plus one line there and one label here.
"""

from __future__ import annotations

import importlib

from soabench.errors import require
from soabench.plugins import BUILTIN_BIRTH_MODELS

#: display names of the registered models (tables and figures)
LABEL: dict[str, str] = {
    "soa": "S-OA",
    "pubm": "PUBM",
    "ubm": "UBM (FOV)",
    "ubm-ws": "UBM (workspace)",
    "atbm": "ATBM",
    "gmbm": "GMBM",
}
#: the four baselines S-OA is compared against (§5.8)
BASELINES: tuple[str, ...] = tuple(name for name in BUILTIN_BIRTH_MODELS if name != "soa")
#: the models of the N_hat sweep and of the KITTI protocol (§5.8): the paper's three (its UBM is ubm-ws) and UBM over
#: the FOV
CORE_MODELS: tuple[str, ...] = ("soa", "pubm", "ubm", "ubm-ws")


def get_birth_model(name: str) -> type:
    """The class of the built-in birth model ``name`` (one of :data:`~soabench.plugins.BUILTIN_BIRTH_MODELS`)."""
    require(
        name in BUILTIN_BIRTH_MODELS,
        f"birth model {name!r} is unknown; choose one of {', '.join(BUILTIN_BIRTH_MODELS)}",
    )
    module, cls = BUILTIN_BIRTH_MODELS[name].split(":")
    return getattr(importlib.import_module(module), cls)
