"""What a run folder's ``run.json`` may hold, checked value by value, and requested-vs-stored comparisons.

``run.json`` is data from a file that may come from anyone (a download, a pull request touching ``results/``), so
every value read back is validated here before use: types, the configuration (the same strict loader as a TOML
file), the network/polygon/scenario strings, and the trial kind and scene loader *names*, looked up in the closed
:mod:`~soabench.experiment.trial.registry` (nothing is imported).

:func:`config_differences` lists the keys where a requested configuration differs from a stored one; a resumed run
(or a re-run ``study``) refuses every difference except more trials, which is safe because trial n's seeds depend
only on (seed, n) (:mod:`soabench.seeding`): trials 0..N-1 of a longer run are those of the shorter one.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from soabench.config import MAX_TRIALS, Config
from soabench.errors import SoabenchError, require
from soabench.experiment.trial import registry

MAX_STRING = 4096  #: longest net/poly/scenario string accepted from a run file


@dataclass(frozen=True)
class RunMeta:
    """The validated content of a ``run.json``."""

    config: Config
    net: str
    polys: tuple[str, ...]
    scenario: str | None
    save_estimates: bool
    trials: int
    trial_kind: str
    scene_loader: str


def _string(where: str, key: str, value: Any, optional: bool = False) -> str | None:
    if value is None and optional:
        return None
    require(
        isinstance(value, str) and 0 < len(value) <= MAX_STRING and "\x00" not in value,
        f"{where}: {key} = {value!r} must be a non-empty string",
    )
    return value


def _legacy_name(meta: dict, new_key: str, old_key: str, default: str) -> Any:
    """The registry name of a run file: ``new_key``; older files stored ``old_key`` (null for the built-in)."""
    if new_key in meta:
        return meta[new_key]
    old = meta.get(old_key)
    return default if old is None else old  # a non-null old import path is refused by the registry lookup


def validate_run_meta(meta: Any, where: str) -> RunMeta:
    """Check every value of a run file (``where`` names it in messages); :class:`SoabenchError` on the first bad one."""
    require(isinstance(meta, dict), f"{where} must hold a JSON object")
    try:
        config = Config.from_record(meta.get("config")).validate()
    except SoabenchError as exc:
        raise SoabenchError(f"{where}: config: {exc}") from None
    net = _string(where, "net", meta.get("net"))
    polys = meta.get("polys", [])
    require(isinstance(polys, list), f"{where}: polys = {polys!r} must be a list of file names")
    polys = tuple(_string(where, "polys[]", p) for p in polys)
    scenario = _string(where, "scenario", meta.get("scenario"), optional=True)
    save = meta.get("save_estimates", False)
    require(isinstance(save, bool), f"{where}: save_estimates = {save!r} must be true or false")
    trials = meta.get("trials", config.experiment.trials)
    require(
        isinstance(trials, int) and not isinstance(trials, bool) and trials == config.experiment.trials,
        f"{where}: trials = {trials!r} must equal config.experiment.trials = {config.experiment.trials}",
    )
    kind = _legacy_name(meta, "trial_kind", "trial_fn", registry.DEFAULT_TRIAL_KIND)
    loader = _legacy_name(meta, "scene_loader", "load_fn", registry.DEFAULT_SCENE_LOADER)
    try:
        registry.trial_kind(kind)
        registry.scene_loader(loader)
    except SoabenchError as exc:
        raise SoabenchError(f"{where}: {exc}") from None
    return RunMeta(config, net, polys, scenario, save, trials, kind, loader)


def _flatten(d: dict, prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = list(v) if isinstance(v, tuple) else v
    return out


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def config_differences(stored: dict, requested: dict, keys: set[str] | None = None) -> list[tuple[str, Any, Any]]:
    """``(dotted key, stored value, requested value)`` for every key that differs (only ``keys`` if given)."""
    a, b = _flatten(stored), _flatten(requested)
    names = sorted(set(a) | set(b)) if keys is None else sorted(keys)
    return [(k, a.get(k), b.get(k)) for k in names if not _same(a.get(k), b.get(k))]


def check_requested(stored: dict, requested: dict, where: str) -> int | None:
    """Refuse every difference between the keys of ``requested`` and ``stored`` (flat ``{dotted key: value}``
    dicts) except more trials.

    Returns the new trial count when ``experiment.trials`` grows (and nothing else differs), else None.
    """
    diffs = config_differences(stored, requested, set(requested))
    more = None
    rest = []
    for key, old, new in diffs:
        if key == "experiment.trials" and isinstance(old, int) and isinstance(new, int) and new > old:
            more = new
        else:
            rest.append((key, old, new))
    if rest:
        listed = "; ".join(f"{k}: stored {old!r}, requested {new!r}" for k, old, new in rest)
        hint = " (fewer trials would drop finished ones)" if any(k == "experiment.trials" for k, _, _ in rest) else ""
        raise SoabenchError(
            f"{where} was made with other settings: {listed}{hint}; resume without these options or start a new "
            "folder with --out"
        )
    if more is not None:
        require(more <= MAX_TRIALS, f"trials = {more} exceeds the limit {MAX_TRIALS}")
    return more


POINT_NAME = re.compile(r"^[a-z][a-z0-9_]{0,63}$")  #: a sweep point's folder name (never a path)


def validate_sweep_meta(meta: Any, where: str, kinds: tuple[str, ...]) -> dict:
    """Check every value of a ``sweep.json`` that is used (points' names are folder names: no path may sneak in)."""
    require(isinstance(meta, dict), f"{where} must hold a JSON object")
    require(meta.get("kind") in kinds, f"{where}: kind = {meta.get('kind')!r} must be one of {', '.join(kinds)}")
    _string(where, "net", meta.get("net"))
    polys = meta.get("polys", [])
    require(isinstance(polys, list), f"{where}: polys = {polys!r} must be a list of file names")
    for p in polys:
        _string(where, "polys[]", p)
    _string(where, "scenario", meta.get("scenario"), optional=True)
    points = meta.get("points")
    require(isinstance(points, list) and len(points) >= 1, f"{where}: points must be a non-empty list")
    names = set()
    for p in points:
        require(isinstance(p, dict), f"{where}: every point must be a JSON object")
        name = p.get("name")
        require(isinstance(name, str) and bool(POINT_NAME.match(name)), f"{where}: point name {name!r} is not allowed")
        require(name not in names, f"{where}: point name {name!r} appears twice")
        names.add(name)
        try:
            Config.from_record(p.get("config")).validate()
        except SoabenchError as exc:
            raise SoabenchError(f"{where}: point {name}: {exc}") from None
        if p.get("scenario") is not None:  # an occlusion point's own scenario file: inside the sweep folder only
            sc = p["scenario"]
            folder = Path(where).resolve().parent
            require(
                isinstance(sc, str) and Path(sc).resolve().is_relative_to(folder / "points"),
                f"{where}: point {name}: scenario {sc!r} is not a file of the sweep's points/ folder",
            )
    values = meta.get("values", [])
    require(
        isinstance(values, list) and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values),
        f"{where}: values must be a list of numbers",
    )
    return meta


def flatten_config(cfg: dict) -> dict[str, Any]:
    """``{"sensor.dt": 1.0, ...}`` from ``Config.to_dict()``."""
    return _flatten(cfg)
