"""The two extension points of the benchmark: :class:`BirthModel` and :class:`Tracker` (bottom layer).

A *birth model* says where our GM-PHD filter expects new targets (S-OA, PUBM, UBM, ATBM, GMBM, or yours); a
*tracker* is anything that turns scans into estimated states (our GM-PHD with a birth model and a probability mode,
Stone Soup's trackers, or yours). Both are plain classes; nothing needs to inherit from these protocols, they only
document the shape the harness calls. Register your class by entry point (groups ``soabench.birth_models`` and
``soabench.trackers``) or name it on the command line as ``module:Class`` (docs/user-guide/birth-model.md,
docs/user-guide/tracker.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:
    import numpy as np

    from soabench.config import BirthConfig, Config, FilterConfig, Sensor
    from soabench.scenario.scene import SceneMap
    from soabench.types import BirthContext, Births, Estimates, Scan, StepResult


@runtime_checkable
class BirthModel(Protocol):
    """``Model(cfg, sensor, scene, rng, **options)`` once per run, then ``model(ctx) -> Births`` once per scan.

    Args of the constructor:
        cfg: the ``[birth]`` settings (N_hat, sigma_v, delta_in, ...), shared by every birth model.
        sensor: the sensor model (dt, FOV, noise, clutter rate of this run).
        scene: the static scene (buildings, sidewalks, workspace box).
        rng: this run's placement generator (same stream for every model of a trial: common random numbers).
        options: a plugin's own ``[plugins.<name>]`` table of the TOML configuration, as keyword arguments.

    The call returns :class:`~soabench.types.Births`: J Gaussian components (w (J,) >= 0, m (J, 4), P (J, 4, 4),
    source (J,) int) appended to the predicted intensity, and/or measurement-driven
    :class:`~soabench.types.NewbornTerms` (docs/method.md §3.0, §3.2).
    """

    name: str

    def __init__(
        self, cfg: BirthConfig, sensor: Sensor, scene: SceneMap, rng: np.random.Generator, **options: Any
    ) -> None: ...

    def __call__(self, ctx: BirthContext) -> Births: ...


@dataclass(frozen=True)
class TrackerSetup:
    """What a tracker is built from, once per run (one trial, one clutter rate, one probability mode).

    Attributes:
        sensor: the sensor model of this run (dt, range-bearing noise sigma_r/sigma_b, FOV, clutter rate lambda_c);
            a tracker's measurement model should be this one.
        scene: the static scene (buildings, sidewalks, workspace box ``scene.bounds``).
        rng: this run's generator (seeded from the trial: same seed, same results).
        mode: the probability mode label of the run ("static", "dynamic", "dynamic+occ", "static+occ"); trackers without
            such modes may ignore it (their rows then repeat per mode).
        config: the whole resolved configuration (filter defaults, metrics settings), read-only.
    """

    sensor: Sensor
    scene: SceneMap
    rng: np.random.Generator
    mode: str
    config: Config


@runtime_checkable
class Tracker(Protocol):
    """``Tracker(setup, **options)`` once per run, then ``tracker.step(scan) -> Estimates`` once per scan, in order.

    ``setup`` is a :class:`TrackerSetup`; ``options`` is the tracker's ``[plugins.<name>]`` table. ``step`` sees
    only the scan (ego pose, measurements Z in range-bearing relative to the ego heading, occluders), never the
    truth, and returns :class:`~soabench.types.Estimates` (our GM-PHD tracker returns the richer
    :class:`~soabench.types.StepResult`). The harness times each step.
    """

    name: str

    def __init__(self, setup: TrackerSetup, **options: Any) -> None: ...

    def step(self, scan: Scan) -> Estimates | StepResult: ...


@dataclass(frozen=True)
class FamilySetup:
    """What a filter family builds one run's filter from (one trial, one clutter rate, one probability mode;
    docs/development.md "Adding a filter family").

    Attributes:
        config: the whole resolved configuration; the family reads ``[filter]`` and its own section.
        sensor: the sensor model of this run (its clutter rate set).
        mode: the run's probability mode label (``"static"``, ``"static+occ"``, ``"dynamic"``, ...), one of the
            family's modes.
        filter_cfg: ``[filter]`` for that mode (``occlusion_pd`` set by the ``+occ`` modes;
            :func:`soabench.config.filter_config_for_mode`).
        filter_mode: the probability model of that mode, ``"static"`` or ``"dynamic"``.
        rng: the trial's association stream (:meth:`soabench.seeding.TrialSeeds.association_rng`), for a family
            that draws (the LMB's Gibbs sampler); the same for every family and mode of a trial.
    """

    config: Config
    sensor: Sensor
    mode: str
    filter_cfg: FilterConfig
    filter_mode: str
    rng: np.random.Generator


@runtime_checkable
class Filter(Protocol):
    """One run's filter of a family: ``build(setup: FamilySetup) -> Filter`` once per run (the registry line's
    builder, :data:`soabench.config.FAMILIES`), then ``filt.step(scan, births) -> StepResult`` once per scan.

    ``births`` are the birth model's :class:`~soabench.types.Births` of the scan, exactly as every family gets them:
    the family decides how they enter (the GM-PHD appends the components, the LMB groups them into Bernoullis).
    ``step`` returns the scan's estimates with their track labels (``StepResult.labels``, one int64 per estimate)
    and its cost figures (:func:`soabench.trackers.step_result_from` makes one from :class:`Estimates`).
    """

    name: str

    def step(self, scan: Scan, births: Births) -> StepResult: ...
