"""Stone Soup bridge: our scans and truth as Stone Soup detections and paths, and Stone Soup's trackers in the
harness (installed with the stonesoup extra, which the test extra includes)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from soabench.config import Config, ExperimentConfig
from soabench.experiment.trial.trial import run_trial
from soabench.geometry import range_bearing
from soabench.seeding import trial_seeds

ss = pytest.importorskip("soabench.bridges.stonesoup", reason="the stonesoup extra is part of the test extra")


@pytest.fixture(scope="module")
def short_run():
    from soabench.scenario import load, simulate
    from soabench.sensor import observe

    scene, scenario = load("intersection")
    cfg = Config()
    seeds = trial_seeds(0, 0)
    rec = simulate(scene, scenario, seeds, duration=30.0)
    return scene, scenario, cfg, observe(rec, scene, cfg.sensor_at(), seeds.sensor_rngs())


def test_to_stonesoup_detections_and_truth(short_run) -> None:
    from stonesoup.types.detection import Clutter, TrueDetection

    _, _, cfg, scans = short_run
    s = cfg.sensor_at()
    feed = ss.to_stonesoup(scans, s.sigma_r, s.sigma_b, gt_set="scene")  # every present walker
    default = ss.to_stonesoup(scans)  # the truth set of our tables (present and in the FOV), the scans' own noise
    in_fov = scans.present & scans.in_fov
    assert {p.id: len(p) for p in default.truths} == {
        str(scans.ped_ids[p]): int(in_fov[:, p].sum()) for p in np.flatnonzero(in_fov.any(0))
    }
    assert [len(d) for _, d in default] == [len(d) for _, d in feed]
    assert len(feed.detections) == len(scans)
    assert sum(len(d) for _, d in feed) == sum(len(sc.Z) for sc in scans.scans)
    assert {p.id for p in feed.truths} == {str(scans.ped_ids[p]) for p in np.flatnonzero(scans.present.any(0))}
    by_id = {p.id: p for p in feed.truths}
    for p in by_id.values():
        assert len(p) == int(scans.present[:, list(map(str, scans.ped_ids)).index(p.id)].sum())
    n_true = n_clutter = 0
    for k, (time, dets) in enumerate(feed):
        scan = scans.scans[k]
        assert time == ss.EPOCH + __import__("datetime").timedelta(seconds=scan.t)
        for det in dets:
            if isinstance(det, TrueDetection):
                n_true += 1
                # the detection's model maps the walker's true state to the noise-free (bearing, range) we compute
                truth = next(st for st in det.groundtruth_path if st.timestamp == time)
                zb, zr = (float(v) for v in det.measurement_model.function(truth))
                p = det.groundtruth_path.id
                r, b = range_bearing(scans.truth_xy[k, list(map(str, scans.ped_ids)).index(p)], scan.ego)
                assert zr == pytest.approx(float(r), abs=1e-9) and math.remainder(zb - float(b), 2 * math.pi) == (
                    pytest.approx(0.0, abs=1e-9)
                )
                # and the detection itself lies within 5 sigma of it
                assert abs(float(det.state_vector[1]) - zr) < 5 * s.sigma_r
            else:
                assert isinstance(det, Clutter)
                n_clutter += 1
    assert n_true == sum(int((src >= 0).sum()) for src in scans.source) and n_true > 0
    assert n_clutter == sum(int((src < 0).sum()) for src in scans.source)


def test_stonesoup_trackers_run_in_the_harness(short_run) -> None:
    scene, scenario, _, _ = short_run
    exp = ExperimentConfig(
        duration=30.0, models=("soa",), trackers=("stonesoup-gmphd", "stonesoup-gnn"), probabilities=("static",)
    )
    cfg = Config(experiment=exp).validate()
    res = run_trial(0, cfg, scene, scenario)
    assert res.failures == []
    rows = {r["model"]: r for r in res.rows}
    assert set(rows) == {"soa", "stonesoup-gmphd", "stonesoup-gnn"}
    for name in ("stonesoup-gmphd", "stonesoup-gnn"):
        r = rows[name]
        assert all(math.isfinite(r[k]) and r[k] >= 0 for k in ("ospa", "gospa", "card_err", "mean_components"))
    steps = [s for s in res.steps if s["model"] == "stonesoup-gmphd"]
    assert len(steps) == 30 and sum(s["tp"] for s in steps) > 0  # its GM-PHD finds walkers
    assert all(math.isfinite(s["sum_w"]) for s in steps)  # the PHD mass is its cardinality


def test_unknown_stonesoup_option_is_refused() -> None:
    from soabench import plugins
    from soabench.errors import SoabenchError

    cfg = Config(experiment=ExperimentConfig(models=(), trackers=("stonesoup-gnn",)), plugins={})
    cfg.plugins["stonesoup-gnn"] = {"min_point": 3}
    with pytest.raises(SoabenchError, match="sets 'min_point'.*its options: min_points, delete_after, gate"):
        plugins.preflight(cfg)
