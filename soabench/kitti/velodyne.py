"""The synthetic KITTI world in the Velodyne frame (docs/method.md §5.9): ground height, box sizes, the world -> ego
frame, and polygons without holes (what the exported label files and the ray-cast scans both draw).
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon
from shapely.ops import split

GROUND_Z = -1.73  #: ground height in the Velodyne frame (m; KITTI sensor setup)
PED_HWL = (1.75, 0.6, 0.8)  #: pedestrian box (m)
CAR_H = 1.5  #: vehicle box height (m)


def ego_frame(xy: np.ndarray, ego: np.ndarray) -> np.ndarray:
    """World points ``xy`` in the Velodyne frame of the ego pose ``ego`` = (x, y, heading): x forward, y left."""
    d = np.asarray(xy, dtype=float).reshape(-1, 2) - ego[:2]
    c, s = math.cos(ego[2]), math.sin(ego[2])
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])


def hole_free(geom) -> list[Polygon]:
    """Polygons without holes covering ``geom``: each hole is cut by a vertical line through its interior."""
    todo = [p for p in shapely.get_parts(geom) if isinstance(p, Polygon) and not p.is_empty]
    out: list[Polygon] = []
    while todo:
        p = todo.pop()
        if not p.interiors:
            out.append(p)
            continue
        x = Polygon(p.interiors[0]).representative_point().x
        y0, y1 = p.bounds[1] - 1.0, p.bounds[3] + 1.0
        todo.extend(q for q in split(p, LineString([(x, y0), (x, y1)])).geoms if isinstance(q, Polygon))
    return out
