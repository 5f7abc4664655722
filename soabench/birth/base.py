"""The BirthModel protocol and what a birth model hands the filter (DESIGN.md; ALGORITHMS.md §2.11, §3.0).

CONTRACT: the data classes and the protocol below are fixed; the shared builder and FOV rule are implemented by
the birth owner in this module.

A birth model is built once per trial, ``Model(cfg, sensor, scene, rng)``, and called once per scan with a
:class:`BirthContext`. It returns :class:`Births`: Gaussian components appended to the predicted intensity before
the update (S-OA, UBM, GMBM, ATBM prev-scan), and/or measurement-driven newborn terms that the update handles
inside each measurement's normaliser with no missed-detection term (PUBM, ATBM same-scan).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from soabench.config import BirthConfig, SensorConfig
    from soabench.gmphd.filter import StepResult
    from soabench.scenario.scene import SceneMap
    from soabench.sensor import Scan

# source codes of birth components (Births.source), for figures and diagnostics
SOURCE_OCCL, SOURCE_SEM, SOURCE_FOV, SOURCE_GRID, SOURCE_GM, SOURCE_MEAS = range(6)
SOURCE_NAMES = ("occl", "sem", "fov", "grid", "gm", "meas")


@dataclass
class NewbornTerms:
    """Measurement-driven newborn terms of scan k, one per measurement, in Z_k order (§3.2, §3.4).

    Attributes:
        m: (M, 4) newborn means (inverse measurement, zero velocity).
        P: (M, 4, 4) newborn covariances blkdiag(J R J^T, sigma_v^2 I).
        beta: callable ``beta(A, kappa) -> (M,)``: the additive term beta_l of each normaliser
            L_l = kappa_l + A_l + beta_l, given the persistent support A_l = sum_j p_D,j w_j q_jl and the clutter
            intensity kappa_l. The newborn posterior weight is beta_l / L_l, its mean/cov (m_l, P_l), and it gets
            no missed-detection term.
    """

    m: np.ndarray
    P: np.ndarray
    beta: Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass
class Births:
    """Birth of one scan: appended Gaussian components (J of them, J may be 0) and optional newborn terms."""

    w: np.ndarray  #: (J,) weights
    m: np.ndarray  #: (J, 4) means [p_x, p_y, v_x, v_y]
    P: np.ndarray  #: (J, 4, 4) covariances
    source: np.ndarray  #: (J,) int source codes (SOURCE_*)
    newborn: NewbornTerms | None = None

    @classmethod
    def empty(cls) -> Births:
        return cls(np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4, 4)), np.zeros(0, dtype=np.int8))

    def __len__(self) -> int:
        return len(self.w)


@dataclass
class BirthContext:
    """What a birth model may look at when scan k arrives (time alignment: everything is at k, §2.12 item 10)."""

    scan: Scan  #: ego pose, Z_k, obstacles O_k, occluders, visible semantic region at k
    prev: StepResult | None  #: the filter's result at k-1 (None at k = 0); ATBM prev-scan reads it
    p_D_b: float = 0.98  #: detection probability of a newborn (filter p_D; Beta prior mean in dynamic mode)


class BirthModel(Protocol):
    """``Model(cfg, sensor, scene, rng)`` then ``model(ctx) -> Births`` once per scan."""

    name: str

    def __init__(self, cfg: BirthConfig, sensor: SensorConfig, scene: SceneMap, rng: np.random.Generator) -> None: ...

    def __call__(self, ctx: BirthContext) -> Births: ...
