"""Poisson multi-Bernoulli mixture (PMBM) filter and its PMB variant, with the GM-PHD's models and birth models
(docs/method.md §10; Williams 2015; García-Fernández, Williams, Granström & Svensson 2018).

Modules: :mod:`.density` (the PMBM as arrays), :mod:`.murty` (ranked assignments), :mod:`.association` (clusters
and global hypotheses), :mod:`.update` (the update with the birth models' newborn terms), :mod:`.pmb` (the
track-oriented collapse), :mod:`.filter` (the cycle).
"""

from soabench.pmbm.density import PMBMDensity
from soabench.pmbm.filter import PMBM_MODES, PMBMFilter
from soabench.pmbm.murty import murty
from soabench.pmbm.update import Hypotheses

__all__ = ["PMBM_MODES", "Hypotheses", "PMBMDensity", "PMBMFilter", "murty"]
