"""Omega_k built only when read (soabench.sensor.VisibleRegion): the deferred region reads as the same polygon as
before, and its point test (Scan.in_visible_region, what S-OA asks) agrees with that polygon away from rounding
distance of its boundary, on scans of every shipped scene and on FOV sectors and annuli."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest
import shapely

from soabench.config import Sensor
from soabench.seeding import trial_seeds
from soabench.sensor import VisibleRegion, observe, segment_meets_convex, visible_region
from soabench.types import DeferredRegion, Obstacles, Scan


@pytest.fixture(scope="module")
def recordings():
    from soabench.scenario import load, simulate

    out = {}
    for net in ("intersection", "tjunction"):
        scene, scenario = load(net)
        seeds = trial_seeds(0, 3)
        out[net] = (scene, simulate(scene, scenario, seeds, duration=20.0), seeds)
    return out


def _deferred(scan: Scan) -> DeferredRegion:
    value = scan.__dict__["_visible_region"]
    assert isinstance(value, VisibleRegion)
    return value


@pytest.mark.parametrize("net", ["intersection", "tjunction"])
@pytest.mark.parametrize(("fov_deg", "r_min"), [(360.0, 0.5), (360.0, 0.0), (120.0, 0.0), (90.0, 3.0)])
def test_point_test_agrees_with_the_built_polygon(recordings, net, fov_deg, r_min):
    """Random points over and around the FOV, and points 1e-6 m either side of every vertex of the built polygon:
    the deferred test and contains_xy on the polygon give the same answer for each one."""
    scene, rec, seeds = recordings[net]
    cfg = dataclasses.replace(Sensor(), fov_deg=fov_deg, r_min=r_min)
    scans = observe(rec, scene, cfg, seeds.sensor_rngs())
    rng = np.random.default_rng(1)
    tested = inside = 0
    for scan in scans.scans[::2]:
        region = _deferred(scan)
        omega = region.build()
        pts = scan.ego[:2] + rng.uniform(-1.05 * cfg.r_max, 1.05 * cfg.r_max, (6000, 2))
        pts = np.concatenate([pts[:2000], pts[shapely.contains_xy(scene.sidewalk, pts[:, 0], pts[:, 1])]])
        verts = shapely.get_coordinates(omega.boundary) if not omega.is_empty else np.zeros((0, 2))
        if len(verts):
            step = rng.normal(size=(len(verts), 2))
            step *= 1e-6 / np.hypot(step[:, 0], step[:, 1])[:, None]
            pts = np.concatenate([pts, verts + step, verts - step])
        ref = shapely.contains_xy(omega, pts[:, 0], pts[:, 1])
        got = scan.in_visible_region(pts)
        assert np.array_equal(got, ref), f"scan {scan.k}: {int(np.sum(got != ref))} of {len(pts)} points differ"
        tested += len(pts)
        inside += int(ref.sum())
    assert tested > 20000 and inside > 300


def test_built_region_is_the_eager_one_and_reading_does_not_change_the_point_test(recordings):
    scene, rec, seeds = recordings["intersection"]
    cfg = Sensor()
    scans = observe(rec, scene, cfg, seeds.sensor_rngs())
    scan = scans.scans[7]
    region = _deferred(scan)
    pts = scan.ego[:2] + np.random.default_rng(2).uniform(-50, 50, (2000, 2))
    before = scan.in_visible_region(pts)
    assert "_built" not in region.__dict__  # the point test did not build the polygon
    inside = [g for g in scan.occluders if g.intersects(shapely.points(scan.ego[:2]))]
    eager = visible_region(scene, scan.ego, scan.obstacles, cfg, occluders=inside)
    assert shapely.to_wkb(scan.visible_region) == shapely.to_wkb(eager)  # bit for bit
    assert scan.visible_region is scan.visible_region  # built once, kept
    assert np.array_equal(scan.in_visible_region(pts), before)
    copy = pickle.loads(pickle.dumps(scan))
    assert isinstance(copy.__dict__["_visible_region"], VisibleRegion)
    assert np.array_equal(copy.in_visible_region(pts), before)
    assert shapely.equals_exact(copy.visible_region, eager, 0.0)


def test_a_geometry_given_directly_is_read_and_tested_as_is():
    box = shapely.box(0.0, 0.0, 2.0, 1.0)
    scan = Scan(0, 0.0, np.zeros(3), np.zeros((0, 2)), Obstacles.empty(), [], box)
    assert scan.visible_region is box
    got = scan.in_visible_region(np.array([[1.0, 0.5], [3.0, 0.5], [0.0, 0.5]]))
    assert got.tolist() == [True, False, False]  # interior only, as shapely.contains_xy
    with pytest.raises(TypeError, match="visible_region"):
        Scan(0, 0.0, np.zeros(3), np.zeros((0, 2)), Obstacles.empty(), [])  # still a required field


def test_segment_meets_convex_known_answers():
    square = np.array([[2.0, -1.0], [4.0, -1.0], [4.0, 1.0], [2.0, 1.0]])  # counter-clockwise
    ego = np.zeros(2)
    pts = np.array(
        [
            [1.0, 0.0],  # in front of the obstacle
            [3.0, 0.0],  # inside it
            [10.0, 0.0],  # behind it
            [10.0, 6.0],  # beside it: the segment passes above the corner (2, 1)
            [10.0, 5.0],  # the segment passes through the corner (2, 1): touching counts (closed)
            [2.0, 1.0],  # on a vertex
            [-5.0, 0.0],  # behind the sensor
            [0.0, 0.0],  # at the sensor
        ]
    )
    got = segment_meets_convex(ego, pts, [square])
    assert got.tolist() == [False, True, True, False, True, True, False, False]
    assert segment_meets_convex(ego, pts, []).tolist() == [False] * len(pts)
    assert segment_meets_convex(ego, np.zeros((0, 2)), [square]).shape == (0,)


def test_segment_meets_convex_matches_shapely_on_random_hulls():
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(200):
        hull = shapely.orient_polygons(shapely.convex_hull(shapely.multipoints(rng.uniform(-3, 3, (7, 2)) + (8, 0))))
        poly = shapely.get_coordinates(hull)[:-1]
        ego = rng.uniform(-2, 2, 2)
        if shapely.intersects(hull, shapely.points(ego)):
            continue
        pts = rng.uniform(-15, 15, (300, 2))
        lines = shapely.linestrings(np.stack([np.broadcast_to(ego, pts.shape), pts], axis=1))
        ref = shapely.intersects(lines, hull)
        away = shapely.distance(lines, shapely.get_exterior_ring(hull)) > 1e-9
        away |= shapely.distance(hull, lines) > 1e-9
        got = segment_meets_convex(ego, pts, [poly])
        assert np.array_equal(got[away], ref[away])
        checked += int(away.sum())
    assert checked > 40000
