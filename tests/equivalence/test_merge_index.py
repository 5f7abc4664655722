"""The spatial index of the Vo-Ma merge (docs/method.md §2.9): exactly the groups of the literal Table II loop.

``merge_groups`` picks the x-sorted window for small mixtures and the grid above that (the grid's own edge cases:
``tests/equivalence/test_merge_grid.py``); the window and the 2-d tree must give the same labels and centres as the
literal loop (``reference_merge_groups``), at every size, for clustered and spread mixtures, with wide components, ties,
duplicates and covariances that are not positive definite.
"""

from __future__ import annotations

import numpy as np
import pytest
from gmphd_cases import reference_merge_groups

from soabench.gmphd import kernels
from soabench.gmphd.reduction import merge_groups


def mixture(rng: np.random.Generator, J: int, layout: str, n_wide: int) -> tuple[np.ndarray, ...]:
    """J components: ``clustered`` (blobs of about 40 around detections, as after an update) or ``spread``
    (uniform over a 100 m square); ``n_wide`` of them get position variances 10 to 400 times larger; a fifth of
    the weights tie at 0.3."""
    if layout == "clustered":
        hubs = rng.uniform(-150.0, 150.0, (max(1, J // 40), 2))
        xy = hubs[rng.integers(0, len(hubs), J)] + rng.normal(0.0, 0.8, (J, 2))
    else:
        xy = rng.uniform(-50.0, 50.0, (J, 2))
    m = np.column_stack([xy, rng.normal(0.0, 1.0, (J, 2))])
    A = rng.normal(0.0, 0.5, (J, 4, 4))
    P = A @ np.swapaxes(A, 1, 2) + 0.3 * np.eye(4)
    wide = rng.choice(J, n_wide, replace=False)
    P[wide, :2, :2] *= rng.uniform(10.0, 400.0, n_wide)[:, None, None]
    P[wide, :2, :2] += 1.0 * np.eye(2)  # stays positive definite after scaling only the position block
    w = rng.uniform(0.0, 1.0, J)
    w[rng.choice(J, J // 5)] = 0.3
    return m, P, w


CASES = [
    (J, layout, n_wide)
    for J in (1, 7, 50, 97, 300, 1500)
    for layout in ("clustered", "spread")
    for n_wide in (0, 1, J // 20)
]


@pytest.mark.parametrize("J, layout, n_wide", CASES)
def test_merge_groups_equal_literal_loop(J, layout, n_wide):
    rng = np.random.default_rng(J * 7 + n_wide + (layout == "spread"))
    m, P, w = mixture(rng, J, layout, n_wide)
    ref = reference_merge_groups(m, P, w, 4.0)
    label, centres = merge_groups(m, P, w, 4.0)
    np.testing.assert_array_equal(label, ref)
    np.testing.assert_array_equal(label[centres], np.arange(len(centres)))
    order = np.argsort(-w, kind="stable")
    for kernel in (kernels.merge_groups_tree, kernels.merge_groups_window):  # both structures, at every size
        lab, cen = kernel(m, P, order, 4.0)
        np.testing.assert_array_equal(lab, label)
        np.testing.assert_array_equal(cen, centres)


@pytest.mark.parametrize("layout", ["clustered", "spread"])
def test_merge_groups_equal_literal_loop_5000(layout):
    """The largest size of the scaling benchmark, with 2 % wide components."""
    rng = np.random.default_rng(5000 + (layout == "spread"))
    m, P, w = mixture(rng, 5000, layout, 100)
    label, centres = merge_groups(m, P, w, 4.0)
    np.testing.assert_array_equal(label, reference_merge_groups(m, P, w, 4.0))
    assert 1 < len(centres) < 5000


def test_merge_tree_edge_cases_match_window():
    """Duplicated means, one huge component, non-positive-definite and non-finite entries, other thresholds: the
    tree gives the window's groups (the window is the pre-index implementation, checked against the literal loop
    above)."""
    rng = np.random.default_rng(3)
    m, P, w = mixture(rng, 600, "clustered", 30)
    m[100:140] = m[99]  # exact duplicates
    P[5] = np.diag([1e6, 1e6, 1.0, 1.0])  # reaches everything
    P[6] = np.diag([1.0, -1.0, 1.0, 1.0])  # not positive definite: never a member
    P[7, 0, 0] = np.nan
    m[8, 0] = np.nan
    m[9, 1] = np.inf
    m[10, 2] = np.nan  # finite position, NaN velocity: indexed, but its quadratic form is NaN
    w[[6, 8, 9]] = [5.0, 4.0, 3.0]  # the odd ones are early centres
    for U in (0.5, 4.0, 30.0):
        order = np.argsort(-w, kind="stable")
        lab_t, cen_t = kernels.merge_groups_tree(m, P, order, U)
        lab_w, cen_w = kernels.merge_groups_window(m, P, order, U)
        np.testing.assert_array_equal(lab_t, lab_w)
        np.testing.assert_array_equal(cen_t, cen_w)
    assert lab_t[101] == lab_t[99]
