"""The closed registry of what a run folder may name: trial kinds and scene loaders.

A run folder is data, never code: ``run.json`` stores the *name* of its trial kind and scene loader
(``"trial_kind": "soabench"``, ``"scene_loader": "sumo"``), and ``--resume`` looks the names up here. Nothing read
from a file is imported, evaluated or called by a path it spells out; a name that is not registered is refused with
one clear error naming the known ones.

Built-ins: trial kind ``soabench`` (:func:`soabench.experiment.trial.trial.run_trial`) and scene loader ``sumo``
(:func:`soabench.scenario.load`). Code (a plugin, a test, a benchmark) adds more with
:func:`register_trial_kind` / :func:`register_scene_loader` *before* a run names them::

    from soabench.experiment.trial.registry import register_trial_kind
    register_trial_kind("my-trial", my_package.trials.run_trial)

A test or benchmark that stands in for the real trial or scene (the built-in names included) does so for one
block with :func:`registered`, which puts every name back as it was on exit.

Signatures: a trial kind is ``fn(trial, config, scene, scenario, *, save_estimates) -> TrialResult``; a scene
loader ``fn(net, polys, scenario) -> (SceneMap, ScenarioConfig)``. Both must be module-level functions so that worker
processes can unpickle them. Registering is done by code the user installed (entry points), never by a run folder.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import Any

from soabench.errors import SoabenchError, require
from soabench.scenario import load

TrialFn = Callable[..., Any]
LoadFn = Callable[..., Any]

DEFAULT_TRIAL_KIND = "soabench"
DEFAULT_SCENE_LOADER = "sumo"

#: names: a letter first, then letters, digits, '.', '_', '-' (at most 64 characters)
NAME_PATTERN = re.compile(r"^[A-Za-z][A-Za-z0-9._-]{0,63}$")


def _builtin_trial(trial, config, scene, scenario, *, save_estimates=False):
    """The built-in trial kind: :func:`soabench.experiment.trial.trial.run_trial` (imported on first use)."""
    # imported when called: scipy would slow every start-up
    from soabench.experiment.trial.trial import run_trial

    return run_trial(trial, config, scene, scenario, save_estimates=save_estimates)


def _builtin_loader(net, polys=(), scenario=None):
    """The built-in scene loader: :func:`soabench.scenario.load` (imported on first use)."""

    return load(net, tuple(polys), scenario)


_TRIAL_KINDS: dict[str, TrialFn] = {DEFAULT_TRIAL_KIND: _builtin_trial}
_SCENE_LOADERS: dict[str, LoadFn] = {DEFAULT_SCENE_LOADER: _builtin_loader}


def _register(table: dict[str, Callable], what: str, name: str, fn: Callable) -> None:
    require(isinstance(name, str) and bool(NAME_PATTERN.match(name)), f"{what} name {name!r} is not a valid name")
    require(callable(fn), f"{what} {name!r} must be a function, not {type(fn).__name__}")
    old = table.get(name)
    require(old is None or old is fn, f"{what} {name!r} is already registered to another function")
    table[name] = fn


def register_trial_kind(name: str, fn: TrialFn) -> None:
    """Make ``fn`` available to runs as trial kind ``name`` (re-registering the same function is a no-op)."""
    _register(_TRIAL_KINDS, "trial kind", name, fn)


def register_scene_loader(name: str, fn: LoadFn) -> None:
    """Make ``fn`` available to runs as scene loader ``name`` (re-registering the same function is a no-op)."""
    _register(_SCENE_LOADERS, "scene loader", name, fn)


@contextmanager
def registered(
    trial_kinds: Mapping[str, TrialFn] | None = None, scene_loaders: Mapping[str, LoadFn] | None = None
) -> Iterator[None]:
    """Within the block, each name of ``trial_kinds`` / ``scene_loaders`` stands for the given function, a registered
    name (a built-in included) being replaced; on exit every name is as before. Names are checked as in
    :func:`register_trial_kind`. For code that stands in for the real trial or scene (tests, benchmarks)::

        with registered(trial_kinds={DEFAULT_TRIAL_KIND: fake_trial}):
            run_experiment(...)
    """
    saved = [(table, dict(table)) for table in (_TRIAL_KINDS, _SCENE_LOADERS)]
    try:
        for table, what, given in (
            (_TRIAL_KINDS, "trial kind", trial_kinds or {}),
            (_SCENE_LOADERS, "scene loader", scene_loaders or {}),
        ):
            for name, fn in given.items():
                table.pop(name, None)
                _register(table, what, name, fn)
        yield
    finally:
        for table, before in saved:
            table.clear()
            table.update(before)


def _lookup(table: dict[str, Callable], what: str, name: Any) -> Callable:
    if not isinstance(name, str) or name not in table:
        raise SoabenchError(
            f"{what} {name!r} is not registered; known: {', '.join(sorted(table))} "
            "(a plugin must be installed and registered before a run can name it)"
        )
    return table[name]


def trial_kind(name: str) -> TrialFn:
    """The registered trial function called ``name``; :class:`SoabenchError` for an unknown name."""
    return _lookup(_TRIAL_KINDS, "trial kind", name)


def scene_loader(name: str) -> LoadFn:
    """The registered scene loader called ``name``; :class:`SoabenchError` for an unknown name."""
    return _lookup(_SCENE_LOADERS, "scene loader", name)


def trial_kinds() -> tuple[str, ...]:
    return tuple(sorted(_TRIAL_KINDS))


def scene_loaders() -> tuple[str, ...]:
    return tuple(sorted(_SCENE_LOADERS))


def _name_of(table: dict[str, Callable], fn: Callable | None, default: str) -> str:
    if fn is None:
        return default
    for name, registered in table.items():
        if registered is fn:
            return name
    # not registered: recorded under a name no lookup will find, so --resume refuses it instead of importing it
    return f"unregistered:{getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', '?')}"


def trial_kind_name(fn: TrialFn | None) -> str:
    """The name ``run.json`` records for ``fn`` (``soabench`` for None)."""
    return _name_of(_TRIAL_KINDS, fn, DEFAULT_TRIAL_KIND)


def scene_loader_name(fn: LoadFn | None) -> str:
    """The name ``run.json`` records for ``fn`` (``sumo`` for None)."""
    return _name_of(_SCENE_LOADERS, fn, DEFAULT_SCENE_LOADER)


_SCENES: dict[tuple, tuple[Any, Any]] = {}


def load_scene_cached(net: str, polys: Sequence[str], scenario: str | None, load_fn: LoadFn | None = None):
    """``(SceneMap, ScenarioConfig)`` of a network, loaded once per process (``load_fn``: the built-in loader)."""
    fn = load_fn or scene_loader(DEFAULT_SCENE_LOADER)
    key = (fn.__module__, fn.__qualname__, str(net), tuple(str(p) for p in polys), scenario)
    if key not in _SCENES:
        _SCENES[key] = fn(net, tuple(polys), scenario)
    return _SCENES[key]
