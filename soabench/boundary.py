"""What :mod:`soabench.api` accepts, checked once at the boundary: configurations, scenes, plugins and estimates.

Each check raises one line naming the value and what is allowed (a :class:`~soabench.errors.SoabenchError`, a
``ValueError``; a :class:`~soabench.errors.WrongTypeError` for an object of the wrong kind, also a ``TypeError``),
never an ``AttributeError`` from deep inside a stage.

State order: our states are [p_x, p_y, v_x, v_y] (:data:`ORDER_SOABENCH`, docs/method.md §2.2), Stone Soup's
[x, v_x, y, v_y] (:data:`ORDER_STONESOUP`). Four-column estimates in the wrong order are found by comparing both
readings with the truth (:func:`check_state_order`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from soabench import plugins
from soabench.config import FAMILIES, Config, MetricsConfig, load_config
from soabench.errors import SoabenchError, require, require_type
from soabench.experiment.trial.guard import PluginOutputError, check_estimates
from soabench.experiment.trial.registry import load_scene_cached
from soabench.scenario.scene import SceneMap
from soabench.tomlfile import read_toml
from soabench.types import Estimates, Scans, StepResult

ORDER_SOABENCH = "x,y,vx,vy"  #: our state order (positions first)
ORDER_STONESOUP = "x,vx,y,vy"  #: Stone Soup's state order (position and velocity per axis)
ORDERS = (ORDER_SOABENCH, ORDER_STONESOUP)
#: our state from Stone Soup's, and back (the permutation is its own inverse)
SWAP_ORDER = [0, 2, 1, 3]


def as_config(config: Config | dict | str | Path | None) -> Config:
    """A validated copy of ``config``: a :class:`Config`, a dict of sections (as a TOML file holds them), the path
    of a TOML file, or None for the defaults."""
    if config is None:
        return Config().validate()
    if isinstance(config, Config):
        return Config.from_dict(config.to_dict()).validate()
    require_type(config, (Config, dict, str, Path), "config", "give a soabench.api.Config, a dict or a TOML path")
    if isinstance(config, dict):
        return Config.from_dict(config).validate()
    return load_config(config)


def family_config(config: Config | dict | str | Path | None, family: str | None) -> tuple[Config, str]:
    """A validated copy of ``config`` for a tracker of one filter family, and that family: ``family`` if given
    (the configuration's ``experiment.filters`` set to it; one naming other families is refused), else the one
    family ``experiment.filters`` names (a configuration naming several is refused)."""
    if family is None:
        cfg = as_config(config)
        named = cfg.experiment.filters
        require(
            len(named) == 1,
            f"experiment.filters = {list(named)!r} names {len(named)} filter families; a tracker runs one: pass "
            f"filter= one of them",
        )
        return cfg, named[0]
    require(
        isinstance(family, str) and family in FAMILIES,
        f"filter = {family!r} is not allowed; choose one of {', '.join(map(repr, FAMILIES))}",
    )
    if config is None or isinstance(config, Config):
        data = (config or Config()).to_dict()
    elif isinstance(config, dict):
        data = dict(config)
    else:
        require_type(config, (Config, dict, str, Path), "config", "give a soabench.api.Config, a dict or a TOML path")
        require(Path(config).is_file(), f"config file {str(config)!r} does not exist")
        data = read_toml(Path(config), "config file")
    exp = data.get("experiment", {})
    require(isinstance(exp, dict), "config section [experiment] must be a table of key = value")
    named = exp.get("filters")
    require(
        named is None or list(named) == [family] or (isinstance(named, (list, tuple)) and family in named),
        f"filter = {family!r} is not among experiment.filters = {named!r} of the configuration; name it there or "
        "drop the key",
    )
    return Config.from_dict({**data, "experiment": {**exp, "filters": [family]}}).validate(), family


def metrics_config(config: Config | MetricsConfig | dict | str | Path | None) -> MetricsConfig:
    """The ``[metrics]`` settings of ``config`` (a whole configuration, or a :class:`MetricsConfig`)."""
    if isinstance(config, MetricsConfig):
        config.validate()
        return config
    return as_config(config).metrics


def as_scene(scene_or_net: Any) -> Any:
    """A :class:`~soabench.scenario.scene.SceneMap`, or the one of a network name or path (loaded once per
    process)."""

    if isinstance(scene_or_net, (str, Path)):
        return load_scene_cached(str(scene_or_net), (), None)[0]
    require_type(scene_or_net, SceneMap, "scene_or_net", "give a network name such as 'intersection' or a SceneMap")
    return scene_or_net


def as_names(value: Any, what: str) -> tuple[str, ...] | None:
    """Names of ``models``/``trackers``/``probabilities``: a comma-separated string, or a sequence of names and (for
    plugins) classes, a class named by its import path ``module:Class``, which this process may then import.
    None stays None."""
    if value is None:
        return None
    items = value.split(",") if isinstance(value, str) else list(value)
    out = []
    for item in items:
        if isinstance(item, type):
            item = class_path(item)
        require(isinstance(item, str), f"{what} holds {item!r}; give names (or plugin classes)")
        out.append(item.strip())
    if what != "probabilities":
        plugins.allow_import_paths(out)
    return tuple(out)


def class_path(cls: type) -> str:
    """``module:Qualname`` of a class, the name a class plugin is resolved (and tabled) under."""
    path = f"{cls.__module__}:{cls.__qualname__}"
    require(
        "<" not in path,
        f"class {cls.__qualname__!r} is defined inside a function; define it at the top level of a module or "
        "notebook so that it can be found by name",
    )
    return path


def plugin(name_or_class: Any) -> tuple[str, str, type]:
    """``(kind, name, class)`` of a birth model or tracker given by name (built-in, entry point, ``module:Class``)
    or as a class; a class with a ``step`` method is a tracker, any other a birth model."""
    if isinstance(name_or_class, type):
        cls = name_or_class
        kind = plugins.TRACKER if callable(getattr(cls, "step", None)) else plugins.BIRTH
        return kind, str(getattr(cls, "name", "") or cls.__name__), cls
    require(
        isinstance(name_or_class, str) and name_or_class != "",
        f"name_or_class = {name_or_class!r} must be a plugin name or class",
    )
    name = name_or_class
    plugins.allow_import_paths([name])
    if plugins.is_import_path(name):
        try:  # the kind follows from its shape: a class with step() is a tracker, else a birth model
            return plugins.TRACKER, name, plugins.resolve(plugins.TRACKER, name)
        except SoabenchError:
            return plugins.BIRTH, name, plugins.resolve(plugins.BIRTH, name)
    births, trackers = plugins.names(plugins.BIRTH), plugins.names(plugins.TRACKER)
    require(
        name in births or name in trackers,
        f"{name!r} is neither a birth model ({', '.join(births)}) nor a tracker ({', '.join(trackers)}); installed "
        "entry points, import paths module:Class and classes are accepted too",
    )
    kind = plugins.BIRTH if name in births else plugins.TRACKER
    return kind, name, plugins.resolve(kind, name)


# ------------------------------------------------------------------------------------------------------ estimates
def _nearest_distance(P: np.ndarray, G: np.ndarray) -> np.ndarray:
    d = np.sqrt(((P[:, None, :] - G[None, :, :]) ** 2).sum(axis=-1))
    return d.min(axis=1)


def check_state_order(scans: Scans, states: Sequence[np.ndarray]) -> None:
    """SoabenchError if four-column ``states`` (one (n, 4) array per scan) read as Stone Soup's [x, v_x, y, v_y]
    fit the truth far better than as ours [x, y, v_x, v_y]: the median distance to the nearest present walker is
    under a quarter, and under 10 m, over at least 5 estimates. Silent when too few estimates meet a walker."""
    ours, theirs = [], []
    for k, X in enumerate(states):
        if X.ndim != 2 or X.shape[1] != 4 or len(X) == 0:
            continue
        G = np.asarray(scans.truth_xy[k], dtype=float)
        G = G[np.isfinite(G).all(axis=1)]
        if len(G) == 0:
            continue
        ours.append(_nearest_distance(X[:, [0, 1]], G))
        theirs.append(_nearest_distance(X[:, [0, 2]], G))
    if not ours:
        return
    a, b = np.concatenate(ours), np.concatenate(theirs)
    if len(a) >= 5 and np.median(b) < min(10.0, 0.25 * np.median(a)):
        raise SoabenchError(
            f"the estimates look like Stone Soup states [x, vx, y, vy] (read so, they lie {np.median(b):.2g} m from "
            f"the walkers; read as [x, y, vx, vy], {np.median(a):.3g} m); pass order={ORDER_STONESOUP!r}, or "
            "convert Stone Soup tracks with soabench.api.from_stonesoup"
        )


def step_results(scans: Scans, estimates: Sequence[Any], order: str | None = None) -> list[StepResult]:
    """The :class:`StepResult` per scan that the metrics read, from a tracker's outputs: StepResults (our GM-PHD),
    :class:`Estimates` or bare (n, 2)/(n, 4) arrays, one per scan, checked as the harness checks a plugin's.

    ``order``: the column order of four-column states (:data:`ORDERS`); None: ours, after
    :func:`check_state_order` found no sign of Stone Soup's.
    """

    require_type(scans, Scans, "scans", "simulate them with soabench.api.simulate_trial")
    require(order is None or order in ORDERS, f"order = {order!r}; choose one of {', '.join(map(repr, ORDERS))}")
    require(
        isinstance(estimates, Sequence) and not isinstance(estimates, (str, np.ndarray)),
        f"estimates must be a list with one Estimates per scan, got a {type(estimates).__name__}",
    )
    require(
        len(estimates) == len(scans),
        f"{len(estimates)} estimates for {len(scans)} scans; give one Estimates (or StepResult) per scan",
    )
    items = [Estimates(np.asarray(e, dtype=float)) if isinstance(e, (np.ndarray, list)) else e for e in estimates]
    if order == ORDER_STONESOUP:
        items = [_swapped(e) for e in items]
    elif order is None:
        check_state_order(scans, [np.asarray(e.X, dtype=float) for e in items if isinstance(e, Estimates)])
    out = []
    for k, (e, scan) in enumerate(zip(items, scans.scans, strict=True)):
        try:
            out.append(check_estimates(e, scan, 0.0))
        except PluginOutputError as exc:
            raise SoabenchError(f"estimates[{k}]: {exc}") from None
    return out


def _swapped(e: Any) -> Any:
    """Four-column Estimates in Stone Soup's order, turned into ours (anything else unchanged)."""
    if not isinstance(e, Estimates):
        return e
    X = np.asarray(e.X, dtype=float)
    if X.ndim == 2 and X.shape[1] == 4:
        return Estimates(X[:, SWAP_ORDER], e.w, e.n_components, e.cardinality, e.labels)
    return e
