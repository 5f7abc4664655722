"""Which birth models and trackers a run may use, and how a name becomes a class (docs/user-guide/tracker.md).

The registry is a closed list, rebuilt in every process from three sources:

1. the built-ins: the six birth models (:data:`BUILTIN_BIRTH_MODELS`) and the Stone Soup bridges
   (:data:`BUILTIN_TRACKERS`, usable when Stone Soup is installed);
2. the installed entry points of the groups ``soabench.birth_models`` and ``soabench.trackers`` (a package's
   ``pyproject.toml`` declares them; the entry point's name is the model's name in every table);
3. the import paths ``module:Class`` the user typed on THIS command line (``--models``, ``--trackers``); they are
   the model's name as typed.

A stored run (``run.json``, its config) records names only. Reading it never imports a string it holds: a name
resolves if it is a built-in or an installed entry point; an import-path name of a stored run (``--resume``) must be
typed again on the command line, otherwise the run is refused with one line saying so. Worker processes (process
pool, Dask) receive the typed import paths of the driver in the task (:func:`session_import_paths`), never from a
file.
"""

from __future__ import annotations

import difflib
import importlib
import inspect
import re
from collections.abc import Iterable
from importlib import metadata
from typing import Any

from soabench.errors import SoabenchError, require

BIRTH_GROUP = "soabench.birth_models"  #: entry-point group of birth-model plugins
TRACKER_GROUP = "soabench.trackers"  #: entry-point group of tracker plugins
BIRTH, TRACKER = "birth model", "tracker"  #: the plugin kinds (``soabench.api.BIRTH_MODEL``, ``soabench.api.TRACKER``)
KINDS = (BIRTH, TRACKER)

#: trackers that ship with soabench (bridges to other frameworks; each needs its optional extra)
#: the built-in birth models: name -> "module:Class" (imported when first used: baselines import soabench.birth.base)
BUILTIN_BIRTH_MODELS: dict[str, str] = {
    "soa": "soabench.birth.soa:SOABirth",
    "pubm": "soabench.baselines.partially_uniform:PartiallyUniformBirth",
    "ubm": "soabench.baselines.uniform:UniformBirth",
    "ubm-ws": "soabench.baselines.uniform:WorkspaceUniformBirth",
    "atbm": "soabench.baselines.adaptive:AdaptiveBirth",
    "gmbm": "soabench.baselines.standard_gm:StandardGMBirth",
}

BUILTIN_TRACKERS: dict[str, str] = {
    "stonesoup-gmphd": "soabench.bridges.stonesoup:StoneSoupGMPHD",
    "stonesoup-gnn": "soabench.bridges.stonesoup:StoneSoupGNN",
}

_IDENT = r"[A-Za-z_]\w*"
_IMPORT_PATH = re.compile(rf"^{_IDENT}(\.{_IDENT})*:{_IDENT}(\.{_IDENT})*$")
_TYPED: set[str] = set()  #: import paths typed on this process's command line (or handed over by the driver)


class PluginError(SoabenchError):
    """A plugin could not be found, imported or built (one line naming the plugin)."""


def is_import_path(name: str) -> bool:
    """``module.sub:Class`` (as typed on the command line), not a registered name."""
    return ":" in name


def allow_import_paths(names: Iterable[str]) -> None:
    """Add the ``module:Class`` names among ``names`` to this process's closed list (command line, driver task)."""
    for name in names:
        if is_import_path(name):
            require(
                bool(_IMPORT_PATH.match(name)),
                f"plugin {name!r} is not an import path of the form package.module:Class",
            )
            _TYPED.add(name)


def session_import_paths() -> tuple[str, ...]:
    """The import paths allowed in this process, for the worker tasks."""
    return tuple(sorted(_TYPED))


def _entry_points(group: str) -> dict[str, metadata.EntryPoint]:
    return {ep.name: ep for ep in metadata.entry_points(group=group)}


def check_kind(kind: str) -> None:
    """SoabenchError unless ``kind`` is one of :data:`KINDS`."""
    require(
        kind in KINDS,
        f"plugin kind {kind!r} is unknown; choose {BIRTH!r} (soabench.api.BIRTH_MODEL) or {TRACKER!r} "
        "(soabench.api.TRACKER)",
    )


def names(kind: str) -> list[str]:
    """Every registered name of ``kind`` (built-ins first, then installed entry points, then typed paths)."""
    check_kind(kind)
    builtin = BUILTIN_BIRTH_MODELS if kind == BIRTH else BUILTIN_TRACKERS
    eps = [n for n in _entry_points(BIRTH_GROUP if kind == BIRTH else TRACKER_GROUP) if n not in builtin]
    return [*builtin, *sorted(eps)]


def is_builtin_birth(name: str) -> bool:
    """One of the six built-in birth models (run unguarded: an error there is a bug of soabench)."""
    return name in BUILTIN_BIRTH_MODELS


def check_name(kind: str, name: str) -> None:
    """SoabenchError unless ``name`` is in the closed list of ``kind`` (see the module docstring)."""
    check_kind(kind)
    require(isinstance(name, str) and name != "", f"{kind} name {name!r} must be a non-empty string")
    if is_import_path(name):
        flag = "--models" if kind == BIRTH else "--trackers"
        require(
            name in _TYPED,
            f"{kind} {name!r} is an import path its caller did not name; soabench imports only built-ins, installed "
            f"entry points and import paths named where the run is asked for: in Python as {flag[2:]}= of "
            f"soabench.api.run (or the class itself), on the command line as {flag} (to resume such a run, name it "
            f"again: --resume DIR {flag} {name})",
        )
        return
    if name in (BUILTIN_BIRTH_MODELS if kind == BIRTH else BUILTIN_TRACKERS):
        return  # no entry-point scan for a built-in
    known = names(kind)
    close = difflib.get_close_matches(name, known, n=1)
    require(
        name in known,
        f"{kind} {name!r} is unknown; choose one of {', '.join(known)}, an installed entry point of group "
        f"{BIRTH_GROUP if kind == BIRTH else TRACKER_GROUP!r} or an import path module:Class"
        + (f" (did you mean {close[0]!r}?)" if close else ""),
    )


def resolve(kind: str, name: str) -> type:
    """The class registered under ``name`` (imported now); PluginError naming the plugin if that fails."""
    check_name(kind, name)
    builtin = BUILTIN_BIRTH_MODELS if kind == BIRTH else BUILTIN_TRACKERS
    try:
        if name in builtin or is_import_path(name):
            target = builtin.get(name, name)
            module, _, qual = target.partition(":")
            obj: Any = importlib.import_module(module)
            for part in qual.split("."):
                obj = getattr(obj, part)
        else:
            obj = _entry_points(BIRTH_GROUP if kind == BIRTH else TRACKER_GROUP)[name].load()
    except SoabenchError as exc:
        raise PluginError(f"{kind} plugin {name!r} cannot be used: {exc}") from None
    except Exception as exc:  # an import error inside the plugin is the plugin's, reported in one line
        raise PluginError(
            f"{kind} plugin {name!r} cannot be imported: {type(exc).__name__}: {exc}{_import_hint(name, exc)}"
        ) from None
    api = "soabench.api.BirthModel" if kind == BIRTH else "soabench.api.Tracker"
    require(
        inspect.isclass(obj),
        f"{kind} plugin {name!r} is {_describe(obj)}, not a class; name a {kind} class (see {api})",
    )
    method = "__call__" if kind == BIRTH else "step"  # dir() of a class lists its own and inherited methods
    require(
        method in dir(obj) and callable(getattr(obj, method)),
        f"{kind} plugin {name!r} ({obj.__module__}.{obj.__qualname__}) has no {method}() method; see {api}",
    )
    return obj


def _describe(obj: Any) -> str:
    """``the built-in function os.system``, ``the module os``, ``an int`` ... for a one-line refusal."""
    if inspect.ismodule(obj):
        return f"the module {obj.__name__}"
    if callable(obj) and hasattr(obj, "__qualname__"):
        kind = "built-in function" if inspect.isbuiltin(obj) else "function"
        return f"the {kind} {getattr(obj, '__module__', None) or '?'}.{obj.__qualname__}"
    return f"an object of type {type(obj).__name__}"


def _import_hint(name: str, exc: Exception) -> str:
    """What to do about a ModuleNotFoundError: make the plugin's module importable, or install what it imports."""
    missing = getattr(exc, "name", None)
    if not isinstance(exc, ModuleNotFoundError) or not missing:
        return ""
    module = name.partition(":")[0] if is_import_path(name) else ""
    if module == missing or module.startswith(missing + "."):
        return (
            f" (the module {module!r} must be importable: put the folder that holds it on PYTHONPATH, e.g. "
            "PYTHONPATH=. soabench ..., or install its package with pip install -e DIR)"
        )
    return f" (the plugin imports {missing!r}, which is not installed here)"


def check_options(kind: str, name: str, cls: type, options: dict[str, Any]) -> None:
    """SoabenchError unless the ``[plugins.<name>]`` table fits the constructor's keyword arguments."""
    if not options:
        return
    try:
        sig = inspect.signature(cls)
    except (TypeError, ValueError):  # a builtin or C callable: let the constructor judge
        return
    params = list(sig.parameters.values())
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return
    accepted = [p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    n_positional = 4 if kind == BIRTH else 1  # (cfg, sensor, scene, rng) or (setup)
    accepted = accepted[n_positional:] if len(accepted) >= n_positional else []
    for key in options:
        require(
            key in accepted,
            f"[plugins.{name}] sets {key!r}, which the {kind} {name!r} does not accept; "
            f"its options: {', '.join(accepted) or 'none'}",
        )


def preflight(config: Any) -> None:
    """Before the first trial: every plugin of ``config`` imports and its ``[plugins.<name>]`` table fits it.

    An import error or an unknown option is a user error (one line, exit 2) caught here, in the driver, so no
    trial runs with a plugin that cannot even be built; errors while a plugin runs are recorded per run instead
    (:mod:`soabench.experiment.trial.guard`).
    """
    exp = config.experiment
    for kind, names_ in ((BIRTH, exp.models), (TRACKER, exp.trackers)):
        for name in names_:
            options = config.plugins.get(name, {})
            if kind == BIRTH and is_builtin_birth(name):
                require(not options, f"[plugins.{name}]: {name} is a built-in birth model; set it in [birth]")
                continue
            check_options(kind, name, resolve(kind, name), options)
