"""The Gaussian mixture as arrays, with per-component metadata (docs/method.md §2.4).

A mixture of J components is ``w (J,)``, ``m (J, 4)``, ``P (J, 4, 4)`` plus

* ``origin (J,) int8``: the birth source code of the component (``soabench.types.SOURCE_*``) kept for its
  whole life (after merging: that of the heaviest member j*); ``ORIGIN_PERSISTENT = -1`` marks components given
  without a source (e.g. a prior built by hand). A component is persistent once ``age > 0``.
* ``n_det (J,) int32``: number of detection updates so far.
* ``age (J,) int32``: predictions survived since birth (0 for births of this scan).
* ``beta (J, 4) float`` in dynamic mode only: the Beta parameters ``sD, tD, sS, tS`` (§4.2, §4.3); ``None`` in
  static mode.
* ``label (J,) int64``: the track label of the component (docs/method.md §2.13): fresh at birth, kept through
  prediction and update, that of the heaviest member j* after merging; ``UNLABELLED = 0`` marks components given
  without one. Labels never enter the arithmetic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ORIGIN_PERSISTENT = -1  #: origin code of a component given without a birth source
UNLABELLED = 0  #: label of a component given without one (a filter run numbers its labels from 1)


@dataclass
class Mixture:
    """Gaussian mixture intensity sum_j w_j N(x; m_j, P_j) (§2.4); in dynamic mode times Beta(p_D) Beta(p_S)."""

    w: np.ndarray
    m: np.ndarray
    P: np.ndarray
    origin: np.ndarray
    n_det: np.ndarray
    age: np.ndarray
    beta: np.ndarray | None = None
    label: np.ndarray | None = None  #: (J,) int64; None when built: every component UNLABELLED

    def __post_init__(self) -> None:
        if self.label is None:
            self.label = np.full(len(self.w), UNLABELLED, dtype=np.int64)

    @classmethod
    def empty(cls, dynamic: bool = False) -> Mixture:
        """The empty mixture (the prior at k = 0, §2.11)."""
        return cls(
            np.zeros(0),
            np.zeros((0, 4)),
            np.zeros((0, 4, 4)),
            np.zeros(0, dtype=np.int8),
            np.zeros(0, dtype=np.int32),
            np.zeros(0, dtype=np.int32),
            np.zeros((0, 4)) if dynamic else None,
        )

    @classmethod
    def from_arrays(
        cls,
        w: np.ndarray,
        m: np.ndarray,
        P: np.ndarray,
        origin: np.ndarray | int = ORIGIN_PERSISTENT,
        n_det: np.ndarray | int = 0,
        age: np.ndarray | int = 0,
        beta: np.ndarray | None = None,
        label: np.ndarray | int = UNLABELLED,
    ) -> Mixture:
        """Build a mixture from weights, means and covariances; scalar metadata is broadcast to all components."""
        w = np.asarray(w, dtype=float).reshape(-1)
        J = len(w)
        m = np.asarray(m, dtype=float).reshape(J, 4)
        P = np.asarray(P, dtype=float).reshape(J, 4, 4)
        origin_a = np.broadcast_to(np.asarray(origin, dtype=np.int8), (J,)).copy()
        n_det_a = np.broadcast_to(np.asarray(n_det, dtype=np.int32), (J,)).copy()
        age_a = np.broadcast_to(np.asarray(age, dtype=np.int32), (J,)).copy()
        beta_a = None if beta is None else np.broadcast_to(np.asarray(beta, dtype=float), (J, 4)).copy()
        label_a = np.broadcast_to(np.asarray(label, dtype=np.int64), (J,)).copy()
        return cls(w, m, P, origin_a, n_det_a, age_a, beta_a, label_a)

    def __len__(self) -> int:
        return len(self.w)

    @property
    def dynamic(self) -> bool:
        """True when the components carry Beta parameters (§4.2-4.5)."""
        return self.beta is not None

    @property
    def sD(self) -> np.ndarray:
        return self._beta_col(0)

    @property
    def tD(self) -> np.ndarray:
        return self._beta_col(1)

    @property
    def sS(self) -> np.ndarray:
        return self._beta_col(2)

    @property
    def tS(self) -> np.ndarray:
        return self._beta_col(3)

    def _beta_col(self, i: int) -> np.ndarray:
        if self.beta is None:
            raise AttributeError("static-mode mixture has no Beta parameters")
        return self.beta[:, i]

    @property
    def mass(self) -> float:
        """Sum of weights: the expected number of targets."""
        return float(self.w.sum())

    def select(self, idx: np.ndarray) -> Mixture:
        """The sub-mixture at integer or boolean index ``idx`` (copies)."""
        return Mixture(
            self.w[idx],
            self.m[idx],
            self.P[idx],
            self.origin[idx],
            self.n_det[idx],
            self.age[idx],
            None if self.beta is None else self.beta[idx],
            self.label[idx],
        )

    def copy(self) -> Mixture:
        return self.select(slice(None)) if len(self) else Mixture.empty(self.dynamic)

    @staticmethod
    def concatenate(parts: list[Mixture]) -> Mixture:
        """Stack mixtures (all static or all dynamic) in order."""
        dyn = parts[0].dynamic
        if any(p.dynamic != dyn for p in parts):
            raise ValueError("cannot concatenate static and dynamic mixtures")
        return Mixture(
            np.concatenate([p.w for p in parts]),
            np.concatenate([p.m for p in parts]),
            np.concatenate([p.P for p in parts]),
            np.concatenate([p.origin for p in parts]),
            np.concatenate([p.n_det for p in parts]),
            np.concatenate([p.age for p in parts]),
            np.concatenate([p.beta for p in parts]) if dyn else None,
            np.concatenate([p.label for p in parts]),
        )
