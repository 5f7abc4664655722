"""The LMB as a filter family (docs/development.md "Adding a filter family"): its registry line's builder."""

from __future__ import annotations

from soabench.lmb.filter import LMBFilter
from soabench.protocols import FamilySetup


def build(setup: FamilySetup) -> LMBFilter:
    """The LMB filter of one run (docs/method.md "LMB filter"): ``[filter]`` for the motion, sensor and gate terms,
    ``[lmb]`` for its own settings, lambda_B = ``birth.N_hat`` for the adaptive birth, and the trial's association
    stream for the Gibbs sampler's seeds."""
    cfg = setup.config
    return LMBFilter(setup.filter_cfg, setup.sensor, setup.filter_mode, lmb_cfg=cfg.lmb, N_hat=cfg.birth.N_hat,
                     rng=setup.rng)  # fmt: skip
