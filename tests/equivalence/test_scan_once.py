"""Work done once per scan (docs/method.md §5.8) and the fast paths of the run folder give the results of the code
they replace: the scan's occluder index and cached values, the filter's input check, the sight blockers of the
line-of-sight gate, the sensor's shadow vertices, and the CSV cells and step tables of a merge."""

from __future__ import annotations

import dataclasses
import math
import pickle

import numpy as np
import pytest
import shapely
from shapely.geometry import box

from soabench.birth.base import FOVRule, inside_any
from soabench.config import FilterConfig, Sensor
from soabench.errors import SoabenchError
from soabench.experiment.runs.files import format_value, pack_table, unpack_table, write_csv, write_csv_lists
from soabench.experiment.runs.store import _rows_of
from soabench.gmphd.filter import GMPHDFilter
from soabench.gmphd.inputs import births_finite
from soabench.gmphd.probabilities import detection_gate
from soabench.sensor import _padded, line_of_sight, line_of_sight_past, sight_blockers
from soabench.types import Births, Obstacles, Scan


def _scan(occluders, Z=None, ego=(0.0, 0.0, 0.0)) -> Scan:
    Z = np.array([[10.0, 0.1], [20.0, -0.3]]) if Z is None else Z
    return Scan(0, 0.0, np.asarray(ego, dtype=float), Z, Obstacles.empty(), occluders, shapely.Polygon())


def test_scan_occluder_index_built_once_and_follows_edits():
    a, b = box(0, 0, 1, 1), box(5, 5, 6, 6)
    scan = _scan([a])
    tree = scan.occluder_index()
    assert scan.occluder_index() is tree
    xy = np.array([[0.5, 0.5], [5.5, 5.5]])
    assert inside_any(scan.occluder_index(), xy).tolist() == [True, False]
    scan.occluders.append(b)  # an edited list is indexed anew
    assert scan.occluder_index() is not tree
    assert inside_any(scan.occluder_index(), xy).tolist() == [True, True]
    scan.occluders = [box(10, 10, 11, 11)]  # so is a replaced one
    assert inside_any(scan.occluder_index(), xy).tolist() == [False, False]


def test_scan_caches_are_not_part_of_its_value():
    scan = _scan([box(0, 0, 1, 1)])
    scan.occluder_index()
    assert scan.once("key", lambda: 41) == 41 and scan.once("key", lambda: 42) == 41
    names = [f.name for f in dataclasses.fields(scan)]  # not fields: replace, asdict and the .npz format skip them
    assert names == ["k", "t", "ego", "Z", "obstacles", "occluders", "visible_region"]
    back = pickle.loads(pickle.dumps(scan))
    assert "_occluder_index" not in back.__dict__ and "_once" not in back.__dict__
    np.testing.assert_array_equal(back.Z, scan.Z)
    assert dataclasses.replace(scan, k=1).__dict__.get("_once") is None


def test_fov_rule_uses_the_scan_index_with_the_same_answer():
    rng = np.random.default_rng(3)
    occ = [box(x, y, x + 3, y + 2) for x, y in rng.uniform(-30, 30, (25, 2))]
    xy = rng.uniform(-35, 35, (400, 2))
    scan = _scan(occ)
    rule = FOVRule.__new__(FOVRule)  # only in_occluder is exercised: no scene needed
    expect = inside_any(list(occ), xy)
    np.testing.assert_array_equal(rule.in_occluder(xy, scan), expect)
    assert "_occluder_index" in scan.__dict__
    assert rule.in_occluder(xy[:0], scan).shape == (0,)


def test_line_of_sight_past_blockers_equals_line_of_sight():
    rng = np.random.default_rng(5)
    occ = [box(x, y, x + 4, y + 3) for x, y in rng.uniform(-40, 40, (30, 2))] + [box(-1, -1, 1, 1)]  # holds the ego
    ego = np.array([0.0, 0.0, 0.3])
    pts = rng.uniform(-50, 50, (300, 2))
    blockers = sight_blockers(ego[:2], occ)
    assert len(blockers) == len(occ) - 1
    np.testing.assert_array_equal(line_of_sight_past(ego[:2], pts, blockers), line_of_sight(ego, pts, occ))
    assert line_of_sight_past(ego[:2], pts[:0], blockers).shape == (0,)
    assert line_of_sight_past(ego[:2], pts, sight_blockers(ego[:2], [])).all()


def test_detection_gate_shares_the_scans_sight_blockers_with_the_same_result():
    rng = np.random.default_rng(6)
    occ = [box(x, y, x + 4, y + 3) for x, y in rng.uniform(-40, 40, (30, 2))]
    ego = np.array([0.0, 0.0, 0.3])
    scan = _scan(occ, ego=ego)
    m = np.column_stack([rng.uniform(-50, 50, (300, 2)), np.zeros((300, 2))])
    sensor = Sensor()
    alone = detection_gate(m, ego, sensor, occ)
    assert 0 < alone.sum() < len(m)  # some means hidden, some seen: the line of sight decides
    shared = detection_gate(m, ego, sensor, occ, scan)
    np.testing.assert_array_equal(shared, alone)
    (key,) = [k for k in scan.__dict__["_once"] if k[0] == "filter.sight_blockers"]
    blockers = scan.__dict__["_once"][key][0]
    np.testing.assert_array_equal(detection_gate(m[::-1], ego, sensor, occ, scan), alone[::-1])
    assert scan.__dict__["_once"][key][0] is blockers  # built once for the scan and pose
    moved = ego + np.array([5.0, 0.0, 0.0])  # another pose keeps its own blockers
    np.testing.assert_array_equal(detection_gate(m, moved, sensor, occ, scan), detection_gate(m, moved, sensor, occ))
    assert len([k for k in scan.__dict__["_once"] if k[0] == "filter.sight_blockers"]) == 2


def test_padded_shadow_vertices_repeat_the_first_vertex():
    polys = [np.arange(6, dtype=float).reshape(3, 2), np.arange(10, dtype=float).reshape(5, 2) + 0.5]
    out = _padded(polys)
    n_max = 5
    old = np.stack([np.concatenate([p, np.repeat(p[:1], n_max - len(p), axis=0)]) for p in polys])
    np.testing.assert_array_equal(out, old)


def _births(w) -> Births:
    J = len(w)
    return Births(np.asarray(w, dtype=float), np.zeros((J, 4)), np.tile(np.eye(4), (J, 1, 1)), np.zeros(J, np.int8))


def test_births_check():
    b = _births([0.1, 0.2])
    assert births_finite(b) is True
    b.w = np.array([0.1, np.nan])
    assert births_finite(b) is False
    b.w = np.array([0.1, -0.2])
    assert births_finite(b) is False
    assert births_finite(_births([])) is True


def test_filter_scan_inputs_checked_once_per_scan_and_errors_still_raised():
    sensor = Sensor()
    scan = _scan([], Z=np.array([[10.0, 0.1]]))
    f1, f2 = GMPHDFilter(FilterConfig(), sensor, "static"), GMPHDFilter(FilterConfig(), sensor, "dynamic")
    r1, r2 = f1.step(scan, _births([0.1])), f2.step(scan, _births([0.1]))
    assert r1.k == r2.k == 0
    assert len([k for k in scan.__dict__["_once"] if k[0] == "filter.scan_inputs"]) == 1
    bad = _scan([], Z=np.array([[np.nan, 0.1]]))
    for _ in range(2):  # the cached check still fails every run
        with pytest.raises(SoabenchError, match="measurements"):
            GMPHDFilter(FilterConfig(), sensor, "static").step(bad, _births([0.1]))
    wrong = _scan([], ego=(0.0, 0.0))
    with pytest.raises(SoabenchError, match="ego pose has shape"):
        GMPHDFilter(FilterConfig(), sensor, "static").step(wrong, _births([0.1]))
    drop = dataclasses.replace(FilterConfig(), nonfinite="drop")
    res = GMPHDFilter(drop, sensor, "static").step(bad, _births([0.1]))
    assert res.n_dropped == 1


def _slow_csv(rows, columns) -> str:
    """write_csv without its fast path: the reference the fast path must match."""
    cols = list(columns) + sorted({k for r in rows for k in r} - set(columns))
    lines = [",".join(cols)]
    for r in rows:
        cells = []
        for c in cols:
            s = format_value(r.get(c))
            if any(ch in s for ch in ',"\n'):
                s = '"' + s.replace('"', '""') + '"'
            cells.append(s)
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


TRICKY = [
    {"a": 1, "b": 0.1, "c": "x,y", "d": True},
    {"a": np.int64(3), "b": math.nan, "c": 'say "hi"', "d": None, "e": math.inf},
    {"a": -0, "b": -math.inf, "c": "line\nbreak", "d": np.float64(2.5), "f": np.bool_(False)},
    {"b": 1e300, "c": "", "a": 7},
]


def test_fast_csv_cells_write_the_same_bytes(tmp_path):
    path = tmp_path / "t.csv"
    write_csv(path, TRICKY, ("a", "b", "c", "d"))
    assert path.read_text() == _slow_csv(TRICKY, ("a", "b", "c", "d"))


def test_step_tables_as_lists_write_what_dicts_would(tmp_path):
    cols = ("a", "b", "c")
    t1 = pack_table(TRICKY[:2], cols)
    t2 = pack_table(TRICKY[2:], ("c", "b", "a", "d"))  # another column order and other extra keys
    t3 = {"columns": ["a", "b", "c", "zz"], "rows": [[1, 2.0]]}  # a short row: the missing cells are absent
    tables = [t1, t2, t3]
    out_cols, rows = _rows_of(tables, cols)
    write_csv_lists(tmp_path / "lists.csv", out_cols, rows)
    write_csv(tmp_path / "dicts.csv", [r for t in tables for r in unpack_table(t)], cols)
    assert (tmp_path / "lists.csv").read_bytes() == (tmp_path / "dicts.csv").read_bytes()
    empty_cols, empty = _rows_of([], cols)
    write_csv_lists(tmp_path / "empty.csv", empty_cols, empty)
    write_csv(tmp_path / "empty_dicts.csv", [], cols)
    assert (tmp_path / "empty.csv").read_bytes() == (tmp_path / "empty_dicts.csv").read_bytes()
