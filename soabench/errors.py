"""One exception type for every error a user can cause (bad path, bad value, bad network).

The CLI prints its message on one line without a traceback and exits with status 2 (docs/development.md, habits).
"""

from __future__ import annotations


class SoabenchError(ValueError):
    """A user-facing error: the message names the bad value and what is allowed."""


def require(condition: bool, message: str) -> None:
    """Raise :class:`SoabenchError` with ``message`` unless ``condition`` holds."""
    if not condition:
        raise SoabenchError(message)


class BadValue(SoabenchError):
    """A bad value of one named input. ``name`` is what Python calls it (the argument of :mod:`soabench.api`, e.g.
    ``net``), and the message reads ``net='intersectoin' is neither ...``; a front end that names its inputs
    otherwise formats the same parts its own way (the command line: ``--net 'intersectoin' is neither ...``,
    :meth:`as_flag`), so one message serves both."""

    def __init__(self, name: str, value: object, problem: str) -> None:
        self.name, self.value, self.problem = name, value, problem
        super().__init__(f"{name}={value!r} {problem}")

    def __reduce__(self) -> tuple:  # rebuilt from its parts when it crosses a process boundary
        return (type(self), (self.name, self.value, self.problem))

    def as_flag(self, flag: str) -> str:
        """The message naming the value as the command-line option ``flag`` (e.g. ``--net``) gives it."""
        return f"{flag} {self.value!r} {self.problem}"


def require_value(condition: bool, name: str, value: object, problem: str) -> None:
    """Raise :class:`BadValue` (``name=value problem``) unless ``condition`` holds."""
    if not condition:
        raise BadValue(name, value, problem)


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a run: the message says what is on disk and how to finish (printed as one line by the CLI)."""


class WrongTypeError(SoabenchError, TypeError):
    """A user-facing error about an object of the wrong kind (also a ``TypeError``): one line naming what was given
    and what is required."""


def require_type(value: object, cls: type | tuple[type, ...], what: str, hint: str = "") -> None:
    """Raise :class:`WrongTypeError` unless ``value`` is an instance of ``cls``; ``hint`` says how to get one."""
    if isinstance(value, cls):
        return
    names = " or ".join(c.__name__ for c in (cls if isinstance(cls, tuple) else (cls,)))
    got = type(value).__name__
    shown = repr(value) if isinstance(value, (int, float, str)) and len(repr(value)) < 40 else f"a {got}"
    raise WrongTypeError(f"{what} must be a {names}, got {shown}" + (f"; {hint}" if hint else ""))
