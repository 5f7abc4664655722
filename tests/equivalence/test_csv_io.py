"""The run store's CSV reader: its direct split reads what the csv module reads, and steps.csv is read only when
a figure needs it."""

from __future__ import annotations

import csv
import json
import math
import os
import re

import numpy as np
import pytest

from soabench.errors import SoabenchError
from soabench.experiment.runs.files import read_csv, write_csv


def csv_module_columns(path) -> dict[str, np.ndarray]:
    """The reference: csv.reader, then float columns where every cell parses (empty cells NaN), else str."""
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader)
        data = list(reader)
    out = {}
    for j, name in enumerate(header):
        col = [r[j] for r in data]
        try:
            out[name] = np.array([float(x) if x != "" else math.nan for x in col], dtype=float)
        except ValueError:
            out[name] = np.array(col, dtype=str)
    return out


def same(a: dict, b: dict) -> bool:
    return list(a) == list(b) and all(
        a[k].dtype == b[k].dtype and a[k].shape == b[k].shape and a[k].tobytes() == b[k].tobytes() for k in a
    )


TEXTS = {
    "plain": "a,b,c\n1,2.5,soa\n-0.0,nan,static\n1e-320,inf,x\n",
    "empty cells": "a,b\n,1\n2,\n",
    "all empty column": "a,b\n,1\n,2\n",
    "quoted comma": 'a,b\n1,"x,y"\n2,"say ""hi"""\n',
    "crlf": "a,b\r\n1,2\r\n3,4\r\n",
    "no trailing newline": "a,b\n1,2\n3,4",
    "header only": "a,b\n",
    "numeric strings": "model,k\n12,1\n7,2\n",
    "spaces parse as float": "a\n 5 \n6\n",
    "text after numbers": "a,b,c\n1,2,\n3,x,\n4,5,7\n",
    "blank line": "a,b\n1,2\n\n3,4\n",
}


@pytest.mark.parametrize("block", [1, 2, 20_000])
@pytest.mark.parametrize("name", sorted(TEXTS))
def test_read_csv_reads_what_the_csv_module_reads(tmp_path, monkeypatch, name, block):
    """Whatever the block of rows parsed at a time (a column can turn out to be text in a later block)."""
    from soabench.experiment.runs import files

    monkeypatch.setattr(files, "_BLOCK", block)
    path = tmp_path / "t.csv"
    path.write_text(TEXTS[name], encoding="utf-8", newline="")
    try:
        want = csv_module_columns(path)
    except IndexError:  # a blank line is a row without cells for the csv module: it holds no row
        without = tmp_path / "without.csv"
        without.write_text(TEXTS[name].replace("\n\n", "\n"), encoding="utf-8", newline="")
        want = csv_module_columns(without)
    assert same(read_csv(path), want), name


@pytest.mark.parametrize(
    ("data", "says"),
    [
        (b"a,b\n1,2\n3\n", "is damaged: a row (2 after the header) has 1 cells, the header 2"),
        (b"a,b\n1,2,3\n", "is damaged: a row (1 after the header) has 3 cells"),
        (b'a,b\n"1,2\n3,4\n', "is damaged"),
        (b"a,b\n1,\xff\n", "is not UTF-8 text"),
    ],
)
def test_a_damaged_or_foreign_table_is_one_line(tmp_path, data, says):
    path = tmp_path / "t.csv"
    path.write_bytes(data)
    with pytest.raises(SoabenchError, match=re.escape(says)) as exc:
        read_csv(path)
    assert "\n" not in str(exc.value)


def test_read_csv_round_trips_what_write_csv_writes(tmp_path):
    rng = np.random.default_rng(3)
    x = rng.standard_normal(500) * 10.0 ** rng.integers(-300, 300, 500)
    rows = [
        {"trial": i, "model": "S,OA" if i % 7 == 0 else "soa", "x": float(v), "none": None} for i, v in enumerate(x)
    ]
    path = tmp_path / "t.csv"
    write_csv(path, rows, ("trial", "model", "x", "none"))
    got = read_csv(path)
    assert same(got, csv_module_columns(path))
    assert got["x"].tobytes() == x.tobytes() and np.isnan(got["none"]).all()


def test_an_empty_file_is_one_clear_error(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("")
    with pytest.raises(SoabenchError, match="is empty"):
        read_csv(path)


def test_steps_are_read_only_when_used(tmp_path, monkeypatch):
    from soabench.experiment.reports import tables as tables_module

    run = tmp_path / "run"
    run.mkdir()
    from soabench.experiment.runs.store import FORMAT_VERSION, RUN_FILE

    meta = {"format": FORMAT_VERSION, "config": {"experiment": {"models": ["soa"], "probabilities": ["static"]}}}
    (run / RUN_FILE).write_text(json.dumps(meta))
    for name in ("trials", "episodes", "timing", "steps"):
        write_csv(run / f"{name}.csv", [{"trial": 0, "model": "soa", "v": 1.5}], ("trial", "model", "v"))
    read: list[str] = []
    real = tables_module.read_csv
    monkeypatch.setattr(tables_module, "read_csv", lambda p: read.append(p.name) or real(p))
    t = tables_module.load_tables(run)
    assert sorted(read) == ["episodes.csv", "timing.csv", "trials.csv"]
    assert t.steps["v"].tolist() == [1.5] and "model" in t.steps and read[-1] == "steps.csv"
    assert t.steps.get("v") is t.steps["v"] and read.count("steps.csv") == 1


def _records(kind: str) -> list[dict]:
    """Three trials' records whose step rows arrive unsorted; ``kind`` makes one of them irregular."""
    from soabench.experiment.runs.files import pack_table
    from soabench.experiment.runs.store import STEP_COLUMNS

    rng = np.random.default_rng(5)
    out = []
    for trial in (0, 1, 2):
        rows = []
        for model in ("gmbm", "soa"):  # not in the run's model order
            for k in rng.permutation(4):
                row = {c: float(rng.standard_normal()) for c in STEP_COLUMNS}
                row.update(trial=trial, clutter=3.0, model=model, mode="static", k=int(k))
                if kind == "extra column" and trial == 1:
                    row["n_plugin"] = 7
                if kind == "out of order" and trial == 2:
                    row["trial"] = 0  # sorts before trial 1's rows
                rows.append(row)
        cols = list(STEP_COLUMNS) + (["n_plugin"] if kind == "extra column" and trial == 1 else [])
        out.append({"trial": trial, "status": "ok", "rows": pack_table([], ()), "steps": pack_table(rows, cols)})
    return out


@pytest.mark.parametrize("kind", ["regular", "extra column", "out of order"])
def test_merge_writes_steps_as_one_sort_of_every_row(tmp_path, kind):
    from soabench.experiment.runs import files, store

    run = store.RunStore(tmp_path / "run")
    run.create({"net": "test"})  # a run folder: its records carry its run_id
    for rec in _records(kind):
        run.write_trial(rec)
    models, modes = ("soa", "gmbm"), ("static",)
    counts = run.merge(models, modes)
    # the reference: every record's rows at once, one stable sort (the merge before it streamed)
    tables = [run.load_trial(t)["steps"] for t in run.done_trials()]
    cols, rows = store._rows_of(tables, store.STEP_COLUMNS)
    m_idx, it, ic, im, ip, ik = (
        {"soa": 0, "gmbm": 1},
        *(cols.index(c) for c in ("trial", "clutter", "model", "mode", "k")),
    )
    rows.sort(key=lambda r: (int(r[it]), float(r[ic]), m_idx[r[im]], r[im], 0, r[ip], r[ik]))
    files.write_csv_lists(tmp_path / "reference.csv", cols, rows)
    assert (run.run_dir / "steps.csv").read_bytes() == (tmp_path / "reference.csv").read_bytes()
    assert counts["steps"] == 3 * 2 * 4 and ("n_plugin" in cols) == (kind == "extra column")


def test_model_failures_after_a_merge_are_the_records_own(tmp_path, monkeypatch):
    """The store that merged knows the model failures without reading the records again, until a record changes."""
    from soabench.experiment.runs import store

    run = store.RunStore(tmp_path / "run")
    run.create({"net": "test"})  # a run folder: its records carry its run_id
    for i, rec in enumerate(_records("regular")):
        rec["model_failures"] = [{"trial": rec["trial"], "model": "plug", "k": i}] if i != 1 else []
        run.write_trial(rec)
    run.merge(("soa", "gmbm"), ("static",))
    want = store.RunStore(run.run_dir).model_failures()  # a fresh store reads the records
    assert [f["k"] for f in want] == [0, 2]
    reads: list[int] = []
    real = store.RunStore.load_trial
    monkeypatch.setattr(store.RunStore, "load_trial", lambda self, t: reads.append(t) or real(self, t))
    assert run.model_failures() == want and reads == []
    rec = _records("regular")[1]
    rec["model_failures"] = [{"trial": 1, "model": "plug", "k": 9}]
    run.write_trial(rec)  # the records changed: read them again
    assert [f["k"] for f in run.model_failures()] == [0, 9, 2] and reads == [0, 1, 2]


#: step-table cells a record can hold, per column of the test below (one value per trial's rows)
_ODD_CELLS = {
    "ospa": [1.5, -0.0, float("nan"), -float("nan"), float("inf"), 1e-320, 2**70, 7, None],  # floats, ints, none
    "card_err": [True, False, 3, 2, 1, 0, 5, 4],  # bools write as 1 / 0
    "sum_w": [0.25, "0.5", " 6 ", "1_0", "", 2.0, "3", 1.0],  # text that float() reads, an empty cell
    "n_est": ["a,b", 'say "hi"', "x", "y", "z", "w", "v", "u"],  # text that needs quoting
    "n_gt": [1, 2, 3, "four", 5, 6, 7, 8],  # numbers in some trials, text in another: only the file decides
    "fp": [10**400, 1, 2, 3, 4, 5, 6, 7],  # an int beyond the float range reads as inf
}


@pytest.mark.parametrize("column", sorted(_ODD_CELLS))
def test_merge_keeps_the_step_columns_read_csv_reads(tmp_path, column):
    """``merge(..., step_columns=True)`` keeps steps.csv's columns as ``read_csv`` reads the file it wrote, byte for
    byte and dtype for dtype, whatever the cells; it gives None where only the file decides, and nothing once a
    merged file changed."""
    from soabench.experiment.reports.tables import load_tables
    from soabench.experiment.runs import store

    run = store.RunStore(tmp_path / "run")
    run.create({"config": {"experiment": {"models": ["soa", "gmbm"], "probabilities": ["static"]}}})
    for trial, value in enumerate(_ODD_CELLS[column]):  # trial t's step rows all hold the column's value t
        rec = _records("regular")[0]
        cols = rec["steps"]["columns"]
        rec["trial"] = trial
        for row in rec["steps"]["rows"]:
            row[cols.index("trial")], row[cols.index(column)] = trial, value
        run.write_trial(rec)
    run.merge(("soa", "gmbm"), ("static",), step_columns=True)
    kept, read = run.step_columns(), read_csv(run.run_dir / "steps.csv")
    if column == "n_gt":
        assert kept is None and read[column].dtype.kind == "U"
        return
    assert kept is not None and same(kept, read)
    assert load_tables(run.run_dir, steps=kept).steps[column] is kept[column]
    assert store.RunStore(run.run_dir).step_columns() is None  # another store did not merge
    run.merge(("soa", "gmbm"), ("static",))  # merged again without columns: none kept
    assert run.step_columns() is None
    run.merge(("soa", "gmbm"), ("static",), step_columns=True)
    os.utime(run.run_dir / "steps.csv", ns=(1, 1))  # the file changed since
    assert run.step_columns() is None
