"""Every documented config key reaches the code that uses it (docs/user-guide/parameters.md).

The keys are read from the parameters page itself (its generated tables), so a key added to
:class:`soabench.config.Config` without a row on the page, or a row without a key, fails here. Each key is set to a
non-default valid value; per key, a short run records it in its resolved configuration (``run.json``), and in one
trial a spy on the configuration's sections sees it read, with the value set, by the code outside
``soabench/config.py`` that uses it (the keys a trial does not read show in the run's rows instead: the number of
trials, the seed, the scans). A key that is set but never read with its value, such as a clutter rate the trial
overwrote, fails here.
"""

from __future__ import annotations

import dataclasses
import json
import re
import sys
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from repo_paths import ROOT
from shapely.geometry import Polygon

import soabench.config as config_module
from soabench import plugins
from soabench.config import (
    BirthConfig,
    Config,
    ExperimentConfig,
    FilterConfig,
    LMBConfig,
    MetricsConfig,
    PMBMConfig,
    Sensor,
    SensorConfig,
)
from soabench.errors import SoabenchError
from soabench.experiment.execution.options import RunOptions
from soabench.gmphd import GMPHDFilter
from soabench.types import Births, Scan

TRACKER = "plugin_fixtures:EchoTracker"
PAGE = ROOT / "docs" / "user-guide" / "parameters.md"

#: a valid value other than the default for every key of the parameters page
NON_DEFAULT: dict[str, object] = {
    "sensor.dt": 2.0,
    "sensor.r_min": 1.0,
    "sensor.r_max": 40.0,
    "sensor.fov_deg": 300.0,
    "sensor.p_D": 0.9,
    "sensor.sigma_r": 0.8,
    "sensor.sigma_b_deg": 4.0,
    "sensor.clutter_space": "cartesian",
    "sensor.visibility_points": 3,
    "sensor.visibility_offset": 0.25,
    "filter.form": "ukf",
    "filter.sigma_a": 0.6,
    "filter.p_S": 0.98,
    "filter.p_D": 0.95,
    "filter.prune_T": 2e-5,
    "filter.merge_U": 3.5,
    "filter.J_max": 900,
    "filter.gate": False,
    "filter.gate_prob": 0.995,
    "filter.extract_thr": 0.45,
    "filter.extraction": "top_n",
    "filter.occlusion_pd": True,
    "filter.max_undetected_birth_age": 7,
    "filter.nonfinite": "drop",
    "filter.beta_factor": 1.2,
    "filter.theta_min": 2.5,
    "filter.n_D": 12.0,
    "filter.mu_D0": 0.97,
    "filter.n_S": 22.0,
    "filter.mu_S0": 0.985,
    "filter.p_S_max": 0.998,
    "birth.N_hat": 0.07,
    "birth.sigma_v_birth": 1.1,
    "birth.delta_in": 0.6,
    "birth.delta_r": 2.5,
    "birth.L": 2,
    "birth.sigma_par": 2.2,
    "birth.sigma_perp": 0.8,
    "birth.ray_start": "centroid",
    "birth.occl_velocity_prior": True,
    "birth.occluders_from_detections": True,
    "birth.sem_mode": "dbscan",
    "birth.sem_resample": "step",
    "birth.sem_include_crossings": True,
    "birth.d_min": 6.0,
    "birth.sigma_sem": 2.2,
    "birth.poisson_k": 20,
    "birth.dbscan_eps": 1.5,
    "birth.dbscan_min_samples": 4,
    "birth.dbscan_split": True,
    "birth.d_fov": 6.0,
    "birth.sigma_fov": 2.2,
    "birth.fov_boundary": "visible",
    "birth.rho": (1.0, 0.5, 0.8),
    "birth.rho_norm": "source",
    "birth.pubm_space": "cart",
    "birth.pubm_hybrid": 0.2,
    "birth.d_u": 6.0,
    "birth.sigma_u": 2.2,
    "birth.ubm_extent": "workspace",
    "birth.atbm": "prev_scan",
    "birth.atbm_alloc": "unexplained",
    "birth.atbm_raw_mass": True,
    "birth.sigma_gm": 2.5,
    "metrics.ospa_c": 90.0,
    "metrics.ospa_p": 2.0,
    "metrics.gospa_c": 4.0,
    "metrics.gospa_p": 2.0,
    "metrics.gt_set": "visible",
    "metrics.d_gate": 4.0,
    "metrics.g_min": 2,
    "metrics.confirm_n": 2,
    "metrics.censored": "lower_bound",
    "metrics.ddof": 1,
    "metrics.gap_bins": (1, 3, 6),
    "experiment.trials": 1,
    "experiment.duration": 6.0,
    "experiment.models": ("gmbm", "atbm", "ubm-ws", "ubm", "pubm", "soa"),  # all six, in another order
    "experiment.trackers": (TRACKER,),
    "experiment.probabilities": ("static", "dynamic", "dynamic+occ"),
    "experiment.clutter": (5.0,),
    "experiment.seed": 4,
    "lmb.r_B_max": 0.4,
    "lmb.prune_r": 2e-3,
    "lmb.max_tracks": 80,
    "lmb.max_hypotheses": 500,
    "lmb.max_components": 8,
    "lmb.extract_r": 0.55,
    "lmb.birth_mapping": "components",  # the old mapping: every other lmb key is still read
    "lmb.association": "exact",
    "pmbm.M_max": 50,
    "pmbm.w_floor": 1e-3,
    "pmbm.r_floor": 1e-4,
    "pmbm.J_h": 8,
    "experiment.filters": ("lmb", "gmphd", "pmbm"),  # three families, the LMB first
    "experiment.plugin_budget": 30.0,  # its reach: tests/hardening/test_plugin_isolation.py (a plugin past its budget)
}

#: the switches that select which other keys are read: the second trial sets them back to their defaults so that
#: the keys they gate (Poisson-disk candidates, ATBM's same-scan mass, the chi-square gate, the extraction
#: threshold) are read too
SWITCHES_BACK = {
    "birth.sem_mode": "poisson",
    "birth.atbm": "same_scan",
    "filter.gate": True,
    "filter.extraction": "vo_ma",
}

SPIED = {
    "sensor": SensorConfig,
    "filter": FilterConfig,
    "birth": BirthConfig,
    "metrics": MetricsConfig,
    "experiment": ExperimentConfig,
    "lmb": LMBConfig,
    "pmbm": PMBMConfig,
}
#: documented keys with a single allowed value (the PMB's marginals come from the Murty hypotheses only): no
#: non-default value exists, so the test checks that every other value is refused instead
SINGLE_VALUED = {"pmbm.marginals": "lbp"}
#: properties that read a key: the consumer uses the radians of a key given in degrees
PROPERTY_KEYS = {"sigma_b": "sigma_b_deg", "fov": "fov_deg"}


def config_keys() -> set[str]:
    """The keys of :class:`Config`."""
    cfg = Config()
    return {f"{sec}.{f.name}" for sec in SPIED for f in dataclasses.fields(getattr(cfg, sec))}


def page_keys() -> set[str]:
    """The keys the parameters page documents: a row ``| `key` | ...`` under a ``### `[section]``` heading of its
    generated block (``[plugins]`` holds each plugin's own options, no key of ours)."""
    text = PAGE.read_text(encoding="utf-8")
    block = text.split("<!-- soabench:parameters -->", 1)[1].split("<!-- /soabench -->", 1)[0]
    keys, section = set(), None
    for line in block.splitlines():
        heading = re.match(r"### `\[(\w+)\]`", line)
        if heading:
            section = heading.group(1)
            continue
        row = re.match(r"\| `(\w+)` \|", line)
        if row and section != "plugins":
            keys.add(f"{section}.{row.group(1)}")
    return keys


DOCUMENTED = sorted(page_keys())
#: the documented keys a trial does not read, and what of the run shows them instead
SHOWN_BY_THE_RUN = {"experiment.trials", "experiment.duration", "experiment.seed", "metrics.gap_bins"}


def as_sections(values: dict[str, object]) -> dict[str, dict[str, object]]:
    out: dict[str, dict[str, object]] = {}
    for key, value in values.items():
        sec, name = key.split(".")
        out.setdefault(sec, {})[name] = list(value) if isinstance(value, tuple) else value
    return out


@pytest.fixture(autouse=True)
def _tracker_plugin():
    plugins.allow_import_paths([TRACKER])


def test_the_page_documents_every_key_and_no_other():
    assert page_keys() == config_keys()


def test_every_documented_key_has_a_non_default_value():
    assert set(NON_DEFAULT) == set(DOCUMENTED) - set(SINGLE_VALUED)
    defaults = dataclasses.asdict(Config())  # every key (to_dict leaves out the families' keys at their defaults)
    for key, value in NON_DEFAULT.items():
        sec, name = key.split(".")
        assert value != defaults[sec][name], key


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory):
    """A one-trial run of every non-default value: its stored configuration, its trial rows and its scan rows."""
    from soabench.experiment.reports.finished import run_experiment
    from soabench.experiment.runs.files import read_csv

    plugins.allow_import_paths([TRACKER])
    run = tmp_path_factory.mktemp("reach") / "run"
    cfg = Config.from_dict(as_sections(NON_DEFAULT)).validate()
    out = run_experiment(cfg, "intersection", out=run, options=RunOptions(workers=1, progress=False, figures=False))
    assert out.complete and out.failures == []
    stored = json.loads((run / "run.json").read_text())["config"]
    summary = json.loads((run / "summary.json").read_text())
    return stored, read_csv(run / "trials.csv"), read_csv(run / "steps.csv"), summary


@pytest.mark.parametrize("key", sorted(SINGLE_VALUED))
def test_a_single_valued_key_refuses_every_other_value(key):
    with pytest.raises(SoabenchError, match=re.escape(key)):
        Config.from_dict(as_sections({**NON_DEFAULT, key: SINGLE_VALUED[key]})).validate()


@pytest.mark.parametrize("key", [k for k in DOCUMENTED if k not in SINGLE_VALUED])
def test_a_run_records_the_key(key, recorded_run):
    stored, *_ = recorded_run
    sec, name = key.split(".")
    value = NON_DEFAULT[key]
    assert stored[sec][name] == (list(value) if isinstance(value, tuple) else value)
    assert "lambda_c" not in stored["sensor"]  # λ is recorded once, as experiment.clutter


@pytest.mark.parametrize("key", sorted(SHOWN_BY_THE_RUN))
def test_the_run_shows_the_key(key, recorded_run):
    _, rows, steps, summary = recorded_run
    exp = Config.from_dict(as_sections(NON_DEFAULT)).experiment
    shown = {
        "experiment.trials": set(rows["trial"]) == set(range(exp.trials)),
        "experiment.seed": set(rows["seed"]) == {exp.seed},
        # one row per scan k = 0 .. duration / dt - 1
        "experiment.duration": set(steps["k"]) == set(range(int(exp.duration / NON_DEFAULT["sensor.dt"]))),
        # the summary's occlusion breakdowns are binned by it (this short run has no gap to put in a bin)
        "metrics.gap_bins": {tuple(r["occlusion"]["bin_labels"]) for r in summary["results"]} == {("1-2", "3-5", "6+")},
    }
    assert shown[key]


def test_the_rows_hold_every_method_mode_and_rate(recorded_run):
    _, rows, *_ = recorded_run
    exp = Config.from_dict(as_sections(NON_DEFAULT)).experiment
    assert set(rows["clutter"]) == set(exp.clutter)
    assert set(rows["model"]) == {*exp.models, *exp.trackers}
    assert set(rows["mode"]) == set(exp.probabilities)
    birth = np.isin(rows["model"], exp.models)  # a whole tracker is no family's: its filter cell is empty
    assert set(rows["filter"][birth]) == set(exp.filters) and set(rows["filter"][~birth]) == {""}


def spied(section: str, cls: type, reads: dict[str, set]) -> type:
    """``cls`` logging ``{section.key: values read}`` when code outside soabench/config.py and the dataclass
    machinery (copies, comparisons, conversion to dicts) reads a key."""
    skip = {str(Path(config_module.__file__)), dataclasses.__file__, "<string>"}
    names = {f.name for f in dataclasses.fields(cls)}

    def getattribute(self, name):
        value = object.__getattribute__(self, name)
        key = PROPERTY_KEYS.get(name, name)
        if key in names and sys._getframe(1).f_code.co_filename not in skip:
            reads.setdefault(f"{section}.{key}", set()).add(
                repr(object.__getattribute__(self, key) if key != name else value)
            )
        return value

    return type(cls.__name__, (cls,), {"__getattribute__": getattribute})


def spy_config(values: dict[str, object], reads: dict[str, set]) -> Config:
    """``values`` as a Config whose sections log the keys read (:func:`spied`)."""
    plain = Config.from_dict(as_sections(values)).validate()
    cfg = Config(
        **{sec: spied(sec, cls, reads)(**dataclasses.asdict(getattr(plain, sec))) for sec, cls in SPIED.items()}
    )
    cfg.plugins = plain.plugins
    return cfg.validate()


@pytest.fixture(scope="module")
def reads() -> dict[str, set]:
    """``{key: values read}`` by the code outside soabench/config.py over two trials: every non-default value, then
    the switches back at their defaults (so that the keys they gate are read too), and one scan with a NaN."""
    from soabench.experiment.trial.trial import run_trial
    from soabench.scenario import load

    plugins.allow_import_paths([TRACKER])
    scene, scenario = load("intersection")
    seen: dict[str, set] = {}
    # the sensor a trial builds from [sensor] at each clutter rate (Config.sensor_at) logs its reads too
    with mock.patch.object(config_module, "Sensor", spied("sensor", Sensor, seen)):
        for values in (NON_DEFAULT, {**NON_DEFAULT, **SWITCHES_BACK}):
            cfg = spy_config(values, seen)
            result = run_trial(0, cfg, scene, scenario)
            assert result.failures == [] and result.rows
        # filter.nonfinite is read only when an input is not finite: one scan with a NaN measurement
        scan = Scan(0, 0.0, np.zeros(3), np.array([[10.0, 0.1], [np.nan, 0.2]]), None, [], Polygon())
        assert GMPHDFilter(cfg.filter, cfg.sensor_at()).step(scan, Births.empty()).n_dropped == 1
    return seen


def test_the_scans_clutter_rate_is_the_experiments(reads):
    assert reads["sensor.lambda_c"] == {"5.0"}  # the scans' clutter rate is experiment.clutter's, unchanged


@pytest.mark.parametrize("key", [k for k in DOCUMENTED if k not in SHOWN_BY_THE_RUN | set(SINGLE_VALUED)])
def test_the_key_reaches_its_consumer_with_its_value(key, reads):
    value = NON_DEFAULT[key]
    want = repr(tuple(value) if isinstance(value, (tuple, list)) else value)
    assert want in reads.get(key, set()), (
        f"{key} = {want} never reaches its consumer (read: {sorted(reads.get(key, set()))})"
    )
