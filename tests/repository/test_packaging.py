"""Only ``soabench`` is installed at the top level; baselines/ and sumo_nets/ are soabench.baselines, soabench.nets."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from repo_paths import ROOT

import soabench.baselines
import soabench.nets
from soabench.birth import get_birth_model
from soabench.plugins import BUILTIN_BIRTH_MODELS
from soabench.scenario import shipped_nets

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def test_every_package_folder_is_installed():
    """A new subpackage under soabench/ must be added to pyproject's explicit package list."""
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "soabench").rglob("__init__.py")}
    assert found - listed == set()
    assert PYPROJECT["tool"]["setuptools"]["package-dir"] == {
        "soabench.baselines": "baselines",
        "soabench.nets": "sumo_nets",
    }
    assert {p.split(".")[0] for p in listed} == {"soabench"}


def test_every_shipped_network_is_listed():
    """A shipped network's folder (data files only) is a folder Python could import: pyproject lists it, so that
    setuptools does not warn that it would be left out of the packages (its files are soabench.nets' data)."""
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    nets = [d.name for d in (ROOT / "sumo_nets").iterdir() if d.is_dir() and not d.name.startswith("__")]
    folders = {f"soabench.nets.{name}" for name in nets if name.isidentifier()}
    assert folders and folders - listed == set()
    assert {n.removeprefix("soabench.nets.") for n in folders} >= set(shipped_nets())


def test_subpackages_are_the_repository_folders():
    assert Path(soabench.baselines.__file__).parent.name == "baselines"
    assert Path(soabench.nets.__file__).parent.name == "sumo_nets"
    assert "intersection" in shipped_nets()
    for name, target in BUILTIN_BIRTH_MODELS.items():
        assert get_birth_model(name).__module__ == target.split(":")[0]


def test_no_top_level_baselines_from_this_project(tmp_path):
    """`import baselines` / `import sumo_nets` must not find this project's folders (outside a checkout's root)."""
    code = (
        "import importlib.util as u\n"
        "for name in ('baselines', 'sumo_nets'):\n"
        "    s = u.find_spec(name)\n"
        "    print(s.origin if s else '')\n"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert str(ROOT) not in done.stdout


@pytest.mark.slow
def test_wheel_holds_only_soabench_with_its_nets(tmp_path):
    """The non-editable install path (`pip install .` builds this wheel): one top-level package, the nets inside."""
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".git", "results", "build", "*.egg-info", "__pycache__"))
    cmd = [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path), "."]
    done = subprocess.run(cmd, cwd=src, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    (wheel,) = tmp_path.glob("soabench-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")} == {"soabench"}
    for needed in (
        "soabench/baselines/adaptive.py",
        "soabench/nets/intersection/intersection.net.xml",
        "soabench/nets/intersection/scenario.toml",
        "soabench/nets/intersection/buildings.poly.xml",
    ):
        assert needed in names
