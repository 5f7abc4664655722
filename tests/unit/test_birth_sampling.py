"""Semantic placement samplers (docs/method.md §3.1.4, paper eq. 14; test T19)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree
from scipy.spatial.distance import pdist
from shapely.geometry import Point, box

from soabench.birth.sampling import dbscan_clusters, grid_points, hex_lattice, poisson_disk, uniform_points


def sidewalks() -> shapely.Geometry:
    """A disconnected Omega: an L of 3 m strips, a far strip and a round plaza."""
    return shapely.union_all(
        [box(0, 0, 100, 3), box(0, 0, 3, 80), box(60, 50, 90, 53), Point(50, 30).buffer(10), box(120, -20, 122, 40)]
    )


def check_t19(pts: np.ndarray, region, d_min: float, rng: np.random.Generator) -> None:
    """T19: pairwise distances >= d_min, all points in Omega, no uniform probe farther than 2 d_min from a sample."""
    assert len(pts) > 1
    assert pdist(pts).min() >= d_min
    assert shapely.contains_xy(region, pts[:, 0], pts[:, 1]).all()
    probes = uniform_points(region, 20000, rng)
    gap, _ = cKDTree(pts).query(probes)
    assert gap.max() <= 2.0 * d_min


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_t19_poisson_disk_on_disconnected_sidewalks(seed):
    region = sidewalks()
    rng = np.random.default_rng(seed)
    pts = poisson_disk(region, 5.0, rng)
    check_t19(pts, region, 5.0, np.random.default_rng(100 + seed))
    # every disconnected piece got samples
    for part in shapely.get_parts(region):
        assert shapely.contains_xy(part, pts[:, 0], pts[:, 1]).any()


@settings(max_examples=15, deadline=None)
@given(
    w=st.floats(1.0, 40.0),
    h=st.floats(1.0, 40.0),
    d_min=st.floats(1.0, 8.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_t19_poisson_disk_property(w, h, d_min, seed):
    region = box(0, 0, w, h).union(Point(w, h).buffer(min(w, h) / 2))
    pts = poisson_disk(region, d_min, np.random.default_rng(seed))
    assert len(pts) >= 1
    assert shapely.contains_xy(region, pts[:, 0], pts[:, 1]).all()
    if len(pts) > 1:
        assert pdist(pts).min() >= d_min
    probes = uniform_points(region, 3000, np.random.default_rng(seed + 1))
    assert cKDTree(pts).query(probes)[0].max() <= 2.0 * d_min


def test_poisson_disk_reproducible_and_seed_dependent():
    region = sidewalks()
    a = poisson_disk(region, 5.0, np.random.default_rng(3))
    b = poisson_disk(region, 5.0, np.random.default_rng(3))
    c = poisson_disk(region, 5.0, np.random.default_rng(4))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_subset_of_poisson_set_keeps_eq14():
    region = sidewalks()
    pts = poisson_disk(region, 5.0, np.random.default_rng(0))
    omega_k = Point(20, 10).buffer(30)
    sub = pts[shapely.contains_xy(omega_k, pts[:, 0], pts[:, 1])]
    assert 1 < len(sub) < len(pts)
    assert pdist(sub).min() >= 5.0


def test_poisson_disk_density_is_plausible():
    """A filled 100 x 100 square holds between the hex packing bound and a sparse bound of points."""
    pts = poisson_disk(box(0, 0, 100, 100), 5.0, np.random.default_rng(0))
    hex_bound = 100 * 100 / (math.sqrt(3) / 2 * 25)  # 462
    assert 0.5 * hex_bound < len(pts) < hex_bound + 50


def test_empty_region_gives_no_points():
    empty = box(0, 0, 1, 1).intersection(box(5, 5, 6, 6))
    assert poisson_disk(empty, 5.0, np.random.default_rng(0)).shape == (0, 2)
    assert uniform_points(empty, 10, np.random.default_rng(0)).shape == (0, 2)
    assert hex_lattice(empty, 5.0).shape == (0, 2)


def test_hex_lattice_pitch_and_clipping():
    region = sidewalks()
    pts = hex_lattice(region, 5.0)
    assert shapely.contains_xy(region, pts[:, 0], pts[:, 1]).all()
    assert pdist(pts).min() == pytest.approx(5.0, abs=1e-9)
    full = hex_lattice(box(0, 0, 50, 50), 5.0)
    nn = cKDTree(full).query(full, k=7)[0][:, 1:]
    inner = (full[:, 0] > 6) & (full[:, 0] < 44) & (full[:, 1] > 6) & (full[:, 1] < 44)
    np.testing.assert_allclose(nn[inner], 5.0, atol=1e-9)  # six neighbours at the pitch: a hexagonal lattice


def test_uniform_points_count_and_membership():
    region = sidewalks()
    pts = uniform_points(region, 500, np.random.default_rng(0))
    assert pts.shape == (500, 2)
    assert shapely.contains_xy(region, pts[:, 0], pts[:, 1]).all()
    # roughly uniform: the share in the plaza matches its area share
    plaza = Point(50, 30).buffer(10)
    share = shapely.contains_xy(plaza, pts[:, 0], pts[:, 1]).mean()
    assert share == pytest.approx(plaza.area / region.area, abs=0.07)


def test_dbscan_two_blobs_give_two_clusters_with_dispersion():
    region = box(0, 0, 10, 2).union(box(30, 0, 32, 20))
    cand = grid_points(region, 0.5)
    mu, s2 = dbscan_clusters(cand, eps=1.0, min_samples=5, cell_area=0.25)
    order = np.argsort(mu[:, 0])
    np.testing.assert_allclose(mu[order], [[5.0, 1.0], [31.0, 10.0]], atol=1e-9)
    # largest eigenvalue of the cluster covariance: the variance along the long axis (20 x 4 points, ddof = 1)
    x = np.arange(0.25, 10, 0.5)
    assert s2[order][0] == pytest.approx(np.var(x) * 80 / 79, rel=1e-9)


def test_dbscan_split_gives_more_compact_clusters():
    region = box(0, 0, 100, 3)
    cand = grid_points(region, 0.5)
    mu1, s1 = dbscan_clusters(cand, 1.0, 5, 0.25)
    mu2, s2 = dbscan_clusters(cand, 1.0, 5, 0.25, split_d_min=5.0, seed=0)
    assert len(mu1) == 1 and len(mu2) == math.ceil(300 / 25)
    assert s2.max() < s1[0]
    assert shapely.contains_xy(region, mu2[:, 0], mu2[:, 1]).all()


def test_dbscan_labels_core_border_noise():
    from soabench.birth.sampling import dbscan_labels

    chain = np.column_stack([np.arange(6) * 0.9, np.zeros(6)])  # 0.9 m apart: one chain cluster
    pair = np.array([[20.0, 0.0], [20.5, 0.0]])  # too few points for a core: noise
    far_border = np.array([[5 * 0.9 + 1.0, 0.0]])  # within eps of the chain's end only: a border point
    pts = np.concatenate([chain, pair, far_border])
    labels = dbscan_labels(pts, eps=1.0, min_samples=3)
    assert list(labels) == [0, 0, 0, 0, 0, 0, -1, -1, 0]


def test_poisson_disk_known_answer():
    """The sampler's output for one region and seed, recorded from the numpy implementation before its grid
    look-ups were compiled (the same random draws and arithmetic: equal here to rounding, bit for bit on the
    machine it was recorded on)."""
    region = shapely.union(shapely.box(0, 0, 30, 10), shapely.box(50, 0, 60, 40))
    pts = poisson_disk(region, 2.0, np.random.default_rng(7), 30)
    assert len(pts) == 126
    ref = [[53.83282806, 9.86596296], [50.00606405, 9.58410625], [52.26372701, 6.73952194], [52.16037016, 39.9927563]]
    assert np.allclose(pts[[0, 1, 2, 63]], ref, rtol=0.0, atol=1e-8)
    assert np.allclose(pts[-1], [25.71426395, 9.99727502], rtol=0.0, atol=1e-8)
