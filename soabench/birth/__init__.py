"""Birth models: the S-OA model here, the four baselines in :mod:`soabench.baselines` (repository folder
``baselines/``).

One registry maps the CLI/config names to classes; a new model is one file plus one line here.
"""

from __future__ import annotations

import importlib

from soabench.errors import require

#: name -> "module:Class" (imported lazily so baselines may import soabench.birth.base)
REGISTRY: dict[str, str] = {
    "soa": "soabench.birth.soa:SOABirth",
    "pubm": "soabench.baselines.partially_uniform:PartiallyUniformBirth",
    "ubm": "soabench.baselines.uniform:UniformBirth",
    "ubm-ws": "soabench.baselines.uniform:WorkspaceUniformBirth",
    "atbm": "soabench.baselines.adaptive:AdaptiveBirth",
    "gmbm": "soabench.baselines.standard_gm:StandardGMBirth",
}


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
BASELINES: tuple[str, ...] = tuple(name for name in REGISTRY if name != "soa")
#: the models of the N_hat sweep and of the KITTI protocol (§5.8): the paper's three (its UBM is ubm-ws) and UBM over
#: the FOV
CORE_MODELS: tuple[str, ...] = ("soa", "pubm", "ubm", "ubm-ws")


def get_birth_model(name: str) -> type:
    """The class registered under ``name`` (one of REGISTRY)."""
    require(name in REGISTRY, f"birth model {name!r} is unknown; choose one of {', '.join(REGISTRY)}")
    module, cls = REGISTRY[name].split(":")
    return getattr(importlib.import_module(module), cls)
