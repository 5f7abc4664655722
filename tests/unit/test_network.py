"""The shipped intersection and the network -> SceneMap loader, without running SUMO."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
import shapely
import sumo
from repo_paths import ROOT
from shapely.geometry import Point

from soabench.errors import SoabenchError
from soabench.scenario import load, load_scenario, shipped_nets
from soabench.scenario.network import read_net

NET_DIR = ROOT / "sumo_nets" / "intersection"
NET = NET_DIR / "intersection.net.xml"


@pytest.fixture(scope="module")
def shipped():
    return load("intersection")


def test_shipped_net_is_listed():
    assert "intersection" in shipped_nets()


def test_world_box_and_coordinates(shipped):
    scene, sc = shipped
    assert scene.bounds == (-50.0, -50.0, 120.0, 50.0)
    assert sc.world_box == (-50.0, -50.0, 120.0, 50.0)
    assert read_net(NET).getLocationOffset() == [0.0, 0.0]  # network coordinates = world coordinates
    for region in (scene.sidewalk, scene.crossings, scene.walking_areas, scene.roads):
        assert scene.world_box.buffer(1e-6).contains(region)


def test_regions_are_consistent(shipped):
    scene, _ = shipped
    assert scene.sidewalk.area > 1000.0  # 3 m sidewalks on both sides of four arms
    assert scene.crossings.area > 100.0  # four 4 m crossings
    assert scene.walking_areas.area > 20.0
    # sidewalks and roads only touch; buildings never overlap the pedestrian area or the road
    assert scene.sidewalk.intersection(scene.roads).area < 1.0
    for b in scene.buildings:
        assert b.intersection(scene.pedestrian_area).area < 1e-6
        assert b.intersection(scene.roads).area < 1e-6
    assert len(scene.buildings) == 4
    assert all(b.area > 1500.0 for b in scene.buildings)


def test_parked_cars_lie_on_parking_lanes(shipped):
    scene, _ = shipped
    assert len(scene.static_occluders) == 17
    for car in scene.static_occluders:
        assert scene.roads.buffer(0.01).contains(car)
        assert car.intersection(scene.sidewalk).area < 1e-9
        assert 3.5 < abs(car.centroid.y) < 6.0  # parking lane band of the main road


def test_doors_on_sidewalk_next_to_buildings(shipped):
    scene, _ = shipped
    assert scene.doors.shape == (8, 2)
    pts = shapely.points(scene.doors)
    assert np.all(shapely.distance(scene.sidewalk_lines, pts) < 1e-6)
    dist_b = np.array([[b.distance(p) for b in scene.buildings] for p in pts]).min(axis=1)
    assert np.all(dist_b < 5.0)


def test_sidewalk_lines_leave_the_box(shipped):
    scene, _ = shipped
    boundary = scene.world_box.exterior
    ends = [Point(c) for ln in scene.sidewalk_lines.geoms for c in (ln.coords[0], ln.coords[-1])]
    assert sum(boundary.distance(p) < 1e-6 for p in ends) == 8  # two sidewalks leave the box on each arm


def test_arms_extend_beyond_the_box():
    x0, y0, x1, y1 = read_net(NET).getBoundary()
    assert x0 <= -200 and x1 >= 250 and y0 <= -150 and y1 >= 150


def test_ego_route_and_vehicle_edges(shipped):
    _, sc = shipped
    assert sc.ego_route == ["W_in", "E_out"]
    assert not set(sc.vehicle_sources + sc.vehicle_sinks) & set(sc.ego_route)
    assert sc.n_vehicles == 3 and sc.n_pedestrians == 6
    assert sc.step_length == 0.1 and sc.duration == 100.0 and sc.pedestrian_model == "jupedsim"


def test_user_net_defaults():
    scene, sc = load(str(NET), polys=[str(NET_DIR / "buildings.poly.xml")])
    # world box: the ego's first max_speed * duration metres plus 40 m, inside the network boundary (+10 m)
    x0, y0, x1, y1 = scene.bounds
    assert -260.0 <= x0 and -210.0 <= y0 and x1 <= 310.0 and y1 <= 210.0
    assert min(x1 - x0, y1 - y0) >= 80.0 and max(x1 - x0, y1 - y0) >= 200.0
    assert len(sc.ego_route) == 2 and sc.ego_route[0].endswith("_in") and sc.ego_route[1].endswith("_out")
    n_in_box = sum(b.intersects(scene.world_box) for b in scene.buildings)
    assert 1 <= n_in_box < 4 and len(scene.doors) == n_in_box  # one per building in the box
    assert len(scene.static_occluders) == 0 and len(scene.buildings) == 4
    assert set(sc.vehicle_sources).isdisjoint(sc.ego_route)


def test_user_scenario_on_user_net(tmp_path):
    toml = tmp_path / "s.toml"
    toml.write_text("[simulation]\nworld_box = [-50, -50, 120, 50]\nduration = 20.0\n[pedestrians]\ncount = 2\n")
    scene, sc = load(str(NET), scenario=str(toml))
    assert sc.duration == 20.0 and sc.n_pedestrians == 2 and scene.bounds == (-50.0, -50.0, 120.0, 50.0)


def test_rebuild_script_holds_the_netconvert_command():
    """The scene's build.sh builds its own sources with the one netconvert command of sumo_nets/netbuild.sh."""
    shared = (NET_DIR.parent / "netbuild.sh").read_text()
    for opt in ("--crossings.guess", "--offset.disable-normalization", '"$1.nod.xml"', '"$1.edg.xml"'):
        assert opt in shared
    text = (NET_DIR / "build.sh").read_text()
    assert "source ../netbuild.sh" in text and "build_net intersection" in text


# ----------------------------------------------------------------------------------------------------- bad input
def _one_line_error(excinfo) -> str:
    msg = str(excinfo.value)
    assert "\n" not in msg and msg
    return msg


def test_missing_net_file(tmp_path):
    with pytest.raises(SoabenchError) as e:
        load(str(tmp_path / "nope.net.xml"))
    assert "nope.net.xml" in _one_line_error(e) and "does not exist" in str(e.value)


def test_unknown_shipped_name():
    with pytest.raises(SoabenchError) as e:
        load("crossroads")
    assert "intersection" in _one_line_error(e)


def test_malformed_net_xml(tmp_path):
    bad = tmp_path / "bad.net.xml"
    bad.write_text("<net><edge id='a'></net>")
    with pytest.raises(SoabenchError) as e:
        load(str(bad))
    assert "bad.net.xml" in _one_line_error(e) and "XML" in str(e.value)


def test_missing_and_malformed_poly_files(tmp_path):
    with pytest.raises(SoabenchError) as e:
        load("intersection", polys=[str(tmp_path / "none.poly.xml")])
    assert "none.poly.xml" in _one_line_error(e)
    bad = tmp_path / "bad.poly.xml"
    bad.write_text("<additional><poly id='x' shape='0,0 1,0'")
    with pytest.raises(SoabenchError) as e:
        load("intersection", polys=[str(bad)])
    assert "bad.poly.xml" in _one_line_error(e)


def test_net_without_pedestrian_lanes(tmp_path):
    (tmp_path / "n.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="100" y="0"/></nodes>')
    (tmp_path / "n.edg.xml").write_text(
        '<edges><edge id="ab" from="a" to="b" numLanes="1" speed="13.9" disallow="pedestrian"/></edges>'
    )
    out = tmp_path / "car_only.net.xml"
    subprocess.run(
        [f"{sumo.SUMO_HOME}/bin/netconvert", "-n", str(tmp_path / "n.nod.xml"), "-e", str(tmp_path / "n.edg.xml"),
         "-o", str(out), "--no-warnings"],
        check=True, capture_output=True, env={"SUMO_HOME": sumo.SUMO_HOME},
    )  # fmt: skip
    with pytest.raises(SoabenchError) as e:
        load(str(out))
    assert "no pedestrian lanes" in _one_line_error(e) and "car_only.net.xml" in str(e.value)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[simulation]\nduration = -5.0\n", "simulation.duration = -5.0"),
        ("[simulation]\nduration = 10.05\n", "multiple of step_length"),
        ("[pedestrians]\ncount = 0\n", "pedestrians.count = 0"),
        ("[pedestrians]\nmodel = 'social'\n", "pedestrians.model = 'social'"),
        ("[pedestrians]\np_enter = 1.5\n", "pedestrians.p_enter = 1.5"),
        ("[pedestrians]\nspeed = [1.2, 0.9]\n", "pedestrians.speed"),
        ("[ego]\nmax_spede = 3.0\n", "unknown key ego.max_spede"),
        ("[weather]\nrain = true\n", "unknown section [weather]"),
        ("[simulation]\nworld_box = [0, 0, -1, 5]\n", "simulation.world_box"),
        ("[vehicles]\ncount = 2.5\n", "vehicles.count = 2.5"),
        ("[simulation\nduration = 5\n", "not valid TOML"),
    ],
)
def test_invalid_scenario_values(tmp_path, text, needle):
    p = tmp_path / "scenario.toml"
    p.write_text(text)
    with pytest.raises(SoabenchError) as e:
        load_scenario(p)
    assert needle in _one_line_error(e)


def test_missing_scenario_file(tmp_path):
    with pytest.raises(SoabenchError) as e:
        load("intersection", scenario=str(tmp_path / "s.toml"))
    assert "s.toml" in _one_line_error(e)


def test_unknown_ego_edge(tmp_path):
    p = tmp_path / "scenario.toml"
    p.write_text("[ego]\nroute = ['W_in', 'nowhere']\n")
    with pytest.raises(SoabenchError) as e:
        load("intersection", scenario=str(p))
    assert "'nowhere'" in _one_line_error(e)


def test_disconnected_ego_route(tmp_path):
    p = tmp_path / "scenario.toml"
    p.write_text("[ego]\nroute = ['W_in', 'N_in']\n")
    with pytest.raises(SoabenchError) as e:
        load("intersection", scenario=str(p))
    assert "does not follow 'W_in'" in _one_line_error(e)
