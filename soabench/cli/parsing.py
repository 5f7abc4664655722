"""The ``soabench`` parser's shared parts: one-line usage errors, help that shows defaults, value types (comma
lists, offsets) and the option groups several commands take (docs/user-guide/commands.md)."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from pathlib import Path

from soabench.config import FAMILIES, PROBABILITY_MODES
from soabench.errors import SoabenchError, require

EXIT_USAGE = 2  #: exit status of every error a user can cause

MAX_OFFSETS = 1001  #: values of one --offsets / --nhat-sweep (e.g. -500:500)
MAX_OFFSET = 10_000  #: largest |offset| (N_hat itself is at most 10000: soabench/config.py)


#: the help of ``--filters``, from the registry of filter families (soabench.config.FAMILIES)
FILTERS_HELP = (
    "filter families every birth model runs in, e.g. gmphd,lmb: "
    + ", ".join(f"{name} ({f.label})" for name, f in FAMILIES.items())
    + " (default gmphd); a family runs the probability modes it defines ("
    + "; ".join(f"{name}: {', '.join(f.modes)}" for name, f in FAMILIES.items())
    + ")"
)


def csv_list(kind: str, allowed: Sequence[str] | None = None) -> Callable[[str], tuple[str, ...]]:
    """An argparse type: a comma-separated list of names (of ``allowed`` when given)."""

    def parse(text: str) -> tuple[str, ...]:
        items = tuple(s.strip() for s in text.split(",") if s.strip())
        if not items:
            raise argparse.ArgumentTypeError(f"{kind} list {text!r} is empty")
        if allowed is not None:
            bad = [s for s in items if s not in allowed]
            if bad:
                raise argparse.ArgumentTypeError(f"{kind} {bad[0]!r} is unknown; choose from {', '.join(allowed)}")
        return items

    return parse


def float_list(text: str) -> tuple[float, ...]:
    """An argparse type: a comma-separated list of numbers."""
    try:
        values = tuple(float(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of numbers") from None
    if not values:
        raise argparse.ArgumentTypeError(f"{text!r} gives no numbers")
    return values


def offsets(text: str) -> tuple[int, ...]:
    """``-10:10`` (inclusive range), ``-10:10:2`` (with step) or ``-5,0,5``; at most :data:`MAX_OFFSETS` values,
    each in [-MAX_OFFSET, MAX_OFFSET] (checked before a range is expanded)."""
    try:
        if ":" in text:
            parts = [int(p) for p in text.split(":")]
            require(len(parts) in (2, 3), "")
            lo, hi = parts[0], parts[1]
            step = parts[2] if len(parts) == 3 else 1
            require(step > 0 and hi >= lo, "")
            values: Sequence[int] = range(lo, hi + 1, step)
        else:
            values = [int(s) for s in text.split(",") if s.strip()]
    except (ValueError, SoabenchError):
        raise argparse.ArgumentTypeError(
            f"offsets {text!r} must be LO:HI, LO:HI:STEP (integers, HI >= LO, STEP > 0) or a comma list of integers"
        ) from None
    if not values:
        raise argparse.ArgumentTypeError(f"offsets {text!r} give no value")
    low, high = (values[0], values[-1]) if isinstance(values, range) else (min(values), max(values))
    if len(values) > MAX_OFFSETS or max(-low, high) > MAX_OFFSET:
        raise argparse.ArgumentTypeError(
            f"offsets {text!r} give {len(values)} values from {low} to {high}; allowed: at most "
            f"{MAX_OFFSETS} values, each in [-{MAX_OFFSET}, {MAX_OFFSET}]"
        )
    return tuple(values)


def add_net_args(p: argparse.ArgumentParser) -> None:
    """``--net``, ``--poly``, ``--scenario``, ``--config``: which scene, with which parameters."""
    p.add_argument(
        "--net",
        default="intersection",
        help="shipped scene name, 'all' (every shipped scene), a scene folder or a path to a .net.xml",
    )
    p.add_argument(
        "--poly",
        action="append",
        default=[],
        metavar="FILE",
        help="polygon file (buildings, obstacles); repeatable (default: only the scenario's own)",
    )
    p.add_argument(
        "--scenario",
        metavar="FILE.toml",
        help="scenario file (default: the shipped net's own; for a user net, defaults derived from the net)",
    )
    p.add_argument(
        "--config",
        metavar="FILE.toml",
        help="parameters, section by section (docs/method.md §7; default: the built-in defaults, soabench/config.py)",
    )


def add_snapshot_args(p: argparse.ArgumentParser, need_out: bool = True) -> None:
    """The options of the one-scene commands (scene, record, birth): the scene, one trial's seeds, the file."""
    add_net_args(p)
    p.add_argument("--seed", type=int, default=0, help="base seed (as in `run`)")
    p.add_argument("--trial", type=int, default=0, help="trial index under the base seed (as in `run`)")
    p.add_argument("--out", required=need_out, help="output file")


def add_filters_arg(p: argparse.ArgumentParser) -> None:
    """``--filters``: the filter families every birth model runs in, read from the registry (run, sweep, study)."""
    p.add_argument("--filters", type=csv_list("filter family", tuple(FAMILIES)), help=FILTERS_HELP)


def add_run_args(p: argparse.ArgumentParser) -> None:
    """The options of the protocol commands (run, sweep, study): the protocol's size, methods and executor."""
    add_net_args(p)
    p.add_argument("--trials", type=int, help="Monte Carlo trials (default 100)")
    p.add_argument("--duration", type=float, help="seconds per trial (default 100)")
    p.add_argument(
        "--models",
        type=csv_list("model"),
        help="birth models: soa,pubm,ubm,ubm-ws,atbm,gmbm (default: all six), installed plugins, or module:Class",
    )
    p.add_argument(
        "--trackers",
        type=csv_list("tracker"),
        help="whole trackers beside them: stonesoup-gmphd, stonesoup-gnn, installed plugins, or module:Class "
        "(default: none)",
    )
    p.add_argument(
        "--probabilities",
        type=csv_list("probability mode", PROBABILITY_MODES),
        help="static,dynamic (default), dynamic+occ or static+occ (static p_D with the line of sight); the "
        "families other than gmphd run static and static+occ only",
    )
    p.add_argument("--seed", type=int, help="base seed (default 0)")
    p.add_argument("--workers", type=int, help="process workers (default: every core)")
    p.add_argument("--out", type=Path, help="run folder (default results/<scenario name>/<timestamp>/)")
    p.add_argument("--save-estimates", action="store_true", help="also write the per-scan estimates")
    p.add_argument(
        "--scheduler", metavar="tcp://HOST:PORT", help="submit trials to this Dask scheduler (default: no Dask)"
    )
    p.add_argument(
        "--dask", choices=["local"], help="start a Dask LocalCluster (processes, one thread each; default: no Dask)"
    )
    p.add_argument("--fail-fast", action="store_true", help="stop at the first failed trial")
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress report (default: a bar on a terminal, a line every 10 s or 5%% of the trials otherwise)",
    )


class OneLineParser(argparse.ArgumentParser):
    """A usage error is one line, like every other error: ``soabench: error: <command>: <what> (see ... --help)``."""

    def error(self, message: str):  # type: ignore[override]
        where = self.prog.removeprefix("soabench").strip()
        self.exit(EXIT_USAGE, f"soabench: error: {where + ': ' if where else ''}{message} (see {self.prog} --help)\n")


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """``--help`` shows every option's default: appended as "(default: X)" unless the help text already says it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        unset = any(action.default is v for v in (None, False, argparse.SUPPRESS))  # flags, optional values
        if "default" in text or not action.option_strings or unset:
            return text
        value = ", ".join(map(str, action.default)) if isinstance(action.default, list) else "%(default)s"
        return f"{text} (default: {value or 'none'})"
