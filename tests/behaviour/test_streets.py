"""Any street: user networks of every kind, OSM import, the shipped scene suite, the occlusion sweep."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
import sumo
from repo_paths import DATA, ROOT

from soabench.cli.main import main
from soabench.errors import SoabenchError
from soabench.scenario import load, shipped_nets, shipped_root, simulate
from soabench.scenario.network import fringe_edges, read_net
from soabench.seeding import trial_seeds

pytestmark = pytest.mark.slow  # OSM import, every shipped scene, the occlusion sweep

BIN = Path(sumo.SUMO_HOME) / "bin"
ENV = {**os.environ, "SUMO_HOME": sumo.SUMO_HOME}


def _tool(*args: str) -> None:
    subprocess.run([str(BIN / args[0]), *args[1:], "--no-warnings"], check=True, capture_output=True, env=ENV)


@pytest.fixture(scope="module")
def nets(tmp_path_factory) -> dict[str, Path]:
    """Every network kind of the issue, generated with the wheel's netgenerate / netconvert."""
    d = tmp_path_factory.mktemp("nets")
    ped = ("--sidewalks.guess", "--crossings.guess")
    _tool("netgenerate", "--grid", "--grid.number", "3", "--grid.length", "80", *ped, "-o", str(d / "grid.net.xml"))
    _tool("netgenerate", "--spider", "--spider.arm-number", "4", "--spider.circle-number", "2",
          "--spider.space-radius", "50", *ped, "-o", str(d / "spider.net.xml"))  # fmt: skip
    _tool("netgenerate", "--rand", "--rand.iterations", "12", "--seed", "3", *ped, "-o", str(d / "rand.net.xml"))
    # hand-built: a one-way street into a dead end with turnarounds, sidewalk lanes written by hand
    (d / "h.nod.xml").write_text(
        '<nodes><node id="a" x="0" y="0"/><node id="b" x="150" y="0" type="priority"/><node id="c" x="300" y="0"/>'
        '<node id="d" x="150" y="150"/></nodes>'
    )
    lanes = '<lane index="0" allow="pedestrian" width="3"/><lane index="1" disallow="pedestrian"/>'
    (d / "h.edg.xml").write_text(
        f'<edges><edge id="ab" from="a" to="b" numLanes="2" speed="13.9">{lanes}</edge>'
        f'<edge id="bc" from="b" to="c" numLanes="2" speed="13.9">{lanes}</edge>'
        f'<edge id="cb" from="c" to="b" numLanes="2" speed="13.9">{lanes}</edge>'
        f'<edge id="bd" from="b" to="d" numLanes="2" speed="13.9">{lanes}</edge>'
        f'<edge id="db" from="d" to="b" numLanes="2" speed="13.9">{lanes}</edge></edges>'
    )
    _tool("netconvert", "-n", str(d / "h.nod.xml"), "-e", str(d / "h.edg.xml"), "--crossings.guess",
          "-o", str(d / "hand.net.xml"))  # fmt: skip
    # footways only: car-only roads; pedestrians walk on separate footway edges on both sides that meet at the
    # junction, joined by two crossings over the road
    (d / "f.nod.xml").write_text(
        '<nodes><node id="c" x="0" y="0" type="priority"/><node id="w" x="-150" y="0"/><node id="e" x="150" y="0"/>'
        '<node id="fw" x="-150" y="12"/><node id="fe" x="150" y="12"/><node id="gw" x="-150" y="-12"/>'
        '<node id="ge" x="150" y="-12"/></nodes>'
    )
    road = 'numLanes="1" speed="13.9" disallow="pedestrian"'
    foot = 'numLanes="1" speed="2" allow="pedestrian" width="2.5"'
    (d / "f.edg.xml").write_text(
        f'<edges><edge id="wc" from="w" to="c" {road}/><edge id="cw" from="c" to="w" {road}/>'
        f'<edge id="ce" from="c" to="e" {road}/><edge id="ec" from="e" to="c" {road}/>'
        f'<edge id="foot1" from="fw" to="c" {foot}/><edge id="foot2" from="c" to="fe" {foot}/>'
        f'<edge id="foot3" from="gw" to="c" {foot}/><edge id="foot4" from="c" to="ge" {foot}/></edges>'
    )
    (d / "f.con.xml").write_text(
        '<connections><crossing node="c" edges="wc cw" priority="true"/>'
        '<crossing node="c" edges="ce ec" priority="true"/></connections>'
    )
    _tool("netconvert", "-n", str(d / "f.nod.xml"), "-e", str(d / "f.edg.xml"), "-x", str(d / "f.con.xml"),
          "--walkingareas", "-o", str(d / "footways.net.xml"))  # fmt: skip
    return {k: d / f"{k}.net.xml" for k in ("grid", "spider", "rand", "hand", "footways")}


def test_turnaround_dead_ends_are_fringe(nets):
    net = read_net(nets["hand"])
    sources, sinks = fringe_edges(net)
    # ab starts at a dead end; bc / bd end at dead ends with a turnaround (sumolib: still fringe); ab is one-way
    assert sources == ["ab", "cb", "db"] and sinks == ["bc", "bd"]


@pytest.mark.parametrize("kind", ["grid", "spider", "rand", "hand", "footways"])
def test_user_net_runs_with_derived_defaults(nets, kind, caplog, monkeypatch):
    caplog.set_level("INFO", logger="soabench")
    monkeypatch.setattr("soabench.scenario.derive._said", set())  # said once per process: another test may have
    scene, sc = load(str(nets[kind]))
    assert len(sc.ego_route) >= 2 and sc.vehicle_sources and sc.vehicle_sinks
    net = read_net(nets[kind])
    for a, b in zip(sc.ego_route[:-1], sc.ego_route[1:], strict=True):
        assert b in {o.getID() for o in net.getEdge(a).getOutgoing()}
    x0, y0, x1, y1 = scene.bounds
    nx0, ny0, nx1, ny1 = net.getBoundary()
    assert nx0 - 10 <= x0 < x1 <= nx1 + 10 and ny0 - 10 <= y0 < y1 <= ny1 + 10
    assert "derived ego route" in caplog.text and "no polygon files" in caplog.text
    rec = simulate(scene, sc, trial_seeds(0, 0), duration=3.0)
    assert rec.ped_present.any() and not np.isnan(rec.ego_pose).any()


def test_footway_net_has_crossings_and_no_sidewalk_lanes(nets):
    scene, _ = load(str(nets["footways"]), quiet=True)
    assert scene.crossings.area > 20.0 and scene.walking_areas.area > 20.0
    net = read_net(nets["footways"])
    assert all(not ln.allows("pedestrian") for e in ("wc", "cw", "ce", "ec") for ln in net.getEdge(e).getLanes())


def test_buildings_without_doors_say_so_and_continue(nets, tmp_path, caplog):
    caplog.set_level("INFO", logger="soabench")
    far = tmp_path / "far.poly.xml"  # a building 500 m from any sidewalk: no door is derived
    far.write_text(
        '<additional><poly id="b" type="building" color="255,200,0" '
        'shape="500,500 540,500 540,540 500,540 500,500"/></additional>'
    )
    scene, sc = load(str(nets["hand"]), polys=[str(far)])
    assert len(scene.buildings) == 1 and len(scene.doors) == 0
    rec = simulate(scene, sc, trial_seeds(0, 0), duration=2.0)
    assert rec.ped_present.any() and rec.meta["n_enter"] == 0
    said = [r.getMessage() for r in caplog.records if "derived" in r.getMessage()]
    assert len(said) == 1 and "0 door(s) from" in said[0]


def test_net_without_pedestrian_lane_names_netconvert_options(tmp_path, nets, capsys):
    _tool("netgenerate", "--grid", "--grid.number", "2", "-o", str(tmp_path / "cars.net.xml"))
    rc = main(["scene", "--net", str(tmp_path / "cars.net.xml"), "--out", str(tmp_path / "x.png")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--sidewalks.guess --crossings.guess" in err[0]


def test_cli_commands_on_a_generated_net(nets, tmp_path):
    net = str(nets["spider"])
    assert main(["scene", "--net", net, "--time", "2", "--out", str(tmp_path / "s.png")]) == 0
    assert main(["record", "--net", net, "--duration", "2", "--out", str(tmp_path / "r.npz")]) == 0
    assert main(["birth", "--net", net, "--time", "2", "--out", str(tmp_path / "b.png")]) == 0
    args = ["--net", net, "--trials", "1", "--duration", "3", "--models", "soa,pubm", "--workers", "1", "--no-progress"]
    assert main(["run", *args, "--out", str(tmp_path / "run")]) == 0
    assert (tmp_path / "run" / "summary.json").is_file()
    assert main(["sweep", "clutter", *args, "--values", "1,3", "--out", str(tmp_path / "sw")]) == 0
    assert (tmp_path / "sw" / "sweep.md").is_file()


# ----------------------------------------------------------------------------------------------------- OSM
def test_import_osm_scene_folder_runs(tmp_path, capsys):
    out = tmp_path / "cross"
    assert main(["import", "osm", str(DATA / "crossroads.osm"), "--out", str(out)]) == 0
    assert {"crossroads.net.xml", "buildings.poly.xml", "scenario.toml", "README.md"} <= {p.name for p in out.iterdir()}
    assert "OpenStreetMap" in (out / "README.md").read_text()
    assert "<location" in (out / "crossroads.net.xml").read_text()[:3000]  # projection kept
    scene, sc = load(str(out))
    assert len(scene.buildings) == 2 and len(scene.doors) >= 1 and sc.pedestrian_model == "striping"
    assert main(["scene", "--net", str(out), "--time", "2", "--out", str(tmp_path / "o.png")]) == 0
    # the folder is refused a second time rather than overwritten
    assert main(["import", "osm", str(DATA / "crossroads.osm"), "--out", str(out)]) == 2


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("<osm><node id='1' lat='0' lon='0'></osm>", "not valid XML"),
        ("<osm><node id='1' lat='0' lon='0'/><way id='2'><nd ref='1'/><tag k='building' v='yes'/></way></osm>",
         "holds no roads"),
        ("<osm><node id='1' lat='0' lon='0'/><way id='2'><nd ref='1'/><tag k='highway' v='motorway'/></way></osm>",
         "no walkable ways"),
    ],
)  # fmt: skip
def test_bad_osm_one_line_exit_2(tmp_path, capsys, text, needle):
    f = tmp_path / "bad.osm"
    f.write_text(text)
    rc = main(["import", "osm", str(f), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and needle in err[0] and "bad.osm" in err[0]


# ----------------------------------------------------------------------------------------------- scene suite
def test_suite_has_four_scenes_with_sources_and_package_data():
    names = shipped_nets()
    assert {"intersection", "tjunction", "grid_block", "arterial"} <= set(names)
    for n in names:
        d = shipped_root() / n
        for pattern in ("*.nod.xml", "*.edg.xml", "*.net.xml", "*.poly.xml", "build.sh", "README.md"):
            assert list(d.glob(pattern)), f"{n}: no {pattern}"
        assert (ROOT / "docs" / "scenes" / f"{n}.png").is_file()


def test_scene_files_match_the_package_data_globs():
    """Every shipped scene file travels with a non-editable install (pyproject package-data for the nets)."""
    import fnmatch
    import sys

    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    data = pyproject["tool"]["setuptools"]["package-data"]
    globs = [g.rsplit("/", 1)[-1] for key, gs in data.items() if "nets" in key for g in gs]
    assert globs
    for n in shipped_nets():
        for f in (shipped_root() / n).iterdir():
            assert any(fnmatch.fnmatch(f.name, g) for g in globs), f"{n}/{f.name} is not package data"


def test_scenes_table(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    for n in shipped_nets():
        assert f"| {n} |" in out


@pytest.mark.parametrize("name", ["tjunction", "grid_block", "arterial", "intersection"])
def test_short_run_on_every_shipped_scene(name):
    scene, sc = load(name)
    rec = simulate(scene, sc, trial_seeds(0, 0), duration=3.0)
    assert rec.ped_present.any() and rec.veh_present.any()
    assert len(scene.doors) > 0 and len(scene.buildings) > 0


def test_parking_density_replaces_parked_cars():
    scene, _ = load("tjunction")
    assert len(scene.static_occluders) >= 20  # 12 per 100 m of kerb
    for car in scene.static_occluders:
        assert scene.roads.buffer(0.01).contains(car) and car.intersection(scene.sidewalk).area < 1e-9


def test_net_all_reports_per_scene(tmp_path, capsys):
    assert main(["scene", "--net", "all", "--time", "1", "--out", str(tmp_path / "s.png")]) == 0
    out = capsys.readouterr().out
    for n in shipped_nets():
        assert (tmp_path / f"s_{n}.png").is_file() and f"| {n} | ok |" in out


# ------------------------------------------------------------------------------------------- occlusion sweep
def test_occlusion_sweep(tmp_path):
    args = ["sweep", "occlusion", "--net", "tjunction", "--values", "0,12", "--trials", "1", "--duration", "4",
            "--models", "soa,ubm", "--workers", "1", "--no-progress", "--out", str(tmp_path / "sw")]  # fmt: skip
    assert main(args) == 0
    sw = tmp_path / "sw"
    assert (sw / "sweep_occlusion.png").is_file()
    md = (sw / "sweep.md").read_text()
    assert "Occlusion sweep" in md and "W / T / L" in md
    from soabench.scenario import load as load_scene

    n0 = len(load_scene("tjunction", scenario=str(sw / "points" / "density_00.00.scenario.toml"))[0].static_occluders)
    n12 = len(load_scene("tjunction", scenario=str(sw / "points" / "density_12.00.scenario.toml"))[0].static_occluders)
    assert n0 == 0 and n12 >= 20


def test_occlusion_sweep_bad_density(tmp_path, capsys):
    rc = main(["sweep", "occlusion", "--values", "50", "--trials", "1", "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "50" in err[0]


def test_parking_on_net_without_parking_lanes(nets, tmp_path):
    toml = tmp_path / "p.toml"
    toml.write_text("[parking]\ndensity = 5.0\n")
    with pytest.raises(SoabenchError, match="parking lanes"):
        load(str(nets["grid"]), scenario=str(toml))
