"""docs/api.md is the reference of ``soabench.api``, generated from its docstrings, and every public function's
example runs and prints what it says."""

from __future__ import annotations

import doctest
import inspect
import os

import pytest

import soabench.api as sb

FUNCTIONS = [name for name in sb.__all__ if inspect.isfunction(getattr(sb, name))]


def test_every_public_function_has_an_example_on_the_reference_page() -> None:
    from repo_paths import ROOT

    page = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    for name in FUNCTIONS:
        doc = inspect.getdoc(getattr(sb, name)) or ""
        assert "Example:" in doc and ">>> " in doc, f"soabench.api.{name} has no example in its docstring"
        assert f"### `{name}`" in page and f"sb.{name}(" in page, f"docs/api.md lacks {name}: python docs/hooks.py"


@pytest.fixture(scope="module")
def sumo_loaded() -> None:
    """SUMO loaded once before the examples run: what it prints when first loaded (a libsumo build may warn about
    its pyarrow) is not an example's output."""
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        sb.simulate_trial("arterial", duration=1)


@pytest.mark.slow
@pytest.mark.parametrize("name", FUNCTIONS)
def test_the_example_of_each_public_function_runs(name: str, tmp_path, sumo_loaded) -> None:
    if "stonesoup" in (inspect.getdoc(getattr(sb, name)) or ""):
        pytest.importorskip("stonesoup")
    import matplotlib

    matplotlib.use("Agg")
    test = doctest.DocTestFinder(recurse=False).find(getattr(sb, name), name, globs={})[0]
    # verbose=False: doctest reads "-v" from sys.argv, and pytest -v would report every passing example as a failure
    runner = doctest.DocTestRunner(verbose=False, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    cwd = os.getcwd()
    os.chdir(tmp_path)  # an example that saves a file saves it here
    try:
        runner.run(test, out=lambda text: pytest.fail(text))
    finally:
        os.chdir(cwd)
    assert runner.failures == 0 and runner.tries > 1
