"""GM-PHD filter cycle (ALGORITHMS.md §2.11). CONTRACT: ``GMPHDFilter`` and ``StepResult`` signatures are fixed.

Usage per trial and (birth model x probability mode)::

    filt = GMPHDFilter(cfg.filter, cfg.sensor, mode="static")      # or "dynamic", "dynamic+occ"
    prev = None
    for scan in scans.scans:
        births = birth_model(BirthContext(scan, prev))
        prev = filt.step(scan, births)                              # predict, append/inject births, update,
                                                                     # reduce, extract
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class StepResult:
    """Output and diagnostics of one filter cycle at scan k (§2.10, §5.7).

    Attributes:
        k: scan index.
        X: (n, 4) extracted states, with multiplicity (floor(w + 0.5) copies).
        X_w: (n,) weight of the component each estimate came from.
        sum_w: posterior mass N_k|k after the update (before reduction).
        sum_w_reduced: mass after prune/merge/cap.
        n_predicted: components after prediction and birth (plus newborn terms, if any).
        n_updated: components after the update.
        n_reduced: components after prune/merge/cap (the paper's "posterior components").
        cap_hit: J_max was hit.
        t_predict, t_update, t_reduce: wall time of each stage (s).
        mean_pD: weight-averaged p_D estimate (dynamic mode; p_D otherwise).
        A: (M,) persistent support of each measurement, sum_j p_D,j w_j q_jl.
        kappa: (M,) clutter intensity of each measurement.
    """

    k: int
    X: np.ndarray
    X_w: np.ndarray
    sum_w: float
    sum_w_reduced: float
    n_predicted: int
    n_updated: int
    n_reduced: int
    cap_hit: bool
    t_predict: float
    t_update: float
    t_reduce: float
    mean_pD: float
    A: np.ndarray
    kappa: np.ndarray
