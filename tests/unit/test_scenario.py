"""libsumo runs of the shipped intersection -> Recording: determinism, physical plausibility, events."""

from __future__ import annotations

import matplotlib
from repo_paths import ROOT

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import shapely  # noqa: E402
import sumolib  # noqa: E402
from shapely.geometry import LineString  # noqa: E402

from soabench.errors import SoabenchError  # noqa: E402
from soabench.figures.scene import plot_scene  # noqa: E402
from soabench.scenario import load, simulate
from soabench.scenario.simulation import _footprint, _heading  # noqa: E402
from soabench.seeding import trial_seeds  # noqa: E402
from soabench.types import Recording

SEEDS = (1, 2, 3, 4, 5, 6)


@pytest.fixture(scope="module")
def shipped():
    return load("intersection")


@pytest.fixture(scope="module")
def recs(shipped):
    """One full 100 s recording per seed (about 0.5 s each)."""
    scene, sc = shipped
    return {s: simulate(scene, sc, trial_seeds(s, 0)) for s in SEEDS}


@pytest.fixture(scope="module")
def rec(recs):
    return recs[1]


def _arrays(r: Recording) -> dict[str, np.ndarray]:
    keys = ("t", "ego_pose", "ego_footprint", "ped_present", "ped_xy", "ped_speed", "ped_heading")
    return {k: getattr(r, k) for k in (*keys, "veh_present", "veh_footprint")}


# ---------------------------------------------------------------------------------------------------- contract
def test_shapes_and_absent_entries(rec):
    T, P, V = 1000, 6, 3
    assert rec.t.shape == (T,) and rec.t[0] == 0.0 and np.allclose(np.diff(rec.t), 0.1)
    assert rec.ego_pose.shape == (T, 3) and rec.ego_footprint.shape == (T, 4, 2)
    assert rec.ped_xy.shape == (T, P, 2) and rec.ped_present.shape == (T, P) and rec.ped_present.dtype == bool
    assert rec.veh_footprint.shape == (T, V, 4, 2) and rec.veh_present.shape == (T, V)
    assert list(rec.ped_ids) == [f"ped{i}" for i in range(P)]
    assert np.isnan(rec.ped_xy[~rec.ped_present]).all() and not np.isnan(rec.ped_xy[rec.ped_present]).any()
    assert np.isnan(rec.ped_speed[~rec.ped_present]).all() and np.isnan(rec.ped_heading[~rec.ped_present]).all()
    assert np.isnan(rec.veh_footprint[~rec.veh_present]).all()
    assert not np.isnan(rec.ego_pose).any()
    assert rec.ped_present[0].all()  # every pedestrian starts on a sidewalk
    assert np.all(np.abs(rec.ped_heading[rec.ped_present]) <= np.pi)
    assert len(rec.static_occluders) == 17 and rec.meta["pedestrian_model"] == "jupedsim"


def test_duration_override(shipped):
    scene, sc = shipped
    short = simulate(scene, sc, trial_seeds(1, 0), duration=3.0)
    assert short.t.shape == (30,)
    with pytest.raises(SoabenchError, match="duration = -1.0"):
        simulate(scene, sc, trial_seeds(1, 0), duration=-1.0)


# ------------------------------------------------------------------------------------------------- determinism
def test_same_seed_bit_identical(shipped, rec):
    scene, sc = shipped
    again = simulate(scene, sc, trial_seeds(1, 0))
    for k, a in _arrays(rec).items():
        b = getattr(again, k)
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), k
    assert rec.meta == again.meta


def test_prefix_of_a_longer_run_is_identical(shipped, rec):
    scene, sc = shipped
    short = simulate(scene, sc, trial_seeds(1, 0), duration=5.0)
    assert np.array_equal(short.ped_xy, rec.ped_xy[:50], equal_nan=True)


def test_different_seeds_differ(recs):
    starts = [r.ped_xy[0] for r in recs.values()]
    for i in range(len(starts)):
        for j in range(i + 1, len(starts)):
            assert np.abs(starts[i] - starts[j]).max() > 1.0
    assert not np.array_equal(recs[1].ped_xy, recs[2].ped_xy, equal_nan=True)
    assert not np.array_equal(recs[1].veh_footprint, recs[2].veh_footprint, equal_nan=True)


# ------------------------------------------------------------------------------------------------- pedestrians
def test_pedestrians_stay_on_pedestrian_areas(shipped, recs):
    scene, _ = shipped
    area = scene.pedestrian_area
    for r in recs.values():
        xy = r.ped_xy[r.ped_present]
        inside = shapely.contains_xy(scene.world_box, xy[:, 0], xy[:, 1])
        assert inside.all()  # walks go between points of the box; arms are long enough never to leave it
        d = shapely.distance(area, shapely.points(xy[inside]))
        assert d.max() <= 0.5


def test_no_jumps_except_at_insertion(recs):
    for r in recs.values():
        both = r.ped_present[1:] & r.ped_present[:-1]
        step = np.linalg.norm(r.ped_xy[1:] - r.ped_xy[:-1], axis=-1)[both]
        assert step.max() <= 0.5
        # the first 100 steps are checked too (initial placement happened before t = 0)
        assert both[:100].sum() > 0


def test_walking_speed_is_plausible(recs):
    v = np.concatenate([r.ped_speed[r.ped_present] for r in recs.values()])
    moving = v[v > 0.05]
    assert 0.8 <= np.median(moving) <= 1.3
    assert v.max() <= 2.0 and v.min() >= 0.0


def test_speed_and_heading_match_the_track(rec):
    both = rec.ped_present[1:] & rec.ped_present[:-1]
    d = (rec.ped_xy[1:] - rec.ped_xy[:-1])[both]
    th = rec.ped_heading[1:][both]
    moving = np.linalg.norm(d, axis=-1) > 0.08
    cosang = np.cos(np.arctan2(d[moving, 1], d[moving, 0]) - th[moving])
    assert np.median(cosang) > 0.95  # navigational angle converted to the math heading


def test_enter_and_exit_buildings_at_doors(shipped, recs):
    scene, _ = shipped
    n_enter = n_exit = 0
    for r in recs.values():
        for j in range(r.ped_present.shape[1]):
            p = r.ped_present[:, j].astype(np.int8)
            for k in np.flatnonzero(np.diff(p) == -1):  # vanish at k + 1
                n_enter += 1
                assert np.linalg.norm(scene.doors - r.ped_xy[k, j], axis=1).min() < 2.0
            for k in np.flatnonzero(np.diff(p) == 1):  # reappear at k + 1
                n_exit += 1
                assert np.linalg.norm(scene.doors - r.ped_xy[k + 1, j], axis=1).min() < 2.0
    assert n_enter >= 3 and n_exit >= 2
    assert sum(r.meta["n_enter"] for r in recs.values()) == n_enter
    assert sum(r.meta["n_exit"] for r in recs.values()) == n_exit
    assert all(r.meta["n_lost"] == 0 for r in recs.values())  # nobody vanishes away from a door


# ----------------------------------------------------------------------------------------------------- vehicles
def test_footprint_from_front_bumper_and_navigational_angle():
    th = _heading(90.0)  # SUMO 90 deg = east
    assert th == 0.0 and _heading(0.0) == pytest.approx(np.pi / 2) and _heading(270.0) == np.pi
    assert np.isnan(_heading(np.nan)) and _heading(-90.0) == np.pi
    fp = _footprint(np.array([10.0, 0.0]), np.float64(th), 4.0, 2.0)
    assert np.allclose(fp, [[6, -1], [10, -1], [10, 1], [6, 1]])
    assert shapely.Polygon(fp).is_valid and shapely.Polygon(fp).area == pytest.approx(8.0)


def test_vehicle_footprints_lie_on_their_lanes(shipped, recs):
    scene, sc = shipped
    net = sumolib.net.readNet(sc.net_file)
    lanes = [
        LineString(ln.getShape())
        for e in net.getEdges()
        for ln in e.getLanes()
        if ln.allows("passenger") and not ln.allows("pedestrian")
    ]
    lines = shapely.MultiLineString(lanes)
    junction = shapely.box(20.0, -15.0, 50.0, 15.0)  # curved internal lanes are not checked
    checked = 0
    for r in recs.values():
        fp = r.veh_footprint[r.veh_present]
        centre = fp.mean(axis=1)
        keep = ~shapely.contains_xy(junction, centre[:, 0], centre[:, 1])
        keep &= shapely.contains_xy(scene.world_box, centre[:, 0], centre[:, 1])
        keep &= shapely.contains_xy(scene.world_box.buffer(-3.0), centre[:, 0], centre[:, 1])
        pts = shapely.points(centre[keep])
        assert shapely.distance(lines, pts).max() < 0.3
        polys = shapely.polygons(fp[keep])
        assert scene.roads.buffer(0.3).contains(polys).all()
        assert shapely.intersects(scene.sidewalk.buffer(-0.1), polys).sum() == 0
        checked += keep.sum()
    assert checked > 1000


def test_vehicles_drive_forwards(rec):
    V = rec.veh_present.shape[1]
    for j in range(V):
        ok = rec.veh_present[1:, j] & rec.veh_present[:-1, j]
        c = rec.veh_footprint[:, j].mean(axis=1)
        d = (c[1:] - c[:-1])[ok]
        front = (rec.veh_footprint[:, j, 1] + rec.veh_footprint[:, j, 2]) / 2 - c
        mv = np.linalg.norm(d, axis=1) > 0.2
        assert mv.sum() > 10
        assert np.all(np.einsum("ij,ij->i", d[mv], front[1:][ok][mv]) > 0)  # the front is ahead of the motion


def test_ego_crosses_the_intersection(rec):
    x = rec.ego_pose[:, 0]
    assert x[0] == pytest.approx(-47.0, abs=1.0)  # enters at the left edge of the world box
    assert (x < 27.0).any() and (x > 43.0).any()  # from west of the junction to east of it
    assert np.all(np.diff(x) >= -1e-9)
    assert np.allclose(rec.ego_pose[:, 1], -1.75)  # centre of the eastbound driving lane
    # stopped at the red light: the FRONT bumper (not the centre) is at the stop line x = 27
    stopped = np.flatnonzero(np.isclose(np.diff(x), 0.0))
    assert len(stopped) > 20
    front = x[stopped[0]] + 4.5 / 2
    assert 24.5 < front <= 27.0


# -------------------------------------------------------------------------------------------------------- I/O
def test_npz_round_trip(rec, tmp_path):
    path = tmp_path / "rec.npz"
    rec.save_npz(path)
    back = Recording.load_npz(path)
    for k, a in _arrays(rec).items():
        b = getattr(back, k)
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), k
    assert list(back.ped_ids) == list(rec.ped_ids) and list(back.veh_ids) == list(rec.veh_ids)
    assert len(back.static_occluders) == len(rec.static_occluders)
    assert all(np.array_equal(a, b) for a, b in zip(back.static_occluders, rec.static_occluders, strict=True))
    assert (back.seed, back.net, back.meta, back.step_length) == (rec.seed, rec.net, rec.meta, rec.step_length)


def test_docs_recording_format_lists_every_array(rec, tmp_path):

    path = tmp_path / "rec.npz"
    rec.save_npz(path)
    page = (ROOT / "docs" / "user-guide" / "outputs.md").read_text(encoding="utf-8")
    doc = page.split("## Recording format", 1)[1].split("\n## ", 1)[0]
    with np.load(path, allow_pickle=False) as data:
        assert [name for name in data.files if f"`{name}`" not in doc] == []


def test_load_npz_errors(tmp_path):
    with pytest.raises(SoabenchError, match="does not exist"):
        Recording.load_npz(tmp_path / "none.npz")
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(SoabenchError, match="lacks arrays"):
        Recording.load_npz(tmp_path / "other.npz")


# ------------------------------------------------------------------------------------------------ robustness
def test_libsumo_closed_after_an_error(shipped, tmp_path):
    scene, sc = shipped
    import dataclasses

    bad = dataclasses.replace(sc, ego_route=["W_in", "N_in"])  # not connected
    with pytest.raises(SoabenchError):
        simulate(scene, bad, trial_seeds(1, 0), duration=1.0)
    ok = simulate(scene, sc, trial_seeds(1, 0), duration=1.0)
    assert ok.ped_present.any()


def test_user_net_with_defaults_runs(shipped):
    scene, sc = load(shipped[1].net_file, polys=shipped[1].poly_files)
    r = simulate(scene, sc, trial_seeds(7, 0), duration=5.0)
    assert r.ped_present[-1].all() and not np.isnan(r.ego_pose).any()
    n_in_box = sum(b.intersects(scene.world_box) for b in scene.buildings)  # doors only for buildings in the box
    assert 0 < len(scene.doors) == n_in_box < 4 and r.net == "intersection"


def test_scene_figure(shipped, rec, tmp_path):
    scene, _ = shipped
    ax = plot_scene(scene, rec, time=50.0)
    assert ax.get_xlim() == (-50.0, 120.0) and ax.get_ylim() == (-50.0, 50.0)
    assert len(ax.patches) > 4 + 17 + 1  # buildings, parked cars, ego, vehicles, regions
    assert "t = 50.0 s" in ax.get_title(loc="left")  # panel titles sit on the left (soabench.figures.style)
    out = tmp_path / "scene.png"
    ax.figure.savefig(out, dpi=60)
    assert out.stat().st_size > 10_000
    ax2 = plot_scene(scene)
    assert ax2.get_xlim() == (-50.0, 120.0)


def test_bit_identical_in_another_process(shipped):
    import hashlib
    import subprocess
    import sys

    scene, sc = shipped
    code = (
        "import hashlib; from soabench.scenario import load, simulate; from soabench.seeding import trial_seeds\n"
        "s, c = load('intersection'); r = simulate(s, c, trial_seeds(3, 1), duration=4.0)\n"
        "print(hashlib.sha256(r.ped_xy.tobytes() + r.veh_footprint.tobytes() + r.ego_pose.tobytes()).hexdigest())"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    r = simulate(scene, sc, trial_seeds(3, 1), duration=4.0)
    here = hashlib.sha256(r.ped_xy.tobytes() + r.veh_footprint.tobytes() + r.ego_pose.tobytes()).hexdigest()
    assert out == here


def test_other_pedestrian_model_runs(shipped):
    import dataclasses

    scene, sc = shipped
    r = simulate(scene, dataclasses.replace(sc, pedestrian_model="striping"), trial_seeds(1, 0), duration=2.0)
    assert r.meta["pedestrian_model"] == "striping" and r.ped_present[-1].all()


@pytest.mark.parametrize(
    ("net", "world_box", "margin", "comment"),
    [
        ("tjunction", (-60.0, -50.0, 110.0, 50.0), 1.0, "the world box minus the paved area + 1.0 m."),
        ("arterial", (-80.0, -45.0, 90.0, 45.0), 2.0, "the world box minus the paved area + 2.0 m."),
    ],
)
def test_shipped_buildings_are_the_world_box_off_the_paved_area(net, world_box, margin, comment):
    """build.sh derives each scene's buildings with soabench.scenario.blocks: it rewrites the shipped file exactly."""
    from soabench.scenario import shipped_root
    from soabench.scenario.blocks import building_blocks, buildings_xml

    folder = shipped_root() / net
    blocks = building_blocks(folder / f"{net}.net.xml", world_box, margin)
    text = buildings_xml(blocks, f"Generated by build.sh: {comment}")
    assert text == (folder / "buildings.poly.xml").read_text()
