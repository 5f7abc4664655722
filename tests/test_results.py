"""The committed results are exactly what `soabench study` produces for its seeds (issue 8).

Re-runs a small slice (a few trials, a few birth models) of each committed part with the configuration stored in
its run folder and compares every metric column with the committed CSV, character for character. A filter run
does not depend on which other filters share its trial (common random numbers, §5.8), so a slice reproduces the
rows of the full run.
"""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import pytest

from soabench.config import Config
from soabench.experiment.store import TRIAL_COLUMNS, format_value
from soabench.experiment.trial import run_trial
from soabench.scenario import load

RESULTS = Path(__file__).parents[1] / "results" / "intersection"


def _committed(run_dir: Path) -> dict[tuple, dict]:
    with open(run_dir / "trials.csv", newline="") as fh:
        return {(r["trial"], r["clutter"], r["model"], r["mode"]): r for r in csv.DictReader(fh)}


def _rerun(run_dir: Path, trials, models, modes) -> list[dict]:
    meta = json.loads((run_dir / "run.json").read_text())
    cfg = Config.from_dict(meta["config"]).validate()
    cfg.experiment = dataclasses.replace(cfg.experiment, models=tuple(models), probabilities=tuple(modes))
    scene, scenario = load(meta["net"], tuple(meta["polys"]), meta["scenario"])
    return [row for t in trials for row in run_trial(t, cfg, scene, scenario).rows]


def _assert_reproduced(run_dir: Path, trials, models, modes) -> None:
    committed = _committed(run_dir)
    rows = _rerun(run_dir, trials, models, modes)
    assert len(rows) == len(trials) * len(models) * len(modes) * len(
        json.loads((run_dir / "run.json").read_text())["config"]["experiment"]["clutter"]
    )
    for row in rows:
        key = tuple(format_value(row[k]) for k in ("trial", "clutter", "model", "mode"))
        assert key in committed, key
        for col in TRIAL_COLUMNS:
            assert format_value(row[col]) == committed[key][col], (key, col)


def test_committed_study_is_complete():
    for part in ("main", "clutter/points/clutter"):
        assert (RESULTS / part / "trials.csv").is_file(), part
    assert (RESULTS / "births" / "sweep.md").is_file()
    assert (RESULTS / "comparison.md").is_file()
    assert len(_committed(RESULTS / "main")) == 100 * 5 * 2


@pytest.mark.parametrize(("trials", "models"), [((0,), ("soa", "atbm")), ((57,), ("pubm", "ubm", "gmbm"))])
def test_main_protocol_rows_are_reproduced(trials, models):
    _assert_reproduced(RESULTS / "main", trials, models, ("static", "dynamic"))


def test_clutter_sweep_rows_are_reproduced():
    _assert_reproduced(RESULTS / "clutter" / "points" / "clutter", (3,), ("soa", "atbm"), ("static",))


def test_births_sweep_point_is_reproduced():
    point = sorted((RESULTS / "births" / "points").iterdir())[0]
    _assert_reproduced(point, (1,), ("soa",), ("static",))


def test_results_readme_tables_are_the_generated_ones():
    readme = (RESULTS.parent / "README.md").read_text(encoding="utf-8")
    section = readme.split("## Paper vs soabench", 1)[1].split("Component counts relative to S-OA", 1)[0]
    generated = (RESULTS / "comparison.md").read_text(encoding="utf-8")
    table_lines = [ln for ln in section.splitlines() if ln.startswith("|")]
    assert len(table_lines) > 30
    assert [ln for ln in table_lines if ln not in generated] == []
