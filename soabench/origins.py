"""Posterior components by birth origin (docs/method.md §5.7): where the components a filter keeps come from.

After the reduction of scan k, every posterior component carries the source code of the birth term it descends
from (``Mixture.origin``, :data:`soabench.types.SOURCE_NAMES`; after a merge the source of the heaviest member) and
its age (predictions survived; a merge keeps the group's largest age). :func:`origin_counts` splits the posterior
count J_k into

* ``n_born_<source>``: components born at this scan (age 0) that survived pruning and merging, per birth source
  (occlusion, semantic, FOV boundary, uniform grid, fixed GM, measurement-driven newborn);
* ``n_surv_<source>``: components that existed before this scan (age > 0), per the source they were born from;
* ``n_unsourced``: components without a birth source (a hand-built prior, or a foreign tracker whose hypotheses
  carry no origin: then every component it reports).

The columns sum to the posterior component count ``n_components`` at every scan; ``steps.csv`` carries them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from soabench.types import SOURCE_NAMES

if TYPE_CHECKING:
    from soabench.types import StepResult

N_SOURCES = len(SOURCE_NAMES)
#: the count columns, in the order :func:`origin_counts` returns them
ORIGIN_KEYS: tuple[str, ...] = (
    *(f"n_born_{s}" for s in SOURCE_NAMES),
    *(f"n_surv_{s}" for s in SOURCE_NAMES),
    "n_unsourced",
)
_UNSOURCED = 2 * N_SOURCES  #: the bin of components without a known source


def origin_counts(origin: np.ndarray, age: np.ndarray) -> np.ndarray:
    """(len(:data:`ORIGIN_KEYS`),) int64 counts of the components with source codes ``origin`` and ages ``age``.

    Bin of a component: its source code s if born this scan (age 0), ``N_SOURCES + s`` if older, the last bin if
    s is not a known source code (``ORIGIN_PERSISTENT`` or a plugin's own code). One ``np.bincount``.
    """
    o = np.asarray(origin).astype(np.int64, copy=False).reshape(-1)
    a = np.asarray(age).reshape(-1)
    known = (o >= 0) & (o < N_SOURCES)
    bins = np.where(known, o + N_SOURCES * (a > 0), _UNSOURCED)
    return np.bincount(bins, minlength=_UNSOURCED + 1)


def unsourced_counts(n: int) -> np.ndarray:
    """The counts of ``n`` components of unknown origin (a tracker that reports no birth sources)."""
    out = np.zeros(_UNSOURCED + 1, dtype=np.int64)
    out[_UNSOURCED] = n
    return out


def origin_counts_of(result: StepResult) -> np.ndarray:
    """The origin counts of a step result: the filter's own, or every component unsourced when the tracker gave
    none (``StepResult.origin_counts is None``)."""
    if result.origin_counts is None:
        return unsourced_counts(int(result.n_reduced))
    return np.asarray(result.origin_counts, dtype=np.int64)
