"""Reading a TOML file a user gives (configuration, scenario, check suite): every way it can be unreadable is one
:class:`~soabench.errors.SoabenchError` line naming the file (docs/development.md, habits: errors a user can cause).

Not UTF-8, not TOML, or nested so deeply that the parser runs out of stack (``a = [[[[...]]]]``): each is refused
with what is wrong, never a traceback.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from soabench.errors import SoabenchError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 only
    import tomli as tomllib


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """The tables of the TOML file ``path``; ``what`` names it in messages ("config file", "suite file", ...)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise SoabenchError(f"{what} {str(p)!r} is not UTF-8 text (byte {exc.start}); save it as UTF-8") from None
    except OSError as exc:
        raise SoabenchError(f"cannot read the {what} {str(p)!r}: {exc.strerror or exc}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SoabenchError(f"{what} {str(p)!r} is not valid TOML: {exc}") from None
    except RecursionError:
        raise SoabenchError(
            f"{what} {str(p)!r} nests arrays or tables too deeply for the TOML reader; give sections of key = value"
        ) from None
