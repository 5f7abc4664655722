"""GM-PHD cases several test groups share: the literal Vo-Ma merge loop (the reference of every merge kernel) and
random filter scenes for property tests."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import strategies as st

from soabench.config import FilterConfig
from soabench.gmphd import Mixture
from soabench.gmphd.probabilities import beta_prior


def reference_merge_groups(m, P, w, U):
    """Literal Vo-Ma Table II loop (one vectorised Mahalanobis pass per merged component), with the tie rule of
    register row 35: d^2 <= U (1 + 1e-9)."""
    Pinv = np.linalg.inv(P)
    alive = np.ones(len(w), bool)
    label = np.full(len(w), -1)
    g = 0
    while alive.any():
        idx = np.flatnonzero(alive)
        j = idx[np.argmax(w[idx])]
        d = m[idx] - m[j]
        d2 = np.einsum("ni,nij,nj->n", d, Pinv[idx], d)
        members = idx[d2 <= U * (1.0 + 1e-9)]
        label[members] = g
        alive[members] = False
        g += 1
    return label


@st.composite
def scenes(draw):
    """(mixture, Z, ego, p_D): positions mix near-ego (r -> 0, even r = 0), in-FOV and far outside the FOV."""
    seed = draw(st.integers(0, 2**32 - 1))
    J = draw(st.integers(0, 12))
    M = draw(st.integers(0, 8))
    dynamic = draw(st.booleans())
    rng = np.random.default_rng(seed)
    ego = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), rng.uniform(-math.pi, math.pi)])
    kind = rng.integers(0, 4, J)
    radius = np.choose(kind, [rng.uniform(0, 1e-6, J), rng.uniform(0, 1.0, J), rng.uniform(1, 55, J), 1e4 * np.ones(J)])
    radius[kind == 0] *= rng.integers(0, 2, (kind == 0).sum())  # some exactly at the ego
    phi = rng.uniform(-math.pi, math.pi, J)
    pos = ego[:2] + radius[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    m = np.column_stack([pos, rng.normal(0, 2, (J, 2))])
    scale = 10.0 ** rng.uniform(-4, 2, J)
    A = rng.normal(0, 1, (J, 4, 4))
    P = scale[:, None, None] * (A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(4))
    w = 10.0 ** rng.uniform(-8, 0.5, J)
    beta = np.tile(beta_prior(FilterConfig()), (J, 1)) * rng.uniform(0.5, 3.0, (J, 1)) if dynamic else None
    mix = Mixture.from_arrays(w, m, P, beta=beta)
    Z = np.column_stack([rng.uniform(0, 60, M), rng.uniform(-math.pi, math.pi, M)])
    if J and M:  # some measurements right on components
        k = min(M, J)
        d = m[:k, :2] - ego[:2]
        Z[:k] = np.column_stack([np.hypot(d[:, 0], d[:, 1]), np.angle(d[:, 0] + 1j * d[:, 1]) - ego[2]])
        Z[:, 1] = np.angle(np.exp(1j * Z[:, 1]))
    p_D = rng.choice([0.0, 0.5, 0.98, 1.0], J)
    return mix, Z, ego, p_D
