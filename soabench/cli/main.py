"""The ``soabench`` parser and entry point: one subcommand per module of :mod:`soabench.cli`, every error a user can
cause as one line with exit status 2, and ``--net all`` (a command on every shipped scene)."""

from __future__ import annotations

import argparse
import copy
import logging
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from soabench import __version__
from soabench.cli import (
    atlas,
    birth,
    check,
    checks,
    export,
    import_osm,
    kitti,
    query,
    record,
    replay,
    report,
    results,
    run,
    scene,
    scenes,
    sensitivity,
    study,
    sweep,
)
from soabench.cli.parsing import EXIT_USAGE, DefaultsHelpFormatter, OneLineParser
from soabench.errors import Interrupted, SoabenchError, require
from soabench.scenario import shipped_nets

#: command name -> its module (``add_parser``, ``handle``), in the order ``soabench --help`` lists them
MODULES = {
    "scene": scene,
    "record": record,
    "birth": birth,
    "run": run,
    "sweep": sweep,
    "study": study,
    "sensitivity": sensitivity,
    "results": results,
    "atlas": atlas,
    "query": query,
    "kitti": kitti,
    "export": export,
    "check": check,
    "replay": replay,
    "report": report,
    "scenes": scenes,
    "import": import_osm,
}
#: command name -> handler
COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {name: module.handle for name, module in MODULES.items()}
SNAPSHOT_COMMANDS = ("scene", "record", "birth")  #: commands whose --out is a file (the others': a folder)


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="soabench",
        formatter_class=DefaultsHelpFormatter,
        description="Where should a multi-target filter expect new targets to appear? "
        "GM-PHD birth models (S-OA and four baselines) on SUMO scenarios.",
    )
    parser.add_argument("--version", action="version", version=f"soabench {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in MODULES.values():
        module.add_parser(sub)
    for command in sub.choices.values():  # subparsers do not inherit the formatter
        command.formatter_class = DefaultsHelpFormatter
    return parser


def _join_negative_values(argv: Sequence[str]) -> list[str]:
    """``--offsets -10:10`` -> ``--offsets=-10:10``: argparse would read a value starting with '-' as an option."""
    out: list[str] = []
    it = iter(argv)
    for token in it:
        if token in ("--offsets", "--values", "--clutter", "--nhat-sweep"):
            value = next(it, None)
            if (
                value is not None
                and value.startswith("-")
                and len(value) > 1
                and (value[1].isdigit() or value[1] == ".")
            ):
                out.append(f"{token}={value}")
                continue
            out.append(token)
            if value is not None:
                out.append(value)
            continue
        out.append(token)
    return out


def run_on_all(
    args: argparse.Namespace, command: Callable[[argparse.Namespace], int], command_name: str, options: set[str]
) -> int:
    """Run ``command(args)`` once per shipped scene (``--net all``); outputs go per scene; report per scene."""

    require(getattr(args, "resume", None) is None, "--net all cannot --resume; resume each scene's folder")
    status: list[tuple[str, str]] = []
    rc_all = 0
    for name in shipped_nets():
        a = copy.copy(args)
        a.net = name
        out = getattr(args, "out", None)
        if out is not None:
            p = Path(out)
            a.out = str(p.with_name(f"{p.stem}_{name}{p.suffix}")) if command_name in SNAPSHOT_COMMANDS else p / name
        print(f"== {name} ==", flush=True)
        try:
            rc = command(a)
            status.append((name, "ok" if rc == 0 else f"exit {rc}"))
        except SoabenchError as exc:
            rc = 2
            status.append((name, f"error: {checks.error_message(exc, options)}"))
        rc_all = max(rc_all, rc)
    print("\n".join(["", "| scene | result |", "|---|---|"] + [f"| {n} | {s} |" for n, s in status]))
    return rc_all


class _CurrentStderr(logging.StreamHandler):
    """A log handler writing to ``sys.stderr`` as it is when a record comes (a caller, or a test, may swap it)."""

    def emit(self, record) -> None:
        self.stream = sys.stderr
        super().emit(record)


def _say_derived() -> None:
    """Print the scene loader's info line (what it derived from a network) to stderr, once."""
    log = logging.getLogger("soabench")
    if not any(getattr(h, "_soabench", False) for h in log.handlers):
        h = _CurrentStderr()
        h.setFormatter(logging.Formatter("soabench: %(message)s"))
        h._soabench = True  # type: ignore[attr-defined]
        log.addHandler(h)
        log.setLevel(logging.INFO)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``soabench`` console script."""
    parser = build_parser()
    argv = _join_negative_values(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    args.explicit = checks.explicit_dests(parser, argv)
    _say_derived()
    options = checks.command_options(parser, argv)
    try:
        checks.check_no_empty_paths(argv)
        if getattr(args, "net", None) == "all":
            return run_on_all(args, COMMANDS[args.command], args.command, options)
        return COMMANDS[args.command](args)
    except BrokenPipeError:  # e.g. `soabench run | head`: the reader left; say nothing more
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except SoabenchError as exc:
        print(f"soabench: error: {checks.error_message(exc, options)}", file=sys.stderr)
        return EXIT_USAGE
    except Interrupted as exc:  # the message says what is on disk and how to finish
        print(f"soabench: {exc}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print("soabench: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:  # a file system refusal the checks could not foresee (disk full, a race): one line
        where = f" {exc.filename!r}" if getattr(exc, "filename", None) else ""
        print(f"soabench: error: cannot read or write{where}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
