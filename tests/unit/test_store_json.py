"""A trial record's compact JSON (soabench.atomic) is written by json's C encoder, asking to_jsonable
only for what json cannot write: the text is the one to_jsonable's walk gives."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from soabench import atomic
from soabench.experiment.runs import files


def _walked(obj) -> str:
    return json.dumps(atomic.to_jsonable(obj), allow_nan=True, separators=(",", ":"))


def test_compact_json_is_the_walked_text():
    samples = [
        {
            "trial": np.int64(3),
            "rows": {"columns": ["x", "y"], "rows": [[np.float64(0.1), np.float32(0.1)], [float("nan"), -np.inf]]},
            "flags": [np.bool_(True), False, None, (1, 2), np.arange(3), np.zeros((2, 2))],
            "text": [np.str_("soa"), "pubm", Path("/tmp/x")],
            "nested": {"a": {"b": [1, 2.5, {"c": np.float64(-0.0)}]}},
        },
        {1: "an int key", "s": 1},
        {True: "a bool key"},
        {None: [np.int32(7)]},
        [np.float64(1e-300), 1e300, 5e-324],
    ]
    for obj in samples:
        assert atomic._compact_json(obj) == _walked(obj)


def test_trial_records_round_trip(tmp_path):
    rec = {"trial": 0, "status": "ok", "rows": files.pack_table([{"a": np.float64(0.25), "b": "soa"}], ["a", "b"])}
    path = tmp_path / "t.json"
    atomic.write_json_atomic(path, rec, compact=True)
    assert path.read_text() == _walked(rec) + "\n"
    assert json.loads(path.read_text()) == {
        "trial": 0,
        "status": "ok",
        "rows": {"columns": ["a", "b"], "rows": [[0.25, "soa"]]},
    }
