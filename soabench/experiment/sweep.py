"""Parameter sweeps over clutter rate and expected births N̂ (ALGORITHMS.md §5.5, §5.8; paper Fig. 5h, §V.C).

* ``clutter`` (values such as 0.5, 3, 5): one run with ``experiment.clutter = values``; every trial's truth and
  detections are shared across lambda (common random numbers, :mod:`soabench.seeding`), so one run gives the
  precision curves and every metric per lambda.
* ``births`` (offsets such as -10..10): one run per ``N_tot = max(1, N_true + o)`` (duplicates after clipping
  dropped), with ``N̂_k = N_tot / K`` and ``K = duration / dt`` scans (register row 24); models S-OA, PUBM and UBM
  unless ``models`` is given or the config names other than all five. The table reports k̄_delay over all counted
  episodes vs N_tot per model and mode, and the std of those means (population, ddof = 0) as in the paper's §V.C.

Layout (``results/<net>/sweep-<kind>-<UTC timestamp>/``)::

    sweep.json              kind, values, points, base config, net (written at start)
    points/<name>/          one ordinary run folder per point (resumable on its own)
    sweep_summary.json      the sweep table's numbers
    sweep.md                the sweep table (Markdown)
    sweep_<kind>.png        the sweep figure

``run_sweep(..., resume=SWEEP_DIR)`` resumes every unfinished point and starts the ones never started.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from soabench.birth import LABEL
from soabench.config import BIRTH_MODEL_NAMES, Config
from soabench.errors import SoabenchError, require
from soabench.experiment.plots import MODEL_COLOR, _figure, _save
from soabench.experiment.report import fmt
from soabench.experiment.runner import (
    LoadFn,
    RunOutcome,
    TrialFn,
    _utc_stamp,
    net_name,
    open_executor,
    run_experiment,
)
from soabench.experiment.store import read_csv, read_json, write_json_atomic, write_text_atomic

SWEEP_FILE = "sweep.json"
KINDS = ("clutter", "births", "occlusion")
BIRTHS_MODELS = ("soa", "pubm", "ubm")
N_TRUE = 6


@dataclass
class SweepOutcome:
    """Like :class:`~soabench.experiment.runner.RunOutcome`, summed over the sweep points."""

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
    base = Config.from_dict(config.to_dict())
    if models is not None:
        base.experiment = dataclasses.replace(base.experiment, models=tuple(models))
    if kind == "occlusion":  # soabench/experiment/occlusion.py: one point per parked-car density
        from soabench.experiment.occlusion import occlusion_points

        base.validate()
        return occlusion_points(values, base.to_dict())
    if kind == "clutter":
        vals = tuple(float(v) for v in values)
        base.experiment = dataclasses.replace(base.experiment, clutter=vals)
        base.validate()
        return [{"name": "clutter", "value": list(vals), "config": base.to_dict()}]
    if models is None and tuple(base.experiment.models) == BIRTH_MODEL_NAMES:  # the default set -> §5.8's three
        base.experiment = dataclasses.replace(base.experiment, models=BIRTHS_MODELS)
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


def run_sweep(
    kind: str,
    values: Sequence[float],
    config: Config | None,
    net: str,
    polys: Sequence[str] = (),
    scenario: str | None = None,
    *,
    out: Path | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    dask_local: bool = False,
    resume: Path | None = None,
    fail_fast: bool = False,
    save_estimates: bool = False,
    progress: bool = True,
    trial_fn: TrialFn | None = None,
    load_fn: LoadFn | None = None,
    models: Sequence[str] | None = None,
    n_true: int = N_TRUE,
    figures: bool = True,
) -> SweepOutcome:
    """Run (or resume) a ``clutter`` or ``births`` sweep; each point is its own run folder under ``points/``.

    Executor options are those of :func:`~soabench.experiment.runner.run_experiment`; one executor (pool or Dask
    cluster) serves every point. The sweep table and figure are written once every point has attempted all trials.
    """
    if resume is not None:
        sweep_dir = Path(resume)
        meta = read_json(sweep_dir / SWEEP_FILE) if (sweep_dir / SWEEP_FILE).is_file() else None
        require(meta is not None, f"{str(sweep_dir)!r} is not a sweep folder (no {SWEEP_FILE})")
        kind, net, polys, scenario = meta["kind"], meta["net"], tuple(meta["polys"]), meta["scenario"]
        points = meta["points"]
    else:
        require(config is not None, "run_sweep needs a config (or resume=SWEEP_DIR)")
        points = sweep_points(kind, values, config, models, n_true)
        sweep_dir = Path(out) if out is not None else Path("results") / net_name(net) / f"sweep-{kind}-{_utc_stamp()}"
        if (sweep_dir / SWEEP_FILE).exists():
            raise SoabenchError(f"{str(sweep_dir)!r} already holds a sweep; resume it or choose another --out")
        sweep_dir.mkdir(parents=True, exist_ok=True)
        if kind == "occlusion":
            from soabench.experiment.occlusion import write_point_scenarios

            write_point_scenarios(sweep_dir, points, net, scenario)
        meta = {
            "kind": kind,
            "values": [float(v) for v in values],
            "n_true": int(n_true),
            "net": str(net),
            "net_name": net_name(net),
            "polys": [str(p) for p in polys],
            "scenario": scenario,
            "base_config": config.to_dict(),
            "created": _utc_stamp(),
            "points": points,
        }
        write_json_atomic(sweep_dir / SWEEP_FILE, meta)

    n_trials_total = sum(int(p["config"]["experiment"]["trials"]) for p in points)
    outcomes: list[RunOutcome] = []
    exe = open_executor(workers, scheduler, dask_local, n_trials=n_trials_total)
    stopped = False
    aborted = True  # until the loop ends normally (Ctrl-C, errors): terminate the workers on the way out
    try:
        for p in points:
            pdir = sweep_dir / "points" / p["name"]
            kwargs: dict[str, Any] = dict(
                fail_fast=fail_fast,
                save_estimates=save_estimates,
                progress=progress,
                trial_fn=trial_fn,
                load_fn=load_fn,
                executor=exe,
                figures=figures,
            )
            sc = p.get("scenario", scenario)  # occlusion points carry their own scenario
            if (pdir / "run.json").is_file():
                o = run_experiment(None, net, polys, sc, resume=pdir, **kwargs)
            else:
                o = run_experiment(Config.from_dict(p["config"]), net, polys, sc, out=pdir, **kwargs)
            outcomes.append(o)
            if not o.summary_markdown:  # the point did not attempt every trial (--fail-fast stopped it)
                stopped = True
                break
        aborted = stopped
    finally:
        exe.close(abort=aborted)

    failures = [{"point": p["name"], **f} for p, o in zip(points, outcomes, strict=False) for f in o.failures]
    n_done = sum(o.n_done for o in outcomes)
    n_missing = n_trials_total - n_done
    outcome = SweepOutcome(sweep_dir, n_missing == 0, n_done, n_missing, failures, "", outcomes)
    if stopped or len(outcomes) < len(points):
        return outcome
    outcome.summary_markdown = write_sweep_report(sweep_dir)
    return outcome


# ------------------------------------------------------------------------------------------------ sweep report
def _episode_means(run_dir: Path, models: Sequence[str], modes: Sequence[str], clutter: float) -> dict:
    """k̄_delay over all counted episodes of a run, per (model, mode)."""
    e = read_csv(run_dir / "episodes.csv")
    out = {}
    for model in models:
        for mode in modes:
            if not e or "delay" not in e or len(e["delay"]) == 0:
                out[(model, mode)] = math.nan
                continue
            m = (e["model"] == model) & (e["mode"] == mode) & (e["clutter"] == clutter) & (e["censored"] == 0)
            d = e["delay"][m]
            d = d[~np.isnan(d)]
            out[(model, mode)] = float(d.mean()) if d.size else math.nan
    return out


def births_report(sweep_dir: Path, meta: dict) -> tuple[dict, str]:
    """k̄_delay vs N_tot per model and mode, and the std of those means (paper §V.C)."""
    points = meta["points"]
    exp = points[0]["config"]["experiment"]
    models, modes, clutter = exp["models"], exp["probabilities"], float(exp["clutter"][0])
    table = []
    for p in points:
        means = _episode_means(sweep_dir / "points" / p["name"], models, modes, clutter)
        table.append(
            {"N_tot": p["value"], "N_hat": p["N_hat"], "delay": {f"{a}/{b}": v for (a, b), v in means.items()}}
        )
    cols = [f"{a}/{b}" for a in models for b in modes]
    std = {}
    for c in cols:
        v = np.array([r["delay"][c] for r in table], dtype=float)
        v = v[~np.isnan(v)]
        std[c] = float(v.std(ddof=0)) if v.size else math.nan
    head = [f"{LABEL.get(c.split('/')[0], c)} {c.split('/')[1]}" for c in cols]
    K = scans_per_run(Config.from_dict(points[0]["config"]))
    lines = [
        f"# N̂ sensitivity sweep: {meta.get('net_name')}",
        "",
        f"k̄_delay (s) over all counted episodes vs the expected births per run N_tot (N̂_k = N_tot / K, "
        f"K = {K} scans, N_true = {meta['n_true']}), λ = {clutter:g}, "
        f"{exp['trials']} trials per point.",
        "",
        "| N_tot | N̂_k | " + " | ".join(head) + " |",
        "|---|---|" + "---|" * len(cols),
    ]
    for r in table:
        lines.append(f"| {r['N_tot']} | {r['N_hat']:.4g} | " + " | ".join(fmt(r["delay"][c]) for c in cols) + " |")
    lines.append("| std over N_tot | | " + " | ".join(fmt(std[c]) for c in cols) + " |")
    fig = _figure(6.5, 4.0)
    ax = fig.add_subplot()
    styles = ["-", "--", ":"]
    for i, mode in enumerate(modes):
        for model in models:
            ax.plot(
                [r["N_tot"] for r in table],
                [r["delay"][f"{model}/{mode}"] for r in table],
                styles[i % 3],
                color=MODEL_COLOR.get(model, "k"),
                marker="o",
                ms=3,
                label=f"{LABEL.get(model, model)} {mode} (std {fmt(std[f'{model}/{mode}'], 2)} s)",
            )
    ax.axvline(meta["n_true"], color="k", lw=0.8, alpha=0.5)
    ax.set_xlabel("expected births per run N_tot")
    ax.set_ylabel("mean tracking delay k̄ (s)")
    ax.set_title("Average delay vs N̂ (paper §V.C)")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    _save(fig, sweep_dir / "sweep_births.png")
    lines += ["", "Figure: `sweep_births.png`"]
    return {"kind": "births", "table": table, "std_over_N_tot": std}, "\n".join(lines) + "\n"


def clutter_report(sweep_dir: Path, meta: dict) -> tuple[dict, str]:
    """Precision, recall, cardinality error, OSPA and k̄_delay per lambda, model and mode (Fig. 5h)."""
    run_dir = sweep_dir / "points" / meta["points"][0]["name"]
    summary = read_json(run_dir / "summary.json")
    rows = []
    for res in summary["results"]:
        for s in res["models"]:
            rows.append({"clutter": res["clutter"], **s})
    lines = [
        f"# Clutter sweep: {meta.get('net_name')}",
        "",
        "One run with every clutter rate (trials share truth and detections across λ); per-run details in "
        f"`points/{meta['points'][0]['name']}/summary.md`.",
        "",
        "| λ | model | mode | precision | recall | card. error | OSPA (m) | k̄ delay (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['clutter']:g} | {LABEL.get(r['model'], r['model'])} | {r['mode']} | {fmt(r['precision_mean'])} "
            f"| {fmt(r['recall_mean'])} | {fmt(r['card_err_mean'])} | {fmt(r['ospa_mean'])} | {fmt(r['delay_mean'])} |"
        )
    fig = _figure(6.5, 4.0)
    ax = fig.add_subplot()
    keys = list(dict.fromkeys((r["model"], r["mode"]) for r in rows))
    for model, mode in keys:
        sub = [r for r in rows if r["model"] == model and r["mode"] == mode]
        ax.plot(
            [r["clutter"] for r in sub],
            [r["precision_mean"] for r in sub],
            "--" if mode != "static" else "-",
            color=MODEL_COLOR.get(model, "k"),
            marker="o",
            label=f"{LABEL.get(model, model)} {mode}",
        )
    ax.set_xlabel("clutter rate λ (per scan)")
    ax.set_ylabel("mean precision over trials")
    ax.set_title("Precision vs clutter (paper Fig. 5h; dashed: dynamic)")
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.0, 0.5))
    ax.grid(alpha=0.3)
    _save(fig, sweep_dir / "sweep_clutter.png")
    lines += ["", f"Figures: `sweep_clutter.png`, `points/{meta['points'][0]['name']}/figures/fig5h_precision.png`"]
    return {"kind": "clutter", "table": rows}, "\n".join(lines) + "\n"


def write_sweep_report(sweep_dir: Path) -> str:
    """Write sweep.md, sweep_summary.json and the sweep figure from the points' CSV files; return the Markdown."""
    sweep_dir = Path(sweep_dir)
    meta = read_json(sweep_dir / SWEEP_FILE)
    from soabench.experiment.occlusion import occlusion_report

    report = {"births": births_report, "clutter": clutter_report, "occlusion": occlusion_report}[meta["kind"]]
    data, md = report(sweep_dir, meta)
    write_json_atomic(sweep_dir / "sweep_summary.json", data)
    write_text_atomic(sweep_dir / "sweep.md", md)
    return md
