"""``soabench import osm FILE.osm --out DIR``: an OpenStreetMap extract -> a scene folder (docs/user-guide/scenes.md).

The wheel's ``netconvert`` builds the network (sidewalks, crossings and walking areas guessed, geometry cleaned,
the projection kept in the net's ``<location>``), ``polyconvert`` the buildings through SUMO's OSM typemap
(``$SUMO_HOME/data/typemap/osmPolyconvert.typ.xml``, building types become ``building.*``). The folder gets a
``scenario.toml`` holding every default derived from the network (:mod:`soabench.scenario.derive`), so a user can
edit them, and a README line on provenance. ``soabench run --net DIR`` / ``soabench scene --net DIR`` accept it.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from soabench.errors import SoabenchError, require
from soabench.folders import check_new_folder, resolve
from soabench.scenario import ScenarioConfig
from soabench.scenario.derive import derive_defaults
from soabench.scenario.network import read_net

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


#: OSM files above this size are refused unless forced: a 50 MB extract took minutes and gigabytes to import, and
#: a trial on its scene several gigabytes (the scene's size is what a trial costs: lanes, polygons, pedestrians)
MAX_OSM_MB = 10.0
PROGRESS_EVERY_S = 10.0  #: a line on stderr this often while netconvert or polyconvert runs


def _say(message: str) -> None:
    print(f"soabench: {message}", file=sys.stderr, flush=True)


def _tool(name: str, args: list[str], what: str) -> None:
    """Run a SUMO tool; a line every :data:`PROGRESS_EVERY_S` seconds while it runs; one-line SoabenchError on a
    failure."""
    home = sumo_home()
    env = {**os.environ, "SUMO_HOME": home}
    t0 = time.monotonic()
    with subprocess.Popen(
        [str(Path(home) / "bin" / name), *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
    ) as proc:
        while True:
            try:
                stdout, stderr = proc.communicate(timeout=PROGRESS_EVERY_S)
                break
            except subprocess.TimeoutExpired:
                _say(f"{name} still running on {what} ({time.monotonic() - t0:.0f} s)")
    if proc.returncode != 0:
        lines = [ln.strip() for ln in (stderr or stdout).splitlines() if ln.strip()]
        err = next((ln for ln in lines if ln.startswith("Error")), lines[-1] if lines else f"exit {proc.returncode}")
        raise SoabenchError(f"{name} failed on {what}: {err}")


@dataclass
class OsmCounts:
    """What an OSM file holds: its size and the elements that make a scene's cost (roads, buildings)."""

    megabytes: float
    nodes: int
    roads: int
    walkable: int
    buildings: int

    def text(self) -> str:
        return (
            f"{self.megabytes:.1f} MB: {self.nodes} nodes, {self.roads} roads ({self.walkable} walkable), "
            f"{self.buildings} buildings"
        )


def check_osm(osm: Path) -> OsmCounts:
    """The counts of an OSM file; SoabenchError (one line) for malformed XML, no roads, no walkable way. Streams the
    file (memory independent of its size)."""
    require(osm.is_file(), f"OSM file {str(osm)!r} does not exist; give the path of an .osm file")
    nodes = roads = walkable = buildings = 0
    try:
        events = ET.iterparse(osm, events=("start", "end"))
        _, root = next(events)
        require(
            root.tag == "osm", f"OSM file {str(osm)!r} is not OpenStreetMap XML (root <{root.tag}>, expected <osm>)"
        )
        for event, elem in events:
            if event != "end" or elem.tag not in ("node", "way", "relation"):
                continue
            if elem.tag == "node":
                nodes += 1
            elif elem.tag == "way":
                tags = {t.get("k"): t.get("v") for t in elem.iter("tag")}
                hw = tags.get("highway")
                buildings += "building" in tags
                if hw is not None:
                    roads += 1
                    walkable += hw in WALKABLE and tags.get("foot") != "no"
            root.clear()  # streamed: the parsed elements are dropped
    except (ET.ParseError, UnicodeDecodeError, ValueError) as exc:
        raise SoabenchError(f"OSM file {str(osm)!r} is not valid XML ({exc})") from None
    except StopIteration:
        raise SoabenchError(f"OSM file {str(osm)!r} is empty") from None
    require(roads > 0, f"OSM file {str(osm)!r} holds no roads (no way with a highway tag); export an area with streets")
    require(
        walkable > 0,
        f"OSM file {str(osm)!r} holds no walkable ways (footway, pedestrian, residential, ...); pedestrians need some",
    )
    return OsmCounts(osm.stat().st_size / 1e6, nodes, roads, walkable, buildings)


def file_stem(osm_name: str) -> str:
    """The name of the files an import writes, from the OSM file's name: letters, digits, ``.``, ``_``, ``-`` kept,
    anything else ``_`` (a name from a file is a name, never a path); ``osm`` when nothing is left."""
    stem = osm_name.removesuffix(".osm.xml").removesuffix(".osm").removesuffix(".xml")
    safe = re.sub(r"[^A-Za-z0-9._-]", "_", stem).lstrip(".-")
    return safe or "osm"


def import_osm(osm_file: str | os.PathLike, out: str | os.PathLike, force: bool = False) -> Path:
    """Build the scene folder ``out`` from ``osm_file`` (module docstring); return its scenario.toml path.

    ``out`` must not exist or be empty; the scene is built in a temporary folder beside it and moved there when
    complete, so an import that fails leaves nothing. Files above :data:`MAX_OSM_MB` are refused unless ``force``.
    """

    osm = Path(osm_file)
    counts = check_osm(osm)
    folder = resolve(out)
    require(
        not (folder / "scenario.toml").exists(),
        f"--out {str(folder)!r} already holds a scene (scenario.toml); choose another folder",
    )
    check_new_folder(folder, "scenario.toml", "scene", "choose another folder")
    require(folder.parent.is_dir(), f"output folder {str(folder.parent)!r} does not exist for --out {str(out)!r}")
    require(
        force or counts.megabytes <= MAX_OSM_MB,
        f"OSM file {str(osm)!r} is {counts.text()}; above {MAX_OSM_MB:g} MB an import takes minutes and a trial on "
        "its scene gigabytes of memory: crop the extract, or pass --force",
    )
    _say(f"importing {osm.name}: {counts.text()}")
    with tempfile.TemporaryDirectory(prefix=f".{folder.name}.import-", dir=folder.parent) as tmp:
        built = _build(osm, Path(tmp) / "scene", file_stem(osm.name))
        if folder.exists():
            folder.rmdir()  # empty (checked above)
        built.rename(folder)
    return folder / "scenario.toml"


def _build(osm: Path, folder: Path, stem: str) -> Path:
    """netconvert, polyconvert, the derived defaults, scenario.toml and README.md into the new ``folder``."""
    folder.mkdir()
    net = folder / f"{stem}.net.xml"
    polys = folder / "buildings.poly.xml"
    t0 = time.monotonic()
    _tool("netconvert", ["--osm-files", str(osm), "-o", str(net), *NETCONVERT_OPTIONS], str(osm))
    _say(f"netconvert built {net.name} ({time.monotonic() - t0:.0f} s)")
    typemap = Path(sumo_home()) / "data" / "typemap" / "osmPolyconvert.typ.xml"
    _tool(
        "polyconvert",
        ["--net-file", str(net), "--osm-files", str(osm), "--type-file", str(typemap), "-o", str(polys),
         "--osm.keep-full-type", "--no-warnings"],
        str(osm),
    )  # fmt: skip
    _say(f"polyconvert wrote {polys.name} ({time.monotonic() - t0:.0f} s)")

    net_map = read_net(net)
    cfg = ScenarioConfig(net_file=str(net), poly_files=[str(polys)], name=stem, pedestrian_model="striping")
    try:
        scene = derive_defaults(cfg, net_map)
    except SoabenchError as exc:
        raise SoabenchError(f"OSM file {str(osm)!r}: {exc}") from None
    edges = net_map.getEdges(withInternal=False)
    n_lanes = sum(len(e.getLanes()) for e in edges)
    _say(
        f"scene {stem}: {len(edges)} edges, {n_lanes} lanes, {len(scene.buildings)} building polygons, "
        f"{cfg.n_pedestrians} pedestrians, {cfg.n_vehicles} vehicles ({time.monotonic() - t0:.0f} s)"
    )
    (folder / "scenario.toml").write_text(scenario_toml(cfg, scene, net.name, polys.name, osm.name), encoding="utf-8")
    (folder / "README.md").write_text(
        f"# {stem}\n\nImported from OpenStreetMap file `{osm.name}` with `soabench import osm` "
        f"(SUMO netconvert {' '.join(NETCONVERT_OPTIONS)}; polyconvert with SUMO's osmPolyconvert typemap). "
        "Map data (c) OpenStreetMap contributors, ODbL.\n",
        encoding="utf-8",
    )
    return folder


def toml_string(text: str) -> str:
    """``text`` as a TOML basic string: quotes, backslashes and control characters escaped (TOML 1.0 §String)."""
    out = []
    for ch in text:
        if ch in ('"', "\\"):
            out.append("\\" + ch)
        elif ch in _SHORT_ESCAPES:
            out.append(_SHORT_ESCAPES[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


_SHORT_ESCAPES = {"\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def _q(items) -> str:
    return "[" + ", ".join(toml_string(str(s)) for s in items) + "]"


def scenario_toml(cfg, scene, net_name: str, poly_name: str, source: str) -> str:
    """A scenario TOML spelling out ``cfg``'s derived values (every key of soabench/scenario/config.py)."""
    x0, y0, x1, y1 = cfg.world_box
    doors = ", ".join(f"[{x:.2f}, {y:.2f}]" for x, y in scene.doors)
    return f"""# Scene imported from OpenStreetMap by `soabench import osm`; the values below were derived from the net
# (docs/user-guide/scenes.md) and may be edited. Keys: soabench/scenario/config.py.

[scenario]
name = {toml_string(cfg.name)}
description = {toml_string(f"OpenStreetMap import of {source}")}

[files]
net = {toml_string(net_name)}
polys = {_q([poly_name])}

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
model = {toml_string(cfg.pedestrian_model)}  # striping: SUMO 1.28's jupedsim hangs where sidewalks enclose a block

[doors]
points = [{doors}]
"""
