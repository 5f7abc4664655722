"""The occluder index of ``birth.base.inside_any``: built once per geometry list, rebuilt when the list changes."""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import box

from soabench.birth.base import geometry_index, inside_any


def brute_force(geoms, xy):
    return np.array([any(g.contains(shapely.Point(p)) for g in geoms) for p in xy], dtype=bool)


def test_index_built_once_per_list_and_results_unchanged():
    rng = np.random.default_rng(0)
    occluders = [box(x, y, x + 2, y + 1) for x, y in rng.uniform(-20, 20, (30, 2))]
    xy = rng.uniform(-22, 22, (500, 2))
    tree = geometry_index(occluders)
    assert geometry_index(occluders) is tree  # reused: one tree per scan, not one per call
    np.testing.assert_array_equal(inside_any(occluders, xy), brute_force(occluders, xy))
    assert geometry_index(occluders) is tree
    same_content = list(occluders)  # another list (another scan) with the same objects: its own entry
    assert geometry_index(same_content) is not tree
    scans = [[box(i, 0, i + 1, 1)] for i in range(100)]  # a trial's scans, visited once per filter run
    trees = [geometry_index(s) for s in scans]
    assert all(geometry_index(s) is t for s, t in zip(scans, trees, strict=True))


def test_edited_list_gets_a_new_index():
    a, b = box(0, 0, 1, 1), box(5, 5, 6, 6)
    occluders = [a]
    xy = np.array([[0.5, 0.5], [5.5, 5.5]])
    assert inside_any(occluders, xy).tolist() == [True, False]
    occluders.append(b)
    assert inside_any(occluders, xy).tolist() == [True, True]
    occluders[0] = box(10, 10, 11, 11)
    assert inside_any(occluders, xy).tolist() == [False, True]
    assert inside_any([], xy).tolist() == [False, False] and inside_any(None, xy).tolist() == [False, False]


def test_many_lists_evict_old_entries():
    lists = [[box(i, 0, i + 1, 1)] for i in range(300)]
    for i, lst in enumerate(lists):
        assert inside_any(lst, np.array([[i + 0.5, 0.5]])).tolist() == [True]
    for i, lst in enumerate(lists):  # evicted entries are rebuilt, correctly
        assert inside_any(lst, np.array([[i + 0.5, 0.5], [i + 1.5, 0.5]])).tolist() == [True, False]


def test_box_prefilter_matches_the_within_query_on_both_paths(monkeypatch):
    """inside_any's bounding-box pairs + prepared contains_xy give the tree query's ``within`` answer: rotated and
    non-convex polygons, points on edges and vertices, NaN points, an empty geometry; numpy boxes and tree boxes."""
    from soabench.birth import base

    rng = np.random.default_rng(3)
    geoms = [shapely.affinity.rotate(box(x, y, x + 3, y + 1.5), a) for (x, y), a in
             zip(rng.uniform(-20, 20, (25, 2)), rng.uniform(0, 180, 25), strict=True)]  # fmt: skip
    geoms += [shapely.Polygon([(0, 0), (6, 0), (6, 6), (3, 2), (0, 6)]), shapely.Polygon()]
    edge = np.array([[3.0, 0.0], [0.0, 0.0], [6.0, 3.0], [3.0, 2.0]])  # on the L-shape's boundary: not interior
    xy = np.vstack([rng.uniform(-24, 24, (2000, 2)), edge, [[np.nan, 1.0]], shapely.get_coordinates(geoms[0])])
    tree = shapely.STRtree(geoms)
    expect = np.zeros(len(xy), dtype=bool)
    expect[tree.query(shapely.points(xy), predicate="within")[0]] = True
    assert expect.sum() > 50 and not expect[2000:].any()
    np.testing.assert_array_equal(inside_any(tree, xy), expect)
    monkeypatch.setattr(base, "_BOX_BRUTE", 0)  # the tree finds the boxes instead of numpy
    np.testing.assert_array_equal(inside_any(tree, xy), expect)
