"""Bad input on the command line: one line and exit 2 for every bad input (a table), a scheduler address refused at
once, Ctrl-C as one line with the resume hint (the report stage included, no worker tracebacks), pool workers
that die with their driver, and a bounded fuzz test of the argument space."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import bad_inputs
import fake_trial as ft
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from processes import alive, children
from repo_paths import TESTS

import soabench.scenario
from soabench.cli.main import main

HERE = TESTS


class Simulated(Exception):
    """Raised by the stubbed simulator: validation passed and a simulation would have started."""


def _messages(err: str) -> list[str]:
    """stderr without the periodic progress lines (off a terminal a run reports progress there)."""
    return [ln for ln in err.strip().splitlines() if not ln.startswith("progress:")]


CATALOGUE = bad_inputs.catalogue()


@pytest.mark.parametrize(("name", "make", "needle"), CATALOGUE, ids=[c[0] for c in CATALOGUE])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, monkeypatch, no_work, name, make, needle):
    monkeypatch.chdir(tmp_path)
    argv = make(tmp_path)
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's usage errors
        code = exc.code
    out, err = capsys.readouterr()
    assert bad_inputs.verdict(code, out, err, needle) == "clean", (name, code, err)
    assert not bad_inputs.STARTED
    assert not (tmp_path / "out" / "run.json").exists()
    assert bad_inputs.foreign_untouched(tmp_path)  # a foreign folder a case offered as --out is left as it was


def test_the_bad_input_catalogue_is_large_distinct_and_covers_every_command():
    names = [c[0] for c in bad_inputs.CASES]
    assert len(names) == len(set(names)) and len(names) >= 400
    from soabench.cli.main import COMMANDS

    assert set(COMMANDS) <= {name.split()[0].rstrip(":") for name in names}


def test_malformed_scheduler_is_refused_at_once(tmp_path, capsys):
    t0 = time.monotonic()
    assert main(["run", "--trials", "1", "--scheduler", "tcp://host:notaport", "--out", str(tmp_path / "o")]) == 2
    assert time.monotonic() - t0 < 5.0  # no connection attempt (it would wait for the 30 s timeout)
    assert "tcp://HOST:PORT" in capsys.readouterr().err


def test_report_stage_ctrl_c_is_one_line_with_the_resume_hint(tmp_path, capsys, monkeypatch):
    import soabench.experiment.reports.report as report

    def interrupted_report(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(report, "write_report", interrupted_report)
    out = tmp_path / "run"
    with ft.as_builtins():
        assert main(["run", "--trials", "2", "--duration", "10", "--workers", "1", "--out", str(out)]) == 130
    lines = _messages(capsys.readouterr().err)
    assert len(lines) == 1 and f"soabench run --resume {out}" in lines[0] and "report" in lines[0]
    monkeypatch.setattr(report, "write_report", lambda run_dir, figures=True, store=None: "summary")
    with ft.as_builtins(trial=None):  # the real trial kind: nothing is left to run
        assert main(["run", "--resume", str(out)]) == 0  # the report is written now


DRIVER = """
import sys
sys.path.insert(0, {here!r})
import fake_trial as ft
from soabench.cli.main import main
with ft.as_builtins(trial=ft.slow_trial):
    code = main({argv!r})
sys.exit(code)
"""


def _driver(argv: list[str]) -> subprocess.Popen:
    code = DRIVER.format(here=str(HERE), argv=argv)
    return subprocess.Popen(
        [sys.executable, "-c", code],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group, as a shell gives a foreground job
    )


def _wait_for(out: Path, n: int, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    t0 = time.monotonic()
    while len(list((out / "trials").glob("trial_*.json"))) < n:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < timeout
        time.sleep(0.05)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_ctrl_c_with_pool_workers_prints_one_line_and_no_worker_traceback(tmp_path):
    out = tmp_path / "run"
    proc = _driver(["run", "--trials", "20", "--duration", "10", "--workers", "2", "--out", str(out)])
    try:
        _wait_for(out, 2, proc)
        os.killpg(proc.pid, signal.SIGINT)  # what a terminal's Ctrl-C does: the whole foreground group
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    lines = _messages(err)
    assert len(lines) == 1 and f"finish with: soabench run --resume {out}" in lines[0], err


@pytest.mark.slow
def test_ctrl_c_with_dask_local_workers_prints_one_line_and_no_worker_traceback(tmp_path):
    from soabench.kernel_warmup import ensure_compiled

    ensure_compiled()  # the kernels in the cache first: the wait below counts trials, not a cold compilation
    out = tmp_path / "run"
    proc = _driver(
        ["run", "--trials", "30", "--duration", "10", "--dask", "local", "--workers", "2", "--out", str(out)]
    )
    try:
        _wait_for(out, 2, proc, timeout=120)
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130
    err = "\n".join(line for line in err.splitlines() if not line.startswith(("INFO", "WARNING")))
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert f"finish with: soabench run --resume {out}" in err.strip().splitlines()[-1]


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_pool_workers_die_with_a_killed_driver(tmp_path):
    out = tmp_path / "run"
    proc = _driver(["run", "--trials", "40", "--duration", "10", "--workers", "2", "--out", str(out)])
    try:
        _wait_for(out, 2, proc)
        workers = children(proc.pid)
        assert workers, "the driver has no worker processes"
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=30)
        t0 = time.monotonic()
        while any(alive(p) for p in workers) and time.monotonic() - t0 < 10:
            time.sleep(0.1)
        assert not any(alive(p) for p in workers), "orphaned workers still run"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    # and the folder resumes: the killed driver's lock is gone with it
    p2 = subprocess.run(
        [sys.executable, "-c", DRIVER.format(here=str(HERE), argv=["run", "--resume", str(out), "--workers", "1"])],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert p2.returncode == 0, p2.stderr
    assert len(list((out / "trials").glob("trial_*.json"))) == 40


# ------------------------------------------------------------------------------------------------ fuzz
VALUES = st.sampled_from(
    ["1", "2", "0", "-1", "1000000000", "nan", "inf", "-inf", "1e300", "0.15", "x", "", "soa", "soa,pubm", "kalman",
     "static", "dynamic+occ", "tcp://127.0.0.1:1", "tcp://", "-10:10", "3:1", "1,2", "é"]
)  # fmt: skip
OPTIONS = st.sampled_from(
    ["--trials", "--duration", "--models", "--probabilities", "--seed", "--workers", "--clutter", "--scheduler",
     "--values", "--offsets", "--time", "--trial", "--model", "--probability", "--sweep-trials", "--births-trials",
     "--bogus"]
)  # fmt: skip
COMMANDS = st.sampled_from(["run", "sweep clutter", "sweep births", "study", "scene", "record", "birth", "nope"])


@pytest.mark.slow
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(COMMANDS, st.lists(st.tuples(OPTIONS, VALUES), max_size=4), st.booleans())
def test_fuzz_the_argument_space(tmp_path_factory, monkeypatch, capsys, fake_builtins, command, options, with_out):
    """Random commands and option values: exit 0/1/2 (or argparse's 2), never another exception or a traceback;
    exit 2 is one line. Trials are the fake trial, figures and simulations are stubbed, so this stays fast."""
    import soabench.experiment.reports.report as report

    monkeypatch.setattr(report, "write_report", lambda run_dir, figures=True, store=None: "summary")
    monkeypatch.setattr(soabench.scenario, "load", lambda *a, **k: (None, SimpleNamespace(step_length=0.1, duration=5)))
    monkeypatch.setattr(soabench.scenario, "simulate", lambda *a, **k: (_ for _ in ()).throw(Simulated()))
    tmp = tmp_path_factory.mktemp("fuzz")
    monkeypatch.chdir(tmp)  # default output folders (results/...) land here
    argv = command.split()
    if command in ("run", "study") or command.startswith("sweep"):
        argv += ["--trials", "1", "--duration", "5"] + (["--births-trials", "1"] if command == "study" else [])
    for opt, val in options:
        argv += [opt, val]
    if with_out:
        argv += ["--out", str(tmp / ("o.png" if command in ("scene", "record", "birth") else "o"))]
    argv += ["--workers", "1"] if command in ("run", "study") or command.startswith("sweep") else []
    capsys.readouterr()
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse: usage errors (2), --help (0)
        code = exc.code
    except Simulated:
        code = 0
    err = capsys.readouterr().err
    assert code in (0, 1, 2, 130), (argv, code, err)
    assert "Traceback" not in err, (argv, err)
    if code == 2 and err.startswith("soabench: error"):
        assert len(_messages(err)) == 1, (argv, err)


def _ctrl_c(*a, **k):
    raise KeyboardInterrupt


def test_ctrl_c_in_the_sweep_report_names_the_sweep_resume(tmp_path, capsys, monkeypatch, fake_cli_runs):
    import soabench.experiment.campaigns.sweep as sweep

    monkeypatch.setattr(sweep, "write_sweep_report", _ctrl_c)
    out = tmp_path / "sw"
    argv = ["sweep", "births", "--offsets", "0,1", "--trials", "1", "--duration", "10", "--workers", "1"]
    assert main([*argv, "--out", str(out)]) == 130
    lines = _messages(capsys.readouterr().err)
    assert len(lines) == 1 and f"finish with: soabench sweep births --resume {out}" in lines[0], lines


def test_ctrl_c_in_the_study_comparison_names_the_study_rerun(tmp_path, capsys, monkeypatch, fake_cli_runs):
    import soabench.experiment.campaigns.study as study
    import soabench.experiment.campaigns.sweep as sweep

    monkeypatch.setattr(sweep, "write_sweep_report", lambda d: "sweep")
    monkeypatch.setattr(study, "write_comparison", _ctrl_c)
    monkeypatch.setattr(study, "paper_protocol_mismatch", lambda meta: None)  # reach the comparison stage
    out = tmp_path / "study"
    argv = ["study", "--trials", "1", "--births-trials", "1", "--duration", "10", "--workers", "1"]
    assert main([*argv, "--out", str(out)]) == 130
    lines = _messages(capsys.readouterr().err)
    assert len(lines) == 1 and f"finish with: soabench study --out {out}" in lines[0], lines
    assert not (out / ".lock").exists()
