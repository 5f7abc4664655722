"""The scene map: static geometry of one network, in world (= SUMO network) coordinates, metres.

Built by :func:`soabench.scenario.network.load_scene`. Every region is shapely geometry so the sensor, the birth
models and the figures share one definition (docs/method.md §2.1(c), docs/user-guide/sumo.md "Semantic regions").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from shapely.geometry import MultiLineString, Polygon
from shapely.geometry.base import BaseGeometry


@dataclass
class SceneMap:
    """Static geometry of a network.

    Attributes:
        name: network name (shipped name or file stem).
        world_box: the evaluated workspace W (axis-aligned rectangle), e.g. [-50, 120] x [-50, 50].
        sidewalk: union of sidewalk lanes (pedestrian-only normal-edge lanes): the semantic region Omega_sidewalk.
        crossings: union of pedestrian crossings.
        walking_areas: union of walking areas.
        roads: union of vehicle lanes and junction shapes minus walking areas.
        buildings: building polygons (from polygon files, ``type`` containing "building"), as given.
        static_occluders: parked cars and other static obstacles (polygons), present from step 0.
        doors: (D, 2) building door points where pedestrians enter (vanish) and exit (reappear).
        sidewalk_lines: centre lines of sidewalk and crossing lanes (for GMBM's boundary exits, §3.5).
        net_file: path of the .net.xml the map was built from.
        poly_files: polygon files that were loaded.
    """

    name: str
    world_box: Polygon
    sidewalk: BaseGeometry
    crossings: BaseGeometry
    walking_areas: BaseGeometry
    roads: BaseGeometry
    buildings: list[Polygon]
    static_occluders: list[Polygon]
    doors: np.ndarray
    sidewalk_lines: MultiLineString
    net_file: str = ""
    poly_files: list[str] = field(default_factory=list)

    @property
    def pedestrian_area(self) -> BaseGeometry:
        """Sidewalks, crossings and walking areas: where a present pedestrian may stand."""
        return self.sidewalk.union(self.crossings).union(self.walking_areas)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) of the world box."""
        return tuple(self.world_box.bounds)  # type: ignore[return-value]
