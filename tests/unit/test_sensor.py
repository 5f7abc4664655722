"""Tests of the synthetic sensor (docs/method.md §2.3, §3.1.1-3.1.2, §3.1.4; T12-T15, T28)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from repo_paths import ROOT
from shapely.geometry import Polygon, box

from soabench.config import Sensor
from soabench.errors import SoabenchError
from soabench.figures.sensor import draw_sensor_overlay
from soabench.geometry import fov_mask, range_bearing, wrap
from soabench.scenario.scene import SceneMap
from soabench.seeding import trial_seeds
from soabench.sensor import (
    circle_tangents,
    compute_obstacles,
    fov_polygon,
    line_of_sight,
    observe,
    occluders_at,
    scan_steps,
    shadow_polygons,
    target_visibility,
    visible_region,
)
from soabench.types import CLUTTER, Recording, Scans

# ----------------------------------------------------------------------------------------------------------------
# synthetic scene and recording (no SUMO needed); also imported by test_sensor_stats.py


def synthetic_scene(buildings: list[Polygon] | None = None, parked: list[Polygon] | None = None) -> SceneMap:
    """A straight east-west road y in [-5, 5] with 3 m sidewalks on both sides, three buildings (one L-shaped)."""
    if buildings is None:
        l_shape = box(80, 10, 110, 40).difference(box(95, 25, 110, 40))
        buildings = [box(0, 10, 30, 40), box(40, -40, 70, -10), l_shape]
    sidewalk = box(-50, 5, 120, 8).union(box(-50, -8, 120, -5)).union(box(33, 8, 37, 50))
    return SceneMap(
        name="synthetic",
        world_box=box(-50, -50, 120, 50),
        sidewalk=sidewalk,
        crossings=box(33, -5, 37, 5),
        walking_areas=Polygon(),
        roads=box(-50, -5, 120, 5),
        buildings=buildings,
        static_occluders=parked if parked is not None else [box(10, 3, 14.5, 4.8)],
        doors=np.array([[15.0, 10.0]]),
        sidewalk_lines=shapely.MultiLineString([[(-50, 6.5), (120, 6.5)], [(-50, -6.5), (120, -6.5)]]),
    )


def _rect(center: np.ndarray, heading: np.ndarray, length: float, width: float) -> np.ndarray:
    """(T, 4, 2) corners of length x width rectangles about ``center`` (T, 2) rotated by ``heading`` (T,)."""
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
    local = np.array([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]]) * [length, width]
    x = center[:, None, 0] + c * local[:, 0] - s * local[:, 1]
    y = center[:, None, 1] + s * local[:, 0] + c * local[:, 1]
    return np.stack([x, y], axis=-1)


def synthetic_recording(
    duration: float = 100.0,
    step: float = 0.1,
    ego_start: tuple[float, float] = (-20.0, -1.5),
    ego_speed: float = 1.0,
    peds: np.ndarray | None = None,
    ped_velocity: np.ndarray | None = None,
    vehicle: bool = True,
) -> Recording:
    """Ego driving east at ``ego_speed``; pedestrians walking at constant velocity (default: 6 on the sidewalks,
    one of them absent (in a building) for the middle third); one other vehicle driving west at y = 2."""
    t = np.round(np.arange(int(round(duration / step)) + 1) * step, 9)
    n_t = len(t)
    ego_xy = np.column_stack([ego_start[0] + ego_speed * t, np.full(n_t, ego_start[1])])
    ego_theta = np.zeros(n_t)
    if peds is None:
        peds = np.array([[-10, 6.5], [20, 6.5], [60, -6.5], [35, 30], [100, 6.5], [5, -6.5]], float)
        ped_velocity = np.array([[0.8, 0], [-0.6, 0], [-1.0, 0], [0, -0.5], [-0.7, 0], [0.5, 0]])
    peds = np.asarray(peds, dtype=float).reshape(-1, 2)
    vel = np.zeros_like(peds) if ped_velocity is None else np.asarray(ped_velocity, dtype=float).reshape(-1, 2)
    ped_xy = peds[None] + t[:, None, None] * vel[None]
    present = np.ones((n_t, len(peds)), dtype=bool)
    if len(peds) >= 4:
        present[(t > duration / 3) & (t < 2 * duration / 3), 3] = False
    ped_xy[~present] = np.nan
    speed = np.where(present, np.hypot(vel[:, 0], vel[:, 1])[None], np.nan)
    heading = np.where(present, np.arctan2(vel[:, 1], vel[:, 0])[None], np.nan)
    if vehicle:
        veh_xy = np.column_stack([110 - 1.5 * t, np.full(n_t, 2.0)])
        veh_fp = _rect(veh_xy, np.full(n_t, np.pi), 4.5, 1.8)[:, None]
        veh_present = np.ones((n_t, 1), dtype=bool)
        veh_ids = np.array(["veh0"])
    else:
        veh_fp, veh_present, veh_ids = np.zeros((n_t, 0, 4, 2)), np.zeros((n_t, 0), bool), np.zeros(0, str)
    return Recording(
        t=t,
        step_length=step,
        ego_pose=np.column_stack([ego_xy, ego_theta]),
        ego_footprint=_rect(ego_xy, ego_theta, 4.5, 1.8),
        ped_ids=np.array([f"ped{i}" for i in range(len(peds))]),
        ped_present=present,
        ped_xy=ped_xy,
        ped_speed=speed,
        ped_heading=heading,
        veh_ids=veh_ids,
        veh_present=veh_present,
        veh_footprint=veh_fp,
        static_occluders=[],
        seed=0,
        net="synthetic",
    )


def static_recording(
    peds: np.ndarray, n_scans: int, ego: tuple[float, float, float] = (0.0, 0.0, 0.0), step: float = 1.0
) -> Recording:
    """Ego and pedestrians standing still for ``n_scans`` scans of 1 s (cheap statistical runs)."""
    rec = synthetic_recording(
        duration=(n_scans - 1) * step, step=step, ego_start=ego[:2], ego_speed=0.0, peds=peds, vehicle=False
    )
    rec.ego_pose[:, 2] = ego[2]
    rec.ped_present[:] = True
    rec.ped_xy[:] = np.asarray(peds, dtype=float).reshape(1, -1, 2)
    return rec


def open_scene(occluders: list[Polygon] | None = None) -> SceneMap:
    """No buildings; optional parked-car occluders."""
    return synthetic_scene(buildings=[], parked=occluders or [])


# ----------------------------------------------------------------------------------------------------------------
# line of sight

BOX = np.array([[9, -1], [11, -1], [11, 1], [9, 1]], dtype=float)  # T13 box [9, 11] x [-1, 1]
ORIGIN = np.zeros(2)


def test_target_behind_box_is_invisible_and_beside_it_visible():
    targets = np.array([[20.0, 0.0], [20.0, 5.0], [5.0, 0.0], [20.0, -3.0]])
    vis = line_of_sight(ORIGIN, targets, [Polygon(BOX)])
    assert vis.tolist() == [False, True, True, True]


def test_line_of_sight_is_strict_touching_is_visible():
    occ = [Polygon(BOX)]
    # through the vertex (9, 1) exactly, and along the top edge y = 1
    assert line_of_sight(ORIGIN, np.array([[18.0, 2.0]]), occ).tolist() == [True]
    assert line_of_sight(np.array([0.0, 1.0]), np.array([[20.0, 1.0]]), occ).tolist() == [True]
    # a hair inside the corner is blocked
    assert line_of_sight(ORIGIN, np.array([[18.0, 1.999]]), occ).tolist() == [False]


def test_line_of_sight_ignores_occluder_containing_the_sensor_and_handles_empty_inputs():
    around_ego = Polygon([(-2, -2), (2, -2), (2, 2), (-2, 2)])
    vis = line_of_sight(ORIGIN, np.array([[20.0, 0.0], [20.0, 5.0]]), [around_ego, Polygon(BOX)])
    assert vis.tolist() == [False, True]
    assert line_of_sight(ORIGIN, np.zeros((0, 2)), [Polygon(BOX)]).shape == (0,)
    assert line_of_sight(ORIGIN, np.array([[20.0, 0.0]]), []).tolist() == [True]


def test_three_visibility_points_see_around_a_thin_pole():
    pole = [box(9.9, -0.1, 10.1, 0.1)]
    target = np.array([[20.0, 0.0]])
    assert target_visibility(ORIGIN, target, pole, 1).tolist() == [False]
    assert target_visibility(ORIGIN, target, pole, 3, 0.3).tolist() == [True]
    wall = [box(9.9, -2, 10.1, 2)]
    assert target_visibility(ORIGIN, target, wall, 3, 0.3).tolist() == [False]


# ----------------------------------------------------------------------------------------------------------------
# tangent rays and obstacles (T12-T15)


def test_T12_circle_tangents():
    theta_min, theta_max, r_b = circle_tangents((10.0, 0.0), 1.0, ORIGIN)
    assert np.degrees(theta_max) == pytest.approx(5.7392, abs=1e-4)
    assert np.degrees(theta_min) == pytest.approx(-5.7392, abs=1e-4)
    assert r_b == pytest.approx(np.sqrt(99.0), abs=1e-9)
    assert r_b == pytest.approx(9.94987, abs=1e-5)
    assert circle_tangents((10.0, 0.0), 1.0, (9.5, 0.0)) is None  # inside
    assert circle_tangents((10.0, 0.0), 1.0, (9.0, 0.0)) is None  # on the circle
    # behind the ego the interval straddles +-pi
    theta_min, theta_max, _ = circle_tangents((-10.0, 0.0), 1.0, ORIGIN)
    assert np.degrees(theta_min) == pytest.approx(180 - 5.7392, abs=1e-4)
    assert np.degrees(theta_max) == pytest.approx(-180 + 5.7392, abs=1e-4)


def test_T13_box_tangents():
    obs = compute_obstacles([BOX], ["parked"], ORIGIN, 50.0)
    assert len(obs) == 1
    assert np.degrees(obs.theta_max[0]) == pytest.approx(6.3402, abs=1e-4)
    assert obs.theta_max[0] == pytest.approx(np.arctan2(1, 9), abs=1e-12)
    assert obs.theta_min[0] == pytest.approx(-np.arctan2(1, 9), abs=1e-12)
    assert obs.r_min[0] == pytest.approx(np.sqrt(82.0), abs=1e-12)
    assert obs.r_max[0] == pytest.approx(9.05539, abs=1e-5)
    assert obs.centroid_range[0] == pytest.approx(10.0)
    assert obs.centroid_bearing[0] == pytest.approx(0.0)
    assert obs.kind.tolist() == ["parked"]
    assert shapely.equals(Polygon(obs.polygons[0]), Polygon(BOX))
    assert Polygon(obs.polygons[0]).exterior.is_ccw and len(obs.polygons[0]) == 4


def test_T14_box_behind_the_ego_straddles_pi():
    obs = compute_obstacles([-BOX], ["vehicle"], ORIGIN, 50.0)
    assert np.degrees(obs.theta_min[0]) == pytest.approx(173.66, abs=5e-3)
    assert np.degrees(obs.theta_max[0]) == pytest.approx(-173.66, abs=5e-3)
    width = np.degrees(np.mod(obs.theta_max[0] - obs.theta_min[0], 2 * np.pi))
    assert width == pytest.approx(12.68, abs=5e-3)
    assert abs(obs.centroid_bearing[0]) == pytest.approx(np.pi)


def test_T15_ego_inside_or_obstacle_beyond_r_max_gives_none():
    inside = compute_obstacles([BOX], ["building"], np.array([10.0, 0.0]), 50.0)
    on_edge = compute_obstacles([BOX], ["building"], np.array([9.0, 0.0]), 50.0)
    far = compute_obstacles([BOX + [60.0, 0.0]], ["building"], ORIGIN, 50.0)
    near_edge = compute_obstacles([BOX + [40.9, 0.0]], ["building"], ORIGIN, 50.0)  # nearest point at 49.9 m
    assert len(inside) == len(on_edge) == len(far) == 0
    assert len(near_edge) == 1
    assert compute_obstacles([], [], ORIGIN, 50.0).theta_min.shape == (0,)


def test_non_convex_building_uses_its_convex_hull():
    l_shape = np.array([[10, 0], [20, 0], [20, 10], [15, 10], [15, 5], [10, 5]], dtype=float)
    obs = compute_obstacles([l_shape], ["building"], np.array([0.0, 20.0]), 50.0)
    hull = Polygon(l_shape).convex_hull
    assert len(obs.polygons[0]) == 5
    assert shapely.equals(Polygon(obs.polygons[0]), hull)
    assert obs.theta_max[0] == pytest.approx(np.arctan2(-10, 20))  # vertex (20, 10)
    assert obs.theta_min[0] == pytest.approx(np.arctan2(-20, 10))  # vertex (10, 0)
    shadow = shadow_polygons(np.array([0.0, 20.0]), obs, 50.0)[0]
    assert shadow.contains(shapely.Point(18.0, 8.0))  # the notch counts as occluded
    assert shadow.contains(shapely.Point(30.0, -5.0)) and not shadow.contains(shapely.Point(5.0, 10.0))


def test_random_obstacles_have_every_vertex_inside_their_cone():
    rng = np.random.default_rng(3)
    n = 300
    centers = rng.uniform(-40, 40, (n, 2))
    angles = rng.uniform(-np.pi, np.pi, n)
    polys = [_rect(c[None], a[None], 4.5, 1.8)[0] for c, a in zip(centers, angles, strict=True)]
    ego = np.array([1.0, -2.0])
    obs = compute_obstacles(polys, ["vehicle"] * n, ego, 60.0)
    assert len(obs) == n - sum(Polygon(p).intersects(shapely.Point(ego)) for p in polys)
    width = np.mod(obs.theta_max - obs.theta_min, 2 * np.pi)
    assert np.all(width < np.pi)
    for i, poly in enumerate(obs.polygons):
        d = poly - ego
        rel = np.mod(np.arctan2(d[:, 1], d[:, 0]) - obs.theta_min[i], 2 * np.pi)
        rel = np.where(rel > 2 * np.pi - 1e-9, 0.0, rel)
        assert np.all(rel <= width[i] + 1e-9)
        assert np.isclose(rel.min(), 0.0, atol=1e-9) and np.isclose(rel.max(), width[i], atol=1e-9)
        assert np.isclose(np.hypot(*(poly[np.argmin(rel)] - ego)), obs.r_min[i])


# ----------------------------------------------------------------------------------------------------------------
# FOV, shadows, Omega_k


def test_fov_polygon_matches_fov_mask():
    rng = np.random.default_rng(0)
    ego = np.array([3.0, -4.0, 2.5])
    pts = ego[:2] + rng.uniform(-60, 60, (3000, 2))
    for cfg in (Sensor(), Sensor(fov_deg=120.0, r_min=2.0), Sensor(fov_deg=90.0, r_min=0.0)):
        poly = fov_polygon(ego, cfg)
        inside = shapely.contains_xy(poly, pts[:, 0], pts[:, 1])
        near_edge = shapely.distance(poly.boundary, shapely.points(pts)) < 0.01
        assert np.array_equal(inside[~near_edge], fov_mask(pts, ego, cfg)[~near_edge])
        assert poly.area == pytest.approx(0.5 * cfg.fov * (cfg.r_max**2 - cfg.r_min**2), rel=1e-3)


def test_visible_region_agrees_with_line_of_sight():
    """A sidewalk point is in Omega_k exactly when it is in the FOV, outside every occluder and in line of sight."""
    occ = [box(9, -1, 11, 1), box(-20, 5, -10, 25), box(-3, -30, 3, -28), box(5, 30, 15, 60)]
    scene = synthetic_scene(buildings=[], parked=occ)
    scene.sidewalk = box(-60, -60, 60, 60)
    ego = np.array([0.5, 0.5, 0.3])
    cfg = Sensor(r_min=1.0)
    obs = compute_obstacles([np.asarray(p.exterior.coords)[:-1] for p in occ], ["parked"] * 4, ego[:2], cfg.r_max)
    omega = visible_region(scene, ego, obs, cfg)
    pts = np.random.default_rng(1).uniform(-55, 55, (4000, 2))
    expected = fov_mask(pts, ego, cfg) & line_of_sight(ego[:2], pts, occ)
    expected &= ~shapely.intersects(shapely.union_all(occ), shapely.points(pts))
    got = shapely.contains_xy(omega, pts[:, 0], pts[:, 1])
    near_edge = shapely.distance(omega.boundary, shapely.points(pts)) < 0.02
    assert np.array_equal(got[~near_edge], expected[~near_edge])
    assert expected.sum() > 1000 and (~expected).sum() > 1000


def test_visible_region_is_clipped_to_the_sidewalk_and_removes_shadows():
    scene = synthetic_scene()
    ego = np.array([10.0, -1.5, 0.0])
    cfg = Sensor()
    polys, kinds = [np.asarray(p.exterior.coords)[:-1] for p in scene.static_occluders], ["parked"]
    omega = visible_region(scene, ego, compute_obstacles(polys, kinds, ego[:2], cfg.r_max), cfg)
    assert omega.difference(scene.sidewalk).area < 1e-6
    assert not omega.contains(shapely.Point(13.0, 6.5))  # behind the parked car [10, 14.5] x [3, 4.8]
    assert omega.contains(shapely.Point(25.0, 6.5)) and omega.contains(shapely.Point(10.0, -6.5))
    assert not omega.contains(shapely.Point(70.0, 6.5))  # beyond r_max


# ----------------------------------------------------------------------------------------------------------------
# occluders of a recording step


def test_occluders_at_lists_buildings_parked_cars_and_present_vehicles_once():
    rec = synthetic_recording(duration=10.0)
    scene = synthetic_scene()
    rec.static_occluders = [np.asarray(scene.static_occluders[0].exterior.coords)[:-1], BOX + [50, 0]]
    polys, kinds = occluders_at(rec, scene, 0)
    assert kinds == ["building"] * 3 + ["parked"] * 2 + ["vehicle"]
    assert np.allclose(polys[-1], rec.veh_footprint[0, 0])
    assert Polygon(polys[2]).area == pytest.approx(scene.buildings[2].area)  # L-shape kept as given
    rec.veh_present[5, 0] = False
    assert occluders_at(rec, scene, 5)[1].count("vehicle") == 0


# ----------------------------------------------------------------------------------------------------------------
# observe


def _observe(rec: Recording, scene: SceneMap, cfg: Sensor | None = None, seed: int = 0) -> Scans:
    return observe(rec, scene, cfg or Sensor(), trial_seeds(seed, 0).sensor_rngs())


@pytest.fixture(scope="module")
def run() -> tuple[Recording, SceneMap, Scans]:
    rec, scene = synthetic_recording(), synthetic_scene()
    return rec, scene, _observe(rec, scene)


def test_observe_samples_every_dt_from_zero(run):
    rec, scene, scans = run
    assert len(scans) == 101 and scans.dt == 1.0
    assert [s.k for s in scans.scans] == list(range(101))
    assert np.allclose([s.t for s in scans.scans], np.arange(101.0))
    assert np.allclose(scans.scans[37].ego, rec.ego_pose[370])
    assert np.allclose(scans.truth_xy[37], rec.ped_xy[370], equal_nan=True)
    short = synthetic_recording(duration=10.0)
    assert len(_observe(short, scene, Sensor(dt=0.5))) == 21
    assert len(scan_steps(np.arange(0, 99.95, 0.1), 0.1, 1.0)) == 100  # 0 .. 99.9 s -> 100 scans


def test_observe_flags_measurements_and_sources_are_consistent(run):
    rec, scene, scans = run
    cfg = Sensor()
    assert np.all(scans.in_fov <= scans.present) and np.all(scans.visible <= scans.in_fov)
    assert np.all(scans.detected <= scans.visible)
    assert np.array_equal(np.isnan(scans.truth_xy[..., 0]), ~scans.present)
    assert not scans.present[50, 3] and scans.present[10, 3]  # ped 3 is inside a building in the middle third
    assert 0 < scans.visible.sum() < scans.in_fov.sum()  # some targets are occluded, some are not
    for k, scan in enumerate(scans.scans):
        src = scans.source[k]
        assert scan.Z.shape == (len(src), 2)
        assert sorted(src[src != CLUTTER].tolist()) == np.flatnonzero(scans.detected[k]).tolist()
        assert np.all((scan.Z[:, 1] > -np.pi) & (scan.Z[:, 1] <= np.pi))
        clutter = scan.Z[src == CLUTTER]
        assert np.all((clutter[:, 0] >= cfg.r_min) & (clutter[:, 0] <= cfg.r_max))
        r, b = range_bearing(scans.truth_xy[k, src[src != CLUTTER]], scan.ego)
        assert np.all(np.abs(scan.Z[src != CLUTTER, 0] - r) < 6 * cfg.sigma_r)
        assert np.all(np.abs(wrap(scan.Z[src != CLUTTER, 1] - b)) < 6 * cfg.sigma_b)
        assert {str(o) for o in scan.obstacles.kind} <= {"building", "parked", "vehicle"}
        assert scan.visible_region.difference(scene.sidewalk).area < 1e-6


def test_visibility_in_observe_matches_line_of_sight_on_the_occluders(run):
    rec, scene, scans = run
    for k in (0, 30, 60, 90):
        polys, _ = occluders_at(rec, scene, 10 * k)
        fov = scans.in_fov[k]
        los = line_of_sight(scans.scans[k].ego[:2], scans.truth_xy[k, fov], [Polygon(p) for p in polys])
        assert np.array_equal(scans.visible[k, fov], los)


def test_measurement_order_is_shuffled(run):
    _, _, scans = run
    first_is_clutter = [s[0] == CLUTTER for s in scans.source if len(s) >= 2 and (s != CLUTTER).any()]
    assert 0 < sum(first_is_clutter) < len(first_is_clutter)


def test_T28_observe_is_deterministic_for_a_seed_and_pure(run):
    rec, scene, scans = run
    again = _observe(rec, scene)
    _assert_scans_equal(scans, again)
    other = _observe(rec, scene, seed=1)
    assert any(
        len(a.Z) != len(b.Z) or not np.array_equal(a.Z, b.Z) for a, b in zip(scans.scans, other.scans, strict=True)
    )


def test_clutter_rate_does_not_change_target_measurements():
    rec, scene = synthetic_recording(duration=30.0), synthetic_scene()
    low = _observe(rec, scene, Sensor(lambda_c=0.5))
    high = _observe(rec, scene, Sensor(lambda_c=5.0))
    assert np.array_equal(low.detected, high.detected)
    n_low = n_high = 0
    for k in range(len(low)):
        ta, tb = low.source[k] != CLUTTER, high.source[k] != CLUTTER
        oa, ob = np.argsort(low.source[k][ta]), np.argsort(high.source[k][tb])
        assert np.array_equal(low.scans[k].Z[ta][oa], high.scans[k].Z[tb][ob])
        n_low += int((low.source[k] == CLUTTER).sum())
        n_high += int((high.source[k] == CLUTTER).sum())
    assert n_high > 3 * n_low


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"p_D": 1.3}, "sensor.p_D = 1.3"),
        ({"lambda_c": -1.0}, "sensor.lambda_c = -1.0"),
        ({"r_min": 60.0}, "r_max"),
        ({"fov_deg": 0.0}, "sensor.fov_deg = 0.0"),
        ({"sigma_r": 0.0}, "sensor.sigma_r = 0.0"),
        ({"dt": 0.15}, "multiple of the SUMO step"),
        ({"clutter_space": "sphere"}, "clutter_space"),
    ],
)
def test_observe_rejects_bad_configuration(change, message):
    rec = synthetic_recording(duration=2.0)
    with pytest.raises(SoabenchError, match=message):
        _observe(rec, synthetic_scene(), Sensor(**change))


def test_observe_rejects_a_recording_without_a_sample_at_t0():
    rec = synthetic_recording(duration=2.0)
    rec.t = rec.t + 0.1
    with pytest.raises(SoabenchError, match="recording starts at t = 0.1"):
        _observe(rec, synthetic_scene())


# ----------------------------------------------------------------------------------------------------------------
# .npz round trip and its documentation


def _assert_scans_equal(a: Scans, b: Scans) -> None:
    assert len(a) == len(b) and a.dt == b.dt
    for name in ("truth_xy", "present", "in_fov", "visible", "detected", "ped_ids"):
        assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=name == "truth_xy"), name
    for k, (sa, sb) in enumerate(zip(a.scans, b.scans, strict=True)):
        assert sa.k == sb.k and sa.t == sb.t and np.array_equal(sa.ego, sb.ego)
        assert np.array_equal(sa.Z, sb.Z) and np.array_equal(a.source[k], b.source[k])
        for name in ("kind", "centroid_range", "centroid_bearing", "theta_min", "theta_max", "r_min", "r_max"):
            assert np.array_equal(getattr(sa.obstacles, name), getattr(sb.obstacles, name)), name
        assert all(np.array_equal(p, q) for p, q in zip(sa.obstacles.polygons, sb.obstacles.polygons, strict=True))
        assert len(sa.occluders) == len(sb.occluders)
        assert all(shapely.equals_exact(p, q, 0.0) for p, q in zip(sa.occluders, sb.occluders, strict=True))
        assert shapely.equals_exact(sa.visible_region, sb.visible_region, 0.0)


def test_save_and_load_npz_round_trip(run, tmp_path):
    _, _, scans = run
    path = tmp_path / "scans.npz"
    scans.save_npz(path)
    _assert_scans_equal(scans, Scans.load_npz(path))
    with np.load(path, allow_pickle=False) as data:
        assert data["Z"].dtype == np.float64 and data["source"].dtype == np.int64
    with pytest.raises(SoabenchError, match="does not exist"):
        Scans.load_npz(tmp_path / "missing.npz")


def test_docs_scans_format_lists_every_array(run, tmp_path):
    _, _, scans = run
    path = tmp_path / "scans.npz"
    scans.save_npz(path)
    page = (ROOT / "docs" / "user-guide" / "outputs.md").read_text(encoding="utf-8")
    doc = page.split("## Scans format", 1)[1].split("\n## ", 1)[0]
    with np.load(path, allow_pickle=False) as data:
        missing = [name for name in data.files if f"`{name}`" not in doc]
    assert missing == []


# ----------------------------------------------------------------------------------------------------------------
# overlay


def test_sensor_overlay_draws_sight_lines_cones_and_measurements(run, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    _, _, scans = run
    k = 30
    fig, ax = plt.subplots()
    draw_sensor_overlay(ax, scans, k, Sensor())
    styles = [(line.get_color(), line.get_linestyle()) for line in ax.lines]
    n_blocked = int((scans.in_fov[k] & ~scans.visible[k]).sum())
    n_visible = int(scans.visible[k].sum())
    assert styles.count(("tab:red", "--")) == n_blocked > 0
    assert styles.count(("tab:green", "-")) == n_visible > 0
    assert styles.count(("0.3", "-")) == 2 * len(scans.scans[k].obstacles)
    markers = {line.get_marker(): len(line.get_xdata()) for line in ax.lines if line.get_linestyle() == "None"}
    assert markers["x"] == int((scans.source[k] == CLUTTER).sum())
    assert markers["."] == int((scans.source[k] != CLUTTER).sum())
    legend = {t.get_text() for t in ax.get_legend().get_texts()}  # every overlay symbol is explained
    assert {"line of sight: blocked", "measurement (clutter)", "field of view", "obstacle + shadow"} <= legend
    out = tmp_path / "overlay.png"
    fig.savefig(out, dpi=50)
    plt.close(fig)
    assert out.stat().st_size > 1000


# ----------------------------------------------------------------------------------------------------------------
# a real SUMO recording (the shipped intersection, 30 s)


def test_observe_on_a_real_sumo_recording():
    from soabench.scenario import load, simulate

    scene, scenario = load("intersection")
    seeds = trial_seeds(3, 0)
    rec = simulate(scene, scenario, seeds, duration=30.0)
    scans = observe(rec, scene, Sensor(), seeds.sensor_rngs())
    assert len(scans) == 30 and np.allclose(scans.scans[-1].ego, rec.ego_pose[290])
    polys, kinds = occluders_at(rec, scene, 0)
    assert kinds.count("building") == len(scene.buildings) > 0
    parked_keys = {shapely.normalize(Polygon(p)).wkb for p, kind in zip(polys, kinds, strict=True) if kind == "parked"}
    assert len(parked_keys) == kinds.count("parked") > 0  # scene and recording parked cars are not double counted
    assert scans.present.any() and np.all(scans.visible <= scans.in_fov) and np.all(scans.detected <= scans.visible)
    for k in range(0, 30, 7):  # visibility against an independent DE-9IM check, one pair at a time
        ego, occ = scans.scans[k].ego, scans.scans[k].occluders
        for i in np.flatnonzero(scans.in_fov[k]):
            sight = shapely.LineString([ego[:2], scans.truth_xy[k, i]])
            blocked = any(sight.relate_pattern(o, "T********") for o in occ if not o.contains(shapely.Point(ego[:2])))
            assert scans.visible[k, i] == (not blocked)
        assert all(o.distance(shapely.Point(ego[:2])) <= 50.0 for o in occ)
        assert scans.scans[k].visible_region.difference(scene.sidewalk).area < 1e-6


def test_ego_in_the_courtyard_of_a_u_shaped_building():
    """The hull contains the sensor: no cone (T15), but the walls still block sight and are not in Omega_k."""
    u_building = box(-10, -10, 10, 10).difference(box(-5, -5, 5, 12))
    scene = synthetic_scene(buildings=[u_building], parked=[])
    scene.sidewalk = box(-40, -40, 40, 40)
    rec = static_recording(np.array([[0.0, 20.0], [0.0, -20.0], [2.0, 2.0]]), 3)
    scans = _observe(rec, scene)
    assert len(scans.scans[0].obstacles) == 0
    assert scans.visible[0].tolist() == [True, False, True]
    omega = scans.scans[0].visible_region
    assert not omega.contains(shapely.Point(7.5, 0.0)) and omega.contains(shapely.Point(0.0, 20.0))


# ----------------------------------------------------------------------------------------------------------------
# T19b: exact shadows (a tangent point beyond r_max must not hide the ground in front of the obstacle)


def _ray_visible(ego_xy: np.ndarray, pts: np.ndarray, occ: list[Polygon]) -> np.ndarray:
    """Brute force: a point is visible when it is in no occluder and its segment to the sensor meets no occluder."""
    inside = shapely.intersects(shapely.union_all(occ), shapely.points(pts)) if occ else np.zeros(len(pts), bool)
    return line_of_sight(ego_xy, pts, occ) & ~inside


def test_T19b_shadow_of_a_small_obstacle_and_of_a_building_reaching_past_r_max():
    ego = np.array([0.0, 0.0, 0.0])
    cfg = Sensor()  # r_max = 50 m
    small = box(29.0, -1.0, 31.0, 1.0)  # 2 m square at 30 m
    building = box(10.0, 45.0, 60.0, 75.0)  # seen obliquely: near corner at 46 m, both tangent corners at ~75 m
    occ = [small, building]
    obs = compute_obstacles([np.asarray(p.exterior.coords)[:-1] for p in occ], ["parked", "building"], ego[:2], 50.0)
    assert min(obs.r_min[1], obs.r_max[1]) > cfg.r_max  # both tangent points of the building lie beyond r_max
    scene = synthetic_scene(buildings=[], parked=occ)
    scene.sidewalk = box(-60, -60, 60, 60)
    omega = visible_region(scene, ego, obs, cfg)
    assert omega.contains(shapely.Point(28.0, 0.0)) and not omega.contains(shapely.Point(32.0, 0.0))
    assert omega.contains(shapely.Point(20.0, 44.0)) and not omega.contains(shapely.Point(20.0, 46.0))
    assert omega.contains(shapely.Point(8.0, 47.0))  # in front of the building's side face
    assert omega.contains(shapely.Point(33.0, 5.0))  # beside the small obstacle's cone
    assert not omega.contains(shapely.Point(11.0, 48.0))  # inside the building
    # the visible area equals a brute-force ray test on a 0.5 m grid to within 1 %
    g = np.arange(-59.75, 60.0, 0.5)
    pts = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    brute = fov_mask(pts, ego, cfg) & _ray_visible(ego[:2], pts, occ)
    assert omega.area == pytest.approx(brute.sum() * 0.25, rel=0.01)


def test_shadow_is_exactly_the_occluded_set_for_random_obstacles():
    """Random convex obstacles, many reaching past r_max: within r_max, a point is in obstacle-plus-shadow exactly
    when it is inside the obstacle or its segment to the sensor meets it (T19b, away from the boundary)."""
    rng = np.random.default_rng(7)
    ego = np.array([1.0, -2.0])
    tested = beyond = 0
    for _ in range(150):
        c = ego + rng.uniform(8, 60) * np.array([np.cos(a := rng.uniform(-np.pi, np.pi)), np.sin(a)])
        poly = shapely.convex_hull(shapely.multipoints(c + rng.normal(0, rng.uniform(0.5, 15), (6, 2))))
        if poly.intersects(shapely.Point(ego)) or poly.area < 0.1:
            continue
        obs = compute_obstacles([np.asarray(poly.exterior.coords)[:-1]], ["building"], ego, 50.0)
        if len(obs) == 0:
            continue
        beyond += bool(max(obs.r_min[0], obs.r_max[0]) > 50.0)
        shadow = shadow_polygons(ego, obs, 50.0)[0]
        pts = ego + rng.uniform(-50, 50, (2000, 2))
        pts = pts[np.hypot(*(pts - ego).T) < 50.0]
        away = shapely.distance(shadow.boundary, shapely.points(pts)) > 1e-3
        got = shapely.contains_xy(shadow, pts[:, 0], pts[:, 1])
        assert np.array_equal(got[away], ~_ray_visible(ego, pts, [poly])[away])
        tested += 1
    assert tested > 100 and beyond > 10


@pytest.mark.parametrize("net", ["intersection", "tjunction", "grid_block", "arterial"])
def test_visible_region_matches_a_brute_force_ray_test_on_the_shipped_scenes(net):
    """Omega_k on scans of every shipped scene agrees point by point with casting rays (T19b, SUMO scans)."""
    from soabench.scenario import load, simulate

    scene, scenario = load(net)
    seeds = trial_seeds(0, 0)
    rec = simulate(scene, scenario, seeds, duration=20.0)
    cfg = Sensor()
    scans = observe(rec, scene, cfg, seeds.sensor_rngs())
    rng = np.random.default_rng(0)
    checked = 0
    for k in range(0, len(scans), 4):
        scan = scans.scans[k]
        ego, occ = scan.ego, list(scan.occluders)
        bounds = scene.sidewalk.bounds
        cand = rng.uniform(bounds[:2], bounds[2:], (60000, 2))
        cand = cand[shapely.contains_xy(scene.sidewalk, cand[:, 0], cand[:, 1])]
        pts = cand[fov_mask(cand, ego, cfg)]
        brute = _ray_visible(ego[:2], pts, occ)
        got = shapely.contains_xy(scan.visible_region, pts[:, 0], pts[:, 1])
        near = shapely.distance(scan.visible_region.boundary, shapely.points(pts)) < 0.05
        assert np.array_equal(got[~near], brute[~near]), f"scan {k}: {np.sum(got[~near] != brute[~near])} points differ"
        checked += len(pts)
    assert checked > 5000
