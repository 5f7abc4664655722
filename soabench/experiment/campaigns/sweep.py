"""Parameter sweeps over clutter rate and expected births N̂ (docs/method.md §5.5, §5.8; paper Fig. 5h, §V.C).

* ``clutter`` (values such as 0.5, 3, 5): one run with ``experiment.clutter = values``; every trial's truth and
  detections are shared across lambda (common random numbers, :mod:`soabench.seeding`), so one run gives the
  precision curves and every metric per lambda.
* ``births`` (offsets such as -10..10): one run per ``N_tot = max(1, N_true + o)`` (duplicates after clipping
  dropped), with ``N̂_k = N_tot / K`` and ``K = duration / dt`` scans (register row 24); models S-OA, PUBM, both UBMs
  unless ``models`` is given or the config names other than all six. The table reports k̄_delay over all counted
  episodes vs N_tot per model and mode, and the std of those means (population, ddof = 0) as in the paper's §V.C.

Layout (``results/<net>/sweep-<kind>-<UTC timestamp>/``)::

    sweep.json              kind, values, points, base config, net (written at start)
    points/<name>/          one ordinary run folder per point (resumable on its own)
    sweep_summary.json      the sweep table's numbers
    sweep.md                the sweep table (Markdown)
    sweep_<kind>.png        the sweep figure

A sweep of several filter families (``experiment.filters``, ``--filters``) runs every point in each; ``sweep.md``
has one section per family (its table and Tracks table), ``sweep_summary.json`` the first family's table under
``table`` and every family's under ``families`` (births) or a ``filter`` per row (clutter, occlusion); the sweep
figure draws the first family. A sweep of the GM-PHD alone has no sections (docs/user-guide/outputs.md).

``sweep(SweepRequest(..., run=RunRequest(..., resume=SWEEP_DIR)))`` resumes every unfinished point and starts the ones
never started.

An N̂ sweep with the built-in trial kind runs its points together (:mod:`soabench.experiment.execution.grouped`): trial n
runs SUMO and the sensor once and every N_tot point's filters on them, then writes each point's record into its
own folder; the results are those of running the points one after another.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from soabench.atomic import write_json_atomic, write_text_atomic
from soabench.birth import CORE_MODELS, LABEL
from soabench.config import BIRTH_MODEL_NAMES, Config, require_distinct
from soabench.errors import Interrupted, require
from soabench.experiment.campaigns.families import config_families, family_heading, first_family_note
from soabench.experiment.campaigns.occlusion import (
    check_parking_lanes,
    occlusion_points,
    occlusion_report,
    write_point_scenarios,
)
from soabench.experiment.execution.executors import open_executor
from soabench.experiment.execution.grouped import group_trials, run_group
from soabench.experiment.execution.runner import (
    ALONE,
    BATCH_FIELDS,
    Batch,
    RunOutcome,
    RunRequest,
    _utc_stamp,
    check_against_scenario,
    scenario_name,
)
from soabench.experiment.reports.finished import run as run_one
from soabench.experiment.reports.paper import read_rows
from soabench.experiment.reports.premerge import merged_on
from soabench.experiment.reports.report import fmt
from soabench.experiment.runs.files import read_csv, read_json
from soabench.experiment.runs.runmeta import check_requested, flatten_config, validate_sweep_meta
from soabench.experiment.trial.registry import load_scene_cached
from soabench.figures.drawing import parallel
from soabench.folders import FolderLock, check_existing_folder, check_new_folder, resolve
from soabench.tracks.report import render_hota

SWEEP_FILE = "sweep.json"
KINDS = ("clutter", "births", "occlusion")
#: each kind's points when none are given (§5.8): clutter rates; N_tot offsets from N_TRUE; parked cars per 100 m
DEFAULT_VALUES: dict[str, tuple[float, ...]] = {
    "clutter": (0.5, 3.0, 5.0),
    "births": tuple(range(-10, 11)),
    "occlusion": (0.0, 4.0, 8.0, 12.0),
}
N_TRUE = 6


def sweep_values(
    kind: str, values: Sequence[float] | None, offsets: Sequence[int] | None, given_keys: set[str]
) -> tuple[float, ...]:
    """The points of a new sweep: ``values`` (clutter rates, parked cars per 100 m) or ``offsets`` (N_tot offsets of
    ``births``), each kind's :data:`DEFAULT_VALUES` when not given. ``given_keys``: the dotted config keys the user
    set; ``clutter`` refuses ``experiment.clutter`` beside its points (λ has one home, docs/user-guide/parameters.md).
    """
    if kind == "clutter":
        require(
            "experiment.clutter" not in given_keys,
            "`sweep clutter` takes its clutter rates from --values; drop --clutter and [experiment] clutter",
        )
    if kind in ("clutter", "occlusion"):
        require(offsets is None, f"--offsets belongs to `sweep births`; use --values for `sweep {kind}`")
        return tuple(values or DEFAULT_VALUES[kind])
    require(
        values is None, "--values belongs to `sweep clutter` and `sweep occlusion`; use --offsets for `sweep births`"
    )
    return tuple(offsets) if offsets is not None else DEFAULT_VALUES["births"]


@dataclass
class SweepOutcome:
    """Like :class:`~soabench.experiment.execution.runner.RunOutcome`, summed over the sweep points."""

    run_dir: Path
    complete: bool
    n_done: int
    n_missing: int
    failures: list[dict] = field(default_factory=list)
    summary_markdown: str = ""
    points: list[RunOutcome] = field(default_factory=list)


def scans_per_run(config: Config) -> int:
    """K = duration / dt (scans per trial)."""
    return max(1, int(round(config.experiment.duration / config.sensor.dt)))


def sweep_points(
    kind: str, values: Sequence[float], config: Config, models: Sequence[str] | None = None, n_true: int = N_TRUE
) -> list[dict]:
    """The points of a sweep: ``{"name", "value", "config"}`` (config as a dict)."""
    require(kind in KINDS, f"sweep kind {kind!r} is unknown; choose one of {', '.join(KINDS)}")
    require(len(values) >= 1, "a sweep needs at least one value")
    require_distinct({"births": "offsets"}.get(kind, "values"), tuple(values))
    base = Config.from_dict(config.to_dict())
    if models is not None:
        base.experiment = dataclasses.replace(base.experiment, models=tuple(models))
    if kind == "occlusion":  # soabench/experiment/campaigns/occlusion.py: one point per parked-car density
        base.validate()
        return occlusion_points(values, base.to_dict())
    if kind == "clutter":
        vals = tuple(float(v) for v in values)
        base.experiment = dataclasses.replace(base.experiment, clutter=vals)
        base.validate()
        return [{"name": "clutter", "value": list(vals), "config": base.to_dict()}]
    if models is None and tuple(base.experiment.models) == BIRTH_MODEL_NAMES:  # the default set -> §5.8's three
        base.experiment = dataclasses.replace(base.experiment, models=CORE_MODELS)
    for v in values:
        require(float(v) == int(v), f"births offset {v!r} must be an integer")
    K = scans_per_run(base)
    n_tots = sorted({max(1, int(n_true) + int(o)) for o in values})
    points = []
    for n_tot in n_tots:
        cfg = Config.from_dict(base.to_dict())
        cfg.birth = dataclasses.replace(cfg.birth, N_hat=n_tot / K)
        cfg.validate()
        points.append({"name": f"ntot_{n_tot:03d}", "value": n_tot, "N_hat": n_tot / K, "config": cfg.to_dict()})
    return points


@dataclass(frozen=True)
class SweepRequest:
    """What a sweep is asked to do: ``kind`` over ``values``, each point a run of ``run`` (its configuration, scene,
    options and trial kind; ``run.out``/``run.resume``: the sweep folder, new or to finish; ``run.requested``: what
    a resume asked for, dotted config keys, ``net``, ``polys``, ``scenario``, ``values``, ``kind``: differences are
    refused except more ``experiment.trials``, which extends every point).

    ``models``: the birth models of every point (None: the config's, the N̂ sweep's three by default); ``n_true``:
    the expected births N_true around which an N̂ sweep's offsets lie. ``grouped``: an N̂ sweep runs its points'
    trials together (module docstring); False runs point after point (the same results, slower; for benchmarks).
    ``run.options.figures``: draw each point's own figures (its ``figures/``); None draws them for the clutter and
    occlusion points and not for the N̂ sweep's, whose ``sweep_births.png`` summarises its points (their tables and
    summaries are written either way).
    """

    kind: str
    values: tuple[float, ...]
    run: RunRequest
    models: tuple[str, ...] | None = None
    n_true: int = N_TRUE
    grouped: bool = True


def run_sweep(kind: str, values: Sequence[float], config: Config | None, net: str, polys: Sequence[str] = (),
              scenario: str | None = None, **fields: Any) -> SweepOutcome:  # fmt: skip
    """:func:`sweep` of a :class:`SweepRequest`; ``fields``: ``models``, ``n_true``, ``grouped``, the other
    :class:`~soabench.experiment.execution.runner.RunRequest` fields and the
    :class:`~soabench.experiment.execution.runner.Batch` fields."""
    batch = Batch(**{k: fields.pop(k) for k in BATCH_FIELDS if k in fields})
    own = {k: fields.pop(k) for k in ("models", "n_true", "grouped") if k in fields}
    if own.get("models") is not None:
        own["models"] = tuple(own["models"])
    run_request = RunRequest(config, net, tuple(polys), scenario, **fields)
    return sweep(SweepRequest(kind, tuple(values), run_request, **own), batch)


def sweep(request: SweepRequest, batch: Batch = ALONE) -> SweepOutcome:
    """Run (or resume) a sweep; each point is its own run folder under ``points/``.

    ``request.run.options`` (:class:`~soabench.experiment.execution.options.RunOptions`) serve every point; one
    executor (pool or Dask cluster) serves them all. The sweep table and figure are written once every point has
    attempted all trials. The folder is resolved, checked and locked like a run folder; on resume, every value of
    ``sweep.json`` is validated and compared with ``request.run.requested``. ``batch`` applies to every point.
    """
    if request.run.options.figures is None:
        options = dataclasses.replace(request.run.options, figures=request.kind != "births")
        request = dataclasses.replace(request, run=dataclasses.replace(request.run, options=options))
    locks: list[FolderLock] = []
    try:
        if request.run.resume is not None:
            sweep_dir = resolve(request.run.resume)
            check_existing_folder(sweep_dir, SWEEP_FILE, "sweep")
            locks.append(FolderLock(sweep_dir, "sweep folder").acquire())
            request, points, more = _resumed_sweep(sweep_dir, request)
        else:
            sweep_dir, points = _new_sweep(request, locks)
            more = None
        return _run_points(sweep_dir, points, more, request, batch)
    finally:
        for lock in locks:
            lock.release()


def _resumed_sweep(sweep_dir: Path, request: SweepRequest) -> tuple[SweepRequest, list[dict], int | None]:
    """A sweep folder's stored request and points, and the trials a resume asks every point for (None: as stored);
    every other difference from what the resume asked for is refused."""
    where = str(sweep_dir / SWEEP_FILE)
    meta = validate_sweep_meta(read_json(sweep_dir / SWEEP_FILE), where, KINDS)
    kind, net, polys, scenario = meta["kind"], meta["net"], tuple(meta["polys"]), meta["scenario"]
    points = meta["points"]
    more = None
    if request.run.requested:
        swept = "birth.N_hat" if kind == "births" else "experiment.clutter"
        stored = {"kind": kind, "net": net, "polys": list(polys), "scenario": scenario}
        stored["values"] = [float(v) for v in meta.get("values", [])]
        stored.update({k: v for k, v in flatten_config(points[0]["config"]).items() if k != swept})
        req = {k: v for k, v in request.run.requested.items() if k != swept}
        if "values" in req:
            req["values"] = [float(v) for v in req["values"]]
        more = check_requested(stored, req, f"sweep folder {str(sweep_dir)!r}")
    if more is not None:  # safe: trial n's seeds depend only on (seed, n); every point gets the new count
        for p in points:
            p["config"]["experiment"]["trials"] = more
        if isinstance(meta.get("base_config"), dict):
            meta["base_config"].setdefault("experiment", {})["trials"] = more
        write_json_atomic(sweep_dir / SWEEP_FILE, meta)
    run_request = dataclasses.replace(request.run, net=net, polys=polys, scenario=scenario)
    return dataclasses.replace(request, kind=kind, run=run_request), points, more


def _new_sweep(request: SweepRequest, locks: list[FolderLock]) -> tuple[Path, list[dict]]:
    """A new sweep's folder (checked, locked: the lock joins ``locks``) with its ``sweep.json``, and its points."""
    kind, values, run = request.kind, request.values, request.run
    require(run.config is not None, "run_sweep needs a config (or resume=SWEEP_DIR)")
    points = sweep_points(kind, values, run.config, request.models, request.n_true)
    # the network and the config cross-checks, before the folder is written
    _, scenario_cfg = load_scene_cached(run.net, run.polys, run.scenario, run.load_fn)
    check_against_scenario(run.config, scenario_cfg)
    if kind == "occlusion":
        check_parking_lanes(scenario_cfg.net_file, values)
    name = scenario_name(run.net, scenario_cfg)
    default = Path("results") / name / f"sweep-{kind}-{_utc_stamp()}"
    sweep_dir = resolve(run.out if run.out is not None else default)
    hint = f"finish it with: soabench sweep {kind} --resume {sweep_dir}"
    check_new_folder(sweep_dir, SWEEP_FILE, "sweep", hint)
    locks.append(FolderLock(sweep_dir, "sweep folder").acquire())
    check_new_folder(sweep_dir, SWEEP_FILE, "sweep", hint)
    if kind == "occlusion":  # one scenario file per density point, written into the sweep folder
        write_point_scenarios(sweep_dir, points, run.net, run.scenario)
    meta = {
        "kind": kind,
        "values": [float(v) for v in values],
        "n_true": int(request.n_true),
        "net": str(run.net),
        "net_name": name,
        "polys": [str(p) for p in run.polys],
        "scenario": run.scenario,
        "base_config": run.config.to_dict(),
        "created": _utc_stamp(),
        "points": points,
    }
    write_json_atomic(sweep_dir / SWEEP_FILE, meta)
    return sweep_dir, points


def _run_points(
    sweep_dir: Path, points: list[dict], more: int | None, request: SweepRequest, batch: Batch
) -> SweepOutcome:
    """The points of a checked, locked sweep folder, one after another on one executor, or together
    (:mod:`soabench.experiment.execution.grouped`): an N̂ sweep of the built-in trial kind, or any sweep given
    ``batch.defer``."""
    kind, run = request.kind, request.run
    grouped = request.grouped and batch.defer is None and batch.run_trials and kind == "births"
    if grouped and run.trial_fn is None and len(points) > 1:
        return _run_points_grouped(sweep_dir, points, more, request)
    hint = f"finish with: soabench sweep {kind} --resume {sweep_dir}"
    n_trials_total = sum(int(p["config"]["experiment"]["trials"]) for p in points)
    deferring = batch.defer is not None or not batch.run_trials
    outcomes: list[RunOutcome] = []
    options = run.options
    exe = None if deferring else open_executor(options.workers, options.scheduler, options.dask_local, n_trials_total)
    # the points run on this sweep's executor; a report's figures on its pool, or on one process per core
    point_options = dataclasses.replace(options, workers=None, scheduler=None, dask_local=False)
    point_batch = dataclasses.replace(batch, executor=exe)
    stopped = False
    aborted = True  # until the loop ends normally (Ctrl-C, errors): terminate the workers on the way out
    try:
        for p in points:
            pdir = sweep_dir / "points" / p["name"]
            point = dataclasses.replace(run, options=point_options, scenario=p.get("scenario", run.scenario))
            if (pdir / "run.json").is_file():
                req = {"experiment.trials": more} if more is not None else None
                point = dataclasses.replace(point, config=None, out=None, resume=pdir, requested=req)
            else:
                point = dataclasses.replace(point, config=Config.from_record(p["config"]), out=pdir, resume=None,
                                            requested=None)  # fmt: skip
            o = run_one(point, point_batch)
            outcomes.append(o)
            if not o.summary_markdown and batch.defer is None:  # the point did not attempt every trial (--fail-fast)
                stopped = True
                break
        aborted = stopped
    except KeyboardInterrupt:
        done = sum(o.n_done for o in outcomes)
        raise Interrupted(f"interrupted: sweep {sweep_dir} is incomplete ({done}+ trials on disk); {hint}") from None
    finally:
        if exe is not None:
            exe.close(abort=aborted)
    if batch.defer is not None:
        return _sweep_outcome(sweep_dir, points, outcomes)
    failures = [{"point": p["name"], **f} for p, o in zip(points, outcomes, strict=False) for f in o.failures]
    n_done = sum(o.n_done for o in outcomes)
    n_missing = n_trials_total - n_done
    outcome = SweepOutcome(sweep_dir, n_missing == 0, n_done, n_missing, failures, "", outcomes)
    if stopped or len(outcomes) < len(points):
        return outcome
    try:
        outcome.summary_markdown = write_sweep_report(sweep_dir)
    except KeyboardInterrupt:
        raise Interrupted(f"interrupted while writing the sweep report of {sweep_dir}; {hint}") from None
    return outcome


def _run_points_grouped(sweep_dir: Path, points: list[dict], more: int | None, request: SweepRequest) -> SweepOutcome:
    """An N̂ sweep's points run together: every folder checked and deferred, their trials run as one group, then
    (every trial attempted) the points merged on the workers and reported, and the sweep's report."""
    hint = f"finish with: soabench sweep {request.kind} --resume {sweep_dir}"
    deferred: list = []
    _run_points(sweep_dir, points, more, request, Batch(defer=deferred))
    if not deferred:  # every trial is attempted: the points' reports and the sweep's
        return _run_points(sweep_dir, points, None, request, Batch(run_trials=False))
    options = request.run.options
    exe = open_executor(options.workers, options.scheduler, options.dask_local, n_trials=len(group_trials(deferred)))
    aborted = True
    try:
        stopped, _ = run_group(deferred, exe, fail_fast=options.fail_fast, progress=options.progress,
                               label=sweep_dir.name)  # fmt: skip
        if stopped:
            return _sweep_outcome(sweep_dir, points, [_stopped_outcome(d) for d in deferred])
        # every trial is attempted: the points merged on the workers, then the points' reports (their figures
        # drawn on the same workers) and the sweep's
        with parallel(exe), merged_on(exe, deferred):
            outcome = _run_points(sweep_dir, points, None, request, Batch(run_trials=False))
        aborted = False
        return outcome
    except KeyboardInterrupt:
        raise Interrupted(f"interrupted: sweep {sweep_dir} is incomplete; {hint}") from None
    finally:
        exe.close(abort=aborted)


def _stopped_outcome(d: Any) -> RunOutcome:
    """The outcome of a deferred point after a group stopped by ``--fail-fast``."""
    n_done = len(d.store.done_trials())
    return RunOutcome(d.store.run_dir, False, n_done, d.n_trials - n_done, d.store.failures())


def _sweep_outcome(sweep_dir: Path, points: list[dict], outcomes: list[RunOutcome]) -> SweepOutcome:
    """A sweep outcome without a report (its points are deferred or were stopped)."""
    n_total = sum(int(p["config"]["experiment"]["trials"]) for p in points)
    n_done = sum(o.n_done for o in outcomes)
    failures = [{"point": p["name"], **f} for p, o in zip(points, outcomes, strict=False) for f in o.failures]
    return SweepOutcome(sweep_dir, False, n_done, n_total - n_done, failures, "", outcomes)


# ------------------------------------------------------------------------------------------------ sweep report
def _episode_means(
    run_dir: Path, models: Sequence[str], modes: Sequence[str], clutter: float, family: str | None = None
) -> dict[tuple[str, str], tuple[float, float]]:
    """k̄_delay over all counted episodes of a run per (model, mode) (of filter family ``family`` when not None),
    and the half-width of its 95 % confidence interval over trials (:func:`~soabench.figures.bars.pooled_mean_ci`)."""
    # imported when called: matplotlib would slow every start-up
    from soabench.figures.bars import pooled_mean_ci

    e = read_csv(run_dir / "episodes.csv")
    out = {}
    for model in models:
        for mode in modes:
            if not e or "delay" not in e or len(e["delay"]) == 0:
                out[(model, mode)] = (math.nan, math.nan)
                continue
            m = (e["model"] == model) & (e["mode"] == mode) & (e["clutter"] == clutter) & (e["censored"] == 0)
            if family is not None:
                m &= e["filter"] == family
            d, trials = e["delay"][m], e["trial"][m]
            trials = trials[~np.isnan(d)]
            d = d[~np.isnan(d)]
            out[(model, mode)] = (float(d.mean()), pooled_mean_ci(d, trials)) if d.size else (math.nan, math.nan)
    return out


def _births_table(
    sweep_dir: Path, points: list[dict], cols: tuple[Sequence[str], Sequence[str]], clutter: float, family: str | None
) -> tuple[list[dict], list[dict], dict[str, float]]:
    """One filter family's N̂ table: k̄_delay per N_tot point and (model, mode), the 95 % CI half-widths (the
    figure's error bars; not in the sweep's tables) and the std of the means over N_tot."""
    models, modes = cols
    table, half = [], []
    for p in points:
        means = _episode_means(sweep_dir / "points" / p["name"], models, modes, clutter, family)
        table.append(
            {"N_tot": p["value"], "N_hat": p["N_hat"], "delay": {f"{a}/{b}": v[0] for (a, b), v in means.items()}}
        )
        half.append({f"{a}/{b}": v[1] for (a, b), v in means.items()})
    std = {}
    for c in (f"{a}/{b}" for a in models for b in modes):
        v = np.array([r["delay"][c] for r in table], dtype=float)
        v = v[~np.isnan(v)]
        std[c] = float(v.std(ddof=0)) if v.size else math.nan
    return table, half, std


def _births_tracks(sweep_dir: Path, points: list[dict], family: str | None) -> list[tuple]:
    """The Tracks rows of one filter family per N_tot point (from each point's summary.json)."""
    return [
        (str(p["value"]), LABEL.get(mo, mo), md, st)
        for p in points
        if (sweep_dir / "points" / p["name"] / "summary.json").is_file()
        for res in [r for r in read_json(sweep_dir / "points" / p["name"] / "summary.json")["results"]
                    if r.get("filter") == family][:1]
        for mo, md, st in res.get("tracks", {}).get("rows", [])
    ]  # fmt: skip


def births_report(sweep_dir: Path, meta: dict) -> tuple[dict, str]:
    """k̄_delay vs N_tot per model and mode, and the std of those means (paper §V.C), per filter family."""
    points = meta["points"]
    exp = points[0]["config"]["experiment"]
    models, modes, clutter = [*exp["models"], *exp.get("trackers", ())], exp["probabilities"], float(exp["clutter"][0])
    cols = [f"{a}/{b}" for a in models for b in modes]
    head = [f"{LABEL.get(a, a)} {b}" for a in models for b in modes]
    K = scans_per_run(Config.from_record(points[0]["config"]))
    lines = [
        f"# N̂ sensitivity sweep: {meta.get('net_name')}",
        "",
        f"k̄_delay (s) over all counted episodes vs the expected births per run N_tot (N̂_k = N_tot / K, "
        f"K = {K} scans, N_true = {meta['n_true']}), λ = {clutter:g}, "
        f"{exp['trials']} trials per point.",
    ]
    sections = []
    for family in config_families(meta["points"][0]["config"]):
        table, half, std = _births_table(sweep_dir, points, (models, modes), clutter, family)
        lines += [*family_heading(family), "", "| N_tot | N̂_k | " + " | ".join(head) + " |"]
        lines.append("|---|---|" + "---|" * len(cols))
        for r in table:
            lines.append(f"| {r['N_tot']} | {r['N_hat']:.4g} | " + " | ".join(fmt(r["delay"][c]) for c in cols) + " |")
        lines.append("| std over N_tot | | " + " | ".join(fmt(std[c]) for c in cols) + " |")
        tracks = _births_tracks(sweep_dir, points, family)
        hota = render_hota("N_tot", tracks)
        if hota:
            lines += ["", "Tracks (docs/method.md §9.3): mean ± σ over trials; — for a tracker without labels.", ""]
            lines += hota
        sections.append((family, table, half, std, tracks))
    # imported when called: matplotlib would slow every start-up
    from soabench.figures.style import save_png
    from soabench.figures.sweeps import births_figure

    _, table, half, std, tracks = sections[0]  # the figure and the summary's table: the first family
    save_png(births_figure(table, models, modes, meta["n_true"], half), sweep_dir / "sweep_births.png")
    lines += ["", "Figure: `sweep_births.png`" + first_family_note([f[0] for f in sections])]
    summary = {"kind": "births", "table": table, "std_over_N_tot": std, "tracks": [list(t) for t in tracks]}
    if len(sections) > 1:
        summary["families"] = [
            {"filter": f, "table": t, "std_over_N_tot": sd, "tracks": [list(x) for x in tr]}
            for f, t, _, sd, tr in sections
        ]
    return summary, "\n".join(lines) + "\n"


def clutter_report(sweep_dir: Path, meta: dict) -> tuple[dict, str]:
    """Precision, recall, cardinality error, OSPA and k̄_delay per lambda, model and mode (Fig. 5h), per filter
    family."""
    run_dir = sweep_dir / "points" / meta["points"][0]["name"]
    summary = read_json(run_dir / "summary.json")
    lines = [
        f"# Clutter sweep: {meta.get('net_name')}",
        "",
        "One run with every clutter rate (trials share truth and detections across λ); per-run details in "
        f"`points/{meta['points'][0]['name']}/summary.md`.",
    ]
    rows, tracks = [], []
    families = config_families(meta["points"][0]["config"])
    for family in families:
        results = [res for res in summary["results"] if res.get("filter") == family]
        named = {} if family is None else {"filter": family}
        fam_rows = [{"clutter": res["clutter"], **named, **s} for res in results for s in res["models"]]
        lines += [*family_heading(family), ""]
        lines.append("| λ | model | mode | precision | recall | card. error | OSPA (m) | k̄ delay (s) |")
        lines.append("|---|---|---|---|---|---|---|---|")
        for r in fam_rows:
            lines.append(
                f"| {r['clutter']:g} | {LABEL.get(r['model'], r['model'])} | {r['mode']} "
                f"| {fmt(r['precision_mean'])} | {fmt(r['recall_mean'])} | {fmt(r['card_err_mean'])} "
                f"| {fmt(r['ospa_mean'])} | {fmt(r['delay_mean'])} |"
            )
        fam_tracks = [
            (f"{res['clutter']:g}", LABEL.get(mo, mo), md, st)
            for res in results
            for mo, md, st in res.get("tracks", {}).get("rows", [])
        ]
        hota = render_hota("λ", fam_tracks)
        if hota:
            lines += ["", "Tracks (docs/method.md §9.3): mean ± σ over trials; — for a tracker without labels.", ""]
            lines += hota
        rows += fam_rows
        tracks += [list(t) if family is None else [family, *t] for t in fam_tracks]
    # imported when called: matplotlib would slow every start-up
    from soabench.figures.style import save_png
    from soabench.figures.sweeps import clutter_figure

    exp = meta["points"][0]["config"]["experiment"]
    trial_rows = [r for r in read_rows(run_dir / "trials.csv") if r.get("filter") == families[0]]
    save_png(clutter_figure(trial_rows, exp["models"], exp["probabilities"]), sweep_dir / "sweep_clutter.png")
    fig5h = f"points/{meta['points'][0]['name']}/figures/fig5h_precision.png"
    lines += ["", f"Figures: `sweep_clutter.png`{first_family_note(families)}, `{fig5h}`"]
    return {"kind": "clutter", "table": rows, "tracks": tracks}, "\n".join(lines) + "\n"


def write_sweep_report(sweep_dir: Path) -> str:
    """Write sweep.md, sweep_summary.json and the sweep figure from the points' CSV files; return the Markdown."""
    sweep_dir = Path(sweep_dir)
    meta = read_json(sweep_dir / SWEEP_FILE)

    report = {"births": births_report, "clutter": clutter_report, "occlusion": occlusion_report}[meta["kind"]]
    data, md = report(sweep_dir, meta)
    write_json_atomic(sweep_dir / "sweep_summary.json", data)
    write_text_atomic(sweep_dir / "sweep.md", md)
    return md
