"""Labelled multi-Bernoulli (LMB) filter with Gaussian-mixture tracks and the GM-PHD's models and birth models
(docs/method.md "LMB filter"; Reuter, Vo, Vo & Dietmayer 2014; Vo, Vo & Hoang 2017).

Modules: :mod:`.tracks` (labelled Bernoulli tracks as arrays, per-track reduction), :mod:`.measurement` (range-
bearing EKF and linear position models), :mod:`.gibbs` (association marginals: enumeration or Gibbs sampling),
:mod:`.update` (joint prediction and update), :mod:`.birth` (birth models -> Bernoullis, adaptive birth),
:mod:`.filter` (the cycle).
"""

from soabench.lmb.filter import LMB_MODES, LMBConfig, LMBFilter
from soabench.lmb.measurement import LinearPosition, RangeBearingEKF
from soabench.lmb.tracks import Tracks, label_pairs, make_labels

__all__ = [
    "LMB_MODES",
    "LMBConfig",
    "LMBFilter",
    "LinearPosition",
    "RangeBearingEKF",
    "Tracks",
    "label_pairs",
    "make_labels",
]
