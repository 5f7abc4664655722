"""The Recording: what really happened in one SUMO run (ground truth), sampled at the SUMO step.

Frames and units: world frame = SUMO network coordinates (x east, y north, metres); angles are mathematical
headings (CCW from +x, radians, wrapped to (-pi, pi]); times in seconds. Absent entries are NaN.
SUMO conventions are already converted (front bumper -> centre, navigational angle -> math heading).

The class lives in the bottom layer, :mod:`soabench.types`; this module keeps the old import path working.
"""

from __future__ import annotations

from soabench.types import RECORDING_FORMAT_VERSION as FORMAT_VERSION
from soabench.types import Recording

__all__ = ["FORMAT_VERSION", "Recording"]
