"""Vectorised GM-PHD filter (docs/method.md §2, §4): mixture arrays, CV/range-bearing models, EKF/UKF update with
log-domain likelihoods and measurement-driven newborn terms, Vo-Ma reduction and extraction, static and Beta
("dynamic") probabilities.

Modules: :mod:`.mixture` (the arrays), :mod:`.models` (predict, update), :mod:`.probabilities` (p_D gate, Beta),
:mod:`.reduction` (prune/merge/cap, extract), :mod:`.filter` (the cycle of §2.11), :mod:`.kernels` and
:mod:`.cycle` (the compiled loops and the fused cycle).
"""

from soabench.gmphd.filter import GMPHDFilter
from soabench.gmphd.mixture import Mixture
from soabench.gmphd.models import cv_model, ekf_terms, measurement_noise, predict, ukf_terms, update
from soabench.gmphd.reduction import cap, extract, merge, prune, prune_merge_cap

__all__ = [
    "GMPHDFilter",
    "Mixture",
    "cap",
    "cv_model",
    "ekf_terms",
    "extract",
    "measurement_noise",
    "merge",
    "predict",
    "prune",
    "prune_merge_cap",
    "ukf_terms",
    "update",
]
