"""SUMO -> KITTI files -> reader: the same measurements and truth in the camera's view as the direct path;
`soabench kitti` end to end on the exported sequences (2 trials x 30 s at 10 Hz; the first ~20 s of a trial see few
pedestrians). The files' own conventions: tests/behaviour/test_kitti_camera.py."""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import shutil

import numpy as np
import pytest

from soabench.cli.main import main
from soabench.geometry import range_bearing
from soabench.kitti.config import KittiConfig, kitti_base_config
from soabench.kitti.export import export_default_fov
from soabench.kitti.reader import open_dataset, read_sequence, to_scans

pytestmark = pytest.mark.slow  # SUMO runs exported to KITTI files

DURATION = 30.0


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("kitti") / "export"
    assert main(["export", "kitti", "--trials", "2", "--duration", str(DURATION), "--out", str(out)]) == 0
    return out


def _direct(trial: int):
    """The direct path: the trial `soabench run` would simulate, observed with the export's sensor."""
    from soabench.scenario import load, simulate
    from soabench.seeding import trial_seeds
    from soabench.sensor import observe

    cfg = kitti_base_config()
    sensor = dataclasses.replace(cfg.sensor_at(), fov_deg=export_default_fov(cfg.sensor))
    scene, scenario = load("intersection")
    seeds = trial_seeds(cfg.experiment.seed, trial)
    recording = simulate(scene, scenario, seeds, duration=DURATION)
    return observe(recording, scene, sensor, seeds.sensor_rngs()), sensor


def _in_ego_frame(xy, ego):
    r, b = range_bearing(xy, ego)
    return np.column_stack([r, b])


def _in_sector(Z, sensor):
    """(M,) measurements (range, bearing) in the sensor's FOV sector (what the reader keeps by default)."""
    return (Z[:, 0] >= sensor.r_min) & (Z[:, 0] <= sensor.r_max) & (np.abs(Z[:, 1]) <= 0.5 * sensor.fov + 1e-12)


def _facing(obstacles, ego, sensor):
    """(N,) obstacles whose cone overlaps the sensor's sector (the only ones the camera can label)."""
    lo = np.angle(np.exp(1j * (obstacles.theta_min - ego[2])))
    width = np.mod(obstacles.theta_max - obstacles.theta_min, 2 * np.pi)
    half = 0.5 * sensor.fov
    return (lo <= half) & (lo + width >= -half) | (lo + width >= 2 * np.pi - half)


@pytest.mark.parametrize("trial", [0, 1])
def test_round_trip_gives_the_direct_measurements_and_truth(exported, trial):
    direct, sensor = _direct(trial)
    ds = open_dataset(exported, semantics=exported / "semantics")
    kc = KittiConfig(source="track_id")
    read = to_scans(read_sequence(ds, f"{trial:04d}"), kc, kitti_base_config().sensor)
    r = read.scans
    assert read.sensor.fov_deg == pytest.approx(sensor.fov_deg, abs=1e-9)  # from P2
    assert len(r) == len(direct) >= round(DURATION / 0.1) and r.dt == direct.dt
    kept = [_in_sector(s.Z, sensor) for s in direct.scans]
    assert read.info["measurements"] == sum(int(m.sum()) for m in kept) > 0
    cols = np.array([int(i) for i in r.ped_ids])
    never = np.setdiff1d(np.arange(direct.present.shape[1]), cols)
    assert not direct.in_fov[:, never].any()  # only pedestrians the sensor never had in its FOV are never labelled
    # labelled: what the camera sees, a subset of the present pedestrians holding every one in the sensor's FOV
    assert not (r.present & ~direct.present[:, cols]).any()
    assert not (direct.in_fov[:, cols] & ~r.present).any()
    assert (direct.present[:, cols] & ~r.present).any()  # the export leaves out pedestrians behind the camera
    for name in ("in_fov", "visible"):
        assert np.array_equal(getattr(direct, name)[:, cols], getattr(r, name)), name
    detected = np.zeros_like(direct.detected)  # detected by a measurement the reader keeps (in the sector)
    for k, m in enumerate(kept):
        src = direct.source[k][m]
        detected[k, src[src >= 0]] = True
    assert np.array_equal(detected[:, cols], r.detected)
    assert direct.detected.any() and direct.visible.any()
    for k, (a, b) in enumerate(zip(direct.scans, r.scans, strict=True)):
        assert b.Z.shape == (int(kept[k].sum()), 2)
        assert np.allclose(a.Z[kept[k]], b.Z, rtol=0, atol=1e-9), k
        mapped = np.where(r.source[k] >= 0, cols[np.maximum(r.source[k], 0)], -1)
        assert np.array_equal(mapped, direct.source[k][kept[k]]), k
        here = np.flatnonzero(r.present[k])
        ta = _in_ego_frame(direct.truth_xy[k, cols[here]], a.ego)
        tb = _in_ego_frame(r.truth_xy[k, here], b.ego)
        assert np.allclose(ta, tb, rtol=0, atol=1e-9), k
        # obstacles facing the camera (vehicles, parked cars, buildings) with their tangent rays, and the visible
        # sidewalk (obstacles behind the camera shadow nothing in its view)
        fa, fb = _facing(a.obstacles, a.ego, sensor), _facing(b.obstacles, b.ego, sensor)
        assert fa.sum() == fb.sum(), k
        for f in ("r_min", "r_max", "centroid_range"):
            va, vb = getattr(a.obstacles, f)[fa], getattr(b.obstacles, f)[fb]
            assert np.allclose(np.sort(va), np.sort(vb), atol=1e-9), (k, f)
        assert b.visible_region.area == pytest.approx(a.visible_region.area, rel=1e-6, abs=1e-6), k
    # relative headings of the ego path agree (the reader's world is the first IMU frame)
    d_direct = np.diff([s.ego[2] for s in direct.scans])
    d_read = np.diff([s.ego[2] for s in r.scans])
    assert np.allclose(np.angle(np.exp(1j * (d_direct - d_read))), 0, atol=1e-9)


def test_obstacles_from_detections_equal_those_from_labels(exported):
    ds = open_dataset(exported)
    seq = read_sequence(ds, "0001")
    base = kitti_base_config().sensor
    a = to_scans(seq, KittiConfig(), base).scans
    b = to_scans(seq, KittiConfig(obstacles="detections"), base).scans
    assert sum(len(s.obstacles) for s in a.scans) > 0
    for sa, sb in zip(a.scans, b.scans, strict=True):
        assert np.allclose(np.sort(sa.obstacles.theta_min), np.sort(sb.obstacles.theta_min))


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_kitti_protocol_end_to_end_and_resume(exported, tmp_path, capsys):
    run = tmp_path / "run"
    argv = ["kitti", "--root", str(exported), "--semantics", str(exported / "semantics"), "--nhat-sweep", "-1:0"]
    assert main([*argv, "--out", str(run)]) == 0
    err = capsys.readouterr().err
    assert (
        "[1/6] cv sequence 0000" in err
        and "[6/6] sweep+0 sequence 0001" in err
        and "[4/6] sweep+0 sequence 0000" in err
    )
    summary = json.loads((run / "summary.json").read_text())

    # N_hat of each held-out fold = targets / frames of the other sequence, counted here from the files themselves
    def targets(seq):
        rows = [ln.split() for ln in (exported / "label_02" / f"{seq}.txt").read_text().splitlines() if ln]
        return len({r[1] for r in rows if r[2] == "Pedestrian"})

    def frames(seq):
        return len((exported / "oxts" / f"{seq}.txt").read_text().splitlines())

    folds = summary["folds"]
    assert [f["sequences"] for f in folds] == [["0000"], ["0001"]]
    assert folds[0]["N_hat"] == pytest.approx(targets("0001") / frames("0001"))
    assert folds[1]["N_hat"] == pytest.approx(targets("0000") / frames("0000"))
    t1 = summary["table1"]
    assert set(t1) == {"soa", "pubm", "ubm", "ubm-ws"}
    assert t1["soa"]["steps"] == frames("0000") + frames("0001")
    for m in t1.values():
        assert 0 <= m["card_err_mean"] and 0 <= m["ospa_mean"] <= 10.0 and m["ospa_std"] > 0
    assert set(summary["pairwise"]) == {"pubm", "ubm", "ubm-ws"}
    assert all(v["n"] > 0 and 0 <= v["share"] <= 100 for v in summary["pairwise"].values())
    assert summary["sweep"]["soa"]["offsets"] == [-1, 0]
    assert len(_rows(run / "sequences.csv")) == 3 * 2 * 4  # (cv + 2 offsets) x 2 sequences x 4 models
    report = (run / "report.md").read_text()
    assert "6.5565 ± 4.4513" in report and "70.3 %" in report and "not KITTI data" in report
    # data paths relative to the report (a committed report reads the same on every machine)
    rel = os.path.relpath(exported.resolve(), run.resolve())
    assert f"Data: `{rel}`" in report and str(exported) not in report
    for name in ("fig6_delay_hist.png", "fig7_components.png", "fig8_nhat_sweep.png"):
        assert (run / "figures" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # track measures (truth ids from label_02): per sequence in sequences.csv, their mean over CV in the Tracks table
    tracks = summary["tracks"]
    assert set(tracks) == {"soa", "pubm", "ubm", "ubm-ws"}
    cv = [r for r in _rows(run / "sequences.csv") if r["setting"] == "cv"]
    for m, t in tracks.items():
        hota = [float(r["hota"]) for r in cv if r["model"] == m]
        assert t["sequences"] == len(hota) == 2 and 0 < t["hota_mean"] <= 1
        assert t["hota_mean"] == pytest.approx(sum(hota) / 2) and t["idsw"] == sum(
            int(r["idsw"]) for r in cv if r["model"] == m
        )
    t = tracks["soa"]
    assert f"| S-OA | {t['hota_mean']:.3f} ± {t['hota_std']:.3f} |" in report
    # KITTI's occluded levels, per truth-frame: every CV frame of the export's pedestrians counts at one level, the
    # export writes 0 (in sight), 2 (hidden) and 3 (centre outside the FOV) only
    levels = summary["occlusion_levels"]["soa"]["occluded"]
    assert levels[1]["frames"] == 0 and sum(r["frames"] for r in levels) > 0
    assert all(0 <= r["associated"] <= r["frames"] and r["idsw"] is not None for r in levels)
    assert "## Occlusion levels" in report and "## Identity through undetected gaps" in report
    # TrackEval's own KITTI evaluation of the same estimates, beside ours: it keeps fewer truth rows (its distractor
    # rule drops the hidden and the truncated ones)
    te = summary["trackeval_kitti"]
    assert set(te) == {"soa", "pubm", "ubm", "ubm-ws"}
    for m, r in te.items():
        assert 0 <= r["hota"] <= 1 and 0 < r["gt_dets"] <= sum(
            x["frames"] for x in summary["occlusion_levels"][m]["occluded"]
        )
    assert "## TrackEval's own KITTI evaluation beside ours" in report

    # resume: a lost record is recomputed bit for bit, nothing else is rerun
    record = run / "records" / "cv" / "0001.json"
    before = json.loads(record.read_text())
    record.unlink()
    (run / "summary.json").unlink()
    assert main(["kitti", "--resume", str(run)]) == 0
    err = capsys.readouterr().err
    assert "cv sequence 0001" in err and "sequence 0000" not in err
    after = json.loads(record.read_text())
    before.pop("timing"), after.pop("timing")
    assert after == before
    assert json.loads((run / "summary.json").read_text())["table1"] == t1


def test_kitti_protocol_scores_identities_per_filter_family(exported, tmp_path, capsys):
    """``--filters gmphd,lmb``: the first family's tables are a GM-PHD-only run's, bit for bit; the LMB's Table I,
    Tracks table and S-OA comparison stand beside them, and sequences.csv names each row's family."""
    common = ["kitti", "--root", str(exported), "--semantics", str(exported / "semantics"), "--models", "soa,pubm"]
    assert main([*common, "--out", str(tmp_path / "gm")]) == 0
    assert main([*common, "--filters", "gmphd,lmb", "--out", str(tmp_path / "both")]) == 0
    capsys.readouterr()
    gm = json.loads((tmp_path / "gm" / "summary.json").read_text())
    both = json.loads((tmp_path / "both" / "summary.json").read_text())
    assert both["table1"] == gm["table1"] and both["tracks"] == gm["tracks"] and "families" not in gm
    lmb = both["families"]["lmb"]
    assert set(lmb["tracks"]) == {"soa", "pubm"} and all(0 < t["hota_mean"] <= 1 for t in lmb["tracks"].values())
    assert lmb["table1"] != both["table1"]  # another filter: other numbers
    rows = _rows(tmp_path / "both" / "sequences.csv")
    assert {r["filter"] for r in rows} == {"gmphd", "lmb"} and len(rows) == 2 * 2 * 2  # families x sequences x models
    report = (tmp_path / "both" / "report.md").read_text()
    assert "## The LMB filter" in report and "### Tracks, LMB" in report
    assert main([*common, "--filters", "lmb", "--probability", "dynamic", "--out", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err
    assert "filter family 'lmb' runs the probability modes static, static+occ only" in err and err.count("\n") == 1
    assert not (tmp_path / "bad").exists()


def test_without_semantics_the_report_says_so(exported, tmp_path, capsys):
    root = tmp_path / "nosem"
    shutil.copytree(exported, root, ignore=shutil.ignore_patterns("semantics"))
    (root / "semantics").mkdir()
    (root / "semantics" / "0000.txt").write_text((exported / "semantics" / "0000.txt").read_text())
    run = tmp_path / "run"
    code = main(
        ["kitti", "--root", str(root), "--semantics", str(root / "semantics"), "--models", "soa", "--out", str(run)]
    )
    assert code == 0
    assert "no semantics/0001.txt: S-OA uses its occlusion and FOV terms only" in capsys.readouterr().err
    assert "No semantics for 1 sequence(s) (0001)" in (run / "report.md").read_text()
