"""Run one scenario with libsumo and record the ground truth (docs/method.md §1.1, §2.1(a)-(b), §2.3 last bullet).

What SUMO simulates (paper Section IV-A):

* the ego drives its predefined route at ``ego_max_speed``, starting at ``ego_start_x``;
* ``n_vehicles`` other vehicles drive random source -> sink routes; a vehicle that leaves is re-inserted at once
  (same id) on a new random route, ~20 m before its first edge enters the world box;
* ``n_pedestrians`` persons walk persistent random walks: whenever a person starts its last walking stage, the
  next one is appended, to a uniform random sidewalk point in the world box, or with probability ``p_enter`` to a
  random door, where SUMO removes the person ("enters the building"); after a dwell time drawn from ``dwell`` the
  same id is re-added at a random door ("exits the building").

Every random choice comes from ``seeds.scenario_rng()`` and SUMO runs with ``--seed seeds.sumo_seed``, so the same
seeds give a bit-identical Recording. libsumo is a process singleton: each simulation runs in a forked child
process that is watched for progress (:mod:`soabench.scenario.watchdog`), so one that stalls inside SUMO stops with
one line instead of hanging.
"""

from __future__ import annotations

import contextlib
import io
import math
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from shapely.geometry import LineString, Point, box

from soabench.errors import SoabenchError, require, require_type
from soabench.geometry import wrap
from soabench.scenario.config import ScenarioConfig
from soabench.scenario.scene import SceneMap
from soabench.scenario.watchdog import INSERTING, STARTING, STEPPING, Progress, run_watched
from soabench.seeding import TrialSeeds
from soabench.types import Recording

#: steps run before the first recorded sample (insertion; the first sample of a new person is dropped anyway).
WARMUP_STEPS = 3
#: minimum distance (m) between the initial pedestrian placements.
MIN_SEPARATION = 2.0
#: re-inserted vehicles start this far (m) before their first edge enters the world box.
VEHICLE_LEAD_IN = 20.0
#: what a stalled jupedsim run is told (docs/user-guide/sumo.md "Stalls").
JUPEDSIM_HINT = (
    'SUMO\'s jupedsim can hang on networks whose sidewalks enclose a block: set [pedestrians] model = "striping" '
    "in the scenario"
)


@dataclass
class _Pedestrian:
    pid: str
    speed: float
    end_edge: str = ""
    end_pos: float = 0.0
    going_in: bool = False  #: the last appended walk ends at a door
    inside: bool = False  #: removed by SUMO at a door, waiting to exit
    exit_time: float = math.inf
    fresh: bool = True  #: inserted and not yet seen moving: samples are dropped (docs/user-guide/sumo.md)
    walks: int = 0
    lost_at: tuple[str, float] | None = None  #: where to re-insert a person SUMO removed away from a door


@dataclass
class _Places:
    """Sidewalk stretches inside the world box, in lane coordinates, for uniform random destinations."""

    edge: list[str]
    lo: np.ndarray
    hi: np.ndarray
    lines: list[LineString]
    lane_len: np.ndarray

    def sample(self, rng: np.random.Generator) -> tuple[str, float]:
        """A uniform random point (by length) of the sidewalk stretches: (edge, lane position)."""
        return self.sample_xy(rng)[:2]

    def sample_xy(self, rng: np.random.Generator) -> tuple[str, float, np.ndarray]:
        """Like :meth:`sample`, also returning the point's world (x, y)."""
        w = self.hi - self.lo
        i = int(rng.choice(len(w), p=w / w.sum()))
        pos = float(self.lo[i] + rng.random() * w[i])
        pt = self.lines[i].interpolate(pos * self.lines[i].length / self.lane_len[i])
        return self.edge[i], pos, np.array([pt.x, pt.y])

    def nearest(self, x: float, y: float) -> tuple[str, float]:
        """(edge, lane position) of the sidewalk point nearest (x, y) inside the box."""
        pt = Point(x, y)
        i = int(np.argmin([ln.distance(pt) for ln in self.lines]))
        s = self.lines[i].project(pt) * self.lane_len[i] / self.lines[i].length
        return self.edge[i], float(np.clip(s, self.lo[i], self.hi[i]))


def _sidewalk_places(libsumo, world: tuple[float, float, float, float], inset: float = 1.0) -> _Places:
    x0, y0, x1, y1 = world
    region = box(x0 + inset, y0 + inset, x1 - inset, y1 - inset)
    edges, lo, hi, lines, lens = [], [], [], [], []
    for lane in sorted(libsumo.lane.getIDList()):
        if lane.startswith(":"):
            continue
        allowed = set(libsumo.lane.getAllowed(lane))
        if "pedestrian" not in allowed or "passenger" in allowed:
            continue
        line = LineString(libsumo.lane.getShape(lane))
        length = libsumo.lane.getLength(lane)
        if line.length <= 0:
            continue
        clipped = line.intersection(region)
        parts = [clipped] if clipped.geom_type == "LineString" else list(getattr(clipped, "geoms", []))
        for part in parts:
            if part.geom_type != "LineString" or part.length < 2.0:
                continue
            a, b = sorted(line.project(Point(c)) for c in (part.coords[0], part.coords[-1]))
            f = length / line.length
            edges.append(libsumo.lane.getEdgeID(lane))
            lo.append(a * f)
            hi.append(b * f)
            lines.append(line)
            lens.append(length)
    require(bool(edges), f"world_box = {list(world)!r} contains no sidewalk lane for pedestrians")
    return _Places(edges, np.asarray(lo), np.asarray(hi), lines, np.asarray(lens))


def _walk(libsumo, from_edge: str, from_pos: float, to_edge: str, to_pos: float) -> list[str]:
    stages = libsumo.simulation.findIntermodalRoute(from_edge, to_edge, "", -1.0, 0, -1.0, -1.0, from_pos, to_pos)
    edges: list[str] = []
    for st in stages:
        edges += [e for e in st.edges if not (edges and edges[-1] == e)]
    return edges


def _routes_xml(sc: ScenarioConfig) -> str:
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n<routes>\n'
        f'    <vType id="ego" vClass="passenger" length="{sc.ego_length}" width="{sc.ego_width}" '
        f'maxSpeed="{sc.ego_max_speed}" speedDev="0" color="255,0,0"/>\n'
        f'    <vType id="car" vClass="passenger" maxSpeed="{sc.vehicle_max_speed}" speedDev="0.1"/>\n'
        '    <vType id="ped" vClass="pedestrian" speedDev="0"/>\n'
        "</routes>\n"
    )


def _footprint(front: np.ndarray, theta: np.ndarray, length, width) -> np.ndarray:
    """Rectangle corners (..., 4, 2) from the front-bumper centre (..., 2), math heading (...) and length, width
    (scalars or (...)) (§2.1(b)): rear-right, front-right, front-left, rear-left (counter-clockwise)."""
    u = np.stack([np.cos(theta), np.sin(theta)], -1)
    n = np.stack([-u[..., 1], u[..., 0]], -1)
    a = 0.5 * np.asarray(length, dtype=float)[..., None] * u
    b = 0.5 * np.asarray(width, dtype=float)[..., None] * n
    c = front - a
    return np.stack([c - a - b, c + a - b, c + a + b, c - a + b], -2)


def _heading(angle_deg: np.ndarray | float) -> np.ndarray:
    """Navigational SUMO angle (deg, 0 = north, clockwise) -> math heading in (-pi, pi] (§2.1(a)); NaN stays NaN."""
    return wrap(np.radians(90.0 - np.asarray(angle_deg, dtype=float)))


#: the two lines libsumo prints on import when the installed pyarrow's version differs from the libarrow SUMO was
#: built against
_ARROW_NOTICE = ("Warning! pyarrow is installed with version", " Try to uninstall pyarrow or install a matching")


def import_libsumo():
    """libsumo, imported once per process. Its import-time notice about a pyarrow version other than the libarrow
    SUMO was built against is dropped: soabench hands SUMO no Arrow data (pyarrow only writes an atlas's Parquet
    files, docs/user-guide/atlas.md), so on every worker the notice would alarm without cause. Every other line
    libsumo prints passes through."""
    if "libsumo" in sys.modules:
        return sys.modules["libsumo"]
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        import libsumo
    for line in printed.getvalue().splitlines():
        if not line.startswith(_ARROW_NOTICE):
            print(line)
    return libsumo


def simulate(scene: SceneMap, scenario: ScenarioConfig, seeds: TrialSeeds, duration: float | None = None) -> Recording:
    """Run ``scenario`` on ``scene`` with libsumo and return the ground truth (module docstring).

    Args:
        scene: the map (world box, doors, static occluders) from :func:`soabench.scenario.load`.
        scenario: the scenario; its routes, sources and sinks must already be resolved (``load`` does this).
        seeds: trial seeds; SUMO gets ``seeds.sumo_seed``, every scenario choice uses ``seeds.scenario_rng()``.
        duration: recorded time (s), overriding ``scenario.duration``.
    """
    import_libsumo()  # imported once here: every forked SUMO run inherits it

    hint = "load both with soabench.scenario.load(net), or call soabench.api.simulate_trial(net, seed, trial)"
    require_type(scene, SceneMap, "simulate's scene", hint)
    require_type(scenario, ScenarioConfig, "simulate's scenario", hint)
    require_type(seeds, TrialSeeds, "simulate's seeds", "make them with soabench.seeding.trial_seeds(seed, trial)")
    dur = scenario.duration if duration is None else duration
    require(
        isinstance(dur, (int, float)) and math.isfinite(dur) and dur >= scenario.step_length,
        f"duration = {dur!r} must be at least one SUMO step ({scenario.step_length} s)",
    )
    require(bool(scenario.ego_route), "ego.route is empty; give the ego's edge ids (or load the scenario with load())")
    n_steps = int(round(dur / scenario.step_length))
    name = Path(scenario.net_file).name
    describe = f"SUMO on {name!r} (pedestrian model {scenario.pedestrian_model!r})"
    hint = JUPEDSIM_HINT if scenario.pedestrian_model == "jupedsim" else ""
    with tempfile.TemporaryDirectory(prefix="soabench_sumo_") as tmp:
        return run_watched(_simulate_here, (scene, scenario, seeds, n_steps, Path(tmp)), describe, hint)


def _simulate_here(
    scene: SceneMap, scenario: ScenarioConfig, seeds: TrialSeeds, n_steps: int, tmp: Path, progress: Progress
) -> Recording:
    """:func:`simulate` in this process (libsumo started and always closed); ``tmp`` holds SUMO's files."""
    libsumo = import_libsumo()

    rng = seeds.scenario_rng()
    routes = tmp / "types.rou.xml"
    routes.write_text(_routes_xml(scenario), encoding="utf-8")
    cmd = [
        "sumo", "-n", scenario.net_file, "-r", str(routes),
        "--step-length", repr(float(scenario.step_length)), "--begin", "0",
        "--seed", str(int(seeds.sumo_seed)), "--pedestrian.model", scenario.pedestrian_model,
        "--no-step-log", "true", "--no-warnings", "true", "--duration-log.disable", "true",
        "--time-to-teleport", "-1", "--collision.action", "none",
        "--output-prefix", str(tmp / "out_"),
    ]  # fmt: skip
    progress.beat(STARTING)
    try:
        libsumo.start(cmd)
    except libsumo.TraCIException as exc:
        raise SoabenchError(f"SUMO could not start on {scenario.net_file!r}: {exc}") from None
    try:
        return _run(libsumo, scene, scenario, seeds, rng, n_steps, progress)
    except (libsumo.TraCIException, libsumo.FatalTraCIError) as exc:
        raise SoabenchError(f"SUMO failed while simulating {scenario.net_file!r}: {exc}") from None
    finally:
        libsumo.close()


def _run(
    libsumo, scene: SceneMap, sc: ScenarioConfig, seeds: TrialSeeds, rng, n_steps: int, progress: Progress
) -> Recording:
    dt = float(sc.step_length)
    world = scene.bounds
    all_edges = set(libsumo.edge.getIDList())
    for e in sc.ego_route + sc.vehicle_sources + sc.vehicle_sinks:
        require(e in all_edges, f"edge {e!r} (ego route / vehicle sources / sinks) is not in {sc.net_file!r}")
    progress.beat(INSERTING)
    places = _sidewalk_places(libsumo, world)
    doors = [places.nearest(x, y) for x, y in np.asarray(scene.doors).reshape(-1, 2)]

    # --- ego -------------------------------------------------------------------------------------------------
    libsumo.route.add("ego_route", sc.ego_route)
    depart_pos = _ego_depart_pos(libsumo, sc)
    libsumo.vehicle.add("ego", "ego_route", "ego", "now", "best", f"{depart_pos:.3f}", "max")

    # --- other vehicles --------------------------------------------------------------------------------------
    veh_ids = [f"veh{i}" for i in range(sc.n_vehicles)]
    n_routes = [0]

    def add_vehicle(vid: str, initial: bool) -> None:
        for _ in range(50):
            s = sc.vehicle_sources[int(rng.integers(len(sc.vehicle_sources)))]
            t = sc.vehicle_sinks[int(rng.integers(len(sc.vehicle_sinks)))]
            if s == t:
                continue
            edges = list(libsumo.simulation.findRoute(s, t, "car").edges)
            if edges:
                break
        else:
            raise SoabenchError(
                f"no route for vehicles between sources {sc.vehicle_sources} and sinks {sc.vehicle_sinks}"
            )
        progress.beat(INSERTING)
        rid = f"r{n_routes[0]}"
        n_routes[0] += 1
        libsumo.route.add(rid, edges)
        lane = f"{edges[0]}_{_drive_lane(libsumo, edges[0])}"
        enter = _box_entry(libsumo, lane, world)
        if initial:  # spread the first vehicles along their first edge, up to the box entry
            pos = float(rng.random()) * max(enter, 1.0)
        else:
            pos = max(0.0, enter - VEHICLE_LEAD_IN)
        exit_lane = f"{edges[-1]}_{_drive_lane(libsumo, edges[-1])}"
        arrival = min(libsumo.lane.getLength(exit_lane), _box_exit(libsumo, exit_lane, world) + VEHICLE_LEAD_IN)
        libsumo.vehicle.add(vid, rid, "car", "now", "best", f"{pos:.3f}", "max", "current", f"{arrival:.3f}")

    if sc.n_vehicles:
        require(
            bool(sc.vehicle_sources) and bool(sc.vehicle_sinks),
            "vehicles.sources and vehicles.sinks are empty; give edge ids (or load the scenario with load())",
        )
    for vid in veh_ids:
        add_vehicle(vid, True)

    # --- pedestrians -----------------------------------------------------------------------------------------
    lo, hi = sc.ped_speed
    peds = [_Pedestrian(f"ped{i}", float(lo + (hi - lo) * rng.random())) for i in range(sc.n_pedestrians)]

    def insert(p: _Pedestrian, edge: str, pos: float) -> None:
        progress.beat(INSERTING)
        libsumo.person.add(p.pid, edge, pos, -3, "ped")
        libsumo.person.setSpeed(p.pid, p.speed)
        p.end_edge, p.end_pos, p.inside, p.going_in, p.fresh = edge, pos, False, False, True
        append_walk(p)

    def append_walk(p: _Pedestrian) -> None:
        go_in = bool(doors) and rng.random() < sc.p_enter
        for _ in range(20):
            edge, pos = doors[int(rng.integers(len(doors)))] if go_in else places.sample(rng)
            edges = _walk(libsumo, p.end_edge, p.end_pos, edge, pos)
            if edges:
                break
        else:
            raise SoabenchError(f"pedestrian {p.pid} found no walking route from edge {p.end_edge!r}")
        libsumo.person.appendWalkingStage(p.pid, edges, pos)
        p.end_edge, p.end_pos, p.going_in = edges[-1], pos, go_in
        p.walks += 1

    starts: list[np.ndarray] = []
    for p in peds:  # initial placements at least MIN_SEPARATION apart (jupedsim delays crowded insertions)
        for _ in range(50):
            edge, pos, xy = places.sample_xy(rng)
            if all(np.hypot(*(xy - q)) >= MIN_SEPARATION for q in starts):
                break
        starts.append(xy)
        insert(p, edge, pos)

    # --- step and record ------------------------------------------------------------------------------------
    T, P, V = n_steps, len(peds), len(veh_ids)
    t = np.arange(T, dtype=float) * dt
    ego_front = np.full((T, 2), np.nan)  # raw SUMO values: front bumper and navigational angle (deg)
    ego_angle = np.full(T, np.nan)
    ped_present = np.zeros((T, P), dtype=bool)
    ped_xy = np.full((T, P, 2), np.nan)
    ped_speed = np.full((T, P), np.nan)
    ped_angle = np.full((T, P), np.nan)
    veh_present = np.zeros((T, V), dtype=bool)
    veh_front = np.full((T, V, 2), np.nan)
    veh_angle = np.full((T, V), np.nan)
    veh_dims = np.full((T, V, 2), np.nan)  # length, width
    dims: dict[str, tuple[float, float]] = {}
    n_enter = n_exit = n_lost = 0
    ego_arrived = None
    t0 = 0.0
    for k in range(-WARMUP_STEPS, T):
        libsumo.simulationStep()
        now = libsumo.simulation.getTime()
        progress.beat(STEPPING, now)
        if k == 0:
            t0 = now
        arrived_p = set(libsumo.simulation.getArrivedPersonIDList())
        arrived_v = set(libsumo.simulation.getArrivedIDList())
        present_p = set(libsumo.person.getIDList())
        for p in peds:
            if p.pid in arrived_p and not p.inside:
                p.inside = True
                if p.going_in:
                    p.exit_time = now + sc.dwell[0] + (sc.dwell[1] - sc.dwell[0]) * rng.random()
                    n_enter += k >= 0
                else:  # removed by SUMO away from a door (should not happen): put it back where its walk ended
                    p.exit_time = now
                    n_lost += 1
                    p.lost_at = places.nearest(*libsumo.simulation.convert2D(p.end_edge, p.end_pos))
        # record the state after this step
        if k >= 0:
            live_v = set(libsumo.vehicle.getIDList())
            if "ego" in live_v:
                ego_front[k] = libsumo.vehicle.getPosition("ego")
                ego_angle[k] = libsumo.vehicle.getAngle("ego")
            elif ego_arrived is None:
                ego_arrived = float(t[k])
            for j, p in enumerate(peds):
                if p.pid in present_p and not p.fresh:
                    ped_present[k, j] = True
                    ped_xy[k, j] = libsumo.person.getPosition(p.pid)
                    ped_speed[k, j] = libsumo.person.getSpeed(p.pid)
                    ped_angle[k, j] = libsumo.person.getAngle(p.pid)
            for j, vid in enumerate(veh_ids):
                if vid in live_v:
                    if vid not in dims:
                        dims[vid] = (libsumo.vehicle.getLength(vid), libsumo.vehicle.getWidth(vid))
                    veh_present[k, j] = True
                    veh_front[k, j] = libsumo.vehicle.getPosition(vid)
                    veh_angle[k, j] = libsumo.vehicle.getAngle(vid)
                    veh_dims[k, j] = dims[vid]
        for p in peds:
            if p.pid in present_p:
                if p.fresh:  # drop samples up to the first moving one (jupedsim may delay an insertion)
                    p.fresh = libsumo.person.getSpeed(p.pid) <= 0.0
                elif not p.going_in and libsumo.person.getRemainingStages(p.pid) <= 1:
                    append_walk(p)
            elif p.inside and now >= p.exit_time:
                if p.lost_at is not None:
                    insert(p, *p.lost_at)
                    p.lost_at = None
                else:
                    edge, pos = doors[int(rng.integers(len(doors)))]
                    insert(p, edge, pos)
                    n_exit += k >= 0
        for vid in veh_ids:
            if vid in arrived_v:
                dims.pop(vid, None)
                add_vehicle(vid, False)
    require(not np.isnan(ego_front[0]).any(), f"the ego could not be inserted on route {sc.ego_route!r}")
    # after an arrival (short user routes) the ego keeps its last pose
    last = np.maximum.accumulate(np.where(np.isnan(ego_angle), 0, np.arange(T)))
    ego_front, ego_angle = ego_front[last], ego_angle[last]
    ego_theta = _heading(ego_angle)
    ego_fp = _footprint(ego_front, ego_theta, sc.ego_length, sc.ego_width)
    ego_centre = ego_front - 0.5 * sc.ego_length * np.stack([np.cos(ego_theta), np.sin(ego_theta)], -1)
    ego_pose = np.column_stack([ego_centre, ego_theta])
    veh_fp = _footprint(veh_front, _heading(veh_angle), veh_dims[..., 0], veh_dims[..., 1])
    ped_heading = _heading(ped_angle)
    return Recording(
        t=t,
        step_length=dt,
        ego_pose=ego_pose,
        ego_footprint=ego_fp,
        ped_ids=np.array([p.pid for p in peds]),
        ped_present=ped_present,
        ped_xy=ped_xy,
        ped_speed=ped_speed,
        ped_heading=ped_heading,
        veh_ids=np.array(veh_ids, dtype=str),
        veh_present=veh_present,
        veh_footprint=veh_fp,
        static_occluders=[np.asarray(o.exterior.coords, dtype=float)[:-1] for o in scene.static_occluders],
        seed=int(seeds.sumo_seed),
        net=scene.name,
        meta={
            "sumo_version": str(libsumo.getVersion()[1]),
            "pedestrian_model": sc.pedestrian_model,
            "base_seed": int(seeds.base_seed),
            "trial": int(seeds.trial),
            "sumo_t0": float(t0),
            "n_enter": int(n_enter),
            "n_exit": int(n_exit),
            "n_lost": int(n_lost),
            "ego_arrived_t": ego_arrived,
        },
    )


def _drive_lane(libsumo, edge: str) -> int:
    """Index of the first lane of ``edge`` that passenger cars may use."""
    for i in range(libsumo.edge.getLaneNumber(edge)):
        allowed = libsumo.lane.getAllowed(f"{edge}_{i}")
        if not allowed or "passenger" in allowed:
            return i
    raise SoabenchError(f"edge {edge!r} has no lane for passenger cars; vehicle routes need drivable edges")


def _box_entry(libsumo, lane: str, world) -> float:
    """Lane position where ``lane`` first enters the world box (0 if it starts inside; its length if never)."""
    line = LineString(libsumo.lane.getShape(lane))
    inside = line.intersection(box(*world))
    f = libsumo.lane.getLength(lane) / max(line.length, 1e-9)
    if inside.is_empty:
        return libsumo.lane.getLength(lane)
    return min(line.project(Point(c)) for g in getattr(inside, "geoms", [inside]) for c in g.coords) * f


def _box_exit(libsumo, lane: str, world) -> float:
    """Lane position where ``lane`` last leaves the world box (0 if it never enters)."""
    line = LineString(libsumo.lane.getShape(lane))
    inside = line.intersection(box(*world))
    f = libsumo.lane.getLength(lane) / max(line.length, 1e-9)
    if inside.is_empty:
        return 0.0
    return max(line.project(Point(c)) for g in getattr(inside, "geoms", [inside]) for c in g.coords) * f


def _ego_depart_pos(libsumo, sc: ScenarioConfig) -> float:
    """Front-bumper lane position on the first route edge that puts the ego's centre at ``ego_start_x``."""
    lane = f"{sc.ego_route[0]}_{_drive_lane(libsumo, sc.ego_route[0])}"
    return ego_depart_pos(libsumo.lane.getShape(lane), libsumo.lane.getLength(lane), sc)


def ego_depart_pos(shape, length: float, sc: ScenarioConfig) -> float:
    """Front-bumper position (m) along the ego's drive lane on its first route edge (``shape``: the lane's points,
    ``length``: its length): ``ego.depart_pos``, or the position that puts the ego's centre at ``ego.start_x``;
    :class:`SoabenchError` if that is off the edge. Checked at load (:mod:`soabench.scenario.derive`) and used by
    the simulation."""
    edge = sc.ego_route[0]
    if sc.ego_start_x is None:
        pos = sc.ego_depart_pos
    else:
        line = LineString(shape)
        xs = np.linspace(0.0, line.length, 2001)
        px = np.array([line.interpolate(s).x for s in xs])
        s = float(xs[np.argmin(np.abs(px - sc.ego_start_x))]) * length / max(line.length, 1e-9)
        pos = s + 0.5 * sc.ego_length
    require(
        0.0 <= pos <= length,
        f"ego start (lane position {pos:.1f} m) is off the first route edge {edge!r} (length {length:.1f} m); give "
        "ego.start_x or ego.depart_pos on that edge",
    )
    return float(pos)
