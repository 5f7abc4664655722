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


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a run: the message says what is on disk and how to finish (printed as one line by the CLI)."""
