"""Every command writes only into a folder of its own (new, empty, or holding nothing but its own files), names read
from files are names, never paths, values written into TOML parse back, and every size a user can type is bounded
before any work (docs/user-guide/folders.md)."""

from __future__ import annotations

import shutil
import sys
import time
from pathlib import Path

import bad_inputs
import pytest
from hypothesis import given
from hypothesis import strategies as st
from repo_paths import DATA

import soabench.scenario.osm as osm
from soabench.cli.main import main
from soabench.tomlfile import tomllib


def _one_error(capsys) -> str:
    lines = bad_inputs.messages(capsys.readouterr().err)
    assert len(lines) == 1 and lines[0].startswith("soabench: error: "), lines
    return lines[0]


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# ------------------------------------------------------------------------------------------ folders not ours
def test_import_osm_into_an_existing_scene_folder_overwrites_nothing(tmp_path, capsys, no_work):
    """The reported loss: README.md, the .net.xml and buildings.poly.xml of an existing folder were replaced."""
    theirs = tmp_path / "crossroads"
    theirs.mkdir()
    for name in ("README.md", "crossroads.net.xml", "buildings.poly.xml"):
        (theirs / name).write_text(f"their {name}\n")
    before = _snapshot(theirs)
    assert main(["import", "osm", str(DATA / "crossroads.osm"), "--out", str(theirs)]) == 2
    assert "not empty" in _one_error(capsys)
    assert _snapshot(theirs) == before and not no_work


@pytest.mark.parametrize("command", ["study", "kitti", "export", "check", "import", "results"])
def test_no_command_writes_into_a_foreign_folder(tmp_path, capsys, monkeypatch, no_work, command):
    monkeypatch.chdir(tmp_path)
    theirs = bad_inputs._foreign(tmp_path)
    (theirs / "data").mkdir()
    (theirs / "data" / "x.csv").write_text("1,2\n")
    before = _snapshot(theirs)
    argv = bad_inputs._out_is(command, lambda t: str(theirs))(tmp_path)
    assert main(argv) == 2
    assert "not empty" in _one_error(capsys)
    assert _snapshot(theirs) == before and sorted(p.name for p in theirs.iterdir()) == [
        "README.md",
        "data",
        "notes.txt",
    ]
    assert not no_work


def test_sensitivity_refuses_a_foreign_folder_and_the_main_run_itself(tmp_path, capsys, no_work):
    argv = bad_inputs._sensitivity(tmp_path, str(bad_inputs._foreign(tmp_path)))
    main_before = _snapshot(tmp_path / "main")
    assert main(argv) == 2 and "not empty" in _one_error(capsys)
    argv[argv.index("--out") + 1] = str(tmp_path / "main")
    assert main(argv) == 2 and "is not a sensitivity folder" in _one_error(capsys)
    assert _snapshot(tmp_path / "main") == main_before


def test_a_check_folder_of_its_own_is_reused(tmp_path, capsys, no_work):
    """A check folder holding only check.json, junit.xml and runs/ is the command's own (CI re-runs into it)."""
    out = tmp_path / "check-results"
    (out / "runs" / "a" / "seed_0").mkdir(parents=True)
    (out / "check.json").write_text("{}")
    suite = bad_inputs._suite(tmp_path, bad_inputs.GOOD_SCENARIO)
    with pytest.raises(bad_inputs.WorkStarted):  # accepted: it got as far as the first trial
        main(["check", "--suite", suite, "--out", str(out)])
    assert not (out / ".lock").exists()


def test_study_reruns_in_its_own_folder(tmp_path, no_work):
    out = tmp_path / "study"
    (out / "main").mkdir(parents=True)
    (out / "comparison.md").write_text("x")
    argv = ["study", "--trials", "1", "--births-trials", "1", "--duration", "5", "--workers", "1", "--out", str(out)]
    with pytest.raises(bad_inputs.WorkStarted):
        main(argv)


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["record", "--out", "r.npz", "--scans", "r.npz"], "is the --out file"),
        (["record", "--out", "r.npz", "--scans", "./r.npz"], "is the --out file"),
        (["record", "--out", "r.npz", "--scans", "s.png"], "must end in .npz"),
        (["scene", "--out", "x.xyz"], "must end in .png"),
        (["birth", "--out", "x.npz"], "must end in .png"),
        (["record", "--out", "x.png"], "must end in .npz"),
        (["run", "--out", ""], "--out '' is empty"),
        (["run", "--out="], "--out '' is empty"),
        (["kitti", "--root", "", "--out", "k"], "--root '' is empty"),
    ],
)
def test_output_files_and_empty_paths(tmp_path, capsys, monkeypatch, no_work, argv, needle):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "keep.txt").write_text("x")
    assert main(argv) == 2 and needle in _one_error(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"] and not no_work


def test_usage_errors_are_one_line(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", "--trials", "x"])
    assert exc.value.code == 2
    line = _one_error(capsys)
    assert "run: argument --trials: invalid int value: 'x'" in line and "soabench run --help" in line


# ------------------------------------------------------------------------------------------ names from data
@pytest.mark.parametrize("name", ["../../../../x", "/tmp/soabench-abs", "a/b", "..", "", ".hidden", "a\\b", "x" * 101])
def test_check_scenario_names_are_names_never_paths(tmp_path, capsys, no_work, name):
    out = tmp_path / "deep" / "er" / "check"
    scenario = f'[[scenario]]\nname = "{name}"\nnet = "intersection"\n'
    suite = bad_inputs._suite(tmp_path, scenario)
    assert main(["check", "--suite", suite, "--out", str(out)]) == 2
    assert "is not a plain name" in _one_error(capsys)
    assert not out.exists() and not (tmp_path / "x").exists() and not Path("/tmp/soabench-abs").exists()


def test_check_scenario_names_that_are_plain_pass():
    from soabench.experiment.campaigns.check import SCENARIO_NAME

    assert all(SCENARIO_NAME.fullmatch(n) for n in ("intersection-static", "a.b_c-1", "X"))


@given(st.text(max_size=40))
def test_toml_string_parses_back_to_the_same_text(text):
    assert tomllib.loads(f"k = {osm.toml_string(text)}")["k"] == text


@pytest.mark.parametrize("name", ['evil".osm', "back\\slash.osm", "new\nline.osm", "../up.osm", "é t.osm"])
def test_scenario_toml_of_an_odd_file_name_parses(name):
    from types import SimpleNamespace

    from soabench.scenario import ScenarioConfig

    stem = osm.file_stem(name)
    assert "/" not in stem and "\\" not in stem and not stem.startswith(".")
    cfg = ScenarioConfig(net_file=f"{stem}.net.xml", poly_files=[], name=stem, pedestrian_model="striping")
    cfg.world_box = (0.0, 0.0, 10.0, 10.0)
    text = osm.scenario_toml(cfg, SimpleNamespace(doors=[(1.0, 2.0)]), f"{stem}.net.xml", "b.poly.xml", name)
    data = tomllib.loads(text)
    assert data["scenario"]["description"].endswith(name) and data["files"]["net"] == f"{stem}.net.xml"


def test_import_of_evil_quote_osm_makes_a_scene_that_loads(tmp_path, capsys):
    """The reported file: ``evil".osm`` imported into a scenario.toml that did not parse."""
    from soabench.scenario import load

    evil = tmp_path / 'evil".osm'
    shutil.copy(DATA / "crossroads.osm", evil)
    out = tmp_path / "scene"
    assert main(["import", "osm", str(evil), "--out", str(out)]) == 0
    toml = tomllib.loads((out / "scenario.toml").read_text())
    assert toml["scenario"]["name"] == "evil_" and 'evil".osm' in toml["scenario"]["description"]
    scene, _ = load(str(out))
    assert len(scene.buildings) == 2
    err = capsys.readouterr().err
    assert "crossroads" not in err and "edges" in err and "lanes" in err  # what the scene costs, said
    assert sorted(p.name for p in tmp_path.iterdir()) == ['evil".osm', "scene"]  # no temporary folder left


# ------------------------------------------------------------------------------------------ bounded work
@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["kitti", "--root", "R", "--out", "o", "--nhat-sweep", "-1000000:1000000"], "at most 1001 values"),
        (["sweep", "births", "--offsets", "0:1000000000", "--out", "o"], "at most 1001 values"),
        (["export", "kitti", "--trials", "1000000", "--out", "o"], "[1, 10000]"),
        (["kitti", "--root", "R", "--out", "o", "--sequences", "0000-99999999"], "at most 10000"),
    ],
)
def test_sizes_are_bounded_before_any_work(tmp_path, capsys, monkeypatch, no_work, argv, needle):
    monkeypatch.chdir(tmp_path)
    bad_inputs._kitti_root(tmp_path)
    argv = [str(tmp_path / "kitti") if a == "R" else a for a in argv]
    t0 = time.monotonic()
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    line = _one_error(capsys)
    assert code == 2 and needle in line and len(line) < 400 and time.monotonic() - t0 < 10
    assert not no_work


def test_a_large_osm_file_is_refused_with_its_counts_unless_forced(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(osm, "MAX_OSM_MB", 0.001)
    assert main(["import", "osm", str(DATA / "crossroads.osm"), "--out", str(tmp_path / "a")]) == 2
    line = _one_error(capsys)
    assert "nodes" in line and "roads" in line and "buildings" in line and "--force" in line
    assert not (tmp_path / "a").exists()
    monkeypatch.setattr(osm, "PROGRESS_EVERY_S", 0.01)  # a progress line while netconvert runs
    assert main(["import", "osm", str(DATA / "crossroads.osm"), "--out", str(tmp_path / "a"), "--force"]) == 0
    err = capsys.readouterr().err
    assert "still running" in err and "netconvert built" in err and (tmp_path / "a" / "scenario.toml").is_file()


def test_osm_counts_stream_the_file(tmp_path):
    counts = osm.check_osm(DATA / "crossroads.osm")
    assert counts.roads >= 2 and counts.walkable >= 1 and counts.buildings == 2 and counts.nodes > 4


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__, "-q"]))
