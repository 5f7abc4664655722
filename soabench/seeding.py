"""Random streams of one trial (docs/method.md §2.12 item 11, §5.8: common random numbers).

Every stage draws from its own ``numpy.random.Generator`` spawned from the trial's ``SeedSequence``, so every
(birth model x probability mode x clutter) filter of trial n sees the same truth and the same measurements, and a
stochastic birth placement never shifts the measurement stream.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TrialSeeds:
    """Seeds and generators of one trial, derived from ``(base_seed, trial)`` only."""

    base_seed: int
    trial: int
    sumo_seed: int
    scenario: np.random.SeedSequence
    sensor: np.random.SeedSequence
    placement: np.random.SeedSequence

    def scenario_rng(self) -> np.random.Generator:
        """Routes, depart times, pedestrian walks and door events."""
        return np.random.default_rng(self.scenario)

    def sensor_rngs(self) -> tuple[np.random.Generator, np.random.Generator]:
        """``(detection_rng, clutter_rng)``: detections and noise, and clutter, on separate streams.

        Neither depends on the clutter rate, so runs at different lambda share detections and noise exactly.
        """
        return (np.random.default_rng(_child(self.sensor, 0)), np.random.default_rng(_child(self.sensor, 1)))

    def placement_rng(self) -> np.random.Generator:
        """Stochastic birth placement (Poisson-disk, uniform semantic sampling)."""
        return np.random.default_rng(self.placement)

    def association_rng(self) -> np.random.Generator:
        """Seeds of the LMB filter's Gibbs sampler (docs/method.md "LMB filter"): a fifth child of the trial's
        root sequence, so the four streams above are unchanged and every LMB run of trial n draws the same seeds."""
        return np.random.default_rng(_child(np.random.SeedSequence([self.base_seed, self.trial]), 4))


def trial_seeds(base_seed: int, trial: int) -> TrialSeeds:
    """The seeds of trial ``trial`` of a run started with ``base_seed`` (independent of worker and order)."""
    root = np.random.SeedSequence([int(base_seed), int(trial)])
    scenario, sensor, placement, sumo = root.spawn(4)
    sumo_seed = int(sumo.generate_state(1, dtype=np.uint32)[0] % 2_000_000_000)
    return TrialSeeds(int(base_seed), int(trial), sumo_seed, scenario, sensor, placement)


def _child(seq: np.random.SeedSequence, i: int) -> np.random.SeedSequence:
    """The i-th child of ``seq``, computed without mutating it (``spawn`` counts calls)."""
    return np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, i))
