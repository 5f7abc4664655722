"""The paper's KITTI protocol (§V-A, §V-B; docs/method.md §5.8, §5.9): k-fold cross-validation of N-hat, every
registered birth model on every held-out sequence, the N-hat sweep.

* Folds: consecutive sequences, ``min(folds, n)`` bins as equal as possible (3 per fold for 21 sequences and 7 folds).
* N-hat of a held-out fold = (sum of the ground-truth targets N_seq of the training sequences) / (sum of their
  frames): the duration-weighted mean of the per-sequence birth rates. Equal weights for all birth components.
* N-hat sweep (``--nhat-sweep -10:10``): per sequence, N_tot = N_seq + offset (clipped at >= 1) expected births,
  N-hat = N_tot / frames (§5.8, register row 24).

The run folder holds ``run.json`` (everything needed to resume), one record per (setting, sequence) under
``records/`` (written atomically; ``--resume`` runs the missing ones), then ``summary.json``, ``report.md``,
``sequences.csv``, ``episodes.csv`` and ``figures/`` (:mod:`soabench.experiment.campaigns.kitti.report`).
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from soabench.atomic import write_json_atomic
from soabench.birth import get_birth_model
from soabench.config import Config
from soabench.errors import SoabenchError, require
from soabench.experiment.campaigns.kitti.report import TRACK_COLUMNS, write_outputs
from soabench.experiment.campaigns.kitti.trackeval_kitti import write_inputs
from soabench.experiment.runs.files import read_json
from soabench.folders import FolderLock, check_new_folder, resolve
from soabench.kitti.config import KittiConfig, KittiSpec
from soabench.kitti.formats import ReadError, UnreadableError
from soabench.kitti.levels import level_split
from soabench.kitti.lidar import lidar_files, lidar_semantics
from soabench.kitti.reader import Dataset, KittiSequence, SequenceScans, open_dataset, read_sequence, to_scans
from soabench.metrics import evaluate
from soabench.trackers import FilterTracker, build_filter, run_tracker
from soabench.tracks.evaluate import evaluate_tracks, run_labels

RUN_FILE = "run.json"
RECORDS = "records"
CV = "cv"
#: per-step series kept in a record (Table I uses card_err and ospa over all time steps)
SERIES = ("n_gt", "n_est", "card_err", "ospa", "n_components")


@dataclass
class KittiOutcome:
    run_dir: Path
    complete: bool
    n_missing: int = 0
    summary_markdown: str = ""


# ---------------------------------------------------------------------------------------------------------------------
# folds and N-hat


def fold_partition(ids: Sequence[str], n_folds: int) -> list[list[str]]:
    """``min(n_folds, n)`` folds of consecutive sequences, sizes differing by at most one (larger folds first)."""
    require(isinstance(n_folds, int) and n_folds >= 2, f"--folds {n_folds!r} must be an integer >= 2")
    n = len(ids)
    require(n >= 2, f"cross-validation needs at least 2 sequences, got {n}")
    k = min(n_folds, n)
    bounds = np.cumsum([0] + [n // k + (i < n % k) for i in range(k)])
    return [list(ids[a:b]) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def n_hat(targets: dict[str, int], frames: dict[str, int], train: Sequence[str]) -> float:
    """N-hat = sum_seq N_seq / sum_seq frames over the training sequences (duration-weighted mean birth rate)."""
    total_frames = sum(frames[s] for s in train)
    require(total_frames > 0, "the training sequences have no frames")
    return sum(targets[s] for s in train) / total_frames


def sweep_n_hat(n_seq: int, frames: int, offset: int) -> float:
    """N-hat of the sweep: max(N_seq + offset, 1) / frames (§5.8)."""
    return max(n_seq + offset, 1) / frames


def count_targets(seq: KittiSequence, kcfg: KittiConfig) -> int:
    """N_seq: distinct track ids of the tracked classes in the labels."""
    return len(np.unique(seq.labels.track_id[np.isin(seq.labels.type, kcfg.classes)]))


# ---------------------------------------------------------------------------------------------------------------------
# one (setting, sequence) task


def run_sequence(
    ss: SequenceScans, cfg: Config, N_hat: float, seed: int, seq: str, kitti_seq: KittiSequence | None = None
) -> dict:
    """Every model of ``cfg.experiment`` (first probability mode) in every filter family of
    ``cfg.experiment.filters`` on one sequence with N-hat; a JSON-ready record. ``kitti_seq``: the parsed sequence,
    to add under ``"kitti_results"`` each labelled model's estimates and labels per frame in the first family (for
    :func:`.trackeval_kitti.write_inputs`; not part of the written record).

    Each model gets a fresh filter and the same placement stream ``SeedSequence([seed, int(seq)])`` (a family that
    draws, the LMB, its first child). The first family's runs are ``record["models"]``, every other family's
    ``record["families"][family]`` (so a record of the GM-PHD alone is as before). Wall-clock times go to
    ``record["timing"]``, so everything else is bit-identical for the same inputs and seed.
    """
    mode = cfg.experiment.probabilities[0]
    birth_cfg = dataclasses.replace(cfg.birth, N_hat=float(N_hat))
    run_cfg = dataclasses.replace(cfg, birth=birth_cfg)
    families = cfg.experiment.filters
    out: dict = {"models": {}, "timing": {}}
    for family in families:
        runs = out["models"] if family == families[0] else out.setdefault("families", {}).setdefault(family, {})
        for model in cfg.experiment.models:
            t0 = time.perf_counter()
            runs[model] = _run_model(ss, run_cfg, family, mode, model, seed, seq)
            X, labels = runs[model].pop("estimates")
            if family == families[0] and kitti_seq is not None and labels is not None:
                out.setdefault("kitti_results", {})[model] = (X, labels)
            key = model if family == families[0] else f"{model} ({family})"
            out["timing"][key] = {**runs[model].pop("timing"), "total": time.perf_counter() - t0}
    return out


def _run_model(ss: SequenceScans, cfg: Config, family: str, mode: str, model: str, seed: int, seq: str) -> dict:
    """One birth model in one filter family on one sequence: its summary, episodes, series and track columns."""
    root = np.random.SeedSequence([int(seed), int(seq)])
    rng = np.random.default_rng(root)
    birth = get_birth_model(model)(cfg.birth, ss.sensor, ss.scene, rng)
    filt, p_D_b = build_filter(family, cfg, ss.sensor, mode, np.random.default_rng(root.spawn(1)[0]))
    run = run_tracker(ss.scans, FilterTracker(birth, filt, p_D_b))
    m = evaluate(ss.scans, run.results, cfg.metrics, ss.sensor)
    X = [r.X for r in run.results]
    labels = run_labels(run.results, X)
    tracks = evaluate_tracks(ss.scans, X, labels, m.episodes, cfg.metrics, ss.sensor)
    summary = {k: (v.item() if hasattr(v, "item") else v) for k, v in m.summary.items()}
    timing = {k: summary.pop(k) for k in list(summary) if k.startswith("t_")}  # wall clock: kept apart
    return {
        "summary": summary,
        "episodes": [dataclasses.asdict(e) for e in m.episodes],
        "series": {k: m.series[k].tolist() for k in SERIES},
        "tracks": {k: tracks[k] for k in TRACK_COLUMNS},
        "levels": level_split(ss, X, labels, cfg.metrics),
        "timing": timing,
        "estimates": (X, labels),
    }


# ---------------------------------------------------------------------------------------------------------------------
# the run


def _read_all(ds: Dataset, spec: KittiSpec, log: Callable[[str], None]) -> tuple[dict[str, KittiSequence], list]:
    """Parse every sequence; unreadable files (and, with ``skip_bad``, bad rows) are reported skips."""
    seqs: dict[str, KittiSequence] = {}
    skipped: list[dict] = []
    for s in ds.ids:
        try:
            seqs[s] = read_sequence(ds, s)
            if spec.lidar:
                lidar_files(spec.lidar, seqs[s])
        except ReadError as exc:
            if not (spec.skip_bad or isinstance(exc, UnreadableError)):
                raise
            skipped.append({"sequence": s, "reason": str(exc)})
            log(f"skipped sequence {s}: {exc}")
    return seqs, skipped


def run_kitti(
    spec: KittiSpec | None,
    out: Path,
    resume: bool = False,
    log: Callable[[str], None] | None = None,
) -> KittiOutcome:
    """Run (or finish, ``resume=True``) the protocol into the run folder ``out``: resolved, new or empty for a new
    run (holding this run's ``run.json`` on resume), locked while it works
    (:mod:`soabench.folders`)."""

    log = log or (lambda msg: print(msg, file=sys.stderr, flush=True))
    out = resolve(out)
    run_file = out / RUN_FILE
    if resume:
        require(run_file.is_file(), f"--resume {str(out)!r} is not a `soabench kitti` run folder (no {RUN_FILE})")
        spec = KittiSpec.from_meta(read_json(run_file))
    else:
        require(spec is not None, "a new run needs its settings")
        check_new_folder(out, RUN_FILE, "run", f"finish it with: soabench kitti --resume {out}")
        open_dataset(spec.root, spec.detections, spec.semantics, spec.sequences)  # bad folders: before any write
    created = not out.exists()
    try:
        with FolderLock(out, "KITTI run folder"):
            if not resume:  # again, under the lock
                check_new_folder(out, RUN_FILE, "run", f"finish it with: soabench kitti --resume {out}")
            return _run_locked(spec, out, resume, log)
    except SoabenchError:  # bad data found while reading the sequences: leave no empty run folder behind
        if created and out.is_dir() and not any(out.iterdir()):
            out.rmdir()
        raise


def _run_locked(spec: KittiSpec, out: Path, resume: bool, log: Callable[[str], None]) -> KittiOutcome:
    """The body of :func:`run_kitti` once the folder is checked and locked."""

    run_file = out / RUN_FILE
    assert spec is not None
    ds = open_dataset(spec.root, spec.detections, spec.semantics, spec.sequences)
    seqs, skipped = _read_all(ds, spec, log)
    ids = [s for s in ds.ids if s in seqs]
    folds = fold_partition(ids, spec.folds)
    targets = {s: count_targets(seqs[s], spec.kitti) for s in ids}
    frames = {s: seqs[s].n_frames for s in ids}
    fold_info = []
    tasks: list[tuple[str, str, float]] = []
    for i, held in enumerate(folds):
        train = [s for s in ids if s not in held]
        nh = n_hat(targets, frames, train)
        fold_info.append({"fold": i, "sequences": held, "train": train, "N_hat": nh})
        tasks.extend((CV, s, nh) for s in held)
    for s in ids:  # sequence by sequence, so each sequence's Scans are built once for all offsets
        tasks.extend((f"sweep{o:+d}", s, sweep_n_hat(targets[s], frames[s], o)) for o in spec.nhat_sweep or [])
    if not resume:
        out.mkdir(parents=True, exist_ok=True)
        write_json_atomic(run_file, spec.to_meta())
    models = list(spec.config.experiment.models)
    for setting, s, nh in tasks:  # records of an earlier session must match this data before anything runs
        path = out / RECORDS / setting / f"{s}.json"
        if path.is_file():
            rec = read_json(path)
            rec = rec if isinstance(rec, dict) else {"N_hat": f"a JSON {type(rec).__name__}, not a record"}
            require(
                (rec.get("setting"), rec.get("sequence")) == (setting, s),
                f"{path} is not the record of {setting} sequence {s} (it says {rec.get('setting')!r} sequence "
                f"{rec.get('sequence')!r}); move it away and resume",
            )
            require(
                rec.get("N_hat") == nh
                and set(rec.get("models") or {}) == set(models)
                and set(rec.get("families") or {}) == set(spec.config.experiment.filters[1:]),
                f"{path} was made with other data or settings (N_hat {rec.get('N_hat')!r}, now {nh!r}); "
                "start a new run folder",
            )
    cache: dict[str, SequenceScans] = {}
    sensor = spec.config.sensor_at()
    for n, (setting, s, nh) in enumerate(tasks, start=1):
        path = out / RECORDS / setting / f"{s}.json"
        if path.is_file():
            continue
        if s not in cache:
            if spec.lidar:
                seqs[s].semantics = lidar_semantics(spec.lidar, seqs[s], spec.kitti, sensor, out, log)
            cache = {s: to_scans(seqs[s], spec.kitti, sensor)}  # one sequence in memory at a time
            for note in cache[s].info["notes"]:
                log(f"warning: {note}")
        t0 = time.perf_counter()
        rec = run_sequence(
            cache[s], spec.config, nh, spec.config.experiment.seed, s, seqs[s] if setting == CV else None
        )
        if (
            setting == CV
        ):  # TrackEval's own KITTI evaluation reads these (soabench.experiment.campaigns.kitti.trackeval_kitti)
            write_inputs(out, seqs[s], cache[s], rec.pop("kitti_results", {}))
        rec.update({"setting": setting, "sequence": s, "N_hat": nh, "info": cache[s].info, "targets": targets[s]})
        write_json_atomic(path, rec)
        brief = ", ".join(
            f"{m} card {r['summary']['card_err']:.2f} OSPA {r['summary']['ospa']:.2f}" for m, r in rec["models"].items()
        )
        log(
            f"[{n}/{len(tasks)}] {setting} sequence {s}: {frames[s]} frames, {targets[s]} targets, "
            f"N_hat = {nh:.5f}: {brief} ({time.perf_counter() - t0:.1f} s)"
        )
    records = {}
    missing = 0
    for setting, s, _ in tasks:
        path = out / RECORDS / setting / f"{s}.json"
        if path.is_file():
            records[(setting, s)] = read_json(path)
        else:  # pragma: no cover - only after a failure between writing and reading
            missing += 1
    if missing:
        return KittiOutcome(out, False, missing)
    md = write_outputs(out, spec, fold_info, records, skipped, targets, frames)
    return KittiOutcome(out, True, 0, md)
