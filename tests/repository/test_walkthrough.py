"""The Python walk-through runs: every code block of docs/user-guide/python.md, in order, and every code cell of
examples/walkthrough.ipynb, in order (read as JSON and executed here: no Jupyter needed)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from repo_paths import ROOT

pytestmark = pytest.mark.slow  # runs every block of the walk-through

PAGE = ROOT / "docs" / "user-guide" / "python.md"
NOTEBOOK = ROOT / "examples" / "walkthrough.ipynb"


def _run_in_order(blocks: list[str], where: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> dict:
    """Execute the code blocks in one namespace, as a notebook kernel would, in a fresh working folder."""
    import matplotlib

    matplotlib.use("Agg")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__main__"}
    for i, block in enumerate(blocks):
        assert not re.search(r"^\s*[%!]", block, re.M), f"{where} block {i} uses IPython magics"
        exec(compile(block, f"{where}[{i}]", "exec"), namespace)
    assert list(tmp_path.iterdir()) == [], f"{where} wrote files"
    return namespace


def page_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", PAGE.read_text(encoding="utf-8"), re.S)


def notebook_cells() -> list[str]:
    nb = json.loads(NOTEBOOK.read_text(encoding="utf-8"))
    assert nb["nbformat"] == 4
    cells = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert all(not c["outputs"] for c in cells), "commit the notebook without outputs"
    return ["".join(c["source"]) for c in cells]


def test_the_page_runs_in_order(monkeypatch, tmp_path) -> None:
    blocks = page_blocks()
    assert len(blocks) >= 8
    ns = _run_in_order(blocks, "python.md", monkeypatch, tmp_path)
    # what the page claims: the study's rows, evaluate's numbers and Stone Soup's OSPA agree
    assert ns["metrics"]["ospa"] < ns["naive_metrics"]["ospa"]
    assert len(ns["study"].trials) == 6 and ns["theirs"].mean() > 0


def test_the_notebook_runs_in_order(monkeypatch, tmp_path) -> None:
    cells = notebook_cells()
    assert {b.rstrip() for b in page_blocks()} <= {c.rstrip() for c in cells}, "the notebook walks the page's steps"
    ns = _run_in_order(cells, "walkthrough.ipynb", monkeypatch, tmp_path)
    assert len(ns["fig"].axes[0].lines) == 3
