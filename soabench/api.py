"""The public API of soabench in one place: import from here, not from the stages (docs/user-guide/birth-model.md,
docs/user-guide/tracker.md).

The data that flows (:mod:`soabench.types`):

* :class:`Recording`: the truth of one scenario run; :class:`Scans` / :class:`Scan`: what a tracker receives per scan
  (ego pose, range-bearing measurements Z, occluders, visible region) plus the truth the metrics read;
* :class:`Births` and :class:`NewbornTerms`: what a birth model hands our GM-PHD filter, from a :class:`BirthContext`;
* :class:`Estimates`: what any tracker returns per scan; :class:`StepResult`: the richer output of our GM-PHD.

The two extension points (:mod:`soabench.protocols`): :class:`BirthModel` and :class:`Tracker` (built from a
:class:`TrackerSetup`). :class:`GMPHDTracker` is our filter with a birth model as a tracker; :func:`build_components`
and :class:`FOVRule` are the shared birth builder and FOV rule (docs/method.md §3.0).

Plugins register by entry point (groups :data:`BIRTH_GROUP`, :data:`TRACKER_GROUP`) or are named on the command line
as ``module:Class``; :func:`resolve` turns a name into the class as the harness does.
"""

from __future__ import annotations

from soabench.birth.base import FOVRule, births_from, build_components, isotropic
from soabench.plugins import BIRTH_GROUP, TRACKER_GROUP, resolve
from soabench.protocols import BirthModel, Tracker, TrackerSetup
from soabench.trackers import GMPHDTracker, run_tracker
from soabench.types import (
    CLUTTER,
    SOURCE_FOV,
    SOURCE_GM,
    SOURCE_GRID,
    SOURCE_MEAS,
    SOURCE_NAMES,
    SOURCE_OCCL,
    SOURCE_SEM,
    BirthContext,
    Births,
    Estimates,
    NewbornTerms,
    Obstacles,
    Recording,
    Scan,
    Scans,
    StepResult,
)

__all__ = [
    "BIRTH_GROUP",
    "CLUTTER",
    "SOURCE_FOV",
    "SOURCE_GM",
    "SOURCE_GRID",
    "SOURCE_MEAS",
    "SOURCE_NAMES",
    "SOURCE_OCCL",
    "SOURCE_SEM",
    "TRACKER_GROUP",
    "BirthContext",
    "BirthModel",
    "Births",
    "Estimates",
    "FOVRule",
    "GMPHDTracker",
    "NewbornTerms",
    "Obstacles",
    "Recording",
    "Scan",
    "Scans",
    "StepResult",
    "Tracker",
    "TrackerSetup",
    "births_from",
    "build_components",
    "isotropic",
    "resolve",
    "run_tracker",
]
