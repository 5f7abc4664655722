"""One trial's scene up to a time: the truth, the scans and one birth model's components at the last scan (the
commands ``scene``, ``record`` and ``birth``; docs/method.md §5.8 for the trial seeds, §3 for the birth models)."""

from __future__ import annotations

from dataclasses import dataclass

from soabench import plugins
from soabench import scenario as scenarios  # by attribute: a test may stand in for its simulate
from soabench.config import MAX_SEED, MAX_TRIALS, Config, check_time, filter_config_for_mode, load_config
from soabench.errors import require
from soabench.experiment.trial.guard import check_births
from soabench.gmphd.filter import GMPHDFilter
from soabench.scenario.config import ScenarioConfig
from soabench.scenario.scene import SceneMap
from soabench.seeding import TrialSeeds, trial_seeds
from soabench.sensor import observe
from soabench.types import BirthContext, Births, Recording, Scan, Scans


@dataclass
class Snapshot:
    """Scene, scenario, config, the trial's seeds and the recording up to the snapshot's time."""

    scene: SceneMap
    scenario: ScenarioConfig
    config: Config
    seeds: TrialSeeds
    recording: Recording

    def scans(self) -> Scans:
        """The sensor's scans of the recording, with the trial's sensor seeds (as a run's trial makes them)."""
        return observe(self.recording, self.scene, self.config.sensor_at(), self.seeds.sensor_rngs())


def take_snapshot(
    net: str,
    polys: tuple[str, ...],
    scenario: str | None,
    config: str | None,
    seed: int,
    trial: int,
    duration: float | None,
    command: str,
    include_end: bool = False,
) -> Snapshot:
    """Trial ``trial`` under base seed ``seed`` simulated for ``duration`` seconds (None: the scenario's).

    ``include_end``: simulate one SUMO step more so that a sample (and a scan, when ``duration`` is a multiple of
    the sensor period) lies exactly at ``duration``: a snapshot at ``--time 50`` shows the scan at t = 50 s.
    ``command`` names the command in the one-clutter-rate refusal.
    """
    require(
        0 <= seed <= MAX_SEED,
        f"--seed {seed} must be >= 0" if seed < 0 else f"--seed {seed} is out of range; allowed: 0 to {MAX_SEED}",
    )
    require(
        0 <= trial < MAX_TRIALS,
        f"--trial {trial} must be >= 0"
        if trial < 0
        else f"--trial {trial} is out of range; allowed: 0 to {MAX_TRIALS - 1} (a run's trial indices)",
    )
    check_time("--time/--duration", duration)
    cfg = load_config(config).gmphd_only(f"`soabench {command}`")
    cfg.single_clutter_rate(f"`soabench {command}`")
    scene, scenario_cfg = scenarios.load(net, polys, scenario)
    duration = float(scenario_cfg.duration) if duration is None else duration
    require(duration > 0, f"--time/--duration {duration!r} must be > 0")
    cfg.sensor.validate(scenario_cfg.step_length)
    seeds = trial_seeds(seed, trial)
    if include_end:
        duration = duration + scenario_cfg.step_length
    recording = scenarios.simulate(scene, scenario_cfg, seeds, duration=duration)
    return Snapshot(scene, scenario_cfg, cfg, seeds, recording)


def check_birth_model(model: str) -> type:
    """The class of birth model ``model`` (an unknown or broken model fails here, before SUMO runs)."""
    plugins.allow_import_paths([model])
    return plugins.resolve(plugins.BIRTH, model)


def births_at_end(snap: Snapshot, scans: Scans, model: str, probability: str) -> tuple[Births, Scan]:
    """Birth components of ``model`` at the last scan, after our GM-PHD ran on every scan before it (stateful
    models see their history), and that scan."""
    cls = check_birth_model(model)
    cfg = snap.config
    builtin = plugins.is_builtin_birth(model)
    options = {} if builtin else cfg.plugins.get(model, {})
    plugins.check_options(plugins.BIRTH, model, cls, options)
    filter_cfg, mode, p_D_b = filter_config_for_mode(cfg.filter, probability)
    filt = GMPHDFilter(filter_cfg, cfg.sensor_at(), mode)
    prev = None
    births = Births.empty()
    try:
        birth_model = cls(cfg.birth, cfg.sensor_at(), snap.scene, snap.seeds.placement_rng(), **options)
        for scan in scans.scans:
            births = birth_model(BirthContext(scan, prev, p_D_b))
            if not builtin:
                births = check_births(births, scan)
            prev = filt.step(scan, births)
    except Exception as exc:  # a plugin's error is one line naming it; a built-in's is a bug of soabench
        if builtin:
            raise
        raise plugins.PluginError(f"birth model plugin {model!r} failed: {type(exc).__name__}: {exc}") from None
    return births, scans.scans[-1]
