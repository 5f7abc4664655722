"""Bad input, property-based: the configuration loader (any table in: a validated config with exact types and
finite values, or one SoabenchError line) and the filter step at its API boundary (random mixtures and scans with
NaN/inf injected: a clear error, or dropped and counted; weights non-negative and finite, mass conserved where it
must be, never a NaN)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from gmphd_cases import scenes
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon

from soabench.config import Config, FilterConfig, Sensor, load_config
from soabench.errors import SoabenchError
from soabench.gmphd import GMPHDFilter
from soabench.types import SOURCE_GRID, SOURCE_MEAS, Births, NewbornTerms, Scan

SETTINGS = settings(max_examples=60, deadline=None)

# ------------------------------------------------------------------------------------------------ config loader
FIELDS = {  # the parameter sections ([plugins.<name>] tables belong to their plugins)
    sec.name: {f.name: f for f in dataclasses.fields(getattr(Config(), sec.name))}
    for sec in dataclasses.fields(Config)
    if dataclasses.is_dataclass(getattr(Config(), sec.name))
}
SCALARS = st.one_of(
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, 1, 3, 0.5, 1.0, 2.0, 100.0, 1e300, "soa", "no", "ekf", "polar", "", "raise", "drop"]),
    st.text(max_size=5),
)
VALUES = st.one_of(SCALARS, st.lists(SCALARS, max_size=4))


@st.composite
def config_tables(draw):
    """Tables over the real sections and keys (and sometimes unknown ones), with values of any type."""
    data = {}
    for sec in draw(st.lists(st.sampled_from([*FIELDS, "bogus"]), max_size=4, unique=True)):
        fields = FIELDS.get(sec, {})
        keys = [*fields, "nope"]
        data[sec] = {}
        for k in draw(st.lists(st.sampled_from(keys), max_size=5, unique=True)):
            f = fields.get(k)
            default = None if f is None else (f.default_factory() if f.default is dataclasses.MISSING else f.default)
            valid = default is not None and draw(st.booleans())  # half the known keys get a valid value
            data[sec][k] = (list(default) if isinstance(default, tuple) else default) if valid else draw(VALUES)
    return data


def _exact(default, value) -> bool:
    if isinstance(default, bool):
        return isinstance(value, bool)
    if default is None or isinstance(default, int):
        return value is None or (isinstance(value, int) and not isinstance(value, bool))
    if isinstance(default, float):
        return isinstance(value, float) and math.isfinite(value)
    if isinstance(default, str):
        return isinstance(value, str)
    if isinstance(default, tuple):
        return isinstance(value, tuple) and all(_exact(default[0], v) for v in value)
    return True


@SETTINGS
@given(config_tables())
def test_config_loader_accepts_exactly_typed_finite_values_or_says_one_line(data):
    try:
        cfg = Config.from_dict(data).validate()
    except SoabenchError as exc:
        assert "\n" not in str(exc) and str(exc)
        return
    for sec, fields in FIELDS.items():
        for name, f in fields.items():
            default = f.default_factory() if f.default is dataclasses.MISSING else f.default
            assert _exact(default, getattr(getattr(cfg, sec), name)), (sec, name)
    again = Config.from_dict(json.loads(json.dumps(cfg.to_dict()))).validate()  # as run.json stores it
    assert again == cfg


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v == math.inf else "-inf" if v == -math.inf else repr(v))
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return json.dumps(v) if isinstance(v, str) else str(v)


@settings(max_examples=40, deadline=None)
@given(config_tables())
def test_config_file_and_table_agree(tmp_path_factory, data):
    """The TOML file path gives the same verdict as the table (the file adds only parsing)."""
    lines = []
    for sec, values in data.items():
        lines.append(f"[{sec}]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in values.items()]
    p = tmp_path_factory.mktemp("cfg") / "c.toml"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    try:
        direct = Config.from_dict(data).validate()
    except SoabenchError:
        direct = None
    if direct is None:
        with pytest.raises(SoabenchError):
            load_config(p)
    else:
        assert load_config(p) == direct


# ------------------------------------------------------------------------------------------------ filter step
def _poison(rng: np.random.Generator, a: np.ndarray, p: float) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    if a.size:
        mask = rng.random(a.shape) < p
        a[mask] = rng.choice([np.nan, np.inf, -np.inf], mask.sum())
    return a


@st.composite
def poisoned_steps(draw):
    mix, Z, ego, _ = draw(scenes())
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    pz, pego, pb = draw(st.sampled_from([0.0, 0.1, 0.5])), draw(st.booleans()), draw(st.sampled_from([0.0, 0.05]))
    Zp = _poison(rng, Z, pz)
    egop = _poison(rng, ego, 0.5) if pego else ego
    w = _poison(rng, mix.w, pb)
    m = _poison(rng, mix.m, pb)
    newborn = None
    if draw(st.booleans()) and len(Zp):  # measurement-driven newborns built from (possibly poisoned) Z
        M = len(Zp)
        with np.errstate(invalid="ignore"):
            nb_m = np.column_stack([Zp[:, 0] * np.cos(Zp[:, 1]), Zp[:, 0] * np.sin(Zp[:, 1]), np.zeros((M, 2))])
        newborn = NewbornTerms(nb_m, np.tile(np.eye(4), (M, 1, 1)), lambda A, k: 0.01 * np.ones(len(A)))
    births = Births(w, m, mix.P, np.full(len(mix), SOURCE_GRID, dtype=np.int8), newborn)
    return Zp, egop, births, draw(st.sampled_from(["static", "dynamic"]))


def _bad_rows(a: np.ndarray) -> int:
    return int((~np.isfinite(a.reshape(len(a), -1)).all(axis=1)).sum()) if len(a) else 0


@SETTINGS
@given(poisoned_steps())
def test_filter_step_raises_on_non_finite_inputs_by_default(case):
    Z, ego, births, mode = case
    filt = GMPHDFilter(FilterConfig(J_max=60), Sensor(), mode=mode)
    bad = not (np.isfinite(Z).all() and np.isfinite(ego).all() and np.isfinite(births.w).all())
    bad = bad or not np.isfinite(births.m).all()
    if bad:
        with pytest.raises(SoabenchError, match="scan 0: .*filter.nonfinite"):
            filt.step(Scan(0, 0.0, ego, Z, None, [], Polygon()), births)
    else:
        res = filt.step(Scan(0, 0.0, ego, Z, None, [], Polygon()), births)
        assert res.n_dropped == 0 and np.isfinite(res.X).all()


@SETTINGS
@given(poisoned_steps())
def test_filter_step_drops_and_counts_non_finite_inputs(case):
    Z, ego, births, mode = case
    filt = GMPHDFilter(FilterConfig(J_max=60, nonfinite="drop"), Sensor(), mode=mode)
    ego_ok = bool(np.isfinite(ego).all())
    n_bad_births = int((~(np.isfinite(births.w) & np.isfinite(births.m).all(axis=1))).sum()) if len(births) else 0
    for k in range(2):
        res = filt.step(Scan(k, float(k), ego, Z, None, [], Polygon()), births)
        assert res.n_dropped == (len(Z) if not ego_ok else _bad_rows(Z))
        assert res.n_dropped_births == n_bad_births
        w = filt.mixture.w
        assert np.isfinite(w).all() and (w >= 0).all()
        assert np.isfinite(filt.mixture.m).all() and np.isfinite(filt.mixture.P).all()
        assert np.isfinite(res.X).all() and np.isfinite(res.X_w).all()
        assert math.isfinite(res.sum_w) and math.isfinite(res.mean_pD)
        assert np.isfinite(res.A).all() and np.isfinite(res.kappa).all()
        if not ego_ok:  # a dropped scan is a missed scan: no detection, the mass is the predicted mass
            assert res.n_newborn == 0 and res.n_pairs == 0


@SETTINGS
@given(scenes(), st.floats(0.0, 1.0), st.sampled_from(["ekf", "ukf"]))
def test_mass_is_conserved_without_detection(scene, p_S, form):
    """p_D = 0: the update keeps every component's weight, so N_k|k = p_S N_k-1 + sum of birth weights, whatever
    the measurements (T1 with p_D = 0), across two steps."""
    mix, Z, ego, _ = scene
    cfg = FilterConfig(form=form, p_S=p_S, p_D=0.0, J_max=1000, prune_T=0.0)
    filt = GMPHDFilter(cfg, Sensor(), mode="static")
    births = Births(mix.w, mix.m, mix.P, np.full(len(mix), SOURCE_MEAS, dtype=np.int8))
    prev = 0.0
    for k in range(2):
        res = filt.step(Scan(k, float(k), ego, Z, None, [], Polygon()), births)
        expected = p_S * prev + births.w.sum()
        np.testing.assert_allclose(res.sum_w, expected, rtol=1e-9, atol=1e-300)
        assert res.sum_w_reduced <= res.sum_w * (1 + 1e-12) + 1e-300
        prev = res.sum_w_reduced


def test_nan_measurement_with_measurement_driven_births_never_reaches_a_state():
    """The issue's case: NaN measurements with PUBM-like newborns put NaN into means; now raise or drop."""
    Z = np.array([[10.0, 0.1], [np.nan, 0.2], [12.0, np.inf]])
    with np.errstate(invalid="ignore"):
        nb_m = np.column_stack([Z[:, 0] * np.cos(Z[:, 1]), Z[:, 0] * np.sin(Z[:, 1]), np.zeros((3, 2))])
    births = Births.empty()
    births.newborn = NewbornTerms(nb_m, np.tile(np.eye(4), (3, 1, 1)), lambda A, k: np.full(len(A), 0.5))
    scan = Scan(0, 0.0, np.zeros(3), Z, None, [], Polygon())
    with pytest.raises(SoabenchError, match=r"scan 0: 2 of 3 measurements .* are not finite"):
        GMPHDFilter(FilterConfig(), Sensor()).step(scan, births)
    res = GMPHDFilter(FilterConfig(nonfinite="drop"), Sensor()).step(scan, births)
    assert res.n_dropped == 2 and res.n_newborn == 1 and np.isfinite(res.X).all() and len(res.X) == 1
    bad_pose = Scan(0, 0.0, np.array([0.0, np.nan, 0.0]), Z[:1], None, [], Polygon())
    with pytest.raises(SoabenchError, match="ego pose"):
        GMPHDFilter(FilterConfig(), Sensor()).step(bad_pose, births)
