"""Synthetic range-bearing sensor: Recording -> Scans (ALGORITHMS.md §2.3, §3.1.1-3.1.2, §5.1).

CONTRACT (data classes below are fixed; the implementation is filled in by the sensor owner).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from shapely.geometry.base import BaseGeometry

CLUTTER = -1  #: source id of a clutter measurement


@dataclass
class Obstacles:
    """Occluders O_k seen from the sensor at one scan (§3.1.1-3.1.2), world frame. N obstacles.

    Attributes:
        polygons: list of N convex (n_i, 2) vertex arrays (convex hull of each occluder).
        kind: (N,) str, "building", "parked", or "vehicle".
        centroid_range: (N,) r'_j (m).
        centroid_bearing: (N,) alpha_c, world-frame direction of the centroid (rad).
        theta_min, theta_max: (N,) world-frame tangent ray directions (rad), wrap-safe (T14).
        r_min, r_max: (N,) tangent-point ranges r^b_min, r^b_max (m).
    Obstacles containing the sensor are left out (T15); only those intersecting the r_max disk are included.
    """

    polygons: list[np.ndarray]
    kind: np.ndarray
    centroid_range: np.ndarray
    centroid_bearing: np.ndarray
    theta_min: np.ndarray
    theta_max: np.ndarray
    r_min: np.ndarray
    r_max: np.ndarray

    def __len__(self) -> int:
        return len(self.polygons)


@dataclass
class Scan:
    """What the filters receive at scan k (never the truth).

    Attributes:
        k: scan index; t: time (s).
        ego: (3,) sensor pose x, y, theta (ego geometric centre, heading).
        Z: (M, 2) measurements (range m, bearing rad relative to the ego heading, wrapped to (-pi, pi]).
        obstacles: O_k.
        occluders: shapely polygons of every occluder at k (buildings, parked cars, other vehicles) for
            line-of-sight tests (the ``occlusion_pd`` option).
        visible_region: Omega_k = sidewalk within the FOV minus occluders and their shadows (shapely).
    """

    k: int
    t: float
    ego: np.ndarray
    Z: np.ndarray
    obstacles: Obstacles
    occluders: list[BaseGeometry]
    visible_region: BaseGeometry


@dataclass
class Scans:
    """K scans plus the per-scan truth needed by the metrics. P pedestrians (same order as the Recording).

    Attributes:
        scans: list of K :class:`Scan` (filter inputs).
        dt: sensor period (s).
        source: list of K (M_k,) int arrays: pedestrian index of each measurement, or CLUTTER (-1).
        truth_xy: (K, P, 2) true positions (NaN while absent).
        present, in_fov, visible, detected: (K, P) bool flags (§5.1, §5.4).
        ped_ids: (P,) pedestrian ids.
    """

    scans: list[Scan]
    dt: float
    source: list[np.ndarray]
    truth_xy: np.ndarray
    present: np.ndarray
    in_fov: np.ndarray
    visible: np.ndarray
    detected: np.ndarray
    ped_ids: np.ndarray

    def __len__(self) -> int:
        return len(self.scans)
