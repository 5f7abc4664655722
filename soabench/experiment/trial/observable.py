"""When the first pedestrian becomes observable on a run's scene: the shortest useful ``--duration``.

A run that observed nobody (:func:`soabench.experiment.reports.report.unobserved_warning`) is usually too short: on the
shipped intersection the ego starts far from the crossing and no pedestrian is in its view for the first seconds.
:func:`duration_hint` finds out from the scene itself: it simulates the run's first trials (same seeds, so the same
pedestrians) for longer, applies the run's sensor (docs/method.md §2.3: field of view and line of sight), and
reports the first scan at which some pedestrian is visible, and from it the shortest duration worth running.
Nothing is written; the simulations are deterministic, so the hint is the same wherever the report is made.
"""

from __future__ import annotations

import functools
import json
import math

import numpy as np

from soabench import scenario as scenarios  # by attribute: a test may stand in for its simulate
from soabench.config import Config
from soabench.errors import SoabenchError
from soabench.experiment.trial import registry
from soabench.experiment.trial.registry import load_scene_cached
from soabench.scenario.derive import said_by_the_driver
from soabench.seeding import trial_seeds
from soabench.sensor import observe

#: trials probed (the run's first ones): their pedestrians are the run's.
PROBE_TRIALS = 3
#: a probe simulates this many times the run's duration, at least the scenario's own duration, at most MAX_PROBE_S.
PROBE_FACTOR = 4.0
MAX_PROBE_S = 600.0
#: the suggested duration leaves this long (s) after the latest first sighting, for detections and tracks to form.
TRACK_MARGIN_S = 5.0


def first_observable(meta: dict, trials: int = PROBE_TRIALS) -> tuple[list[float | None], float]:
    """(time in s of the first scan with a visible pedestrian, None if none, for each of the run's first ``trials``
    trials; the probed duration in s), from a run's ``run.json`` metadata."""

    config = Config.from_dict(meta["config"])
    exp = config.experiment
    with said_by_the_driver():  # the run already said what was derived
        scene, scenario = load_scene_cached(meta["net"], tuple(meta.get("polys") or ()), meta.get("scenario"))
    probe = min(max(PROBE_FACTOR * float(exp.duration), float(scenario.duration)), MAX_PROBE_S)
    probe = round(probe / scenario.step_length) * scenario.step_length
    firsts: list[float | None] = []
    for trial in range(min(trials, int(exp.trials))):
        seeds = trial_seeds(exp.seed, trial)
        scans = observe(
            scenarios.simulate(scene, scenario, seeds, duration=probe), scene, config.sensor_at(), seeds.sensor_rngs()
        )
        seen = np.flatnonzero(np.asarray(scans.visible).any(axis=1))
        firsts.append(float(seen[0] * scans.dt) if len(seen) else None)
    return firsts, probe


@functools.lru_cache(maxsize=16)
def _hint(meta_json: str) -> str:
    meta = json.loads(meta_json)
    try:
        firsts, probe = first_observable(meta)
    except (SoabenchError, OSError):  # the scene is not loadable here (a copied run folder): no hint
        return ""
    name = meta.get("net_name") or meta.get("net")
    if not firsts:
        return ""
    seen = [t for t in firsts if t is not None]
    each = ", ".join(f"trial {i}: {'never' if t is None else f'{t:g} s'}" for i, t in enumerate(firsts))
    if not seen:
        return (
            f" On {name} no pedestrian becomes observable within {probe:g} s either ({each}): the scene or the sensor "
            "keeps them out of view."
        )
    shortest = TRACK_MARGIN_S * math.ceil((max(seen) + TRACK_MARGIN_S) / TRACK_MARGIN_S)
    return (
        f" On {name} the first pedestrian becomes observable (in the sensor's field of view and line of sight) at "
        f"t = {min(seen):g} s ({each}); the shortest useful duration for this scene is about {shortest:g} s "
        f"(--duration {shortest:g})."
    )


def duration_hint(meta: dict) -> str:
    """One or two sentences for a run that observed nobody: when the first pedestrian becomes observable on its
    scene and the shortest useful ``--duration``; '' for a run of another trial kind or scene loader (tests, plugins
    of the harness), whose scenes soabench cannot simulate."""

    if meta.get("trial_kind", registry.DEFAULT_TRIAL_KIND) != registry.DEFAULT_TRIAL_KIND:
        return ""
    if meta.get("scene_loader", registry.DEFAULT_SCENE_LOADER) != registry.DEFAULT_SCENE_LOADER:
        return ""
    keys = ("net", "net_name", "polys", "scenario", "config")
    return _hint(json.dumps({k: meta.get(k) for k in keys}, sort_keys=True))
