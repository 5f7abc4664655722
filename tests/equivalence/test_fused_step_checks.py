"""What the fused step does inside its compiled calls instead of in Python (docs/method.md §2.11, §2.12, §5.7):
the birth components' input check (:func:`cycle.births_ok`) and the posterior's origin counts
(:func:`cycle.origin_counts`) must decide and count exactly as :mod:`soabench.gmphd.inputs` and
:mod:`soabench.origins` do, and a step with a bad birth component must raise or drop as the array path does.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from shapely.geometry import Polygon

from soabench.config import FilterConfig, Sensor
from soabench.errors import SoabenchError
from soabench.gmphd import GMPHDFilter, cycle
from soabench.gmphd.inputs import births_finite
from soabench.origins import N_SOURCES, origin_counts
from soabench.types import SOURCE_GRID, Births, Scan


def _births(w: np.ndarray) -> Births:
    J = len(w)
    m = np.column_stack([np.linspace(5.0, 30.0, J), np.zeros(J), np.zeros((J, 2))])
    return Births(np.asarray(w, dtype=float), m, np.tile(np.eye(4), (J, 1, 1)), np.full(J, SOURCE_GRID, np.int8))


@pytest.mark.parametrize(
    "where, value",
    [
        (None, None),
        ("w", np.nan),
        ("w", np.inf),
        ("w", -1e-300),
        ("w", -0.0),  # -0.0 >= 0: accepted by both
        ("m", np.nan),
        ("m", -np.inf),
        ("P", np.nan),
        ("P", np.inf),
    ],
)
def test_compiled_birth_check_is_births_finite(where, value):
    for J in (0, 1, 4):
        b = _births(np.full(J, 0.1))
        if where is not None and J:
            arr = getattr(b, where)
            arr.reshape(J, -1)[J - 1, -1] = value
        assert cycle.births_ok(b.w, b.m, b.P) is births_finite(b), (where, value, J)


def test_compiled_origin_counts_are_those_of_the_origins_module():
    rng = np.random.default_rng(3)
    for J in (0, 1, 50, 500):
        origin = rng.integers(-3, N_SOURCES + 4, J).astype(np.int8)  # known codes, persistent (-1), plugin codes
        age = rng.integers(0, 3, J).astype(np.int32)
        got = cycle.origin_counts(origin, age, N_SOURCES)
        np.testing.assert_array_equal(got, origin_counts(origin, age))
        assert got.dtype == np.int64 and got.sum() == J


@pytest.mark.parametrize("mode", ["static", "dynamic"])
@pytest.mark.parametrize("bad", [np.nan, -0.5])
def test_fused_step_raises_or_drops_a_bad_birth_as_the_array_path(mode, bad):
    scan = Scan(0, 0.0, np.zeros(3), np.array([[10.0, 0.1], [20.0, -0.3]]), None, [], Polygon())
    births = _births(np.array([0.1, bad, 0.2]))
    for fused in (True, False):
        with pytest.raises(SoabenchError, match=r"scan 0: 1 of 3 birth components .* filter.nonfinite"):
            GMPHDFilter(FilterConfig(), Sensor(), mode, fused=fused).step(scan, births)
    drop = dataclasses.replace(FilterConfig(), nonfinite="drop")
    res = {f: GMPHDFilter(drop, Sensor(), mode, fused=f).step(scan, births) for f in (True, False)}
    assert res[True].n_dropped_births == res[False].n_dropped_births == 1
    assert res[True].n_predicted == res[False].n_predicted == 2
    np.testing.assert_allclose(res[True].X, res[False].X, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(res[True].origin_counts, res[False].origin_counts)


def test_kappa_is_computed_once_per_scan_and_clutter_setting():
    """Filters with the same clutter settings share kappa of a scan; another clutter rate gets its own."""
    scan = Scan(0, 0.0, np.zeros(3), np.array([[10.0, 0.1], [20.0, -0.3]]), None, [], Polygon())
    a = GMPHDFilter(FilterConfig(), Sensor(), "static").step(scan, _births(np.full(2, 0.1)))
    b = GMPHDFilter(FilterConfig(), Sensor(), "dynamic").step(scan, _births(np.full(2, 0.1)))
    c = GMPHDFilter(FilterConfig(), Sensor(lambda_c=10.0), "static").step(scan, _births(np.full(2, 0.1)))
    assert a.kappa is b.kappa
    np.testing.assert_allclose(c.kappa, a.kappa * 10.0 / Sensor().lambda_c, rtol=1e-15)
