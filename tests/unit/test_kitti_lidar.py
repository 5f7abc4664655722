"""S-OA's semantic region from segmented LiDAR scans (soabench/kitti/lidar.py, soabench/kitti/raycast.py): the
synthetic scans of a SUMO export give back the scene's visible sidewalk, S-OA on them matches S-OA on the scene's own
sidewalk polygons, the regions are cached in the run folder, and bad scan or label files stop the run with one line.

One export of 2 trials x 30 s with ``--lidar`` is shared by the module (KITTI's protocol needs >= 2 sequences)."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil

import numpy as np
import pytest
import shapely

from soabench.cli.main import main
from soabench.kitti.config import KittiConfig, kitti_base_config
from soabench.kitti.formats import ReadError
from soabench.kitti.lidar import (
    LidarParams,
    _label_lut,
    _polygons,
    class_ids,
    frame_files,
    region_from_points,
    sequence_regions,
)
from soabench.kitti.lidar_raster import closed_raster, frame_cells, outline_rings
from soabench.kitti.raycast import SIDEWALK, beam_pattern
from soabench.kitti.reader import open_dataset, read_sequence, sensor_for, to_scans

DURATION = 30.0
#: measured IoU of Omega_k (sum of intersections / sum of unions over the 300 frames of sequence 0000) between the
#: point-cloud region and the scene's sidewalk polygons, default parameters: 0.549 out to r_max = 50 m, 0.790 within
#: 30 m of the sensor (beyond, scan rings lie 5-8 m apart and miss strips of sidewalk); bounds with a margin
IOU_BOUNDS = {50.0: 0.50, 30.0: 0.72}
#: S-OA with point-cloud semantics vs with the scene's polygons (same data, N-hat, seed). Measured: mean |cardinality
#: error| 0.833 vs 0.830 (0000) and 1.223 vs 1.223 (0001); mean delay 0.45 vs 0.30 s (2 episodes) and 0.42 vs 0.34 s
#: (5 episodes). Tolerances:
CARD_TOL = 0.10  #: on the sequence's mean |cardinality error|
DELAY_TOL = 0.5  #: on the sequence's mean tracking delay (s)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The export, and `soabench kitti` (S-OA only) on it with --semantics and with --point-labels."""
    base = tmp_path_factory.mktemp("lidar")
    exp = base / "export"
    args = ["export", "kitti", "--trials", "2", "--duration", str(DURATION), "--lidar", "--out", str(exp)]
    assert main(args) == 0
    common = ["kitti", "--root", str(exp), "--models", "soa", "--folds", "2"]
    assert main([*common, "--semantics", str(exp / "semantics"), "--out", str(base / "poly")]) == 0
    assert main([*common, "--point-labels", str(exp / "point_labels"), "--out", str(base / "lidar")]) == 0
    return exp, base / "poly", base / "lidar"


def _record(run, seq):
    return json.loads((run / "records" / "cv" / f"{seq}.json").read_text())["models"]["soa"]


def test_region_of_points_is_the_rasterised_closed_area():
    """Points every 0.3 m on a 10 m x 4 m rectangle: the region is that rectangle to within a cell."""
    x, y = np.meshgrid(np.arange(0.0, 10.0, 0.3), np.arange(5.0, 9.0, 0.3))
    region = region_from_points(np.column_stack([x.ravel(), y.ravel()]), LidarParams(grid=0.5, closing=1.0), 50.0)
    rect = shapely.box(0.0, 5.0, 10.0, 9.0)
    assert shapely.intersection(region, rect).area / shapely.union(region, rect).area > 0.85
    assert region_from_points(np.zeros((0, 2)), LidarParams(), 50.0).is_empty


def _cells_by_arrays(pts, lab, ids, params, r_max, half_fov):
    """The marked cells of each class by the array form of docs/method.md §3.1.4 steps 1-2 (numpy, one class at a
    time), to check the compiled loop against."""
    xy = pts[:, :2].astype(float)
    near = (np.abs(xy) <= r_max).all(axis=1)
    if half_fov >= 0:
        near &= np.abs(np.degrees(np.arctan2(xy[:, 1], xy[:, 0]))) <= half_fov
    xy, lab = xy[near], lab[near]
    r = np.hypot(xy[:, 0], xy[:, 1])
    sector = np.floor((np.arctan2(xy[:, 1], xy[:, 0]) + np.pi) / np.radians(params.sector_deg)).astype(np.int64)
    order = np.lexsort((r, sector))  # by sector, then range, then index
    s, rr = sector[order], r[order]
    out = []
    for cid in ids.values():
        c = np.isin(lab, cid)[order]
        pair = (s[1:] == s[:-1]) & c[1:] & c[:-1] & (np.diff(rr) <= params.fill) & (np.diff(rr) > params.grid)
        a, b = xy[order][:-1][pair], xy[order][1:][pair]
        n = np.ceil(np.hypot(*(b - a).T) / (0.5 * params.grid)).astype(np.int64)
        seg = np.repeat(np.arange(len(n)), n)
        t = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
        q = np.concatenate([xy[np.isin(lab, cid)], a[seg] + t[:, None] * (b[seg] - a[seg])])
        out.append(set(map(tuple, np.floor(q / params.grid).astype(np.int64).tolist())))
    return out


@pytest.mark.parametrize("half_fov", [-1.0, 45.5])
def test_compiled_cells_are_those_of_the_array_form(half_fov):
    """Random returns (rings of a scanner, a few classes): the compiled binning and gap fill mark the same cells."""
    rng = np.random.default_rng(5)
    az = rng.uniform(-np.pi, np.pi, 6000)
    r = rng.choice([4.0, 6.5, 9.0, 13.0, 18.0, 26.0, 40.0, 60.0], 6000) + rng.normal(0.0, 0.05, 6000)
    pts = np.column_stack([r * np.cos(az), r * np.sin(az), np.zeros(6000), np.zeros(6000)]).astype("<f4")
    lab = rng.choice(np.array([48, 50, 40, 0], dtype=np.uint32), 6000, p=[0.5, 0.2, 0.2, 0.1])
    ids = class_ids(("sidewalk", "building"))
    p = LidarParams()
    ci, cj, cc = frame_cells(pts, lab, _label_lut(ids), 2, 50.0, half_fov, p.grid, np.radians(p.sector_deg), p.fill)
    want = _cells_by_arrays(pts, lab, ids, p, 50.0, half_fov)
    for c in range(2):
        assert set(zip(ci[cc == c].tolist(), cj[cc == c].tolist(), strict=True)) == want[c]
    assert len(want[0]) > 100


def _random_raster(seed, shape=(40, 30)):
    rng = np.random.default_rng(seed)
    occ = rng.random(shape) < 0.55
    occ[[0, -1], :] = occ[:, [0, -1]] = False
    return occ


@pytest.mark.parametrize("seed", range(6))
def test_closing_and_traced_outline_are_exact(seed):
    """Random rasters (holes, islands in holes, cells meeting at a corner): the compiled closing is scipy's, and the
    traced rings (shells with their holes, per 4-connected component) cover exactly the occupied cells."""
    from scipy import ndimage

    occ = _random_raster(seed)
    ci, cj = np.nonzero(occ)
    closed, i0, j0 = closed_raster(ci, cj, 2)
    pad = np.zeros((occ.shape[0] + 6, occ.shape[1] + 6), dtype=bool)
    pad[ci + 3, cj + 3] = True
    disc = np.add.outer(np.arange(-2, 3) ** 2, np.arange(-2, 3) ** 2) <= 4
    ref = ndimage.binary_closing(pad, structure=disc)
    lo = (ci.min() - 3, cj.min() - 3)
    want = ref[lo[0] + 3 :, lo[1] + 3 :][: closed.shape[0], : closed.shape[1]]
    assert (i0, j0) == lo and np.array_equal(closed, want) and ref.sum() == closed.sum()
    vi, vj, starts, counts, area2, comp = outline_rings(occ)
    rings = [np.column_stack([vi[s : s + n], vj[s : s + n]]) for s, n in zip(starts, counts, strict=True)]
    polys = []
    for c in np.unique(comp):
        shell = [r for r, a, k in zip(rings, area2, comp, strict=True) if k == c and a > 0]
        assert len(shell) == 1
        polys.append(
            shapely.Polygon(shell[0], [r for r, a, k in zip(rings, area2, comp, strict=True) if k == c and a < 0])
        )
    assert sum(area2) == 2 * occ.sum() and sum(p.area for p in polys) == occ.sum()
    cells = shapely.union_all(shapely.box(ci, cj, ci + 1, cj + 1))
    assert shapely.symmetric_difference(shapely.union_all(polys), cells).area == 0.0
    # simplified, made valid where rings touch, cut into hole-free pieces that do not overlap
    pieces = [shapely.Polygon(xy) for xy in _polygons(occ, 0, 0, 1.0)]
    assert all(p.is_valid and not p.interiors for p in pieces)
    union = shapely.union_all(pieces)
    assert union.area == pytest.approx(sum(p.area for p in pieces)) and union.area == pytest.approx(occ.sum(), rel=0.1)


@pytest.mark.parametrize("seed", range(6))
def test_simplified_polygons_agree_with_shapely_simplify(seed):
    """The hole-free polygons of a raster cover what ``shapely.simplify`` makes of the union of its cells (within half
    a cell) to an IoU of at least 0.97, and are valid."""
    occ = ndimage_smooth(_random_raster(seed, (60, 50)))
    ci, cj = np.nonzero(occ)
    g = 0.5
    ref = shapely.simplify(shapely.coverage_union_all(shapely.box(ci * g, cj * g, (ci + 1) * g, (cj + 1) * g)), g / 2)
    got = [shapely.Polygon(xy) for xy in _polygons(occ, 0, 0, g)]
    assert all(p.is_valid and not p.interiors for p in got)
    mine = shapely.union_all(got)
    assert shapely.intersection(mine, ref).area / shapely.union(mine, ref).area >= 0.97


def ndimage_smooth(occ):
    """Blobs rather than noise: a majority filter of a random raster."""
    from scipy import ndimage

    return ndimage.uniform_filter(occ.astype(float), 5) > 0.5


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_scan_with_non_finite_points_is_a_read_error_naming_it(tmp_path, bad):
    vel, lab = tmp_path / "velodyne" / "0003", tmp_path / "labels" / "0003"
    vel.mkdir(parents=True)
    lab.mkdir(parents=True)
    pts = np.full((50, 4), bad, dtype="<f4")
    pts.tofile(vel / "000000.bin")
    np.full(len(pts), 48, dtype="<u4").tofile(lab / "000000.label")
    with pytest.raises(ReadError, match=r"000000\.bin: 50 of 50 points have a NaN or infinite coordinate"):
        sequence_regions(tmp_path / "velodyne", tmp_path / "labels", "0003", 1, ("sidewalk",), LidarParams(), 50.0)


def test_regions_are_cached_by_files_and_parameters(tmp_path):
    """Two frames of hand-made points: built once, read back, rebuilt when a parameter or a file changes."""
    vel, lab = tmp_path / "velodyne" / "0003", tmp_path / "labels" / "0003"
    vel.mkdir(parents=True)
    lab.mkdir(parents=True)
    x, y = np.meshgrid(np.arange(2.0, 12.0, 0.3), np.arange(3.0, 6.0, 0.3))
    pts = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, -1.7), np.zeros(x.size)]).astype("<f4")
    for k in range(2):
        pts.tofile(vel / f"{k:06d}.bin")
        np.full(len(pts), 48 | (7 << 16), dtype="<u4").tofile(lab / f"{k:06d}.label")  # sidewalk, instance 7
    args = (tmp_path / "velodyne", tmp_path / "labels", "0003", 2, ("sidewalk",))
    cache = tmp_path / "run" / "lidar"
    sem, hit = sequence_regions(*args, LidarParams(), 50.0, cache)
    assert not hit and sorted(sem) == [0, 1] and sem[0][0][0] == "sidewalk"
    assert shapely.Polygon(sem[0][0][1]).area == pytest.approx(10.0 * 3.0, rel=0.2)
    again, hit = sequence_regions(*args, LidarParams(), 50.0, cache)
    assert hit and all(np.array_equal(a[1], b[1]) for a, b in zip(sem[1], again[1], strict=True))
    assert not sequence_regions(*args, LidarParams(grid=1.0), 50.0, cache)[1]
    assert sequence_regions(*args, LidarParams(grid=1.0), 50.0, cache)[1]
    changed, before = lab / "000001.label", (lab / "000001.label").stat().st_mtime_ns
    changed.write_bytes(np.zeros(len(pts), dtype="<u4").tobytes())  # unlabelled now, same size
    os.utime(changed, ns=(before + 10**9, before + 10**9))  # a later time even where mtimes are coarse
    sem, hit = sequence_regions(*args, LidarParams(grid=1.0), 50.0, cache)
    assert not hit and sorted(sem) == [0]


@pytest.mark.slow
def test_synthetic_scans_follow_the_hdl64_pattern(runs):
    exp = runs[0]
    files = frame_files(exp / "velodyne", exp / "point_labels", "0000", 300)
    az, el = beam_pattern()
    assert len(el) == 64 and np.degrees(el[[0, -1]]).round(1).tolist() == [-24.8, 2.0]
    assert all(0 < n <= len(az) * len(el) for _, _, n in files)
    lab = np.fromfile(files[150][1], dtype="<u4")
    assert (lab == SIDEWALK).any() and set(np.unique(lab)) <= {10, 30, 40, 48, 50}


@pytest.mark.slow
def test_region_from_synthetic_scans_matches_the_visible_sidewalk(runs):
    exp, _, lidar_run = runs
    cfg, kc = kitti_base_config(), KittiConfig()
    seq = read_sequence(open_dataset(exp, None, exp / "semantics"), "0000")
    ref = to_scans(seq, kc, cfg.sensor_at())
    sem, cached = sequence_regions(
        exp / "velodyne", exp / "point_labels", "0000", seq.n_frames, ("sidewalk", "building"), LidarParams(),
        cfg.sensor.r_max, lidar_run / "lidar", sensor_for(seq, kc, cfg.sensor_at()).fov_deg,
    )  # fmt: skip
    assert cached  # the run built them with these parameters
    out = to_scans(dataclasses.replace(seq, semantics=sem), kc, cfg.sensor_at())
    for radius, bound in IOU_BOUNDS.items():
        inter = union = 0.0
        for a, b in zip(ref.scans.scans, out.scans.scans, strict=True):
            disk = shapely.Point(a.ego[:2]).buffer(radius, 64)
            ra, rb = shapely.intersection(a.visible_region, disk), shapely.intersection(b.visible_region, disk)
            inter += shapely.intersection(ra, rb).area
            union += shapely.union(ra, rb).area
        assert union > 0 and inter / union >= bound, (radius, inter / union)


@pytest.mark.slow
def test_soa_with_point_cloud_semantics_matches_the_scene_polygons(runs):
    _, poly_run, lidar_run = runs
    for seq in ("0000", "0001"):
        a, b = _record(poly_run, seq), _record(lidar_run, seq)
        card = (a["summary"]["card_err"], b["summary"]["card_err"])
        assert abs(card[0] - card[1]) <= CARD_TOL, card
        da = [e["delay"] for e in a["episodes"] if e["delay"] is not None]
        db = [e["delay"] for e in b["episodes"] if e["delay"] is not None]
        assert len(da) >= 1 and len(db) >= 1
        assert abs(np.mean(da) - np.mean(db)) <= DELAY_TOL, (np.mean(da), np.mean(db), len(da), len(db))


@pytest.mark.slow
def test_report_names_the_semantic_source_and_resume_reads_the_cache(runs, capsys):
    _, poly_run, lidar_run = runs
    assert "point labels" in (lidar_run / "report.md").read_text()
    assert "point labels" not in (poly_run / "report.md").read_text()
    (lidar_run / "records" / "cv" / "0001.json").unlink()
    capsys.readouterr()
    assert main(["kitti", "--resume", str(lidar_run)]) == 0
    assert "read from lidar/0001.npz" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize(
    ("damage", "message"),
    [
        ("short_bin", "is not a whole number of points"),
        ("extra_label", "labels, but"),
        ("no_label", "is missing"),
    ],
)
def test_bad_scans_or_labels_stop_with_one_line(runs, tmp_path, capsys, damage, message):
    exp = runs[0]
    bad = tmp_path / "export"
    shutil.copytree(exp, bad, ignore=shutil.ignore_patterns("velodyne", "point_labels"))
    for d in ("velodyne", "point_labels"):  # links to the export's files, sequence 0001's frame 10 a copy
        (bad / d / "0001").mkdir(parents=True)
        (bad / d / "0000").symlink_to(exp / d / "0000")
        for f in (exp / d / "0001").iterdir():
            (bad / d / "0001" / f.name).symlink_to(f)
    scan, lab = bad / "velodyne" / "0001" / "000010.bin", bad / "point_labels" / "0001" / "000010.label"
    for f in (scan, lab):
        data = f.read_bytes()
        f.unlink()
        f.write_bytes(data)
    if damage == "short_bin":
        scan.write_bytes(scan.read_bytes()[:-4])
    elif damage == "extra_label":
        lab.write_bytes(lab.read_bytes() + b"\0\0\0\0")
    else:
        lab.unlink()
    capsys.readouterr()
    args = ["kitti", "--root", str(bad), "--point-labels", str(bad / "point_labels"), "--models", "soa"]
    assert main([*args, "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and "0001" in err[0]
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
def test_option_errors(runs, tmp_path, capsys):
    exp = runs[0]
    base = ["kitti", "--root", str(exp), "--out", str(tmp_path / "run")]
    curb = tmp_path / "curb.toml"
    curb.write_text('[kitti]\nsemantic_classes = ["curb"]\n')
    cases = [
        (["--point-labels", str(exp / "point_labels"), "--semantics", str(exp / "semantics")], "either"),
        (["--lidar-grid", "0.5"], "needs --point-labels"),
        (["--point-labels", str(tmp_path / "nope")], "is not a folder"),
        (["--point-labels", str(exp / "point_labels"), "--lidar-grid", "0"], "--lidar-grid"),
        (["--point-labels", str(exp / "point_labels"), "--config", str(curb)], "'curb' have no SemanticKITTI id"),
    ]
    for extra, message in cases:
        capsys.readouterr()
        assert main([*base, *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0]
