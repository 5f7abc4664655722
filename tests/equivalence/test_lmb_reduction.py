"""The LMB's own merge loops against the GM-PHD's merge kernels (docs/method.md §2.9, "LMB filter"): the birth
grouping (``soabench.lmb.cycle._merge_groups_at``) gives the groups of ``kernels.merge_groups`` (window or grid), and
the per-track reduction (``soabench.lmb.tracks.reduce_components``) gives, bit for bit, what the window, the moments
and a stable sort of the group weights give, for tracks of one to hundreds of components, tied weights, more groups
than ``L_max``, components pruned by T and tracks with a non-finite component (which take the kernels' path)."""

from __future__ import annotations

import numpy as np
import pytest
from test_merge_index import mixture

from soabench.gmphd import kernels
from soabench.lmb.cycle import _merge_groups_at
from soabench.lmb.tracks import reduce_components


@pytest.mark.parametrize("J", [1, 40, 97, 300])
@pytest.mark.parametrize("layout", ["clustered", "spread"])
def test_birth_grouping_gives_the_groups_of_merge_groups(J, layout):
    rng = np.random.default_rng(J + 5 * (layout == "spread"))
    m, P, w = mixture(rng, 2 * J, layout, J // 10)
    idx = np.sort(rng.choice(2 * J, J, replace=False))  # the components of positive weight, as birth_groups keeps
    order = np.argsort(-w[idx], kind="stable")
    for U in (0.5, 4.0, 30.0):
        label, centres = _merge_groups_at(m, P, idx, order, U)
        ref_label, ref_centres = kernels.merge_groups(m[idx], P[idx], order, U)  # grid above 96 components
        np.testing.assert_array_equal(label, ref_label)
        np.testing.assert_array_equal(centres, ref_centres)


def _reduce_with_kernels(start, w, m, P, T, U, L_max):
    """The per-track reduction written with the merge kernels on gathered copies (prune, window groups, moments,
    the L_max heaviest groups by a stable sort, renormalised)."""
    out_start, out = [0], []
    for i in range(len(start) - 1):
        a, b = start[i], start[i + 1]
        keep = np.flatnonzero(w[a:b] > T) + a
        if not len(keep):
            keep = np.array([a + int(np.argmax(w[a:b]))])
        wk, mk, Pk = w[keep].copy(), np.ascontiguousarray(m[keep]), np.ascontiguousarray(P[keep])
        label, centres = kernels.merge_groups_window(mk, Pk, np.argsort(-wk, kind="mergesort"), U)
        dummy = np.zeros(len(keep), dtype=np.int32)
        W, mt, Pt, _, _, _ = kernels.merge_moments(label, centres, wk, mk, Pk, dummy, dummy)
        sel = np.sort(np.argsort(-W, kind="mergesort")[:L_max])
        total = 0.0
        for g in sel:
            total += W[g]
        out += [(W[g] / total, mt[g], Pt[g]) for g in sel]
        out_start.append(len(out))
    return (np.array(out_start), np.array([o[0] for o in out]), np.array([o[1] for o in out]).reshape(-1, 4),
            np.array([o[2] for o in out]).reshape(-1, 4, 4))  # fmt: skip


@pytest.mark.parametrize("seed", range(4))
def test_track_reduction_equals_the_merge_kernels_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    sizes = [1, 2, 3, 7, 15, 40, 120, 1, 5]
    m, P, w = mixture(rng, sum(sizes), "clustered", 4)
    w[rng.choice(len(w), len(w) // 4, replace=False)] *= 1e-6  # pruned by T
    w[sizes[0] + 1] = w[sizes[0]]  # an exact tie inside the second track
    start = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    for T, U, L_max in ((1e-5, 4.0, 10), (1e-5, 0.5, 3), (0.0, 30.0, 1), (0.5, 4.0, 10)):
        got = reduce_components(start, w, m, P, T, U, L_max)
        ref = _reduce_with_kernels(start, w, m, P, T, U, L_max)
        for g, r in zip(got, ref, strict=True):
            assert g.shape == r.shape and g.tobytes() == r.astype(g.dtype).tobytes()
    bad = P.copy()
    bad[start[5] + 3, 0, 0] = np.nan  # a non-finite component: that track takes the kernels' path
    got = reduce_components(start, w, m, bad, 1e-5, 4.0, 10)
    ref = _reduce_with_kernels(start, w, m, bad, 1e-5, 4.0, 10)
    for g, r in zip(got, ref, strict=True):
        np.testing.assert_array_equal(g, r.astype(g.dtype))
