"""Settings of the KITTI path (docs/method.md §5.9): what the reader takes from the files and how.

They live in a ``[kitti]`` section of the ``--config`` TOML file beside the usual sections; the KITTI defaults of the
other sections (frame period 0.1 s, OSPA c = 10 m, delay gate 2 m) are in :func:`kitti_base_config`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from soabench.birth import CORE_MODELS
from soabench.config import Config
from soabench.errors import require
from soabench.kitti.formats import KITTI_TYPES
from soabench.tomlfile import read_toml

VEHICLE_CLASSES = ("Car", "Van", "Truck", "Tram")  #: KITTI classes that occlude (obstacles O_k)


@dataclass
class KittiConfig:
    """The ``[kitti]`` section."""

    classes: tuple[str, ...] = ("Pedestrian", "Cyclist")  #: tracked classes (truth and measurements)
    obstacle_classes: tuple[str, ...] = VEHICLE_CLASSES  #: classes whose boxes are occluders
    obstacles: str = "labels"  #: "labels" (like the SUMO path's truth polygons) or "detections"
    score_min: float = -math.inf  #: detections with a lower score are dropped
    fov_deg: float = 0.0  #: horizontal FOV (deg); 0 = from calib P2 and ``image_width`` (nominal without calib)
    image_width: float = 1242.0  #: image width (px) for the FOV from P2
    max_occluded: int = 1  #: labels with KITTI ``occluded`` above this are not "visible" (delay episodes)
    detections_in_fov: bool = True  #: drop detections outside FOV_k (counted in the summary)
    source: str = "match"  #: measurement origin for the metrics: "match" (gated assignment) or "track_id"
    match_gate: float = 2.0  #: gate (m) of the detection-to-truth assignment when ``source = "match"``
    semantic_classes: tuple[str, ...] = ("sidewalk",)  #: semantic classes forming Omega (S-OA semantic births)
    occluder_classes: tuple[str, ...] = ("building",)  #: semantic classes that are static occluders

    def validate(self) -> KittiConfig:
        require(len(self.classes) >= 1, "kitti.classes must name at least one class")
        require(
            not set(self.classes) & set(self.obstacle_classes),
            f"kitti.classes {list(self.classes)} and kitti.obstacle_classes {list(self.obstacle_classes)} overlap; "
            "a tracked class cannot also be an occluder",
        )
        for key in ("classes", "obstacle_classes"):
            bad = [c for c in getattr(self, key) if c not in KITTI_TYPES or c == "DontCare"]
            require(
                not bad,
                f"kitti.{key}: {bad[0] if bad else ''!r} is not a KITTI object type; allowed: "
                + ", ".join(t for t in KITTI_TYPES if t != "DontCare"),
            )
        require(
            not math.isnan(self.score_min) and self.score_min < math.inf,
            f"kitti.score_min = {self.score_min!r} must be a number below inf (inf drops every detection; "
            "default -inf: keep all)",
        )
        require(
            self.obstacles in ("labels", "detections"),
            f"kitti.obstacles = {self.obstacles!r}; choose 'labels' or 'detections'",
        )
        require(self.source in ("match", "track_id"), f"kitti.source = {self.source!r}; choose 'match' or 'track_id'")
        require(0.0 <= self.fov_deg < 180.0, f"kitti.fov_deg = {self.fov_deg!r} must be in [0, 180) (0: from calib)")
        require(self.image_width > 0, f"kitti.image_width = {self.image_width!r} must be > 0")
        require(self.match_gate > 0, f"kitti.match_gate = {self.match_gate!r} must be > 0")
        require(self.max_occluded in (0, 1, 2, 3), f"kitti.max_occluded = {self.max_occluded!r} must be 0, 1, 2 or 3")
        return self


def kitti_base_config() -> Config:
    """The defaults of the KITTI protocol: the paper's c = 10 m OSPA, 10 Hz frames, a 2 m delay gate (§5.4)."""
    cfg = Config()
    cfg.sensor = dataclasses.replace(cfg.sensor, dt=0.1)
    cfg.metrics = dataclasses.replace(cfg.metrics, ospa_c=10.0, d_gate=2.0)
    cfg.experiment = dataclasses.replace(cfg.experiment, models=CORE_MODELS, probabilities=("static",))
    return cfg


def load_kitti_config(path: str | Path | None) -> tuple[Config, KittiConfig]:
    """The config file (TOML; sections of :class:`~soabench.config.Config` plus ``[kitti]``) over the KITTI base."""
    base = kitti_base_config()
    if path is None:
        return base.validate(), KittiConfig().validate()
    p = Path(path)
    require(p.is_file(), f"config file {str(p)!r} does not exist")
    data = read_toml(p, "config file")
    kitti = kitti_from_dict(data.pop("kitti", {}))
    cfg = Config.from_dict(data, base).validate()
    cfg.single_clutter_rate("a KITTI run")
    return cfg, kitti


def kitti_from_dict(values: Any) -> KittiConfig:
    """A :class:`KittiConfig` from ``key = value`` pairs (unknown keys are errors)."""
    require(isinstance(values, dict), "config section [kitti] must be a table of key = value")
    cfg = KittiConfig()
    fields = {f.name for f in dataclasses.fields(cfg)}
    for key, value in values.items():
        require(key in fields, f"unknown config key kitti.{key}; allowed: {', '.join(sorted(fields))}")
        default = getattr(cfg, key)
        if key == "score_min" and value is None:  # how kitti_to_dict writes -inf
            value = -math.inf
        if isinstance(default, tuple):
            require(isinstance(value, (list, tuple)), f"kitti.{key} = {value!r} must be a list")
            value = tuple(str(v) for v in value)
        elif isinstance(default, bool):
            require(isinstance(value, bool), f"kitti.{key} = {value!r} must be true or false")
        elif isinstance(default, float):
            is_num = isinstance(value, (int, float)) and not isinstance(value, bool)
            require(is_num, f"kitti.{key} = {value!r} is not a number")
            value = float(value)
        elif isinstance(default, int):
            is_int = isinstance(value, int) and not isinstance(value, bool)
            require(is_int, f"kitti.{key} = {value!r} is not an integer")
        setattr(cfg, key, value)
    return cfg.validate()


def kitti_to_dict(cfg: KittiConfig) -> dict[str, Any]:
    out = dataclasses.asdict(cfg)
    return {k: list(v) if isinstance(v, tuple) else (None if v == -math.inf else v) for k, v in out.items()}


FORMAT = "soabench-kitti-1"  #: the ``format`` of a KITTI run folder's ``run.json``


@dataclass
class KittiSpec:
    """Everything a KITTI run needs (stored in ``run.json``)."""

    root: str
    detections: str | None
    semantics: str | None
    sequences: list[int] | None
    folds: int
    nhat_sweep: list[int] | None
    skip_bad: bool
    config: Config
    kitti: KittiConfig = field(default_factory=KittiConfig)
    lidar: dict | None = None  #: with segmented scans: velodyne, point_labels and the LidarParams fields (lidar.py)

    def to_meta(self) -> dict:
        return {
            "format": FORMAT,
            "root": self.root,
            "detections": self.detections,
            "semantics": self.semantics,
            "sequences": self.sequences,
            "folds": self.folds,
            "nhat_sweep": self.nhat_sweep,
            "skip_bad": self.skip_bad,
            "config": self.config.to_dict(),
            "kitti": kitti_to_dict(self.kitti),
        } | ({"lidar": self.lidar} if self.lidar else {})

    @classmethod
    def from_meta(cls, meta: dict) -> KittiSpec:
        require(isinstance(meta, dict) and meta.get("format") == FORMAT, "not a `soabench kitti` run folder")
        return cls(
            root=meta["root"],
            detections=meta["detections"],
            semantics=meta["semantics"],
            sequences=meta["sequences"],
            folds=int(meta["folds"]),
            nhat_sweep=meta["nhat_sweep"],
            skip_bad=bool(meta["skip_bad"]),
            config=Config.from_record(meta["config"]).validate(),
            kitti=kitti_from_dict(meta["kitti"]),
            lidar=meta.get("lidar"),
        )


def kitti_run_config(
    path: str | Path | None,
    models: tuple[str, ...] | None = None,
    seed: int | None = None,
    probability: str | None = None,
    classes: tuple[str, ...] | None = None,
    score_min: float | None = None,
    filters: tuple[str, ...] | None = None,
) -> tuple[Config, KittiConfig]:
    """The configuration of a new KITTI run: the file ``path`` (:func:`load_kitti_config`) overlaid by the given
    values (None: the file's), validated; ``filters``: the filter families every model runs in (each must define
    the run's probability mode)."""
    cfg, kcfg = load_kitti_config(path)
    overrides: dict[str, Any] = {"models": models, "seed": seed, "filters": filters}
    if probability is not None:
        overrides["probabilities"] = (probability,)
    cfg.experiment = dataclasses.replace(cfg.experiment, **{k: v for k, v in overrides.items() if v is not None})
    cfg.validate()
    if classes is not None:
        kcfg = dataclasses.replace(kcfg, classes=tuple(classes)).validate()
    if score_min is not None:
        kcfg = dataclasses.replace(kcfg, score_min=float(score_min)).validate()
    return cfg, kcfg
