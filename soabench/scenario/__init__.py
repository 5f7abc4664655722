"""SUMO scenarios: networks -> :class:`SceneMap`, libsumo runs -> :class:`~soabench.types.Recording`
(docs/development.md pipeline, stage 1).

Public API: :func:`load` (network + polygons + scenario TOML) and :func:`simulate` (one run with libsumo).
"""

from __future__ import annotations

import difflib
import os
from collections.abc import Sequence
from importlib.resources import files
from pathlib import Path

from soabench.errors import require, require_value
from soabench.scenario.config import ScenarioConfig, load_scenario, scenario_from_dict
from soabench.scenario.derive import derive_defaults
from soabench.scenario.network import read_net
from soabench.scenario.scene import SceneMap
from soabench.scenario.simulation import simulate

__all__ = [
    "USER_NET_DEFAULTS",
    "ScenarioConfig",
    "SceneMap",
    "load",
    "load_scenario",
    "scene_folder",
    "shipped_nets",
    "shipped_root",
    "simulate",
]


#: what a user ``.net.xml`` without a scenario file gets besides the derived defaults (scenario-TOML shaped, so a
#: generated scenario file, e.g. a ``sweep occlusion`` point's, starts from it): striping, since SUMO 1.28's jupedsim
#: hangs on nets whose sidewalks enclose a block (a grid).
USER_NET_DEFAULTS: dict[str, dict] = {"pedestrians": {"model": "striping"}}


def shipped_root() -> Path:
    """The folder of the shipped scenes. The ONE place that knows where they live (a packaging change repoints it)."""
    return Path(str(files("soabench.nets")))  # the repository's sumo_nets/ folder


def shipped_nets() -> list[str]:
    """Names of the shipped scenes (folders of :func:`shipped_root` holding a ``scenario.toml``)."""
    root = shipped_root()
    return sorted(p.name for p in root.iterdir() if p.is_dir() and (p / "scenario.toml").is_file())


def scene_folder(net: str) -> Path | None:
    """The scene folder ``net`` names: a shipped scene, or a directory holding a ``scenario.toml`` (as written by
    ``soabench import osm``); None for anything else (e.g. a ``.net.xml`` path)."""
    if net in shipped_nets():
        return shipped_root() / net
    p = Path(net)
    if p.is_dir():
        require_value(
            (p / "scenario.toml").is_file(),
            "net",
            net,
            "is a folder without a scenario.toml; give a scene folder (see `soabench import osm`) or the path of a "
            ".net.xml",
        )
        return p
    return None


def _stem(net_file: str) -> str:
    """``foo`` for ``path/foo.net.xml``."""
    return Path(net_file).name.removesuffix(".gz").removesuffix(".xml").removesuffix(".net")


def _scenario_file_name(path: str | Path) -> str:
    """``busy`` for ``busy.toml``; the folder's name for a file called ``scenario.toml``."""
    p = Path(path)
    return p.resolve().parent.name if p.stem == "scenario" else p.stem


def load(
    net: str, polys: Sequence[str] = (), scenario: str | None = None, *, quiet: bool = False
) -> tuple[SceneMap, ScenarioConfig]:
    """The scene map and the resolved scenario of a network.

    Args:
        net: a shipped name (folder under :func:`shipped_root`, which brings its own polygon files and
            scenario.toml), a scene folder (a directory with a ``scenario.toml``) or the path of a user ``.net.xml``.
        polys: extra SUMO polygon files (buildings / obstacles), added to the scenario's own.
        scenario: a scenario TOML; default: the scene folder's own, or defaults for a user network.
        quiet: do not log the one info line naming what was derived.

    The scenario's name (``ScenarioConfig.name``: labels, summaries, the default output folder) is the scenario
    file's ``[scenario] name``; without one, the file stem of the network the scenario names (``files.net``), else
    of the scenario file (its folder's name for a ``scenario.toml``); without a scenario file, the scene folder's
    name (a shipped name) or the ``.net.xml`` file stem.

    Whatever the scenario leaves open is derived from the network (docs/user-guide/scenes.md; module
    :mod:`soabench.scenario.derive`): ego route, world box, vehicle sources / sinks and doors.
    """
    folder = scene_folder(net)
    if folder is not None:
        own = folder / "scenario.toml"
        cfg = load_scenario(scenario if scenario is not None else own)
        user_net = scenario is not None and bool(cfg.net_file)  # the user's scenario names its own network
        if scenario is None or not cfg.net_file:
            if not cfg.net_file:
                nets = sorted(folder.glob("*.net.xml"))
                n = len(nets)
                require(n == 1, f"scene folder {str(folder)!r} must hold exactly one .net.xml, found {n}")
                cfg.net_file = str(nets[0])
            if scenario is not None:  # a user scenario on a scene folder keeps the folder's own polygons
                cfg.poly_files = load_scenario(own).poly_files + cfg.poly_files
        if scenario is None:
            name = folder.resolve().name
        elif user_net:
            name = _stem(cfg.net_file)
        else:  # the scene's network under a user scenario is no longer the scene's scenario: name it after the file
            name = _scenario_file_name(scenario)
    else:
        shipped = shipped_nets()
        looks_like_path = os.sep in net or net.endswith(".xml") or Path(net).exists()
        close = difflib.get_close_matches(net, shipped, n=1)
        require_value(
            looks_like_path,
            "net",
            net,
            f"is neither a shipped network ({', '.join(shipped)}), a scene folder nor a path to a .net.xml"
            + (f" (did you mean {close[0]!r}?)" if close else ""),
        )
        if scenario is not None:
            cfg = load_scenario(scenario)
        else:
            cfg = scenario_from_dict(USER_NET_DEFAULTS, source="user net defaults")
        cfg.net_file = str(Path(net).resolve()) if Path(net).exists() else net
        name = _stem(net)
    cfg.poly_files = list(dict.fromkeys(list(cfg.poly_files) + [str(p) for p in polys]))  # each file once
    cfg.name = cfg.name or name
    sumo_net = read_net(cfg.net_file)
    scene = derive_defaults(cfg, sumo_net, quiet=quiet)
    cfg.validate()
    return scene, cfg
