"""``soabench check``: the example suite of examples/check runs, passes against its own fresh baseline, and a
regression (a baseline S-OA beat) fails with exit status 1, a JUnit failure and a FAIL line."""

from __future__ import annotations

import json
import shutil
import xml.etree.ElementTree as ET

import pytest
from repo_paths import ROOT

from soabench.cli.main import main

pytestmark = pytest.mark.slow  # `soabench check` of the example suite: real runs

SUITE = ROOT / "examples" / "check" / "suite.toml"


def test_example_suite_passes_then_catches_a_regression(tmp_path, capsys) -> None:
    suite = tmp_path / "suite.toml"
    shutil.copy(SUITE, suite)
    out = tmp_path / "out"
    assert main(["check", "--suite", str(suite), "--out", str(out), "--update-baseline"]) == 0
    text = capsys.readouterr().out
    assert "soabench check example: PASS" in text
    base = json.loads((tmp_path / "baseline.json").read_text())
    key = "intersection-static/soa/static/lambda=3/ospa"
    assert base["values"][key] > 0 and not any(k.split("/")[-1].startswith("t_") for k in base["values"])
    report = json.loads((out / "check.json").read_text())
    assert report["passed"] and len(report["checks"]) == 10

    # pretend S-OA used to be 20 % better: the same (deterministic) run is now a regression
    base["values"][key] *= 0.8
    (tmp_path / "baseline.json").write_text(json.dumps(base))
    assert main(["check", "--suite", str(suite), "--out", str(out)]) == 1
    text = capsys.readouterr().out
    assert "FAIL (1 of 10 checks)" in text and f"{key}" in text
    root = ET.parse(out / "junit.xml").getroot()
    cases = list(root.iter("testcase"))
    failed = [c.get("name") for c in cases if c.find("failure") is not None]
    assert failed == [key]
    # every case says its value, bound, trials and time; the suite's compilation of the kernels is apart
    props = {c.get("name"): {p.get("name"): p.get("value") for p in c.iter("property")} for c in cases}
    assert set(props[key]) == {"value", "bound", "trials", "time_s"}
    assert (
        float(props[key]["value"]) == pytest.approx(report["values"][key], rel=1e-5)
        and "baseline" in props[key]["bound"]
    )
    assert int(props[key]["trials"]) >= 1 and float(props[key]["time_s"]) > 0
    suite_props = {p.get("name") for p in root.find("testsuite").find("properties")}
    assert suite_props == {"compile_s", "wall_s"}
    assert not json.loads((out / "check.json").read_text())["passed"]


def test_bad_suites_are_one_line_errors(tmp_path, capsys) -> None:
    suite = tmp_path / "s.toml"
    for text, msg in [
        ('[[scenario]]\nname = "a"\nnet = "intersection"\nmodel = ["soa"]\n', "unknown key 'model'"),
        ('[[scenario]]\nname = "a"\nnet = "intersection"\n[[threshold]]\nmetric = "ospa"\n', "sets none of max"),
        (
            '[[scenario]]\nname = "a"\nnet = "intersection"\n[[threshold]]\nmetric = "ospa"\nmax_increase = 0.1\n',
            "relative thresholds need",
        ),
        ('[suite]\nbaseline = "nope.json"\n[[scenario]]\nname = "a"\nnet = "intersection"\n[[threshold]]\n'
         'metric = "ospa"\nmax_increase = 0.1\n', "create it with soabench check --update-baseline"),
        ('[[scenario]]\nname = "a"\nnet = "intersection"\nmodels = ["nosuch"]\n', "'nosuch' is unknown"),
        ('[[scenario]]\nname = "a"\nnet = "intersection"\npolys = ["nope.poly.xml"]\n', "poly.xml' does not exist"),
        # a misspelled metric is a bad suite (exit 2, naming it and the allowed ones), not a failed check
        ('[[scenario]]\nname = "a"\nnet = "intersection"\n[[threshold]]\nmetric = "opsa"\nmax = 1\n',
         "metric 'opsa' is not a trials.csv metric (did you mean 'ospa'?); allowed: delay_mean, "),
        # so is a misspelled model or mode: refused before the suite runs, with the closest name
        ('[[scenario]]\nname = "a"\nnet = "intersection"\n[[threshold]]\nmetric = "ospa"\nmodel = "sao"\nmax = 1\n',
         "model = 'sao' is not a model or tracker its scenarios run, or '*' (did you mean 'soa'?)"),
        ('[[scenario]]\nname = "a"\nnet = "intersection"\n[[threshold]]\nmetric = "ospa"\nmode = "dynamik"\n'
         'max = 1\n', "mode = 'dynamik' is not a probability mode its scenarios run; allowed: static"),
    ]:  # fmt: skip
        suite.write_text(text)
        assert main(["check", "--suite", str(suite), "--out", str(tmp_path / "o")]) == 2, text
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and msg in err[0], (err, msg)


def test_a_suite_config_that_sets_the_protocol_is_refused(tmp_path, capsys) -> None:
    """The [[scenario]] tables are the one home of the experiment keys in a suite (one of them: the clutter rate)."""
    (tmp_path / "c.toml").write_text("[experiment]\nclutter = [5.0]\n")
    suite = tmp_path / "s.toml"
    suite.write_text('[suite]\nconfig = "c.toml"\n[[scenario]]\nname = "a"\nnet = "intersection"\nclutter = [1.0]\n')
    assert main(["check", "--suite", str(suite), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1 and "[experiment] clutter is set per scenario in a check suite ([[scenario]] clutter)" in err[0]
    )


def test_import_path_plugins_need_plugin_flag_and_a_failed_plugin_fails(
    tmp_path, capsys, typed_plugins_cleared
) -> None:
    suite = tmp_path / "s.toml"
    suite.write_text(
        '[[scenario]]\nname = "a"\nnet = "intersection"\nduration = 6\n'
        'models = ["soa", "plugin_fixtures:RaiseAtScan3"]\ntrackers = ["plugin_fixtures:EchoTracker"]\n'
        '[[threshold]]\nmetric = "gospa"\nmodel = "plugin_fixtures:EchoTracker"\nmin = 0\n'
    )
    assert main(["check", "--suite", str(suite), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()  # the check command's advice, not run's --models
    assert len(err) == 1 and "add --plugin plugin_fixtures:RaiseAtScan3" in err[0] and "--models" not in err[0]
    argv = ["check", "--suite", str(suite), "--out", str(tmp_path / "o")]
    argv += ["--plugin", "plugin_fixtures:RaiseAtScan3", "--plugin", "plugin_fixtures:EchoTracker"]
    assert main(argv) == 1
    out = capsys.readouterr().out
    assert "a/plugin_fixtures:EchoTracker/static/lambda=3/gospa" in out and "FAIL (1 of 2 checks)" in out
    assert "'plugin_fixtures:RaiseAtScan3' failed in trial 0 at scan 3" in out


def test_calibrate_proposes_thresholds_from_repeated_runs(tmp_path, capsys) -> None:
    suite = tmp_path / "s.toml"
    suite.write_text(
        '[[scenario]]\nname = "a"\nnet = "arterial"\ntrials = 1\nduration = 10\n'
        '[[threshold]]\nmetric = "ospa"\nmodel = "soa"\nmax = 100\n'
        '[[threshold]]\nmetric = "recall"\nmodel = "soa"\nmin = 0\n'
    )
    out = tmp_path / "o"
    assert main(["check", "--suite", str(suite), "--out", str(out), "--calibrate", "3"]) == 0
    text = capsys.readouterr().out
    cal = json.loads((out / "calibration.json").read_text())
    assert cal["repetitions"] == 3 and [p["key"] for p in cal["proposals"]] == [
        "a/soa/static/lambda=3/ospa", "a/soa/static/lambda=3/recall"]  # fmt: skip
    ospa, recall = cal["proposals"]
    assert ospa["runs"] == 3 and ospa["low"] < ospa["mean"] < ospa["high"] and ospa["std"] > 0  # three seeds differ
    assert ospa["threshold"] == f"max = {ospa['high']:.6g}" and recall["threshold"] == f"min = {recall['low']:.6g}"
    assert "a/soa/static/lambda=3/ospa" in text and "95 % bounds" in text
    assert "0.40 with 10" in text and "3 runs are few: calibrate with 10 or more." in text  # how many runs it needs
    assert main(["check", "--suite", str(suite), "--out", str(out), "--calibrate", "1"]) == 2
    assert "--calibrate 1 must be an integer >= 2" in capsys.readouterr().err
