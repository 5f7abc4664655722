"""Track metrics (docs/method.md §9.3, §9.4): HOTA / CLEAR MOT / IDF1 against TrackEval (T32), OSPA(2)
(T33), re-emergence after occlusion (T34)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from shapely.geometry import Polygon
from trackeval.metrics import CLEAR, HOTA, Identity

from soabench.config import MetricsConfig, Sensor
from soabench.errors import SoabenchError
from soabench.metrics import delay_episodes
from soabench.tracks.evaluate import ALPHA_KEYS, LABEL_KEYS, REEMERGENCE_KEYS, TRACK_KEYS, evaluate_tracks
from soabench.tracks.ospa2 import ospa2
from soabench.tracks.reemergence import associated_labels, occlusion_gaps, reemergence
from soabench.tracks.scores import ALPHAS, track_scores
from soabench.tracks.sequence import TrackSequence
from soabench.types import Scan, Scans

D_GATE = 5.0

# ---------------------------------------------------------------------------------------------------------------------
# T32: HOTA, CLEAR MOT and IDF1 equal TrackEval's


def random_sequence(seed: int, K: int = 40) -> tuple[list, list, list, list]:
    """1-6 walking truths that leave and come back (gaps), 0-8 estimates per scan near them with noise, labels drawn
    from a small pool so that they swap between truths and recur after gaps."""
    rng = np.random.default_rng(seed)
    n_truth = int(rng.integers(1, 7))
    pos = rng.uniform(0, 30, (n_truth, 2))
    gt_ids, gt_xy, est_ids, est_xy = [], [], [], []
    for _ in range(K):
        pos += rng.normal(0, 0.7, pos.shape)
        present = np.flatnonzero(rng.random(n_truth) < 0.8)
        gt_ids.append(present + 100)
        gt_xy.append(pos[present].copy())
        m = int(rng.integers(0, 9))
        est_ids.append(rng.choice(12, m, replace=False) * 7 - 20)  # negative labels too: any int64
        est_xy.append(pos[rng.integers(0, n_truth, m)] + rng.normal(0, 3.0, (m, 2)))
    return gt_ids, gt_xy, est_ids, est_xy


def trackeval_values(seq: TrackSequence) -> dict[str, np.ndarray]:
    """TrackEval's HOTA, CLEAR and Identity of ``seq`` (S of register row 30, threshold 0.5; no config printing)."""
    data = seq.trackeval_data(D_GATE)
    quiet = {"THRESHOLD": 0.5, "PRINT_CONFIG": False}
    return {
        **HOTA().eval_sequence(data),
        **CLEAR(dict(quiet)).eval_sequence(data),
        **Identity(dict(quiet)).eval_sequence(data),
    }


#: our field -> TrackEval's
FIELDS = {
    "hota_alpha": "HOTA", "deta_alpha": "DetA", "assa_alpha": "AssA", "loca_alpha": "LocA", "detre_alpha": "DetRe",
    "detpr_alpha": "DetPr", "assre_alpha": "AssRe", "asspr_alpha": "AssPr", "mota": "MOTA", "motp": "MOTP",
    "moda": "MODA", "idsw": "IDSW", "frag": "Frag", "mt": "MT", "pt": "PT", "ml": "ML", "clr_tp": "CLR_TP",
    "clr_fn": "CLR_FN", "clr_fp": "CLR_FP", "idf1": "IDF1", "idp": "IDP", "idr": "IDR", "idtp": "IDTP",
    "idfn": "IDFN", "idfp": "IDFP",
}  # fmt: skip


def assert_equal_trackeval(gt_ids, gt_xy, est_ids, est_xy) -> None:
    ours = track_scores(gt_ids, gt_xy, est_ids, est_xy, D_GATE)
    ref = trackeval_values(TrackSequence.of(gt_ids, gt_xy, est_ids, est_xy))
    for field, key in FIELDS.items():
        np.testing.assert_allclose(getattr(ours, field), ref[key], rtol=0, atol=1e-12, err_msg=field)
    for field, key in (("hota", "HOTA"), ("deta", "DetA"), ("assa", "AssA"), ("loca", "LocA")):
        assert abs(getattr(ours, field) - float(np.mean(ref[key]))) <= 1e-12, field


@pytest.mark.parametrize("seed", range(20))
def test_t32_random_sequences_equal_trackeval(seed):
    gt_ids, gt_xy, est_ids, est_xy = random_sequence(seed)
    ours = track_scores(gt_ids, gt_xy, est_ids, est_xy, D_GATE)
    assert 0 < ours.hota < 1 and ours.idsw + ours.frag > 0  # a sequence with something to get wrong
    assert_equal_trackeval(gt_ids, gt_xy, est_ids, est_xy)


@pytest.mark.parametrize("case", ["no estimates", "no truth", "nothing", "empty scans between"])
def test_t32_empty_cases_equal_trackeval(case):
    gt_ids, gt_xy, est_ids, est_xy = random_sequence(3, K=12)
    if case in ("no estimates", "nothing"):
        est_ids, est_xy = [np.zeros(0, int)] * 12, [np.zeros((0, 2))] * 12
    if case in ("no truth", "nothing"):
        gt_ids, gt_xy = [np.zeros(0, int)] * 12, [np.zeros((0, 2))] * 12
    if case == "empty scans between":
        for k in (2, 3, 7):
            est_ids[k], est_xy[k] = np.zeros(0, int), np.zeros((0, 2))
        gt_ids[5], gt_xy[5] = np.zeros(0, int), np.zeros((0, 2))
    assert_equal_trackeval(gt_ids, gt_xy, est_ids, est_xy)


def two_walkers(N: int, swap: bool) -> tuple[list, list, list, list]:
    """Two targets 50 m apart over 2N scans, estimated exactly; with ``swap`` their labels swap after scan N."""
    gt_ids, gt_xy, est_ids, est_xy = [], [], [], []
    for k in range(2 * N):
        xy = np.array([[k * 1.0, 0.0], [k * 1.0, 50.0]])
        gt_ids.append(np.array([1, 2]))
        gt_xy.append(xy)
        est_ids.append(np.array([20, 10]) if swap and k >= N else np.array([10, 20]))
        est_xy.append(xy.copy())
    return gt_ids, gt_xy, est_ids, est_xy


def test_t32_perfect_tracking():
    s = track_scores(*two_walkers(10, swap=False), D_GATE)
    assert s.hota == s.deta == s.assa == s.loca == 1.0
    assert s.mota == s.idf1 == s.motp == 1.0 and s.idsw == s.frag == 0 and (s.mt, s.pt, s.ml) == (2, 0, 0)


@pytest.mark.parametrize("N", [5, 10, 17])
def test_t32_swapped_labels(N):
    s = track_scores(*two_walkers(N, swap=True), D_GATE)
    assert s.deta == 1.0
    assert s.assa == pytest.approx(1 / 3, abs=1e-15)
    assert s.hota == pytest.approx(1 / math.sqrt(3), abs=1e-15)
    assert s.idsw == 2 and s.idf1 == 0.5 and s.mota == 1 - 2 / (4 * N)
    np.testing.assert_allclose(s.hota_alpha, np.full(len(ALPHAS), 1 / math.sqrt(3)), rtol=0, atol=1e-15)
    assert_equal_trackeval(*two_walkers(N, swap=True))


def test_similarity_threshold_is_the_delay_gate():
    """S >= 0.5 exactly when d <= d_gate: an estimate at d_gate matches, one just beyond does not."""
    for d, matched in ((D_GATE, 1), (D_GATE * (1 + 1e-9), 0)):
        s = track_scores([np.array([1])], [np.array([[0.0, 0.0]])], [np.array([7])], [np.array([[d, 0.0]])], D_GATE)
        assert s.clr_tp == s.idtp == matched


@pytest.mark.parametrize(
    ("gt_ids", "est_ids", "est_xy", "message"),
    [
        ([np.array([1, 1])], [np.array([3])], [np.zeros((1, 2))], "truth at scan 0: an id appears twice"),
        ([np.array([1, 2])], [np.array([3, 3])], [np.zeros((2, 2))], "estimates at scan 0: an id appears twice"),
        ([np.array([1, 2])], [np.array([3, 4])], [np.zeros((1, 2))], "1 positions"),
        ([np.array([1, 2])], [np.array([0.5])], [np.zeros((1, 2))], "ids must be integers"),
        ([np.array([1, 2])], [np.array([3])], [np.array([[np.nan, 0.0]])], "NaN or infinite position"),
        ([np.array([1, 2])], [], [], "1 scans of truth but 0 scans of estimates"),
    ],
)
def test_bad_input_is_one_clear_error(gt_ids, est_ids, est_xy, message):
    with pytest.raises(SoabenchError, match=message):
        track_scores(gt_ids, [np.zeros((2, 2))], est_ids, est_xy, D_GATE)


def test_t32_repeated_positions_equal_trackeval():
    """Estimates extracted twice (equal positions, different labels) and two truths at one point: several optimal
    matchings exist, and the scan is matched as TrackEval matches it."""
    gt_ids, gt_xy, est_ids, est_xy = random_sequence(11)
    for k in range(0, 40, 3):
        if len(est_xy[k]) >= 2:
            est_xy[k][1] = est_xy[k][0]
        if len(gt_xy[k]) >= 2:
            gt_xy[k][1] = gt_xy[k][0]
    assert_equal_trackeval(gt_ids, gt_xy, est_ids, est_xy)


def test_blocks_cover_every_scan(monkeypatch):
    """Scores do not depend on how many scans the padded similarity blocks hold."""
    import soabench.tracks.sequence as sequence

    args = random_sequence(7)
    whole = track_scores(*args, D_GATE)
    monkeypatch.setattr(sequence, "BLOCK_CELLS", 5)
    small = track_scores(*args, D_GATE)
    for key, value in whole.scalars().items():
        assert small.scalars()[key] == pytest.approx(value, abs=1e-12), key


# ---------------------------------------------------------------------------------------------------------------------
# T33: OSPA(2)


def walk(K: int, offset: float = 0.0) -> list[np.ndarray]:
    return [np.array([[k * 1.0 + offset, 2.0]]) for k in range(K)]


def test_t33_identical_tracks_give_zero():
    gt_ids, gt_xy, _, _ = random_sequence(4)
    r = ospa2(gt_ids, gt_xy, gt_ids, gt_xy)
    assert r.ospa2 == r.loc == r.card == 0.0


def test_t33_no_tracks_give_c():
    r = ospa2([np.array([1])] * 20, walk(20), [np.zeros(0, int)] * 20, [np.zeros((0, 2))] * 20, c=10.0)
    assert r.ospa2 == 10.0 and r.card == 10.0 and r.loc == 0.0
    np.testing.assert_array_equal(r.series[:, 0], 10.0)


def test_t33_constant_offset_gives_the_offset():
    r = ospa2([np.array([1])] * 20, walk(20), [np.array([5])] * 20, walk(20, 3.0), c=10.0, p=1.0, window=10)
    assert r.ospa2 == pytest.approx(3.0, abs=1e-12) and r.loc == pytest.approx(3.0, abs=1e-12) and r.card == 0.0


def ospa2_by_definition(gt_ids, gt_xy, est_ids, est_xy, c, p, w) -> np.ndarray:
    """OSPA(2) per scan straight from its definition: every track's positions in the window, the base distance of
    every pair, the OSPA minimum over every injection of the smaller set of tracks into the larger."""
    K = len(gt_ids)
    out = np.zeros(K)
    for k in range(K):
        window = range(max(0, k - w + 1), k + 1)
        X = {
            i: {t: gt_xy[t][list(gt_ids[t]).index(i)] for t in window if i in gt_ids[t]}
            for t in window
            for i in gt_ids[t]
        }
        Y = {
            j: {t: est_xy[t][list(est_ids[t]).index(j)] for t in window if j in est_ids[t]}
            for t in window
            for j in est_ids[t]
        }
        A, B = (list(X.values()), list(Y.values())) if len(X) <= len(Y) else (list(Y.values()), list(X.values()))
        if not B:
            continue

        def base(x, y):
            scans = set(x) | set(y)
            return sum(min(c, float(np.hypot(*(x[t] - y[t])))) if t in x and t in y else c for t in scans) / len(scans)

        best = min(
            sum(min(c, base(a, B[j])) ** p for a, j in zip(A, perm, strict=False))
            for perm in itertools.permutations(range(len(B)), len(A))
        )
        out[k] = ((best + c**p * (len(B) - len(A))) / len(B)) ** (1 / p)
    return out


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize(("p", "w"), [(1.0, 10), (2.0, 3)])
def test_t33_equals_the_definition(seed, p, w):
    gt_ids, gt_xy, est_ids, est_xy = random_sequence(seed, K=15)
    est_ids = [np.asarray(i) % 5 for i in est_ids]  # at most 5 estimate tracks: the permutations stay few
    keep = [np.unique(i, return_index=True)[1] for i in est_ids]
    est_ids = [i[j] for i, j in zip(est_ids, keep, strict=True)]
    est_xy = [x[j] for x, j in zip(est_xy, keep, strict=True)]
    r = ospa2(gt_ids, gt_xy, est_ids, est_xy, c=10.0, p=p, window=w)
    expected = ospa2_by_definition(gt_ids, gt_xy, est_ids, est_xy, 10.0, p, w)
    np.testing.assert_allclose(r.series[:, 0], expected, rtol=0, atol=1e-12)
    assert r.ospa2 == pytest.approx(expected.mean(), abs=1e-12)
    np.testing.assert_allclose(r.series[:, 1] ** p + r.series[:, 2] ** p, expected**p, rtol=0, atol=1e-9)


def test_t33_a_label_switch_costs_inside_the_window():
    """One truth, tracked exactly, whose label changes at scan 10: the windows that hold both labels pay for the
    two half-tracks (each absent on part of the window), and OSPA(2) returns to 0 once the old label has left."""
    K, w = 30, 10
    est_ids = [np.array([1 if k < 10 else 2]) for k in range(K)]
    r = ospa2([np.array([0])] * K, walk(K), est_ids, walk(K), c=10.0, window=w)
    assert (r.series[:10, 0] == 0).all() and (r.series[10 + w - 1 :, 0] == 0).all()
    assert (r.series[10 : 10 + w - 1, 0] > 0).all() and r.card > 0


# ---------------------------------------------------------------------------------------------------------------------
# T34: re-emergence after occlusion


def occluded_walker(fresh_label: bool, K: int = 31) -> dict:
    """One target visible 0-9, occluded in the FOV 10-14, visible 15-30, detected whenever visible; a tracker that
    follows it throughout (coasting through the gap), with one label, or a fresh label from scan 15 on."""
    in_view = np.ones((K, 1), dtype=bool)
    visible = in_view.copy()
    visible[10:15] = False
    truth = np.array([[[k * 1.0, 0.0]] for k in range(K)])
    est_xy = [truth[k] + 0.5 for k in range(K)]
    est_labels = [np.array([2 if fresh_label and k >= 15 else 1]) for k in range(K)]
    assoc, labels = associated_labels(est_xy, est_labels, truth, in_view, D_GATE)
    episodes = delay_episodes(visible, visible, assoc, dt=1.0)
    return {"episodes": episodes, "gaps": occlusion_gaps(in_view, visible), "assoc": assoc, "labels": labels}


def test_t34_coasted_with_one_label_keeps_identity():
    case = occluded_walker(fresh_label=False)
    r = reemergence(case["episodes"], case["gaps"], case["assoc"], case["labels"])
    assert [(g.k_a, g.k_b) for g in case["gaps"]] == [(10, 14)]
    assert r.entry["n_episodes"] == 1 and r.reemergence["n_episodes"] == 1
    assert r.entry["delay_mean"] == 0.0 and r.reemergence["delay_mean"] == 0.0
    assert (r.n_gaps, r.n_coasted, r.coasted) == (1, 1, 1.0)
    assert (r.n_id, r.id_kept) == (1, 1.0)


def test_t34_fresh_label_after_the_gap_loses_identity():
    case = occluded_walker(fresh_label=True)
    r = reemergence(case["episodes"], case["gaps"], case["assoc"], case["labels"])
    assert r.coasted == 1.0 and (r.n_id, r.id_kept) == (1, 0.0)


def test_t34_unlabelled_tracker_has_no_identity_value():
    case = occluded_walker(fresh_label=False)
    r = reemergence(case["episodes"], case["gaps"], case["assoc"], None)
    assert r.n_id is None and r.id_kept is None
    assert r.summary()["id_kept"] is None and r.summary()["coasted"] == 1.0


def test_t34_lost_during_the_gap_is_not_coasted_and_reacquisition_is_delayed():
    """No estimate during the gap and for two scans after it: not coasted, a 2-scan re-emergence delay, and the
    identity question is asked at the re-acquisition scan (17), where the label is the old one."""
    K = 31
    in_view = np.ones((K, 1), dtype=bool)
    visible = in_view.copy()
    visible[10:15] = False
    truth = np.array([[[k * 1.0, 0.0]] for k in range(K)])
    shown = [k < 10 or k >= 17 for k in range(K)]
    est_xy = [truth[k] if shown[k] else np.zeros((0, 2)) for k in range(K)]
    est_labels = [np.array([4]) if shown[k] else np.zeros(0, int) for k in range(K)]
    assoc, labels = associated_labels(est_xy, est_labels, truth, in_view, D_GATE)
    r = reemergence(delay_episodes(visible, visible, assoc, dt=0.5), occlusion_gaps(in_view, visible), assoc, labels)
    assert r.coasted == 0.0 and r.reemergence["delay_mean"] == 1.0 and r.entry["delay_mean"] == 0.0
    assert (r.n_id, r.id_kept) == (1, 1.0)


def test_gaps_need_visibility_on_both_sides():
    """Occluded at the start, occluded until the end, or out of the FOV in between: no occlusion gap."""
    K = 12
    visible = np.zeros((K, 3), dtype=bool)
    in_view = np.ones((K, 3), dtype=bool)
    visible[4:, 0] = True  # occluded 0-3, then visible: entry, not re-emergence
    visible[:6, 1] = True  # visible, then occluded to the end
    visible[:3, 2] = visible[8:, 2] = True
    in_view[5, 2] = False  # left the FOV inside the invisible run 3-7
    assert occlusion_gaps(in_view, visible) == []
    in_view[5, 2] = True
    assert [(g.target, g.k_a, g.k_b) for g in occlusion_gaps(in_view, visible)] == [(2, 3, 7)]


# ---------------------------------------------------------------------------------------------------------------------
# one filter run: the columns a trial adds


def occlusion_scans(K: int = 31) -> Scans:
    """Target 0 walks at y = 5 and is occluded at scans 10-14; target 1 stands at (20, -10), always visible."""
    truth = np.stack([np.array([[10 + 0.5 * k, 5.0], [20.0, -10.0]]) for k in range(K)])
    visible = np.ones((K, 2), dtype=bool)
    visible[10:15, 0] = False
    empty = [Scan(k, float(k), np.zeros(3), np.zeros((0, 2)), None, [], Polygon()) for k in range(K)]  # type: ignore[arg-type]
    ones = np.ones((K, 2), dtype=bool)
    return Scans(
        empty, 1.0, [np.zeros(0, int)] * K, truth, ones, ones.copy(), visible, visible.copy(), np.array(["a", "b"])
    )


def test_evaluate_tracks_labelled_and_unlabelled():
    scans = occlusion_scans()
    K = len(scans.scans)
    far = np.array([[500.0, 0.0, 0.0, 0.0]])  # outside the FOV: not in Est_k, and neither is its label
    X = [np.vstack([np.column_stack([scans.truth_xy[k] + 0.3, np.zeros((2, 2))]), far]) for k in range(K)]
    labels = [np.array([7 if k < 15 else 9, 8, 99]) for k in range(K)]
    X[3], labels[3] = np.zeros((0, 4)), np.zeros(0, dtype=np.int64)  # a scan without estimates
    cfg, sensor_cfg = MetricsConfig(), Sensor()
    assoc = np.ones((K, 2), dtype=bool)
    episodes = delay_episodes(scans.visible, scans.detected, assoc, scans.dt)
    out = evaluate_tracks(scans, X, labels, episodes, cfg, sensor_cfg)
    assert list(out) == list(TRACK_KEYS)
    expected = track_scores([np.array([0, 1])] * K, list(scans.truth_xy), [lab[:2] for lab in labels],
                            [x[:2, :2] for x in X], cfg.d_gate)  # fmt: skip
    assert expected.clr_fn == 2  # the empty scan
    assert out["hota"] == expected.hota and out["idsw"] == expected.idsw == 1 and out["idf1"] == expected.idf1
    assert out["n_entry"] == 2 and out["n_reemergence"] == 1 and out["delay_reemergence_mean"] == 0.0
    assert (out["coasted"], out["n_gaps"], out["id_kept"], out["n_id"]) == (1.0, 1, 0.0, 1)
    assert out["ospa2"] > 0 and out["ospa2"] == pytest.approx(out["ospa2_loc"] + out["ospa2_card"])
    plain = evaluate_tracks(scans, X, None, episodes, cfg, sensor_cfg)
    assert [out[key] for key in ALPHA_KEYS] == expected.hota_alpha.tolist()
    assert (
        all(plain[key] is None for key in LABEL_KEYS + ALPHA_KEYS)
        and plain["id_kept"] is None
        and plain["n_id"] is None
    )
    assert {k: plain[k] for k in REEMERGENCE_KEYS if k not in ("id_kept", "n_id")} == {
        k: out[k] for k in REEMERGENCE_KEYS if k not in ("id_kept", "n_id")
    }
