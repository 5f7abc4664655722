"""What a result depends on besides its seed, and how closely a re-run must reproduce it.

A run's numbers come out of numpy, scipy, shapely, SUMO and the numba-compiled filter kernels (numba + its LLVM,
llvmlite) on some CPU. ``run.json`` and ``summary.json`` record all of them (:func:`platform_info`), and the
tolerance a re-run is held to (:data:`REPRODUCTION_TOLERANCE`), so a difference can be traced to a version or a
machine instead of being guessed at.
"""

from __future__ import annotations

import math
import os
import platform
from importlib import metadata
from typing import Any

#: How closely re-running a committed trial must reproduce each number of ``trials.csv``: ``|new - old| <=
#: abs + rel * |old|`` (NaN only matches NaN; integers and text must be equal). On one machine and one set of
#: versions a re-run is bit-identical (same seed); across CPUs and libm/LLVM builds the last digits of
#: transcendental functions may differ and the filter carries such differences through a trial. 1e-6 relative is
#: a thousand times finer than any number the summaries print (three decimals), so a difference beyond it is a
#: change of results, not of rounding: results/ is then stale against the code and must be regenerated.
REPRODUCTION_TOLERANCE: dict[str, float] = {"rel": 1e-6, "abs": 1e-9}

#: the command that regenerates the committed results (results/README.md)
REGENERATE_COMMAND = "soabench results --out results"


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo`` on Linux, ``platform.processor()`` elsewhere)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def platform_info() -> dict[str, Any]:
    """The machine a run was driven from: CPU model, architecture, OS, core count."""
    return {
        "cpu": cpu_model(),
        "machine": platform.machine(),
        "system": f"{platform.system()} {platform.release()}",
        "cpu_count": os.cpu_count(),
    }


def within_tolerance(new: Any, old: Any, tol: dict[str, float] = REPRODUCTION_TOLERANCE) -> bool:
    """True when ``new`` reproduces ``old`` (numbers or their CSV text) within ``tol`` (see the constant)."""
    a, b = _number(new), _number(old)
    if a is None or b is None:
        return str(new) == str(old)
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    if math.isinf(a) or math.isinf(b):
        return a == b
    return abs(a - b) <= tol["abs"] + tol["rel"] * abs(b)


def _number(v: Any) -> float | None:
    if isinstance(v, bool):
        return float(v)
    if isinstance(v, (int, float)):
        return float(v)
    try:
        return float(str(v))
    except ValueError:
        return None


def package_versions() -> dict[str, str]:
    """Versions of the packages that shape the results (summary.json)."""
    out = {"python": platform.python_version()}
    for label, dist in (
        ("numpy", "numpy"),
        ("scipy", "scipy"),
        ("shapely", "shapely"),
        ("numba", "numba"),
        ("llvmlite", "llvmlite"),
        ("sumo", "eclipse-sumo"),
        ("libsumo", "libsumo"),
        ("soabench", "soabench"),
    ):
        try:
            out[label] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[label] = "not installed"
    return out
