"""``soabench results`` regenerates all of results/ in one command, every part resumable.

The protocol runs use the fake trial (tests/fake_trial.py) and no run figures; the occlusion density and the KITTI
export run real SUMO on tiny settings (one 10 s trial per scene, two 10 s sequences).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import fake_trial as ft
import numpy as np
import pytest
from shapely.geometry import box

import soabench.scenario
from soabench.cli.main import main
from soabench.config import FILTER_FAMILIES, Sensor
from soabench.experiment.campaigns import cross_scene
from soabench.experiment.campaigns.occlusion_density import scan_occlusion
from soabench.experiment.reports import paper
from soabench.experiment.runs.files import read_json

pytestmark = pytest.mark.slow  # `soabench results` with SUMO scenes

TINY = [
    "--scenes", "intersection,tjunction", "--trials", "2", "--duration", "10", "--births-trials", "1",
    "--scene-trials", "2", "--density-trials", "1", "--kitti-sequences", "2",
    "--kitti-duration", "10", "--kitti-folds", "2", "--atlas-scenes", "none", "--workers", "1", "--no-progress",
]  # fmt: skip


def _messages(err: str) -> list[str]:
    return [ln for ln in err.strip().splitlines() if not ln.startswith(("progress:", "soabench results:"))]


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    """One tiny ``soabench results`` run, then a second run on the finished folder (with counters)."""
    out = tmp_path_factory.mktemp("results") / "results"
    calls = {"trials": 0, "simulate": 0}
    real_simulate = soabench.scenario.simulate

    def counting_trial(*a, **k):
        calls["trials"] += 1
        return ft.fake_trial(*a, **k)

    def counting_simulate(*a, **k):
        calls["simulate"] += 1
        return real_simulate(*a, **k)

    with pytest.MonkeyPatch.context() as mp, ft.as_builtins(trial=counting_trial):
        import soabench.figures.results as plots

        mp.setattr(plots, "make_figures", lambda tables, folder: [])
        mp.setattr(soabench.scenario, "simulate", counting_simulate)
        first = main(["results", "--out", str(out), *TINY])
        first_calls = dict(calls)
        files = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()}
        calls.update(trials=0, simulate=0)
        second = main(["results", "--out", str(out), *TINY])
        after = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()}
    return SimpleNamespace(out=out, first=first, second=second, first_calls=first_calls, calls=calls,
                           files=files, after=after)  # fmt: skip


def test_one_command_writes_every_part(suite):
    out = suite.out
    assert suite.first == 0
    assert suite.first_calls["trials"] > 0 and suite.first_calls["simulate"] > 0
    for f in (
        "intersection/main/trials.csv",
        "intersection/clutter/sweep.md",
        "intersection/births/sweep.md",
        "intersection/sensitivity/gate_off/summary.json",
        "intersection/sensitivity/visible/summary.json",
        "intersection/sensitivity/sensitivity.md",
        "tjunction/main/trials.csv",
        "tjunction/clutter/sweep.md",
        "tjunction/births/sweep.md",
        "tjunction/sensitivity/sensitivity.md",
        "scenes/density/intersection.json",
        "scenes/density/tjunction.json",
        "scenes/summary.md",
        "scenes/summary.csv",
        "scenes/advantage_vs_occlusion.png",
        "kitti/intersection/export/label_02/0001.txt",
        "kitti/intersection/run/summary.json",
        "kitti/intersection/run/report.md",
        "filters/trials.csv",
        "filters-lmb-components/trials.csv",
    ):
        assert (out / f).is_file(), f
    families = read_json(out / "filters/run.json")["config"]
    assert families["experiment"]["filters"] == list(FILTER_FAMILIES)  # every family of the registry
    assert families["experiment"]["probabilities"] == ["static", "static+occ"]
    assert families["lmb"]["birth_mapping"] == "groups"
    ablation = read_json(out / "filters-lmb-components/run.json")["config"]
    assert ablation["experiment"]["filters"] == ["lmb"] and ablation["lmb"]["birth_mapping"] == "components"
    sens = out / "intersection/sensitivity"
    assert read_json(sens / "visible/run.json")["config"]["metrics"]["gt_set"] == "visible"
    assert read_json(sens / "gate_off/run.json")["config"]["filter"]["gate"] is False
    assert read_json(out / "tjunction/main/run.json")["config"]["experiment"]["trials"] == 2
    rows = paper.read_rows(out / "scenes" / "summary.csv")
    assert {r["scene"] for r in rows} == {"intersection", "tjunction"}
    assert len(rows) == 2 * 2 * len(cross_scene.BASELINES)  # scenes x modes x baselines
    for scene in ("intersection", "tjunction"):
        d = read_json(out / "scenes" / "density" / f"{scene}.json")
        assert 0.0 < d["occluded_sidewalk"] < 1.0 and d["scans"] == 10
        assert {r["occluded_sidewalk"] for r in rows if r["scene"] == scene} == {d["occluded_sidewalk"]}
    assert read_json(out / "kitti/intersection/export/export.json")["trials"] == 2


def test_index_pages_link_every_part(suite):
    """Every run folder has its report.html, each study and results/ an index.html linking the parts."""
    from soabench.experiment.reports.html import find_runs

    runs = find_runs(suite.out)
    every = {p.parent for p in suite.out.rglob("run.json")}
    assert set(runs) == {r for r in every if "kitti" not in r.parts} and len(runs) > 2 * 4
    assert all((r / "report.html").is_file() for r in runs)
    root = (suite.out / "index.html").read_text(encoding="utf-8")
    for scene in ("intersection", "tjunction"):
        assert f'href="{scene}/index.html"' in root and f'href="{scene}/main/report.html"' in root
        study = (suite.out / scene / "index.html").read_text(encoding="utf-8")
        assert 'href="main/report.html"' in study and 'href="births/points/ntot_001/report.html"' in study
    assert "kitti/intersection/run/" in root  # the KITTI protocol's report.md, shown as a part


def test_rerun_on_a_complete_folder_keeps_every_part(suite):
    """Nothing is simulated or run again and no file of a part changes; only the summary is redrawn (same bytes)."""
    assert suite.second == 0
    assert suite.calls == {"trials": 0, "simulate": 0}
    assert set(suite.after) == set(suite.files)
    changed = [p for p in suite.files if suite.after[p] != suite.files[p]]
    assert all(p.parent == suite.out / "scenes" for p in changed), changed


def test_other_settings_are_refused_in_one_line_before_any_work(suite, capsys, monkeypatch):
    def no_trial(*a, **k):
        raise AssertionError("a trial ran")

    argv = ["results", "--out", str(suite.out), *TINY, "--kitti-folds", "3"]
    with ft.as_builtins(trial=no_trial, loader=None):
        assert main(argv) == 2
    lines = _messages(capsys.readouterr().err)
    assert len(lines) == 1 and "folds: stored 2, requested 3" in lines[0], lines
    assert main(["results", "--out", str(suite.out), *TINY, "--scene-trials", "1"]) == 2
    lines = _messages(capsys.readouterr().err)
    assert len(lines) == 1 and "experiment.trials: stored 2, requested 1" in lines[0], lines


@pytest.mark.parametrize(
    ("flags", "needle"),
    [
        (["--scenes", "nowhere"], "--scenes nowhere: not a shipped scene"),
        (["--kitti-scenes", "atlantis"], "--kitti-scenes atlantis"),
        (["--kitti-sequences", "1"], "--kitti-sequences 1"),
        (["--scene-trials", "0"], "--scene-trials 0"),
        (["--duration", "-5"], "--duration -5.0"),
        (["--workers", "0"], "--workers 0"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, flags, needle):
    out = tmp_path / "res"
    assert main(["results", "--out", str(out), *flags]) == 2
    lines = _messages(capsys.readouterr().err)
    assert len(lines) == 1 and lines[0].startswith("soabench: error: ") and needle in lines[0], lines
    assert not out.exists() or not any(out.iterdir())


def test_ctrl_c_names_the_command_that_finishes(tmp_path, capsys, monkeypatch, fake_builtins):
    import soabench.experiment.campaigns.occlusion_density as od

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(od, "scene_density", interrupted)
    out = tmp_path / "res"
    argv = ["results", "--out", str(out), "--scenes", "grid_block", "--scene-trials", "1", "--duration", "5"]
    import soabench.figures.results as plots

    monkeypatch.setattr(plots, "make_figures", lambda tables, folder: [])
    assert main([*argv, "--workers", "1", "--no-progress", "--kitti-scenes", "none"]) == 130
    lines = _messages(capsys.readouterr().err)
    assert len(lines) == 1 and "grid_block occlusion density" in lines[0], lines
    assert f"finish with: soabench results --out {out.resolve()}" in lines[0]
    assert (out / "grid_block" / "main" / "summary.json").is_file()  # the finished part stays
    assert not (out / "scenes" / "density" / "grid_block.json").exists()  # no half-written file
    assert not (out / ".lock").exists()


# ------------------------------------------------------------------------------------------------ the table
def _rows(n: int, soa_better: int, scale: float = 1.0) -> list[dict]:
    """Synthetic trials.csv rows: S-OA's delay lower than PUBM's in the first ``soa_better`` of ``n`` trials,
    S-OA's cardinality error and OSPA ``scale`` times PUBM's."""
    rng = np.random.default_rng(3)
    rows = []
    for t in range(n):
        base_card, base_ospa = 2.0 + rng.random(), 40.0 + rng.random()
        for model, delay, card, ospa in (
            ("soa", 1.0 if t < soa_better else 2.0, scale * base_card, scale * base_ospa),
            ("pubm", 1.5, base_card, base_ospa),
        ):
            rows.append(
                {"trial": float(t), "clutter": 3.0, "mode": "static", "model": model, "delay_mean": delay,
                 "card_err": card, "ospa": ospa}
            )  # fmt: skip
    return rows


def test_cross_scene_table_from_synthetic_inputs():
    dens_a = {"occluded_sidewalk": 0.7, "occluded_sidewalk_se": 0.02, "occluded_pedestrians": 0.4}
    dens_b = {"occluded_sidewalk": 0.2, "occluded_sidewalk_se": math.nan, "occluded_pedestrians": 0.1}
    a = cross_scene.advantage_rows("dense", dens_a, _rows(40, 30, scale=0.8))
    b = cross_scene.advantage_rows("open", dens_b, _rows(40, 10, scale=1.1))
    assert [(r["mode"], r["baseline"]) for r in a] == [("static", "pubm")]
    ra, rb = a[0], b[0]
    assert (ra["delay_wins"], ra["delay_trials"], ra["delay_win_pct"]) == (30, 40, 75.0)
    assert (rb["delay_wins"], rb["delay_win_pct"]) == (10, 25.0)
    assert ra["card_reduction"] == pytest.approx(20.0) and ra["ospa_reduction"] == pytest.approx(20.0)
    assert rb["card_reduction"] == pytest.approx(-10.0)
    for r in (ra, rb):
        assert r["delay_win_ci_low"] <= r["delay_win_pct"] <= r["delay_win_ci_high"]
        assert r["card_ci_low"] <= r["card_reduction"] + 1e-9 and r["card_reduction"] <= r["card_ci_high"] + 1e-9
    assert ra["delay_p"] < 0.05 and ra["card_p"] < 1e-4
    md = cross_scene.markdown(a + b)
    assert md.index("| open |") < md.index("| dense |")  # scenes by increasing density
    assert "| dense | 70.0 ± 2.0 % | 40.0 % | 40 |" in md and "| open | 20.0 % | 10.0 % | 40 |" in md
    assert "| dense | PUBM | 75 % (30/40) [" in md and "| 20.0 % [" in md


class _Scans(SimpleNamespace):
    def __len__(self) -> int:
        return len(self.scans)


def test_density_of_a_scan_is_the_hidden_share_of_the_sidewalk_in_the_fov():
    sidewalk = box(0, 0, 10, 10)
    scan = SimpleNamespace(ego=np.array([5.0, 5.0, 0.0]), visible_region=box(0, 0, 10, 2.5))  # a quarter visible
    far = SimpleNamespace(ego=np.array([500.0, 500.0, 0.0]), visible_region=box(0, 0, 0, 0))  # no sidewalk in FOV
    in_fov = np.array([[True, True, True, False], [False, False, False, False]])
    visible = np.array([[True, False, False, False], [False, False, False, False]])
    scans = _Scans(scans=[scan, far], sensor=Sensor(), in_fov=in_fov, visible=visible)
    occ = scan_occlusion(scans, SimpleNamespace(sidewalk=sidewalk))
    in_view = 100.0 - math.pi * Sensor().r_min ** 2  # the FOV's inner hole (r < r_min) is not in view
    assert occ["shares"][0] == pytest.approx(1.0 - 25.0 / in_view, abs=1e-4)
    assert math.isnan(occ["shares"][1])
    assert (occ["in_fov"], occ["hidden"]) == (3, 2)


def test_results_command_is_listed_in_the_help(capsys):
    with pytest.raises(SystemExit):
        main(["results", "--help"])
    assert "--scene-trials" in capsys.readouterr().out


def test_a_study_is_kept_only_when_every_part_folder_is_complete(suite, tmp_path):
    """A part the study gained later (a run or sweep folder beside main/, clutter/, births/) must be complete too."""
    import shutil

    from soabench.experiment.campaigns.results_suite import Settings, study_kept

    root = tmp_path / "intersection"
    shutil.copytree(suite.out / "intersection", root)
    tiny = Settings(trials=2, duration=10.0, births_trials=1)
    assert study_kept(root, tiny)
    assert not study_kept(root, Settings(trials=3, duration=10.0, births_trials=1))  # more trials: resumed
    assert not study_kept(root, Settings(trials=2, duration=10.0, births_trials=2))
    (root / "sensitivity" / "visible" / "summary.json").unlink()  # the sensitivity part: two runs and its table
    assert not study_kept(root, tiny)
    shutil.copytree(suite.out / "intersection", root, dirs_exist_ok=True)
    assert study_kept(root, tiny)
    (root / "sensitivity" / "sensitivity.md").unlink()
    assert not study_kept(root, tiny)
    shutil.copytree(suite.out / "intersection", root, dirs_exist_ok=True)
    extra = root / "later_part"
    shutil.copytree(root / "main", extra)
    assert study_kept(root, tiny)
    (extra / "summary.json").unlink()
    assert not study_kept(root, tiny)


def test_a_part_made_with_other_models_is_refused_with_the_way_out(suite, tmp_path):
    """E.g. results committed before a sixth birth model joined the defaults: refused, never silently kept."""
    import json
    import shutil

    from soabench.errors import SoabenchError
    from soabench.experiment.campaigns.results_suite import Settings, _base_config, same_settings

    run = tmp_path / "main"
    shutil.copytree(suite.out / "tjunction" / "main", run)
    cfg = _base_config(Settings(duration=10.0), 2)
    assert same_settings(run, cfg) is True
    assert same_settings(run, _base_config(Settings(duration=10.0), 3)) is False  # more trials: extended
    meta = json.loads((run / "run.json").read_text())
    meta["config"]["experiment"]["models"] = ["soa", "pubm"]
    (run / "run.json").write_text(json.dumps(meta))
    with pytest.raises(SoabenchError, match=r"experiment.models: stored \['soa', 'pubm'\].*remove that folder"):
        same_settings(run, cfg)


def test_the_filters_part_is_kept_extended_or_refused(suite, tmp_path):
    """The families run: kept when complete with the settings, extended by more trials (its finished trials kept),
    refused when made with other families."""
    import json
    import shutil

    from soabench.errors import SoabenchError
    from soabench.experiment.campaigns.results_suite import Settings, _filters_part
    from soabench.experiment.execution.options import RunOptions
    from soabench.experiment.runs.files import read_csv

    part = tmp_path / "filters"
    shutil.copytree(suite.out / "filters", part)
    exe, log = RunOptions(workers=1, progress=False, figures=False), lambda msg: None
    with ft.as_builtins():
        assert _filters_part(part, Settings(trials=2, duration=10.0), exe, log) == ("kept", 0)
        before = read_csv(part / "trials.csv")
        assert _filters_part(part, Settings(trials=3, duration=10.0), exe, log) == ("done", 0)
    after = read_csv(part / "trials.csv")
    assert set(after["trial"]) == {0, 1, 2} and set(after["filter"]) == set(FILTER_FAMILIES)
    old = after["trial"] < 2
    assert list(after["ospa"][old]) == list(before["ospa"])  # the finished trials are kept as they were
    meta = json.loads((part / "run.json").read_text())
    meta["config"]["experiment"]["filters"] = ["gmphd"]
    (part / "run.json").write_text(json.dumps(meta))
    want = r"experiment.filters: stored \['gmphd'\], requested \['gmphd', 'lmb', 'pmbm'"
    with pytest.raises(SoabenchError, match=want):
        _filters_part(part, Settings(trials=3, duration=10.0), exe, log)


def test_study_companions_run_in_its_trials_and_resume(tmp_path, fake_builtins, monkeypatch):
    """A study with a companion folder (how ``soabench results`` runs its families folders): the companion holds
    what running it alone gives, its session says it ran in the study's group, and a companion that lost a trial
    is resumed by the next study call. (That a shared trial equals one run alone is tests/equivalence/
    test_work_once.py's.)"""
    import soabench.figures.results as plots
    from soabench.config import Config, ExperimentConfig
    from soabench.experiment.campaigns.study import Companion, run_study
    from soabench.experiment.execution.options import RunOptions
    from soabench.experiment.reports.finished import run_experiment

    monkeypatch.setattr(plots, "make_figures", lambda tables, folder: [])

    def config(**exp) -> Config:
        base = dict(trials=2, duration=5.0, models=("soa", "pubm"), probabilities=("static",), seed=4)
        return Config(experiment=ExperimentConfig(**{**base, **exp})).validate()

    options = RunOptions(workers=1, progress=False, figures=False)
    families = config(filters=("gmphd", "pmbm"))
    companion = Companion(tmp_path / "filters", families, ("experiment.trials", "experiment.filters"))
    study = dict(births_trials=1, options=options, companions=(companion,))
    o = run_study(config(probabilities=("static", "dynamic")), "intersection", out=tmp_path / "study", **study)
    assert o.complete and len(o.companions) == 1 and o.companions[0].complete
    run_experiment(families, "intersection", out=tmp_path / "alone", options=options)
    tables = ("trials.csv", "episodes.csv", "steps.csv")
    ref = {t: (tmp_path / "alone" / t).read_text() for t in tables}
    assert {t: (companion.folder / t).read_text() for t in tables} == ref
    (session,) = (companion.folder / "sessions").iterdir()
    assert "grouped" in read_json(session)["executor"]

    (companion.folder / "trials" / "trial_00001.json").unlink()
    for t in (*tables, "summary.json"):
        (companion.folder / t).unlink()
    o = run_study(config(probabilities=("static", "dynamic")), "intersection", out=tmp_path / "study", **study)
    assert o.companions[0].complete and o.companions[0].n_done == 2
    assert len(list((companion.folder / "sessions").iterdir())) == 2
    assert {t: (companion.folder / t).read_text() for t in tables} == ref
