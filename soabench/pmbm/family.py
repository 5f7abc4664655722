"""The PMBM and the PMB as filter families (docs/development.md "Adding a filter family"): their registry lines'
builders. Both read ``[pmbm]``."""

from __future__ import annotations

from soabench.pmbm.filter import PMBMFilter
from soabench.protocols import FamilySetup


def build(setup: FamilySetup) -> PMBMFilter:
    """The PMBM filter of one run (docs/method.md §10): ``[filter]`` for the motion, sensor, gate and intensity
    reduction, ``[pmbm]`` for its hypotheses; it draws nothing."""
    return PMBMFilter(setup.filter_cfg, setup.sensor, setup.filter_mode, pmbm_cfg=setup.config.pmbm)


def build_pmb(setup: FamilySetup) -> PMBMFilter:
    """The PMB filter of one run (docs/method.md §10.5): the PMBM collapsed to one multi-Bernoulli per update."""
    return PMBMFilter(setup.filter_cfg, setup.sensor, setup.filter_mode, pmbm_cfg=setup.config.pmbm, pmb=True)
