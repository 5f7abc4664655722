"""Every tunable parameter with its default (docs/method.md §1.2 and the decision register §7).

Defaults are the register's bold options. A TOML file may set any of them, section by section::

    [experiment]
    clutter = [5.0]
    [birth]
    sem_mode = "dbscan"

Unknown sections or keys and out-of-range values raise :class:`~soabench.errors.SoabenchError` naming the value
and what is allowed. Each parameter has one key and one home: the clutter rate λ is ``experiment.clutter`` (the
rates a run loops over; a command that observes one scene uses its single rate). The ``[sensor]`` section holds no
rate: the sensor that makes a run's scans is :class:`Sensor`, the section at one rate of ``experiment.clutter``
(:meth:`Config.sensor_at`); ``sensor.lambda_c`` in a file is refused with one line naming the key
(:data:`NOT_KEYS`). The scenario itself (network, vehicles, pedestrians) is configured by the network's
``scenario.toml`` (see :mod:`soabench.scenario`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from soabench import plugins
from soabench.errors import SoabenchError, require
from soabench.tomlfile import read_toml

BIRTH_MODEL_NAMES: tuple[str, ...] = tuple(plugins.BUILTIN_BIRTH_MODELS)  #: the built-in birth models
#: the probability modes (docs/method.md §4.6): static probabilities, the Beta-augmented dynamic ones, and each with
#: the line-of-sight p_D of §4.4 (``+occ``)
PROBABILITY_MODES = ("static", "dynamic", "dynamic+occ", "static+occ")


@dataclass(frozen=True)
class FilterFamily:
    """One filter family every birth model can run in (docs/development.md "Adding a filter family").

    Attributes:
        name: its name in ``--filters``, ``experiment.filters`` and the ``filter`` column of the tables.
        label: how tables and figures name it.
        modes: the probability modes it defines (docs/method.md §4.6); a run skips the others for it (their table
            cells read "—"), and a run none of whose modes it defines is refused.
        build: ``"module:function"`` of its builder, ``build(setup: FamilySetup) -> Filter``
            (:mod:`soabench.protocols`); imported when a run builds its first filter, never at start-up.
        section: its own config section (a dataclass field of :class:`Config`), or None when it reads ``[filter]``
            only. A key of the section set while no run names the family is refused.
        hatch: its bar hatch in ``families.png``.
    """

    name: str
    label: str
    modes: tuple[str, ...]
    build: str
    section: str | None = None
    hatch: str = ""


#: the filter families, in the order tables and figures list them; the first is the default of every run
FAMILIES: dict[str, FilterFamily] = {
    f.name: f
    for f in (
        FilterFamily("gmphd", "GM-PHD", PROBABILITY_MODES, "soabench.gmphd.family:build"),
        FilterFamily("lmb", "LMB", ("static", "static+occ"), "soabench.lmb.family:build", section="lmb", hatch="////"),
        FilterFamily(
            "pmbm", "PMBM", ("static", "static+occ"), "soabench.pmbm.family:build", section="pmbm", hatch="xx"
        ),
        FilterFamily(
            "pmb", "PMB", ("static", "static+occ"), "soabench.pmbm.family:build_pmb", section="pmbm", hatch="\\\\\\\\"
        ),
    )
}
#: the filter families' names (docs/method.md "LMB filter"); the first is the default
FILTER_FAMILIES = tuple(FAMILIES)
#: the probability modes each family runs; a family's other modes are skipped (their table cells read "—")
FAMILY_MODES = {name: f.modes for name, f in FAMILIES.items()}


def family_label(name: str) -> str:
    """How tables and figures name filter family ``name`` (the name itself for one not registered)."""
    return FAMILIES[name].label if name in FAMILIES else name


#: names a file may give that are not config keys, with the key that holds the value (one home per parameter)
NOT_KEYS = {"sensor.lambda_c": "experiment.clutter"}
#: the default clutter rate λ (mean clutter count per scan): the default of ``experiment.clutter``
CLUTTER_RATE = 3.0

MAX_TRIALS = 100_000  #: upper bound of experiment.trials (and --trials): 1000 times the paper's 100-trial protocol
MAX_SEED = 2**63 - 1  #: largest base seed
MAX_GAP_BINS = 12  #: most occlusion-gap length bins (metrics.gap_bins)
MAX_DURATION = 86400.0  #: longest simulated time (s): experiment.duration and a snapshot's --time / --duration


def _one_of(name: str, value: Any, allowed: tuple) -> None:
    require(value in allowed, f"{name} = {value!r} is not allowed; choose one of {', '.join(map(repr, allowed))}")


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _in_range(
    name: str, value: float, lo: float, hi: float = 1e6, lo_open: bool = False, hi_open: bool = False
) -> None:
    """``value`` is a finite number in the interval; the message says the expected type or the allowed interval."""
    require(_is_number(value), f"{name} = {value!r} must be a number, not {type(value).__name__}")
    ok = math.isfinite(value) and (value > lo if lo_open else value >= lo) and (value < hi if hi_open else value <= hi)
    lb = "(" if lo_open else "["
    rb = ")" if hi_open else "]"
    require(ok, f"{name} = {value!r} is out of range; allowed: {lb}{lo:g}, {hi:g}{rb}")


def _int_range(name: str, value: int, lo: int, hi: int) -> None:
    """``value`` is an integer (not a boolean) in [lo, hi]."""
    require(
        isinstance(value, int) and not isinstance(value, bool),
        f"{name} = {value!r} must be an integer, not {type(value).__name__}",
    )
    require(lo <= value <= hi, f"{name} = {value!r} is out of range; allowed: integers in [{lo}, {hi}]")


def _positive(name: str, value: float, hi: float = 1e6) -> None:
    _in_range(name, value, 0.0, hi, lo_open=True)


def _non_negative(name: str, value: float, hi: float = 1e6) -> None:
    _in_range(name, value, 0.0, hi)


def check_time(flag: str, value: float | None) -> None:
    """A finite, positive time of at most :data:`MAX_DURATION` seconds (None: not given)."""
    if value is None:
        return
    require(
        math.isfinite(value) and 0 < value <= MAX_DURATION,
        f"{flag} {value!r} is out of range; allowed: (0, {MAX_DURATION:g}] seconds",
    )


def require_distinct(name: str, values: tuple) -> None:
    """Each value once: a repeated clutter rate or mode would write every row twice and count its trials twice."""
    seen: set = set()
    for v in values:
        require(v not in seen, f"{name} = {list(values)!r} names {v!r} twice; give each value once")
        seen.add(v)


def _check_type(name: str, default: Any, value: Any) -> Any:
    """``value`` from a file, checked against the type of the field's ``default``; ints become floats for floats."""
    if default is None and value is None:  # an unset Optional field (JSON null in a run file)
        return None
    if isinstance(default, bool):
        require(isinstance(value, bool), f"{name} = {value!r} must be a boolean (true or false)")
    elif default is None or isinstance(default, int):  # Optional[int] fields default to None
        require(
            isinstance(value, int) and not isinstance(value, bool),
            f"{name} = {value!r} must be an integer, not {type(value).__name__}",
        )
    elif isinstance(default, float):
        require(_is_number(value), f"{name} = {value!r} must be a number, not {type(value).__name__}")
        return float(value)
    elif isinstance(default, str):
        require(isinstance(value, str), f"{name} = {value!r} must be a string, not {type(value).__name__}")
    elif isinstance(default, tuple):
        require(isinstance(value, (list, tuple)), f"{name} = {value!r} must be a list")
        item = default[0] if default else ""  # the one empty-default list (experiment.trackers) holds names
        return tuple(_check_type(f"{name}[]", item, v) for v in value)
    return value


@dataclass
class SensorConfig:
    """Synthetic range-bearing sensor (docs/method.md §2.3; register rows 3, 4, 7)."""

    dt: float = 1.0  #: sensor/filter period (s), a multiple of the SUMO step
    r_min: float = 0.5  #: minimum range (m)
    r_max: float = 50.0  #: maximum range (m)
    fov_deg: float = 360.0  #: angular sector Theta (deg), centred on the ego heading
    p_D: float = 0.98  #: detection probability of a visible target [P]
    sigma_r: float = 1.0  #: range noise std (m) [P]
    sigma_b_deg: float = 5.0  #: bearing noise std (deg) [P]
    clutter_space: str = "polar"  #: "polar" (uniform in (r, b)) or "cartesian" (uniform in area, kappa ~ r)
    visibility_points: int = 1  #: 1 (centre) or 3 (centre and +-offset across the line of sight)
    visibility_offset: float = 0.3  #: lateral offset (m) of the extra sight points

    @property
    def fov(self) -> float:
        """Theta in radians."""
        return math.radians(self.fov_deg)

    @property
    def sigma_b(self) -> float:
        """Bearing noise std in radians."""
        return math.radians(self.sigma_b_deg)

    def validate(self, sumo_step: float | None = None) -> None:
        _positive("sensor.dt", self.dt, hi=60.0)
        if sumo_step is not None:
            ratio = self.dt / sumo_step
            require(
                abs(ratio - round(ratio)) < 1e-9 and round(ratio) >= 1,
                f"sensor.dt = {self.dt!r} must be a positive multiple of the SUMO step {sumo_step!r} s",
            )
        _in_range("sensor.r_min", self.r_min, 0.0, 1e4, hi_open=True)
        _in_range("sensor.r_max", self.r_max, 0.0, 1e4, lo_open=True)
        require(
            self.r_max > self.r_min,
            f"sensor.r_max = {self.r_max!r} must exceed r_min = {self.r_min!r} (need 0 <= r_min < r_max)",
        )
        _in_range("sensor.fov_deg", self.fov_deg, 0.0, 360.0, lo_open=True)
        _in_range("sensor.p_D", self.p_D, 0.0, 1.0)
        _positive("sensor.sigma_r", self.sigma_r, hi=1e3)
        _positive("sensor.sigma_b_deg", self.sigma_b_deg, hi=180.0)
        _one_of("sensor.clutter_space", self.clutter_space, ("polar", "cartesian"))
        _one_of("sensor.visibility_points", self.visibility_points, (1, 3))
        _non_negative("sensor.visibility_offset", self.visibility_offset, hi=100.0)

    def at(self, lambda_c: float) -> Sensor:
        """The sensor of these settings at clutter rate ``lambda_c`` (a rate of ``experiment.clutter``)."""
        return Sensor(**{f.name: getattr(self, f.name) for f in dataclasses.fields(SensorConfig)}, lambda_c=lambda_c)


@dataclass
class Sensor(SensorConfig):
    """The sensor that makes a run's scans (docs/method.md §2.3): the ``[sensor]`` settings at one clutter rate λ.

    A run builds one per rate of ``experiment.clutter`` (:meth:`Config.sensor_at`); ``lambda_c`` is not a key of its
    own. The scans, the filter's clutter intensity kappa and a tracker plugin read λ from here.
    """

    lambda_c: float = field(default=CLUTTER_RATE, kw_only=True)  #: mean clutter count per scan (1/scan)

    def __post_init__(self) -> None:
        self.lambda_c = float(self.lambda_c) if _is_number(self.lambda_c) else self.lambda_c

    @property
    def settings(self) -> SensorConfig:
        """The ``[sensor]`` settings without the rate: what the line-of-sight geometry of the scans depends on."""
        return SensorConfig(**{f.name: getattr(self, f.name) for f in dataclasses.fields(SensorConfig)})

    def validate(self, sumo_step: float | None = None) -> None:
        super().validate(sumo_step)
        _non_negative("sensor.lambda_c", self.lambda_c, hi=1e4)


@dataclass
class FilterConfig:
    """GM-PHD filter (docs/method.md §2, §4; register rows 1, 4, 20, 21, 25)."""

    form: str = "ekf"  #: "ekf" or "ukf" (equal-weight cubature points, §2.7)
    sigma_a: float = 0.5  #: CV process noise (m/s^2); 0.5 for SUMO pedestrians (§1.2)
    p_S: float = 0.99  #: survival probability [P]
    p_D: float = 0.98  #: detection probability inside the FOV [P]
    prune_T: float = 1e-5  #: pruning threshold T [P]
    merge_U: float = 4.0  #: merging threshold U (squared Mahalanobis) [P]
    J_max: int = 1000  #: component cap
    gate: bool = True  #: chi-square gating of q (never of clutter)
    gate_prob: float = 0.999  #: gate probability (chi2_2(0.999) = 13.8155)
    extract_thr: float = 0.5  #: extraction threshold
    extraction: str = "vo_ma"  #: "vo_ma" (w > 0.5, floor(w + 0.5) copies) or "top_n" (ablation)
    occlusion_pd: bool = False  #: line-of-sight gate in p_D (§4.4); set by the "+occ" modes
    max_undetected_birth_age: int | None = None  #: prune n_det = 0 components older than this (§4.4)
    #: non-finite measurements, ego poses or birth components given to ``GMPHDFilter.step``: "raise" (default: they
    #: mean a broken input upstream) or "drop" (dropped and counted in ``StepResult.n_dropped``; for real sensor data)
    nonfinite: str = "raise"
    # dynamic probabilities (§4.2-4.5)
    beta_factor: float = 1.1  #: mean-preserving variance inflation f
    theta_min: float = 2.0  #: inflation guard
    n_D: float = 10.0  #: Beta p_D prior strength s + t
    mu_D0: float = 0.98  #: Beta p_D prior mean
    n_S: float = 20.0  #: Beta p_S prior strength
    mu_S0: float = 0.99  #: Beta p_S prior mean
    p_S_max: float = 0.999  #: cap of the Beta p_S mean

    def validate(self) -> None:
        _one_of("filter.form", self.form, ("ekf", "ukf"))
        _non_negative("filter.sigma_a", self.sigma_a, hi=100.0)
        _in_range("filter.p_S", self.p_S, 0.0, 1.0)
        _in_range("filter.p_D", self.p_D, 0.0, 1.0)
        _in_range("filter.prune_T", self.prune_T, 0.0, 1.0, hi_open=True)
        _positive("filter.merge_U", self.merge_U)
        _int_range("filter.J_max", self.J_max, 1, 1_000_000)
        _in_range("filter.gate_prob", self.gate_prob, 0.0, 1.0, lo_open=True, hi_open=True)
        _non_negative("filter.extract_thr", self.extract_thr)
        _one_of("filter.extraction", self.extraction, ("vo_ma", "top_n"))
        _one_of("filter.nonfinite", self.nonfinite, ("raise", "drop"))
        if self.max_undetected_birth_age is not None:
            _int_range("filter.max_undetected_birth_age", self.max_undetected_birth_age, 0, 10**9)
        _in_range("filter.beta_factor", self.beta_factor, 1.0, 1e3)
        _positive("filter.theta_min", self.theta_min)
        _positive("filter.n_D", self.n_D, hi=1e9)
        _in_range("filter.mu_D0", self.mu_D0, 0.0, 1.0, lo_open=True, hi_open=True)
        _positive("filter.n_S", self.n_S, hi=1e9)
        _in_range("filter.mu_S0", self.mu_S0, 0.0, 1.0, lo_open=True, hi_open=True)
        _in_range("filter.p_S_max", self.p_S_max, 0.0, 1.0, lo_open=True, hi_open=True)


@dataclass
class BirthConfig:
    """Birth models (docs/method.md §3; register rows 9-19, 24, 26)."""

    N_hat: float = 0.06  #: expected births per step [P]
    sigma_v_birth: float = 1.0  #: velocity prior std per axis (m/s), §3.0
    delta_in: float = 0.5  #: inset of birth means from the range limits (m), §3.0
    # S-OA occlusion terms (§3.1.1-3.1.3)
    delta_r: float = 2.0  #: layer spacing (m)
    L: int = 3  #: layers per tangent ray
    sigma_par: float = 2.0  #: std along the ray (m)
    sigma_perp: float = 0.75  #: std across the ray (m)
    ray_start: str = "tangent"  #: "tangent" (tangent-point range) or "centroid"
    occl_velocity_prior: bool = False  #: velocity mean 0.8 m/s out of the cone (not in the paper)
    occluders_from_detections: bool = False  #: only occluders whose footprint is itself visible
    # S-OA semantic terms (§3.1.4)
    sem_mode: str = "poisson"  #: "poisson", "hex", "dbscan" or "uniform"
    sem_resample: str = "trial"  #: "trial" (sample once, clip per step) or "step"
    sem_include_crossings: bool = False  #: add crossings (and walking areas) to Omega
    d_min: float = 5.0  #: Poisson-disk distance (m)
    sigma_sem: float = 2.0  #: semantic position std (m)
    poisson_k: int = 30  #: Bridson candidates per active point
    dbscan_eps: float = 1.0  #: DBSCAN eps (m)
    dbscan_min_samples: int = 5  #: DBSCAN min_samples
    dbscan_split: bool = False  #: split clusters with k-means into ceil(area/d_min^2) parts
    # S-OA FOV boundary terms (§3.1.5)
    d_fov: float = 5.0  #: spacing along the FOV boundary (m)
    sigma_fov: float = 2.0  #: FOV boundary std (m); the inset delta_fov equals it
    fov_boundary: str = "range"  #: "range" (unclipped) or "visible" (ray-cast, 1 deg bins)
    # S-OA weights (§3.1.6)
    rho: tuple[float, float, float] = (1.0, 1.0, 1.0)  #: source confidences (occl, sem, fov)
    rho_norm: str = "component"  #: "component" (paper) or "source"
    # PUBM (§3.2)
    pubm_space: str = "meas"  #: "meas" or "cart"
    pubm_hybrid: float = 0.0  #: eta, share of GMBM components
    # UBM (§3.3)
    d_u: float = 5.0  #: grid spacing (m)
    sigma_u: float = 2.5  #: grid std (m)
    ubm_extent: str = "fov"  #: "fov" (clipped to the FOV) or "workspace"
    # ATBM (§3.4)
    atbm: str = "same_scan"  #: "same_scan" or "prev_scan"
    atbm_alloc: str = "uniform"  #: "uniform" or "unexplained"
    atbm_raw_mass: bool = False  #: SMC-literal raw newborn mass in L(z)
    # GMBM (§3.5)
    sigma_gm: float = 3.0  #: GMBM std (m)

    def validate(self) -> None:
        _non_negative("birth.N_hat", self.N_hat, hi=1e4)
        _positive("birth.sigma_v_birth", self.sigma_v_birth, hi=100.0)
        _non_negative("birth.delta_in", self.delta_in, hi=1e4)
        _positive("birth.delta_r", self.delta_r, hi=1e4)
        _int_range("birth.L", self.L, 0, 1000)
        _positive("birth.sigma_par", self.sigma_par, hi=1e4)
        _positive("birth.sigma_perp", self.sigma_perp, hi=1e4)
        _one_of("birth.ray_start", self.ray_start, ("tangent", "centroid"))
        _one_of("birth.sem_mode", self.sem_mode, ("poisson", "hex", "dbscan", "uniform"))
        _one_of("birth.sem_resample", self.sem_resample, ("trial", "step"))
        _in_range("birth.d_min", self.d_min, 0.5, 1e4)  # spacings: >= 0.5 m bounds the sample count
        _positive("birth.sigma_sem", self.sigma_sem, hi=1e4)
        _int_range("birth.poisson_k", self.poisson_k, 1, 1000)
        _positive("birth.dbscan_eps", self.dbscan_eps, hi=1e4)
        _int_range("birth.dbscan_min_samples", self.dbscan_min_samples, 1, 1_000_000)
        _in_range("birth.d_fov", self.d_fov, 0.5, 1e4)
        _positive("birth.sigma_fov", self.sigma_fov, hi=1e4)
        _one_of("birth.fov_boundary", self.fov_boundary, ("range", "visible"))
        require(
            len(self.rho) == 3
            and all(_is_number(r) and math.isfinite(r) and 0 <= r <= 1e6 for r in self.rho)
            and sum(self.rho) > 0,
            f"birth.rho = {list(self.rho)!r} must be three finite numbers in [0, 1e6] (occl, sem, fov), not all zero",
        )
        _one_of("birth.rho_norm", self.rho_norm, ("component", "source"))
        _one_of("birth.pubm_space", self.pubm_space, ("meas", "cart"))
        _in_range("birth.pubm_hybrid", self.pubm_hybrid, 0.0, 1.0)
        _in_range("birth.d_u", self.d_u, 0.5, 1e4)
        _positive("birth.sigma_u", self.sigma_u, hi=1e4)
        _one_of("birth.ubm_extent", self.ubm_extent, ("fov", "workspace"))
        _one_of("birth.atbm", self.atbm, ("same_scan", "prev_scan"))
        _one_of("birth.atbm_alloc", self.atbm_alloc, ("uniform", "unexplained"))
        _positive("birth.sigma_gm", self.sigma_gm, hi=1e4)


@dataclass
class MetricsConfig:
    """Evaluation (docs/method.md §5; register rows 5, 6, 22, 23)."""

    ospa_c: float = 100.0  #: OSPA cut-off c [P]
    ospa_p: float = 1.0  #: OSPA order p [P]
    gospa_c: float = 5.0  #: GOSPA cut-off (extra metric)
    gospa_p: float = 1.0  #: GOSPA order
    gt_set: str = "fov"  #: "fov" (present and in the FOV), "visible", or "scene"
    d_gate: float = 5.0  #: association gate of the delay and precision metrics (m)
    g_min: int = 1  #: episode gap
    confirm_n: int = 1  #: consecutive associated steps needed for initiation
    censored: str = "exclude"  #: "exclude" (count separately) or "lower_bound"
    ddof: int = 0  #: per-trial sigma convention
    gap_bins: tuple[int, ...] = (1, 2, 4, 8)  #: first scan count of each occlusion-gap length bin (1, 2-3, 4-7, 8+)

    def validate(self) -> None:
        _positive("metrics.ospa_c", self.ospa_c)
        _in_range("metrics.ospa_p", self.ospa_p, 1.0, 100.0)
        _positive("metrics.gospa_c", self.gospa_c)
        _in_range("metrics.gospa_p", self.gospa_p, 1.0, 100.0)
        _one_of("metrics.gt_set", self.gt_set, ("fov", "visible", "scene"))
        _positive("metrics.d_gate", self.d_gate)
        _int_range("metrics.g_min", self.g_min, 1, 1_000_000)
        _int_range("metrics.confirm_n", self.confirm_n, 1, 1_000_000)
        _one_of("metrics.censored", self.censored, ("exclude", "lower_bound"))
        _one_of("metrics.ddof", self.ddof, (0, 1))
        bins = self.gap_bins
        require(
            isinstance(bins, tuple) and 1 <= len(bins) <= MAX_GAP_BINS,
            f"metrics.gap_bins = {list(bins)!r} must list 1 to {MAX_GAP_BINS} gap lengths",
        )
        for b in bins:
            _int_range("metrics.gap_bins[]", b, 1, 1_000_000)
        require(
            bins[0] == 1 and all(a < b for a, b in zip(bins, bins[1:], strict=False)),
            f"metrics.gap_bins = {list(bins)!r} must start at 1 and increase (each the first scan count of a bin)",
        )


@dataclass
class ExperimentConfig:
    """The Monte Carlo protocol (docs/method.md §5.8)."""

    trials: int = 100  #: Monte Carlo trials
    duration: float = 100.0  #: seconds simulated per trial
    models: tuple[str, ...] = BIRTH_MODEL_NAMES  #: birth models to run in our GM-PHD (built-ins or plugins)
    trackers: tuple[str, ...] = ()  #: whole trackers to run beside them (soabench.plugins)
    probabilities: tuple[str, ...] = ("static", "dynamic")  #: probability modes to run (each once)
    clutter: tuple[float, ...] = (CLUTTER_RATE,)  #: clutter rates lambda, each once (each gets every model x mode)
    filters: tuple[str, ...] = FILTER_FAMILIES[:1]  #: filter families every birth model runs in: gmphd, lmb, pmbm, pmb
    seed: int = 0  #: base seed; trial n uses SeedSequence([seed, n])
    plugin_budget: float = 120.0  #: plugin time budget (s) to build and per scan; past it the run fails (0: no limit)

    def validate(self) -> None:
        _int_range("trials", self.trials, 1, MAX_TRIALS)
        _positive("duration", self.duration, hi=MAX_DURATION)
        require(len(self.models) + len(self.trackers) >= 1, "models must name at least one birth model or tracker")
        for m in self.models:
            plugins.check_name(plugins.BIRTH, m)
        for t in self.trackers:
            plugins.check_name(plugins.TRACKER, t)
        require(len(set(self.models)) == len(self.models), f"models = {list(self.models)!r} has duplicates")
        both = set(self.models) & set(self.trackers)
        require(len(set(self.trackers)) == len(self.trackers), f"trackers = {list(self.trackers)!r} has duplicates")
        if both:
            raise SoabenchError(f"{sorted(both)[0]!r} is named both as a model and as a tracker")
        require(len(self.probabilities) >= 1, "probabilities must name at least one mode")
        for p in self.probabilities:
            _one_of("probability mode", p, PROBABILITY_MODES)
        require_distinct("probabilities", self.probabilities)
        require(len(self.filters) >= 1, f"filters must name at least one of {', '.join(FILTER_FAMILIES)}")
        for f in self.filters:
            _one_of("filter family", f, FILTER_FAMILIES)
        require_distinct("filters", self.filters)
        for f in self.filters:
            runs = [p for p in self.probabilities if p in FAMILY_MODES[f]]
            require(
                bool(runs),
                f"filter family {f!r} runs the probability modes {', '.join(FAMILY_MODES[f])} only, and probabilities "
                f"= {list(self.probabilities)!r} names none of them; add one of them to experiment.probabilities "
                "(e.g. static)",
            )
        require(len(self.clutter) >= 1, "clutter must give at least one rate")
        for lam in self.clutter:
            _non_negative("clutter", lam, hi=1e4)
        require_distinct("clutter", self.clutter)
        _int_range("seed", self.seed, 0, MAX_SEED)
        _non_negative("plugin_budget", self.plugin_budget, hi=86400.0)


#: the ways the LMB computes its association marginals (docs/method.md "LMB filter", register row 40)
LMB_ASSOCIATIONS = ("bounded", "exact")


@dataclass
class LMBConfig:
    """The LMB filter, read by runs whose experiment.filters names lmb (docs/method.md "LMB filter").

    Defaults: Vo's toolbox; register row 33 for r_B,max. A key set here while no run reads it is refused.
    """

    r_B_max: float = 0.5  #: largest existence probability r_B,max of a birth track
    prune_r: float = 1e-3  #: tracks with existence probability r below this are dropped
    max_tracks: int = 100  #: most probable tracks kept after each scan
    max_hypotheses: int = 1000  #: per cluster: exact up to this many valid hypotheses, else this many Gibbs sweeps
    max_components: int = 10  #: Gaussian components kept per track (J_h; also per birth group)
    extract_r: float = 0.5  #: estimates: the tracks with r above this, labelled
    #: how birth components become Bernoullis (docs/method.md "LMB filter"): "groups" (one per merge group,
    #: r = min(sum w, r_B_max)) or "components" (one per component, r = min(w, r_B_max), every newborn term as
    #: Reuter's adaptive birth)
    birth_mapping: str = "groups"
    #: association marginals (docs/method.md "LMB filter"): "bounded" (exact up to max_hypotheses valid
    #: hypotheses, Gibbs sampling above) or "exact" (also exact for any cluster of at most 10 measurements)
    association: str = "bounded"  #: "bounded": exact to max_hypotheses, Gibbs above; "exact": also clusters of <= 10 z

    def validate(self) -> LMBConfig:
        _in_range("lmb.r_B_max", self.r_B_max, 0.0, 1.0, lo_open=True, hi_open=True)
        _in_range("lmb.prune_r", self.prune_r, 0.0, 1.0, hi_open=True)
        _int_range("lmb.max_tracks", self.max_tracks, 1, 1_000_000)
        _int_range("lmb.max_hypotheses", self.max_hypotheses, 1, 10_000_000)
        _int_range("lmb.max_components", self.max_components, 1, 10_000)
        _in_range("lmb.extract_r", self.extract_r, 0.0, 1.0, hi_open=True)
        _one_of("lmb.birth_mapping", self.birth_mapping, ("groups", "components"))
        _one_of("lmb.association", self.association, LMB_ASSOCIATIONS)
        return self


#: the ways the PMB variant computes its marginal association probabilities (docs/method.md §10.5)
PMB_MARGINALS = ("murty",)


@dataclass
class PMBMConfig:
    """The PMBM filter and its PMB variant, read by runs whose experiment.filters names pmbm or pmb (docs/method.md
    §10, register rows 36-37). A key set here while no run reads it is refused."""

    M_max: int = 100  #: global hypotheses kept; each prior global hypothesis a asks Murty for ceil(M_max w_a)
    w_floor: float = 1e-4  #: global hypotheses of weight below this are dropped (then renormalised)
    r_floor: float = 1e-5  #: a track whose every single-target hypothesis has r below this is dropped
    J_h: int = 10  #: Gaussian components kept per single-target hypothesis
    marginals: str = "murty"  #: the PMB's marginals: from the Murty hypotheses

    def validate(self) -> PMBMConfig:
        _int_range("pmbm.M_max", self.M_max, 1, 100_000)
        _in_range("pmbm.w_floor", self.w_floor, 0.0, 1.0, hi_open=True)
        _in_range("pmbm.r_floor", self.r_floor, 0.0, 1.0, hi_open=True)
        _int_range("pmbm.J_h", self.J_h, 1, 10_000)
        _one_of("pmbm.marginals", self.marginals, PMB_MARGINALS)
        return self


@dataclass
class Config:
    """The full resolved configuration of a run."""

    sensor: SensorConfig = field(default_factory=SensorConfig)
    filter: FilterConfig = field(default_factory=FilterConfig)
    birth: BirthConfig = field(default_factory=BirthConfig)
    metrics: MetricsConfig = field(default_factory=MetricsConfig)
    experiment: ExperimentConfig = field(default_factory=ExperimentConfig)
    lmb: LMBConfig = field(default_factory=LMBConfig)
    pmbm: PMBMConfig = field(default_factory=PMBMConfig)
    #: ``[plugins.<name>]`` tables: a plugin's own options, passed to its constructor as keyword arguments
    plugins: dict[str, dict[str, Any]] = field(default_factory=dict)

    def validate(self, sumo_step: float | None = None) -> Config:
        for sec in dataclasses.fields(self):  # exact types first (a boolean is not an integer, "no" is not false)
            obj = getattr(self, sec.name)
            if not dataclasses.is_dataclass(obj):  # [plugins.<name>]: the plugin checks its own options
                continue
            for f in dataclasses.fields(obj):
                default = f.default_factory() if f.default is dataclasses.MISSING else f.default
                _check_type(f"{sec.name}.{f.name}", default, getattr(obj, f.name))
        self.experiment.validate()
        self.sensor.validate(sumo_step)
        self.filter.validate()
        self.birth.validate()
        self.metrics.validate()
        for section in dict.fromkeys(f.section for f in FAMILIES.values() if f.section is not None):
            self._check_family_section(str(section))
        require(
            self.experiment.duration >= self.sensor.dt,
            f"duration = {self.experiment.duration!r} is shorter than one sensor period sensor.dt = {self.sensor.dt!r}",
        )
        for name, table in self.plugins.items():
            require(isinstance(table, dict), f"[plugins.{name}] must be a table of option = value")
        return self

    def _check_family_section(self, section: str) -> None:
        """Validate a filter family's own section; a key of it set while the run names none of the families that
        read it is refused, not ignored."""
        values = getattr(self, section)
        values.validate()
        default = type(values)()
        changed = [f.name for f in dataclasses.fields(values) if getattr(values, f.name) != getattr(default, f.name)]
        readers = [f for f in FAMILIES.values() if f.section == section]
        if changed and not any(f.name in self.experiment.filters for f in readers):
            names = " or ".join(f.name for f in readers)
            raise SoabenchError(
                f"{section}.{changed[0]} = {getattr(values, changed[0])!r} is set but experiment.filters = "
                f"{list(self.experiment.filters)!r} runs no {' or '.join(f.label for f in readers)} filter; add "
                f"{names} to experiment.filters (e.g. ['gmphd', '{readers[0].name}']) or remove the key"
            )

    def to_dict(self) -> dict[str, dict[str, Any]]:
        """Plain nested dict (tuples as lists), for the summary JSON and ``from_dict``; without the sections of the
        filter families the run does not name (then at their defaults) and, when the run names the default family
        only, without ``experiment.filters`` (the identity of a default run is
        unchanged)."""
        out = dataclasses.asdict(self)
        named = tuple(out["experiment"]["filters"])
        read = {f.section for f in FAMILIES.values() if f.name in named}
        for section in {f.section for f in FAMILIES.values() if f.section is not None} - read:
            del out[section]
        if named == FILTER_FAMILIES[:1]:  # the default family: run.json as before the key
            del out["experiment"]["filters"]
        return {sec: {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()} for sec, d in out.items()}

    def sensor_at(self, lambda_c: float | None = None) -> Sensor:
        """The sensor at clutter rate ``lambda_c``, one of ``experiment.clutter`` (docs/method.md §5.8: a run makes
        the scans of each rate in turn); None: the first rate, the one rate of a command that observes one scene."""
        return self.sensor.at(self.experiment.clutter[0] if lambda_c is None else lambda_c)

    def gmphd_only(self, command: str) -> Config:
        """This configuration, for a command that runs the GM-PHD family only (docs/user-guide/outputs.md "Filter
        families"): ``experiment.filters`` naming another family is refused with one line, never ignored."""
        families = self.experiment.filters
        require(
            tuple(families) == FILTER_FAMILIES[:1],
            f"experiment.filters = {list(families)!r}: {command} runs the GM-PHD family only; run the families side "
            "by side with `soabench run --filters gmphd,lmb`",
        )
        return self

    def single_clutter_rate(self, command: str) -> float:
        """The one clutter rate of a command that observes one scene; a list of several is refused with one line."""
        rates = self.experiment.clutter
        require(
            len(rates) == 1,
            f"experiment.clutter = {list(rates)!r} gives {len(rates)} rates; {command} observes at one rate: give one",
        )
        return float(rates[0])

    @classmethod
    def from_dict(cls, data: dict[str, Any], base: Config | None = None) -> Config:
        """Overlay ``data`` (sections of key = value) on ``base`` (defaults if None); unknown keys are errors."""
        cfg = dataclasses.replace(base) if base is not None else cls()
        cfg = cls(
            **{
                f.name: dict(cfg.plugins) if f.name == "plugins" else dataclasses.replace(getattr(cfg, f.name))
                for f in dataclasses.fields(cls)
            }
        )
        sections = {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cls)}
        require(isinstance(data, dict), "a configuration must be a table of sections")
        for sec, values in data.items():
            require(sec in sections, f"unknown config section [{sec}]; allowed: {', '.join(sections)}")
            require(isinstance(values, dict), f"config section [{sec}] must be a table of key = value")
            if sec == "plugins":  # free-form per plugin; the plugin's constructor is the judge (soabench.plugins)
                for name, table in values.items():
                    require(isinstance(table, dict), f"[plugins.{name}] must be a table of option = value")
                    cfg.plugins[name] = dict(table)
                continue
            obj = sections[sec]
            fields = {f.name: f for f in dataclasses.fields(obj)}
            for key, value in values.items():
                if f"{sec}.{key}" in NOT_KEYS:
                    raise SoabenchError(_not_key_message(f"{sec}.{key}", value))
                require(key in fields, f"unknown config key {sec}.{key}; allowed: {', '.join(sorted(fields))}")
                f = fields[key]
                default = f.default_factory() if f.default is dataclasses.MISSING else f.default
                setattr(obj, key, _check_type(f"{sec}.{key}", default, value))
        return cfg

    @classmethod
    def from_record(cls, data: Any) -> Config:
        """The configuration stored in a run or sweep file: like :meth:`from_dict`, except that a recorded
        ``sensor.lambda_c`` is dropped (the scans' rate, which ``experiment.clutter`` of the same record sets)."""
        if isinstance(data, dict) and isinstance(data.get("sensor"), dict) and "lambda_c" in data["sensor"]:
            data = {**data, "sensor": {k: v for k, v in data["sensor"].items() if k != "lambda_c"}}
        return cls.from_dict(data)


def _not_key_message(key: str, value: Any) -> str:
    """One line naming a name that is not a key and the key that holds its value."""
    home = NOT_KEYS[key]
    example = f"[{value!r}]" if _is_number(value) else "[3.0]"
    section, name = home.split(".")
    return f"{key} is not a config key: the clutter rate has one key, {home} (a list: [{section}] {name} = {example})"


def filter_config_for_mode(cfg: FilterConfig, mode: str) -> tuple[FilterConfig, str, float]:
    """Filter settings of a probability mode (docs/method.md §4.6): ``(filter_cfg, filter_mode, p_D_b)``.

    ``static`` and ``dynamic`` use ``cfg`` as given; ``static+occ`` and ``dynamic+occ`` are ``static`` and ``dynamic``
    with the line-of-sight gate of §4.4 (``occlusion_pd``). ``p_D_b`` is the detection probability of a newborn
    term: p_D in the static modes, the Beta prior mean mu_D0 in the dynamic modes (§4.2).
    """
    _one_of("probability mode", mode, PROBABILITY_MODES)
    if mode == "static":
        return cfg, "static", cfg.p_D
    if mode == "static+occ":
        return dataclasses.replace(cfg, occlusion_pd=True), "static", cfg.p_D
    if mode == "dynamic+occ":
        return dataclasses.replace(cfg, occlusion_pd=True), "dynamic", cfg.mu_D0
    return cfg, "dynamic", cfg.mu_D0


def load_config(path: str | Path | None, base: Config | None = None, validate: bool = True) -> Config:
    """Read a TOML configuration file over ``base`` (defaults if None) and validate the result (``validate``: False
    for a caller that overlays more values, e.g. the command-line flags, and validates the whole)."""
    if path is None:
        cfg = base or Config()
    else:
        p = Path(path)
        require(p.is_file(), f"config file {str(p)!r} does not exist")
        cfg = Config.from_dict(read_toml(p, "config file"), base)
    return cfg.validate() if validate else cfg
