"""Track labels (docs/method.md §2.13): the labelled GM-PHD, the label contract of every tracker, truth labels.

* T30: labels never enter the arithmetic. On recorded scans of the shipped intersection, for every birth model and
  probability mode, a filter whose labels are scrambled at every scan (the counter started elsewhere, the prior's
  labels permuted) gives weights, means, covariances, estimates and diagnostics bit-identical to an untouched one.
  (The byte-identical ``trials.csv`` of a short run against the code before labels is recorded in
  benchmarks/README.md.)
* T31: one target, p_D = 1, no clutter, a constant-velocity walk of 30 scans keeps one label from initiation on.
* The merge and extraction rules of §2.13 on hand-made mixtures, on the compiled cycle and the array path alike.
* Plugin output: labels are checked (shape, integer dtype, distinct within a scan) with one clear message.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from shapely.geometry import Polygon

from soabench.birth import get_birth_model
from soabench.config import PROBABILITY_MODES, FilterConfig, Sensor, filter_config_for_mode
from soabench.experiment.trial.guard import PluginOutputError, check_estimates
from soabench.gmphd import GMPHDFilter, Mixture, cycle, reduction
from soabench.gmphd.filter import _mixture_arrays
from soabench.gmphd.models import h
from soabench.plugins import BUILTIN_BIRTH_MODELS
from soabench.types import BirthContext, Births, Estimates, NewbornTerms, Obstacles, Scan, truth_labels


@pytest.fixture(scope="module")
def recorded(recorded_intersection):
    """(config, scene, sensor, scans, seeds) of a 30 s trial of the shipped intersection with lambda = 3."""
    cfg, scene, scans, seeds = recorded_intersection
    return cfg, scene, *scans[3.0], seeds


def _bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a).tobytes()


@pytest.mark.parametrize("model", list(BUILTIN_BIRTH_MODELS))
def test_t30_labels_do_not_move_a_number(recorded, model):
    cfg, scene, sensor, scans, seeds = recorded
    rng = np.random.default_rng(30)
    n_labelled = 0
    for mode in PROBABILITY_MODES:
        filter_cfg, filter_mode, p_D_b = filter_config_for_mode(cfg.filter, mode)
        birth = get_birth_model(model)(cfg.birth, sensor, scene, seeds.placement_rng())
        plain = GMPHDFilter(filter_cfg, sensor, filter_mode)
        scrambled = GMPHDFilter(filter_cfg, sensor, filter_mode)
        scrambled.next_label = 10**12
        prev = None
        for scan in scans.scans:
            births = birth(BirthContext(scan, prev, p_D_b))
            mix = scrambled.mixture
            mix.label = rng.permutation(mix.label) + rng.integers(0, 1000)  # any labels at all
            a, b = plain.step(scan, births), scrambled.step(scan, births)
            for f in ("w", "m", "P", "origin", "n_det", "age"):
                assert _bits(getattr(plain.mixture, f)) == _bits(getattr(scrambled.mixture, f)), f
            if plain.mixture.beta is not None:
                assert _bits(plain.mixture.beta) == _bits(scrambled.mixture.beta)
            for f in ("X", "X_w", "A", "kappa", "origin_counts"):
                assert _bits(getattr(a, f)) == _bits(getattr(b, f)), f
            for f in ("sum_w", "sum_w_reduced", "mean_pD", "n_predicted", "n_updated", "n_reduced", "n_pairs"):
                assert getattr(a, f) == getattr(b, f), f
            assert a.labels.dtype == np.int64 and len(a.labels) == len(a.X)
            assert len(set(a.labels.tolist())) == len(a.labels)  # distinct within a scan (§2.13 item 4)
            n_labelled += len(a.labels)
            prev = a
    assert n_labelled > 0


def _walk_scans(n: int = 30, seed: int = 31) -> tuple[list[Scan], Sensor, np.ndarray]:
    """One target on a constant-velocity walk in front of a static sensor, detected at every scan, no clutter."""
    sensor = Sensor(lambda_c=0.0, p_D=1.0)
    rng = np.random.default_rng(seed)
    x0 = np.array([12.0, -6.0, 0.6, 0.5])
    ego = np.zeros(3)
    scans, truth = [], []
    for k in range(n):
        x = x0.copy()
        x[:2] += k * sensor.dt * x0[2:]
        z = h(x[None], ego)[0] + rng.normal(0.0, [sensor.sigma_r, sensor.sigma_b])
        scans.append(Scan(k, k * sensor.dt, ego, z.reshape(1, 2), Obstacles.empty(), [], Polygon()))
        truth.append(x)
    return scans, sensor, np.array(truth)


def _start_birth(x: np.ndarray) -> Births:
    """A fixed birth component where the walk starts (GMBM-like)."""
    m = np.array([[x[0], x[1], 0.0, 0.0]])
    return Births(np.array([0.1]), m, np.diag([4.0, 4.0, 1.0, 1.0])[None], np.zeros(1, dtype=np.int8))


def _newborn(z: np.ndarray, ego: np.ndarray) -> Births:
    """A measurement-driven newborn term at each measurement (PUBM/ATBM-like), with a small constant beta."""
    r, b = z[:, 0], z[:, 1] + ego[2]
    M = len(z)
    m = np.column_stack([ego[0] + r * np.cos(b), ego[1] + r * np.sin(b), np.zeros((M, 2))])
    P = np.broadcast_to(np.diag([1.0, 1.0, 1.0, 1.0]), (M, 4, 4)).copy()
    nb = NewbornTerms(m, P, lambda A, kappa: np.full(len(A), 1e-3))
    return dataclasses.replace(Births.empty(), newborn=nb)


@pytest.mark.parametrize("birth", ["appended", "newborn"])
@pytest.mark.parametrize("mode", ["static", "dynamic"])
@pytest.mark.parametrize("fused", [True, False])
def test_t31_one_target_keeps_one_label(birth, mode, fused):
    scans, sensor, truth = _walk_scans()
    filt = GMPHDFilter(FilterConfig(p_D=1.0), sensor, mode, fused=fused)
    labels, first = [], None
    for k, scan in enumerate(scans):
        births = _start_birth(truth[0]) if birth == "appended" else _newborn(scan.Z, scan.ego)
        res = filt.step(scan, births)
        if len(res.X):
            first = k if first is None else first
            assert len(res.X) == 1, f"scan {k}: {len(res.X)} estimates of one target"
            assert np.hypot(*(res.X[0, :2] - truth[k, :2])) < 3.0
            labels.append(int(res.labels[0]))
        else:
            assert first is None, f"scan {k}: the track was lost after initiation at scan {first}"
    assert first is not None and first <= 1
    assert len(set(labels)) == 1, f"labels {labels}: one target must keep one label (IDSW = 0, Frag = 0)"
    assert labels[0] >= 1


def _mix(w, xy, label, P_scale=1.0) -> Mixture:
    w = np.asarray(w, dtype=float)
    m = np.zeros((len(w), 4))
    m[:, :2] = xy
    P = np.broadcast_to(np.eye(4) * P_scale, (len(w), 4, 4)).copy()
    return Mixture.from_arrays(w, m, P, origin=0, label=np.asarray(label, dtype=np.int64))


CFG = FilterConfig()
RED = GMPHDFilter(CFG, Sensor(), "static")._red_pars


def _reduce_both(mix: Mixture, next_label: int):
    """The compiled reduction and the array path (prune/merge/cap, then extraction) of one mixture."""
    red, X, X_w, X_label, _, stats = cycle.reduce(*_mixture_arrays(mix.copy()), RED, next_label)
    arr = reduction.prune_merge_cap(mix.copy(), CFG.prune_T, CFG.merge_U, CFG.J_max, CFG.theta_min)
    aX, _, aX_label, a_next = reduction.extract_labelled(arr.mix, CFG.extract_thr, "vo_ma", next_label)
    np.testing.assert_array_equal(red[7], arr.mix.label)
    np.testing.assert_array_equal(X_label, aX_label)
    np.testing.assert_array_equal(X, aX)
    assert stats[4] == a_next
    return red[0], red[7], X_label, stats[4]


def test_merged_component_takes_the_heaviest_members_label():
    # three members of one group: the heaviest (index 1) is j*, its label goes to the merged component
    w, label, X_label, nxt = _reduce_both(_mix([0.3, 0.5, 0.2], [[0, 0], [0.1, 0], [0, 0.1]], [7, 8, 9]), 100)
    assert len(w) == 1 and label.tolist() == [8] and X_label.tolist() == [8] and nxt == 100


def test_merge_tie_keeps_the_label_of_the_member_picked_first():
    # equal weights: the merge picks the lower index first (stable heaviest-first order), so its label wins
    _, label, _, _ = _reduce_both(_mix([0.4, 0.4], [[0, 0], [0.1, 0]], [5, 3]), 100)
    assert label.tolist() == [5]


def test_extraction_conflict_heaviest_keeps_others_fresh_and_written_back():
    # two far-apart updated copies of one track (label 4) both extracted, plus a heavy component with 3 copies
    mix = _mix([0.7, 0.9, 2.6, 0.3], [[0, 0], [40, 0], [0, 40], [40, 40]], [4, 4, 6, 4])
    w, label, X_label, nxt = _reduce_both(mix, 100)
    # the reduction orders the components heaviest first (merge groups in creation order): 2.6, 0.9, 0.7, 0.3
    assert w.tolist() == [2.6, 0.9, 0.7, 0.3]
    # 0.9 keeps 4; 0.7 gets the fresh 100, written back; 0.3 (not extracted) keeps 4
    assert label.tolist() == [6, 4, 100, 4]
    # X in component order: the three copies of 2.6 (6, then one-scan labels 101 and 102, after the conflict's
    # fresh label), 4, 100
    assert X_label.tolist() == [6, 101, 102, 4, 100]
    assert nxt == 103


def test_extraction_conflict_tie_goes_to_the_lower_index():
    _, label, X_label, nxt = _reduce_both(_mix([0.8, 0.8, 0.8], [[0, 0], [40, 0], [80, 0]], [2, 2, 2]), 10)
    assert label.tolist() == [2, 10, 11] and X_label.tolist() == [2, 10, 11] and nxt == 12


def test_a_conflict_winner_continues_its_track_next_scan():
    """The relabelled copy continues under its fresh label: after one more cycle both tracks keep their labels."""
    scans, sensor, _ = _walk_scans(2)
    filt = GMPHDFilter(FilterConfig(), sensor, "static")
    filt.mixture = _mix([0.9, 0.8], [[15, 8], [15, -8]], [4, 4], P_scale=0.5)
    filt.next_label = 50
    scan = Scan(0, 0.0, np.zeros(3), h(filt.mixture.m, np.zeros(3)), Obstacles.empty(), [], Polygon())
    first = filt.step(scan, Births.empty())
    assert sorted(first.labels.tolist()) == [4, 50]
    pred_xy = filt.mixture.m[:, :2] + sensor.dt * filt.mixture.m[:, 2:]
    scan = Scan(1, sensor.dt, np.zeros(3), h(np.column_stack([pred_xy, np.zeros((2, 2))]), np.zeros(3)),
                Obstacles.empty(), [], Polygon())  # fmt: skip
    second = filt.step(scan, Births.empty())
    by_y = {round(float(y)): int(lab) for y, lab in zip(second.X[:, 1], second.labels, strict=True)}
    assert by_y == {8: 4, -8: 50}


def test_birth_and_newborn_labels_come_from_one_counter_in_order():
    filt = GMPHDFilter(FilterConfig(), Sensor(lambda_c=0.0), "static", fused=True)
    births = _start_birth(np.array([10.0, 0.0]))
    births = Births(
        np.full(3, 0.01), np.repeat(births.m, 3, 0) + [[0, 0, 0, 0], [0, 30, 0, 0], [0, -30, 0, 0]],
        np.repeat(births.P, 3, 0), np.zeros(3, dtype=np.int8),
        _newborn(np.array([[20.0, 0.5], [25.0, -0.5]]), np.zeros(3)).newborn,
    )  # fmt: skip
    scan = Scan(0, 0.0, np.zeros(3), np.array([[20.0, 0.5], [25.0, -0.5]]), Obstacles.empty(), [], Polygon())
    res = filt.step(scan, births)
    # births take 1, 2, 3 (none detected: weights 0.01, pruned or kept, never extracted); the newborns of the two
    # measurements take 4 and 5 and are the estimates
    assert sorted(res.labels.tolist()) == [4, 5]
    assert filt.next_label == 6


def test_plugin_labels_are_checked():
    scan = Scan(0, 0.0, np.zeros(3), np.zeros((0, 2)), Obstacles.empty(), [], Polygon())
    X = np.array([[1.0, 2.0], [3.0, 4.0]])
    ok = check_estimates(Estimates(X, labels=np.array([7, 9], dtype=np.int32)), scan, 0.0)
    assert ok.labels.dtype == np.int64 and ok.labels.tolist() == [7, 9]
    assert check_estimates(Estimates(X), scan, 0.0).labels is None
    for bad, says in (
        (np.array([1.0, 2.0]), "dtype float64"),
        (np.array([1, 2, 3]), "shape (3,)"),
        (np.array([True, False]), "dtype bool"),
        (np.array(["a", "b"]), "dtype <U1"),
    ):
        with pytest.raises(ValueError, match="Estimates: labels") as exc:  # refused when built
            Estimates(X, labels=bad)
        assert says in str(exc.value) and "\n" not in str(exc.value)
        built = Estimates(X)
        built.labels = bad  # set after building: the harness's check still refuses it
        with pytest.raises(PluginOutputError, match="Estimates.labels") as exc:
            check_estimates(built, scan, 0.0)
        assert says in str(exc.value)
    with pytest.raises(PluginOutputError, match="label 5 to more than one estimate"):
        check_estimates(Estimates(X, labels=np.array([5, 5])), scan, 0.0)


def test_truth_labels():
    assert truth_labels(np.array(["ped0", "ped12", "ped3"])).tolist() == [0, 12, 3]
    assert truth_labels(np.array(["3", "17"])).tolist() == [3, 17]
    assert truth_labels(np.array(["a", "b", "c"])).tolist() == [0, 1, 2]
    assert truth_labels(np.array(["ped1", "car1"])).tolist() == [0, 1]  # two prefixes: by column
    assert truth_labels(np.array(["p1", "p01"])).tolist() == [0, 1]  # equal numbers: by column
    assert truth_labels(np.array([], dtype=str)).dtype == np.int64


def test_scans_carry_the_pedestrians_ids_as_ints(recorded):
    scans = recorded[3]
    labels = scans.ped_labels
    assert labels.dtype == np.int64 and len(labels) == scans.truth_xy.shape[1] == len(scans.ped_ids)
    assert [f"ped{i}" for i in labels] == [str(p) for p in scans.ped_ids]


@pytest.mark.parametrize("name", ["stonesoup-gnn", "stonesoup-gmphd"])
def test_stonesoup_trackers_keep_one_label_on_one_target(name):
    """The bridge numbers Stone Soup's track ids (GNN) and component tags (GM-PHD) per run: the T31 walk is one
    track under one label from the scan it is first reported on."""
    from soabench.api import make_tracker

    scans, _, _ = _walk_scans()
    tracker = make_tracker(name, "intersection", {"experiment": {"clutter": [0.0]}})
    labels = []
    for scan in scans:
        est = check_estimates(tracker.step(scan), scan, 0.0)
        assert est.labels is not None and len(est.labels) == len(est.X) <= 1
        labels += est.labels.tolist()
    assert len(labels) >= len(scans) - 2 and set(labels) == {1}


def test_kitti_truth_labels_are_the_track_ids_of_label_02(tmp_path):
    from kitti_files import write_sequence

    from soabench.kitti.config import KittiConfig
    from soabench.kitti.reader import open_dataset, read_sequence, to_scans

    write_sequence(tmp_path, "0000")
    labels = tmp_path / "label_02" / "0000.txt"
    labels.write_text(labels.read_text().replace(" 0 Pedestrian ", " 17 Pedestrian "))  # track id 0 -> 17
    ss = to_scans(read_sequence(open_dataset(tmp_path), "0000"), KittiConfig(), Sensor(dt=0.1, r_max=50.0))
    assert list(ss.scans.ped_ids) == ["17"] and ss.scans.ped_labels.tolist() == [17]


def _extract_labels_reference(w, label, idx, reps, nxt):
    """The rule of §2.13 item 4 written plainly: heaviest (then lowest index) keeps a shared label, the others get
    fresh labels heaviest first; extra copies get fresh labels after those, in the order of X."""
    label = label.copy()
    owner = {}
    for j in sorted(idx.tolist(), key=lambda j: (-w[j], j)):
        owner.setdefault(int(label[j]), j)
    for j in sorted(idx.tolist(), key=lambda j: (-w[j], j)):
        if owner[int(label[j])] != j:
            label[j], nxt = nxt, nxt + 1
    out = []
    for j, r in zip(idx.tolist(), reps.tolist(), strict=True):
        out.append(int(label[j]))
        for _ in range(r - 1):
            out.append(nxt)
            nxt += 1
    return out, label, nxt


@pytest.mark.parametrize("n", [2, 7, 24, 25, 120])
def test_extract_labels_equals_the_plain_rule(n):
    """Small scans take a pairwise conflict test, large ones a sort: both give the plain rule's labels."""
    from soabench.gmphd.kernels import extract_labels

    rng = np.random.default_rng(n)
    for _ in range(20):
        J = n + 5
        w = rng.choice([0.6, 0.8, 1.2, 2.6], J)  # ties on purpose
        label = rng.integers(1, max(2, n // 2), J).astype(np.int64)
        idx = np.sort(rng.choice(J, n, replace=False))
        reps = np.floor(w[idx] + 0.5).astype(np.int64)
        want = _extract_labels_reference(w, label, idx, reps, 1000)
        out, new_label, nxt = extract_labels(w, label.copy(), idx, reps, 1000)
        assert out.tolist() == want[0] and new_label.tolist() == want[1].tolist() and nxt == want[2]


def test_labelled_estimates_reach_the_step_results_the_metrics_read(recorded):
    """Estimates built from the truth, labelled with the truth's labels, pass through the checks of
    ``soabench.api.evaluate`` (:func:`soabench.boundary.step_results`) with their labels row for row."""
    from soabench.boundary import step_results

    scans = recorded[3]
    estimates = []
    for k in range(len(scans)):
        cols = np.flatnonzero(scans.present[k])
        estimates.append(Estimates(scans.truth_xy[k, cols], labels=scans.ped_labels[cols]))
    results = step_results(scans, estimates)
    assert sum(len(r.labels) for r in results) == int(scans.present.sum()) > 0
    for k, r in enumerate(results):
        assert r.labels.tolist() == scans.ped_labels[scans.present[k]].tolist()
