"""Birth of the LMB filter from the GM-PHD's birth models (docs/method.md "LMB filter", register row 33).

Every birth model hands the filter :class:`~soabench.types.Births` through the same contract as for the GM-PHD:

* a Gaussian birth component (w_j, m_j, P_j) becomes the Bernoulli with label (k, j), existence
  r_j = min(w_j, r_B,max) and density N(m_j, P_j) (:func:`gm_birth`);
* measurement-driven newborn terms (PUBM, ATBM) become the adaptive birth of Reuter et al. (2014, eq. 75): at scan
  k, one Bernoulli per measurement z of scan k-1 with r_B(z) = min(r_B,max, lambda_B (1 - r_U(z)) / sum_xi
  (1 - r_U(xi))), r_U(z) the probability that the LMB update of scan k-1 associated z with a track, lambda_B = N_hat,
  and the density the model's newborn term for z (given at k-1) predicted one step with the CV model
  (:func:`adaptive_birth`). The newborn terms' own weights (beta) are not used: the LMB's birth mass is r_B.
"""

from __future__ import annotations

import numpy as np

from soabench.gmphd.mixture import Mixture
from soabench.gmphd.models import predict as predict_mixture
from soabench.lmb.tracks import Tracks, make_labels
from soabench.types import SOURCE_MEAS, Births


def gm_birth(births: Births, k: int, r_max: float) -> Tracks:
    """Bernoullis r_j = min(w_j, r_max), N(m_j, P_j), labels (k, j) of the birth components of scan ``k``."""
    J = len(births)
    if J == 0:
        return Tracks.empty()
    r = np.minimum(np.asarray(births.w, dtype=float), r_max)
    keep = np.flatnonzero(r > 0.0)
    return Tracks.single(
        r[keep],
        np.asarray(births.m, dtype=float)[keep],
        np.asarray(births.P, dtype=float)[keep],
        make_labels(k, keep),
        np.asarray(births.source, dtype=np.int8)[keep],
    )


def adaptive_existence(r_U: np.ndarray, lambda_B: float, r_max: float) -> np.ndarray:
    """r_B(z) = min(r_max, lambda_B (1 - r_U(z)) / sum_xi (1 - r_U(xi))) (Reuter et al. 2014, eq. 75); all zero
    when every measurement was fully explained by the tracks."""
    free = np.clip(1.0 - np.asarray(r_U, dtype=float), 0.0, 1.0)
    total = free.sum()
    if not total > 0.0:
        return np.zeros_like(free)
    return np.minimum(r_max, lambda_B * free / total)


def adaptive_birth(
    m: np.ndarray,
    P: np.ndarray,
    r_U: np.ndarray,
    lambda_B: float,
    r_max: float,
    F: np.ndarray,
    Q: np.ndarray,
    k: int,
    j0: int,
) -> Tracks:
    """Adaptive birth at scan ``k`` from the newborn terms (m, P) of the previous scan's measurements and their
    association probabilities ``r_U``: labels (k, j0 + l) for measurement l."""
    r = adaptive_existence(r_U, lambda_B, r_max)
    keep = np.flatnonzero(r > 0.0)
    if len(keep) == 0:
        return Tracks.empty()
    mix = predict_mixture(Mixture.from_arrays(r[keep], np.asarray(m)[keep], np.asarray(P)[keep]), F, Q, 1.0)
    return Tracks.single(r[keep], mix.m, mix.P, make_labels(k, j0 + keep), SOURCE_MEAS)
