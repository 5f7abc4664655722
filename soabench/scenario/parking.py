"""Kerbside parked cars at a given density: the occluder-density axis of ``soabench sweep occlusion``.

Parked cars are static occluders (docs/user-guide/sumo.md "Parked cars": exact, free, present from step 0). They stand
on
*parking lanes*: normal-edge lanes that carry some vehicle class but neither passenger cars nor pedestrians (the
shipped scenes use ``allow="custom1"`` lanes beside the sidewalk), so SUMO traffic never drives through them.
Placement is deterministic (no random numbers): along every parking-lane stretch inside the world box, minus a
clearance at both lane ends (junctions and their crossings), ``floor(density * L / 100)`` cars are spaced evenly.
"""

from __future__ import annotations

import math

import numpy as np
from shapely.geometry import LineString, Polygon

from soabench.errors import require

#: parked car footprint (m): length, width (the shipped intersection's parked cars).
CAR_LENGTH, CAR_WIDTH = 4.5, 1.9
#: no car closer than this to either end of a parking lane (junction areas, crossings).
END_CLEARANCE = 6.0


def parking_lanes(net) -> list:
    """Normal-edge lanes for parked cars (some vehicle class, but neither passenger cars nor pedestrians)."""
    out = []
    for e in net.getEdges(withInternal=False):
        if e.getFunction() != "":
            continue
        for lane in e.getLanes():
            perms = set(lane.getPermissions())
            if perms and not lane.allows("passenger") and not lane.allows("pedestrian"):
                out.append(lane)
    return sorted(out, key=lambda ln: ln.getID())


def _rectangle(centre: np.ndarray, u: np.ndarray) -> Polygon:
    n = np.array([-u[1], u[0]])
    a, b = 0.5 * CAR_LENGTH * u, 0.5 * CAR_WIDTH * n
    return Polygon([centre - a - b, centre + a - b, centre + a + b, centre - a + b])


def kerbside_parking(net, world: Polygon, density: float) -> tuple[list[Polygon], float]:
    """(parked cars, kerb length in m): ``density`` cars per 100 m of parking lane inside ``world`` (module doc)."""
    lanes = parking_lanes(net)
    require(
        density == 0 or bool(lanes),
        f'parking.density = {density!r} needs parking lanes (normal-edge lanes such as allow="custom1" that carry '
        "neither passenger cars nor pedestrians); this network has none, so set parking.density = 0",
    )
    cars: list[Polygon] = []
    kerb = 0.0
    for lane in lanes:
        line = LineString(lane.getShape())
        if line.length <= 2 * END_CLEARANCE:
            continue
        usable = line.intersection(world)
        parts = [usable] if usable.geom_type == "LineString" else list(getattr(usable, "geoms", []))
        for part in parts:
            if part.geom_type != "LineString" or part.is_empty:
                continue
            s0, s1 = sorted(line.project(part.interpolate(f, normalized=True)) for f in (0.0, 1.0))
            a, b = max(s0, END_CLEARANCE), min(s1, line.length - END_CLEARANCE)
            if b - a < CAR_LENGTH:
                continue
            kerb += b - a
            n = int(math.floor(density * (b - a) / 100.0 + 1e-9))
            n = min(n, int((b - a) // (CAR_LENGTH + 1.0)))
            for i in range(n):
                s = a + (i + 0.5) * (b - a) / n
                p, q = line.interpolate(max(s - 0.5, 0.0)), line.interpolate(min(s + 0.5, line.length))
                u = np.array([q.x - p.x, q.y - p.y])
                u /= max(np.hypot(*u), 1e-9)
                c = line.interpolate(s)
                cars.append(_rectangle(np.array([c.x, c.y]), u))
    return cars, kerb
