"""The GM-PHD as a filter family (docs/development.md "Adding a filter family"): its registry line's builder."""

from __future__ import annotations

from soabench.gmphd.filter import GMPHDFilter
from soabench.protocols import FamilySetup


def build(setup: FamilySetup) -> GMPHDFilter:
    """The GM-PHD filter of one run (docs/method.md §2.11) in the setup's probability model; it reads ``[filter]``
    only and draws nothing."""
    return GMPHDFilter(setup.filter_cfg, setup.sensor, setup.filter_mode)
