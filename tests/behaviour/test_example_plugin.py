"""The example plugin package (examples/soabench-example-plugin) installs with pip and runs through its entry points.

The package is built without build isolation and without dependencies into a private folder (the current
environment stays as it was), then ``soabench run`` in a fresh interpreter with that folder on PYTHONPATH finds the
birth model ``edge`` and the tracker ``nnkf`` by entry point only: no import path is typed.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from repo_paths import ROOT

pytestmark = pytest.mark.slow  # pip-installs the example plugin, then real runs

EXAMPLE = ROOT / "examples" / "soabench-example-plugin"


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("example_plugin")
    src = tmp / "src"
    shutil.copytree(EXAMPLE, src, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    target = tmp / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--no-build-isolation", "--no-deps", "--target", str(target),
         str(src)],
        check=True,
        capture_output=True,
        text=True,
    )  # fmt: skip
    assert (target / "soabench_example_plugin" / "tracker.py").is_file()
    return target


def _env(site: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def _other_plugin(site: Path) -> Path:
    """Another installed soabench plugin (distribution metadata only), whose names sort after the example's."""
    info = site / "zz_other_plugin-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: zz-other-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[soabench.birth_models]\nzz_birth = zz_other:Birth\n[soabench.trackers]\nzz_tracker = zz_other:Tracker\n"
    )
    return site


@pytest.mark.parametrize("others", [False, True], ids=["alone", "beside-another-plugin"])
def test_entry_points_are_found(installed, tmp_path, others) -> None:
    """The example's entry points are found and resolve to its classes, whatever else the user has installed."""
    code = (
        "from soabench import plugins; "
        "print('edge' in plugins.names(plugins.BIRTH), 'nnkf' in plugins.names(plugins.TRACKER), "
        "'zz_tracker' in plugins.names(plugins.TRACKER), plugins.resolve(plugins.TRACKER, 'nnkf').__module__, "
        "plugins.resolve(plugins.BIRTH, 'edge').__module__)"
    )
    env = _env(installed)
    if others:
        env["PYTHONPATH"] = os.pathsep.join([env["PYTHONPATH"], str(_other_plugin(tmp_path / "other"))])
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    found = ["True", "True", str(others), "soabench_example_plugin.tracker", "soabench_example_plugin.births"]
    assert out.stdout.split() == found


def test_example_plugins_run_beside_soa(installed, tmp_path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text("[plugins.nnkf]\nm = 2\nn = 3\n[plugins.edge]\nn_arc = 24\n")
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "soabench.cli", "run", "--models", "soa,edge", "--trackers", "nnkf",
           "--probabilities", "static", "--trials", "1", "--duration", "25", "--workers", "1", "--config", str(cfg),
           "--out", str(out), "--no-progress"]  # fmt: skip
    proc = subprocess.run(cmd, env=_env(installed), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["model_failures"] == []
    stats = {s["model"]: s for s in summary["results"][0]["models"]}
    assert set(stats) == {"soa", "edge", "nnkf"}
    # the NN tracker really tracks: some of its confirmed estimates lie near true pedestrians
    assert stats["nnkf"]["n_trials"] == 1
    assert {c["baseline"] for c in summary["results"][0]["vs_soa"]} == {"edge", "nnkf"}
    from soabench.experiment.runs.files import read_csv

    steps = read_csv(out / "steps.csv")
    nn = steps["model"] == "nnkf"
    assert nn.sum() == 25 and steps["tp"][nn].sum() > 0 and np.all(steps["n_est"][nn] >= steps["tp"][nn])
    assert "| nnkf | static | 1 |" in (out / "summary.md").read_text(encoding="utf-8")  # the full tables
    assert "nnkf" in proc.stdout and f"open {out / 'report.html'}" in proc.stdout  # the printed headline
