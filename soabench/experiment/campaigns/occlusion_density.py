"""How much of a scene the sensor cannot see: the occlusion density of the cross-scene summary (docs/method.md §3.1.4).

Measured on the very SUMO runs and scans of trials 0..n-1 of the main protocol (same seeds, :mod:`soabench.seeding`;
the clutter rate changes neither the occluders nor line of sight), two numbers per scene:

* **occluded sidewalk share** (the summary's x axis): per scan k, ``1 - |Omega_k| / |S ∩ FOV_k|``, where S is the
  sidewalk and Omega_k the visible region (§3.1.4: the sidewalk in the FOV minus every occluder and its shadow);
  the mean over every scan with sidewalk in its FOV, pooled over the trials. It is a property of the scene's
  geometry and traffic (buildings, parked cars, passing vehicles), not of where the pedestrians happen to walk;
* **occluded pedestrian share**: the share of pedestrian-scans inside the FOV without line of sight,
  ``sum_k |in FOV_k and not visible_k| / sum_k |in FOV_k|`` (the truth flags of §5.1).

Each scene's numbers are written to ``<name>.json`` (:func:`write_density`) with what they were measured on (trials,
seed, duration, sensor), so a re-run keeps a file made with the same settings.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from soabench import scenario as scenarios  # by attribute: a test may stand in for load, simulate
from soabench.atomic import to_jsonable, write_json_atomic
from soabench.config import Config
from soabench.errors import require
from soabench.experiment.runs.files import read_json
from soabench.seeding import trial_seeds
from soabench.sensor import fov_polygon, observe

FORMAT = "soabench-occlusion-density-1"


def scan_occlusion(scans: Any, scene: Any) -> dict[str, Any]:
    """Per-scan occluded share of the sidewalk in the FOV (NaN without sidewalk in the FOV) and pedestrian counts."""

    sensor = scans.sensor
    region = scene.sidewalk
    shares = np.full(len(scans), np.nan)
    for k, scan in enumerate(scans.scans):
        fov = fov_polygon(scan.ego, sensor)
        seen = shapely.area(shapely.intersection(shapely.clip_by_rect(region, *fov.bounds), fov))
        if seen > 1e-9:
            shares[k] = min(max(1.0 - float(scan.visible_region.area) / float(seen), 0.0), 1.0)
    in_fov = np.asarray(scans.in_fov, dtype=bool)
    hidden = in_fov & ~np.asarray(scans.visible, dtype=bool)
    return {"shares": shares, "in_fov": int(in_fov.sum()), "hidden": int(hidden.sum())}


def scene_density(
    net: str,
    config: Config,
    trials: int,
    *,
    load_fn: Callable[..., Any] | None = None,
    simulate_fn: Callable[..., Any] | None = None,
    observe_fn: Callable[..., Any] | None = None,
) -> dict[str, Any]:
    """The occlusion density of ``net`` over trials 0..trials-1 of ``config`` (seed, duration, sensor)."""

    require(isinstance(trials, int) and trials >= 1, f"density trials {trials!r} must be an integer >= 1")
    load_fn, simulate_fn, observe_fn = (
        load_fn or scenarios.load,
        simulate_fn or scenarios.simulate,
        observe_fn or observe,
    )
    scene, scenario = load_fn(net, (), None)
    exp = config.experiment
    sensor = config.sensor_at()
    per_trial, shares, n_in, n_hidden = [], [], 0, 0
    for n in range(trials):
        seeds = trial_seeds(exp.seed, n)
        recording = simulate_fn(scene, scenario, seeds, duration=exp.duration)
        scans = observe_fn(recording, scene, sensor, seeds.sensor_rngs())
        occ = scan_occlusion(scans, scene)
        ok = occ["shares"][np.isfinite(occ["shares"])]
        shares.append(ok)
        n_in += occ["in_fov"]
        n_hidden += occ["hidden"]
        per_trial.append(
            {
                "trial": n,
                "occluded_sidewalk": float(ok.mean()) if len(ok) else math.nan,
                "scans": len(ok),
                "pedestrians_in_fov": occ["in_fov"],
                "pedestrians_hidden": occ["hidden"],
            }
        )
    pooled = np.concatenate(shares) if shares else np.zeros(0)
    trial_means = np.array([t["occluded_sidewalk"] for t in per_trial])
    trial_means = trial_means[np.isfinite(trial_means)]
    return {
        "format": FORMAT,
        "net": net,
        "settings": settings(config, trials),
        "occluded_sidewalk": float(pooled.mean()) if len(pooled) else math.nan,
        # spread of the per-trial means (the trials are independent; scans within a trial are not)
        "occluded_sidewalk_se": float(trial_means.std(ddof=1) / math.sqrt(len(trial_means)))
        if len(trial_means) > 1
        else math.nan,
        "occluded_pedestrians": n_hidden / n_in if n_in else math.nan,
        "scans": int(len(pooled)),
        "pedestrians_in_fov": n_in,
        "pedestrians_hidden": n_hidden,
        "trials": per_trial,
    }


def settings(config: Config, trials: int) -> dict[str, Any]:
    """What a density depends on: trials, seed, duration and the sensor (JSON-ready, compared on a re-run)."""
    exp = config.experiment
    return {
        "trials": int(trials),
        "seed": int(exp.seed),
        "duration": float(exp.duration),
        "sensor": dataclasses.asdict(config.sensor),
    }


def read_density(path: Path) -> dict[str, Any] | None:
    """A density file's content if it is one (checked field by field: it is data from a file), else None."""

    try:
        data = read_json(path)
    except Exception:  # unreadable or not JSON: measured again
        return None
    ok = (
        isinstance(data, dict)
        and data.get("format") == FORMAT
        and isinstance(data.get("settings"), dict)
        and all(isinstance(data.get(k), (int, float)) for k in ("occluded_sidewalk", "occluded_pedestrians"))
    )
    return data if ok else None


def write_density(path: Path, net: str, config: Config, trials: int, **fns: Any) -> tuple[dict[str, Any], bool]:
    """Measure and write ``path`` unless it already holds the density of ``net`` for these settings.

    Returns (density, kept). The file is written atomically: an interrupted measurement leaves no file.
    """

    old = read_density(path) if Path(path).is_file() else None
    want = to_jsonable(settings(config, trials))
    if old is not None and old.get("net") == net and old["settings"] == want:
        return old, True
    data = to_jsonable(scene_density(net, config, trials, **fns))
    write_json_atomic(Path(path), data)
    return data, False
