"""The PMB variant (docs/method.md §10.5): after each update the PMBM is collapsed, track by track, to one
multi-Bernoulli (track-oriented PMB, Williams 2015).

With P(h) the marginal probability of single-target hypothesis h (the summed weights of the global hypotheses that
pick it), track i becomes one Bernoulli with r_i = sum_h P(h) r_h and density sum_h P(h) r_h p_h / r_i; the
intensity is unchanged. The first moment (the PHD) is kept exactly. A track whose r_i is 0 is dropped.
"""

from __future__ import annotations

import numpy as np

from soabench.lmb.tracks import Tracks
from soabench.pmbm.density import PMBMDensity


def collapse(d: PMBMDensity) -> PMBMDensity:
    """The track-oriented PMB of ``d`` (module docstring): one hypothesis per track, one global hypothesis."""
    hyps = d.hyps
    n = d.n_tracks
    p = d.hypothesis_probabilities()
    pr = p * hyps.r  # (H,) P(h) r_h
    r = np.bincount(d.track, weights=pr, minlength=n).astype(float, copy=False)  # float also with no track
    alive = r > 0.0
    owner = hyps.owner()
    track_c = d.track[owner]
    w = pr[owner] * hyps.w
    keep_c = (w > 0.0) & alive[track_c]  # components are grouped by track: hypotheses of a track are contiguous
    w = w[keep_c] / r[track_c[keep_c]]
    tracks = np.flatnonzero(alive)
    counts = np.bincount(track_c[keep_c], minlength=n)[tracks]
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    # label, origin and age of each kept track: those of its most probable hypothesis (all share label and origin)
    best = np.full(n, -1, dtype=np.int64)
    order = np.lexsort((-pr, d.track))  # by track, then by decreasing P(h) r_h
    first = np.ones(len(order), dtype=bool)
    first[1:] = d.track[order[1:]] != d.track[order[:-1]]
    best[d.track[order[first]]] = order[first]
    b = best[tracks]
    out = Tracks(r[tracks], hyps.label[b], hyps.origin[b], hyps.age[b], start, w, hyps.m[keep_c], hyps.P[keep_c])
    N = len(tracks)
    return PMBMDensity(d.ppp, out, np.arange(N, dtype=np.int64), np.arange(N, dtype=np.int64)[None, :], np.zeros(1))
