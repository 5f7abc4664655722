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
