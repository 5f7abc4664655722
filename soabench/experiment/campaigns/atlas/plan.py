"""An atlas's plan: each design point's configuration and scene variant, and what running it costs (§5.10).

A point's configuration is the base configuration with its config axes set (``sensor.p_D`` also sets
``filter.p_D`` unless ``filter.p_D`` is an axis of its own: a filter that knows the sensor; with both axes the
mismatch is studied). Points whose scene axes agree form one *scene variant*: one scenario (the scene's own with the
scenario keys set) and one SUMO run per trial for all of them. Every value is checked here, before anything is
written: a configuration through :meth:`Config.validate`, a scenario through
:func:`soabench.scenario.config.scenario_from_dict`.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from soabench.config import FAMILY_MODES, Config
from soabench.errors import SoabenchError, require
from soabench.experiment.campaigns.atlas.design import Design, is_scene_axis

#: measured on a 2-core development machine (benchmarks/README.md, "Atlas"): core-seconds of one SUMO run and of
#: one filter run (model x mode x family x clutter rate) per 100 s simulated, with 6 pedestrians; both grow with
#: the pedestrians (SUMO: linearly; a filter: with the measurements per scan)
SUMO_CORE_S = 2.0
FILTER_CORE_S = 0.25


@dataclass(frozen=True)
class SceneVariant:
    """One combination of the scene axes' values: ``net`` and the scenario keys set (empty: the scene's own)."""

    index: int
    net: str
    scenario: dict[str, Any]  #: scenario key (``section.key``) -> value

    @property
    def name(self) -> str:
        return f"s{self.index:04d}"


@dataclass(frozen=True)
class PointPlan:
    """One design point: its axis values, scene variant and configuration (as the overrides of the base)."""

    index: int
    values: dict[str, Any]
    scene: int
    overrides: dict[str, dict[str, Any]]  #: section -> key -> value, applied to the base configuration


def base_pedestrians(net: str) -> int:
    """The pedestrians of ``net``'s own scenario (for ``birth.N_hat_offset`` without a pedestrians axis)."""
    from soabench.experiment.campaigns.occlusion import base_scenario

    data = base_scenario(net, None)
    return int(data.get("pedestrians", {}).get("count", 6))


def overrides_of(values: dict[str, Any], base: Config, pedestrians: int) -> dict[str, dict[str, Any]]:
    """The config sections a point sets (module docstring)."""
    out: dict[str, dict[str, Any]] = {}

    def put(key: str, value: Any) -> None:
        sec, name = key.split(".", 1)
        out.setdefault(sec, {})[name] = value

    for key, v in values.items():
        if is_scene_axis(key):
            continue
        if key == "experiment.clutter":
            put("experiment.clutter", [float(v)])
        elif key == "filters":
            put("experiment.filters", [str(v)])
        elif key == "birth.N_hat_offset":
            K = max(1, int(round(base.experiment.duration / base.sensor.dt)))
            put("birth.N_hat", max(1, pedestrians + int(v)) / K)
        else:
            put(key, v)
    if "sensor.p_D" in values and "filter.p_D" not in values:
        put("filter.p_D", float(values["sensor.p_D"]))
    return out


def point_config(base: dict, overrides: dict[str, dict[str, Any]]) -> Config:
    """The configuration of a point: ``base`` (``Config.to_dict()``) with ``overrides`` set, validated."""
    data = json.loads(json.dumps(base))
    for sec, table in overrides.items():
        data.setdefault(sec, {}).update(table)
    return Config.from_dict(data).validate()


def plan_points(design: Design, base: Config, net: str) -> tuple[list[SceneVariant], list[PointPlan]]:
    """The scene variants and points of ``design`` on ``net`` (every value checked; one line naming a bad one)."""
    scene_keys = [a.key for a in design.axes if is_scene_axis(a.key)]
    variants: dict[tuple, SceneVariant] = {}
    points: list[PointPlan] = []
    base_dict = base.to_dict()
    peds_of: dict[str, int] = {}
    checked: set[tuple] = set()
    for i, values in enumerate(design.points):
        v_net = str(values.get("net", net))
        scen = {k: values[k] for k in scene_keys if k != "net"}
        vkey = (v_net, tuple(sorted(scen.items())))
        if vkey not in variants:
            variants[vkey] = SceneVariant(len(variants), v_net, scen)
        if "pedestrians.count" in scen:
            peds = int(scen["pedestrians.count"])
        else:
            if v_net not in peds_of:
                peds_of[v_net] = base_pedestrians(v_net)
            peds = peds_of[v_net]
        ov = overrides_of(values, base, peds)
        okey = json.dumps(ov, sort_keys=True)
        if okey not in checked:
            try:
                point_config(base_dict, ov)
            except SoabenchError as exc:
                shown = ", ".join(f"{k} = {v!r}" for k, v in values.items() if not is_scene_axis(k))
                raise SoabenchError(f"design point {shown}: {exc}") from None
            checked.add(okey)
        points.append(PointPlan(i, dict(values), variants[vkey].index, ov))
    return list(variants.values()), points


def variant_scenario(variant: SceneVariant) -> dict | None:
    """The scenario dict of a variant (the scene's own with its keys set), validated; None: the scene's own file."""
    if not variant.scenario:
        return None
    from soabench.experiment.campaigns.occlusion import base_scenario, check_parking_lanes
    from soabench.scenario.config import scenario_from_dict

    data = {k: dict(v) for k, v in base_scenario(variant.net, None).items()}
    for key, value in variant.scenario.items():
        sec, name = key.split(".", 1)
        data.setdefault(sec, {})[name] = value
    try:
        scenario_from_dict(data, source=f"scene {variant.net}")
    except SoabenchError as exc:
        raise SoabenchError(f"axis value {_shown(variant.scenario)}: {exc}") from None
    if "parking.density" in variant.scenario and "net" in data.get("files", {}):
        check_parking_lanes(
            data["files"]["net"],
            [variant.scenario["parking.density"]],
            what=f"axis parking.density on scene {variant.net!r}",
            fix="drop the parking.density axis for this scene (or give it only the value 0)",
        )
    return data


def _shown(values: dict[str, Any]) -> str:
    return ", ".join(f"{k} = {v!r}" for k, v in values.items())


def check_scenes(variants: Sequence[SceneVariant]) -> None:
    """Every scene variant's scenario is valid (before anything is written); scene names are checked by loading."""
    from soabench.scenario import shipped_nets

    shipped = shipped_nets()
    for v in variants:
        require(
            v.net in shipped or Path(v.net).exists(),
            f"scene {v.net!r} is not a shipped scene or a path; allowed: {', '.join(shipped)} or a scene folder",
        )
    seen: set = set()
    for v in variants:  # each distinct scenario value once
        for key, value in v.scenario.items():
            if (v.net, key, value) not in seen:
                seen.add((v.net, key, value))
                variant_scenario(SceneVariant(-1, v.net, {key: value}))
    for v in variants:
        variant_scenario(v)


@dataclass(frozen=True)
class Cost:
    """What running an atlas takes: points, trials, SUMO runs, filter runs and estimated core-hours."""

    points: int
    trials: int
    sumo_runs: int
    filter_runs: int
    core_hours: float

    def lines(self, done: int = 0) -> list[str]:
        left = f" ({done} of them finished)" if done else ""
        return [
            f"points: {self.points}",
            f"trials: {self.trials} (points x trials per point){left}",
            f"SUMO runs: {self.sumo_runs} (one per scene variant and trial, shared by its points)",
            f"filter runs: {self.filter_runs} (trials x models x modes x families)",
            f"estimated: {self.core_hours:.2f} core-hours (about {self.core_hours * 60:.0f} core-minutes; "
            "rates of benchmarks/README.md, Atlas)",
        ]


def runs_per_trial(cfg: Config) -> int:
    """Filter runs of one trial of one point: (models x modes per family) x families x clutter rates + trackers."""

    exp = cfg.experiment
    per_family = sum(len([m for m in exp.probabilities if m in FAMILY_MODES[f]]) for f in exp.filters)
    return (len(exp.models) * per_family + len(exp.trackers)) * len(exp.clutter)


def estimate(
    base: Config, variants: Sequence[SceneVariant], points: Sequence[PointPlan], trials: int, pedestrians: int = 6
) -> Cost:
    """The cost of ``trials`` trials at every point (the constants above, scaled by duration and pedestrians)."""
    scale = base.experiment.duration / 100.0
    base_dict = base.to_dict()
    sumo = 0.0
    for v in variants:
        peds = int(v.scenario.get("pedestrians.count", pedestrians))
        sumo += SUMO_CORE_S * scale * max(1.0, peds / 6.0)
    filt, n_runs = 0.0, 0
    cache: dict[str, int] = {}
    for p in points:
        key = json.dumps(p.overrides, sort_keys=True)
        if key not in cache:
            cache[key] = runs_per_trial(point_config(base_dict, p.overrides))
        peds = int(variants[p.scene].scenario.get("pedestrians.count", pedestrians))
        n_runs += cache[key]
        filt += cache[key] * FILTER_CORE_S * scale * math.sqrt(max(1.0, peds / 6.0))
    return Cost(
        points=len(points),
        trials=len(points) * trials,
        sumo_runs=len(variants) * trials,
        filter_runs=n_runs * trials,
        core_hours=(sumo + filt) * trials / 3600.0,
    )


def with_experiment(cfg: Config, **changes: Any) -> Config:
    out = Config.from_dict(cfg.to_dict())
    out.experiment = dataclasses.replace(out.experiment, **changes)
    return out.validate()
