"""Baseline birth models PUBM, UBM, ATBM, GMBM (docs/method.md §3.2-3.5; tests T18, T20, T21)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from shapely.geometry import MultiLineString, Polygon, box

from soabench.baselines.adaptive import AdaptiveBirth, newborn_likelihood, unexplained_mass
from soabench.baselines.partially_uniform import PartiallyUniformBirth
from soabench.baselines.standard_gm import StandardGMBirth, boundary_exits, entry_points
from soabench.baselines.uniform import UniformBirth, grid_nodes
from soabench.birth import get_birth_model
from soabench.birth.base import inside_any
from soabench.config import BirthConfig, Sensor
from soabench.geometry import clutter_intensity, fov_mask
from soabench.plugins import BUILTIN_BIRTH_MODELS
from soabench.scenario.scene import SceneMap
from soabench.types import SOURCE_GM, SOURCE_GRID, SOURCE_MEAS, BirthContext, Obstacles, Scan, StepResult


def make_scene(box_=(-50.0, -50.0, 120.0, 50.0)) -> SceneMap:
    """Intersection with 4 sidewalk lines crossing the world box (8 exits), 4 corner buildings, 2 doors."""
    W = box(*box_)
    lines = MultiLineString(
        [[(-60, 7.5), (130, 7.5)], [(-60, -7.5), (130, -7.5)], [(27.5, -60), (27.5, 60)], [(42.5, -60), (42.5, 60)]]
    ).intersection(W)
    sidewalk = lines.buffer(1.5, cap_style="flat")
    buildings = [box(-50, 10, 25, 50), box(45, 10, 120, 50), box(-50, -50, 25, -10), box(45, -50, 120, -10)]
    parked = [box(0, 3, 4.5, 5)]
    doors = np.array([[0.0, 7.5], [80.0, -7.5]])
    return SceneMap(
        "synthetic", W, sidewalk, Polygon(), Polygon(), box(-50, -6, 120, 6), buildings, parked, doors, lines
    )


def make_scan(scene: SceneMap, ego=(10.0, 0.0, 0.0), Z=None, k: int = 0, vehicles=()) -> Scan:
    e = np.asarray(ego, dtype=float)
    occ = [*scene.buildings, *scene.static_occluders, *[Polygon(v) for v in vehicles]]
    empty = Obstacles([], np.zeros(0, dtype=str), *(np.zeros(0) for _ in range(6)))
    Z = np.zeros((0, 2)) if Z is None else np.asarray(Z, dtype=float).reshape(-1, 2)
    return Scan(k, float(k), e, Z, empty, occ, Polygon())


def ctx(scan: Scan, prev=None, p_D_b: float = 0.98) -> BirthContext:
    return BirthContext(scan, prev, p_D_b)


def newborn_weight(births, A, kappa) -> np.ndarray:
    """The filter's newborn posterior weight beta_l / (kappa_l + A_l + beta_l) (§3.2, §3.4)."""
    beta = births.newborn.beta(np.asarray(A, dtype=float), np.asarray(kappa, dtype=float))
    return beta / (np.asarray(kappa) + np.asarray(A) + beta)


# ---------------------------------------------------------------------------------------------------------------------
# registry
# ---------------------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["soa", "pubm", "ubm", "atbm", "gmbm"])
def test_registry_constructs_every_model_and_returns_births(name):
    scene = make_scene()
    cls = get_birth_model(name)
    assert cls.name == name and name in BUILTIN_BIRTH_MODELS
    model = cls(BirthConfig(), Sensor(), scene, np.random.default_rng(0))
    scan = make_scan(scene, Z=[[10.0, 0.5]])
    scan.visible_region = scene.sidewalk.intersection(shapely.Point(10, 0).buffer(50))
    births = model(ctx(scan))
    assert births.m.shape == (len(births), 4) and births.P.shape == (len(births), 4, 4)
    assert len(births) > 0 or births.newborn is not None


# ---------------------------------------------------------------------------------------------------------------------
# PUBM (§3.2, T20)
# ---------------------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("lam, expected", [(3.0, 0.0192232), (0.5, 0.105225)])
def test_t20_pubm_isolated_measurement_weight(lam, expected):
    sensor = Sensor(r_min=0.0, lambda_c=lam)
    scene = make_scene()
    model = PartiallyUniformBirth(BirthConfig(), sensor, scene, np.random.default_rng(0))
    Z = np.array([[20.0, 0.0]])
    births = model(ctx(make_scan(scene, ego=(0.0, 0.0, 0.0), Z=Z)))
    assert len(births) == 0
    w = newborn_weight(births, [0.0], clutter_intensity(Z, sensor))
    assert w[0] == pytest.approx(expected, abs=1e-6)
    assert w[0] == pytest.approx(0.98 * 0.06 / (lam + 0.98 * 0.06), rel=1e-12)
    # position covariance J R J^T at bearing 0, r = 20: diag(1, 400 sigma_b^2) = diag(1, 3.0462)
    np.testing.assert_allclose(births.newborn.P[0, :2, :2], np.diag([1.0, 3.0462]), atol=1e-4)
    np.testing.assert_allclose(births.newborn.P[0, 2:, 2:], np.eye(2))
    np.testing.assert_allclose(births.newborn.m[0], [20.0, 0.0, 0.0, 0.0], atol=1e-12)


def test_pubm_inverse_measurement_uses_ego_pose():
    scene = make_scene()
    sensor = Sensor()
    model = PartiallyUniformBirth(BirthConfig(), sensor, scene, np.random.default_rng(0))
    births = model(ctx(make_scan(scene, ego=(5.0, -2.0, math.pi / 2), Z=[[10.0, -math.pi / 2], [4.0, 0.0]])))
    np.testing.assert_allclose(births.newborn.m[:, :2], [[15.0, -2.0], [5.0, 2.0]], atol=1e-12)


def test_pubm_cart_variant_and_empty_scan():
    scene = make_scene()
    sensor = Sensor(r_min=0.0)
    model = PartiallyUniformBirth(BirthConfig(pubm_space="cart"), sensor, scene, np.random.default_rng(0))
    Z = np.array([[20.0, 0.3], [40.0, -1.0]])
    births = model(ctx(make_scan(scene, Z=Z)))
    beta = births.newborn.beta(np.zeros(2), np.zeros(2))
    A = math.pi * 50.0**2
    np.testing.assert_allclose(beta, 0.98 * 0.06 * Z[:, 0] / A, rtol=1e-12)
    none = model(ctx(make_scan(scene)))
    assert none.newborn is None and len(none) == 0


def test_pubm_hybrid_adds_gm_components_with_eta_mass():
    scene = make_scene()
    eta = 0.25
    cfg = BirthConfig(pubm_hybrid=eta)
    sensor = Sensor(r_max=500.0)  # every entry point in range
    model = PartiallyUniformBirth(cfg, sensor, scene, np.random.default_rng(0))
    births = model(ctx(make_scan(scene, ego=(35.0, 0.0, 0.0), Z=[[10.0, 0.0]])))
    assert np.all(births.source == SOURCE_GM)
    assert births.w.sum() == pytest.approx(eta * cfg.N_hat, abs=1e-15)
    beta = births.newborn.beta(np.zeros(1), np.zeros(1))
    assert beta[0] == pytest.approx(0.98 * (1 - eta) * cfg.N_hat / ((500.0 - 0.5) * 2 * math.pi), rel=1e-12)


# ---------------------------------------------------------------------------------------------------------------------
# ATBM (§3.4, T21)
# ---------------------------------------------------------------------------------------------------------------------


def test_t21_atbm_isolated_measurement_weight():
    sensor = Sensor()
    assert newborn_likelihood(sensor) == pytest.approx(0.911891, abs=1e-6)
    scene = make_scene()
    model = AdaptiveBirth(BirthConfig(), sensor, scene, np.random.default_rng(0))
    Z = np.column_stack([np.linspace(5, 45, 9), np.linspace(-3, 3, 9)])  # M = 9: nu = 0.06 / 9
    births = model(ctx(make_scan(scene, Z=Z)))
    kappa = np.full(9, 0.0095493)
    w = newborn_weight(births, np.zeros(9), kappa)
    np.testing.assert_allclose(w, 0.384194, atol=1e-6)
    # a persistent component exactly at z_0 with w = 1: A_0 = p_D q with q = N(0; 0, S), S = R + J P J^T (P ~ R)
    q = 1.0 / (2 * math.pi * math.sqrt(np.linalg.det(2 * np.diag([1.0, sensor.sigma_b**2]))))
    A = np.zeros(9)
    A[0] = 0.98 * q
    assert newborn_weight(births, A, kappa)[0] < 0.01
    polar = Z[:, :1] * np.column_stack([np.cos(Z[:, 1]), np.sin(Z[:, 1])])
    np.testing.assert_allclose(births.newborn.m[:, :2], np.array([10.0, 0.0]) + polar, atol=1e-12)


def test_atbm_raw_mass_and_unexplained_allocation():
    scene = make_scene()
    sensor = Sensor()
    Z = np.array([[10.0, 0.0], [20.0, 1.0], [30.0, -1.0]])
    raw = AdaptiveBirth(BirthConfig(atbm_raw_mass=True), sensor, scene, np.random.default_rng(0))
    b = raw(ctx(make_scan(scene, Z=Z)))
    np.testing.assert_allclose(b.newborn.beta(np.zeros(3), np.full(3, 0.01)), 0.02, rtol=1e-12)
    un = AdaptiveBirth(BirthConfig(atbm_alloc="unexplained"), sensor, scene, np.random.default_rng(0))
    b = un(ctx(make_scan(scene, Z=Z)))
    kappa = np.full(3, 0.01)
    A = np.array([0.0, 0.01, 0.99])  # rho = 0, 0.5, 0.99
    nu = unexplained_mass(A, kappa, 0.06)
    np.testing.assert_allclose(nu, 0.06 * np.array([1.0, 0.5, 0.01]) / 1.51, rtol=1e-12)
    assert nu.sum() == pytest.approx(0.06, abs=1e-15)
    np.testing.assert_allclose(b.newborn.beta(A, kappa), 0.98 * newborn_likelihood(sensor) * nu, rtol=1e-12)
    assert unexplained_mass(np.ones(2), np.zeros(2), 0.06).sum() == 0.0  # all explained, no clutter: no birth


def _step(k: int, A, kappa) -> StepResult:
    """A StepResult at k carrying only what ATBM prev-scan reads (A, kappa)."""
    return StepResult(
        k=k,
        X=np.zeros((0, 4)),
        X_w=np.zeros(0),
        sum_w=0.0,
        sum_w_reduced=0.0,
        n_predicted=0,
        n_updated=0,
        n_reduced=0,
        cap_hit=False,
        t_predict=0.0,
        t_update=0.0,
        t_reduce=0.0,
        mean_pD=0.98,
        A=np.asarray(A, dtype=float),
        kappa=np.asarray(kappa, dtype=float),
    )


def test_atbm_prev_scan_appends_predicted_components_from_the_previous_scan():
    scene = make_scene()
    sensor = Sensor()
    cfg = BirthConfig(atbm="prev_scan")
    model = AdaptiveBirth(cfg, sensor, scene, np.random.default_rng(0))
    Z0 = np.array([[10.0, 0.0], [12.0, math.pi]])
    s0 = make_scan(scene, ego=(0.0, 0.0, 0.0), Z=Z0, k=0)
    assert len(model(ctx(s0, None))) == 0 and model(ctx(s0, None)).newborn is None
    s1 = make_scan(scene, ego=(2.0, 0.0, 0.0), Z=np.zeros((0, 2)), k=1)
    kappa = np.full(2, 0.01)
    b = model(ctx(s1, _step(0, [0.0, 0.01], kappa)))
    assert np.all(b.source == SOURCE_MEAS) and len(b) == 2
    np.testing.assert_allclose(b.w, 0.06 * np.array([1.0, 0.5]) / 1.5, rtol=1e-12)
    # mean from the k-1 ego pose, predicted with F (zero velocity: the position is unchanged)
    np.testing.assert_allclose(b.m[:, :2], [[10.0, 0.0], [-12.0, 0.0]], atol=1e-12)
    # P = F P0 F^T + Q: the position variance grows by dt^2 sigma_v^2 + sigma_a^2 dt^4 / 4
    assert b.P[0, 0, 0] == pytest.approx(1.0 + 1.0 + 0.25 * 0.25, rel=1e-12)
    assert b.P[0, 0, 2] == pytest.approx(1.0 + 0.25 * 0.5, rel=1e-12)
    assert b.newborn is None


# ---------------------------------------------------------------------------------------------------------------------
# UBM (§3.3, T18)
# ---------------------------------------------------------------------------------------------------------------------


def test_ubm_grid_of_the_paper_workspace():
    nodes = grid_nodes((-50.0, -50.0, 120.0, 50.0), 5.0)
    assert len(nodes) == 34 * 20 == 680
    np.testing.assert_allclose(nodes.min(axis=0), [-47.5, -47.5])
    np.testing.assert_allclose(nodes.max(axis=0), [117.5, 47.5])


@pytest.mark.parametrize("ego", [(10.0, 0.0, 0.0), (35.0, 0.0, 1.0), (110.0, 40.0, 2.0)])
def test_t18_ubm_mass_is_n_hat_after_the_fov_rule(ego):
    scene = make_scene()
    cfg, sensor = BirthConfig(), Sensor()
    model = UniformBirth(cfg, sensor, scene, np.random.default_rng(0))
    car = np.array([[15.0, -3.0], [19.5, -3.0], [19.5, -1.0], [15.0, -1.0]])
    scan = make_scan(scene, ego=ego, vehicles=(car,))
    births = model(ctx(scan))
    assert len(births) > 0 and np.all(births.source == SOURCE_GRID)
    assert births.w.sum() == pytest.approx(cfg.N_hat, abs=1e-12)
    xy = births.m[:, :2]
    assert fov_mask(xy, scan.ego, sensor, inset=cfg.delta_in).all()
    assert not inside_any(scan.occluders, xy).any()
    np.testing.assert_allclose(births.P[:, :2, :2], np.broadcast_to(2.5**2 * np.eye(2), (len(births), 2, 2)))
    # exactly the grid nodes that pass the rule
    nodes = grid_nodes(scene.bounds, cfg.d_u)
    ok = fov_mask(nodes, scan.ego, sensor, inset=cfg.delta_in) & ~inside_any(scan.occluders, nodes)
    assert len(births) == ok.sum()


def test_ubm_no_buildings_gives_about_pi_r2_over_du2_nodes():
    scene = make_scene(box_=(-100.0, -100.0, 100.0, 100.0))
    scene.buildings, scene.static_occluders = [], []
    births = UniformBirth(BirthConfig(), Sensor(), scene, np.random.default_rng(0))(
        ctx(make_scan(scene, ego=(0.0, 0.0, 0.0)))
    )
    assert abs(len(births) - math.pi * 49.5**2 / 25) < 15  # ~ 308 nodes within 49.5 m


# ---------------------------------------------------------------------------------------------------------------------
# GMBM (§3.5)
# ---------------------------------------------------------------------------------------------------------------------


def test_gmbm_components_derived_from_sidewalk_lines_and_doors():
    scene = make_scene()
    exits = boundary_exits(scene)
    expected = {
        (-50.0, 7.5), (-50.0, -7.5), (120.0, 7.5), (120.0, -7.5),
        (27.5, -50.0), (27.5, 50.0), (42.5, -50.0), (42.5, 50.0),
    }  # fmt: skip
    assert {tuple(np.round(p, 9)) for p in exits} == expected
    pts = entry_points(scene)
    assert len(pts) == 8 + 2
    np.testing.assert_allclose(pts[-2:], scene.doors)
    # another world box gives other exits: nothing typed in
    small = make_scene(box_=(0.0, -20.0, 60.0, 20.0))
    assert {tuple(np.round(p, 9)) for p in boundary_exits(small)} == {
        (0.0, 7.5), (0.0, -7.5), (60.0, 7.5), (60.0, -7.5),
        (27.5, -20.0), (27.5, 20.0), (42.5, -20.0), (42.5, 20.0),
    }  # fmt: skip


def test_gmbm_fixed_weights_skip_outside_fov_without_renormalising():
    scene = make_scene()
    cfg, sensor = BirthConfig(), Sensor()
    model = StandardGMBirth(cfg, sensor, scene, np.random.default_rng(0))
    assert model.J_GM == 10
    scan = make_scan(scene, ego=(-30.0, 0.0, 0.0))
    births = model(ctx(scan))
    # within 49.5 m of (-30, 0): the two west exits and the door at (0, 7.5)
    np.testing.assert_allclose(
        births.m[np.lexsort(births.m[:, :2].T[::-1]), :2], [[-50.0, -7.5], [-50.0, 7.5], [0.0, 7.5]]
    )
    np.testing.assert_allclose(births.w, cfg.N_hat / 10)
    assert births.w.sum() == pytest.approx(0.3 * cfg.N_hat)
    np.testing.assert_allclose(births.P[:, :2, :2], np.broadcast_to(9.0 * np.eye(2), (3, 2, 2)))
    wide = StandardGMBirth(cfg, Sensor(r_max=500.0), scene, np.random.default_rng(0))
    assert wide(ctx(make_scan(scene, ego=(35.0, 0.0, 0.0)))).w.sum() == pytest.approx(cfg.N_hat, abs=1e-15)
