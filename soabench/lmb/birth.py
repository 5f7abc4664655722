"""Birth of the LMB filter from the GM-PHD's birth models (docs/method.md "LMB filter", birth).

Every birth model hands the filter :class:`~soabench.types.Births` through the same contract as for the GM-PHD;
``[lmb] birth_mapping`` says how they become Bernoullis.

``"groups"`` (default; docs/method.md "LMB filter", birth):

* the scan's Gaussian birth components are grouped with the §2.9 merge test (greedy from the heaviest, d² <= U, as
  the GM-PHD's merge groups them) and each group becomes one Bernoulli with label (k, g), existence
  r_g = min(sum of the group's weights, r_B,max) and density the group's mixture (its J_h heaviest components,
  weights normalised) (:func:`group_birth`): overlapping components pool their mass as they do in the GM-PHD;
* measurement-driven newborn terms keep their own weighting. A birth intensity's terms (PUBM, §3.2) give the
  measurement z of scan k-1 the Bernoulli r_B(z) = min(r_B,max, (1 - r_U(z)) beta_z / (kappa(z) + beta_z))
  (:func:`intensity_existence`); terms that allocate an expected number of births (ATBM, §3.4:
  ``NewbornTerms.adaptive``) give Reuter's adaptive birth (2014, eq. 75), r_B(z) = min(r_B,max, lambda_B
  (1 - r_U(z)) / sum_xi (1 - r_U(xi))), lambda_B = N_hat (:func:`adaptive_existence`).

``"components"`` (§9.5): each birth component is its own Bernoulli, r_j = min(w_j, r_B,max), N(m_j, P_j), label
(k, j) (:func:`gm_birth`), and every model's newborn terms give the adaptive birth.

In both, r_U(z) is the probability that the LMB update of scan k-1 associated z with a track, and the density of a
measurement's Bernoulli is the model's newborn term for z (given at k-1) predicted one step with the CV model
(:func:`measurement_birth`).
"""

from __future__ import annotations

import numpy as np

from soabench.gmphd.mixture import Mixture
from soabench.gmphd.models import predict as predict_mixture
from soabench.lmb.cycle import birth_groups
from soabench.lmb.tracks import Tracks, make_labels
from soabench.types import SOURCE_MEAS, Births

#: the values of ``[lmb] birth_mapping`` (docs/method.md "LMB filter"): merge groups (the default) or one Bernoulli
#: per component
BIRTH_MAPPINGS = ("groups", "components")

#: a measurement with 1 - r_U(z) at or below this counts as explained by the tracks (docs/method.md "LMB filter",
#: numerics): where a track surely took z, 1 - r_U is 0 or a few 1e-16 depending on rounding, and no birth may
#: hinge on that (the adaptive rule would even normalise such a remainder up to lambda_B / M)
EXPLAINED_TOL = 1e-9


def _unexplained(r_U: np.ndarray) -> np.ndarray:
    """1 - r_U(z) clipped to [0, 1], set to 0 at or below :data:`EXPLAINED_TOL`."""
    free = np.clip(1.0 - np.asarray(r_U, dtype=float), 0.0, 1.0)
    return np.where(free > EXPLAINED_TOL, free, 0.0)


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


def group_birth(births: Births, k: int, r_max: float, U: float, J_h: int) -> Tracks:
    """One Bernoulli per §2.9 merge group of the birth components of scan ``k`` (module docstring): groups in the
    merge's order (heaviest centre first), labels (k, g), origin the centre's source; components of zero weight
    join no group."""
    w = np.ascontiguousarray(births.w, dtype=float).reshape(-1)
    if not (w > 0.0).any():
        return Tracks.empty()
    m = np.ascontiguousarray(births.m, dtype=float).reshape(-1, 4)
    P = np.ascontiguousarray(births.P, dtype=float).reshape(-1, 4, 4)
    source = np.ascontiguousarray(births.source, dtype=np.int8).reshape(-1)
    r, origin, n_comp, comp, wk = birth_groups(w, m, P, source, float(r_max), float(U), int(J_h))
    G = len(r)
    start = np.concatenate([[0], np.cumsum(n_comp)]).astype(np.int64)
    return Tracks(r, make_labels(k, np.arange(G)), origin, np.zeros(G, dtype=np.int32), start, wk, m[comp], P[comp])


def adaptive_existence(r_U: np.ndarray, lambda_B: float, r_max: float) -> np.ndarray:
    """r_B(z) = min(r_max, lambda_B (1 - r_U(z)) / sum_xi (1 - r_U(xi))) (Reuter et al. 2014, eq. 75); all zero
    when every measurement was explained by the tracks (1 - r_U at most :data:`EXPLAINED_TOL`)."""
    free = _unexplained(r_U)
    total = free.sum()
    if not total > 0.0:
        return np.zeros_like(free)
    return np.minimum(r_max, lambda_B * free / total)


def intensity_existence(r_U: np.ndarray, beta: np.ndarray, kappa: np.ndarray, r_max: float) -> np.ndarray:
    """r_B(z) = min(r_max, (1 - r_U(z)) beta_z / (kappa(z) + beta_z)) (docs/method.md "LMB filter", birth): the
    chance that z was a new target under a birth intensity whose term at z is beta_z, among the measurements no
    track took (none where 1 - r_U is at most :data:`EXPLAINED_TOL`)."""
    free = _unexplained(r_U)
    beta = np.asarray(beta, dtype=float)
    den = np.asarray(kappa, dtype=float) + beta
    share = np.divide(beta, den, out=np.zeros_like(beta), where=den > 0.0)
    return np.minimum(r_max, free * share)


def measurement_birth(
    m: np.ndarray, P: np.ndarray, r: np.ndarray, F: np.ndarray, Q: np.ndarray, k: int, j0: int
) -> Tracks:
    """Bernoullis at scan ``k`` from the newborn terms (m, P) of the previous scan's measurements with existences
    ``r`` (:func:`adaptive_existence`, :func:`intensity_existence`): labels (k, j0 + l) for measurement l, the
    densities predicted one step."""
    keep = np.flatnonzero(np.asarray(r) > 0.0)
    if len(keep) == 0:
        return Tracks.empty()
    mix = predict_mixture(Mixture.from_arrays(r[keep], np.asarray(m)[keep], np.asarray(P)[keep]), F, Q, 1.0)
    return Tracks.single(r[keep], mix.m, mix.P, make_labels(k, j0 + keep), SOURCE_MEAS)
