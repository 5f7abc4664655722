"""Output files a user gets: modes from the user's umask, sensor parameters in the scans file,
defaults in every ``--help``."""

from __future__ import annotations

import argparse
import json
import math
import os
import stat

import numpy as np
import pytest

from soabench.atomic import write_json_atomic, write_text_atomic
from soabench.cli.main import build_parser, main
from soabench.cli.parsing import DefaultsHelpFormatter
from soabench.config import Sensor
from soabench.errors import SoabenchError
from soabench.types import SENSOR_UNITS, Scans


@pytest.fixture
def umask():
    old = os.umask(0o022)
    yield lambda mask: os.umask(mask)
    os.umask(old)


@pytest.mark.parametrize("mask", [0o022, 0o027, 0o002])
def test_atomic_writes_follow_the_umask(tmp_path, umask, mask):
    umask(mask)
    write_text_atomic(tmp_path / "summary.md", "x\n")
    write_json_atomic(tmp_path / "deep" / "summary.json", {"a": 1})
    for path in (tmp_path / "summary.md", tmp_path / "deep" / "summary.json"):
        assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~mask, oct(path.stat().st_mode)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary file left


def test_record_scans_carry_the_sensor_parameters_and_units(tmp_path, umask):
    umask(0o022)
    cfg_file = tmp_path / "sensor.toml"
    cfg_file.write_text("[sensor]\nfov_deg = 120.0\nsigma_b_deg = 3.0\n[experiment]\nclutter = [2.5]\n")
    out = tmp_path / "rec.npz"
    assert main(["record", "--duration", "3", "--config", str(cfg_file), "--out", str(out), "--scans"]) == 0
    scans_path = tmp_path / "rec.scans.npz"
    for path in (out, scans_path):
        assert stat.S_IMODE(path.stat().st_mode) == 0o644
    expected = Sensor(fov_deg=120.0, lambda_c=2.5, sigma_b_deg=3.0)
    with np.load(scans_path, allow_pickle=False) as d:
        assert float(d["sigma_r"]) == expected.sigma_r and float(d["p_D"]) == expected.p_D
        assert float(d["sigma_b"]) == pytest.approx(math.radians(3.0))
        assert float(d["fov"]) == pytest.approx(math.radians(120.0))
        assert float(d["lambda_c"]) == 2.5 and float(d["dt"]) == expected.dt
        assert (float(d["r_min"]), float(d["r_max"])) == (expected.r_min, expected.r_max)
        meta = json.loads(str(d["sensor_json"]))
    assert meta["units"] == SENSOR_UNITS and meta["units"]["sigma_b"] == "rad"
    assert meta["config"]["fov_deg"] == 120.0
    assert Scans.load_npz(scans_path).sensor == expected


def test_scans_without_a_sensor_are_not_exported(tmp_path):
    scans = Scans([], 1.0, [], np.zeros((0, 0, 2)), *(np.zeros((0, 0), bool),) * 4, np.zeros(0, str))
    with pytest.raises(SoabenchError, match="carry no Sensor"):
        scans.save_npz(tmp_path / "s.npz")
    assert not (tmp_path / "s.npz").exists()


def _commands(parser: argparse.ArgumentParser):
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices


def test_every_option_shows_its_default():
    parser = build_parser()
    missing = []
    for name, command in [("soabench", parser), *_commands(parser).items()]:
        formatter = DefaultsHelpFormatter(name)
        for action in command._actions:
            takes_value = action.nargs != 0  # flags (store_true, --help, --version) are off unless given
            if action.option_strings and takes_value and not action.required:
                if not action.help or "default" not in formatter._get_help_string(action):
                    missing.append(f"{name} {action.option_strings[0]}")
    assert missing == []
    text = _commands(parser)["birth"].format_help()
    assert "(default: soa)" in " ".join(text.split()) and "(default: static)" in text
    assert "(default: 0)" in _commands(parser)["scene"].format_help()
