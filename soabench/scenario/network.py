"""SUMO network + polygon files -> :class:`SceneMap` (docs/method.md §2.1(c), docs/user-guide/sumo.md "Semantic
regions").

Every region is shapely geometry in world (= SUMO network) coordinates, clipped to the world box W:

* sidewalk: normal-edge lanes that allow pedestrians but not passenger cars, centre line buffered by width/2
  (flat caps, mitre joins) -- the semantic birth region Omega_sidewalk;
* crossings: crossing lanes buffered the same way; walking areas: their lane shapes (already outlines);
* roads: every lane that allows some non-pedestrian class (driving and parking lanes, normal and internal), plus
  junction shapes, minus walking areas;
* buildings: polygons whose ``type`` contains "building"; static occluders: polygons whose ``type`` contains one
  of :data:`OCCLUDER_TYPES` (other polygon types, e.g. OSM land use, are ignored);
* doors: door points projected onto the nearest sidewalk centre line (where SUMO persons arrive and depart).
"""

from __future__ import annotations

import os
import xml.sax
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import shapely
import shapely.ops
from shapely.geometry import LineString, MultiLineString, Point, Polygon, box
from shapely.geometry.base import BaseGeometry

from soabench.errors import SoabenchError, require
from soabench.scenario.config import MAX_COORDINATE
from soabench.scenario.scene import SceneMap

#: farthest a scenario's door may lie from a sidewalk centre line (m); as far as a derived door may lie from a
#: sidewalk (:func:`default_doors`)
MAX_DOOR_DISTANCE = 30.0
#: polygon ``type`` substrings (case-insensitive) that make a polygon a static occluder.
OCCLUDER_TYPES = ("parked", "car", "vehicle", "obstacle", "occluder", "wall")

_MITRE = {"cap_style": "flat", "join_style": "mitre", "mitre_limit": 3.0}


def _check_file(path: str | os.PathLike, what: str, suffix: str = ".xml") -> Path:
    p = Path(path)
    require(p.is_file(), f"{what} {str(path)!r} does not exist; give the path of an existing {suffix} file")
    return p


def _require_well_formed(p: Path, what: str) -> None:
    """Raise a one-line SoabenchError if ``p`` is not well-formed XML (sumolib may fail earlier, less clearly)."""
    import xml.etree.ElementTree as ET

    try:
        ET.parse(p)
    except ET.ParseError as exc:
        raise SoabenchError(f"{what} {str(p)!r} is not valid XML ({exc})") from None


def read_net(net_file: str | os.PathLike):  # -> sumolib.net.Net
    """Read a SUMO network with internal edges, crossings and walking areas; SoabenchError on a bad file."""
    import sumolib

    p = _check_file(net_file, "network file", ".net.xml")
    try:
        net = sumolib.net.readNet(str(p), withInternal=True, withPedestrianConnections=True)
    except xml.sax.SAXParseException as exc:
        raise SoabenchError(
            f"network file {str(p)!r} is not valid XML ({exc.getMessage()} at line {exc.getLineNumber()})"
        ) from None
    except Exception as exc:  # sumolib raises assorted errors on non-network XML
        _require_well_formed(p, "network file")
        raise SoabenchError(f"network file {str(p)!r} is not a SUMO network ({type(exc).__name__}: {exc})") from None
    require(
        len(net.getEdges()) > 0, f"network file {str(p)!r} holds no edges; give a SUMO .net.xml built by netconvert"
    )
    return net


def _require_not_a_network(p: Path) -> None:
    """Refuse a SUMO network given as a polygon file (it reads as one without polygons)."""
    import xml.etree.ElementTree as ET

    try:
        _, root = next(ET.iterparse(p, events=("start",)))
    except (ET.ParseError, StopIteration):
        return  # the polygon reader names what is wrong with the file
    require(
        root.tag != "net",
        f"polygon file {str(p)!r} is a SUMO network, not a polygon file; give it with --net (polygons: --poly)",
    )


def _require_outline(p: Path, poly) -> None:
    """A building's or occluder's outline: at least 3 points, finite coordinates within
    :data:`~soabench.scenario.config.MAX_COORDINATE` (a scene spans at most 10 000 km)."""

    where = f"polygon {poly.id!r} ({poly.type}) of {str(p)!r}"
    require(len(poly.shape) >= 3, f"{where} has {len(poly.shape)} point(s); an outline needs at least 3")
    xy = np.asarray(poly.shape, dtype=float)
    bad = xy[~(np.isfinite(xy) & (np.abs(xy) <= MAX_COORDINATE))]
    if len(bad):
        raise SoabenchError(
            f"{where} has the coordinate {float(bad[0])!r}; allowed: finite, |value| <= {MAX_COORDINATE:g} m"
        )


def read_polygons(
    poly_files: Sequence[str | os.PathLike], skip_parked: bool = False
) -> tuple[list[Polygon], list[Polygon]]:
    """Buildings and static occluders from SUMO polygon files (``<poly type=.. shape=..>``), in file order.
    ``skip_parked``: leave out occluders whose type contains "parked" (``[parking] density`` replaces them)."""
    import sumolib

    buildings: list[Polygon] = []
    occluders: list[Polygon] = []
    for f in poly_files:
        p = _check_file(f, "polygon file")
        _require_not_a_network(p)
        try:
            polys = sumolib.shapes.polygon.read(str(p), includeTaz=False)
        except xml.sax.SAXParseException as exc:
            raise SoabenchError(
                f"polygon file {str(p)!r} is not valid XML ({exc.getMessage()} at line {exc.getLineNumber()})"
            ) from None
        except Exception as exc:
            _require_well_formed(p, "polygon file")
            raise SoabenchError(
                f"polygon file {str(p)!r} could not be read as SUMO polygons ({type(exc).__name__}: {exc})"
            ) from None
        ids: set[str] = set()
        for poly in polys:
            require(poly.id not in ids, f"polygon file {str(p)!r} holds the polygon id {poly.id!r} twice")
            ids.add(poly.id)
            kind = (poly.type or "").lower()
            used = "building" in kind or (
                any(k in kind for k in OCCLUDER_TYPES) and not (skip_parked and "parked" in kind)
            )
            if not used:
                continue
            _require_outline(p, poly)
            geom = shapely.make_valid(Polygon([(float(x), float(y)) for x, y in poly.shape]))
            if geom.is_empty or geom.area <= 0:
                continue
            if geom.geom_type != "Polygon":  # keep the largest piece of a self-intersecting outline
                geom = max(getattr(geom, "geoms", [geom]), key=lambda g: g.area)
            if "building" in kind:
                buildings.append(geom)
            elif any(k in kind for k in OCCLUDER_TYPES) and not (skip_parked and "parked" in kind):
                occluders.append(geom)
    return buildings, occluders


def _lane_line(lane) -> LineString | None:
    shape = lane.getShape()
    return LineString(shape) if len(shape) >= 2 else None


def _is_sidewalk(lane) -> bool:
    return lane.allows("pedestrian") and not lane.allows("passenger")


def _carries_vehicles(lane) -> bool:
    return len(set(lane.getPermissions()) - {"pedestrian"}) > 0


def net_regions(net) -> dict[str, BaseGeometry | list[LineString]]:
    """Unclipped semantic regions of a sumolib network (see the module docstring)."""
    sidewalk, crossings, walking, road, lines = [], [], [], [], []
    for edge in net.getEdges(withInternal=True):
        func = edge.getFunction()
        for lane in edge.getLanes():
            if func == "walkingarea":
                shape = lane.getShape()
                if len(shape) >= 3:
                    walking.append(shapely.make_valid(Polygon(shape)))
                continue
            line = _lane_line(lane)
            if line is None or line.length <= 0:
                continue
            area = line.buffer(lane.getWidth() / 2.0, **_MITRE)
            if func == "crossing":
                crossings.append(area)
                lines.append(line)
            elif func == "" and _is_sidewalk(lane):
                sidewalk.append(area)
                lines.append(line)
            elif _carries_vehicles(lane):
                road.append(area)
    for node in net.getNodes():
        shape = node.getShape()
        if len(shape) >= 3:
            road.append(shapely.make_valid(Polygon(shape)))
    walking_u = shapely.union_all(walking) if walking else Polygon()
    road_u = shapely.union_all(road).difference(walking_u) if road else Polygon()
    return {
        "sidewalk": shapely.union_all(sidewalk) if sidewalk else Polygon(),
        "crossings": shapely.union_all(crossings) if crossings else Polygon(),
        "walking_areas": walking_u,
        "roads": road_u,
        "lines": lines,
    }


def sidewalk_lanes(net) -> list:
    """Normal-edge sidewalk lanes (pedestrians allowed, passenger cars not), sorted by id."""
    lanes = [ln for e in net.getEdges(withInternal=False) for ln in e.getLanes() if _is_sidewalk(ln)]
    return sorted(lanes, key=lambda ln: ln.getID())


def default_doors(buildings: Sequence[Polygon], sidewalk: BaseGeometry, max_dist: float = 30.0) -> np.ndarray:
    """One door per building: the point of its outline nearest the sidewalk region (buildings farther away than
    ``max_dist`` metres get none). Used for user networks whose scenario gives no doors."""
    doors = []
    if sidewalk.is_empty:
        return np.zeros((0, 2))
    for b in buildings:
        if b.distance(sidewalk) <= max_dist:
            p, _ = shapely.ops.nearest_points(b.exterior, sidewalk)
            doors.append((p.x, p.y))
    return np.asarray(doors, dtype=float).reshape(-1, 2)


def project_doors(points: np.ndarray, lines: Sequence[LineString], max_dist: float | None = None) -> np.ndarray:
    """Each door point moved onto the nearest sidewalk centre line (where SUMO persons depart and arrive).

    ``max_dist``: refuse a door farther than this (m) from every sidewalk centre line in the box (a door given at
    the wrong place would otherwise be moved silently onto some sidewalk)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(pts) == 0 or not lines:
        require(
            max_dist is None or len(pts) == 0,
            f"doors.points: {len(pts)} door(s) given but the world box holds no sidewalk centre line to put them on",
        )
        return pts.copy()
    ml = MultiLineString(list(lines))
    out = []
    for x, y in pts:
        q, _ = shapely.ops.nearest_points(ml, Point(x, y))
        if max_dist is not None and not q.distance(Point(x, y)) <= max_dist:
            raise SoabenchError(
                f"door [{x:g}, {y:g}] lies {q.distance(Point(x, y)):.4g} m from the nearest sidewalk in the world "
                f"box; allowed: at most {max_dist:g} m (doors.points are points on buildings facing a sidewalk)"
            )
        out.append((q.x, q.y))
    return np.asarray(out, dtype=float)


def _clip(geom: BaseGeometry, world: Polygon) -> BaseGeometry:
    return geom.intersection(world) if not geom.is_empty else geom


def load_scene(
    net_file: str | os.PathLike,
    poly_files: Sequence[str | os.PathLike] = (),
    world_box: Sequence[float] | None = None,
    doors: np.ndarray | None = None,
    name: str | None = None,
    net=None,
    skip_parked: bool = False,
    door_limit: float | None = None,
) -> SceneMap:
    """Build the :class:`SceneMap` of a network (docs/method.md §2.1(c)).

    Args:
        net_file: SUMO ``.net.xml``.
        poly_files: SUMO polygon files (buildings, parked cars, obstacles).
        world_box: (x_min, y_min, x_max, y_max); default: the network's boundary.
        doors: (D, 2) door points; default: one per building (:func:`default_doors`). Stored projected onto the
            nearest sidewalk centre line.
        name: map name; default: the file stem.
        net: an already read sumolib network (skips re-reading ``net_file``).
        skip_parked: leave out the polygon files' parked cars (see :func:`read_polygons`).
        door_limit: refuse a door farther than this (m) from every sidewalk (:func:`project_doors`).
    """
    net = net if net is not None else read_net(net_file)
    regions = net_regions(net)
    require(
        not regions["sidewalk"].is_empty,
        f"network {str(net_file)!r} has no pedestrian lanes (sidewalks or footways); rebuild it with netconvert "
        "--sidewalks.guess --crossings.guess --walkingareas",
    )
    if world_box is None:
        world_box = tuple(float(v) for v in net.getBoundary())
    x0, y0, x1, y1 = (float(v) for v in world_box)
    require(x1 > x0 and y1 > y0, f"world_box = {list(world_box)!r} must be [x_min, y_min, x_max, y_max] with min < max")
    world = box(x0, y0, x1, y1)
    buildings, occluders = read_polygons(poly_files, skip_parked)
    sidewalk = _clip(regions["sidewalk"], world)
    require(
        not sidewalk.is_empty,
        f"world_box = {[x0, y0, x1, y1]!r} contains no sidewalk of network {str(net_file)!r}; "
        "choose a box over the net",
    )
    lines = [g for ln in regions["lines"] for g in _parts(ln.intersection(world))]
    if doors is None:
        doors = default_doors(buildings, sidewalk)
    doors = project_doors(
        np.asarray(doors, dtype=float).reshape(-1, 2), _sidewalk_only_lines(net, world), max_dist=door_limit
    )
    return SceneMap(
        name=name or Path(net_file).name.removesuffix(".xml").removesuffix(".net"),
        world_box=world,
        sidewalk=sidewalk,
        crossings=_clip(regions["crossings"], world),
        walking_areas=_clip(regions["walking_areas"], world),
        roads=_clip(regions["roads"], world),
        buildings=buildings,
        static_occluders=occluders,
        doors=doors,
        sidewalk_lines=MultiLineString(lines),
        net_file=str(net_file),
        poly_files=[str(p) for p in poly_files],
    )


def _parts(geom: BaseGeometry) -> list[LineString]:
    if geom.is_empty:
        return []
    if isinstance(geom, LineString):
        return [geom]
    return [g for g in getattr(geom, "geoms", []) if isinstance(g, LineString) and g.length > 0]


def _sidewalk_only_lines(net, world: Polygon) -> list[LineString]:
    """Sidewalk centre lines inside the world box (doors must lie on a normal edge, never on a crossing)."""
    out = []
    for lane in sidewalk_lanes(net):
        line = _lane_line(lane)
        if line is not None:
            out += _parts(line.intersection(world))
    return out


def _non_turn_connections(conns: dict, vclass: str) -> bool:
    """True if ``conns`` ({edge: [Connection]}) holds a connection between two ``vclass`` lanes of normal edges that
    is not a turnaround (sumolib's ``Edge.is_fringe`` semantics, restricted to ``vclass``)."""
    from sumolib.net.connection import Connection

    turns = (Connection.LINKDIR_TURN, Connection.LINKDIR_TURN_LEFTHAND)
    for other, cs in conns.items():
        if other.getFunction() != "":
            continue
        for c in cs:
            if c.getDirection() in turns:
                continue
            if c.getFromLane().allows(vclass) and c.getToLane().allows(vclass):
                return True
    return False


def fringe_edges(net, vclass: str = "passenger") -> tuple[list[str], list[str]]:
    """(sources, sinks): normal edges allowing ``vclass`` with no incoming / no outgoing ``vclass`` connection other
    than a turnaround (sumolib's ``Edge.is_fringe``: a dead end with a turnaround is still a fringe), sorted by id.

    A net without any dead end (e.g. a ``netgenerate --grid`` net) has no fringe in this sense; then the edges that
    start / end at a node on the convex hull of the network's nodes are used (the streets at its border)."""
    sources, sinks = [], []
    edges = [e for e in net.getEdges(withInternal=False) if e.getFunction() == "" and e.allows(vclass)]
    for e in edges:
        if not _non_turn_connections(e.getIncoming(), vclass):
            sources.append(e.getID())
        if not _non_turn_connections(e.getOutgoing(), vclass):
            sinks.append(e.getID())
    if not sources or not sinks:
        hull_nodes = _hull_nodes(net)
        if not sources:
            sources = [e.getID() for e in edges if e.getFromNode().getID() in hull_nodes]
        if not sinks:
            sinks = [e.getID() for e in edges if e.getToNode().getID() in hull_nodes]
    return sorted(sources), sorted(sinks)


def _hull_nodes(net, tol: float = 1.0) -> set[str]:
    """Ids of the nodes lying on (within ``tol`` m of) the convex hull of all node positions."""
    nodes = [n for n in net.getNodes() if n.getType() != "internal"]
    if len(nodes) < 3:
        return {n.getID() for n in nodes}
    pts = shapely.points([n.getCoord()[:2] for n in nodes])
    hull = shapely.convex_hull(shapely.multipoints(pts))
    ring = hull.exterior if hull.geom_type == "Polygon" else hull
    d = shapely.distance(ring, pts)
    return {n.getID() for n, di in zip(nodes, d, strict=True) if di <= tol}


def vclass_graph(net, vclass: str = "passenger"):
    """(edge ids, sparse matrix): arc i -> j (weight = length of edge j) for every connection between ``vclass``
    lanes of normal edges i and j, except turnarounds (the ego drives through, it does not U-turn)."""
    from scipy.sparse import csr_matrix
    from sumolib.net.connection import Connection

    turns = (Connection.LINKDIR_TURN, Connection.LINKDIR_TURN_LEFTHAND)

    edges = sorted(
        (e for e in net.getEdges(withInternal=False) if e.getFunction() == "" and e.allows(vclass)),
        key=lambda e: e.getID(),
    )
    index = {e.getID(): i for i, e in enumerate(edges)}
    rows, cols, w = [], [], []
    for e in edges:
        for other, cs in e.getOutgoing().items():
            j = index.get(other.getID())
            ok = any(
                c.getFromLane().allows(vclass) and c.getToLane().allows(vclass) and c.getDirection() not in turns
                for c in cs
            )
            if j is None or not ok:
                continue
            rows.append(index[e.getID()])
            cols.append(j)
            w.append(max(other.getLength(), 1e-3))
    n = len(edges)
    return [e.getID() for e in edges], csr_matrix((w, (rows, cols)), shape=(n, n))


def default_ego_route(net, vclass: str = "passenger") -> list[str]:
    """The longest of the shortest ``vclass`` routes from a source to a sink fringe edge (:func:`fringe_edges`),
    for user networks without a scenario. One Dijkstra per source (scipy), so large OSM nets stay fast."""
    from scipy.sparse.csgraph import dijkstra

    ids, graph = vclass_graph(net, vclass)
    require(
        bool(ids),
        "network has no edge for passenger cars, so the ego has nowhere to drive; give a net with a road "
        "(footways alone are not enough) or an ego route in a scenario file",
    )
    sources, sinks = fringe_edges(net, vclass)
    index = {e: i for i, e in enumerate(ids)}
    src = np.array([index[s] for s in sources], dtype=int)
    dst = np.array([index[t] for t in sinks], dtype=int)
    require(src.size > 0 and dst.size > 0, "network has no fringe edges for passenger cars; give an ego route")
    dist, pred = dijkstra(graph, directed=True, indices=src, return_predecessors=True)
    d = dist[:, dst] + np.array([net.getEdge(s).getLength() for s in sources])[:, None]
    d[~np.isfinite(d)] = -1.0
    d[src[:, None] == dst[None, :]] = -1.0
    i, j = np.unravel_index(int(np.argmax(d)), d.shape)
    require(d[i, j] > 0, "no route for passenger cars connects two fringe edges of the network; give an ego route")
    path = [int(dst[j])]
    while path[-1] != src[i]:
        path.append(int(pred[i, path[-1]]))
    return [ids[k] for k in reversed(path)]
