"""Scenario configuration: what SUMO simulates on a network (docs/method.md §1.1 scene, paper Section IV-A).

A scenario TOML has these sections (every key optional; paths are relative to the TOML file)::

    [files]        net = "intersection.net.xml"; polys = ["buildings.poly.xml", "parked_cars.poly.xml"]
    [simulation]   world_box = [x_min, y_min, x_max, y_max]; step_length = 0.1; duration = 100.0
    [ego]          route = ["W_in", "E_out"]; start_x = -47.0 (or depart_pos); max_speed; length; width
    [vehicles]     count = 3; sources = [...]; sinks = [...]; max_speed
    [pedestrians]  count = 6; model = "jupedsim"; speed = [0.8, 1.0]; p_enter = 0.3; dwell = [5.0, 20.0]
    [doors]        points = [[x, y], ...]

Unknown sections or keys and invalid values raise :class:`SoabenchError` naming the value and what is allowed.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from soabench.errors import SoabenchError, require

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 only
    import tomli as tomllib

PEDESTRIAN_MODELS = ("jupedsim", "striping", "nonInteracting")


@dataclass
class ScenarioConfig:
    """One scenario on one network. Empty route / source / sink / door lists mean "derive from the network"
    (see :func:`soabench.scenario.load`).

    Attributes:
        net_file: SUMO ``.net.xml``.
        poly_files: SUMO polygon files (buildings, parked cars, obstacles).
        world_box: evaluated workspace W as (x_min, y_min, x_max, y_max) in m; None = network boundary.
        step_length: SUMO step (s).
        duration: recorded time (s); the Recording holds round(duration / step_length) samples.
        ego_route: edge ids of the ego's predefined path.
        ego_start_x: x (m) of the ego's geometric centre at t = 0 on the first route edge (None = use depart_pos).
        ego_depart_pos: position (m) of the ego's front bumper along its first edge when ``ego_start_x`` is None.
        ego_max_speed: ego speed limit (m/s); slow enough to stay in W for the whole run.
        ego_length, ego_width: ego footprint (m).
        n_vehicles: number of other moving vehicles (each re-inserted on a new random route when it leaves).
        vehicle_sources, vehicle_sinks: candidate first / last edges of their routes.
        vehicle_max_speed: their speed limit (m/s).
        n_pedestrians: number of pedestrians (stable ids ``ped0`` .. ``ped{P-1}``).
        pedestrian_model: SUMO ``--pedestrian.model``.
        ped_speed: (min, max) of each pedestrian's walking speed, drawn once per trial (m/s).
        p_enter: probability that a pedestrian's next walk ends at a door, entering the building (vanishing).
        dwell: (min, max) time (s) spent inside a building before exiting at a random door.
        doors: door points (x, y) near buildings; moved onto the nearest sidewalk centre line.
        name: network name.
    """

    net_file: str = ""
    poly_files: list[str] = field(default_factory=list)
    world_box: tuple[float, float, float, float] | None = None
    step_length: float = 0.1
    duration: float = 100.0
    ego_route: list[str] = field(default_factory=list)
    ego_start_x: float | None = None
    ego_depart_pos: float = 0.0
    ego_max_speed: float = 2.0
    ego_length: float = 4.5
    ego_width: float = 1.8
    n_vehicles: int = 3
    vehicle_sources: list[str] = field(default_factory=list)
    vehicle_sinks: list[str] = field(default_factory=list)
    vehicle_max_speed: float = 10.0
    n_pedestrians: int = 6
    pedestrian_model: str = "jupedsim"
    ped_speed: tuple[float, float] = (0.8, 1.0)
    p_enter: float = 0.3
    dwell: tuple[float, float] = (5.0, 20.0)
    doors: list[tuple[float, float]] | None = None
    name: str = ""

    @property
    def n_steps(self) -> int:
        """Number of recorded samples T."""
        return int(round(self.duration / self.step_length))

    def validate(self) -> None:
        """Raise :class:`SoabenchError` on the first invalid value."""
        _num("simulation.step_length", self.step_length, lo=0.0, lo_open=True, hi=1.0)
        _num("simulation.duration", self.duration, lo=0.0, lo_open=True)
        require(
            self.n_steps >= 1 and abs(self.n_steps * self.step_length - self.duration) < 1e-6,
            f"simulation.duration = {self.duration!r} must be a positive multiple of "
            f"step_length = {self.step_length!r}",
        )
        if self.world_box is not None:
            wb = self.world_box
            require(
                len(wb) == 4 and all(_is_num(v) for v in wb) and wb[2] > wb[0] and wb[3] > wb[1],
                f"simulation.world_box = {list(wb)!r} must be [x_min, y_min, x_max, y_max] with min < max",
            )
        require(
            isinstance(self.ego_route, list) and all(isinstance(e, str) and e for e in self.ego_route),
            f"ego.route = {self.ego_route!r} must be a list of edge ids",
        )
        if self.ego_start_x is not None:
            _num("ego.start_x", self.ego_start_x)
        _num("ego.depart_pos", self.ego_depart_pos, lo=0.0)
        _num("ego.max_speed", self.ego_max_speed, lo=0.0, lo_open=True, hi=70.0)
        _num("ego.length", self.ego_length, lo=0.0, lo_open=True, hi=30.0)
        _num("ego.width", self.ego_width, lo=0.0, lo_open=True, hi=5.0)
        _int("vehicles.count", self.n_vehicles, lo=0, hi=100)
        for key, lst in (("vehicles.sources", self.vehicle_sources), ("vehicles.sinks", self.vehicle_sinks)):
            require(isinstance(lst, list) and all(isinstance(e, str) for e in lst), f"{key} = {lst!r} must be edge ids")
        _num("vehicles.max_speed", self.vehicle_max_speed, lo=0.0, lo_open=True, hi=70.0)
        _int("pedestrians.count", self.n_pedestrians, lo=1, hi=200)
        require(
            self.pedestrian_model in PEDESTRIAN_MODELS,
            f"pedestrians.model = {self.pedestrian_model!r} is not allowed; choose one of "
            + ", ".join(map(repr, PEDESTRIAN_MODELS)),
        )
        _pair("pedestrians.speed", self.ped_speed, lo=0.0, lo_open=True, hi=3.0)
        _num("pedestrians.p_enter", self.p_enter, lo=0.0, hi=1.0)
        _pair("pedestrians.dwell", self.dwell, lo=1.0, hi=1e6)
        if self.doors is not None:
            require(
                all(len(d) == 2 and _is_num(d[0]) and _is_num(d[1]) for d in self.doors),
                f"doors.points = {self.doors!r} must be a list of [x, y] pairs",
            )


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _num(name: str, v: Any, lo: float = -math.inf, hi: float = math.inf, lo_open: bool = False) -> None:
    ok = _is_num(v) and (v > lo if lo_open else v >= lo) and v <= hi
    lb = "(" if lo_open else "["
    require(ok, f"{name} = {v!r} is out of range; allowed: {lb}{lo}, {hi}]")


def _int(name: str, v: Any, lo: int, hi: int) -> None:
    ok = isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi
    require(ok, f"{name} = {v!r} must be an integer in [{lo}, {hi}]")


def _pair(name: str, v: Any, lo: float, hi: float, lo_open: bool = False) -> None:
    ok = isinstance(v, (list, tuple)) and len(v) == 2 and all(_is_num(x) for x in v) and v[0] <= v[1]
    ok = ok and (v[0] > lo if lo_open else v[0] >= lo) and v[1] <= hi
    require(ok, f"{name} = {v!r} must be [min, max] with {lo} {'<' if lo_open else '<='} min <= max <= {hi}")


#: TOML (section, key) -> ScenarioConfig field.
_KEYS: dict[str, dict[str, str]] = {
    "files": {"net": "net_file", "polys": "poly_files"},
    "simulation": {"world_box": "world_box", "step_length": "step_length", "duration": "duration"},
    "ego": {
        "route": "ego_route",
        "start_x": "ego_start_x",
        "depart_pos": "ego_depart_pos",
        "max_speed": "ego_max_speed",
        "length": "ego_length",
        "width": "ego_width",
    },
    "vehicles": {
        "count": "n_vehicles",
        "sources": "vehicle_sources",
        "sinks": "vehicle_sinks",
        "max_speed": "vehicle_max_speed",
    },
    "pedestrians": {
        "count": "n_pedestrians",
        "model": "pedestrian_model",
        "speed": "ped_speed",
        "p_enter": "p_enter",
        "dwell": "dwell",
    },
    "doors": {"points": "doors"},
    "scenario": {"name": "name"},
}


def load_scenario(path: str | Path) -> ScenarioConfig:
    """Read and validate a scenario TOML (module docstring); relative file paths are resolved against its folder."""
    p = Path(path)
    require(p.is_file(), f"scenario file {str(path)!r} does not exist; give the path of a scenario .toml")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SoabenchError(f"scenario file {str(p)!r} is not valid TOML ({exc})") from None
    return scenario_from_dict(data, base=p.parent, source=str(p))


def scenario_from_dict(data: dict, base: Path | None = None, source: str = "scenario") -> ScenarioConfig:
    """Build a validated :class:`ScenarioConfig` from TOML-shaped ``data`` (sections of :data:`_KEYS`)."""
    cfg = ScenarioConfig()
    names = {f.name for f in fields(cfg)}
    for section, table in data.items():
        require(
            section in _KEYS and isinstance(table, dict),
            f"{source}: unknown section [{section}]; allowed: " + ", ".join(f"[{s}]" for s in _KEYS),
        )
        for key, value in table.items():
            require(
                key in _KEYS[section],
                f"{source}: unknown key {section}.{key}; allowed in [{section}]: {', '.join(_KEYS[section])}",
            )
            attr = _KEYS[section][key]
            assert attr in names
            setattr(cfg, attr, value)
    base = base or Path(".")
    if cfg.net_file:
        require(isinstance(cfg.net_file, str), f"files.net = {cfg.net_file!r} must be a path")
        cfg.net_file = str((base / cfg.net_file).resolve())
    require(
        isinstance(cfg.poly_files, list) and all(isinstance(f, str) for f in cfg.poly_files),
        f"files.polys = {cfg.poly_files!r} must be a list of paths",
    )
    cfg.poly_files = [str((base / f).resolve()) for f in cfg.poly_files]
    if isinstance(cfg.world_box, list):
        cfg.world_box = tuple(cfg.world_box)  # type: ignore[assignment]
    if cfg.doors is not None and isinstance(cfg.doors, list):
        cfg.doors = [tuple(d) if isinstance(d, list) else d for d in cfg.doors]
    for attr in ("ped_speed", "dwell"):
        if isinstance(getattr(cfg, attr), list):
            setattr(cfg, attr, tuple(getattr(cfg, attr)))
    cfg.validate()
    return cfg
