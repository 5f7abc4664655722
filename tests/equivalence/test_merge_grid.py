"""The grid index of the Vo-Ma merge (docs/method.md §2.9, ``kernels.merge_groups_grid``): exactly the groups of
the x-sorted window (itself checked against the literal Table II loop in ``tests/equivalence/test_merge_index.py``), for
clustered and spread mixtures, wide components, far outliers, ties, duplicates and bad covariances."""

from __future__ import annotations

import numpy as np
import pytest
from test_merge_index import mixture

from soabench.gmphd import kernels


def _same_groups(m: np.ndarray, P: np.ndarray, w: np.ndarray, U: float) -> None:
    order = np.argsort(-w, kind="stable")
    lab_g, cen_g = kernels.merge_groups_grid(m, P, order, U)
    lab_w, cen_w = kernels.merge_groups_window(m, P, order, U)
    np.testing.assert_array_equal(lab_g, lab_w)
    np.testing.assert_array_equal(cen_g, cen_w)


@pytest.mark.parametrize("J", [1, 2, 97, 800, 3000])
@pytest.mark.parametrize("layout", ["clustered", "spread"])
def test_grid_equals_window(J, layout):
    rng = np.random.default_rng(J + 11 * (layout == "spread"))
    for n_wide in (0, J // 20 + 1):
        m, P, w = mixture(rng, J, layout, min(n_wide, J))
        for U in (0.5, 4.0, 30.0):
            _same_groups(m, P, w, U)


def test_grid_edge_cases():
    """Duplicates, one component reaching everything, a far outlier that would make a fine grid huge, reaches
    spanning many classes, bad covariances and non-finite entries, U = 0."""
    rng = np.random.default_rng(5)
    m, P, w = mixture(rng, 900, "clustered", 40)
    m[100:140] = m[99]  # exact duplicates
    P[5] = np.diag([1e6, 1e6, 1.0, 1.0])  # reaches everything
    P[11] = np.diag([1e12, 1e12, 1.0, 1.0])  # beyond the coarsest finite class
    P[6] = np.diag([1.0, -1.0, 1.0, 1.0])  # not positive definite: never a member
    P[7, 0, 0] = np.nan
    m[8, 0] = np.nan
    m[9, 1] = np.inf
    m[10, 2] = np.nan  # finite position, NaN velocity
    m[12, :2] = [1e7, -1e7]  # a far outlier
    P[13, :2, :2] *= 1e-6  # a very small reach
    w[[6, 8, 9, 12]] = [5.0, 4.0, 3.0, 2.5]  # the odd ones are early centres
    for U in (0.0, 0.5, 4.0, 30.0):
        _same_groups(m, P, w, U)
    far = m.copy()
    far[:, :2] += 1e6  # the whole mixture far from the origin
    _same_groups(far, P, w, 4.0)
