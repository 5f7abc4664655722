"""The PMBM density as arrays (docs/method.md §10.1).

* ``ppp``: the undetected targets' Poisson intensity, a Gaussian mixture (:class:`soabench.gmphd.mixture.Mixture`,
  the GM-PHD's data structure).
* ``hyps``: every single-target hypothesis of every track, as :class:`soabench.lmb.tracks.Tracks` rows (existence
  ``r``, Gaussian-mixture density, the track's ``label``, ``origin``, ``age``); ``track[h]`` is the track of
  hypothesis h (tracks numbered 0..n-1, hypotheses of a track contiguous).
* ``table`` (A, n): global hypothesis a picks hypothesis ``table[a, i]`` (an index into ``hyps``) of track i;
  ``log_w`` (A,) are the normalised log weights of the global hypotheses.

A single-target hypothesis carries no weight of its own: the global weights hold the products of the likelihood
factors (§10.3), kept as logarithms so that they never underflow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from soabench.gmphd.mixture import Mixture
from soabench.lmb.tracks import Tracks
from soabench.pmbm.kernels import global_weights


@dataclass
class PMBMDensity:
    """A PMBM density (module docstring)."""

    ppp: Mixture
    hyps: Tracks
    track: np.ndarray  #: (H,) int64 track of each hypothesis
    table: np.ndarray  #: (A, n) int64 hypothesis of each track in each global hypothesis
    log_w: np.ndarray  #: (A,) log weights of the global hypotheses (logsumexp = 0)

    @classmethod
    def empty(cls) -> PMBMDensity:
        """No target: empty intensity, no track, one global hypothesis of weight 1."""
        return cls(
            Mixture.empty(), Tracks.empty(), np.zeros(0, dtype=np.int64), np.zeros((1, 0), dtype=np.int64), np.zeros(1)
        )

    @property
    def n_tracks(self) -> int:
        return self.table.shape[1]

    @property
    def track_labels(self) -> np.ndarray:
        """(n,) the label of each track."""
        first = np.searchsorted(self.track, np.arange(self.n_tracks))
        return self.hyps.label[first]

    def hypothesis_probabilities(self) -> np.ndarray:
        """(H,) the marginal probability of each single-target hypothesis: the sum of the weights of the global
        hypotheses that pick it."""
        if not self.table.size:
            return np.zeros(len(self.hyps))
        n = self.table.shape[1]
        # summed in the table's row order (as np.add.at(p, table, w[:, None]) would)
        ew = global_weights(self.log_w)
        return np.bincount(self.table.ravel(), weights=np.repeat(ew, n), minlength=len(self.hyps))

    def phd_mass(self, p_hyp: np.ndarray | None = None) -> float:
        """The expected number of targets: the intensity's mass plus sum_a w_a sum_i r_i (``p_hyp``: the
        :meth:`hypothesis_probabilities`, if known)."""
        if p_hyp is None:
            p_hyp = self.hypothesis_probabilities()
        return float(self.ppp.w.sum() + p_hyp @ self.hyps.r)

    def phd(self) -> Mixture:
        """The first moment: the intensity plus sum_a w_a sum_i r_i p_i (weights r_h P(h) omega_c per component)."""
        ph = self.hypothesis_probabilities() * self.hyps.r
        owner = self.hyps.owner()
        tracks = Mixture.from_arrays(ph[owner] * self.hyps.w, self.hyps.m, self.hyps.P)
        return Mixture.concatenate([self.ppp.select(slice(None)), tracks]) if len(self.ppp) else tracks

    def cardinality(self, n_max: int) -> np.ndarray:
        """(n_max + 1,) the cardinality distribution: the Poisson of the intensity's mass convolved with each
        global hypothesis's multi-Bernoulli, mixed over the global hypotheses."""
        from scipy.stats import poisson

        out = np.zeros(n_max + 1)
        r = self.hyps.r
        ew = global_weights(self.log_w)
        for a in range(self.table.shape[0]):
            pmf = np.zeros(n_max + 1)
            pmf[0] = 1.0
            for h in self.table[a]:
                pmf[1:] = pmf[1:] * (1.0 - r[h]) + pmf[:-1] * r[h]
                pmf[0] *= 1.0 - r[h]
            out += ew[a] * pmf
        pois = poisson.pmf(np.arange(n_max + 1), self.ppp.mass)
        return np.convolve(out, pois)[: n_max + 1]
