"""``soabench check --suite FILE.toml``: short scenarios with per-metric thresholds, the CI mode for tracker developers.

A suite file (TOML, read as data only) holds:

* ``[suite]``: ``name``, optional ``baseline`` (JSON path, relative to the suite file) and ``config`` (a soabench
  configuration TOML, relative to the suite file, e.g. for ``[plugins.<name>]`` options);
* one ``[[scenario]]`` table per short scenario: ``name``, ``net`` (a shipped network or a path relative to the
  suite file), optional ``polys`` (polygon files) and ``scenario`` (scenario TOML), ``seeds`` (base seeds),
  ``trials`` per seed, ``duration`` (s), ``models``, ``trackers``, ``probabilities``, ``clutter`` and ``filter`` (the
  filter family the birth models run in, one name of the registry ``soabench.config.FAMILIES``; default ``gmphd``;
  every probability mode of the scenario must be one the family defines);
* one ``[[threshold]]`` table per check: ``metric`` (a metric or ``t_*`` timing column of trials.csv, e.g.
  ``ospa``, ``card_err``, ``precision``; any other name is a bad suite), ``model`` (a name or ``"*"``), optional
  ``mode``/``scenario`` filters, and any of ``max``, ``min`` (absolute), ``max_increase``, ``max_decrease``
  (relative to the baseline value: fail when the value exceeds ``baseline * (1 + max_increase)`` or falls below
  ``baseline * (1 - max_decrease)``) and ``abs_tol`` (slack added to the relative bounds, default 1e-9).

Besides the trials.csv columns, the occlusion metrics of docs/method.md §9.4 read episodes.csv: per gap-length bin
of ``metrics.gap_bins`` (default 1, 2-3, 4-7, 8+ scans) ``identity_kept_gap_<bin>`` and ``coasted_gap_<bin>`` (e.g.
``identity_kept_gap_2-3``), and ``identity_kept_long`` / ``coasted_long`` for the longest bin; each is pooled over
the re-emergences of every trial and seed (kept / counted), so each bin gets its own threshold.

A value is the mean of the metric over every trial and seed of one (scenario, model, mode, clutter). A value that is
NaN (no trial produced it) fails every threshold on it, and a plugin run that failed (soabench.experiment.trial.guard)
fails the suite. Results: a table on stdout, ``check.json`` and ``junit.xml`` in ``--out``; exit status 0 when every
check passes, 1 on a regression. ``--update-baseline`` writes every measured value to the baseline file.

``--calibrate N`` runs the suite's scenarios N times on fresh seeds (repetition r: every seed plus
r x :data:`CALIBRATION_SEED_STRIDE`) and proposes, for every value a threshold reads, the bounds a further run stays
inside with 95 % probability: the mean of the N values ± t_{0.975, N-1} s √(1 + 1/N) (s their standard deviation),
written to ``calibration.json`` and printed; nothing is checked.
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
import re
import shutil
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape, quoteattr

import numpy as np

from soabench import plugins
from soabench.atomic import write_json_atomic, write_text_atomic
from soabench.config import CLUTTER_RATE, FAMILIES, FAMILY_MODES, FILTER_FAMILIES, Config, MetricsConfig
from soabench.errors import SoabenchError, require
from soabench.experiment.runs.files import read_csv
from soabench.experiment.trial.guard import failure_message
from soabench.folders import FolderLock, check_own_folder, resolve
from soabench.tomlfile import read_toml

SUITE_KEYS = {"name", "baseline", "config"}
SCENARIO_KEYS = {
    "name",
    "net",
    "polys",
    "scenario",
    "seeds",
    "trials",
    "duration",
    "models",
    "trackers",
    "probabilities",
    "clutter",
    "filter",
}
THRESHOLD_KEYS = {"metric", "model", "mode", "scenario", "max", "min", "max_increase", "max_decrease", "abs_tol"}
BASELINE_FORMAT = 1
#: the ``[[scenario]]`` key of an ``[experiment]`` key where the two names differ
SCENARIO_KEY_OF = {"seed": "seeds", "filters": "filter"}
#: a scenario's name names its folder ``--out/runs/NAME/``: a plain name, never a path
SCENARIO_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")
#: every entry of a check folder (a folder holding anything else is not a check's and is refused)
CHECK_ENTRIES = ("check.json", "junit.xml", "runs", "calibration.json")
#: ``--calibrate``: repetition r runs every scenario's seeds plus r x this (trials no other repetition runs)
CALIBRATION_SEED_STRIDE = 1000
#: how far a proposed bound moves from one calibration to the next, measured on the example suite (benchmarks/README.md
#: "Calibration runs"): the standard deviation of the bound over independent calibrations, as a share of its margin
#: (the bound's distance from the mean), median over the suite's bounds
STABILITY_NOTE = (
    "How stable: on the example suite a proposed bound moved from one calibration to the next by 0.72 of its margin "
    "(the distance from the mean) with 5 runs, 0.40 with 10 and 0.28 with 20 (standard deviations), and lay 40 %, "
    "13 % and 5 % further out than with 120 runs."
)


@dataclass
class Scenario:
    name: str
    net: str
    polys: tuple[str, ...] = ()
    scenario: str | None = None
    seeds: tuple[int, ...] = (0,)
    trials: int = 1
    duration: float = 20.0
    models: tuple[str, ...] = ("soa",)
    trackers: tuple[str, ...] = ()
    probabilities: tuple[str, ...] = ("static",)
    clutter: tuple[float, ...] = (CLUTTER_RATE,)
    #: the filter family the scenario's birth models run in (one scenario, one family: its value keys stay those of
    #: any other scenario, and two scenarios compare two families)
    filter: str = FILTER_FAMILIES[0]


@dataclass
class Threshold:
    metric: str
    model: str = "*"
    mode: str | None = None
    scenario: str | None = None
    max: float | None = None
    min: float | None = None
    max_increase: float | None = None
    max_decrease: float | None = None
    abs_tol: float = 1e-9

    @property
    def relative(self) -> bool:
        return self.max_increase is not None or self.max_decrease is not None


@dataclass
class Suite:
    name: str
    path: Path
    scenarios: list[Scenario]
    thresholds: list[Threshold]
    baseline: Path | None = None
    config: Path | None = None


@dataclass
class CheckResult:
    """One check: a threshold applied to one value (or a failed plugin run)."""

    name: str
    passed: bool
    message: str
    value: float = math.nan
    bound: str = ""
    trials: int = 0  #: the trials the value is a mean over (every seed of its scenario)
    time_s: float = 0.0  #: seconds its scenario's runs took (the kernels' compilation apart)


@dataclass
class ScenarioRuns:
    """What the runs of one scenario took: trials over every seed, and seconds (the kernels' compilation apart)."""

    trials: int = 0
    time_s: float = 0.0


@dataclass
class CheckOutcome:
    suite: str
    values: dict[str, float]
    results: list[CheckResult] = field(default_factory=list)
    wall_s: float = 0.0
    compile_s: float = 0.0  #: seconds compiling the kernels before the first run (a cold machine; 0 when cached)

    @property
    def passed(self) -> bool:
        return all(r.passed for r in self.results)


# ------------------------------------------------------------------------------------------------ the suite file
def _table(data: Any, where: str, allowed: set[str]) -> dict:
    require(isinstance(data, dict), f"{where} must be a table of key = value")
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise SoabenchError(f"{where}: unknown key {unknown[0]!r}; allowed: {', '.join(sorted(allowed))}")
    return data


def _strs(v: Any, where: str) -> tuple[str, ...]:
    require(isinstance(v, list) and all(isinstance(s, str) for s in v), f"{where} = {v!r} must be a list of names")
    return tuple(v)


#: metrics of trials.csv that are fractions or scores in [0, 1] (docs/user-guide/outputs.md); MOTA may be negative
#: and is at most 1; every other metric and timing column is a count, a distance, a delay or a time, >= 0
UNIT_METRICS = frozenset(
    ("precision", "recall", "mean_pD", "hota", "deta", "assa", "loca", "motp", "idf1", "idp", "idr", "coasted",
     "id_kept", *(f"hota_a{a:02d}" for a in range(5, 100, 5)))
)  # fmt: skip


def metric_range(metric: str) -> tuple[float, float]:
    """The values ``metric`` (a trials.csv metric or timing column) can take: a threshold outside them passes or
    fails whatever the tracker does."""
    if metric in UNIT_METRICS or metric.startswith(("identity_kept_", "coasted_")):  # also the occlusion metrics
        return 0.0, 1.0
    if metric == "mota":
        return -math.inf, 1.0
    return 0.0, math.inf


def _number(v: Any, where: str, lo: float = -math.inf) -> float:
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= lo
    require(ok, f"{where} = {v!r} must be a finite number >= {lo:g}")
    return float(v)


def _inside(folder: Path, name: Any, where: str) -> Path:
    """``folder / name`` for a relative path that stays inside ``folder`` (``--update-baseline`` writes it: a suite
    file never names a place outside its own folder)."""
    require(isinstance(name, str) and name != "", f"{where} = {name!r} must be a file name relative to the suite")
    path = (folder / name).resolve()
    require(
        not Path(name).is_absolute() and path.is_relative_to(folder),
        f"{where} = {name!r} lies outside the suite file's folder {str(folder)!r}; give a path inside it",
    )
    return path


def load_suite(path: str | Path) -> Suite:
    """Read and validate a suite file (SoabenchError naming the value and what is allowed)."""
    p = Path(path)
    require(p.is_file(), f"suite file {str(p)!r} does not exist")
    data = read_toml(p, "suite file")
    _table(data, str(p), {"suite", "scenario", "threshold"})
    head = _table(data.get("suite", {}), "[suite]", SUITE_KEYS)
    here = p.resolve().parent
    suite = Suite(
        name=str(head.get("name", p.stem)),
        path=p,
        scenarios=[],
        thresholds=[],
        baseline=_inside(here, head["baseline"], "[suite] baseline") if "baseline" in head else None,
        config=here / head["config"] if "config" in head else None,
    )
    scen = data.get("scenario", [])
    require(isinstance(scen, list) and len(scen) >= 1, f"{p}: give at least one [[scenario]] table")
    suite.scenarios = [_scenario(raw, i, p, here) for i, raw in enumerate(scen)]
    names = [s.name for s in suite.scenarios]
    require(len(set(names)) == len(names), f"{p}: scenario names {names} repeat")
    suite.thresholds = [_threshold(raw, i, suite) for i, raw in enumerate(data.get("threshold", []))]
    if any(th.relative for th in suite.thresholds):
        require(suite.baseline is not None, f'{p}: relative thresholds need [suite] baseline = "FILE.json"')
    return suite


def _scenario(raw: Any, i: int, p: Path, here: Path) -> Scenario:
    """``[[scenario]]`` table ``i`` of suite file ``p`` (in folder ``here``), validated."""
    t = _table(raw, f"[[scenario]] #{i + 1}", SCENARIO_KEYS)
    require("name" in t and "net" in t, f"[[scenario]] #{i + 1} needs a name and a net")
    require(
        isinstance(t["name"], str) and SCENARIO_NAME.fullmatch(t["name"]) is not None,
        f"[[scenario]] #{i + 1}: name = {t['name']!r} is not a plain name (letters, digits, '.', '_', '-', at most "
        "100, starting with a letter or digit): it names the folder --out/runs/NAME",
    )
    net = str(t["net"])
    if "/" in net or net.endswith(".xml"):
        net = str(here / net)
    s = Scenario(name=str(t["name"]), net=net)
    w = f"scenario {s.name!r}"
    if "polys" in t:
        s.polys = tuple(str(here / f) for f in _strs(t["polys"], f"{w}: polys"))
    if "scenario" in t:
        require(isinstance(t["scenario"], str), f"{w}: scenario must be a path to a scenario TOML")
        s.scenario = str(here / t["scenario"])
    if "seeds" in t:
        require(
            isinstance(t["seeds"], list)
            and len(t["seeds"]) >= 1
            and all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in t["seeds"]),
            f"{w}: seeds = {t['seeds']!r} must be a non-empty list of integers >= 0",
        )
        s.seeds = tuple(t["seeds"])
    if "trials" in t:
        require(isinstance(t["trials"], int) and t["trials"] >= 1, f"{w}: trials must be an integer >= 1")
        s.trials = int(t["trials"])
    if "duration" in t:
        s.duration = _number(t["duration"], f"{w}: duration", 1e-9)
    for key in ("models", "trackers", "probabilities"):
        if key in t:
            setattr(s, key, _strs(t[key], f"{w}: {key}"))
    if "clutter" in t:
        require(isinstance(t["clutter"], list) and t["clutter"], f"{w}: clutter must be a list of rates")
        s.clutter = tuple(_number(c, f"{w}: clutter", 0.0) for c in t["clutter"])
    if "filter" in t:
        s.filter = _family(t["filter"], s.probabilities, f"{p}: {w}")
    return s


def _threshold(raw: Any, i: int, suite: Suite) -> Threshold:
    """``[[threshold]]`` table ``i`` of ``suite``, validated against the suite's scenarios."""
    p, names = suite.path, [s.name for s in suite.scenarios]
    t = _table(raw, f"[[threshold]] #{i + 1}", THRESHOLD_KEYS)
    require("metric" in t, f"[[threshold]] #{i + 1} needs a metric")
    bins = _suite_bins(suite.config, [sc.filter for sc in suite.scenarios])
    _check_metric(t["metric"], f"{p}: [[threshold]] #{i + 1}", bins)
    th = Threshold(metric=str(t["metric"]), model=str(t.get("model", "*")))
    th.mode, th.scenario = t.get("mode"), t.get("scenario")
    lo, hi = metric_range(th.metric)
    for key in ("max", "min"):
        if key in t:
            v = _number(t[key], f"threshold {th.metric}: {key}")
            setattr(th, key, v)
            require(
                lo <= v <= hi,
                f"{p}: [[threshold]] #{i + 1}: {th.metric} {key} = {t[key]!r} is outside the metric's range "
                f"[{lo:g}, {hi:g}] (such a threshold passes or fails whatever the tracker does)",
            )
    require(
        th.max is None or th.min is None or th.min <= th.max,
        f"{p}: [[threshold]] #{i + 1}: {th.metric} min = {th.min!r} is above max = {th.max!r} (no value passes)",
    )
    for key in ("max_increase", "max_decrease", "abs_tol"):
        if key in t:
            setattr(th, key, _number(t[key], f"threshold {th.metric}: {key}", 0.0))
    require(
        any(v is not None for v in (th.max, th.min, th.max_increase, th.max_decrease)),
        f"threshold on {th.metric!r} sets none of max, min, max_increase, max_decrease",
    )
    require(th.scenario is None or th.scenario in names, f"threshold scenario {th.scenario!r} is not in {names}")
    scoped = [s for s in suite.scenarios if th.scenario is None or s.name == th.scenario]
    where = f"{p}: [[threshold]] #{i + 1}"
    run_names = ["*", *dict.fromkeys(m for s in scoped for m in (*s.models, *s.trackers))]
    _check_name(th.model, run_names, f"{where}: model", "a model or tracker its scenarios run, or '*'")
    if th.mode is not None:
        modes = list(dict.fromkeys(m for s in scoped for m in s.probabilities))
        _check_name(th.mode, modes, f"{where}: mode", "a probability mode its scenarios run")
    return th


def _family(name: Any, modes: Sequence[str], where: str) -> str:
    """A scenario's filter family: a name of the registry whose probability modes include every mode the scenario
    runs (a mode it lacks would leave the thresholds on it matching nothing after the whole suite ran)."""
    require(
        isinstance(name, str) and name in FAMILY_MODES,
        f"{where}: filter = {name!r} is not a filter family; allowed: {', '.join(FILTER_FAMILIES)}",
    )
    lacking = [m for m in modes if m not in FAMILY_MODES[name]]
    if lacking:
        raise SoabenchError(
            f"{where}: filter family {name!r} runs the probability modes {', '.join(FAMILY_MODES[name])} only, and "
            f"probabilities names {lacking[0]!r}; drop it or choose another filter"
        )
    return name


def _check_name(name: Any, allowed: list[str], where: str, what: str) -> None:
    """A threshold's model or mode must be one its scenarios run (else no value would match, after the whole suite
    ran): one line with the closest name."""
    if name in allowed:
        return
    close = difflib.get_close_matches(str(name), allowed, n=1)
    guess = f" (did you mean {close[0]!r}?)" if close else ""
    raise SoabenchError(f"{where} = {name!r} is not {what}{guess}; allowed: {', '.join(allowed)}")


def gap_metrics(bins: Sequence[int]) -> dict[str, tuple[str, int]]:
    """The occlusion metrics of a suite (module docstring): name -> (episodes.csv column, bin index)."""
    from soabench.experiment.reports.occlusion import bin_labels

    out = {}
    for column, name in (("gap_id_kept", "identity_kept"), ("gap_coasted", "coasted")):
        for i, label in enumerate(bin_labels(bins)):
            out[f"{name}_gap_{label}"] = (column, i)
        out[f"{name}_long"] = (column, len(bins) - 1)
    return out


def _check_metric(metric: Any, where: str, bins: Sequence[int] | None = None) -> None:
    """A threshold's metric must be a metric or timing column of trials.csv or an occlusion metric of the suite's
    gap bins (a typo is a bad suite, not a failed check)."""
    # imported when called: scipy would slow every start-up
    from soabench.experiment.runs.store import METRIC_COLUMNS, TIMING_COLUMNS

    allowed = METRIC_COLUMNS + TIMING_COLUMNS + tuple(gap_metrics(bins or MetricsConfig().gap_bins))
    if metric in allowed:
        return
    close = difflib.get_close_matches(str(metric), allowed, n=1)
    guess = f" (did you mean {close[0]!r}?)" if close else ""
    raise SoabenchError(f"{where}: metric {metric!r} is not a trials.csv metric{guess}; allowed: {', '.join(allowed)}")


def suite_config(config: Path | None, families: Sequence[str]) -> Config:
    """A suite's ``[suite] config`` (the defaults without one), validated as read by runs of every filter family its
    scenarios name: a family's own section (``[lmb]``, ``[pmbm]``) may be set when a scenario runs that family."""
    if config is None:
        return Config().validate()
    require(config.is_file(), f"config file {str(config)!r} does not exist")
    cfg = Config.from_dict(read_toml(config, "config file"))
    cfg.experiment = dataclasses.replace(cfg.experiment, filters=tuple(dict.fromkeys(families)))
    return cfg.validate()


def _suite_bins(config: Path | None, families: Sequence[str]) -> tuple[int, ...]:
    """The gap bins of a suite's configuration (the defaults without one)."""
    return suite_config(config, families).metrics.gap_bins


def _gap_values(run_dir: Path, scenario: str, bins: Sequence[int], sums: dict[tuple, list[float]]) -> None:
    """Add the kept / counted sums of every occlusion metric of one run folder's episodes.csv to ``sums`` (keyed by
    the value key's parts)."""
    e = read_csv(run_dir / "episodes.csv")
    if "gap_scans" not in e or not len(e["gap_scans"]):
        return
    n = np.array([float(v) if v != "" else math.nan for v in np.asarray(e["gap_scans"]).tolist()])
    which = np.searchsorted(np.asarray(bins), n, side="right") - 1
    for name, (column, i) in gap_metrics(bins).items():
        cells = np.array([float(v) if v != "" else math.nan for v in np.asarray(e[column]).tolist()])
        ok = np.isfinite(n) & (which == i) & np.isfinite(cells)
        for j in np.flatnonzero(ok):
            key = (scenario, str(e["model"][j]), str(e["mode"][j]), float(e["clutter"][j]), name)
            acc = sums.setdefault(key, [0.0, 0.0])
            acc[0] += cells[j]
            acc[1] += 1.0


def check_import_paths(suite: Suite) -> None:
    """Every import-path plugin a suite names must be allowed with ``--plugin`` (soabench.plugins: the closed list);
    said before anything runs, with the check command's advice."""

    typed = set(plugins.session_import_paths())
    for s in suite.scenarios:
        for name in (*s.models, *s.trackers):
            require(
                not plugins.is_import_path(name) or name in typed,
                f"{suite.path}: scenario {s.name!r} names the import-path plugin {name!r}; soabench imports only "
                f"built-ins, installed entry points and import paths allowed on the command line: add --plugin {name}",
            )


# ------------------------------------------------------------------------------------------------ running
def value_key(scenario: str, model: str, mode: str, clutter: float, metric: str) -> str:
    return f"{scenario}/{model}/{mode}/lambda={clutter:g}/{metric}"


def _refuse_protocol_keys(config: Path | None) -> None:
    """In a suite the ``[[scenario]]`` tables own the protocol (each experiment key has that one home): a
    ``[suite] config`` file that sets an ``[experiment]`` key is refused with one line naming both keys."""
    if config is None:
        return
    section = read_toml(config, "config file").get("experiment", {})  # suite_config read it
    if section:
        key = sorted(section)[0]
        raise SoabenchError(
            f"{config}: [experiment] {key} is set per scenario in a check suite ([[scenario]] "
            f"{SCENARIO_KEY_OF.get(key, key)}); remove it from the config file"
        )


def _config_for(base: Config, s: Scenario, seed: int) -> Config:
    cfg = Config.from_dict(base.to_dict())
    cfg.experiment = dataclasses.replace(
        cfg.experiment,
        trials=s.trials,
        duration=s.duration,
        models=s.models,
        trackers=s.trackers,
        probabilities=s.probabilities,
        clutter=s.clutter,
        seed=seed,
        filters=(s.filter,),
    )
    read = {f.section for f in FAMILIES.values() if f.name == s.filter}
    for section in {f.section for f in FAMILIES.values() if f.section is not None} - read:  # another scenario's
        setattr(cfg, section, type(getattr(cfg, section))())
    return cfg.validate()


@dataclass
class SuiteRun:
    """One run of a suite's scenarios: the mean of every metric per key, the plugin failures, what each scenario's
    runs took and the seconds spent compiling the kernels first."""

    values: dict[str, float]
    failures: list[dict]
    took: dict[str, ScenarioRuns]
    compile_s: float = 0.0


def check_scenarios(suite: Suite) -> Config:
    """Every scenario of ``suite`` as a run would take it (its plugins, models, trackers, modes and its scene, loaded
    once per process as the runs load it): a bad one is refused with one line naming it before any scenario runs or
    anything is written. Returns the suite's base configuration."""
    # imported when called: the scene loader brings SUMO's readers
    from soabench.experiment.trial.registry import load_scene_cached

    check_import_paths(suite)
    base = suite_config(suite.config, [s.filter for s in suite.scenarios])
    _refuse_protocol_keys(suite.config)
    for s in suite.scenarios:
        try:
            _config_for(base, s, s.seeds[0])
            load_scene_cached(s.net, tuple(str(p) for p in s.polys), s.scenario)
        except SoabenchError as exc:
            raise SoabenchError(f"{suite.path}: [[scenario]] {s.name!r}: {exc}") from None
    return base


def run_suite(suite: Suite, out: Path, workers: int | None = None, seed_offset: int = 0) -> SuiteRun:
    """Run every scenario and seed (each seed plus ``seed_offset``) and collect a :class:`SuiteRun`."""
    # imported when called: scipy would slow every start-up
    from soabench.experiment.execution.options import RunOptions
    from soabench.experiment.execution.runner import RunRequest
    from soabench.experiment.reports.finished import run
    from soabench.experiment.runs.store import RunStore
    from soabench.kernel_warmup import ensure_compiled

    base = check_scenarios(suite)
    # once, for every scenario; timed apart: a cold machine's compilation is not the suite's time
    compile_s = ensure_compiled([_config_for(base, s, s.seeds[0]) for s in suite.scenarios])
    rows: dict[tuple, list[dict]] = {}
    gap_sums: dict[tuple, list[float]] = {}
    bins = base.metrics.gap_bins
    failures: list[dict] = []
    took = {s.name: ScenarioRuns() for s in suite.scenarios}
    for s in suite.scenarios:
        for seed in (x + seed_offset for x in s.seeds):
            t0 = time.perf_counter()
            run_dir = out / "runs" / s.name / f"seed_{seed}"
            if run_dir.exists():
                shutil.rmtree(run_dir)
            cfg = _config_for(base, s, seed)
            options = RunOptions(workers=workers, progress=False, figures=False)
            o = run(RunRequest(cfg, s.net, s.polys, s.scenario, out=run_dir, options=options))
            require(o.complete, f"scenario {s.name!r} seed {seed}: {o.n_missing} trial(s) failed; see {run_dir}")
            failures += [{**f, "scenario": s.name, "seed": seed} for f in RunStore(run_dir).model_failures()]
            table = read_csv(run_dir / "trials.csv")
            _gap_values(run_dir, s.name, bins, gap_sums)
            n = len(table["model"])
            for i in range(n):
                key = (s.name, str(table["model"][i]), str(table["mode"][i]), float(table["clutter"][i]))
                rows.setdefault(key, []).append({c: table[c][i] for c in table})
            took[s.name].trials += s.trials
            took[s.name].time_s += time.perf_counter() - t0
    values: dict[str, float] = {}
    for (scen, model, mode, lam), rs in sorted(rows.items()):
        for col, v in rs[0].items():
            if col in ("trial", "seed", "sumo_seed", "clutter", "model", "mode") or not isinstance(
                v, (float, int, np.floating, np.integer)
            ):
                continue
            vals = np.array([float(r[col]) for r in rs])
            values[value_key(scen, model, mode, lam, col)] = float(np.mean(vals)) if len(vals) else math.nan
        for name in gap_metrics(bins):  # a labelled run with no gap in a bin: NaN, which fails its threshold
            kept, counted = gap_sums.get((scen, model, mode, lam, name), (0.0, 0.0))
            values[value_key(scen, model, mode, lam, name)] = kept / counted if counted else math.nan
    return SuiteRun(values, failures, took, compile_s)


def _matches(th: Threshold, key: str) -> bool:
    scen, model, mode, _lam, metric = key.split("/")
    return (
        metric == th.metric
        and (th.model == "*" or th.model == model)
        and (th.mode is None or th.mode == mode)
        and (th.scenario is None or th.scenario == scen)
    )


def evaluate(suite: Suite, values: dict[str, float], baseline: dict[str, float] | None) -> list[CheckResult]:
    """Apply every threshold to every value it matches (a threshold that matches nothing is a failed check)."""
    results = []
    for th in suite.thresholds:
        keys = [k for k in values if _matches(th, k)]
        if not keys:
            results.append(
                CheckResult(f"{th.scenario or '*'}/{th.model}/{th.mode or '*'}/{th.metric}", False, "no value matches")
            )
            continue
        for key in keys:
            v = values[key]
            bounds, bad = [], []
            if th.max is not None:
                bounds.append(f"<= {th.max:g}")
                bad += [] if v <= th.max else [f"{v:.6g} > max {th.max:g}"]
            if th.min is not None:
                bounds.append(f">= {th.min:g}")
                bad += [] if v >= th.min else [f"{v:.6g} < min {th.min:g}"]
            if th.relative:
                b = (baseline or {}).get(key)
                if b is None or not math.isfinite(b):
                    bad.append("no baseline value (run with --update-baseline)")
                else:
                    if th.max_increase is not None:
                        hi = b + abs(b) * th.max_increase + th.abs_tol
                        bounds.append(f"<= {hi:.6g} (baseline {b:.6g} +{100 * th.max_increase:g}%)")
                        bad += [] if v <= hi else [f"{v:.6g} > {hi:.6g} (baseline {b:.6g} +{100 * th.max_increase:g}%)"]
                    if th.max_decrease is not None:
                        lo = b - abs(b) * th.max_decrease - th.abs_tol
                        bounds.append(f">= {lo:.6g} (baseline {b:.6g} -{100 * th.max_decrease:g}%)")
                        bad += [] if v >= lo else [f"{v:.6g} < {lo:.6g} (baseline {b:.6g} -{100 * th.max_decrease:g}%)"]
            if not math.isfinite(v):
                bad = ["no result (NaN): no trial produced this value"]
            results.append(CheckResult(key, not bad, "; ".join(bad) or "ok", v, ", ".join(bounds)))
    return results


def read_baseline(path: Path) -> dict[str, float]:
    require(path.is_file(), f"baseline {str(path)!r} does not exist; create it with soabench check --update-baseline")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, RecursionError) as exc:  # not JSON, not UTF-8, or nested too deeply to read
        raise SoabenchError(f"baseline {str(path)!r} is not valid JSON: {type(exc).__name__}: {exc}") from None
    require(
        isinstance(data, dict) and data.get("format") == BASELINE_FORMAT and isinstance(data.get("values"), dict),
        f"baseline {str(path)!r} is not a soabench check baseline (format {BASELINE_FORMAT})",
    )
    return {str(k): float(v) if v is not None else math.nan for k, v in data["values"].items()}


def write_baseline(path: Path, suite: Suite, values: dict[str, float]) -> None:

    path.parent.mkdir(parents=True, exist_ok=True)
    clean = {k: (v if math.isfinite(v) else None) for k, v in values.items() if not _is_time(k)}
    write_json_atomic(path, {"format": BASELINE_FORMAT, "suite": suite.name, "values": clean})


def _is_time(key: str) -> bool:
    """Wall-clock columns differ between runs; they are never baselined."""
    return key.rsplit("/", 1)[-1].startswith("t_")


# ------------------------------------------------------------------------------------------------ reports
def _properties(indent: str, items: dict[str, Any]) -> list[str]:
    """A JUnit ``<properties>`` element (a CI server shows them beside the case)."""
    props = [f"{indent}  <property name={quoteattr(k)} value={quoteattr(str(v))}/>" for k, v in items.items()]
    return [f"{indent}<properties>", *props, f"{indent}</properties>"]


def junit_xml(outcome: CheckOutcome) -> str:
    """The checks as JUnit XML: one case per check with its value, bound, trials and time as properties; the
    suite's time is its runs', its compilation of the kernels a property of its own."""
    failures = sum(not r.passed for r in outcome.results)
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f"<testsuites><testsuite name={quoteattr('soabench check: ' + outcome.suite)} "
        f'tests="{len(outcome.results)}" failures="{failures}" errors="0" '
        f'time="{outcome.wall_s - outcome.compile_s:.3f}">',
        *_properties("  ", {"compile_s": f"{outcome.compile_s:.3f}", "wall_s": f"{outcome.wall_s:.3f}"}),
    ]
    for r in outcome.results:
        lines.append(
            f'  <testcase classname={quoteattr(outcome.suite)} name={quoteattr(r.name)} time="{r.time_s:.3f}">'
        )
        lines += _properties(
            "    ", {"value": f"{r.value:.6g}", "bound": r.bound, "trials": r.trials, "time_s": f"{r.time_s:.3f}"}
        )
        if not r.passed:
            lines.append(f"    <failure message={quoteattr(r.message)}>{escape(r.message)}</failure>")
        lines.append("  </testcase>")
    lines.append("</testsuite></testsuites>")
    return "\n".join(lines) + "\n"


def table(outcome: CheckOutcome) -> str:
    rows = [("check", "value", "bound", "result")]
    for r in outcome.results:
        rows.append((r.name, f"{r.value:.6g}", r.bound, "ok" if r.passed else f"FAIL: {r.message}"))
    widths = [max(len(row[i]) for row in rows) for i in range(3)]
    out = [" | ".join(c.ljust(w) for c, w in zip(row[:3], widths, strict=True)) + " | " + row[3] for row in rows]
    out.insert(1, "-" * len(out[0]))
    n_fail = sum(not r.passed for r in outcome.results)
    verdict = "PASS" if not n_fail else f"FAIL ({n_fail} of {len(outcome.results)} checks)"
    return "\n".join(out) + f"\n\nsoabench check {outcome.suite}: {verdict}\n"


@dataclass
class Proposal:
    """A threshold proposed from N repetitions of the suite: the values' mean, standard deviation and the 95 %
    prediction bounds of one further run."""

    key: str
    runs: int
    mean: float
    std: float
    low: float
    high: float
    threshold: str


def propose(suite: Suite, repetitions: list[dict[str, float]]) -> list[Proposal]:
    """Every value a threshold of ``suite`` reads, over ``repetitions`` (one dict of values per run of the suite):
    its prediction bounds and the threshold they give (``min``/``max`` as the suite's threshold sets, the relative
    ones as a fraction of the mean)."""
    # imported when called: scipy would slow every start-up
    from scipy.stats import t as student_t

    out = []
    n = len(repetitions)
    for th in suite.thresholds:
        lo_m, hi_m = metric_range(th.metric)
        for key in (k for k in repetitions[0] if _matches(th, k)):
            v = np.array([r.get(key, math.nan) for r in repetitions], dtype=float)
            v = v[np.isfinite(v)]
            mean = float(v.mean()) if v.size else math.nan
            std = float(v.std(ddof=1)) if v.size > 1 else math.nan
            half = float(student_t.ppf(0.975, v.size - 1) * std * math.sqrt(1 + 1 / v.size)) if v.size > 1 else math.nan
            # a bound past the metric's range would be refused by the suite: it stops at the range's edge, and says
            # the value is too noisy to bound
            lo, hi = max(mean - half, lo_m), min(mean + half, hi_m)
            noisy = " (the band passes the metric's range: too noisy to bound, add trials)"
            parts = []
            if th.min is not None:
                parts.append(f"min = {lo:.6g}" + noisy * (mean - half < lo_m))
            if th.max is not None:
                parts.append(f"max = {hi:.6g}" + noisy * (mean + half > hi_m))
            rel = half / abs(mean) if mean else math.nan
            if th.max_increase is not None:
                parts.append(f"max_increase = {rel:.3g}")
            if th.max_decrease is not None:
                parts.append(f"max_decrease = {rel:.3g}")
            out.append(Proposal(key, n, mean, std, lo, hi, ", ".join(parts)))
    return out


def calibration_table(proposals: list[Proposal]) -> str:
    rows = [("value", "runs", "mean", "std", "95 % low", "95 % high", "proposed threshold")]
    for p in proposals:
        nums = (f"{p.mean:.6g}", f"{p.std:.3g}", f"{p.low:.6g}", f"{p.high:.6g}")
        rows.append((p.key, str(p.runs), *nums, p.threshold))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]
    return "\n".join(lines) + "\n"


def run_calibration(
    suite_path: str | Path, out: Path, n: int, workers: int | None = 1, plugin_paths: Sequence[str] = ()
) -> int:
    """``soabench check --calibrate N``: the suite's scenarios N times on fresh seeds, and the thresholds their
    spread supports (:func:`propose`), printed and written to ``calibration.json``."""
    require(isinstance(n, int) and n >= 2, f"--calibrate {n} must be an integer >= 2 (a spread needs two runs)")
    require(workers is None or workers >= 1, f"--workers {workers} must be >= 1")
    plugins.allow_import_paths(plugin_paths)
    suite = load_suite(suite_path)
    require(bool(suite.thresholds), f"{suite.path}: no [[threshold]] to calibrate")
    check_scenarios(suite)  # before the folder is made
    out = resolve(out)
    check_own_folder(out, "check folder", CHECK_ENTRIES)
    with FolderLock(out, "check folder"):
        check_own_folder(out, "check folder", CHECK_ENTRIES)
        repetitions = []
        for r in range(n):
            done = run_suite(suite, out, workers, seed_offset=r * CALIBRATION_SEED_STRIDE)
            values, failures = done.values, done.failures
            if failures:  # a calibration of a failing plugin would propose bounds for runs that did not happen
                raise SoabenchError(f"a plugin run failed in repetition {r + 1}: {failure_message(failures[0])}")
            repetitions.append(values)
        proposals = propose(suite, repetitions)
        write_json_atomic(
            out / "calibration.json",
            {"suite": suite.name, "repetitions": n, "seed_stride": CALIBRATION_SEED_STRIDE,
             "proposals": [dataclasses.asdict(p) for p in proposals]},
        )  # fmt: skip
    sys.stdout.write(calibration_table(proposals))
    print(
        f"soabench check {suite.name}: {n} runs on fresh seeds; a further run stays inside the 95 % bounds with "
        f"probability 0.95 (the bounds narrow as 1/√trials: more trials per scenario, tighter thresholds); wrote "
        f"{out / 'calibration.json'}"
    )
    print(STABILITY_NOTE if n >= 10 else f"{STABILITY_NOTE} {n} runs are few: calibrate with 10 or more.")
    return 0


def run_check(
    suite_path: str | Path,
    out: Path,
    update_baseline: bool = False,
    workers: int | None = 1,
    plugin_paths: Sequence[str] = (),
) -> int:
    """The ``check`` command: exit status 0 (every check passed) or 1 (a regression). ``plugin_paths``: the
    ``module:Class`` plugins the suite may name (entry-point plugins need none)."""
    require(workers is None or workers >= 1, f"--workers {workers} must be >= 1")
    for name in plugin_paths:
        require(":" in name, f"--plugin {name!r} must be MODULE:CLASS (installed entry-point plugins need no --plugin)")
    plugins.allow_import_paths(plugin_paths)
    t0 = time.perf_counter()
    suite = load_suite(suite_path)
    baseline = None
    if any(th.relative for th in suite.thresholds) and not update_baseline:
        baseline = read_baseline(suite.baseline)  # a missing baseline is a user error, before any run

    check_scenarios(suite)  # before the folder is made
    out = resolve(out)
    check_own_folder(out, "check folder", CHECK_ENTRIES)
    with FolderLock(out, "check folder"):
        check_own_folder(out, "check folder", CHECK_ENTRIES)  # again, under the lock
        return _check_locked(suite, out, baseline, update_baseline, workers, t0)


def _check_locked(
    suite: Suite, out: Path, baseline: dict[str, float] | None, update_baseline: bool, workers: int | None, t0: float
) -> int:
    """The body of :func:`run_check` once ``out`` is checked and locked."""
    done = run_suite(suite, out, workers)
    values, failures, took, compile_s = done.values, done.failures, done.took, done.compile_s
    if update_baseline:
        require(suite.baseline is not None, f'{suite.path}: --update-baseline needs [suite] baseline = "FILE.json"')
        write_baseline(suite.baseline, suite, values)
        print(f"wrote baseline {suite.baseline} ({sum(not _is_time(k) for k in values)} values)")
        baseline = read_baseline(suite.baseline)
    outcome = CheckOutcome(suite.name, values, evaluate(suite, values, baseline), compile_s=compile_s)

    for f in failures:
        outcome.results.append(CheckResult(f"{f['scenario']}/{f['model']}/plugin", False, failure_message(f)))
    for r in outcome.results:  # each check carries its scenario's trials and time
        runs = took.get(r.name.split("/", 1)[0])
        if runs is not None:
            r.trials, r.time_s = runs.trials, runs.time_s
    outcome.wall_s = time.perf_counter() - t0

    write_json_atomic(
        out / "check.json",
        {
            "suite": suite.name,
            "passed": outcome.passed,
            "wall_s": outcome.wall_s,
            "compile_s": outcome.compile_s,
            "values": {k: (v if math.isfinite(v) else None) for k, v in values.items()},
            "checks": [
                {**dataclasses.asdict(r), "value": r.value if math.isfinite(r.value) else None} for r in outcome.results
            ],
        },
    )
    write_text_atomic(out / "junit.xml", junit_xml(outcome))
    sys.stdout.write(table(outcome))
    print(f"wrote {out / 'check.json'} and {out / 'junit.xml'}")
    return 0 if outcome.passed else 1
