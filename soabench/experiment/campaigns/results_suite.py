"""``soabench results``: every part of results/ from one command, each part resumable.

Parts, in order, under ``OUT`` (default ``results/``):

* ``intersection/``: the paper's study (:mod:`soabench.experiment.campaigns.study`: main protocol, clutter sweep, N_hat
  sweep, comparison with the paper) on the shipped intersection;
* ``filters/``: the main protocol on the shipped intersection (its trials, duration and seed; λ = 3) with every
  birth model in every filter family of the registry (the GM-PHD, the LMB, the PMBM and the PMB;
  ``--filters gmphd,lmb,pmbm,pmb``), in the modes every family runs, ``static`` and ``static+occ``
  (:func:`_filters_part`): does occlusion-aware birth help a labelled filter? Beside it
  ``filters-lmb-components/``: the LMB with its earlier birth mapping (``[lmb] birth_mapping = "components"``,
  static), the ablation that shows what the mapping changes. Both run in the intersection study's trials
  (:class:`~soabench.experiment.campaigns.study.Companion`): trial n's SUMO recording, scans and births are
  computed once for the study and them; when the study is already complete they run on their own.
* ``<scene>/``: the same study on every other shipped scene (``--scene-trials`` trials of its main protocol; no
  comparison with the paper, whose numbers belong to its own protocol on the intersection);
* ``scenes/density/<scene>.json``: each scene's occlusion density (:mod:`.occlusion_density`);
* ``scenes/``: the cross-scene summary (:mod:`.cross_scene`): S-OA's advantage against occlusion density;
* ``atlas/<scene>/``: the atlas over scene parameters (:mod:`soabench.experiment.campaigns.atlas`; design
  :data:`ATLAS_AXES`: parking density x pedestrians x clutter x p_D, ``--atlas-trials`` trials per point, the six
  birth models, static, GM-PHD) on ``--atlas-scenes``: when does S-OA pay off?
* ``kitti/<scene>/``: SUMO trials exported in the KITTI tracking layout (``export/``) and the KITTI protocol on them
  (``run/``: k-fold N_hat, Table I; :mod:`soabench.experiment.campaigns.kitti.protocol`).

An existing complete part with the same settings is kept as it is (nothing is re-run or rewritten); an unfinished
one is resumed (its finished trials are kept); a part made with other settings is refused with one line naming the
difference. Ctrl-C leaves every finished trial on disk and names the command that finishes the job.
"""

from __future__ import annotations

import dataclasses
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from soabench.atomic import write_json_atomic
from soabench.birth import CORE_MODELS
from soabench.config import FILTER_FAMILIES, MAX_SEED, MAX_TRIALS, Config, check_time
from soabench.errors import Interrupted, SoabenchError, require
from soabench.experiment.campaigns.occlusion_density import write_density
from soabench.experiment.execution.options import RUN_DEFAULTS, RunOptions, check_workers
from soabench.experiment.reports.html import write_index
from soabench.experiment.runs.files import read_json
from soabench.experiment.runs.runmeta import flatten_config
from soabench.folders import FolderLock, check_own_folder, resolve
from soabench.kitti.config import KittiSpec, load_kitti_config
from soabench.scenario import shipped_nets
from soabench.scenario.network import read_net
from soabench.scenario.parking import parking_lanes

if TYPE_CHECKING:
    from soabench.experiment.campaigns.study import Companion
    from soabench.experiment.execution.runner import RunOutcome

#: the study's part folders; a study is kept only when each is complete (a part added to the study belongs here)
STUDY_PARTS = ("main", "clutter", "births")  # and sensitivity/ (two run folders and its table; see study_kept)
SETTINGS_FILE = "settings.json"  #: what a KITTI part was made with (sequences, duration, seed, folds)


@dataclass(frozen=True)
class Settings:
    """Sizes of every part (the defaults are the paper's: an hour-long job, ``benchmarks/README.md``)."""

    scenes: tuple[str, ...] | None = None  #: shipped scenes of the summary (None: every shipped scene)
    trials: int = 100  #: main protocol and clutter sweep of the intersection study (the paper's 100)
    duration: float = 100.0  #: seconds per SUMO trial (every protocol part and the density)
    seed: int = 0
    births_trials: int = 30  #: trials per point of the study's N_hat sweep
    scene_trials: int = 100  #: main protocol trials on each other scene
    density_trials: int = 20  #: trials per scene whose scans give the occlusion density
    kitti_scenes: tuple[str, ...] = ("intersection",)
    kitti_sequences: int = 21  #: like KITTI's training set
    kitti_duration: float = 40.0  #: seconds per exported sequence (400 frames at 10 Hz; KITTI's average is 381)
    kitti_folds: int = 7  #: the paper's 7-fold cross-validation (3 sequences per fold for 21)
    #: scenes of the atlas part (a scene with parking lanes and one without), and trials per point
    atlas_scenes: tuple[str, ...] = ("intersection", "grid_block")
    atlas_trials: int = 20

    def validate(self, shipped: Sequence[str]) -> Settings:
        """Every size in its range (the bounds of soabench/config.py and of ``export kitti``), before any part runs."""
        # imported when called: scipy would slow every start-up
        from soabench.kitti.export import MAX_EXPORT_TRIALS

        def count(name: str, low: int, high: int, why: str = "") -> None:
            v = getattr(self, name)
            ok = isinstance(v, int) and low <= v <= high
            require(ok, f"--{name.replace('_', '-')} {v!r} is out of range; allowed: integers in [{low}, {high}]{why}")

        for name in ("trials", "births_trials", "scene_trials", "density_trials", "atlas_trials"):
            count(name, 1, MAX_TRIALS)
        count("kitti_sequences", 2, MAX_EXPORT_TRIALS, " (cross-validation needs 2)")
        count("kitti_folds", 2, MAX_EXPORT_TRIALS, " (more folds than sequences: one per sequence)")
        count("seed", 0, MAX_SEED)
        for name in ("duration", "kitti_duration"):
            check_time(f"--{name.replace('_', '-')}", getattr(self, name))
        lists = (("--scenes", self.scenes or ()), ("--kitti-scenes", self.kitti_scenes))
        for flag, names in (*lists, ("--atlas-scenes", self.atlas_scenes)):
            bad = [n for n in names if n not in shipped]
            require(not bad, f"{flag} {','.join(bad)}: not a shipped scene; allowed: {', '.join(shipped)}")
        require(self.scenes is None or len(self.scenes) >= 1, "--scenes must name at least one shipped scene")
        return self


@dataclass
class ResultsOutcome:
    """What ``soabench results`` ended with: per part "kept", "done" or "incomplete"."""

    run_dir: Path
    parts: dict[str, str] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)  #: wall-clock time per part
    n_missing: int = 0
    summary_markdown: str = ""

    @property
    def complete(self) -> bool:
        return all(v in ("kept", "done") for v in self.parts.values())


# ------------------------------------------------------------------------------------------------ completeness
def _json(path: Path) -> Any:

    try:
        return read_json(path) if path.is_file() else None
    except Exception:  # unreadable: not complete
        return None


def run_complete(run_dir: Path) -> bool:
    """A run folder whose report says every trial has a result."""
    s = _json(run_dir / "summary.json")
    return isinstance(s, dict) and s.get("complete") is True and (run_dir / "trials.csv").is_file()


def sweep_complete(sweep_dir: Path) -> bool:
    """A sweep folder with its report and every point's run complete."""
    meta = _json(sweep_dir / "sweep.json")
    if not isinstance(meta, dict) or not (sweep_dir / "sweep_summary.json").is_file():
        return False
    points = meta.get("points")
    return isinstance(points, list) and all(
        isinstance(p, dict) and isinstance(p.get("name"), str) and run_complete(sweep_dir / "points" / p["name"])
        for p in points
    )


def part_complete(folder: Path) -> bool:
    if (folder / "run.json").is_file():
        return run_complete(folder)
    if (folder / "sweep.json").is_file():
        return sweep_complete(folder)
    return False


#: the settings a stored run is compared on (besides the keys a part names)
SIZE_KEYS = (
    "experiment.trials",
    "experiment.duration",
    "experiment.seed",
    "experiment.models",
    "experiment.probabilities",
)


def _equal(a: Any, b: Any) -> bool:
    if isinstance(b, (tuple, list)):
        return isinstance(a, (tuple, list)) and list(a) == list(b)
    if isinstance(b, float) and isinstance(a, (int, float)) and not isinstance(a, bool):
        return float(a) == b
    return a == b


def same_settings(run_dir: Path, cfg, keys: Sequence[str] = SIZE_KEYS) -> bool:
    """Compare a stored run with the requested ``cfg`` on ``keys``: True when equal, False when only more trials
    are requested (the run is extended); any other difference is refused with one line."""

    meta = _json(run_dir / "run.json")
    config = meta.get("config") if isinstance(meta, dict) else None
    stored = flatten_config(config) if isinstance(config, dict) else {}
    want = flatten_config(cfg.to_dict())
    diffs, more = [], False
    for k in keys:
        old, new = stored.get(k), want.get(k)
        if _equal(old, new):
            continue
        if k == "experiment.trials" and isinstance(old, int) and isinstance(new, int) and new > old:
            more = True
        else:
            diffs.append(f"{k}: stored {old!r}, requested {new!r}")
    if diffs:
        fewer = (
            " (fewer trials would drop finished ones)" if any(d.startswith("experiment.trials") for d in diffs) else ""
        )
        raise SoabenchError(
            f"{run_dir} was made with other settings: {'; '.join(diffs)}{fewer}; remove that folder to make it "
            "again with these settings, or give the options it was made with"
        )
    return not more


def study_kept(root: Path, s: Settings, trials: int | None = None) -> bool:
    """The study in ``root`` is complete with these settings: every part of :data:`STUDY_PARTS` (and any other
    part folder it holds) complete, its main protocol and sweep points made with the requested settings. A part
    made with other settings is refused (:func:`same_settings`); more trials are not "kept" (the study extends).
    ``trials``: of the main protocol and clutter sweep (default ``s.trials``; the other scenes' ``s.scene_trials``)."""

    main_cfg = _base_config(s, trials or s.trials)
    births_cfg = _base_config(s, s.births_trials, models=CORE_MODELS, probabilities=("static",))
    same = True
    if (root / "main" / "run.json").is_file():
        same &= same_settings(root / "main", main_cfg)
    for part, cfg in (("clutter", main_cfg), ("births", births_cfg)):
        meta = _json(root / part / "sweep.json")
        for p in meta.get("points", []) if isinstance(meta, dict) else []:
            point = root / part / "points" / str(p.get("name") if isinstance(p, dict) else "")
            if (point / "run.json").is_file():
                same &= same_settings(point, cfg)
    if not same or not all(part_complete(root / p) for p in STUDY_PARTS):
        return False
    # imported when called: scipy would slow every start-up
    from soabench.experiment.campaigns.sensitivity_runs import VARIANTS

    sens = root / "sensitivity"
    if not (sens / "sensitivity.md").is_file() or not all(run_complete(sens / v) for v in VARIANTS):
        return False
    others = [d for d in root.iterdir() if d.is_dir() and d.name not in STUDY_PARTS]
    return all(part_complete(d) for d in others if (d / "run.json").is_file() or (d / "sweep.json").is_file())


# ------------------------------------------------------------------------------------------------ parts
def _base_config(s: Settings, trials: int, **experiment: Any):

    cfg = Config()
    cfg.experiment = dataclasses.replace(cfg.experiment, trials=trials, duration=s.duration, seed=s.seed, **experiment)
    return cfg.validate()


def _status(complete: bool) -> str:
    return "done" if complete else "incomplete"


def _study_part(
    root: Path,
    s: Settings,
    exe: RunOptions,
    log: Callable[[str], None],
    net: str = "intersection",
    trials: int | None = None,
    companions: Sequence[Companion] = (),
) -> tuple[str, int, list[RunOutcome] | None]:
    """The study (:func:`soabench.experiment.campaigns.study.run_study`) of scene ``net`` in ``root``: kept when
    complete with these settings, else resumed or started; ``trials`` of its main protocol (default ``s.trials``).
    ``companions`` run in the study's trials; their outcomes are returned (None when the study was kept: they did
    not run)."""
    # imported when called: scipy would slow every start-up
    from soabench.experiment.campaigns.study import run_study

    if root.is_dir() and study_kept(root, s, trials):
        log(f"kept {root} (the study is complete)")
        return "kept", 0, None
    explicit = {*SIZE_KEYS, "births_trials"}
    cfg = _base_config(s, trials or s.trials)
    o = run_study(cfg, net, out=root, births_trials=s.births_trials, explicit=explicit, options=exe,
                  companions=tuple(companions))  # fmt: skip
    return _status(o.complete), o.n_missing, list(o.companions)


def _kitti_want(scene: str, s: Settings) -> dict[str, Any]:
    return {
        "net": scene,
        "sequences": s.kitti_sequences,
        "duration": float(s.kitti_duration),
        "seed": s.seed,
        "folds": s.kitti_folds,
    }


def kitti_settings_check(base: Path, want: dict[str, Any]) -> dict | None:
    """The stored settings of a KITTI part (None if new); refuses a part made with other settings."""
    stored = _json(base / SETTINGS_FILE)
    if stored is not None and stored != want:
        diff = [k for k in want if not isinstance(stored, dict) or stored.get(k) != want[k]]
        listed = "; ".join(
            f"{k}: stored {stored.get(k) if isinstance(stored, dict) else None!r}, requested {want[k]!r}" for k in diff
        )
        raise SoabenchError(
            f"{base} was made with other settings ({listed}); remove it or give the options it was made with"
        )
    return stored


def _kitti_part(base: Path, scene: str, s: Settings, log: Callable[[str], None], progress: bool) -> tuple[str, int]:
    """Export ``kitti_sequences`` SUMO trials of ``scene`` in the KITTI layout, then the KITTI protocol on them."""
    # imported when called: matplotlib, scipy would slow every start-up
    from soabench.experiment.campaigns.kitti.protocol import run_kitti
    from soabench.kitti.export import export_kitti

    export, run = base / "export", base / "run"
    cfg, kcfg = load_kitti_config(None)
    cfg.experiment = dataclasses.replace(cfg.experiment, seed=s.seed)
    cfg.validate()
    want = _kitti_want(scene, s)
    stored = kitti_settings_check(base, want)
    if stored is not None and (run / "summary.json").is_file():
        log(f"kept {base} (KITTI export and protocol complete)")
        return "kept", 0
    require(
        stored is not None or not base.exists() or not any(base.iterdir()),
        f"{base} holds files but no {SETTINGS_FILE}; remove it or give another --out",
    )
    base.mkdir(parents=True, exist_ok=True)
    write_json_atomic(base / SETTINGS_FILE, want)
    if not (export / "export.json").is_file():
        partial = base / "export.partial"  # an interrupted export: ours by name, started again
        if partial.exists():
            shutil.rmtree(partial)
        require(not export.exists(), f"{export} exists but holds no finished export (no export.json); remove it")
        partial.mkdir(parents=True)
        export_kitti(cfg, scene, (), None, s.kitti_sequences, partial, duration=s.kitti_duration, log=log)
        partial.rename(export)
    quiet = None if progress else (lambda msg: None)
    if (run / "run.json").is_file():
        o = run_kitti(None, run, resume=True, log=quiet)
    else:
        spec = KittiSpec(
            root=str(export.resolve()),
            detections=None,
            semantics=str((export / "semantics").resolve()),
            sequences=None,
            folds=s.kitti_folds,
            nhat_sweep=None,
            skip_bad=False,
            config=cfg,
            kitti=kcfg,
        )
        o = run_kitti(spec, run, log=quiet)
    return ("done" if o.complete else "incomplete"), o.n_missing


def _index_pages(root: Path, scenes: Sequence[str], log: Callable[[str], None]) -> tuple[str, int]:
    """Every run folder's ``report.html``, each study's ``index.html`` and ``index.html`` linking every part
    (docs/user-guide/replay.md); a kept part gets its pages here too, an unchanged page is not rewritten."""
    for scene in scenes:
        if (root / scene).is_dir():
            write_index(root / scene)
    index = write_index(root, reports=False)[0]
    log(f"wrote {index}")
    return "done", 0


#: the atlas part's design: every combination of these values (static probabilities, GM-PHD, the six models)
ATLAS_AXES: dict[str, tuple[float, ...]] = {
    "parking.density": (0.0, 4.0, 8.0, 12.0),
    "pedestrians.count": (3, 6, 12, 24),
    "experiment.clutter": (0.5, 3.0, 5.0),
    "sensor.p_D": (0.7, 0.9, 0.98),
}


def atlas_axes(scene: str) -> dict[str, tuple[float, ...]]:
    """:data:`ATLAS_AXES` on ``scene``; a scene without parking lanes (grid_block: its kerbs are sidewalks and shop
    fronts) has no parked cars to vary, so it drops the parking axis (its occluders are its buildings)."""
    from soabench.experiment.campaigns.occlusion import base_scenario

    net_file = base_scenario(scene, None).get("files", {}).get("net")
    if net_file and not parking_lanes(read_net(net_file)):
        return {k: v for k, v in ATLAS_AXES.items() if k != "parking.density"}
    return dict(ATLAS_AXES)


def atlas_request(folder: Path, scene: str, s: Settings):
    """The atlas of ``scene`` in ``folder`` (:func:`atlas_axes`, ``s.atlas_trials`` trials per point)."""
    from soabench.experiment.campaigns.atlas.design import make_axis, make_design
    from soabench.experiment.campaigns.atlas.run import AtlasRequest

    axes = [make_axis(k, list(v)) for k, v in atlas_axes(scene).items()]
    cfg = _base_config(s, s.atlas_trials, probabilities=("static",))
    keys = {"experiment.trials", "experiment.duration", "experiment.seed", "experiment.models"}
    keys.add("experiment.probabilities")
    return AtlasRequest(out=folder, net=scene, design=make_design(axes), config=cfg, force=True, explicit=keys)


def _atlas_part(folder: Path, scene: str, s: Settings, exe: RunOptions, log: Callable[[str], None]):
    """The atlas of ``scene``: kept when complete with these settings (its chunks compacted if a part of it is not),
    else resumed (more trials: extended) or started; its report is drawn whenever trials were added."""
    from soabench.experiment.campaigns.atlas.run import run_atlas
    from soabench.experiment.campaigns.atlas.store import done_chunks, is_atlas, read_meta

    req = atlas_request(folder, scene, s)
    if is_atlas(folder):
        meta = read_meta(folder)
        n_chunks = meta["trials"] * len(meta["scenes"])
        same = meta["trials"] == s.atlas_trials and req.design is not None
        if same and len({c for c in done_chunks(folder) if c[0] < meta["trials"]}) == n_chunks:
            if (folder / "report" / "summary.md").is_file():
                from soabench.experiment.campaigns.atlas.compact import compact

                with FolderLock(folder, "atlas folder"):
                    n = compact(folder).get("trials", 0)  # chunks an earlier layout left: into parts, same rows
                log(f"kept {folder} (the atlas is complete" + (f"; {n} chunks compacted)" if n else ")"))
                return "kept", 0
    o = run_atlas(req, exe, log=log)
    return ("done" if o.complete else "incomplete"), o.n_missing


#: the filter families of the ``filters/`` part (every family of the registry), and the modes every family runs
FILTERS_PART = {"filters": FILTER_FAMILIES, "probabilities": ("static", "static+occ")}
#: the ``filters-lmb-components/`` ablation: the LMB with one Bernoulli per birth component
#: (docs/method.md "LMB filter", birth)
ABLATION_PART = {"filters": ("lmb",), "probabilities": ("static",)}
ABLATION_LMB = {"birth_mapping": "components"}
#: the two families parts' names in the command's table of parts
FAMILIES_PART = "intersection filter families"
ABLATION_PART_NAME = "intersection LMB, one Bernoulli per birth component"
#: the keys a stored families run must share with the requested one
FILTERS_KEYS = (*SIZE_KEYS, "experiment.filters", "experiment.probabilities", "lmb.birth_mapping")


def filters_config(s: Settings) -> Config:
    """The configuration of the ``filters/`` part: the main protocol's sizes with every family."""
    return _base_config(s, s.trials, **FILTERS_PART)


def ablation_config(s: Settings) -> Config:
    """The configuration of the ``filters-lmb-components/`` part: the main protocol's sizes, the LMB with its
    earlier birth mapping."""
    cfg = _base_config(s, s.trials, **ABLATION_PART)
    cfg.lmb = dataclasses.replace(cfg.lmb, **ABLATION_LMB)
    return cfg.validate()


def filters_kept(folder: Path, cfg: Config, log: Callable[[str], None]) -> bool:
    """A families folder complete with the settings of ``cfg`` (:data:`FILTERS_KEYS`): kept as it is."""
    if (folder / "run.json").is_file() and same_settings(folder, cfg, FILTERS_KEYS) and run_complete(folder):
        log(f"kept {folder} (the families run is complete)")
        return True
    return False


def _filters_part(
    folder: Path, s: Settings, exe: RunOptions, log: Callable[[str], None], cfg: Config | None = None
) -> tuple[str, int]:
    """The main protocol on the intersection with every filter family (module docstring) in ``folder`` (``cfg``:
    the ablation's instead), on its own: kept when complete with these settings, else resumed (more trials:
    extended) or started."""
    # imported when called: scipy would slow every start-up
    from soabench.experiment.campaigns.study import Companion

    cfg = cfg if cfg is not None else filters_config(s)
    if filters_kept(folder, cfg, log):
        return "kept", 0
    return _ran(Companion(folder, cfg, FILTERS_KEYS).run("intersection", exe))


def _ran(o: RunOutcome) -> tuple[str, int]:
    """A run's status in the table of parts and its missing trials."""
    return _status(o.complete), o.n_missing


# ------------------------------------------------------------------------------------------------ the command
def run_results(
    out: Path,
    settings: Settings | None = None,
    *,
    options: RunOptions = RUN_DEFAULTS,
    log: Callable[[str], None] | None = None,
) -> ResultsOutcome:
    """Make (or finish) every part of results/ in ``out``; see the module docstring. ``options``: workers and
    progress of every part (the others are each part's own)."""

    workers, progress = options.workers, options.progress
    check_workers(workers)

    shipped = shipped_nets()
    s = (settings or Settings()).validate(shipped)
    scenes = list(s.scenes or shipped)
    log = log or (lambda msg: print(f"soabench results: {msg}", file=sys.stderr, flush=True))
    root = resolve(out)
    own = (
        *shipped,
        "scenes",
        "filters",
        "filters-lmb-components",
        "atlas",
        "kitti",
        "README.md",
        "index.html",
    )  # README.md: results/'s own description
    check_own_folder(root, "results folder", own)
    root.mkdir(parents=True, exist_ok=True)
    hint = f"finish with: soabench results --out {root} (and the same options)"
    exe = RunOptions(workers=workers, progress=progress)
    outcome = ResultsOutcome(root)
    part = "start"

    def step(name: str, work: Callable[[], tuple[str, int]], banner: bool = True) -> None:
        nonlocal part
        part = name
        if banner:
            log(f"== {name} ==")
        t0 = time.perf_counter()
        outcome.parts[name] = "incomplete"  # its place in the table of parts, before those it runs
        status, missing = work()
        outcome.parts[name] = status
        outcome.seconds[name] = time.perf_counter() - t0
        outcome.n_missing += missing

    def intersection() -> tuple[str, int]:
        """The intersection study with the families runs in its trials (module docstring); a families folder
        not run there (kept, or the study kept) is kept or run on its own."""
        from soabench.experiment.campaigns.study import Companion

        folders = {FAMILIES_PART: (root / "filters", filters_config(s)),
                   ABLATION_PART_NAME: (root / "filters-lmb-components", ablation_config(s))}  # fmt: skip
        todo = {n: Companion(f, c, FILTERS_KEYS) for n, (f, c) in folders.items() if not filters_kept(f, c, log)}
        status, missing, done = _study_part(root / "intersection", s, exe, log, companions=tuple(todo.values()))
        ran = dict(zip(todo, done, strict=True)) if done is not None else {}
        for name in folders:
            if name not in todo:
                outcome.parts[name], outcome.seconds[name] = "kept", 0.0
            elif name in ran:  # ran in the study's trials (its time is the study's)
                outcome.parts[name], n_missing = _ran(ran[name])
                outcome.n_missing += n_missing
            else:  # the study was kept: the folder runs on its own
                step(name, lambda c=todo[name]: _ran(c.run("intersection", exe)))
        return status, missing

    with FolderLock(root, "results folder"):
        for scene in s.kitti_scenes:  # cheap checks first: refuse a mismatch before hours of work
            kitti_settings_check(root / "kitti" / scene, _kitti_want(scene, s))
        try:
            mains = {n: root / n / "main" for n in scenes}
            if "intersection" in scenes:
                step("intersection study", intersection)
            for scene in (n for n in scenes if n != "intersection"):
                step(
                    f"{scene} study",
                    lambda scene=scene: _study_part(root / scene, s, exe, log, net=scene, trials=s.scene_trials)[:2],
                )
            densities: dict[str, dict] = {}
            for scene in scenes:

                def measure(scene: str = scene) -> tuple[str, int]:
                    path = root / "scenes" / "density" / f"{scene}.json"
                    densities[scene], kept = write_density(path, scene, _base_config(s, 1), s.density_trials)
                    share = 100 * densities[scene]["occluded_sidewalk"]
                    log(
                        f"{'kept' if kept else 'wrote'} the occlusion density of {scene}: {share:.1f} % of the sidewalk"
                    )
                    return ("kept" if kept else "done"), 0

                step(f"{scene} occlusion density", measure, banner=False)

            def summary() -> tuple[str, int]:
                # imported when called: scipy would slow every start-up
                from soabench.experiment.campaigns.cross_scene import write_summary

                ready = [n for n in scenes if run_complete(mains[n])]
                if ready:
                    triples = [(n, densities[n], mains[n] / "trials.csv") for n in ready]
                    outcome.summary_markdown = write_summary(root / "scenes", triples)
                    log(f"wrote {root / 'scenes' / 'summary.md'} ({len(ready)} of {len(scenes)} scenes)")
                return ("done" if len(ready) == len(scenes) else "incomplete"), 0

            step("cross-scene summary", summary, banner=False)
            for scene in s.atlas_scenes:
                step(
                    f"{scene} atlas",
                    lambda scene=scene: _atlas_part(root / "atlas" / scene, scene, s, exe, log),
                )
            for scene in s.kitti_scenes:
                step(
                    f"{scene} KITTI export and protocol",
                    lambda scene=scene: _kitti_part(root / "kitti" / scene, scene, s, log, progress),
                )
            step("index pages", lambda: _index_pages(root, scenes, log), banner=False)
        except KeyboardInterrupt:
            raise Interrupted(
                f"interrupted during the {part}: finished parts and trials are on disk in {root}; {hint}"
            ) from None
    return outcome
