"""SUMO scenarios: networks -> :class:`SceneMap`, libsumo runs -> :class:`Recording` (docs/development.md pipeline,
stage 1).

Public API: :func:`load` (network + polygons + scenario TOML) and :func:`simulate` (one run with libsumo).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from importlib.resources import files
from pathlib import Path

from soabench.errors import require
from soabench.scenario.config import ScenarioConfig, load_scenario
from soabench.scenario.recording import Recording
from soabench.scenario.scene import SceneMap
from soabench.scenario.simulation import simulate

__all__ = ["Recording", "ScenarioConfig", "SceneMap", "load", "load_scenario", "shipped_nets", "simulate"]


def shipped_nets() -> list[str]:
    """Names of the networks shipped in :mod:`soabench.nets` (repository folder ``sumo_nets/``): its folders holding
    a ``scenario.toml``."""
    root = Path(str(files("soabench.nets")))
    return sorted(p.name for p in root.iterdir() if p.is_dir() and (p / "scenario.toml").is_file())


def _stem(net_file: str) -> str:
    """``foo`` for ``path/foo.net.xml``."""
    return Path(net_file).name.removesuffix(".gz").removesuffix(".xml").removesuffix(".net")


def _scenario_file_name(path: str | Path) -> str:
    """``busy`` for ``busy.toml``; the folder's name for a file called ``scenario.toml``."""
    p = Path(path)
    return p.resolve().parent.name if p.stem == "scenario" else p.stem


def load(net: str, polys: Sequence[str] = (), scenario: str | None = None) -> tuple[SceneMap, ScenarioConfig]:
    """The scene map and the resolved scenario of a network.

    Args:
        net: a shipped name (folder under :mod:`soabench.nets`, which brings its own polygon files and scenario.toml)
            or the path of a user ``.net.xml``.
        polys: extra SUMO polygon files (buildings / obstacles), added to the scenario's own.
        scenario: a scenario TOML; default: the shipped net's own, or defaults for a user network.

    The scenario's name (``ScenarioConfig.name``: labels, summaries, the default output folder) is the scenario
    file's ``[scenario] name``; without one, the file stem of the network the scenario names (``files.net``), else
    of the scenario file (its folder's name for a ``scenario.toml``); without a scenario file, the shipped name or
    the ``.net.xml`` file stem.

    Defaults for a user network without a scenario (README, "User networks"): world box = the
    network boundary; ego route = the longest shortest route between two fringe edges; vehicle sources / sinks =
    the fringe edges not on the ego route; doors = for each building, its outline point nearest the sidewalk.
    """
    from soabench.scenario.network import default_ego_route, fringe_edges, load_scene, read_net

    shipped = shipped_nets()
    if net in shipped:
        folder = Path(str(files("soabench.nets"))) / net
        cfg = load_scenario(scenario if scenario is not None else folder / "scenario.toml")
        user_net = scenario is not None and bool(cfg.net_file)  # the user's scenario names its own network
        if scenario is None or not cfg.net_file:
            nets = sorted(folder.glob("*.net.xml"))
            require(len(nets) == 1, f"shipped net {net!r} must hold exactly one .net.xml, found {len(nets)}")
            if not cfg.net_file:
                cfg.net_file = str(nets[0])
            if scenario is not None:  # a user scenario on a shipped net keeps the net's own polygons
                own = load_scenario(folder / "scenario.toml")
                cfg.poly_files = own.poly_files + cfg.poly_files
        if scenario is None:
            name = net
        elif user_net:
            name = _stem(cfg.net_file)
        else:  # the shipped network under a user scenario is no longer the shipped scenario: name it after the file
            name = _scenario_file_name(scenario)
    else:
        looks_like_path = os.sep in net or net.endswith(".xml") or Path(net).exists()
        require(
            looks_like_path,
            f"--net {net!r} is neither a shipped network ({', '.join(shipped)}) nor a path to a .net.xml",
        )
        cfg = load_scenario(scenario) if scenario is not None else ScenarioConfig()
        cfg.net_file = str(Path(net).resolve()) if Path(net).exists() else net
        name = _stem(net)
    cfg.poly_files = list(cfg.poly_files) + [str(p) for p in polys]
    cfg.name = cfg.name or name
    sumo_net = read_net(cfg.net_file)
    scene = load_scene(cfg.net_file, cfg.poly_files, cfg.world_box, cfg.doors, cfg.name, net=sumo_net)
    if cfg.world_box is None:
        cfg.world_box = scene.bounds
    if not cfg.ego_route:
        cfg.ego_route = default_ego_route(sumo_net)
    edges = {e.getID() for e in sumo_net.getEdges(withInternal=False)}
    for e in cfg.ego_route:
        require(e in edges, f"ego.route edge {e!r} is not in network {cfg.net_file!r}")
    for a, b in zip(cfg.ego_route[:-1], cfg.ego_route[1:], strict=True):
        nxt = {o.getID() for o in sumo_net.getEdge(a).getOutgoing()}
        require(b in nxt, f"ego.route = {cfg.ego_route!r}: edge {b!r} does not follow {a!r}; give connected edges")
    if not cfg.vehicle_sources or not cfg.vehicle_sinks:
        sources, sinks = fringe_edges(sumo_net)
        ego = set(cfg.ego_route)
        cfg.vehicle_sources = cfg.vehicle_sources or [e for e in sources if e not in ego] or sources
        cfg.vehicle_sinks = cfg.vehicle_sinks or [e for e in sinks if e not in ego] or sinks
    cfg.validate()
    return scene, cfg
