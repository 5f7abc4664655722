"""The Recording: what really happened in one SUMO run (ground truth), sampled at the SUMO step.

Frames and units: world frame = SUMO network coordinates (x east, y north, metres); angles are mathematical
headings (CCW from +x, radians, wrapped to (-pi, pi]); times in seconds. Absent entries are NaN.
SUMO conventions are already converted (front bumper -> centre, navigational angle -> math heading).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class Recording:
    """Ground truth of one scenario run. T steps, P pedestrians (stable ids), V vehicle slots.

    Attributes:
        t: (T,) simulation time of each step (s).
        step_length: SUMO step (s).
        ego_pose: (T, 3) ego geometric centre x, y (m) and heading theta (rad).
        ego_footprint: (T, 4, 2) ego rectangle corners (m).
        ped_ids: (P,) stable pedestrian ids (str).
        ped_present: (T, P) bool, True while the pedestrian is in the scene (not inside a building).
        ped_xy: (T, P, 2) position (m), NaN while absent.
        ped_speed: (T, P) speed (m/s), NaN while absent.
        ped_heading: (T, P) heading (rad), NaN while absent.
        veh_ids: (V,) ids of the other (non-ego) vehicle slots.
        veh_present: (T, V) bool.
        veh_footprint: (T, V, 4, 2) corners of each other vehicle (m), NaN while absent.
        static_occluders: list of (n_i, 2) polygons (parked cars), constant over time.
        seed: trial seed used for SUMO and the scenario.
        net: network name.
        meta: free-form provenance (SUMO version, pedestrian model, ...).
    """

    t: np.ndarray
    step_length: float
    ego_pose: np.ndarray
    ego_footprint: np.ndarray
    ped_ids: np.ndarray
    ped_present: np.ndarray
    ped_xy: np.ndarray
    ped_speed: np.ndarray
    ped_heading: np.ndarray
    veh_ids: np.ndarray
    veh_present: np.ndarray
    veh_footprint: np.ndarray
    static_occluders: list[np.ndarray]
    seed: int
    net: str
    meta: dict = field(default_factory=dict)

    def save_npz(self, path: str | Path) -> None:
        """Write the Recording as a compressed .npz (format in README, "Recording format")."""
        raise NotImplementedError  # implemented by the scenario module owner

    @classmethod
    def load_npz(cls, path: str | Path) -> Recording:
        raise NotImplementedError
