"""What a reader trips on in a short run: a run that observes nobody says how long to run instead, and summary.md
defines its terms with the values used."""

from __future__ import annotations

import json
import re

import pytest

from soabench.cli.main import main


def _run(tmp_path, name: str, duration: float, *extra: str) -> dict:
    out = tmp_path / name
    args = ["run", "--trials", "1", "--duration", f"{duration:g}", "--models", "soa", "--probabilities", "static",
            "--workers", "1", "--no-progress", "--out", str(out), *extra]  # fmt: skip
    assert main(args) == 0
    return {"summary": json.loads((out / "summary.json").read_text()), "md": (out / "summary.md").read_text()}


@pytest.mark.slow
def test_unobserved_run_names_the_shortest_useful_duration_and_it_is(tmp_path):
    """10 s of the default scene observe nobody; the warning says from the scene when somebody becomes observable,
    and a run of the suggested duration does observe somebody."""
    short = _run(tmp_path, "short", 10)
    (warning,) = short["summary"]["warnings"]
    found = re.search(r"first pedestrian becomes observable .* at t = ([\d.]+) s .* about ([\d.]+) s", warning)
    assert found, warning
    first, shortest = float(found.group(1)), float(found.group(2))
    assert 10 <= first < shortest
    assert warning in short["md"]
    assert not _run(tmp_path, "long", shortest)["summary"]["warnings"]


@pytest.mark.slow
def test_summary_legend_defines_censored_and_the_cut_offs_used(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[metrics]\nospa_c = 40.0\ngospa_c = 3.0\n")
    md = _run(tmp_path, "run", 2, "--config", str(cfg))["md"]
    (legend,) = [ln for ln in md.splitlines() if ln.startswith("Legend:")]
    assert "**censored** counts detection episodes" in legend and 'metrics.censored = "exclude"' in legend
    assert "**OSPA** (§5.2): cut-off c = 40 m, order p = 1" in legend
    assert "**GOSPA** (§5.6): cut-off c = 3 m, order p = 1" in legend
