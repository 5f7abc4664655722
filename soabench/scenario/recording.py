"""The Recording: what really happened in one SUMO run (ground truth), sampled at the SUMO step.

Frames and units: world frame = SUMO network coordinates (x east, y north, metres); angles are mathematical
headings (CCW from +x, radians, wrapped to (-pi, pi]); times in seconds. Absent entries are NaN.
SUMO conventions are already converted (front bumper -> centre, navigational angle -> math heading).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from soabench.errors import SoabenchError, require


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
        """Write the Recording as a compressed .npz (format: README, "Recording format"); exact round trip."""
        occ = [np.asarray(o, dtype=float).reshape(-1, 2) for o in self.static_occluders]
        offsets = np.cumsum([0] + [len(o) for o in occ]).astype(np.int64)
        np.savez_compressed(
            Path(path),
            format_version=np.array(FORMAT_VERSION),
            t=np.asarray(self.t, dtype=float),
            step_length=np.array(float(self.step_length)),
            ego_pose=np.asarray(self.ego_pose, dtype=float),
            ego_footprint=np.asarray(self.ego_footprint, dtype=float),
            ped_ids=np.asarray(self.ped_ids, dtype=str),
            ped_present=np.asarray(self.ped_present, dtype=bool),
            ped_xy=np.asarray(self.ped_xy, dtype=float),
            ped_speed=np.asarray(self.ped_speed, dtype=float),
            ped_heading=np.asarray(self.ped_heading, dtype=float),
            veh_ids=np.asarray(self.veh_ids, dtype=str),
            veh_present=np.asarray(self.veh_present, dtype=bool),
            veh_footprint=np.asarray(self.veh_footprint, dtype=float),
            static_occluder_xy=np.concatenate(occ) if occ else np.zeros((0, 2)),
            static_occluder_offsets=offsets,
            seed=np.array(int(self.seed), dtype=np.int64),
            net=np.array(str(self.net)),
            meta_json=np.array(json.dumps(self.meta, sort_keys=True)),
        )

    @classmethod
    def load_npz(cls, path: str | Path) -> Recording:
        """Read a Recording written by :meth:`save_npz`; SoabenchError on a missing or foreign file."""
        p = Path(path)
        require(p.is_file(), f"recording file {str(path)!r} does not exist; give a .npz written by save_npz")
        try:
            with np.load(p, allow_pickle=False) as z:
                d = {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            raise SoabenchError(f"recording file {str(p)!r} is not a readable .npz ({exc})") from None
        missing = sorted(set(_KEYS) - set(d))
        require(not missing, f"recording file {str(p)!r} lacks arrays {missing}; it was not written by save_npz")
        xy, off = d["static_occluder_xy"], d["static_occluder_offsets"]
        return cls(
            t=d["t"],
            step_length=float(d["step_length"]),
            ego_pose=d["ego_pose"],
            ego_footprint=d["ego_footprint"],
            ped_ids=d["ped_ids"],
            ped_present=d["ped_present"],
            ped_xy=d["ped_xy"],
            ped_speed=d["ped_speed"],
            ped_heading=d["ped_heading"],
            veh_ids=d["veh_ids"],
            veh_present=d["veh_present"],
            veh_footprint=d["veh_footprint"],
            static_occluders=[xy[off[i] : off[i + 1]] for i in range(len(off) - 1)],
            seed=int(d["seed"]),
            net=str(d["net"]),
            meta=json.loads(str(d["meta_json"])),
        )


FORMAT_VERSION = 1
_KEYS = (
    "t", "step_length", "ego_pose", "ego_footprint", "ped_ids", "ped_present", "ped_xy", "ped_speed", "ped_heading",
    "veh_ids", "veh_present", "veh_footprint", "static_occluder_xy", "static_occluder_offsets", "seed", "net",
    "meta_json",
)  # fmt: skip
