"""``soabench atlas``: the trials of every design point, on the process pool or Dask, into a Parquet dataset (§5.10).

One task is one *chunk*: trial n of every point of one scene variant (:mod:`.plan`). The task runs SUMO once, the
sensor once per distinct sensor setting and each point's filters on them (a
:class:`~soabench.experiment.trial.trial.TrialShare` carries the recording and the scans from point to point, as the
study does for its clutter rates), and returns the chunk's rows. Trial n has the same seeds at every point
(:mod:`soabench.seeding`): common random numbers inside a point (every model sees the same truth, detections and
clutter) and across the points of a variant. The driver writes each chunk as its task finishes
(:mod:`.store`; workers need no shared file system) and holds only the chunks in flight, so memory stays flat in the
number of trials; at the end of a session it compacts the finished chunks into a few parts (:mod:`.compact`). Tasks
run trial-major (trial 0 of every variant, then trial 1, ...): an interrupted atlas has about as many trials at every
point, and a resumed one runs only the chunks that are not complete (:func:`.store.done_chunks`).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import sys
import threading
import time
import traceback
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from soabench import plugins
from soabench.atomic import to_jsonable, write_bytes_atomic, write_json_atomic, write_text_atomic
from soabench.config import Config
from soabench.errors import Interrupted, require
from soabench.experiment.campaigns.atlas import store
from soabench.experiment.campaigns.atlas.design import Design, axis_type, filter_families_allowed
from soabench.experiment.campaigns.atlas.plan import (
    Cost,
    PointPlan,
    SceneVariant,
    check_scenes,
    estimate,
    plan_points,
    point_config,
    variant_scenario,
)
from soabench.experiment.execution.executors import failure_record, open_executor
from soabench.experiment.execution.options import RUN_DEFAULTS, RunOptions
from soabench.experiment.execution.progress import Progress
from soabench.experiment.runs.provenance import package_versions, platform_info
from soabench.experiment.trial import registry
from soabench.folders import FolderLock, check_writable_target, resolve

DEFAULT_MAX_TRIALS = 20_000  #: trials (points x trials per point) an atlas runs without --force


@dataclass(frozen=True)
class AtlasSpec:
    """What a worker needs to run any chunk (small and picklable: the points as overrides of one base config)."""

    config: dict  #: the base configuration (``Config.to_dict()``)
    scenes: tuple[tuple[str, str | None], ...]  #: per scene variant: (net, scenario file or None)
    points: tuple[tuple[int, int, str, tuple], ...]  #: (point, scene, overrides as JSON, axis columns)
    steps: bool = False
    trial_kind: str = registry.DEFAULT_TRIAL_KIND
    scene_loader: str = registry.DEFAULT_SCENE_LOADER
    plugin_paths: tuple[str, ...] = ()
    #: ``experiment.seed`` of the base config, read through :class:`~soabench.config.Config` once (a failure
    #: record's seed)
    base_seed: int = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "base_seed", int(Config.from_dict(self.config).experiment.seed))

    @property
    def task_fn(self) -> Any:
        return run_chunk_task

    def chunk_of(self, task: int) -> tuple[int, int]:
        """(trial, scene variant) of a task index (trial-major)."""
        return divmod(int(task), len(self.scenes))


_LOCK = threading.Lock()  # libsumo is a process singleton: one chunk at a time per worker process


def run_chunk_task(task: int, spec: AtlasSpec) -> dict:
    """Run one chunk (module docstring) in this process; an exception becomes a failure record."""
    n, s = spec.chunk_of(task)
    base_seed = spec.base_seed
    t0 = time.perf_counter()
    try:
        with _LOCK:
            plugins.allow_import_paths(spec.plugin_paths)
            net, scenario = spec.scenes[s]
            load_fn = registry.scene_loader(spec.scene_loader)
            scene, scen = registry.load_scene_cached(net, (), scenario, load_fn)
            fn = registry.trial_kind(spec.trial_kind)
            share = None
            if fn is registry._builtin_trial:  # soabench's own trial: run_trial, with the share
                from soabench.experiment.trial.trial import TrialShare, run_trial

                share = TrialShare()
                fn = functools.partial(run_trial, share=share)
            rows, episodes, steps = [], [], []
            for point, scene_i, overrides, head in spec.points:
                if scene_i != s:
                    continue
                cfg = point_config(spec.config, json.loads(overrides))
                res = fn(n, cfg, scene, scen, save_estimates=False)
                family = cfg.experiment.filters[0] if len(cfg.experiment.filters) == 1 else None
                lead = {"point": point, "scene": s, **dict(head)}
                for table, out in (
                    (res.rows, rows),
                    (res.episodes, episodes),
                    (res.steps if spec.steps else (), steps),
                ):
                    for r in table:
                        out.append({**lead, "family": r.get("filter", family), **r})
    except Exception as exc:  # a failed chunk must not stop the atlas
        return failure_record(int(task), base_seed, f"{type(exc).__name__}: {exc}", traceback.format_exc())
    return {
        "trial": int(task),
        "status": "ok",
        "trials": store.columns_of(rows, {}),
        "episodes": store.columns_of(episodes, {}),
        "steps": store.columns_of(steps, {}) if spec.steps else None,
        "elapsed": time.perf_counter() - t0,
        "shared": dict(share.counts) if share is not None else {},
    }


# ------------------------------------------------------------------------------------------------ the request
@dataclass
class AtlasRequest:
    """An atlas to start (``design`` given) or to resume (``design`` None: the folder's own)."""

    out: Path
    net: str = "intersection"
    design: Design | None = None
    config: Config | None = None  #: the base configuration (experiment.trials: trials per point)
    steps: bool = False
    max_trials: int = DEFAULT_MAX_TRIALS
    force: bool = False
    dry_run: bool = False
    report: bool = True
    trial_kind: str = registry.DEFAULT_TRIAL_KIND
    scene_loader: str = registry.DEFAULT_SCENE_LOADER
    #: dotted keys the user gave (a resumed atlas refuses other values of these; more trials extend it)
    explicit: set[str] = field(default_factory=set)


@dataclass
class AtlasOutcome:
    run_dir: Path
    complete: bool
    n_done: int
    n_missing: int
    cost: Cost | None = None
    summary_markdown: str = ""
    failures: list[dict] = field(default_factory=list)
    #: what the chunks computed and reused (recordings, scans, ...: TrialShare counts), summed over this session
    shared: dict[str, int] = field(default_factory=dict)
    elapsed: float = 0.0  #: summed task seconds of this session (core-seconds of the chunks run)


def _utc() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def head_of(values: dict[str, Any]) -> tuple:
    """A point's axis columns (key with ``.`` as ``_``), as a tuple of pairs (hashable, picklable)."""
    return tuple((k.replace(".", "_"), v) for k, v in values.items())


def _new_meta(req: AtlasRequest, variants: list[SceneVariant], points: list[PointPlan], cost: Cost) -> dict:
    cfg = req.config
    assert cfg is not None and req.design is not None
    return {
        "format": store.FORMAT,
        "created": _utc(),
        "net": req.net,
        "design": req.design.to_dict(),
        "trials": int(cfg.experiment.trials),
        "seed": int(cfg.experiment.seed),
        "seeds": "trial n of every point uses SeedSequence([seed, n]) (soabench.seeding): the same SUMO run, "
        "detections and clutter at every point of a scene variant",
        "config": cfg.to_dict(),
        "steps": bool(req.steps),
        "trial_kind": req.trial_kind,
        "scene_loader": req.scene_loader,
        "scenes": [{"index": v.index, "net": v.net, "scenario": v.scenario} for v in variants],
        "points": [{"point": p.index, "scene": p.scene, "values": p.values, "overrides": p.overrides} for p in points],
        "estimate": dataclasses.asdict(cost),
        "versions": package_versions(),
        "platform": platform_info(),
    }


def _spec(root: Path, meta: dict) -> AtlasSpec:
    scenes = []
    for v in meta["scenes"]:
        path = root / "scenes" / f"s{int(v['index']):04d}.scenario.toml"
        scenes.append((str(v["net"]), str(path) if v["scenario"] else None))
    points = tuple(
        (int(p["point"]), int(p["scene"]), json.dumps(p["overrides"], sort_keys=True), head_of(p["values"]))
        for p in meta["points"]
    )
    cfg = meta["config"]
    models = tuple(cfg.get("experiment", {}).get("models", ()))
    return AtlasSpec(
        config=cfg,
        scenes=tuple(scenes),
        points=points,
        steps=bool(meta.get("steps")),
        trial_kind=str(meta.get("trial_kind", registry.DEFAULT_TRIAL_KIND)),
        scene_loader=str(meta.get("scene_loader", registry.DEFAULT_SCENE_LOADER)),
        plugin_paths=tuple(m for m in models if ":" in m),
    )


def _write_scenes(root: Path, variants: list[SceneVariant]) -> None:
    """The scenario file of each scene variant, written in every session: it is derived from the scene and the
    variant's keys, and names the scene's files where this checkout has them (an atlas made elsewhere, or by a
    checkout since moved, resumes and grows here)."""
    from soabench.experiment.campaigns.occlusion import dump_toml

    for v in variants:
        data = variant_scenario(v)
        if data is not None:
            write_text_atomic(root / "scenes" / f"{v.name}.scenario.toml", dump_toml(data))


def _write_new(root: Path, meta: dict, variants: list[SceneVariant]) -> None:
    _write_scenes(root, variants)
    cols = store.columns_of(
        (
            {
                "point": p["point"],
                "scene": p["scene"],
                "net": meta["scenes"][p["scene"]]["net"],
                **dict(head_of(p["values"])),
                "config": json.dumps(point_config(meta["config"], p["overrides"]).to_dict(), sort_keys=True),
            }
            for p in meta["points"]
        ),
        {},
    )

    write_bytes_atomic(root / "points.parquet", store.parquet_bytes(cols))
    write_json_atomic(root / store.ATLAS_FILE, to_jsonable(meta))  # last: its presence marks a planned atlas


def _todo(spec: AtlasSpec, trials: int, done: set[tuple[int, int]]) -> Iterator[int]:
    n_scenes = len(spec.scenes)
    for t in range(trials * n_scenes):
        if divmod(t, n_scenes) not in done:
            yield t


def _check_resume(root: Path, meta: dict, req: AtlasRequest) -> dict:
    """A resumed atlas: the request agrees with the stored design and settings (more trials extend it)."""
    if req.design is not None:
        require(
            req.design.to_dict() == meta["design"] and req.net == meta["net"],
            f"{root} holds an atlas of another design or scene; give the same axes and --net, or another --out",
        )
    if req.config is not None:
        stored = Config.from_dict(meta["config"]).to_dict()
        want = req.config.to_dict()
        for sec, table in want.items():
            for k, v in table.items():
                key = f"{sec}.{k}"
                if key == "experiment.trials" or key not in req.explicit:
                    continue
                old = stored.get(sec, {}).get(k)
                require(
                    old == v,
                    f"{root} was made with {key} = {old!r}, not {v!r}; give the options it was made with, or another "
                    "--out",
                )
        if "experiment.trials" in req.explicit:
            n = int(req.config.experiment.trials)
            require(
                n >= meta["trials"],
                f"{root} has {meta['trials']} trials per point; --trials {n} would drop finished ones",
            )
            if n > meta["trials"]:
                meta = {**meta, "trials": n, "config": {**meta["config"]}}
                meta["config"]["experiment"] = {**meta["config"]["experiment"], "trials": n}
    return meta


def plan(req: AtlasRequest) -> tuple[dict, list[SceneVariant], list[PointPlan], Cost]:
    """Check a new atlas (every axis value, the scenes, the size) and return its meta, variants, points and cost."""
    require(req.design is not None and req.config is not None, "a new atlas needs a design and a configuration")
    assert req.design is not None and req.config is not None
    for a in req.design.axes:
        if a.key == "filters":
            bad = [v for v in a.values if v not in filter_families_allowed()]
            require(not bad, f"axis filters: {bad[0] if bad else ''!r} is unknown; allowed: "
                    f"{', '.join(filter_families_allowed())}")  # fmt: skip
        axis_type(a.key)
    variants, points = plan_points(req.design, req.config, req.net)
    check_scenes(variants)
    cost = estimate(req.config, variants, points, req.config.experiment.trials)
    require(
        req.force or cost.trials <= req.max_trials,
        f"the design has {cost.trials} trials ({cost.points} points x {req.config.experiment.trials}), more than "
        f"--max-trials {req.max_trials}; estimated {cost.core_hours:.1f} core-hours; add --force to run it",
    )
    return _new_meta(req, variants, points, cost), variants, points, cost


def run_atlas(req: AtlasRequest, options: RunOptions = RUN_DEFAULTS, log: Any = None) -> AtlasOutcome:
    """Start, resume or (``dry_run``) cost an atlas (module docstring). Bad input is refused before anything is
    written or run."""
    log = log or (lambda msg: print(msg, file=sys.stderr, flush=True))
    options.validate()
    root = resolve(req.out)
    resuming = (root / store.ATLAS_FILE).exists()
    if resuming:
        meta = _check_resume(root, store.read_meta(root), req)
        cfg = Config.from_dict(meta["config"])
        variants = [SceneVariant(int(v["index"]), str(v["net"]), dict(v["scenario"])) for v in meta["scenes"]]
        points = [
            PointPlan(int(p["point"]), dict(p["values"]), int(p["scene"]), p["overrides"]) for p in meta["points"]
        ]
        cost = estimate(cfg, variants, points, int(meta["trials"]))
    else:
        check_writable_target(root, "atlas folder")
        if root.is_dir():
            content = sorted(p.name for p in root.iterdir() if p.name != ".soabench.lock")
            require(
                not content,
                f"{str(root)!r} is not empty ({', '.join(content[:4])}) and holds no atlas; give a new or empty folder",
            )
        meta, variants, points, cost = plan(req)
    done = store.done_chunks(root) if resuming else set()
    n_trials = int(meta["trials"])
    n_chunks = n_trials * len(variants)
    if req.dry_run:
        done_trials = sum(sum(1 for p in points if p.scene == s) for n, s in done if n < n_trials)
        return AtlasOutcome(
            root, False, done_trials, cost.trials - done_trials, cost, "\n".join(cost.lines(done_trials))
        )
    with FolderLock(root, "atlas folder"):
        if not resuming:
            _write_new(root, meta, variants)
        else:
            _write_scenes(root, variants)
            if meta["trials"] != store.read_meta(root)["trials"]:
                write_json_atomic(root / store.ATLAS_FILE, to_jsonable(meta))
        store.clear_partials(root)
        spec = _spec(root, meta)
        todo_n = n_chunks - len({c for c in done if c[0] < n_trials})
        failures: list[dict] = []
        shared: dict[str, int] = {}
        elapsed = 0.0
        if todo_n:
            if registry.trial_kind(spec.trial_kind) is registry._builtin_trial:
                from soabench.kernel_warmup import ensure_compiled

                ensure_compiled(point_config(spec.config, json.loads(ov)) for _, _, ov, _ in spec.points)
            exe = open_executor(options.workers, options.scheduler, options.dask_local, n_trials=todo_n)
            bar = Progress(n_chunks, n_chunks - todo_n, options.progress, label=root.name, unit="chunks")
            aborted = True
            try:
                gen = exe.results(spec, _todo(spec, n_trials, done))
                try:
                    for t, rec in gen:
                        n, s = spec.chunk_of(t)
                        if rec.get("status") == "ok":
                            for key, v in (rec.get("shared") or {}).items():
                                shared[key] = shared.get(key, 0) + int(v)
                            elapsed += float(rec.get("elapsed", 0.0))
                            store.write_chunk(root, n, s, {k: rec.get(k) for k in ("trials", "episodes", "steps")})
                            bar.update(True)
                        else:
                            failures.append({"trial": n, "scene": s, "error": rec.get("error", "")})
                            write_json_atomic(
                                root / "failures" / store.chunk_name(n, s).replace(".parquet", ".json"),
                                {**rec, "trial": n, "scene": s},
                            )
                            bar.update(False)
                            log(f"soabench atlas: trial {n} of scene variant {s} failed: {rec.get('error', '')}")
                finally:
                    gen.close()
                    bar.close()
                aborted = False
            except KeyboardInterrupt:
                raise Interrupted(
                    f"interrupted: the atlas in {root} is incomplete (finished chunks are on disk); finish with: "
                    f"soabench atlas --out {root}"
                ) from None
            finally:
                exe.close(abort=aborted)
        from soabench.experiment.campaigns.atlas.compact import compact

        compact(root)  # the session's chunks into parts: few files for the report and every query
        done = store.done_chunks(root)
        n_done_chunks = len({c for c in done if c[0] < n_trials})
        complete = n_done_chunks == n_chunks
        per_scene = {v.index: sum(1 for p in points if p.scene == v.index) for v in variants}
        n_done = sum(per_scene[s] for n, s in done if n < n_trials)
        md = ""
        if req.report and n_done:
            from soabench.experiment.campaigns.atlas.report import write_report

            md = write_report(root)
    return AtlasOutcome(root, complete, n_done, cost.trials - n_done, cost, md, failures, shared, elapsed)
