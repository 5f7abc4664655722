"""The plugin examples of the manual run as printed (docs/user-guide/birth-model.md, docs/user-guide/tracker.md).

Each page's first ``python`` block is written into a package of its own, named by import path on the command line as
a reader would, and the command must succeed and use it.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

from repo_paths import ROOT

from soabench.cli.main import main

DOCS = ROOT / "docs" / "user-guide"


def _example_package(page: str, tmp_path: Path, monkeypatch, package: str) -> str:
    """The page's first python block as ``package/<module>.py`` on ``sys.path``; returns the module's import name."""
    code = re.search(r"```python\n(.*?)```", (DOCS / page).read_text(encoding="utf-8"), re.S).group(1)
    module = re.match(r"# mypkg/(\w+)\.py\n", code).group(1)
    (tmp_path / package).mkdir()
    (tmp_path / package / "__init__.py").write_text("")
    (tmp_path / package / f"{module}.py").write_text(code)
    monkeypatch.syspath_prepend(str(tmp_path))
    return f"{package}.{module}"


def test_the_birth_model_example_draws_its_components(tmp_path, monkeypatch, capsys):
    module = _example_package("birth-model.md", tmp_path, monkeypatch, "docs_example_births")
    out = tmp_path / "ring.png"
    assert main(["birth", "--model", f"{module}:RingBirth", "--time", "20", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    n = int(re.search(r"\((\d+) components", said).group(1))
    assert out.stat().st_size > 0 and 0 < n <= 24  # the ring's 24 means, minus those the FOV rule drops


def test_the_tracker_example_gets_rows_beside_soa(tmp_path, monkeypatch):
    module = _example_package("tracker.md", tmp_path, monkeypatch, "docs_example_trackers")
    name = f"{module}:NearestMeasurement"
    run = tmp_path / "run"
    argv = ["run", "--models", "soa", "--trackers", name, "--probabilities", "static", "--trials", "1"]
    assert main([*argv, "--duration", "10", "--workers", "1", "--no-progress", "--out", str(run)]) == 0
    with open(run / "trials.csv", newline="") as fh:
        rows = {r["model"]: r for r in csv.DictReader(fh)}
    assert set(rows) == {"soa", name}
    assert int(rows[name]["tp"]) + int(rows[name]["fp"]) > 0  # it reported every measurement as a target
