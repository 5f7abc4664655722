"""CLI behaviour a user sees: bad input gives one line naming the problem and exit status 2, no traceback,
and no output file."""

from __future__ import annotations

import subprocess
import sys

import pytest

from soabench.cli.main import main


def _run(argv, capsys):
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.fixture()
def bad_files(tmp_path):
    malformed = tmp_path / "broken.net.xml"
    malformed.write_text("<net version='1.20'><edge id='a'>")  # not well-formed
    scenario = tmp_path / "bad_scenario.toml"
    scenario.write_text("duration = -5.0\n")
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[sensor]\np_D = 1.3\n")
    return {"malformed": malformed, "scenario": scenario, "config": cfg}


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["record", "--net", "/no/such/file.net.xml", "--out", "{tmp}/r.npz"], "/no/such/file.net.xml"),
        (["record", "--net", "no_such_shipped_net", "--out", "{tmp}/r.npz"], "no_such_shipped_net"),
        (["record", "--net", "{malformed}", "--out", "{tmp}/r.npz"], "broken.net.xml"),
        (["record", "--scenario", "{scenario}", "--out", "{tmp}/r.npz"], "duration"),
        (["record", "--poly", "/no/such/poly.xml", "--out", "{tmp}/r.npz"], "/no/such/poly.xml"),
        (["record", "--config", "{config}", "--out", "{tmp}/r.npz"], "sensor.p_D = 1.3"),
        (["record", "--out", "/no/such/dir/r.npz"], "/no/such/dir"),
        (["run", "--trials", "0", "--out", "{tmp}/run"], "trials = 0"),
        (["run", "--clutter", "-1", "--out", "{tmp}/run"], "clutter = -1"),
        (["run", "--config", "{config}", "--out", "{tmp}/run"], "sensor.p_D = 1.3"),
        (["run", "--resume", "/no/such/run"], "/no/such/run"),
    ],
)
def test_bad_input_one_line_exit_2_no_output(tmp_path, capsys, bad_files, argv, needle):
    argv = [a.format(tmp=tmp_path, **bad_files) for a in argv]
    code, _, err = _run(argv, capsys)
    assert code == 2
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("soabench: error:")
    assert needle in lines[0]
    assert not (tmp_path / "r.npz").exists()
    assert not (tmp_path / "run").exists()


def test_unknown_model_is_rejected_in_one_line(capsys):
    # names are checked against the plugin registry (built-ins, entry points, typed import paths), not argparse
    assert main(["run", "--models", "soa,kalman"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'kalman' is unknown" in err[0]


def test_console_script_prints_no_traceback(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "soabench.cli", "record", "--net", str(tmp_path / "nope.net.xml"), "--out", "x.npz"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert "nope.net.xml" in proc.stderr
