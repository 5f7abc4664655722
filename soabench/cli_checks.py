"""Command-line checks that need no simulation: which options were given, a scheduler address, an output file.

Kept out of :mod:`soabench.cli` so that the parser module stays a thin table of subcommands. Every check raises
:class:`~soabench.errors.SoabenchError` (one line, exit status 2).
"""

from __future__ import annotations

import argparse
import ipaddress
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from soabench.errors import SoabenchError, require

#: ``[scheme://]host:port``; the schemes Dask's communication layer speaks over a network
SCHEDULER_ADDRESS = re.compile(
    r"^(?:(?P<scheme>tcp|tls|ws|wss|ucx)://)?(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9.-]{0,252})):(?P<port>\d{1,5})$"
)
MAX_SNAPSHOT_TIME = 86400.0  #: --time / --duration of scene, record and birth (s), as experiment.duration


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


def _is_host(host: str) -> bool:
    """A host name (with a letter), a dotted-quad IPv4 or a bracketed IPv6 address: a bare number such as ``3``
    (which the resolver would read as 0.0.0.3) is not."""
    literal = host.strip("[]")
    if host.startswith("[") or not any(c.isalpha() for c in literal):
        try:
            ipaddress.ip_address(literal)
        except ValueError:
            return False
    return True


def check_scheduler_address(address: str | None) -> None:
    """Refuse a malformed ``--scheduler`` at once (instead of a connection timeout later)."""
    if address is None:
        return
    m = SCHEDULER_ADDRESS.match(address.strip())
    ok = m is not None and 1 <= int(m.group("port")) <= 65535 and _is_host(m.group("host"))
    require(ok, f"--scheduler {address!r} is not a scheduler address; expected tcp://HOST:PORT (port 1-65535)")


def check_time(flag: str, value: float | None) -> None:
    """A finite, positive time of at most one day (s)."""
    if value is None:
        return
    require(
        math.isfinite(value) and 0 < value <= MAX_SNAPSHOT_TIME,
        f"{flag} {value!r} is out of range; allowed: (0, {MAX_SNAPSHOT_TIME:g}] seconds",
    )


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


def check_out_file(path: str, suffix: str | None = None, flag: str = "--out") -> Path:
    """An output file path: resolved, not a folder, in an existing writable folder, ending in ``suffix`` (the
    format it is written in) when given."""
    require(bool(path), f"{flag} needs a file name")
    try:
        out = Path(path).expanduser().resolve()
    except (OSError, RuntimeError) as exc:
        raise SoabenchError(f"cannot resolve {flag} {path!r}: {exc}") from None
    require(not out.is_dir(), f"{flag} {path!r} is a folder; give a file name")
    require(
        suffix is None or out.suffix.lower() == suffix,
        f"{flag} {path!r} must end in {suffix}: the file is written in that format",
    )
    parent = out.parent
    if not parent.exists():
        anc = parent
        while not anc.exists():
            anc = anc.parent
        require(anc.is_dir(), f"{flag} {path!r} lies under {str(anc)!r}, which is a file, not a folder")
        raise SoabenchError(f"output folder {str(parent)!r} does not exist for {path!r}")
    require(parent.is_dir(), f"{flag} {path!r} lies under {str(parent)!r}, which is a file, not a folder")
    from soabench.experiment.ownership import probe_writable

    probe_writable(parent, f"{flag} {path!r}: the folder {str(parent)!r}")
    return out


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
    from soabench.experiment.runmeta import flatten_config

    flat = flatten_config(cfg.to_dict())
    out = {k: flat[k] for k in keys if k in flat}
    if "net" in explicit:
        out["net"] = args.net
    if "poly" in explicit:
        out["polys"] = [str(p) for p in args.poly]
    if "scenario" in explicit:
        out["scenario"] = args.scenario
    return out
