"""What the command line asked for: the options written on it (not filled from defaults), the config keys they
and ``--config`` set, paths that must not be empty, and how an error names a value (by its flag). Every check
raises :class:`~soabench.errors.SoabenchError` (one line, exit status 2)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

from soabench.errors import BadValue, SoabenchError, require


def explicit_dests(parser: argparse.ArgumentParser, argv: Sequence[str]) -> set[str]:
    """Destinations of the options written on the command line (not filled from defaults).

    Follows argparse's matching: ``--opt``, ``--opt=value`` and unambiguous prefixes such as ``--tri`` for
    ``--trials``, within the chosen subcommand.
    """
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    command = next((t for t in argv if t in sub.choices), None)
    if command is None:
        return set()
    options: dict[str, str] = {}
    for action in sub.choices[command]._actions:
        for opt in action.option_strings:
            options[opt] = action.dest
    out: set[str] = set()
    for token in argv:
        if not token.startswith("--") or token == "--":
            continue
        name = token.split("=", 1)[0]
        if name in options:
            out.add(options[name])
            continue
        matches = {options[o] for o in options if o.startswith(name)}
        if len(matches) == 1:
            out |= matches
    return out


def command_options(parser: argparse.ArgumentParser, argv: Sequence[str]) -> set[str]:
    """The option strings (``--net``, ...) of the subcommand ``argv`` chooses, nested ones included (``sweep
    clutter``): the flags an error message may name."""
    options: set[str] = set()
    chosen = parser
    while True:
        sub = next((a for a in chosen._actions if isinstance(a, argparse._SubParsersAction)), None)
        command = None if sub is None else next((t for t in argv if t in sub.choices), None)
        if command is None:
            break
        chosen = sub.choices[command]
    for action in chosen._actions:
        options.update(o for o in action.option_strings if o.startswith("--"))
    return options


def error_message(exc: SoabenchError, options: set[str]) -> str:
    """The one line the command line prints for ``exc``: a :class:`~soabench.errors.BadValue` names its value as
    the flag that gave it (``--net 'intersectoin' ...``) when the command has that flag, else as Python does."""
    if isinstance(exc, BadValue):
        flag = "--" + exc.name.replace("_", "-")
        if flag in options:
            return exc.as_flag(flag)
    return str(exc)


#: options naming a file or folder: an empty value is refused (``Path("")`` would be the working folder)
PATH_OPTIONS = frozenset(
    ("--out", "--scans", "--resume", "--main", "--root", "--detections", "--semantics", "--config", "--scenario",
     "--poly", "--net", "--suite")
)  # fmt: skip


def check_no_empty_paths(argv: Sequence[str]) -> None:
    """Refuse ``--out ''`` (and ``--out=``) for every option of :data:`PATH_OPTIONS`."""
    for i, token in enumerate(argv):
        name, eq, value = token.partition("=")
        if name in PATH_OPTIONS:
            empty = value == "" if eq else (i + 1 < len(argv) and argv[i + 1] == "")
            require(not empty, f"{name} '' is empty; give a path")


#: command-line dest -> dotted config key, for the options that override the configuration
FLAG_KEYS = {
    "trials": "experiment.trials",
    "duration": "experiment.duration",
    "models": "experiment.models",
    "trackers": "experiment.trackers",
    "probabilities": "experiment.probabilities",
    "filters": "experiment.filters",
    "clutter": "experiment.clutter",
    "seed": "experiment.seed",
}


def config_file_keys(path: str | None) -> set[str]:
    """Dotted keys a (valid, already loaded) TOML config file sets."""
    if path is None:
        return set()
    from soabench.tomlfile import read_toml

    data = read_toml(path, "config file")
    return {f"{sec}.{k}" for sec, values in data.items() if isinstance(values, dict) for k in values}


def requested_keys(args: argparse.Namespace, explicit: set[str]) -> set[str]:
    """Dotted config keys the user asked for: flags given and keys of ``--config``."""
    keys = {key for dest, key in FLAG_KEYS.items() if dest in explicit and getattr(args, dest, None) is not None}
    return keys | config_file_keys(getattr(args, "config", None))


def requested_values(cfg: Any, keys: set[str], args: argparse.Namespace, explicit: set[str]) -> dict[str, Any]:
    """``{dotted key: value}`` of ``keys`` in the validated ``cfg``, plus ``net``/``polys``/``scenario`` if given."""
    from soabench.experiment.runs.runmeta import flatten_config

    flat = flatten_config(cfg.to_dict())
    out = {k: flat[k] for k in keys if k in flat}
    if "net" in explicit:
        out["net"] = args.net
    if "poly" in explicit:
        out["polys"] = [str(p) for p in args.poly]
    if "scenario" in explicit:
        out["scenario"] = args.scenario
    return out
