"""Work done once: the shared paths give exactly the results of the paths that recompute.

* births of a mode-free model (S-OA, UBM, UBM (workspace), GMBM) computed once per scan and shared by every
  probability mode, clutter rate and N̂ (weight-free candidates, weighed per N̂) vs one birth model per run;
* a :class:`TrialShare` across configs (the study's main run, clutter sweep and N̂ sweep) vs each config alone;
* an N̂ sweep whose points run together (one SUMO run per trial) vs point after point, and its resume.

Every comparison is over every non-timing column (trials.csv holds no timing column; t_* are in the rows only).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from soabench import plugins
from soabench.config import Config, ExperimentConfig
from soabench.experiment.campaigns.sweep import run_sweep, scans_per_run
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.runs.files import read_csv
from soabench.experiment.trial.trial import ROW_TIME_KEYS, TrialShare, run_trial

pytestmark = pytest.mark.slow  # real trials, shared and recomputed

MODELS = ("soa", "pubm", "ubm", "ubm-ws", "atbm", "gmbm")
MODE_FREE = {"soa", "ubm", "ubm-ws", "gmbm"}


@pytest.fixture(scope="module")
def intersection():
    from soabench.scenario import load

    return load("intersection")


def config(**exp) -> Config:
    base = dict(duration=8.0, models=MODELS, probabilities=("static", "dynamic"), clutter=(3.0,), seed=11)
    return Config(experiment=ExperimentConfig(**{**base, **exp})).validate()


def results(res) -> tuple:
    """Everything a trial writes except wall-clock times."""
    rows = [{k: v for k, v in r.items() if k not in ROW_TIME_KEYS} for r in res.rows]
    return repr(rows), repr(res.episodes), repr(res.steps)


def counting_factory(calls: dict[str, int]):
    """The built-in birth models, counting their calls per model name (mode_free and the rest inherited)."""

    def factory(name: str) -> type:
        base = plugins.resolve(plugins.BIRTH, name)

        if hasattr(base, "candidates"):  # a mode-free model's births are its weight-free candidates, weighed

            class Counted(base):
                def candidates(self, ctx):
                    calls[name] = calls.get(name, 0) + 1
                    return super().candidates(ctx)

        else:

            class Counted(base):
                def __call__(self, ctx):
                    calls[name] = calls.get(name, 0) + 1
                    return super().__call__(ctx)

        return Counted

    return factory


def test_mode_free_births_are_the_ones_that_read_only_the_scan():
    for name in MODELS:
        cls = plugins.resolve(plugins.BIRTH, name)
        assert bool(getattr(cls, "mode_free", False)) == (name in MODE_FREE), name


def test_births_once_equal_births_per_mode(intersection):
    scene, scenario = intersection
    cfg = config(probabilities=("static", "dynamic", "dynamic+occ"), clutter=(0.5, 5.0))
    once: dict[str, int] = {}
    per_mode: dict[str, int] = {}
    a = run_trial(1, cfg, scene, scenario, birth_factory=counting_factory(once))
    b = run_trial(1, cfg, scene, scenario, birth_factory=counting_factory(per_mode), births_once=False)
    assert results(a) == results(b)
    K = int(round(cfg.experiment.duration / cfg.sensor.dt))
    n_lam, n_modes = 2, 3
    for name in MODELS:  # a mode-free model's candidates once per scan for every lambda and mode; the rest per run
        assert per_mode[name] == n_lam * n_modes * K, name
        assert once[name] == (K if name in MODE_FREE else n_lam * n_modes * K), name


def test_share_across_configs_equals_each_config_alone(intersection):
    scene, scenario = intersection
    main = config(models=("soa", "pubm", "atbm"))
    clutter = config(models=("soa", "pubm", "atbm"), clutter=(0.5, 3.0))
    births = dataclasses.replace(main)
    births.birth = dataclasses.replace(main.birth, N_hat=0.05)
    births.experiment = dataclasses.replace(main.experiment, probabilities=("static",))
    alone = [run_trial(2, c, scene, scenario) for c in (main, clutter, births)]
    share = TrialShare()
    shared = [run_trial(2, c, scene, scenario, share=share) for c in (main, clutter, births)]
    for x, y in zip(alone, shared, strict=True):
        assert results(x) == results(y)
    c = share.counts
    assert c["recording"] == 1 and c["recording_reused"] == 2  # SUMO once for the three configs
    assert c["scans"] == 2 and c["scans_reused"] == 2  # lambda = 3 observed once, lambda = 0.5 once
    assert c["runs_reused"] == 3 * 2  # the clutter config's lambda = 3 runs are the main config's
    assert c["runs"] == 6 + 6 + 3  # another N_hat is another filter run
    # S-OA's weight-free candidates once per scan for lambda = 0.5 and 3 and both N_hat (only weighed per config)
    K = int(round(main.experiment.duration / main.sensor.dt))
    assert c["birth_candidates"] == K and c["birth_candidates_reused"] == 2 * K


def test_sensitivity_variants_share_the_recording_and_rescore_the_filter_runs(intersection):
    """The study's sensitivity runs in one share with the main run: the gate-off run reuses the recording and the
    scans; the visible-truth run (another metrics config only) scores the main run's filter runs again instead of
    running the filters, with exactly the results of running it alone."""
    from soabench.experiment.execution.grouped import rescored
    from soabench.experiment.execution.runner import TaskSpec
    from soabench.experiment.runs.runmeta import RunMeta

    scene, scenario = intersection
    main = config(models=("soa", "pubm"))
    gate_off = dataclasses.replace(main, filter=dataclasses.replace(main.filter, gate=False))
    visible = dataclasses.replace(main, metrics=dataclasses.replace(main.metrics, gt_set="visible"))
    configs = (main, gate_off, visible)
    spec = lambda c: TaskSpec(RunMeta(c, "intersection", (), None, False, 1, "soabench", "sumo"))  # noqa: E731
    assert rescored([spec(main), spec(visible)]) and not rescored([spec(main), spec(gate_off)])
    alone = [run_trial(1, c, scene, scenario) for c in configs]
    share = TrialShare(keep_filter_runs=True)
    shared = [run_trial(1, c, scene, scenario, share=share) for c in configs]
    for x, y in zip(alone, shared, strict=True):
        assert results(x) == results(y)
    assert results(alone[0]) != results(alone[2])  # the truth set does change the scores
    c = share.counts
    assert c["recording"] == 1 and c["recording_reused"] == 2 and c["scans"] == 1 and c["scans_reused"] == 2
    assert c["runs"] == 4 + 4 and c["runs_rescored"] == 4  # main and gate-off run the filters, visible scores


def test_a_families_folder_scores_the_default_folders_gmphd_runs(intersection):
    """A folder that names the GM-PHD among several families (``soabench results``'s ``filters/``) beside a
    default-family folder of the same filter config (the study's main run): its GM-PHD runs are the default folder's
    filter runs, scored again under its own key (rows with the ``filter`` column), with exactly the results of
    running it alone; a folder with another filter config runs its own."""
    from soabench.experiment.execution.grouped import rescored
    from soabench.experiment.execution.runner import TaskSpec
    from soabench.experiment.runs.runmeta import RunMeta

    scene, scenario = intersection
    main = config(models=("soa", "pubm"), probabilities=("static",))
    families = config(models=("soa", "pubm"), probabilities=("static",), filters=("gmphd", "lmb"))
    lmb_only = config(models=("soa", "pubm"), probabilities=("static",), filters=("lmb",))
    gate_off = dataclasses.replace(families, filter=dataclasses.replace(families.filter, gate=False))
    spec = lambda c: TaskSpec(RunMeta(c, "intersection", (), None, False, 1, "soabench", "sumo"))  # noqa: E731
    assert rescored([spec(main), spec(families)])
    assert not rescored([spec(main), spec(lmb_only)]) and not rescored([spec(main), spec(gate_off)])
    alone = [run_trial(1, c, scene, scenario) for c in (main, families)]
    share = TrialShare(keep_filter_runs=True)
    shared = [run_trial(1, c, scene, scenario, share=share) for c in (main, families)]
    for x, y in zip(alone, shared, strict=True):
        assert results(x) == results(y)
    assert all(r["filter"] in ("gmphd", "lmb") for r in shared[1].rows)
    c = share.counts
    assert c["runs"] == 2 + 2 and c["runs_rescored"] == 2  # the families folder runs its LMB, scores the GM-PHD


def _csvs(run_dir: Path) -> dict[str, str]:
    """The result files as text (they hold no wall-clock column: those are in timing.csv)."""
    out = {name: (run_dir / name).read_text() for name in ("trials.csv", "episodes.csv", "steps.csv")}
    assert "t_birth" not in out["trials.csv"] and len(read_csv(run_dir / "trials.csv")["trial"]) > 0
    return out


def _same(a: dict, b: dict) -> bool:
    return a == b


def test_grouped_births_sweep_equals_point_by_point_and_resumes(tmp_path):
    cfg = config(models=("soa", "pubm", "ubm"), probabilities=("static",), trials=2, duration=6.0)
    options = RunOptions(workers=1, progress=False, figures=False)
    kw = dict(options=options, n_true=2)
    run_sweep("births", (-1, 0), cfg, "intersection", out=tmp_path / "grouped", **kw)
    run_sweep("births", (-1, 0), cfg, "intersection", out=tmp_path / "serial", grouped=False, **kw)
    points = ("ntot_001", "ntot_002")
    ref = {p: _csvs(tmp_path / "serial" / "points" / p) for p in points}
    for p in points:
        pdir = tmp_path / "grouped" / "points" / p
        assert _same(_csvs(pdir), ref[p]), p
        (session,) = (pdir / "sessions").iterdir()
        assert json.loads(session.read_text())["trials_run"] == 2
    assert (tmp_path / "grouped" / "sweep.md").is_file()

    # a killed sweep: point ntot_002 lost trial 1; the resume runs that trial alone and the folders are as before
    gone = tmp_path / "grouped" / "points" / "ntot_002"
    (gone / "trials" / "trial_00001.json").unlink()
    for name in ("trials.csv", "episodes.csv", "steps.csv", "sweep.md"):
        for f in (gone / name, tmp_path / "grouped" / name):
            f.unlink(missing_ok=True)
    out = run_sweep("births", (), None, "intersection", resume=tmp_path / "grouped", **kw)
    assert out.complete and out.n_done == 4
    sessions = sorted((gone / "sessions").iterdir())
    assert len(sessions) == 2 and json.loads(sessions[-1].read_text())["trials_run"] == 1
    assert len(list((tmp_path / "grouped" / "points" / "ntot_001" / "sessions").iterdir())) == 1
    for p in points:
        assert _same(_csvs(tmp_path / "grouped" / "points" / p), ref[p]), p
    assert (tmp_path / "grouped" / "sweep.md").is_file()


def _exact(v) -> object:
    """A comparable exact form: geometries as WKB, arrays as (dtype, shape, bytes), containers element-wise."""
    import numpy as np
    import shapely

    if isinstance(v, shapely.Geometry):
        return shapely.to_wkb(v)
    if isinstance(v, np.ndarray) and v.dtype != object:
        return (str(v.dtype), v.shape, v.tobytes())
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_exact(x) for x in v]
    if dataclasses.is_dataclass(v):
        return {f.name: _exact(getattr(v, f.name)) for f in dataclasses.fields(v)}
    return repr(v)


def _scan_data(scans) -> object:
    """Every field of every scan and the truth arrays of the Scans, exactly."""
    return _exact(scans)


def test_sensor_geometry_once_for_every_clutter_rate(intersection):
    from soabench.scenario import simulate
    from soabench.seeding import trial_seeds
    from soabench.sensor import observe

    scene, scenario = intersection
    cfg = config()
    seeds = trial_seeds(cfg.experiment.seed, 3)
    recording = simulate(scene, scenario, seeds, duration=cfg.experiment.duration)
    geometry: dict = {}
    for lam in (0.5, 5.0, 0.0):
        sensor = cfg.sensor_at(lam)
        fresh = observe(recording, scene, sensor, seeds.sensor_rngs())
        reused = observe(recording, scene, sensor, seeds.sensor_rngs(), geometry=geometry)
        assert _scan_data(fresh) == _scan_data(reused), lam
    assert len(geometry["steps"]) == len(fresh.scans)
    # another setting than lambda_c starts the geometry afresh
    narrow = dataclasses.replace(sensor, r_max=sensor.r_max / 2)
    a = observe(recording, scene, narrow, seeds.sensor_rngs(), geometry=geometry)
    assert _scan_data(a) == _scan_data(observe(recording, scene, narrow, seeds.sensor_rngs()))


def test_grouped_sweep_fail_fast_then_resume(tmp_path, monkeypatch):
    """A trial failing in one folder of a group: that folder records the failure, --fail-fast stops the group with
    every finished record on disk, and the resume gives the folders of a run that never failed."""
    import soabench.experiment.trial.trial as trial_mod

    cfg = config(models=("soa", "pubm"), probabilities=("static",), trials=3, duration=4.0)
    options = RunOptions(workers=1, progress=False, figures=False)
    kw = dict(options=options, n_true=2)
    real = trial_mod.run_trial
    second = 2 / scans_per_run(cfg)  # N_hat of point ntot_002

    def failing(trial, config, *args, **kwargs):
        if trial == 1 and config.birth.N_hat == second:
            raise RuntimeError("injected")
        return real(trial, config, *args, **kwargs)

    monkeypatch.setattr(trial_mod, "run_trial", failing)
    sw = tmp_path / "sw"
    o = run_sweep(
        "births",
        (-1, 0),
        cfg,
        "intersection",
        out=sw,
        **{**kw, "options": dataclasses.replace(options, fail_fast=True)},
    )
    assert not o.complete and o.summary_markdown == "" and not (sw / "sweep.md").exists()
    first, second = sw / "points" / "ntot_001", sw / "points" / "ntot_002"
    assert sorted(p.name for p in (first / "trials").iterdir()) == ["trial_00000.json", "trial_00001.json"]
    assert sorted(p.name for p in (second / "trials").iterdir()) == ["trial_00000.json"]
    assert [p.name for p in (second / "failed").iterdir()] == ["trial_00001.json"]
    assert "injected" in (second / "failed" / "trial_00001.json").read_text()

    monkeypatch.setattr(trial_mod, "run_trial", real)
    o2 = run_sweep("births", (), None, "intersection", resume=sw, **kw)
    assert o2.complete and o2.n_done == 6 and (sw / "sweep.md").is_file()
    run_sweep("births", (-1, 0), cfg, "intersection", out=tmp_path / "ref", grouped=False, **kw)
    for p in ("ntot_001", "ntot_002"):
        assert _csvs(sw / "points" / p) == _csvs(tmp_path / "ref" / "points" / p), p


def test_a_second_session_of_the_same_name_is_kept_and_sorts_after(tmp_path):
    from soabench.experiment.runs.store import RunStore

    store = RunStore(tmp_path)
    for i in range(3):
        store.write_session("20261123T000000Z-1", {"i": i})
    assert [s["i"] for s in store.sessions()] == [0, 1, 2]


def test_inverse_measurement_terms_once_per_scan():
    """PUBM and ATBM (static and dynamic) read one set of inverse-measurement newborn terms per scan: the same values
    as computing them anew, read-only, and a setting that changes them keys another set."""
    import numpy as np

    from soabench.baselines.partially_uniform import inverse_measurement_terms, scan_inverse_terms
    from soabench.config import Sensor
    from soabench.types import Obstacles, Scan

    sensor = Sensor()
    Z = np.array([[10.0, 0.3], [25.0, -2.0], [3.0, 3.1]])
    scan = Scan(4, 4.0, np.array([1.0, -2.0, 0.7]), Z, Obstacles.empty(), [], None)
    m, P = scan_inverse_terms(scan, sensor, 0.8)
    m_ref, P_ref = inverse_measurement_terms(Z, scan.ego, sensor, 0.8)
    assert np.array_equal(m, m_ref) and np.array_equal(P, P_ref)
    again = scan_inverse_terms(scan, sensor, 0.8)
    assert again[0] is m and again[1] is P and not m.flags.writeable and not P.flags.writeable
    other = scan_inverse_terms(scan, dataclasses.replace(sensor, sigma_r=2.0), 0.8)
    assert not np.array_equal(other[1], P)
    assert np.array_equal(
        scan_inverse_terms(scan, sensor, 1.5)[1], inverse_measurement_terms(Z, scan.ego, sensor, 1.5)[1]
    )


def test_families_runs_share_the_main_protocols_trial(intersection):
    """The families runs of ``soabench results`` (every family in static and static+occ, and the LMB with one
    Bernoulli per birth component) in one share with the main protocol: SUMO, the sensor and the mode-free births
    once for all three, each config's results exactly those of running it alone."""
    scene, scenario = intersection
    models = ("soa", "pubm", "ubm")
    main = config(models=models)
    families = config(models=models, filters=("gmphd", "lmb", "pmbm", "pmb"), probabilities=("static", "static+occ"))
    ablation = config(models=models, filters=("lmb",), probabilities=("static",))
    ablation.lmb = dataclasses.replace(ablation.lmb, birth_mapping="components")
    configs = (main, families, ablation)
    alone = [run_trial(1, c, scene, scenario) for c in configs]
    share = TrialShare()
    shared = [run_trial(1, c, scene, scenario, share=share) for c in configs]
    for x, y in zip(alone, shared, strict=True):
        assert results(x) == results(y)
    c = share.counts
    assert c["recording"] == 1 and c["recording_reused"] == 2 and c["scans"] == 1 and c["scans_reused"] == 2
    K = int(round(main.experiment.duration / main.sensor.dt))
    free = 2  # S-OA and UBM: their candidates once per scan for the three configs
    assert c["birth_candidates"] == free * K and c["birth_candidates_reused"] == 2 * free * K
    assert c["runs"] == 6 + 24 + 3  # a family's run is its own filter run, even the GM-PHD's
