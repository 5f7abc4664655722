"""S-OA birth model (docs/method.md §3.0-3.1; tests T12-T15, T18; paper eqs. 8-17) on small synthetic scenes."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import shapely
from shapely.geometry import MultiLineString, Point, Polygon, box

from soabench.birth import get_birth_model
from soabench.birth.base import FOVRule, build_components, inside_any
from soabench.birth.soa import SOABirth, combined_weights, dedup, ego_inside, occlusion_layers
from soabench.config import BirthConfig, Sensor
from soabench.geometry import fov_mask, range_bearing, wrap
from soabench.scenario.scene import SceneMap
from soabench.types import SOURCE_FOV, SOURCE_OCCL, SOURCE_SEM, BirthContext, Obstacles, Scan

# ---------------------------------------------------------------------------------------------------------------------
# synthetic scene and scans (the spec geometry of §3.1.2 written out here, independent of the sensor module)
# ---------------------------------------------------------------------------------------------------------------------


def make_scene() -> SceneMap:
    """A plus-shaped intersection in W = [-50, 120] x [-50, 50]: sidewalks, crossings, 4 corner buildings, 2 parked
    cars, 2 doors."""
    W = box(-50, -50, 120, 50)
    sidewalk = shapely.union_all(
        [box(-50, 6, 29, 9), box(41, 6, 120, 9), box(-50, -9, 29, -6), box(41, -9, 120, -6)]
        + [box(26, -50, 29, 50), box(41, -50, 44, 50)]
    )
    crossings = shapely.union_all([box(29, -9, 41, -6), box(29, 6, 41, 9)])
    buildings = [box(-50, 10, 25, 50), box(45, 10, 120, 50), box(-50, -50, 25, -10), box(45, -50, 120, -10)]
    parked = [box(0, 3, 4.5, 5), box(60, -5, 64.5, -3)]
    lines = MultiLineString(
        [[(-50, 7.5), (120, 7.5)], [(-50, -7.5), (120, -7.5)], [(27.5, -50), (27.5, 50)], [(42.5, -50), (42.5, 50)]]
    )
    doors = np.array([[0.0, 7.5], [80.0, -7.5]])
    return SceneMap(
        "synthetic", W, sidewalk, crossings, Polygon(), box(-50, -6, 120, 6), buildings, parked, doors, lines
    )


def tangent_geometry(poly: np.ndarray, e: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """§3.1.2 for one convex polygon: (r'_c, alpha_c, theta_min, theta_max, r_b_min, r_b_max)."""
    c = np.asarray(Polygon(poly).centroid.coords[0])
    alpha_c = math.atan2(c[1] - e[1], c[0] - e[0])
    d = poly - e
    delta = wrap(np.arctan2(d[:, 1], d[:, 0]) - alpha_c)
    i0, i1 = int(np.argmin(delta)), int(np.argmax(delta))
    r = np.hypot(d[:, 0], d[:, 1])
    return (
        float(np.hypot(*(c - e))),
        alpha_c,
        float(wrap(alpha_c + delta[i0])),
        float(wrap(alpha_c + delta[i1])),
        float(r[i0]),
        float(r[i1]),
    )


def make_obstacles(polys: list[np.ndarray], kinds: list[str], e: np.ndarray, r_max: float = 50.0) -> Obstacles:
    """O_k: every polygon intersecting the r_max disk and not containing the sensor (§3.1.1)."""
    keep = [
        i for i, p in enumerate(polys) if Polygon(p).distance(Point(e)) <= r_max and not Polygon(p).intersects(Point(e))
    ]
    rows = np.array([tangent_geometry(np.asarray(polys[i], dtype=float), e) for i in keep]).reshape(-1, 6)
    return Obstacles(
        polygons=[np.asarray(polys[i], dtype=float) for i in keep],
        kind=np.array([kinds[i] for i in keep], dtype=str),
        centroid_range=rows[:, 0],
        centroid_bearing=rows[:, 1],
        theta_min=rows[:, 2],
        theta_max=rows[:, 3],
        r_min=rows[:, 4],
        r_max=rows[:, 5],
    )


def box_xy(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def make_scan(
    scene: SceneMap,
    ego=(10.0, 0.0, 0.0),
    vehicles: tuple[np.ndarray, ...] = (),
    sensor: Sensor | None = None,
    k: int = 0,
    Z: np.ndarray | None = None,
) -> Scan:
    """A scan at ``ego`` with the scene's buildings, parked cars and ``vehicles`` as occluders; Omega_k is the
    sidewalk in the FOV minus the occluders and their shadows (clipped by a line-of-sight grid-free construction)."""
    sensor = sensor or Sensor()
    e = np.asarray(ego, dtype=float)
    polys = [np.asarray(p.exterior.coords)[:-1] for p in [*scene.buildings, *scene.static_occluders]]
    polys += [np.asarray(v, dtype=float) for v in vehicles]
    kinds = ["building"] * len(scene.buildings) + ["parked"] * len(scene.static_occluders) + ["vehicle"] * len(vehicles)
    obs = make_obstacles(polys, kinds, e[:2], sensor.r_max)
    occluders = [Polygon(p) for p in polys]
    # obstacle + shadow = convex hull of its vertices and their far projections
    shadows = [
        shapely.convex_hull(shapely.multipoints(np.concatenate([p, e[:2] + 1e3 * (p - e[:2])]))) for p in obs.polygons
    ]
    disc = Point(e[:2]).buffer(sensor.r_max, quad_segs=64)
    omega = scene.sidewalk.intersection(disc).difference(shapely.union_all([*shadows, *occluders]))
    return Scan(k, float(k), e, np.zeros((0, 2)) if Z is None else Z, obs, occluders, omega)


CAR = box_xy(15.0, -3.0, 19.5, -1.0)


def soa(cfg: BirthConfig | None = None, sensor: Sensor | None = None, seed: int = 1, scene=None) -> SOABirth:
    return SOABirth(cfg or BirthConfig(), sensor or Sensor(), scene or make_scene(), np.random.default_rng(seed))


def check_rule(births, scan: Scan, scene: SceneMap, sensor: Sensor, cfg: BirthConfig) -> None:
    """Every birth mean in FOV_k (inset delta_in), in the workspace, not inside a building or occluder."""
    xy = births.m[:, :2]
    assert fov_mask(xy, scan.ego, sensor, inset=cfg.delta_in).all()
    x0, y0, x1, y1 = scene.bounds
    assert ((xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)).all()
    assert not inside_any([*scene.buildings, *scene.static_occluders, *scan.occluders], xy).any()


# ---------------------------------------------------------------------------------------------------------------------
# shared builder and FOV rule (§3.0)
# ---------------------------------------------------------------------------------------------------------------------


def test_build_components_blocks():
    p = np.array([[1.0, 2.0], [3.0, 4.0]])
    P_p = np.array([[[2.0, 0.5], [0.5, 1.0]], [[3.0, 0.0], [0.0, 3.0]]])
    m, P = build_components(p, P_p, 1.5, v=np.array([[0.1, 0.2], [0.0, 0.0]]))
    assert m.shape == (2, 4) and P.shape == (2, 4, 4)
    np.testing.assert_array_equal(m[0], [1.0, 2.0, 0.1, 0.2])
    np.testing.assert_array_equal(P[0, :2, :2], P_p[0])
    np.testing.assert_array_equal(P[:, 2:, 2:], np.broadcast_to(2.25 * np.eye(2), (2, 2, 2)))
    np.testing.assert_array_equal(P[:, :2, 2:], 0.0)


def test_fov_rule_drops_outside_fov_workspace_buildings_and_occluders():
    scene = make_scene()
    sensor = Sensor()
    scan = make_scan(scene, vehicles=(CAR,))
    rule = FOVRule(BirthConfig(), sensor, scene)
    pts = np.array(
        [
            [20.0, 7.0],  # sidewalk, in range: passes
            [10.3, 0.0],  # r = 0.3 < r_min + delta_in
            [10.0, 49.8],  # r = 49.8 > r_max - delta_in (and inside a building)
            [-49.0, 0.0],  # r = 59 > r_max
            [0.0, 30.0],  # inside a building
            [2.0, 4.0],  # inside a parked car
            [17.0, -2.0],  # inside the vehicle of this scan
        ]
    )
    np.testing.assert_array_equal(rule.mask(pts, scan), [True, False, False, False, False, False, False])
    far = make_scan(scene, ego=(100.0, 0.0, 0.0))
    assert not rule.mask(np.array([[125.0, 0.0]]), far)[0]  # in range but outside the workspace


# ---------------------------------------------------------------------------------------------------------------------
# occlusion layers (T12-T15)
# ---------------------------------------------------------------------------------------------------------------------


def _single(theta_min, theta_max, r_b, poly, centroid_range=None) -> Obstacles:
    return Obstacles(
        [np.asarray(poly, dtype=float)],
        np.array(["parked"]),
        np.array([centroid_range if centroid_range is not None else r_b]),
        np.array([0.5 * (theta_min + theta_max)]),
        np.array([theta_min]),
        np.array([theta_max]),
        np.array([r_b]),
        np.array([r_b]),
    )


def test_t12_circle_first_layer_at_tangent_range_plus_delta_r():
    a = math.asin(0.1)
    assert math.degrees(a) == pytest.approx(5.7392, abs=1e-4)
    r_b = math.sqrt(99.0)
    assert r_b == pytest.approx(9.94987, abs=1e-5)
    circle = np.column_stack(
        [
            10 + np.cos(np.linspace(0, 2 * np.pi, 64, endpoint=False)),
            np.sin(np.linspace(0, 2 * np.pi, 64, endpoint=False)),
        ]
    )
    cfg = BirthConfig()
    p, P_p, v, r = occlusion_layers(_single(-a, a, r_b, circle), np.zeros(3), cfg)
    assert len(p) == 2 * cfg.L
    p = p.reshape(2, cfg.L, 2)
    for b, th in enumerate((-a, a)):
        expected = (r_b + cfg.delta_r * np.arange(1, cfg.L + 1))[:, None] * np.array([math.cos(th), math.sin(th)])
        np.testing.assert_allclose(p[b], expected, atol=1e-9)
        np.testing.assert_allclose(np.hypot(*p[b, 0]), r_b + cfg.delta_r, atol=1e-9)
    np.testing.assert_array_equal(v, 0.0)


def test_t13_box_rays_and_layer_covariance_eigenvectors():
    e = np.zeros(3)
    poly = box_xy(9, -1, 11, 1)
    rc, ac, th_min, th_max, rb_min, rb_max = tangent_geometry(poly, e[:2])
    assert math.degrees(th_max) == pytest.approx(6.3402, abs=1e-4)
    assert math.degrees(th_min) == pytest.approx(-6.3402, abs=1e-4)
    assert rb_min == pytest.approx(math.sqrt(82), abs=1e-12) and rb_max == pytest.approx(9.05539, abs=1e-5)
    cfg = BirthConfig()
    obs = make_obstacles([poly], ["parked"], e[:2])
    p, P_p, _, r = occlusion_layers(obs, e, cfg)
    np.testing.assert_allclose(r.reshape(2, cfg.L)[:, 0], math.sqrt(82) + cfg.delta_r, atol=1e-9)
    for j, th in enumerate(np.repeat([th_min, th_max], cfg.L)):
        u = np.array([math.cos(th), math.sin(th)])
        u_perp = np.array([-math.sin(th), math.cos(th)])
        np.testing.assert_allclose(P_p[j] @ u, cfg.sigma_par**2 * u, atol=1e-12)
        np.testing.assert_allclose(P_p[j] @ u_perp, cfg.sigma_perp**2 * u_perp, atol=1e-12)
        evals = np.linalg.eigvalsh(P_p[j])
        np.testing.assert_allclose(evals, [cfg.sigma_perp**2, cfg.sigma_par**2], atol=1e-12)
        # the mean lies on the ray theta_b
        np.testing.assert_allclose(math.atan2(p[j, 1], p[j, 0]), th, atol=1e-12)


def test_t14_wrap_around_box_and_velocity_prior_points_out_of_the_cone():
    e = np.zeros(3)
    poly = box_xy(-11, -1, -9, 1)
    obs = make_obstacles([poly], ["parked"], e[:2])
    assert math.degrees(obs.theta_min[0]) == pytest.approx(173.66, abs=5e-3)
    assert math.degrees(obs.theta_max[0]) == pytest.approx(-173.66, abs=5e-3)
    width = math.degrees(wrap(obs.theta_max[0] - obs.theta_min[0]))
    assert width == pytest.approx(12.68, abs=5e-3)
    cfg = BirthConfig(occl_velocity_prior=True)
    p, _, v, _ = occlusion_layers(obs, e, cfg)
    _, bearing = range_bearing(p, e)
    np.testing.assert_allclose(wrap(bearing - np.repeat([obs.theta_min[0], obs.theta_max[0]], cfg.L)), 0.0, atol=1e-12)
    assert np.all(p[:, 0] < -9.0)  # behind the box, on the far side through +-pi
    np.testing.assert_allclose(np.hypot(v[:, 0], v[:, 1]), 0.8)
    # moving along v leaves the cone: the bearing of p + v is outside [theta_min, theta_max] (through pi)
    _, b_out = range_bearing(p + v, e)
    inside = np.abs(wrap(b_out - math.pi)) <= math.radians(6.34)
    assert not inside.any()


def test_t15_ego_inside_obstacle_and_obstacle_beyond_range_give_nothing():
    cfg = BirthConfig()
    poly = box_xy(-1, -1, 1, 1)
    assert ego_inside([poly, box_xy(9, -1, 11, 1), poly[::-1]], np.zeros(2)).tolist() == [True, False, True]
    p, *_ = occlusion_layers(_single(-0.5, 0.5, 0.5, poly), np.zeros(3), cfg)
    assert len(p) == 0
    scene = make_scene()
    model = soa(cfg, scene=scene)
    scan = make_scan(scene, ego=(10.0, 0.0, 0.0))
    far = box_xy(70, -1, 72, 1)
    scan.obstacles = make_obstacles([far], ["vehicle"], scan.ego[:2], r_max=100.0)  # tangent range 60 > r_max
    births = model(BirthContext(scan, None))
    assert not np.any(births.source == SOURCE_OCCL)
    assert births.w.sum() == pytest.approx(cfg.N_hat, abs=1e-12)


def test_ray_start_centroid_uses_centroid_range():
    e = np.zeros(3)
    obs = make_obstacles([box_xy(9, -1, 11, 1)], ["parked"], e[:2])
    cfg = BirthConfig(ray_start="centroid")
    _, _, _, r = occlusion_layers(obs, e, cfg)
    np.testing.assert_allclose(r.reshape(2, cfg.L)[:, 0], 10.0 + cfg.delta_r, atol=1e-12)


def test_dedup_greedy_keeps_one_of_each_close_pair():
    xy = np.array([[0.0, 0.0], [0.5, 0.0], [5.0, 0.0], [5.9, 0.0], [6.8, 0.0]])
    keep = dedup(xy, 1.0)
    assert keep.tolist() == [True, False, True, False, True]  # 6.8 stays: its only close neighbour was dropped


def test_adjacent_cars_sharing_a_ray_are_deduplicated():
    scene = make_scene()
    car2 = box_xy(19.5, -3.0, 24.0, -1.0)  # bumper to bumper with CAR: same lower tangent ray direction region
    scan = make_scan(scene, vehicles=(CAR, car2))
    cfg = BirthConfig()
    births = soa(cfg, scene=scene)(BirthContext(scan, None))
    occ = births.m[births.source == SOURCE_OCCL, :2]
    assert len(occ) > 0
    d = np.hypot(*(occ[:, None, :] - occ[None, :, :]).transpose(2, 0, 1))
    assert d[np.triu_indices(len(occ), 1)].min() >= 0.5 * cfg.delta_r


def test_occlusion_layers_start_behind_their_obstacle():
    scene = make_scene()
    scan = make_scan(scene, vehicles=(CAR,))
    cfg = BirthConfig()
    p, _, _, r = occlusion_layers(scan.obstacles, scan.ego, cfg)
    rb = np.repeat(np.column_stack([scan.obstacles.r_min, scan.obstacles.r_max]), cfg.L, axis=1).ravel()
    np.testing.assert_allclose(r - rb, np.tile(cfg.delta_r * np.arange(1, cfg.L + 1), 2 * len(scan.obstacles)))
    # none of the layer means is inside its own obstacle
    owner = np.repeat(np.arange(len(scan.obstacles)), 2 * cfg.L)
    for j, poly in enumerate(scan.obstacles.polygons):
        assert not shapely.contains_xy(Polygon(poly), p[owner == j, 0], p[owner == j, 1]).any()


# ---------------------------------------------------------------------------------------------------------------------
# the whole model: mass, FOV rule, semantic clipping, FOV ring, options (T18)
# ---------------------------------------------------------------------------------------------------------------------

POSES = [(10.0, 0.0, 0.0), (35.0, 0.0, 1.0), (35.0, 30.0, -2.0), (100.0, -7.5, 3.1), (-45.0, 7.0, 0.3)]


@pytest.mark.parametrize("ego", POSES)
def test_t18_mass_is_n_hat_and_every_mean_passes_the_fov_rule(ego):
    scene = make_scene()
    cfg, sensor = BirthConfig(), Sensor()
    scan = make_scan(scene, ego=ego, vehicles=(CAR,))
    births = soa(cfg, sensor, scene=scene)(BirthContext(scan, None))
    assert len(births) > 0
    assert births.w.sum() == pytest.approx(cfg.N_hat, abs=1e-12)
    np.testing.assert_allclose(births.w, cfg.N_hat / len(births), rtol=1e-12)  # rho = (1, 1, 1): equal weights
    check_rule(births, scan, scene, sensor, cfg)
    sem = births.m[births.source == SOURCE_SEM, :2]
    assert shapely.contains_xy(scan.visible_region, sem[:, 0], sem[:, 1]).all()
    np.testing.assert_array_equal(births.m[:, 2:], 0.0)
    np.testing.assert_allclose(births.P[:, 2:, 2:], np.broadcast_to(np.eye(2), (len(births), 2, 2)))


def test_t18_source_confidences_double_occlusion_weights():
    scene = make_scene()
    scan = make_scan(scene, vehicles=(CAR,))
    cfg = BirthConfig(rho=(2.0, 1.0, 1.0))
    births = soa(cfg, scene=scene)(BirthContext(scan, None))
    w_o = births.w[births.source == SOURCE_OCCL]
    w_s = births.w[births.source == SOURCE_SEM]
    w_f = births.w[births.source == SOURCE_FOV]
    assert len(w_o) and len(w_s) and len(w_f)
    np.testing.assert_allclose(w_o, 2.0 * w_s[0], rtol=1e-12)
    np.testing.assert_allclose(w_f, w_s[0], rtol=1e-12)
    assert births.w.sum() == pytest.approx(cfg.N_hat, abs=1e-12)


def test_combined_weights_component_and_source_normalisation():
    src = np.array([0, 0, 1, 1, 1, 1, 2])
    w = combined_weights(src, (1.0, 1.0, 2.0), 0.06, "component")
    np.testing.assert_allclose(w, 0.06 * np.array([1, 1, 1, 1, 1, 1, 2]) / 8)
    w = combined_weights(src, (1.0, 1.0, 2.0), 0.06, "source")
    np.testing.assert_allclose([w[src == s].sum() for s in range(3)], [0.015, 0.015, 0.03])
    w = combined_weights(np.array([1, 1]), (1.0, 1.0, 2.0), 0.06, "source")  # only one source present: all of N_hat
    assert w.sum() == pytest.approx(0.06, abs=1e-15)
    assert combined_weights(np.array([0, 0]), (0.0, 1.0, 1.0), 0.06, "component").sum() == 0.0


def test_fov_ring_has_world_frame_phase_and_count():
    scene = make_scene()
    cfg, sensor = BirthConfig(), Sensor()
    model = soa(cfg, sensor, scene=scene)
    n_fov = math.floor(2 * math.pi * (sensor.r_max - cfg.sigma_fov) / cfg.d_fov)
    assert len(model.fov_local) == n_fov
    scans = [make_scan(scene, ego=(35.0, 0.0, th)) for th in (0.0, 1.3)]
    rings = [model.fov_boundary(s) for s in scans]
    np.testing.assert_allclose(rings[0], rings[1])  # the phase does not follow the ego heading
    r, b = range_bearing(rings[0], np.array([35.0, 0.0, 0.0]))
    np.testing.assert_allclose(r, sensor.r_max - cfg.sigma_fov)
    np.testing.assert_allclose(np.sort(wrap(b)), np.sort(wrap(2 * np.pi * np.arange(n_fov) / n_fov)), atol=1e-12)


def test_sector_fov_births_stay_in_the_sector():
    scene = make_scene()
    cfg, sensor = BirthConfig(), Sensor(fov_deg=120.0)
    for ego in [(10.0, 0.0, 0.0), (35.0, 0.0, 2.5), (35.0, 20.0, -1.6)]:
        scan = make_scan(scene, ego=ego, vehicles=(CAR,), sensor=sensor)
        births = soa(cfg, sensor, scene=scene)(BirthContext(scan, None))
        assert np.any(births.source == SOURCE_FOV)
        check_rule(births, scan, scene, sensor, cfg)
        assert births.w.sum() == pytest.approx(cfg.N_hat, abs=1e-12)


def test_same_seed_same_components_other_seed_other_semantic_points():
    scene = make_scene()
    scan = make_scan(scene, vehicles=(CAR,))
    a = soa(seed=7, scene=scene)(BirthContext(scan, None))
    b = soa(seed=7, scene=scene)(BirthContext(scan, None))
    c = soa(seed=8, scene=scene)(BirthContext(scan, None))
    for f in ("w", "m", "P", "source"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert not np.array_equal(a.m[a.source == SOURCE_SEM], c.m[c.source == SOURCE_SEM])


def test_poisson_points_are_sampled_once_and_clipped_per_step():
    scene = make_scene()
    model = soa(scene=scene)
    pts = model.sem_pts.copy()
    assert shapely.contains_xy(scene.sidewalk, pts[:, 0], pts[:, 1]).all()
    for ego in POSES[:3]:
        births = model(BirthContext(make_scan(scene, ego=ego), None))
        sem = births.m[births.source == SOURCE_SEM, :2]
        # every semantic mean is one of the trial's points (a subset keeps eq. 14)
        assert np.all(np.min(np.hypot(*(sem[:, None, :] - pts[None]).transpose(2, 0, 1)), axis=1) == 0.0)
    np.testing.assert_array_equal(model.sem_pts, pts)


@pytest.mark.parametrize(
    "overrides",
    [
        {"sem_mode": "hex"},
        {"sem_mode": "uniform"},
        {"sem_mode": "dbscan"},
        {"sem_mode": "dbscan", "dbscan_split": True},
        {"sem_resample": "step"},
        {"sem_include_crossings": True},
        {"sem_include_crossings": True, "sem_mode": "uniform"},
        {"fov_boundary": "visible"},
        {"occluders_from_detections": True},
        {"occl_velocity_prior": True},
        {"rho_norm": "source", "rho": (3.0, 1.0, 0.5)},
    ],
)
def test_options_keep_mass_and_fov_rule(overrides):
    scene = make_scene()
    cfg, sensor = BirthConfig(**overrides), Sensor()
    model = soa(cfg, sensor, scene=scene)
    for k, ego in enumerate(POSES[:3]):
        scan = make_scan(scene, ego=ego, vehicles=(CAR,), k=k)
        births = model(BirthContext(scan, None))
        assert len(births) > 0
        assert births.w.sum() == pytest.approx(cfg.N_hat, abs=1e-12)
        check_rule(births, scan, scene, sensor, cfg)
        assert set(np.unique(births.source)) <= {SOURCE_OCCL, SOURCE_SEM, SOURCE_FOV}


def test_hex_semantic_means_respect_d_min():
    scene = make_scene()
    cfg = BirthConfig(sem_mode="hex")
    births = soa(cfg, scene=scene)(BirthContext(make_scan(scene, ego=(35.0, 0.0, 0.0)), None))
    sem = births.m[births.source == SOURCE_SEM, :2]
    assert len(sem) > 5
    d = np.hypot(*(sem[:, None, :] - sem[None]).transpose(2, 0, 1))
    assert d[np.triu_indices(len(sem), 1)].min() >= cfg.d_min - 1e-9


def test_crossings_option_adds_semantic_means_on_crossings():
    scene = make_scene()
    scan = make_scan(scene, ego=(35.0, 0.0, 0.0))
    base = soa(BirthConfig(sem_mode="hex"), scene=scene)(BirthContext(scan, None))
    plus = soa(BirthConfig(sem_mode="hex", sem_include_crossings=True), scene=scene)(BirthContext(scan, None))
    on_x = lambda b: shapely.contains_xy(scene.crossings, *b.m[b.source == SOURCE_SEM, :2].T).sum()  # noqa: E731
    assert on_x(base) == 0 and on_x(plus) > 0


def test_visible_fov_boundary_stops_at_occluders():
    scene = make_scene()
    cfg = BirthConfig(fov_boundary="visible")
    scan = make_scan(scene, ego=(10.0, 0.0, 0.0))
    pts = soa(cfg, scene=scene).fov_boundary(scan)
    r, _ = range_bearing(pts, scan.ego)
    assert r.max() <= 50.0 - cfg.sigma_fov + 1e-9
    assert r.min() < 20.0  # the boundary follows the building fronts at y = +-10


def test_occluders_from_detections_drops_hidden_obstacles():
    scene = make_scene()
    hidden = box_xy(26.0, -3.0, 27.0, -2.5)  # small box right behind CAR, inside its shadow
    scan = make_scan(scene, vehicles=(CAR, hidden))
    n_obs = len(scan.obstacles)
    all_ = soa(BirthConfig(), scene=scene).occlusion(scan)[0]
    det = soa(BirthConfig(occluders_from_detections=True), scene=scene).occlusion(scan)[0]
    assert n_obs >= 3 and len(det) < len(all_)
    # the remaining layers are exactly those of the visible obstacles: none along the hidden box's rays
    k = [i for i in range(n_obs) if np.allclose(scan.obstacles.polygons[i], hidden)][0]
    th = [scan.obstacles.theta_min[k], scan.obstacles.theta_max[k]]
    _, b = range_bearing(det, scan.ego)
    assert not np.any(np.isclose(wrap(b[:, None] - np.array(th)[None]), 0.0, atol=1e-12))


def test_registry_builds_soa():
    cls = get_birth_model("soa")
    assert cls is SOABirth and cls.name == "soa"


def test_no_obstacles_and_ego_far_outside_still_consistent():
    scene = dataclasses.replace(make_scene(), buildings=[], static_occluders=[])
    cfg = BirthConfig()
    scan = make_scan(scene, ego=(300.0, 300.0, 0.0))  # the FOV misses the workspace entirely
    births = soa(cfg, scene=scene)(BirthContext(scan, None))
    assert len(births) == 0 and births.w.sum() == 0.0
