"""Config defaults (docs/method.md §1.2, §7), TOML overlay and validation messages."""

from __future__ import annotations

import pytest

from soabench.config import Config, Sensor, filter_config_for_mode, load_config
from soabench.errors import SoabenchError


def test_defaults_are_the_registers_bold_options():
    cfg = Config().validate()
    assert (cfg.sensor.dt, cfg.sensor.r_min, cfg.sensor.r_max, cfg.sensor.fov_deg) == (1.0, 0.5, 50.0, 360.0)
    assert (cfg.sensor.p_D, cfg.sensor.sigma_r, cfg.sensor.sigma_b_deg, cfg.sensor_at().lambda_c) == (
        0.98,
        1.0,
        5.0,
        3.0,
    )
    assert (cfg.filter.p_S, cfg.filter.p_D, cfg.filter.prune_T, cfg.filter.merge_U) == (0.99, 0.98, 1e-5, 4.0)
    assert (cfg.filter.J_max, cfg.filter.form, cfg.filter.extract_thr) == (1000, "ekf", 0.5)
    assert cfg.birth.N_hat == pytest.approx(6 / 100)
    assert (cfg.birth.delta_r, cfg.birth.L, cfg.birth.sigma_par, cfg.birth.sigma_perp) == (2.0, 3, 2.0, 0.75)
    assert (cfg.birth.sem_mode, cfg.birth.d_min, cfg.birth.sigma_sem) == ("poisson", 5.0, 2.0)
    assert (cfg.birth.d_u, cfg.birth.sigma_u, cfg.birth.atbm, cfg.birth.sigma_gm) == (5.0, 2.5, "same_scan", 3.0)
    assert (cfg.metrics.ospa_c, cfg.metrics.ospa_p, cfg.metrics.d_gate, cfg.metrics.gt_set) == (100.0, 1.0, 5.0, "fov")
    assert (cfg.experiment.trials, cfg.experiment.duration, cfg.experiment.clutter) == (100, 100.0, (3.0,))
    assert cfg.experiment.models == ("soa", "pubm", "ubm", "ubm-ws", "atbm", "gmbm")
    assert cfg.experiment.probabilities == ("static", "dynamic")


def test_toml_overlay_and_round_trip(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text('[sensor]\nfov_deg = 120.0\n[birth]\nrho = [2, 1, 1]\n[experiment]\nmodels = ["soa"]\nclutter = [5]\n')
    cfg = load_config(p)
    assert cfg.sensor_at().lambda_c == 5.0 and isinstance(
        cfg.sensor_at().lambda_c, float
    )  # the scans' rate, from the key
    assert cfg.birth.rho == (2, 1, 1) and cfg.experiment.models == ("soa",)
    again = Config.from_dict(cfg.to_dict()).validate()
    assert again == cfg


@pytest.mark.parametrize(
    ("toml", "needle"),
    [
        ("[sensor]\np_D = 1.3\n", "sensor.p_D = 1.3"),
        ("[experiment]\nclutter = [-1]\n", "clutter = -1"),
        ("[sensor]\nr_min = 60.0\n", "r_max"),
        ("[sensor]\nfov_deg = 0.0\n", "sensor.fov_deg"),
        ("[sensor]\nsigma_r = 0.0\n", "sensor.sigma_r"),
        ("[experiment]\ntrials = 0\n", "trials = 0"),
        ("[experiment]\nmodels = ['soa', 'kalman']\n", "'kalman'"),
        ("[birth]\nsem_mode = 'grid'\n", "birth.sem_mode = 'grid'"),
        ("[filter]\nbogus = 1\n", "unknown config key filter.bogus"),
        ("[nonsense]\nx = 1\n", "unknown config section [nonsense]"),
        ("[sensor\n", "not valid TOML"),
    ],
)
def test_bad_values_name_the_value_and_what_is_allowed(tmp_path, toml, needle):
    p = tmp_path / "bad.toml"
    p.write_text(toml)
    with pytest.raises(SoabenchError) as info:
        load_config(p)
    assert needle in str(info.value)
    assert "\n" not in str(info.value)


def test_dt_must_be_a_multiple_of_the_sumo_step():
    cfg = Config()
    cfg.sensor.dt = 0.25
    with pytest.raises(SoabenchError, match="multiple of the SUMO step"):
        cfg.validate(sumo_step=0.1)
    cfg.sensor.dt = 0.3
    cfg.validate(sumo_step=0.1)


def test_probability_modes():
    f = Config().filter
    cfg, mode, p_D_b = filter_config_for_mode(f, "static")
    assert (mode, p_D_b, cfg.occlusion_pd) == ("static", 0.98, False)
    cfg, mode, p_D_b = filter_config_for_mode(f, "dynamic+occ")
    assert (mode, p_D_b, cfg.occlusion_pd) == ("dynamic", f.mu_D0, True)
    assert f.occlusion_pd is False  # the base config is not mutated
    with pytest.raises(SoabenchError, match="probability mode"):
        filter_config_for_mode(f, "sometimes")


def test_missing_config_file():
    with pytest.raises(SoabenchError, match="does not exist"):
        load_config("/nonexistent/cfg.toml")


def test_the_clutter_rate_has_one_key(tmp_path):
    """λ is experiment.clutter: the [sensor] section holds no rate, the sensor of the scans is the section at a rate
    of it, and sensor.lambda_c in a file is refused with one line naming both (docs/user-guide/parameters.md)."""
    cfg = Config.from_dict({"experiment": {"clutter": [5.0, 0.5]}}).validate()
    assert not hasattr(cfg.sensor, "lambda_c") and "lambda_c" not in cfg.to_dict()["sensor"]
    assert cfg.sensor_at().lambda_c == 5.0 and isinstance(cfg.sensor_at(1).lambda_c, float)  # the first rate
    assert cfg.sensor_at(0.5).settings == cfg.sensor and isinstance(cfg.sensor_at(0.5), Sensor)
    assert Config.from_dict(cfg.to_dict()).validate() == cfg
    for data in ({"sensor": {"lambda_c": 5.0}}, {"sensor": {"lambda_c": 5.0}, "experiment": {"clutter": [5.0]}}):
        with pytest.raises(SoabenchError) as err:
            Config.from_dict(data)
        line = str(err.value)
        assert "\n" not in line and "sensor.lambda_c" in line and "experiment.clutter" in line
    with pytest.raises(SoabenchError, match=r"sensor.lambda_c = -1.0"):
        cfg.sensor_at(-1.0).validate()
    with pytest.raises(SoabenchError, match=r"experiment.clutter = \[0.5, 3.0\] gives 2 rates; `soabench scene`"):
        Config.from_dict({"experiment": {"clutter": [0.5, 3.0]}}).validate().single_clutter_rate("`soabench scene`")


def test_a_run_record_with_the_sensor_rate_is_read():
    """Run files that record sensor.lambda_c beside experiment.clutter read as their experiment.clutter."""
    stored = Config.from_dict({"experiment": {"clutter": [0.5, 3.0, 5.0]}}).to_dict()
    stored["sensor"]["lambda_c"] = 3.0
    cfg = Config.from_record(stored).validate()
    assert cfg.experiment.clutter == (0.5, 3.0, 5.0) and cfg.sensor_at().lambda_c == 0.5


def test_the_clutter_sweep_takes_its_rates_from_values_only(tmp_path, capsys):
    from soabench.cli.main import main

    cfg = tmp_path / "c.toml"
    cfg.write_text("[experiment]\nclutter = [5.0]\n")
    for extra in (["--config", str(cfg)], ["--clutter", "2"]):
        assert main(["sweep", "clutter", "--trials", "1", "--duration", "5", "--out", str(tmp_path / "s"), *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "`sweep clutter` takes its clutter rates from --values" in err[0]
    assert not (tmp_path / "s").exists()
