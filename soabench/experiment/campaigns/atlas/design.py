"""The design of an atlas: its axes, their values and the points they span (docs/method.md §5.10).

An axis is a parameter key of the parameters page (``sensor.p_D``, ``birth.N_hat``, ``filter.*``, ...), the
clutter rate ``experiment.clutter``, a scenario key (``parking.density``, ``pedestrians.count``,
``vehicles.count``, ...), ``net`` (the scene itself), ``filters`` (the filter family) or ``birth.N_hat_offset``
(N_tot = max(1, pedestrians + offset) expected births over the run, N_hat = N_tot / K as in the N_hat sweep).

* **scene axes** (``net`` and the scenario keys) change the SUMO run: each combination of their values is one
  *scene variant* with its own scenario file;
* every other axis changes only the sensor, the birth model or the filter: all points of one scene variant read the
  same SUMO run of trial n (and the same scans where the sensor settings agree).

Designs: the full factorial of listed values (default), or ``sobol`` / ``lhs`` over ranges ``LO:HI`` with
``scipy.stats.qmc`` (scrambled, seeded by the atlas seed), where a listed axis is sampled as a choice among its values.
Every value is checked against the parameter's range before anything is written (one line naming it).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from soabench.config import FAMILIES, Config
from soabench.errors import SoabenchError, require

#: scenario keys an axis may vary (section.key of the scenario file) and their value types
SCENE_KEYS: dict[str, type] = {
    "parking.density": float,
    "pedestrians.count": int,
    "pedestrians.p_enter": float,
    "pedestrians.model": str,
    "vehicles.count": int,
    "vehicles.max_speed": float,
}
#: axes that are neither config nor scenario keys
SPECIAL_KEYS = ("net", "filters", "birth.N_hat_offset")
#: config sections whose scalar keys may be axes (and each filter family's own section)
CONFIG_SECTIONS = ("sensor", "filter", "birth", "metrics", *(f.section for f in FAMILIES.values() if f.section))
#: ``experiment`` keys fixed for the whole atlas (trials, duration and seed: the protocol; models and modes run at
#: every point)
FIXED_EXPERIMENT = ("trials", "duration", "seed", "models", "trackers", "probabilities", "plugin_budget")
DESIGNS = ("factorial", "sobol", "lhs")
MAX_POINTS = 100_000  #: points of one design at most
MAX_VALUES = 1000  #: values of one axis at most
MAX_AXES = 12


def config_axis_types() -> dict[str, type]:
    """Every config key an axis may vary, with the type of its values (from the defaults of :class:`Config`)."""
    cfg = Config()
    out: dict[str, type] = {"experiment.clutter": float}
    for sec in CONFIG_SECTIONS:
        obj = getattr(cfg, sec)
        for f in dataclasses.fields(obj):
            v = getattr(obj, f.name)
            if isinstance(v, (bool, int, float, str)):
                out[f"{sec}.{f.name}"] = type(v)
    return out


def axis_type(key: str) -> type:
    """The value type of axis ``key``; an unknown key is refused with one line naming the allowed ones."""
    if key == "net" or key == "filters":
        return str
    if key == "birth.N_hat_offset":
        return int
    if key in SCENE_KEYS:
        return SCENE_KEYS[key]
    types = config_axis_types()
    if key in types:
        return types[key]
    if key.startswith("experiment."):
        raise SoabenchError(
            f"axis {key!r} is not an axis: {key} is fixed for the whole atlas (give it as an option); "
            "experiment.clutter is the experiment key an axis may vary"
        )
    raise SoabenchError(
        f"axis {key!r} is unknown; allowed: a key of the parameters page (docs/user-guide/parameters.md) such as "
        f"sensor.p_D or birth.N_hat, experiment.clutter, a scenario key ({', '.join(SCENE_KEYS)}), "
        f"{', '.join(SPECIAL_KEYS)}"
    )


def is_scene_axis(key: str) -> bool:
    """True for the axes that change the SUMO run (module docstring)."""
    return key == "net" or key in SCENE_KEYS


def parse_value(key: str, text: Any) -> Any:
    """One value of axis ``key`` (text from the command line, or a TOML value) in the axis's type."""
    kind = axis_type(key)
    if kind is bool:
        if isinstance(text, bool):
            return text
        low = str(text).strip().lower()
        require(low in ("true", "false"), f"axis {key}: value {text!r} must be true or false")
        return low == "true"
    if kind is int:
        try:
            v = float(text) if not isinstance(text, bool) else math.nan
        except (TypeError, ValueError):
            v = math.nan
        require(math.isfinite(v) and v == int(v), f"axis {key}: value {text!r} is not allowed; allowed: integers")
        return int(v)
    if kind is float:
        try:
            v = float(text) if not isinstance(text, bool) else math.nan
        except (TypeError, ValueError):
            v = math.nan
        require(math.isfinite(v), f"axis {key}: value {text!r} is not allowed; allowed: finite numbers")
        return v
    require(isinstance(text, str) and text.strip() != "", f"axis {key}: value {text!r} must be a name")
    return text.strip()


@dataclass(frozen=True)
class Axis:
    """One axis: listed ``values`` (factorial, or a choice in a sampled design) or a range ``(low, high)``."""

    key: str
    values: tuple[Any, ...] = ()
    low: float | None = None
    high: float | None = None

    @property
    def is_range(self) -> bool:
        return self.low is not None

    @property
    def column(self) -> str:
        """The axis's column name in the atlas tables (dots become underscores: plain SQL identifiers)."""
        return self.key.replace(".", "_")

    def to_dict(self) -> dict[str, Any]:
        if self.is_range:
            return {"key": self.key, "low": self.low, "high": self.high}
        return {"key": self.key, "values": list(self.values)}


def parse_axis(text: str) -> Axis:
    """``KEY=V1,V2,...`` (listed values) or ``KEY=LO:HI`` (a range, for sampled designs)."""
    key, eq, rest = str(text).partition("=")
    key = key.strip()
    require(bool(eq) and key != "", f"--axis {text!r} must be KEY=V1,V2,... or KEY=LO:HI")
    return make_axis(key, rest)


def make_axis(key: str, spec: Any) -> Axis:
    """An :class:`Axis` from a command-line text (``V1,V2`` or ``LO:HI``), a TOML list or a TOML table
    ``{low = LO, high = HI}``."""
    kind = axis_type(key)
    if isinstance(spec, Mapping):
        require(set(spec) == {"low", "high"}, f"axis {key}: a range is a table {{low = LO, high = HI}}")
        return _range_axis(key, kind, spec["low"], spec["high"])
    if isinstance(spec, str) and ":" in spec and kind in (int, float):
        lo, _, hi = spec.partition(":")
        return _range_axis(key, kind, lo, hi)
    items = spec if isinstance(spec, (list, tuple)) else [s for s in str(spec).split(",") if s.strip()]
    require(len(items) >= 1, f"axis {key} is empty; give at least one value (KEY=V1,V2,...)")
    require(len(items) <= MAX_VALUES, f"axis {key} has {len(items)} values; allowed: at most {MAX_VALUES}")
    values = tuple(parse_value(key, v) for v in items)
    seen: set = set()
    for v in values:
        require(v not in seen, f"axis {key} names {v!r} twice; give each value once")
        seen.add(v)
    return Axis(key, values)


def _range_axis(key: str, kind: type, lo: Any, hi: Any) -> Axis:
    require(kind in (int, float), f"axis {key}: a range LO:HI needs a numeric parameter; list its values instead")
    low, high = float(parse_value(key, lo)), float(parse_value(key, hi))
    require(low < high, f"axis {key}: range {lo}:{hi} must have LO < HI")
    return Axis(key, (), low, high)


@dataclass(frozen=True)
class Design:
    """The axes, how they are combined and the points they give (each a dict axis key -> value)."""

    axes: tuple[Axis, ...]
    kind: str = "factorial"
    n_points: int | None = None  #: sampled designs: how many points
    points: tuple[dict[str, Any], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "n_points": self.n_points,
            "axes": [a.to_dict() for a in self.axes],
        }


def make_design(axes: Sequence[Axis], kind: str = "factorial", n_points: int | None = None, seed: int = 0) -> Design:
    """The points of ``axes`` (module docstring): checked, in a fixed order (the first axis varies slowest)."""
    require(kind in DESIGNS, f"design {kind!r} is unknown; choose one of {', '.join(DESIGNS)}")
    require(len(axes) >= 1, "an atlas needs at least one axis (--axis KEY=V1,V2,... or --design FILE.toml)")
    require(len(axes) <= MAX_AXES, f"{len(axes)} axes; allowed: at most {MAX_AXES}")
    keys = [a.key for a in axes]
    for k in keys:
        require(keys.count(k) == 1, f"axis {k} is given twice; give each axis once")
    require(
        not ("birth.N_hat" in keys and "birth.N_hat_offset" in keys),
        "axes birth.N_hat and birth.N_hat_offset set the same parameter; give one of them",
    )
    if kind == "factorial":
        ranged = [a.key for a in axes if a.is_range]
        require(not ranged, f"axis {ranged[0] if ranged else ''}: a range LO:HI needs --sample sobol or lhs")
        require(n_points is None, "--points belongs to a sampled design (--sample sobol or lhs)")
        total = math.prod(len(a.values) for a in axes)
        require(total <= MAX_POINTS, f"the design has {total} points; allowed: at most {MAX_POINTS}")
        points = tuple(dict(zip(keys, combo, strict=True)) for combo in itertools.product(*(a.values for a in axes)))
        return Design(tuple(axes), kind, None, points)
    require(
        n_points is not None and 1 <= n_points <= MAX_POINTS,
        f"--points {n_points!r}: a {kind} design needs a number of points in [1, {MAX_POINTS}]",
    )
    # imported when called: scipy would slow every start-up
    from scipy.stats import qmc

    if kind == "sobol":
        m = int(round(math.log2(n_points)))
        require(2**m == n_points, f"--points {n_points}: a Sobol design needs a power of 2 (e.g. {2 ** max(m, 1)})")
        u = qmc.Sobol(d=len(axes), scramble=True, seed=seed).random_base2(m)
    else:
        u = qmc.LatinHypercube(d=len(axes), seed=seed).random(n_points)
    points = []
    for row in u:
        p = {}
        for a, x in zip(axes, row, strict=True):
            if a.is_range:
                v = a.low + float(x) * (a.high - a.low)
                p[a.key] = int(round(v)) if axis_type(a.key) is int else float(v)
            else:
                p[a.key] = a.values[min(int(x * len(a.values)), len(a.values) - 1)]
        points.append(p)
    return Design(tuple(axes), kind, n_points, tuple(points))


def design_from_dict(data: Any, source: str) -> tuple[list[Axis], dict[str, Any]]:
    """The axes and options of a design file (TOML: ``[axes]`` key = list or {low, high}; ``[design]`` kind,
    points). Options: ``kind``, ``points``."""
    require(isinstance(data, dict), f"{source}: a design file is a table")
    unknown = [k for k in data if k not in ("axes", "design")]
    require(not unknown, f"{source}: unknown section [{unknown[0] if unknown else ''}]; allowed: [axes], [design]")
    axes_t = data.get("axes")
    require(isinstance(axes_t, dict) and axes_t, f"{source}: [axes] must give at least one axis (KEY = [V1, V2])")
    axes = [make_axis(str(k), v) for k, v in axes_t.items()]
    opts = data.get("design", {})
    require(isinstance(opts, dict), f"{source}: [design] must be a table")
    bad = [k for k in opts if k not in ("kind", "points")]
    require(not bad, f"{source}: unknown key design.{bad[0] if bad else ''}; allowed: kind, points")
    return axes, dict(opts)


def filter_families_allowed() -> tuple[str, ...]:
    """The filter families a ``filters`` axis may name: the family registry's (:data:`soabench.config.FAMILIES`)."""
    return tuple(FAMILIES)
