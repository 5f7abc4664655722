"""The compiled line-of-sight test (soabench.sensor.SightBlockers, soabench.geometry_kernels.sight_blocked) gives
GEOS's decisions bit for bit (method §2.3, §4.4): random scenes and the degenerate ones certified signs cannot
decide (tangent rays through vertices, ends on core edges and vertices, sight lines along edges, the sensor on a
boundary or in a hole, cores that split or vanish, zero-length and non-finite segments). Every comparison is ``==``
on every element against :func:`soabench.sensor._line_of_sight_reference` (GEOS alone) with its own blockers."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import shapely
from shapely import affinity

from soabench import sensor
from soabench.geometry_kernels import UNSURE, _orient, sight_blocked, sight_polygons
from soabench.sensor import SIGHT_TOL, _line_of_sight_reference, line_of_sight, line_of_sight_past, sight_blockers


@pytest.fixture(autouse=True)
def _always_compiled(monkeypatch):
    """Every line through the compiled test, however few (a pose's first few lines otherwise go to GEOS alone)."""
    monkeypatch.setattr(sensor, "FEW_SIGHT_LINES", 0)


def _compare(ego, pts, occ) -> int:
    """Assert the compiled decisions equal GEOS's; return the (line, occluder) pairs that went to GEOS."""
    ego = np.asarray(ego, dtype=float)
    pts = np.asarray(pts, dtype=float).reshape(-1, 2)
    fast = sight_blockers(ego, occ)
    got = line_of_sight_past(ego, pts, fast)
    want = _line_of_sight_reference(ego, pts, sight_blockers(ego, occ))
    assert got.dtype == want.dtype == bool and got.shape == want.shape
    bad = np.flatnonzero(got != want)
    assert not len(bad), f"ego {ego.tolist()}, targets {pts[bad[:5]].tolist()}: {got[bad[:5]]} != {want[bad[:5]]}"
    return fast.fallback_pairs


def _random_polygon(rng: np.random.Generator) -> shapely.Polygon:
    """A rotated box, an L-shaped block or a star-shaped (non-convex) polygon."""
    c = rng.uniform(-40.0, 40.0, 2)
    kind = rng.integers(3)
    if kind == 0:
        g = shapely.box(*(c - rng.uniform(0.3, 3.0, 2)), *(c + rng.uniform(0.3, 3.0, 2)))
    elif kind == 1:
        g = shapely.Polygon(np.array([[0.0, 0], [8, 0], [8, 3], [3, 3], [3, 9], [0, 9]]) + c)
    else:
        k = rng.integers(5, 12)
        a = (np.arange(k) + rng.uniform(0.0, 0.9, k)) * (2 * np.pi / k)  # gaps below pi: a simple polygon
        r = rng.uniform(1.0, 5.0, k)
        g = shapely.Polygon(c + np.column_stack([r * np.cos(a), r * np.sin(a)]))
    return affinity.rotate(g, rng.uniform(0.0, 180.0))


def test_random_scenes_equal_geos_with_no_fallback():
    rng = np.random.default_rng(2024)
    n_blocked = n_pairs = 0
    for _ in range(40):
        occ = [_random_polygon(rng) for _ in range(rng.integers(1, 30))]
        ego = rng.uniform(-10.0, 10.0, 2)
        pts = rng.uniform(-50.0, 50.0, (60, 2))
        assert _compare(ego, pts, occ) == 0  # general position: every sign certified
        n_blocked += int((~line_of_sight(ego, pts, occ)).sum())
        n_pairs += len(pts)
    assert 0.1 < n_blocked / n_pairs < 0.9  # scenes that hide some points and not others


def test_tangent_rays_through_vertices_and_ends_on_core_edges_and_vertices():
    """S-OA's births lie on rays through an occluder's vertices; targets exactly on the core's vertices, on its
    edges (rounded points of the edge) and a hair inside or outside the occluder."""
    rng = np.random.default_rng(7)
    fell_back = 0
    for _ in range(25):
        occ = [_random_polygon(rng) for _ in range(6)]
        ego = rng.uniform(-5.0, 5.0, 2)
        vert = np.concatenate([shapely.get_coordinates(g) for g in occ])
        cores = shapely.buffer(np.array(occ, dtype=object), -SIGHT_TOL, join_style="mitre")
        core_v = shapely.get_coordinates(cores)
        t = rng.uniform(0.0, 1.0, (len(core_v) - 1, 1))
        on_edges = core_v[:-1] + t * (core_v[1:] - core_v[:-1])
        rays = np.concatenate([ego + s * (vert - ego) for s in (0.5, 1.0, 1.5, 2.0, 3.0)])
        hair = np.concatenate([vert + d for d in (1e-12, -1e-12, 5e-10, -5e-10, 2e-9)])
        centroids = shapely.get_coordinates(shapely.centroid(np.array(occ, dtype=object)))
        fell_back += _compare(ego, np.concatenate([rays, core_v, on_edges, hair, centroids]), occ)
    assert fell_back > 0  # the exact touches go to GEOS


def test_sight_lines_along_edges_and_the_sensor_on_a_boundary():
    box = shapely.box(9.0, -1.0, 11.0, 1.0)
    core = shapely.buffer(box, -SIGHT_TOL, join_style="mitre")
    cx = shapely.get_coordinates(core)
    pts = np.array([[12.0, 1.0], [10.0, 1.0], [9.0, 1.0], [11.0, 1.0], [13.5, 1.5], [12.0, 0.0], [9.5, 1.0]])
    fell_back = 0
    for ego in ([0.0, 1.0], [0.0, -1.0], [9.0, 1.0], [10.0, 1.0], [9.0, 0.0], [0.0, cx[0, 1]], cx[0], cx[1],
                2 * cx[0] - cx[1], [0.0, 0.0]):  # fmt: skip
        fell_back += _compare(ego, np.concatenate([pts, cx, (cx[:-1] + cx[1:]) / 2]), [box])
    assert fell_back > 0


def test_the_sensor_inside_an_occluder_or_a_hole_and_holed_split_or_empty_cores():
    """An occluder holding the sensor is ignored; a hole around the sensor is not; an occluder narrower than twice the
    margin has an empty core (never blocks); a neck of width 1e-9 m splits the core into a MultiPolygon."""
    holed = shapely.Polygon([(-20, -20), (20, -20), (20, 20), (-20, 20)], [[(-5, -5), (5, -5), (5, 5), (-5, 5)]])
    thin = shapely.box(6.0, -3.0, 6.0 + 1e-9, 3.0)
    neck = shapely.union_all(
        [shapely.box(-8, 6, -6, 8), shapely.box(-6, 6.9, -4, 6.9 + 1.5e-9), shapely.box(-4, 6, -2, 8)]
    )
    cores = shapely.buffer(np.array([holed, thin, neck], dtype=object), -SIGHT_TOL, join_style="mitre")
    assert shapely.is_empty(cores[1]) and shapely.get_num_interior_rings(cores[0]) == 1
    assert shapely.get_type_id(cores[2]) == 6  # a MultiPolygon
    rng = np.random.default_rng(3)
    pts = np.concatenate([rng.uniform(-25, 25, (300, 2)), shapely.get_coordinates(cores[2]), [[7.0, 0.0], [-5, 7]]])
    for ego in ([0.0, 0.0], [1.0, -2.0], [6.0 + 5e-10, 0.0], [-5.0, 7.0], [30.0, 30.0], [0.0, 10.0]):
        _compare(ego, pts, [holed, thin, neck, shapely.box(-1, -1, 1, 1)])
    sensor_inside = shapely.box(-1, -1, 1, 1)
    assert len(sight_blockers(np.zeros(2), [sensor_inside, thin])) == 1


def test_an_invalid_core_goes_to_geos():
    """1e6 m from the origin the margin is a few units of the last place, and GEOS's erosion of this star returns a
    self-intersecting core; GEOS's predicates on it follow its own rules (here: the target counts as outside the core,
    though the exact even-odd sets put it inside), so its pairs go to GEOS."""
    star = shapely.Polygon([(1000014.337291239, -23.702971783739525), (1000014.119512556, -24.198523084494468),
                            (1000016.6027295918, -24.0748670650458), (1000014.2053648748, -18.600252317888376),
                            (1000013.8813562337, -20.087033693019148)])  # fmt: skip
    assert not shapely.is_valid(shapely.buffer(star, -SIGHT_TOL, join_style="mitre"))
    ego, target = [999998.5865837986, 3.4153050462057983], [1000013.8813562347, -20.087033693064352]
    assert line_of_sight(np.asarray(ego), np.array([target]), [star]).tolist() == [True]
    assert _compare(ego, [target, [1000015.0, -22.0], [1000020.0, -30.0]], [star]) > 0
    bowtie = shapely.Polygon([(10, -2), (14, 2), (14, -2), (10, 2)])  # an invalid occluder: its lines go to GEOS too
    assert _compare([0.0, 0.0], [[12.0, 0.0], [11.0, 0.5], [20.0, 0.0], [20.0, 9.0]], [bowtie]) > 0


def test_zero_length_and_non_finite_segments_go_to_geos():
    occ = [shapely.box(2.0, -1.0, 4.0, 1.0), shapely.box(-1.0, -1.0, 1.0, 1.0)]
    ego = np.array([-3.0, 0.0])
    pts = np.array([[-3.0, 0.0], [6.0, 0.0], [3.0, 0.0], [-3.0, 0.0], [0.0, 0.0]])
    assert _compare(ego, pts, occ) == 2 * len(occ)  # the two zero-length segments
    with pytest.warns(RuntimeWarning):  # GEOS makes a line of a NaN point; both sides decide it alike
        assert _compare(ego, [[np.nan, 0.0], [6.0, 0.0]], occ) == len(occ)
    for side in (line_of_sight_past, _line_of_sight_reference):  # GEOS refuses an infinite point, on both sides
        with pytest.raises(shapely.errors.GEOSException):
            side(ego, np.array([[np.inf, 1.0]]), sight_blockers(ego, occ))


def test_blockers_reused_over_point_sets_build_cores_as_needed():
    """Later point sets from the same pose meet other occluders: their cores are built then, the decisions stay
    GEOS's; a second pose of the same blockers is decided from its own position."""
    rng = np.random.default_rng(11)
    occ = [_random_polygon(rng) for _ in range(20)]
    ego = np.array([0.3, -0.2])
    blockers, ref = sight_blockers(ego, occ), sight_blockers(ego, occ)
    for k in range(6):
        pts = rng.uniform(-50, 50, (5 + 10 * k, 2))
        np.testing.assert_array_equal(line_of_sight_past(ego, pts, blockers), _line_of_sight_reference(ego, pts, ref))
    assert 0 < blockers._n_built <= len(occ)


def test_certified_signs_are_the_exact_signs():
    """_orient's +-1 is the sign of the exact determinant (rational arithmetic) on near-collinear triples; it says
    UNSURE rather than guess, and 0 never."""
    rng = np.random.default_rng(5)
    n_unsure = 0
    for _ in range(3000):
        a, b = rng.uniform(-100, 100, 2), rng.uniform(-100, 100, 2)
        c = a + rng.uniform(-2, 3) * (b - a) + rng.choice([0.0, 1e-15, 1e-13, 1e-10]) * rng.normal(size=2)
        c = c.astype(float)
        got = _orient(*a, *b, *c)
        fa, fb, fc = ([Fraction(float(v)) for v in p] for p in (a, b, c))
        exact = (fa[0] - fc[0]) * (fb[1] - fc[1]) - (fa[1] - fc[1]) * (fb[0] - fc[0])
        if got == UNSURE:
            n_unsure += 1
        else:
            assert got == (exact > 0) - (exact < 0) and got != 0
    assert 0 < n_unsure < 3000


def test_one_compiled_specialisation_each():
    """Every caller hands the kernels the same argument types: one machine-code version of each."""
    rng = np.random.default_rng(1)
    holed = shapely.Polygon([(-20, -20), (20, -20), (20, 20), (-20, 20)], [[(-5, -5), (5, -5), (5, 5), (-5, 5)]])
    for occ in ([holed], [_random_polygon(rng) for _ in range(5)], [shapely.box(0, 0, 1e-9, 1)]):
        line_of_sight(np.zeros(2), rng.uniform(-30, 30, (20, 2)), occ)
        line_of_sight(np.zeros(2), np.array([[0.0, 0.0]]), occ)
    assert len(sight_blocked.signatures) == 1 and len(sight_polygons.signatures) == 1


def test_a_poses_first_few_lines_go_to_geos_alone_with_the_same_decisions(monkeypatch):
    monkeypatch.setattr(sensor, "FEW_SIGHT_LINES", 16)
    rng = np.random.default_rng(8)
    occ = [_random_polygon(rng) for _ in range(15)]
    ego = rng.uniform(-5.0, 5.0, 2)
    few, many = rng.uniform(-50, 50, (5, 2)), rng.uniform(-50, 50, (40, 2))
    blockers, ref = sight_blockers(ego, occ), sight_blockers(ego, occ)
    np.testing.assert_array_equal(line_of_sight_past(ego, few, blockers), _line_of_sight_reference(ego, few, ref))
    assert not blockers._posed  # decided by GEOS: no rings listed
    np.testing.assert_array_equal(line_of_sight_past(ego, many, blockers), _line_of_sight_reference(ego, many, ref))
    np.testing.assert_array_equal(line_of_sight_past(ego, few, blockers), _line_of_sight_reference(ego, few, ref))
    assert blockers._posed  # listed by the many: the next few go through the compiled test


@pytest.mark.parametrize("n", [0, 1])
def test_no_targets_or_no_occluders(n):
    occ = [shapely.box(2.0, -1.0, 4.0, 1.0)] * n
    assert line_of_sight(np.zeros(2), np.zeros((0, 2)), occ).shape == (0,)
    assert line_of_sight(np.zeros(2), np.array([[5.0, 0.0]]), occ).tolist() == [n == 0]
