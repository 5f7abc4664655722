"""Defaults derived from a network for whatever a scenario leaves open (docs/user-guide/scenes.md).

* ego route: the longest of the shortest passenger-car routes between two fringe edges
  (:func:`~soabench.scenario.network.default_ego_route`; dead ends with turnarounds count as fringe);
* world box: the stretch the ego covers in the run (``max_speed * duration`` from its start) plus
  :data:`BOX_MARGIN` on every side, cut to the network boundary;
* vehicle sources / sinks: the fringe edges not on the ego route;
* doors: for each building overlapping the world box and within 30 m of a sidewalk, its outline point nearest the
  sidewalk, moved onto the nearest pedestrian lane; no buildings -> no doors (nobody enters or exits);
* parked cars: ``[parking] density`` (optional) on the parking lanes (:mod:`soabench.scenario.parking`).

:func:`derive_defaults` says in one info line (logger ``soabench``) what it derived.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator

import numpy as np
from shapely.geometry import LineString, box

from soabench.errors import SoabenchError, require
from soabench.scenario.config import ScenarioConfig
from soabench.scenario.network import (
    MAX_DOOR_DISTANCE,
    default_doors,
    default_ego_route,
    fringe_edges,
    load_scene,
    net_regions,
    read_polygons,
)
from soabench.scenario.parking import kerbside_parking
from soabench.scenario.scene import SceneMap
from soabench.scenario.simulation import ego_depart_pos

#: metres added around the ego's stretch for the derived world box (the default sensor range is 50 m).
BOX_MARGIN = 40.0
#: the network boundary (node positions) grown by this much (m) before it cuts the world box.
NET_PAD = 10.0
#: the message a network without a single pedestrian lane gets.
NO_SIDEWALK_HINT = (
    "rebuild it with netconvert --sidewalks.guess --crossings.guess --walkingareas "
    "(or import OpenStreetMap with `soabench import osm`)"
)

log = logging.getLogger("soabench")
_said: set[str] = set()
_silenced = [False]


def info_once(line: str) -> None:
    """Log ``line`` at INFO once per process, and not at all inside :func:`said_by_the_driver`."""
    if line not in _said and not _silenced[0]:
        _said.add(line)
        log.info(line)


@contextlib.contextmanager
def said_by_the_driver() -> Iterator[None]:
    """Silence :func:`info_once` within: a run's worker loads the scene its driver loaded and described already,
    so the user reads what was derived once per scene, not once per process."""
    before, _silenced[0] = _silenced[0], True
    try:
        yield
    finally:
        _silenced[0] = before


def _has_pedestrian_lane(net) -> bool:
    return any(
        ln.allows("pedestrian") and not ln.allows("passenger")
        for e in net.getEdges(withInternal=False)
        if e.getFunction() == ""
        for ln in e.getLanes()
    )


def _drive_line(net, edge_id: str) -> LineString:
    edge = net.getEdge(edge_id)
    lanes = [ln for ln in edge.getLanes() if ln.allows("passenger")] or edge.getLanes()
    return LineString(lanes[0].getShape())


def ego_stretch(net, route: list[str], start: float, reach: float) -> LineString:
    """The ego's path from ``start`` m along its route, ``reach`` m long (shorter if the route ends first)."""
    pts: list[tuple[float, float]] = []
    for e in route:
        coords = list(_drive_line(net, e).coords)
        pts += coords if not pts else coords[1:] if coords[0] == pts[-1] else coords
    line = LineString(pts)
    a = min(max(start, 0.0), line.length)
    b = min(a + reach, line.length)
    return LineString([line.interpolate(s) for s in np.linspace(a, b, 64)])


def derived_world_box(net, cfg: ScenarioConfig) -> tuple[float, float, float, float]:
    """World box = the ego's stretch during the run plus :data:`BOX_MARGIN`, cut to the network boundary."""
    start = cfg.ego_depart_pos if cfg.ego_start_x is None else 0.0  # start_x given: from the route start
    stretch = ego_stretch(net, cfg.ego_route, start, cfg.ego_max_speed * cfg.duration + cfg.ego_length)
    x0, y0, x1, y1 = stretch.bounds
    nx0, ny0, nx1, ny1 = (float(v) for v in net.getBoundary())
    nx0, ny0, nx1, ny1 = nx0 - NET_PAD, ny0 - NET_PAD, nx1 + NET_PAD, ny1 + NET_PAD  # lanes lie beside the nodes
    bx = (max(x0 - BOX_MARGIN, nx0), max(y0 - BOX_MARGIN, ny0), min(x1 + BOX_MARGIN, nx1), min(y1 + BOX_MARGIN, ny1))
    return tuple(round(v, 2) for v in bx)  # type: ignore[return-value]


def _check_route(net, cfg: ScenarioConfig) -> None:
    edges = {e.getID() for e in net.getEdges(withInternal=False)}
    for e in cfg.ego_route:
        require(e in edges, f"ego.route edge {e!r} is not in network {cfg.net_file!r}")
    for a, b in zip(cfg.ego_route[:-1], cfg.ego_route[1:], strict=True):
        nxt = {o.getID() for o in net.getEdge(a).getOutgoing()}
        require(b in nxt, f"ego.route = {cfg.ego_route!r}: edge {b!r} does not follow {a!r}; give connected edges")


def _drive_lane(net, edge_id: str):
    """The first lane of ``edge_id`` passenger cars may use (as the simulation picks it); SoabenchError if none."""
    for lane in net.getEdge(edge_id).getLanes():
        if lane.allows("passenger"):
            return lane
    raise SoabenchError(f"edge {edge_id!r} has no lane for passenger cars; vehicle routes need drivable edges")


def check_vehicles_and_ego(net, cfg: ScenarioConfig) -> None:
    """What the simulation would find only inside a trial, found at load: every vehicle source and sink is a
    drivable edge of the network, and the ego's start (``ego.start_x`` or ``ego.depart_pos``) lies on its first
    route edge (the same position :mod:`soabench.scenario.simulation` computes)."""
    edges = {e.getID() for e in net.getEdges(withInternal=False)}
    for key, ids in (("vehicles.sources", cfg.vehicle_sources), ("vehicles.sinks", cfg.vehicle_sinks)):
        for e in ids:
            require(e in edges, f"{key} edge {e!r} is not in network {cfg.net_file!r}")
            if cfg.n_vehicles:
                _drive_lane(net, e)

    lane = _drive_lane(net, cfg.ego_route[0])
    ego_depart_pos(lane.getShape(), lane.getLength(), cfg)


def derive_defaults(cfg: ScenarioConfig, net, quiet: bool = False) -> SceneMap:
    """Fill ``cfg``'s open fields from ``net`` (module docstring) and return the scene map; log what was derived."""

    require(
        _has_pedestrian_lane(net),
        f"network {cfg.net_file!r} has no pedestrian lanes (sidewalks or footways); {NO_SIDEWALK_HINT}",
    )
    said: list[str] = []
    if not cfg.ego_route:
        cfg.ego_route = default_ego_route(net)
        length = sum(net.getEdge(e).getLength() for e in cfg.ego_route)
        said.append(f"ego route {cfg.ego_route[0]} -> {cfg.ego_route[-1]} ({len(cfg.ego_route)} edges, {length:.0f} m)")
    _check_route(net, cfg)
    if cfg.world_box is None:
        cfg.world_box = derived_world_box(net, cfg)
        x0, y0, x1, y1 = cfg.world_box
        said.append(f"world box [{x0:g}, {y0:g}, {x1:g}, {y1:g}] ({x1 - x0:.0f} x {y1 - y0:.0f} m)")
    doors = None if cfg.doors is None else np.asarray(cfg.doors, dtype=float).reshape(-1, 2)
    world = box(*cfg.world_box)
    if doors is None:
        buildings, _ = read_polygons(cfg.poly_files)
        near = [b for b in buildings if b.intersects(world)]

        doors = default_doors(near, net_regions(net)["sidewalk"].intersection(world)) if near else np.zeros((0, 2))
        if not cfg.poly_files:
            said.append("no polygon files: no buildings, no doors (nobody enters or exits)")
        elif not buildings:
            said.append("no buildings in the polygon files: no doors (nobody enters or exits)")
        else:
            said.append(f"{len(doors)} door(s) from {len(near)} building(s) in the box")
    scene = load_scene(
        cfg.net_file,
        cfg.poly_files,
        cfg.world_box,
        doors,
        cfg.name,
        net=net,
        skip_parked=cfg.parking_density is not None,
        door_limit=MAX_DOOR_DISTANCE if cfg.doors is not None else None,
    )
    if cfg.parking_density is not None:
        cars, kerb = kerbside_parking(net, scene.world_box, float(cfg.parking_density))
        scene.static_occluders = scene.static_occluders + cars
        said.append(f"{len(cars)} parked cars ({cfg.parking_density:g} per 100 m of {kerb:.0f} m parking lane)")
    if not cfg.vehicle_sources or not cfg.vehicle_sinks:
        sources, sinks = fringe_edges(net)
        ego = set(cfg.ego_route)
        cfg.vehicle_sources = cfg.vehicle_sources or [e for e in sources if e not in ego] or sources
        cfg.vehicle_sinks = cfg.vehicle_sinks or [e for e in sinks if e not in ego] or sinks
        said.append(f"{len(cfg.vehicle_sources)} vehicle source(s), {len(cfg.vehicle_sinks)} sink(s)")
    check_vehicles_and_ego(net, cfg)
    if said and not quiet:
        info_once(f"{cfg.name}: derived " + "; ".join(said))
    return scene
