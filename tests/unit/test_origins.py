"""Posterior components by origin (soabench/origins.py, docs/method.md §5.7): the split of the posterior count J_k
into components born at this scan per birth source and components surviving from earlier scans.

A hand-built two-scan case whose every component's fate is known (weights chosen against the pruning threshold T,
means placed for or against merging) checks the split on both filter paths; the columns' sum is checked here and
in tests/unit/test_trial.py (real pipeline) and tests/equivalence/test_fused_cycle.py (fused against array path).
"""

from __future__ import annotations

import numpy as np
import pytest
from shapely.geometry import Polygon

from soabench.config import FilterConfig, Sensor
from soabench.gmphd import GMPHDFilter
from soabench.gmphd.mixture import ORIGIN_PERSISTENT
from soabench.metrics import SERIES_KEYS
from soabench.origins import ORIGIN_KEYS, origin_counts, origin_counts_of
from soabench.trackers import step_result_from
from soabench.types import (
    SOURCE_FOV,
    SOURCE_GRID,
    SOURCE_NAMES,
    SOURCE_OCCL,
    SOURCE_SEM,
    Births,
    Estimates,
    NewbornTerms,
    Scan,
)


def counts(res) -> dict[str, int]:
    """The non-zero origin counts of a step result, by column name."""
    return {k: int(v) for k, v in zip(ORIGIN_KEYS, res.origin_counts, strict=True) if v}


def test_origin_counts_bins_by_source_and_age():
    origin = np.array([SOURCE_OCCL, SOURCE_OCCL, SOURCE_SEM, SOURCE_GRID, ORIGIN_PERSISTENT, 9, SOURCE_OCCL], np.int8)
    age = np.array([0, 0, 3, 1, 0, 2, 1], np.int32)
    c = dict(zip(ORIGIN_KEYS, origin_counts(origin, age).tolist(), strict=True))
    assert c == {**dict.fromkeys(ORIGIN_KEYS, 0), "n_born_occl": 2, "n_surv_occl": 1, "n_surv_sem": 1,
                 "n_surv_grid": 1, "n_unsourced": 2}  # fmt: skip
    assert origin_counts(np.zeros(0, np.int8), np.zeros(0, np.int32)).tolist() == [0] * len(ORIGIN_KEYS)
    assert len(ORIGIN_KEYS) == 2 * len(SOURCE_NAMES) + 1 and set(ORIGIN_KEYS) <= set(SERIES_KEYS)


def test_a_tracker_without_sources_reports_every_component_unsourced():
    res = step_result_from(Estimates(np.zeros((2, 2)), n_components=7), 0, 0.0)
    assert res.origin_counts is None
    c = dict(zip(ORIGIN_KEYS, origin_counts_of(res).tolist(), strict=True))
    assert c["n_unsourced"] == 7 and sum(c.values()) == 7


def _births(w, xy, src, newborn=None) -> Births:
    n = len(w)
    m = np.column_stack([np.asarray(xy, float), np.zeros((n, 2))])
    P = np.broadcast_to(np.diag([4.0, 4.0, 1.0, 1.0]), (n, 4, 4)).copy()
    return Births(np.asarray(w, float), m, P, np.asarray(src, np.int8), newborn)


@pytest.mark.parametrize("fused", [True, False])
def test_hand_built_scans_split_as_known(fused):
    """Scan 0 (sensor at the origin, 360°, r_max 50 m): two occlusion births and a semantic one of weight 0.1
    (missed: 0.1 (1 - p_D) = 2e-3 > T, kept), a grid birth of weight 1e-4 (missed: 2e-6 < T, pruned), and one
    measurement far from every birth that a measurement-driven newborn term explains. Scan 1, no measurement: a
    FOV birth, and an occlusion birth on top of the surviving semantic component; heavier, it absorbs it, and the
    merged component is older than this scan (a group's age is its oldest member's), so it counts as surviving,
    with the source of its heaviest member (occlusion)."""
    cfg, sensor = FilterConfig(), Sensor()
    filt = GMPHDFilter(cfg, sensor, "static", fused=fused)
    z = np.array([[30.0, np.pi]])  # 30 m behind the sensor: at (-30, 0)
    newborn = NewbornTerms(
        np.array([[-30.0, 0.0, 0.0, 0.0]]), np.diag([1.0, 1.0, 1.0, 1.0])[None], lambda A, kappa: np.ones(len(A))
    )
    births0 = _births(
        [0.1, 0.1, 0.1, 1e-4],
        [[10.0, 0.0], [0.0, 20.0], [-15.0, -15.0], [30.0, 0.0]],
        [SOURCE_OCCL, SOURCE_OCCL, SOURCE_SEM, SOURCE_GRID],
        newborn,
    )
    scan0 = Scan(0, 0.0, np.zeros(3), z, None, [], Polygon())
    res0 = filt.step(scan0, births0)
    assert counts(res0) == {"n_born_occl": 2, "n_born_sem": 1, "n_born_meas": 1}
    assert res0.n_reduced == 4 and res0.n_newborn == 1

    births1 = _births([0.1, 0.1], [[0.0, -30.0], [-15.0, -15.0]], [SOURCE_FOV, SOURCE_OCCL])
    res1 = filt.step(Scan(1, 1.0, np.zeros(3), np.zeros((0, 2)), None, [], Polygon()), births1)
    # 2 occlusion + the merged semantic/occlusion component survive, the newborn of scan 0 survives, a FOV birth
    assert counts(res1) == {"n_born_fov": 1, "n_surv_occl": 3, "n_surv_meas": 1}
    assert res1.n_reduced == 5 and int(res1.origin_counts.sum()) == res1.n_reduced
