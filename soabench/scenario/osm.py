"""``soabench import osm FILE.osm --out DIR``: an OpenStreetMap extract -> a scene folder (docs/user-guide/scenes.md).

The wheel's ``netconvert`` builds the network (sidewalks, crossings and walking areas guessed, geometry cleaned,
the projection kept in the net's ``<location>``), ``polyconvert`` the buildings through SUMO's OSM typemap
(``$SUMO_HOME/data/typemap/osmPolyconvert.typ.xml``, building types become ``building.*``). The folder gets a
``scenario.toml`` holding every default derived from the network (:mod:`soabench.scenario.derive`), so a user can
edit them, and a README line on provenance. ``soabench run --net DIR`` / ``soabench scene --net DIR`` accept it.
"""

from __future__ import annotations

import os
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

from soabench.errors import SoabenchError, require

#: netconvert options of an import (pedestrian infrastructure guessed, geometry cleaned).
NETCONVERT_OPTIONS = (
    "--sidewalks.guess", "--crossings.guess", "--walkingareas", "--osm.sidewalks", "--osm.crossings",
    "--geometry.remove", "--junctions.join", "--roundabouts.guess", "--remove-edges.isolated",
    "--keep-edges.by-vclass", "passenger,pedestrian",
    "--no-turnarounds.except-deadend", "--no-warnings",
)  # fmt: skip

#: OSM ``highway`` values people may walk on (a file with none of them has no walkable way).
WALKABLE = {
    "footway", "pedestrian", "path", "steps", "living_street", "residential", "tertiary", "secondary", "primary",
    "unclassified", "service", "track", "crossing", "sidewalk", "cycleway",
}  # fmt: skip


def sumo_home() -> str:
    """SUMO_HOME of the eclipse-sumo wheel (its ``bin/`` holds netconvert, polyconvert)."""
    import sumo

    return str(sumo.SUMO_HOME)


def _tool(name: str, args: list[str], what: str) -> None:
    home = sumo_home()
    env = {**os.environ, "SUMO_HOME": home}
    proc = subprocess.run([str(Path(home) / "bin" / name), *args], capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        lines = [ln.strip() for ln in (proc.stderr or proc.stdout).splitlines() if ln.strip()]
        err = next((ln for ln in lines if ln.startswith("Error")), lines[-1] if lines else f"exit {proc.returncode}")
        raise SoabenchError(f"{name} failed on {what}: {err}")


def check_osm(osm: Path) -> tuple[int, int]:
    """(roads, walkable ways) of an OSM file; SoabenchError (one line) for malformed XML, no roads, no walkable way."""
    require(osm.is_file(), f"OSM file {str(osm)!r} does not exist; give the path of an .osm file")
    try:
        root = ET.parse(osm).getroot()
    except ET.ParseError as exc:
        raise SoabenchError(f"OSM file {str(osm)!r} is not valid XML ({exc})") from None
    require(root.tag == "osm", f"OSM file {str(osm)!r} is not OpenStreetMap XML (root <{root.tag}>, expected <osm>)")
    roads = walkable = 0
    for way in root.iter("way"):
        tags = {t.get("k"): t.get("v") for t in way.iter("tag")}
        hw = tags.get("highway")
        if hw is None:
            continue
        roads += 1
        walkable += hw in WALKABLE and tags.get("foot") != "no"
    require(roads > 0, f"OSM file {str(osm)!r} holds no roads (no way with a highway tag); export an area with streets")
    require(
        walkable > 0,
        f"OSM file {str(osm)!r} holds no walkable ways (footway, pedestrian, residential, ...); pedestrians need some",
    )
    return roads, walkable


def import_osm(osm_file: str | os.PathLike, out: str | os.PathLike) -> Path:
    """Build the scene folder ``out`` from ``osm_file`` (module docstring); return its scenario.toml path."""
    osm = Path(osm_file)
    check_osm(osm)
    folder = Path(out)
    require(
        not (folder / "scenario.toml").exists(),
        f"--out {str(folder)!r} already holds a scene (scenario.toml); choose another folder",
    )
    require(folder.parent.is_dir(), f"output folder {str(folder.parent)!r} does not exist for --out {str(out)!r}")
    folder.mkdir(exist_ok=True)
    stem = osm.name.removesuffix(".osm.xml").removesuffix(".osm").removesuffix(".xml") or "osm"
    net = folder / f"{stem}.net.xml"
    polys = folder / "buildings.poly.xml"
    tmp_net = folder / f".{stem}.net.xml.tmp"
    _tool("netconvert", ["--osm-files", str(osm), "-o", str(tmp_net), *NETCONVERT_OPTIONS], str(osm))
    tmp_net.replace(net)
    typemap = Path(sumo_home()) / "data" / "typemap" / "osmPolyconvert.typ.xml"
    _tool(
        "polyconvert",
        ["--net-file", str(net), "--osm-files", str(osm), "--type-file", str(typemap), "-o", str(polys),
         "--osm.keep-full-type", "--no-warnings"],
        str(osm),
    )  # fmt: skip
    from soabench.scenario import ScenarioConfig
    from soabench.scenario.derive import derive_defaults
    from soabench.scenario.network import read_net

    cfg = ScenarioConfig(net_file=str(net), poly_files=[str(polys)], name=stem, pedestrian_model="striping")
    try:
        scene = derive_defaults(cfg, read_net(net))
    except SoabenchError as exc:
        for f in (net, polys):
            f.unlink(missing_ok=True)
        raise SoabenchError(f"OSM file {str(osm)!r}: {exc}") from None
    (folder / "scenario.toml").write_text(scenario_toml(cfg, scene, net.name, polys.name, osm.name), encoding="utf-8")
    (folder / "README.md").write_text(
        f"# {stem}\n\nImported from OpenStreetMap file `{osm.name}` with `soabench import osm` "
        f"(SUMO netconvert {' '.join(NETCONVERT_OPTIONS)}; polyconvert with SUMO's osmPolyconvert typemap). "
        "Map data (c) OpenStreetMap contributors, ODbL.\n",
        encoding="utf-8",
    )
    return folder / "scenario.toml"


def _q(items) -> str:
    return "[" + ", ".join(f'"{s}"' for s in items) + "]"


def scenario_toml(cfg, scene, net_name: str, poly_name: str, source: str) -> str:
    """A scenario TOML spelling out ``cfg``'s derived values (every key of soabench/scenario/config.py)."""
    x0, y0, x1, y1 = cfg.world_box
    doors = ", ".join(f"[{x:.2f}, {y:.2f}]" for x, y in scene.doors)
    return f"""# Scene imported from {source} by `soabench import osm`; the values below were derived from the network
# (docs/user-guide/scenes.md) and may be edited. Keys: soabench/scenario/config.py.

[scenario]
name = "{cfg.name}"
description = "OpenStreetMap import of {source}"

[files]
net = "{net_name}"
polys = ["{poly_name}"]

[simulation]
world_box = [{x0:.2f}, {y0:.2f}, {x1:.2f}, {y1:.2f}]
step_length = {cfg.step_length!r}
duration = {cfg.duration!r}

[ego]
route = {_q(cfg.ego_route)}
max_speed = {cfg.ego_max_speed!r}

[vehicles]
count = {cfg.n_vehicles}
sources = {_q(cfg.vehicle_sources)}
sinks = {_q(cfg.vehicle_sinks)}

[pedestrians]
count = {cfg.n_pedestrians}
model = "{cfg.pedestrian_model}"   # striping: SUMO 1.28's jupedsim hangs on nets whose sidewalks enclose a block

[doors]
points = [{doors}]
"""
