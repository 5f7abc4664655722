"""Track metrics at crowd sizes (docs/method.md §9.3): IDF1's assignment split into the components of the overlap
graph, and OSPA(2)'s windows with far pairs kept apart, give the values of the whole-problem forms, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment
from test_track_metrics import D_GATE, assert_equal_trackeval, random_sequence

from soabench.tracks.ospa2 import ospa2
from soabench.tracks.scores import _identity_matched, track_scores
from soabench.tracks.sequence import TrackSequence


def square_identity(potential: np.ndarray, gt_count: np.ndarray, tr_count: np.ndarray) -> tuple[int, int]:
    """(IDFN, IDFP) of TrackEval's square assignment over every truth and track, each with a dummy partner."""
    nG, nT = potential.shape
    n = nG + nT
    fp_mat, fn_mat = np.zeros((n, n)), np.zeros((n, n))
    fp_mat[nG:, :nT] = 1e10
    fn_mat[:nG, nT:] = 1e10
    fn_mat[:nG, :nT] = gt_count[:, None] - potential
    fn_mat[np.arange(nG), nT + np.arange(nG)] = gt_count
    fp_mat[:nG, :nT] = tr_count[None, :] - potential
    fp_mat[nG + np.arange(nT), np.arange(nT)] = tr_count
    rows, cols = linear_sum_assignment(fn_mat + fp_mat)
    return int(fn_mat[rows, cols].sum()), int(fp_mat[rows, cols].sum())


@pytest.mark.parametrize("seed", range(30))
def test_identity_by_components_equals_the_square_assignment(seed):
    """Sparse overlap counts with many equal values (ties), stars, isolated truths and tracks: the same IDFN and
    IDFP as the square problem."""
    rng = np.random.default_rng(seed)
    nG, nT = int(rng.integers(1, 25)), int(rng.integers(1, 40))
    potential = np.where(rng.random((nG, nT)) < rng.uniform(0.02, 0.4), rng.integers(1, 4, (nG, nT)), 0).astype(float)
    gt_count = potential.sum(axis=1) + rng.integers(0, 5, nG)
    tr_count = potential.sum(axis=0) + rng.integers(0, 5, nT)
    matched = _identity_matched(potential)
    idfn, idfp = square_identity(potential, gt_count, tr_count)
    assert (int(gt_count.sum() - matched), int(tr_count.sum() - matched)) == (idfn, idfp)


def crowd_sequence(seed: int, groups: int = 4, K: int = 30) -> tuple[list, list, list, list]:
    """``groups`` copies of :func:`random_sequence` 200 m apart, with their own ids: several components."""
    parts = [random_sequence(seed * 10 + g, K) for g in range(groups)]
    out: tuple[list, list, list, list] = ([], [], [], [])
    for k in range(K):
        out[0].append(np.concatenate([p[0][k] + 1000 * g for g, p in enumerate(parts)]))
        out[1].append(np.concatenate([p[1][k] + [200.0 * g, 0.0] for g, p in enumerate(parts)]))
        out[2].append(np.concatenate([p[2][k] + 1000 * g for g, p in enumerate(parts)]))
        out[3].append(np.concatenate([p[3][k] + [200.0 * g, 0.0] for g, p in enumerate(parts)]))
    return out


@pytest.mark.parametrize("seed", range(4))
def test_crowd_sequences_equal_trackeval(seed):
    assert_equal_trackeval(*crowd_sequence(seed))
    assert track_scores(*crowd_sequence(seed), D_GATE).idf1 < 1  # something to get wrong


def ospa2_every_pair(seq: TrackSequence, c: float, p: float, window: int) -> np.ndarray:
    """(K,) OSPA(2) with every pair's base distance summed scan by scan, in the operations of the compiled loop
    (the window's tracks in id order, the minimum-cost assignment and numpy's pairwise sum of the same kernels)."""
    from soabench.metrics_kernels import assignment, np_sum

    K = len(seq)

    def dense(rows, n):
        out = np.full((K, n, 2), np.nan)
        out[np.repeat(np.arange(K), np.diff(rows.off)), rows.ids] = rows.xy
        return out

    G, E = dense(seq.gt, len(seq.gt_labels)), dense(seq.est, len(seq.est_labels))
    out = np.zeros(K)
    for k in range(K):
        lo = max(0, k - window + 1)
        gsel = np.flatnonzero(~np.isnan(G[lo : k + 1, :, 0]).all(axis=0))
        esel = np.flatnonzero(~np.isnan(E[lo : k + 1, :, 0]).all(axis=0))
        m, n = len(gsel), len(esel)
        if max(m, n) == 0:
            continue
        total, count = np.zeros((m, n)), np.zeros((m, n))
        for t in range(lo, k + 1):
            gp, ep = G[t, gsel], E[t, esel]
            dx = gp[:, None, 0] - ep[None, :, 0]
            dy = gp[:, None, 1] - ep[None, :, 1]
            both = ~np.isnan(gp[:, None, 0]) & ~np.isnan(ep[None, :, 0])
            either = ~np.isnan(gp[:, None, 0]) | ~np.isnan(ep[None, :, 0])
            term = np.where(both, np.minimum(c, np.sqrt(dx * dx + dy * dy)), c)
            total = np.where(either, total + term, total)
            count += either
        D = np.minimum(total / np.maximum(count, 1), c) ** p
        Cm = D if m <= n else D.T.copy()
        loc_p = 0.0
        if min(m, n):
            rows, cols = assignment(np.ascontiguousarray(Cm))
            loc_p = np_sum(Cm[rows, cols].copy(), min(m, n)) / max(m, n)
        out[k] = (loc_p + c**p * (max(m, n) - min(m, n)) / max(m, n)) ** (1.0 / p)
    return out


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("window", [10, 70])
def test_ospa2_far_pairs_apart_equals_every_pair(seed, window):
    """Groups 200 m apart (most pairs never within c), label changes, gaps; windows of one and two mask words."""
    seq = TrackSequence.of(*crowd_sequence(seed, K=90))
    got = ospa2(*crowd_sequence(seed, K=90), c=10.0, p=1.0, window=window).series[:, 0]
    np.testing.assert_array_equal(got, ospa2_every_pair(seq, 10.0, 1.0, window))


@pytest.mark.parametrize("seed", range(20))
def test_sparse_assignment_keeps_the_nonzero_pairs_of_the_whole_assignment(seed):
    """Clusters of non-zero (negative, continuous: one optimum) costs among zeros, rows and columns without any:
    the non-zero pairs of the whole matrix's minimum-cost assignment, in row order."""
    from soabench.tracks.kernels import sparse_assignment

    rng = np.random.default_rng(seed)
    a, b = int(rng.integers(1, 30)), int(rng.integers(1, 30))
    C = np.where(rng.random((a, b)) < rng.uniform(0.02, 0.3), -rng.random((a, b)), 0.0)
    rows, cols = linear_sum_assignment(C)
    keep = C[rows, cols] != 0
    got = sparse_assignment(C)
    np.testing.assert_array_equal(got[0], rows[keep])
    np.testing.assert_array_equal(got[1], cols[keep])


@pytest.mark.parametrize("seed", range(20))
def test_equal_rows_as_compared_pair_by_pair(seed):
    """Rows with few values (zeros, repeats, -0.0): the same answer as comparing every pair of rows."""
    from soabench.tracks.kernels import _equal_rows

    rng = np.random.default_rng(seed)
    a, b = int(rng.integers(1, 12)), int(rng.integers(1, 6))
    C = rng.choice([0.0, -0.0, -0.5, -1.0], size=(a, b), p=[0.6, 0.1, 0.15, 0.15])
    expected = any((C[i] == C[j]).all() and (C[i] != 0).any() for i in range(a) for j in range(i + 1, a))
    assert _equal_rows(C) == expected


@pytest.mark.parametrize("seed", range(12))
def test_sparse_sum_is_the_dense_arrays_sum_bit_for_bit(seed):
    """Lengths around numpy's block sizes (8, 128 and their splits), densities from empty to full, magnitudes over
    six decades: the sum of the listed entries in numpy's pairwise order is ``ndarray.sum`` of the dense array, for
    each of several arrays listed at the same positions (a listed zero included)."""
    from soabench.tracks.kernels import sparse_np_sum

    rng = np.random.default_rng(seed)
    for n in (0, 1, 7, 8, 9, 127, 128, 129, 136, 1000, 4099, 250_000):
        a = np.where(
            rng.random(n) < rng.choice([0.0, 0.001, 0.05, 0.5, 1.0]), rng.random(n) * 10 ** rng.uniform(-3, 3, n), 0.0
        )
        b = np.where(rng.random(n) < 0.5, 0.0, a[::-1])
        pos = np.flatnonzero(a + b)
        sums = sparse_np_sum(pos, np.column_stack([a[pos], b[pos], 0.0 * a[pos]]), n)
        assert sums.tolist() == [a.sum(), b.sum(), 0.0]


def padded_global_counts(seq: TrackSequence, d_gate: float, nG: int, nT: int) -> tuple[np.ndarray, np.ndarray]:
    """HOTA's summed overlaps and Identity's potential counts (nG * nT,) over padded runs of scans with numpy, as
    TrackEval's arrays give them."""
    eps = np.finfo(float).eps
    potential, id_potential = np.zeros(nG * nT), np.zeros(nG * nT)
    for _, S, g, e in seq.blocks(d_gate):
        denom = S.sum(axis=1)[:, None, :] + S.sum(axis=2)[:, :, None] - S
        iou = np.zeros_like(S)
        np.divide(S, denom, out=iou, where=denom > eps)
        valid = (g[:, :, None] >= 0) & (e[:, None, :] >= 0)
        cell = (g[:, :, None] * nT + e[:, None, :])[valid]
        potential += np.bincount(cell, weights=iou[valid], minlength=nG * nT)
        id_potential += np.bincount(cell, weights=S[valid] >= 0.5, minlength=nG * nT)
    return potential, id_potential


@pytest.mark.parametrize("seed", range(6))
def test_global_counts_are_the_padded_arrays_sums_bit_for_bit(seed, monkeypatch):
    """Crowd groups and random walks, runs of scans shorter than the sequence (a small block size): the compiled
    loop over the pairs of non-zero similarity gives the padded arrays' sums to the bit."""
    import soabench.tracks.sequence as sequence
    from soabench.tracks.kernels import global_counts

    monkeypatch.setattr(sequence, "BLOCK_CELLS", 2000)
    for seq in (TrackSequence.of(*crowd_sequence(seed, K=40)), TrackSequence.of(*random_sequence(seed, K=40))):
        nG, nT = len(seq.gt_labels), len(seq.est_labels)
        want = padded_global_counts(seq, D_GATE, nG, nT)
        G, E = int(np.diff(seq.gt.off).max()), int(np.diff(seq.est.off).max())
        got = np.zeros(nG * nT), np.zeros(nG * nT)
        g, e = seq.gt, seq.est
        step = max(1, 2000 // (G * E))
        cells = global_counts(g.ids, g.off, g.xy, e.ids, e.off, e.xy, D_GATE, 0.5, step, nT, *got)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        for c, a in zip(cells, got, strict=True):  # each non-zero cell listed once
            np.testing.assert_array_equal(np.sort(c), np.flatnonzero(a))
        assert (want[0] > 0).any()


def near_pairs_case(seed: int) -> tuple[np.ndarray, int, int]:
    """(m, n) base distances in [0, c] with c = 10: a random share of near pairs (continuous costs, so one optimum),
    every other pair exactly c; from a few sparse pairs to a crowd's dense block, either side the larger."""
    rng = np.random.default_rng(seed)
    m, n = int(rng.integers(1, 60)), int(rng.integers(1, 60))
    if seed % 4 == 0:  # a crowd: most pairs near, far more estimate tracks than truths (or the other way round)
        m, n = (int(rng.integers(40, 80)), int(rng.integers(100, 200)))[:: 1 if seed % 8 == 0 else -1]
    near = rng.random((m, n)) < rng.uniform(0.02, 0.6)
    D = np.where(near, 10.0 * rng.random((m, n)) ** 0.3, 10.0)
    return D, m, n


@pytest.mark.parametrize("seed", range(40))
def test_near_pairs_assignment_equals_the_dense_one(seed):
    """Each row's cost in an assignment over the near pairs only (a row free to stay unmatched at c) is its cost in
    the dense matrix's minimum-cost assignment (scipy), so OSPA(2)'s sum over the rows is the same bit for bit."""
    from soabench.metrics_kernels import np_sum
    from soabench.tracks.kernels import _near_assignment

    D, m, n = near_pairs_case(seed)
    a, b = np.nonzero(D < 10.0)
    vals = np.empty(min(m, n))
    _near_assignment(a, b, D[a, b].copy(), len(a), m, n, 10.0, vals)
    Cm = D if m <= n else D.T.copy()
    rows, cols = linear_sum_assignment(Cm)
    np.testing.assert_array_equal(vals, Cm[rows, cols])
    assert np_sum(vals, len(vals)) == np_sum(Cm[rows, cols].copy(), len(vals))


@pytest.mark.parametrize("seed", range(2))
def test_ospa2_with_a_cutoff_whose_sums_are_not_exact_equals_every_pair(seed):
    """c = 0.7: 0.7 added three times and divided by 3 is below 0.7, so a far pair's cost depends on its count and
    the dense cost matrix is assigned."""
    seq = TrackSequence.of(*crowd_sequence(seed, K=40))
    got = ospa2(*crowd_sequence(seed, K=40), c=0.7, p=1.0, window=10).series[:, 0]
    np.testing.assert_array_equal(got, ospa2_every_pair(seq, 0.7, 1.0, 10))


def test_track_measures_read_the_gated_matching_of_the_metrics():
    """The §5.4 matching the re-emergence measures read (associated estimates and their labels) taken from the run's
    metrics (``TrialMetrics.partner``) gives the columns and gap cells of matching again: estimates extracted twice
    (scipy's choice of the compiled path's left-over scans), labels that switch, gaps with and without an estimate."""
    import dataclasses

    from soabench.config import MetricsConfig, Sensor
    from soabench.metrics import evaluate
    from soabench.tracks.evaluate import track_evaluation
    from soabench.types import Obstacles, Scan, Scans, StepResult

    rng = np.random.default_rng(5)
    K, P = 80, 8
    sensor, mcfg = dataclasses.replace(Sensor(), fov_deg=360.0), MetricsConfig()
    truth = np.cumsum(rng.normal(0.0, 0.5, (K, P, 2)), axis=0) + rng.uniform(-25, 25, (1, P, 2))
    visible = np.ones((K, P), dtype=bool)
    for p in range(P):  # two occlusion gaps per target
        for k0 in rng.choice(np.arange(3, K - 8), 2, replace=False):
            visible[k0 : k0 + int(rng.integers(1, 5)), p] = False
    X, labels, results = [], [], []
    for k in range(K):
        shown = visible[k] | (rng.random(P) < 0.5)  # coasted through part of the gaps
        est = truth[k, shown] + rng.normal(0.0, 0.8, (int(shown.sum()), 2))
        lab = np.flatnonzero(shown) + 100 * (k // 20)  # every target's label changes every 20 scans
        if len(est) > 2 and k % 2:
            est[1] = est[2] = 0.5 * (est[1] + est[2])  # one estimate, extracted twice, between two truths
        x = np.zeros((len(est), 4))
        x[:, :2] = est
        X.append(x)
        labels.append(lab.astype(np.int64))
        n, none = len(x), np.zeros(0)
        results.append(StepResult(k, x, np.ones(n), 1.0 * n, 1.0 * n, n, n, n, False, 0.0, 0.0, 0.0, 0.98, none, none))
    ones = np.ones((K, P), dtype=bool)
    scans = Scans([Scan(k, float(k), np.zeros(3), np.zeros((0, 2)), Obstacles.empty(), [], None) for k in range(K)],
                  1.0, [np.zeros(0, dtype=np.int64)] * K, truth, ones, ones.copy(), visible, visible.copy(),
                  np.array([str(p) for p in range(P)]))  # fmt: skip
    metrics = evaluate(scans, results, mcfg, sensor)
    for lab in (labels, None):
        again = track_evaluation(scans, X, lab, metrics.episodes, mcfg, sensor)
        read = track_evaluation(scans, X, lab, metrics.episodes, mcfg, sensor, metrics.partner)
        assert str(read) == str(again)  # every value and its type (NaN as NaN)
    assert again[0]["n_gaps"] > 5 and 0 < read[0]["coasted"] < 1 and read[0]["n_reemergence"] > 5
