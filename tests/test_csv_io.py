"""The run store's CSV reader: its direct split reads what the csv module reads, and steps.csv is read only when
a figure needs it."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from soabench.errors import SoabenchError
from soabench.experiment.store import read_csv, write_csv


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
}


@pytest.mark.parametrize("name", sorted(TEXTS))
def test_read_csv_reads_what_the_csv_module_reads(tmp_path, name):
    path = tmp_path / "t.csv"
    path.write_text(TEXTS[name], encoding="utf-8", newline="")
    assert same(read_csv(path), csv_module_columns(path)), name


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
    from soabench.experiment import tables as tables_module

    run = tmp_path / "run"
    run.mkdir()
    from soabench.experiment.store import FORMAT_VERSION, RUN_FILE

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
