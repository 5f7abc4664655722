"""soabench.api: one import for a notebook. Its run gives the rows `soabench run` writes, bit for bit; its pieces
(simulate_trial, make_tracker, evaluate) give a run's row; wrong input fails at the boundary in one line."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

import soabench.api as sb
from soabench.experiment.runs.files import read_csv
from soabench.experiment.runs.store import METRIC_COLUMNS
from soabench.tracks.evaluate import TRACK_KEYS

NET = "arterial"  # walkers are seen within 20 s (the intersection's first walkers appear later)
MODELS = "soa,pubm,atbm"  # a mode-free model, a per-mode one and one that reads the previous step
ARGS = dict(net=NET, trials=2, duration=20, seed=3, models=MODELS, probabilities="static,dynamic")


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "run"
    cmd = [
        sys.executable, "-m", "soabench.cli", "run", "--net", NET, "--trials", "2", "--duration", "20", "--seed", "3",
        "--models", MODELS, "--probabilities", "static,dynamic", "--workers", "1", "--no-progress", "--out", str(out),
    ]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.fixture(scope="module")
def api_run(tmp_path_factory) -> tuple[sb.RunResult, Path]:
    cwd = tmp_path_factory.mktemp("cwd")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(cwd)
        result = sb.run(**ARGS)
    return result, cwd


def test_dir_lists_only_public_names() -> None:
    assert dir(sb) == sorted(sb.__all__)
    assert all(hasattr(sb, name) for name in sb.__all__)
    leaked = [n for n in vars(sb) if not n.startswith("_") and n not in sb.__all__]
    assert leaked == [], f"module-level names outside __all__: {leaked}"
    for name in ("simulate_trial", "make_tracker", "evaluate", "run", "to_stonesoup", "from_stonesoup"):
        assert getattr(sb, name).__doc__, name
    assert (sb.BIRTH_MODEL, sb.TRACKER) == ("birth model", "tracker")


@pytest.mark.slow
def test_run_in_memory_equals_the_cli_tables_bit_for_bit(cli_run, api_run, tmp_path) -> None:
    result, cwd = api_run
    assert list(cwd.iterdir()) == [], "an in-memory run wrote files"
    assert result.run_dir is None and result.complete
    assert len(result.trials) == 2 * 3 * 2 and len(result.episodes) > 0 and len(result.steps) == 2 * 3 * 2 * 20
    for name in ("trials", "episodes", "steps"):
        cli = read_csv(cli_run / f"{name}.csv")
        table = result.table(name)
        assert list(table.dtype.names) == list(cli), name
        for col in cli:
            a = np.asarray(table[col])
            if cli[col].dtype.kind == "f":
                assert a.dtype.kind in "fib", (name, col)
                b = a.astype(float)
                same = (b == cli[col]) | (np.isnan(b) & np.isnan(cli[col]))
                assert same.all(), (name, col)
            else:
                assert (a.astype(str) == cli[col]).all(), (name, col)
    for path in result.write_csv(tmp_path / "api"):
        assert path.read_bytes() == (cli_run / path.name).read_bytes(), path.name


def test_run_with_out_writes_the_cli_folder(cli_run, tmp_path) -> None:
    args = {**ARGS, "trials": 1, "models": "soa"}
    result = sb.run(**args, out=tmp_path / "run")
    assert result.run_dir == tmp_path / "run" and (tmp_path / "run" / "trials.csv").is_file()
    cli = read_csv(cli_run / "trials.csv")
    rows = (cli["trial"] == 0) & (cli["model"] == "soa")
    assert np.array_equal(result.trials["ospa"], cli["ospa"][rows])
    assert (tmp_path / "run" / "trials.csv").read_text().splitlines()[1:] == [
        line
        for line in (cli_run / "trials.csv").read_text().splitlines()[1:]
        if line.startswith("0,3,") and ",soa," in line
    ]


def test_result_reprs_are_short_and_pandas_is_optional(api_run, monkeypatch) -> None:
    result, _ = api_run
    assert len(repr(result)) < 300 and "12 trial rows" in repr(result)
    monkeypatch.setitem(sys.modules, "pandas", None)  # as if not installed
    with pytest.raises(ValueError, match="pip install pandas") as exc:
        result.to_pandas("episodes")
    assert "\n" not in str(exc.value)
    fake = types.SimpleNamespace(DataFrame=types.SimpleNamespace(from_records=lambda rec: ("frame", rec)))
    monkeypatch.setitem(sys.modules, "pandas", fake)
    assert result.to_pandas("steps") == ("frame", result.steps)
    with pytest.raises(ValueError, match="choose one of trials, episodes, steps, timing"):
        result.to_pandas("rows")


@pytest.fixture(scope="module")
def trial1():
    return sb.simulate_trial(NET, seed=3, trial=1, duration=20)


@pytest.mark.parametrize(("model", "mode"), [("soa", "static"), ("atbm", "dynamic"), ("pubm", "dynamic")])
def test_simulate_make_tracker_evaluate_give_the_run_row(api_run, trial1, model, mode) -> None:
    result, _ = api_run
    _, scans = trial1
    tracker = sb.make_tracker(model, NET, mode=mode, seed=3, trial=1)
    metrics = sb.evaluate(scans, [tracker.step(scan) for scan in scans])
    t = result.trials
    (row,) = t[(t["trial"] == 1) & (t["model"] == model) & (t["mode"] == mode)]
    assert "hota" in metrics.summary  # our filter labels its estimates: the §9 track columns come too
    for col in METRIC_COLUMNS:  # the §5 metrics and the §9 track columns, as in trials.csv
        a, b = metrics[col], row[col]
        assert a == b or (a is None and b is None) or (np.isnan(a) and np.isnan(b)), (col, a, b)
    # the same numbers from Estimates (what any tracker returns) as from the filter's StepResults
    tracker = sb.make_tracker(model, NET, mode=mode, seed=3, trial=1)
    est = [sb.Estimates(res.X) for res in (tracker.step(scan) for scan in scans)]
    again = sb.evaluate(scans, est)
    for col in ("ospa", "gospa", "tp", "fp", "fn", "delay_mean", "precision", "recall", "card_err"):
        assert again[col] == metrics[col] or (np.isnan(again[col]) and np.isnan(metrics[col])), col
    assert not set(TRACK_KEYS) & set(again.summary)  # no labels: no track columns


def test_make_tracker_takes_names_classes_and_import_paths(trial1) -> None:
    from plugin_fixtures import EchoTracker, OneBirth

    _, scans = trial1
    for name_or_class in (OneBirth, "plugin_fixtures:OneBirth", "ubm"):
        tracker = sb.make_tracker(name_or_class, NET)
        assert isinstance(tracker, sb.GMPHDTracker) and isinstance(tracker.step(scans[0]), sb.StepResult)
    for name_or_class in (EchoTracker, "plugin_fixtures:EchoTracker", "stonesoup-gnn"):
        tracker = sb.make_tracker(name_or_class, NET)
        assert isinstance(tracker.step(scans[0]), sb.Estimates), name_or_class
    with pytest.raises(ValueError, match="neither a birth model .* nor a tracker"):
        sb.make_tracker("kalman", NET)
    with pytest.raises(ValueError, match="built-in birth model: set its options in the config's"):
        sb.make_tracker("soa", NET, N_hat=2.0)
    assert "FilterTracker(family 'gmphd', birth model 'soa'" in repr(sb.make_tracker("soa", NET))


def test_make_tracker_runs_any_family(trial1) -> None:
    """``filter=`` (or the configuration's one family) picks the family; the LMB's step gives labelled estimates; a
    configuration naming several families, another family, or a mode the family lacks is refused with one line."""
    _, scans = trial1
    lmb = sb.make_tracker("soa", NET, filter="lmb")
    assert lmb.name == "lmb" and type(lmb.filt).__name__ == "LMBFilter"
    out = [lmb.step(scan) for scan in scans[:5]]
    assert all(r.labels is not None and len(r.labels) == len(r.X) for r in out)
    by_config = sb.make_tracker("soa", NET, config={"experiment": {"filters": ["lmb"], "probabilities": ["static"]}})
    assert by_config.name == "lmb"
    tuned = sb.make_tracker("soa", NET, config={"lmb": {"max_tracks": 7}}, filter="lmb")
    assert tuned.filt.lmb.max_tracks == 7  # an [lmb] key is honoured when the tracker runs the LMB
    with pytest.raises(ValueError, match="names 2 filter families; a tracker runs one"):
        sb.make_tracker("soa", NET, config={"experiment": {"filters": ["gmphd", "lmb"]}})
    with pytest.raises(ValueError, match="filter = 'lmb' is not among experiment.filters"):
        sb.make_tracker("soa", NET, config={"experiment": {"filters": ["gmphd"]}}, filter="lmb")
    with pytest.raises(ValueError, match="filter = 'kf' is not allowed"):
        sb.make_tracker("soa", NET, filter="kf")
    with pytest.raises(ValueError, match="probability mode 'dynamic' is not defined for the LMB filter"):
        sb.make_tracker("soa", NET, filter="lmb", mode="dynamic")


def test_resolve_validates_the_kind() -> None:
    assert sb.resolve(sb.BIRTH_MODEL, "soa").__name__ == "SOABirth"
    with pytest.raises(ValueError) as exc:
        sb.resolve("birth", "soa")
    assert "kind 'birth' is unknown" in str(exc.value) and "stonesoup" not in str(exc.value)
    with pytest.raises(ValueError, match="tracker 'soa' is unknown"):
        sb.resolve(sb.TRACKER, "soa")


def _one_line(exc_info) -> str:
    text = str(exc_info.value)
    assert "\n" not in text and text
    return text


def test_wrong_objects_fail_at_the_boundary_in_one_line(trial1) -> None:
    from soabench.config import Config
    from soabench.scenario import load, simulate
    from soabench.seeding import trial_seeds
    from soabench.sensor import observe

    recording, scans = trial1
    scene, scenario = load(NET, quiet=True)
    with pytest.raises(TypeError) as exc:
        simulate(scene, scenario, 3)
    assert "seeds must be a TrialSeeds, got 3" in _one_line(exc)
    with pytest.raises(TypeError) as exc:
        observe(recording, scene, Config(), trial_seeds(0, 0).sensor_rngs())
    assert "must be a Sensor, got a Config" in _one_line(exc)
    tracker = sb.make_tracker("soa", NET)
    with pytest.raises(TypeError) as exc:
        tracker.step(scans)
    assert "got a Scans" in _one_line(exc)
    with pytest.raises(TypeError) as exc:
        sb.make_tracker("stonesoup-gmphd", NET).step(scans)
    assert "got a Scans" in _one_line(exc)
    with pytest.raises(TypeError) as exc:
        sb.evaluate(recording, [])
    assert "scans must be a Scans, got a Recording" in _one_line(exc)
    with pytest.raises(ValueError) as exc:
        sb.evaluate(scans, [sb.Estimates.empty()] * 3)
    assert "3 estimates for 20 scans" in _one_line(exc)
    with pytest.raises(TypeError) as exc:
        sb.simulate_trial(NET, config=3.5)
    assert "config must be a Config or dict or str or Path" in _one_line(exc)


def test_make_tracker_names_the_plugin_whose_births_are_unusable(trial1) -> None:
    _, scans = trial1
    tracker = sb.make_tracker("plugin_fixtures:HugeWeights", NET)
    with pytest.raises(ValueError) as exc:
        tracker.step(scans[0])
    assert "birth model 'plugin_fixtures:HugeWeights' at scan 0: Births.w[0] = 1e+300" in _one_line(exc)


def test_make_tracker_honours_the_configured_filter_family_or_refuses_in_one_line() -> None:
    lmb = {"experiment": {"filters": ["lmb"]}}
    with pytest.raises(ValueError) as exc:
        sb.make_tracker("soa", NET, mode="dynamic", config=lmb)
    assert "probability mode 'dynamic' is not defined for the LMB filter" in _one_line(exc)
    tracker = sb.make_tracker("soa", NET, mode="static", config=lmb)
    assert type(tracker.filt).__module__.startswith("soabench.lmb")
    with pytest.raises(ValueError) as exc:
        sb.make_tracker("soa", NET, config={"experiment": {"filters": ["gmphd", "lmb"]}})
    assert "names 2 filter families; a tracker runs one" in _one_line(exc)


def test_nan_truth_rows_are_refused_by_the_metric_helpers(trial1) -> None:
    from soabench.metrics import gated_assignment, gospa, gt_mask, ospa

    _, scans = trial1
    k = 0
    truth = scans.truth_xy[k].copy()
    truth[1] = np.nan  # an absent walker's row, as truth_xy holds it
    est = np.array([[0.0, 0.0]])
    for call in (lambda: ospa(est, truth), lambda: gospa(truth, est), lambda: gated_assignment(est, truth, 5.0)):
        with pytest.raises(ValueError) as exc:
            call()
        assert "NaN or infinite position" in _one_line(exc) and "gt_mask" in str(exc.value)
    assert ospa(est, truth[gt_mask(scans)[k] & np.isfinite(truth).all(axis=1)])[0] >= 0


def test_stonesoup_ordered_states_are_detected_or_taken_with_order(trial1) -> None:
    _, scans = trial1
    tracker = sb.make_tracker("soa", NET)
    ours = [sb.Estimates(res.X) for res in (tracker.step(scan) for scan in scans)]
    theirs = [sb.Estimates(e.X[:, [0, 2, 1, 3]]) for e in ours]
    with pytest.raises(ValueError) as exc:
        sb.evaluate(scans, theirs)
    assert "order='x,vx,y,vy'" in _one_line(exc)
    a = sb.evaluate(scans, ours)
    b = sb.evaluate(scans, theirs, order=sb.ORDER_STONESOUP)
    assert a.summary == pytest.approx(b.summary, nan_ok=True) and a["tp"] > 0
    with pytest.raises(ValueError, match="order = 'xy'"):
        sb.evaluate(scans, ours, order="xy")


def test_reprs_are_short(trial1) -> None:
    recording, scans = trial1
    tracker = sb.make_tracker("soa", NET)
    res = tracker.step(scans[0])
    for obj, start in (
        (scans, "Scans(20 scans"),
        (scans[0], "Scan(k=0"),
        (recording, "Recording(net="),
        (res, "StepResult(k=0"),
        (sb.Estimates(res.X), "Estimates("),
        (sb.evaluate(scans, [tracker.step(s) for s in scans[1:]] + [res]), "TrialMetrics(ospa="),
        (sb.Births.empty(), "Births(0 components"),
    ):
        assert repr(obj).startswith(start) and len(repr(obj)) < 300, repr(obj)[:400]


def test_stonesoup_bridge_both_ways_on_our_truth_set(trial1) -> None:
    pytest.importorskip("stonesoup")
    from stonesoup.measures import Euclidean
    from stonesoup.metricgenerator.ospametric import OSPAMetric
    from stonesoup.types.state import State
    from stonesoup.types.track import Track

    from soabench.bridges.stonesoup import estimate_set, scan_time
    from soabench.metrics import gt_mask

    _, scans = trial1
    feed = sb.to_stonesoup(scans)  # noise from the scans, truth = present and in the FOV
    in_set = gt_mask(scans, "fov")
    assert sum(len(p) for p in feed.truths) == int(in_set.sum()) < int(scans.present.sum())
    assert len(sb.to_stonesoup(scans, gt_set="scene").truths) >= len(feed.truths)
    # tracks of a Stone Soup tracker, back into our estimates, with their ids
    gnn = sb.make_tracker("stonesoup-gnn", NET)
    tracks: set = set()
    for time, detections in feed:
        tracks |= gnn.tracker.update_tracker(time, detections)[1]
    estimates, labels = sb.from_stonesoup(tracks, scans)
    assert len(estimates) == len(scans) and sum(len(e) for e in estimates) > 0
    assert {str(t.id) for t in tracks} == set(np.concatenate(labels))
    ours = sb.evaluate(scans, estimates)
    # Stone Soup's OSPA on the same sets, positions only, equals ours scan by scan
    ospa = OSPAMetric(c=100, p=1, measure=Euclidean(mapping=(0, 2)))
    est_states = estimate_set(tracks, scans)
    truth_states = [s for path in feed.truths for s in path]
    value = ospa.compute_over_time(est_states, [0] * len(est_states), truth_states, [0] * len(truth_states))
    by_time = {m.timestamp: m.value for m in value.value}
    theirs = np.array([by_time.get(scan_time(scan), 0.0) for scan in scans])
    assert np.allclose(theirs, ours.series["ospa"], rtol=0, atol=1e-9)
    assert np.array_equal(sb.stonesoup_ospa(tracks, scans), theirs)  # the same comparison from soabench.api
    # a round trip of known tracks keeps states and ids
    track = Track([State([1.0, 0.5, 2.0, -0.5], timestamp=scan_time(scans[k])) for k in (2, 3)], id="t7")
    est, lab = sb.from_stonesoup([track], scans)
    assert np.array_equal(est[2].X, [[1.0, 2.0, 0.5, -0.5]]) and list(lab[3]) == ["t7"] and len(est[0]) == 0
    off = Track(
        [State([1.0, 0.5, 2.0, -0.5], timestamp=scan_time(scans[2]) + (scan_time(scans[1]) - scan_time(scans[0])) / 2)]
    )
    with pytest.raises(ValueError, match="no scan's time"):
        sb.from_stonesoup([off], scans)


def test_config_forms_are_accepted(tmp_path) -> None:
    path = tmp_path / "c.toml"
    path.write_text("[experiment]\nclutter = [1.0]\n")
    a = sb.simulate_trial(NET, duration=5, config=path)[1]
    b = sb.simulate_trial(NET, duration=5, config={"experiment": {"clutter": [1.0]}})[1]
    cfg = sb.Config()
    cfg.experiment = dataclasses.replace(cfg.experiment, clutter=(1.0,))
    c = sb.simulate_trial(NET, duration=5, config=cfg)[1]
    assert a.sensor.lambda_c == b.sensor.lambda_c == c.sensor.lambda_c == 1.0
    assert all(np.array_equal(x.Z, y.Z) and np.array_equal(x.Z, z.Z) for x, y, z in zip(a, b, c, strict=True))


def test_run_on_two_processes_equals_the_serial_run(api_run) -> None:
    result, _ = api_run
    parallel = sb.run(**ARGS, workers=2)
    for name in ("trials", "episodes", "steps"):
        a, b = result.table(name), parallel.table(name)
        assert a.dtype == b.dtype and len(a) == len(b), name
        for col in a.dtype.names:
            x, y = a[col], b[col]
            same = (x == y) | (np.isnan(x) & np.isnan(y)) if x.dtype.kind == "f" else x == y
            assert np.all(same), (name, col)


def test_failed_plugin_runs_and_failed_trials_are_listed(monkeypatch) -> None:
    from soabench.experiment.execution import runner

    result = sb.run(net=NET, trials=1, duration=5, models=["soa", "plugin_fixtures:RaiseAtScan3"])
    assert set(result.trials["model"]) == {"soa"} and result.complete
    assert [(f["model"], f["k"]) for f in result.model_failures] == [("plugin_fixtures:RaiseAtScan3", 3)] * 2

    def broken(trial, *args, **kwargs):
        raise RuntimeError(f"trial {trial} broke")

    monkeypatch.setattr(runner, "_default_trial_fn", lambda: broken)
    with pytest.warns(UserWarning, match=r"2 of 2 trials failed \(trial 0: RuntimeError: trial 0 broke\)"):
        failed = sb.run(net=NET, trials=2, duration=5, models="soa")
    assert not failed.complete and len(failed.trials) == 0 and [f["trial"] for f in failed.failures] == [0, 1]
    assert "2 failed trials" in repr(failed)


def test_scene_and_a_scan_drawn_on_matplotlib_axes(trial1, tmp_path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    _, scans = trial1
    scene = sb.load_scene(NET)
    k = max(range(len(scans)), key=lambda k: len(scans[k].Z))
    fig, ax = plt.subplots()
    X = np.array([[1.0, 2.0], [3.0, 4.0]])
    assert sb.draw_scene(ax, scene, scan=scans[k], estimates=sb.Estimates(X, labels=np.array([4, 9]))) is ax
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert {"road", "sidewalk / walking area", f"measurement ({len(scans[k].Z)})", "estimate (2)"} <= set(labels)
    assert {"4", "9"} <= {t.get_text() for t in ax.texts}  # the track labels beside the estimates
    fig.savefig(tmp_path / "scene.png")
    plt.close(fig)
    tracker = sb.make_tracker("soa", scene)
    steps = [tracker.step(scan) for scan in scans.scans[: k + 1]]
    fig, ax = plt.subplots()
    sb.draw_scene(ax, scene, scan=scans[k], estimates=steps[k])  # our filter's StepResult, as make_tracker gives it
    assert f"estimate ({len(steps[k].X)})" in [t.get_text() for t in ax.get_legend().get_texts()]
    plt.close(fig)
    with pytest.raises(TypeError, match="^scan must be a Scan, got a Scans"):
        sb.draw_scene(plt.subplots()[1], scene, scan=scans)
    with pytest.raises(ValueError, match="^net=3 must be a scene name"):
        sb.load_scene(3)


def test_estimates_and_scan_files_fail_when_built_or_read_naming_what_is_wrong(trial1, tmp_path) -> None:
    recording, scans = trial1
    for bad, says in (
        (dict(X=(3, 3)), "Estimates: X has shape (2,)"),
        (dict(X=np.zeros((3, 3))), "Estimates: X has shape (3, 3)"),
        (dict(X=np.zeros((2, 2)), labels=np.array([1.0, 2.0])), "Estimates: labels has shape (2,) and dtype float64"),
        (dict(X=np.zeros((2, 2)), w=np.ones(3)), "Estimates: w has shape (3,)"),
    ):
        with pytest.raises(ValueError) as exc:
            sb.Estimates(**bad)
        assert str(exc.value).startswith(says) and "\n" not in str(exc.value)
    recording.save_npz(tmp_path / "rec.npz")
    with pytest.raises(ValueError, match="is a Recording file .* read it with soabench.api.Recording.load_npz"):
        sb.Scans.load_npz(tmp_path / "rec.npz")
    scans.save_npz(tmp_path / "scans.npz")
    with pytest.raises(ValueError, match="is a Scans file .* read it with soabench.api.Scans.load_npz"):
        sb.Recording.load_npz(tmp_path / "scans.npz")
    np.savez(tmp_path / "other.npz", a=np.zeros(2))
    with pytest.raises(ValueError, match="is not a soabench Scans file .* lacks"):
        sb.Scans.load_npz(tmp_path / "other.npz")


def test_scans_are_checked_when_built_naming_the_argument(trial1, tmp_path) -> None:
    _, scans = trial1
    K, P = scans.present.shape
    xy = scans.truth_xy.copy()
    k, j = np.argwhere(scans.present)[0]
    xy[k, j, 1] = np.nan
    source = list(scans.source)
    m = next(i for i, s in enumerate(source) if len(s))
    source[m] = source[m][:-1]
    clutter_only = list(scans.source)
    clutter_only[m] = np.full(len(clutter_only[m]), P)
    for bad, says in (
        (dict(truth_xy=xy[:, :, :1]), f"Scans: truth_xy has shape ({K}, {P}, 1) and dtype float64; give ({K}, {P}, 2)"),
        (dict(present=scans.present.astype(int)), f"Scans: present has shape ({K}, {P}) and dtype int64; give"),
        (dict(visible=scans.visible[:-1]), f"Scans: visible has shape ({K - 1}, {P}) and dtype bool; give ({K}, {P})"),
        (dict(truth_xy=xy), f"Scans: truth_xy[{k}, {j}] is [{xy[k, j, 0]}, nan] where present[{k}, {j}] is True"),
        (dict(source=source), f"Scans: source[{m}] has shape ({len(source[m])},) and dtype int64; give"),
        (dict(source=clutter_only), f"Scans: source[{m}] holds {P}..{P}; give pedestrian columns 0..{P - 1}"),
        (dict(source=scans.source[:-1]), f"Scans: source holds {K - 1} entries; give a list of {K} arrays"),
        (dict(dt=0.0), "Scans: dt = 0.0; give the sensor period in seconds"),
    ):
        with pytest.raises(ValueError) as exc:
            dataclasses.replace(scans, **bad)
        assert _one_line(exc).startswith(says), (says, str(exc.value))
    scans.save_npz(tmp_path / "scans.npz")
    with np.load(tmp_path / "scans.npz") as data:
        arrays = dict(data)
    np.savez(tmp_path / "offsets.npz", **{**arrays, "z_offsets": arrays["z_offsets"][::-1]})
    with pytest.raises(ValueError) as exc:
        sb.Scans.load_npz(tmp_path / "offsets.npz")
    assert "offsets.npz: z_offsets does not match its arrays" in _one_line(exc)
    np.savez(tmp_path / "flags.npz", **{**arrays, "detected": arrays["detected"][:, :-1]})
    with pytest.raises(ValueError) as exc:
        sb.Scans.load_npz(tmp_path / "flags.npz")
    assert f"flags.npz: Scans: detected has shape ({K}, {P - 1})" in _one_line(exc)


def test_a_bad_value_is_named_as_the_python_argument_or_as_the_flag(tmp_path, capsys) -> None:
    import pickle

    from soabench.cli.main import main
    from soabench.errors import BadValue

    stray = tmp_path / "stray"
    stray.mkdir()
    (stray / "notes.txt").write_text("mine")
    calls = (
        (dict(net="intersectoin"), "net='intersectoin' is neither a shipped network", "--net", "intersectoin"),
        (
            dict(out=str(stray)),
            f"out={str(stray)!r} is not empty (notes.txt) but holds no run.json",
            "--out",
            str(stray),
        ),
        (dict(workers=0), "workers=0 is out of range; allowed: integers in [1, ", "--workers", "0"),
    )
    for kwargs, says, flag, value in calls:
        with pytest.raises(BadValue) as exc:
            sb.run(trials=1, duration=5, **kwargs)
        assert _one_line(exc).startswith(says) and "--" not in str(exc.value), str(exc.value)
        assert pickle.loads(pickle.dumps(exc.value)).args == exc.value.args  # crosses a process boundary whole
        assert main(["run", flag, value, "--trials", "1", "--duration", "5", "--no-progress"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"soabench: error: {flag} {exc.value.value!r} {exc.value.problem}"], err
    with pytest.raises(BadValue, match=r"\(did you mean 'intersection'\?\)$"):
        sb.load_scene("intersectoin")


def test_metrics_of_the_same_run_compare_equal_without_their_timings(trial1) -> None:
    _, scans = trial1
    runs = []
    for _ in range(2):
        tracker = sb.make_tracker("soa", NET, seed=3, trial=1)
        runs.append(sb.evaluate(scans, [tracker.step(scan) for scan in scans]))
    a, b = runs
    assert a["t_update"] != b["t_update"] or a["t_predict"] != b["t_predict"]  # wall clock: never the same twice
    assert a == b and not set(a.values()) & {"t_predict", "t_update", "t_reduce"}
    b.summary["ospa"] += 1e-9
    assert a != b
