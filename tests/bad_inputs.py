"""A table of bad command-line inputs (issue 14): every one must give ONE line on stderr and exit status 2, without
a traceback and without running a trial. Used by tests/test_hardening_cli.py and benchmarks/bench_reliability.py.

Each case is ``(name, make_argv(tmp) -> argv, needle)``: ``make_argv`` may write files under ``tmp`` (a fresh
folder per case); ``needle`` must appear in the error line.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

Case = tuple[str, Callable[[Path], list[str]], str]


def _toml(tmp: Path, text: str) -> str:
    p = tmp / "c.toml"
    p.write_text(text)
    return str(p)


def _run(tmp: Path, *extra: str) -> list[str]:
    return ["run", "--trials", "1", "--duration", "5", "--workers", "1", "--out", str(tmp / "out"), *extra]


def _cfg(text: str, needle: str, command: str = "run") -> Case:
    def make(tmp: Path) -> list[str]:
        if command == "run":
            return _run(tmp, "--config", _toml(tmp, text))
        return [command, "--config", _toml(tmp, text), "--out", str(tmp / "x.png")]

    return (f"{command} config {text.strip()!r}", make, needle)


def _a_file(tmp: Path) -> Path:
    f = tmp / "afile"
    f.write_text("x")
    return f


def _not_utf8(tmp: Path) -> list[str]:
    p = tmp / "latin1.toml"
    p.write_bytes("# caf\xe9\n[experiment]\nclutter = [3.0]\n".encode("latin-1"))
    return _run(tmp, "--config", str(p))


def _unwritable(tmp: Path) -> Path:
    """A folder this process cannot write to: mode 0o500, or /sys for root (who ignores permission bits)."""
    if os.geteuid() == 0:
        return Path("/sys")
    d = tmp / "ro"
    d.mkdir()
    os.chmod(d, 0o500)
    return d


CASES: list[Case] = [
    # configuration: exact types
    _cfg('[filter]\ngate = "no"\n', "must be a boolean"),
    _cfg("[filter]\ngate = 1\n", "must be a boolean"),
    _cfg("[filter]\nJ_max = 1.5\n", "must be an integer"),
    _cfg("[filter]\nJ_max = true\n", "must be an integer"),
    _cfg('[experiment]\ntrials = "5"\n', "must be an integer"),
    _cfg("[experiment]\ntrials = 2.0\n", "must be an integer"),
    _cfg('[experiment]\nclutter = ["3"]\n', "must be a number"),
    _cfg("[experiment]\nclutter = [true]\n", "must be a number"),
    _cfg(
        "[sensor]\nlambda_c = 5.0\n",
        "sensor.lambda_c is not a config key: the clutter rate has one key, experiment.clutter",
    ),
    _cfg("[sensor]\nclutter_space = 1\n", "must be a string"),
    _cfg('[experiment]\nmodels = "soa"\n', "must be a list"),
    _cfg("[experiment]\nmodels = [1]\n", "must be a string"),
    _cfg('[birth]\nrho = [1, "a", 1]\n', "must be a number"),
    _cfg("[sensor]\nvisibility_points = true\n", "must be an integer"),
    _cfg("[metrics]\nddof = false\n", "must be an integer"),
    # configuration: finite ranges
    _cfg("[birth]\nrho = [1.0, inf, 1.0]\n", "birth.rho"),
    _cfg("[birth]\nrho = [1.0, nan, 1.0]\n", "birth.rho"),
    _cfg("[sensor]\nr_max = inf\n", "sensor.r_max = inf"),
    _cfg("[filter]\nsigma_a = 1e300\n", "filter.sigma_a = 1e+300"),
    _cfg("[experiment]\nclutter = [nan]\n", "clutter = nan"),
    _cfg("[experiment]\nclutter = [0.5, 3.0]\n", "gives 2 rates; `soabench scene` observes at one rate", "scene"),
    _cfg("[birth]\nN_hat = 1e9\n", "birth.N_hat"),
    _cfg("[birth]\nd_min = 1e-9\n", "birth.d_min"),
    _cfg("[metrics]\nospa_c = -inf\n", "metrics.ospa_c"),
    _cfg("[experiment]\nduration = inf\n", "duration = inf"),
    _cfg("[experiment]\nseed = -1\n", "seed = -1"),
    _cfg("[filter]\nmerge_U = 0.0\n", "filter.merge_U"),
    _cfg("[filter]\nnonfinite = 'ignore'\n", "filter.nonfinite"),
    # cross-checks against the scenario, for every command
    _cfg("[sensor]\ndt = 0.15\n", "multiple of the SUMO step"),
    _cfg("[sensor]\ndt = 0.15\n", "multiple of the SUMO step", command="scene"),
    _cfg("[sensor]\ndt = 0.15\n", "multiple of the SUMO step", command="birth"),
    (
        "sweep config dt = 0.15",
        lambda t: [
            "sweep",
            "clutter",
            "--config",
            _toml(t, "[sensor]\ndt = 0.15\n"),
            "--trials",
            "1",
            "--out",
            str(t / "sw"),
        ],
        "multiple of the SUMO step",
    ),  # fmt: skip
    # flags
    ("--trials 10^9", lambda t: _run(t)[:1] + ["--trials", "1000000000", "--out", str(t / "o")], "[1, 100000]"),
    ("--trials 0", lambda t: ["run", "--trials", "0", "--out", str(t / "o")], "trials = 0"),
    ("--duration nan", lambda t: ["run", "--duration", "nan", "--out", str(t / "o")], "duration = nan"),
    ("--duration -5", lambda t: ["run", "--duration=-5", "--out", str(t / "o")], "duration = -5"),
    ("--clutter inf", lambda t: _run(t, "--clutter", "inf"), "clutter = inf"),
    ("--seed -3", lambda t: _run(t, "--seed=-3"), "seed = -3"),
    ("--workers 0", lambda t: _run(t)[:-4] + ["--workers", "0", "--out", str(t / "o")], "--workers 0"),
    ("--workers 10^6", lambda t: _run(t)[:-4] + ["--workers", "1000000", "--out", str(t / "o")], "[1, 1024]"),
    ("scene --time inf", lambda t: ["scene", "--time", "inf", "--out", str(t / "s.png")], "--time/--duration inf"),
    ("record --duration 1e12", lambda t: ["record", "--duration", "1e12", "--out", str(t / "r.npz")], "out of range"),
    (
        "sweep births --offsets 1e9",
        lambda t: ["sweep", "births", "--offsets", "0,1000000000", "--trials", "1", "--out", str(t / "sw")],
        "birth.N_hat",
    ),  # fmt: skip
    (
        "sweep clutter --all-figures",
        lambda t: ["sweep", "clutter", "--all-figures", "--trials", "1", "--out", str(t / "sw")],
        "--all-figures belongs to `sweep births`",
    ),  # fmt: skip
    ("study --births-trials 0", lambda t: ["study", "--births-trials", "0", "--out", str(t / "st")], "--births-trials"),
    # scheduler address: refused at once, before any connection attempt
    ("--scheduler garbage", lambda t: _run(t, "--scheduler", "not an address"), "tcp://HOST:PORT"),
    ("--scheduler no port", lambda t: _run(t, "--scheduler", "tcp://localhost"), "tcp://HOST:PORT"),
    ("--scheduler port 0", lambda t: _run(t, "--scheduler", "tcp://127.0.0.1:0"), "tcp://HOST:PORT"),
    ("--scheduler port 99999", lambda t: _run(t, "--scheduler", "127.0.0.1:99999"), "tcp://HOST:PORT"),
    ("--scheduler http", lambda t: _run(t, "--scheduler", "http://127.0.0.1:8786"), "tcp://HOST:PORT"),
    ("--scheduler refused port", lambda t: _run(t, "--scheduler", "tcp://127.0.0.1:1"), "cannot connect"),
    # files
    ("config not UTF-8", _not_utf8, "not UTF-8"),
    ("config is a folder", lambda t: _run(t, "--config", str(t)), "does not exist"),
    ("config missing", lambda t: _run(t, "--config", str(t / "nope.toml")), "does not exist"),
    ("config not TOML", lambda t: _run(t, "--config", _toml(t, "[sensor\n")), "not valid TOML"),
    ("run --out is a file", lambda t: _run(t)[:-2] + ["--out", str(_a_file(t))], "is a file, not a folder"),
    ("run --out under a file", lambda t: _run(t)[:-2] + ["--out", str(_a_file(t) / "run")], "which is a file"),
    ("run --out unwritable", lambda t: _run(t)[:-2] + ["--out", str(_unwritable(t) / "run")], "not writable"),
    ("sweep --out is a file", lambda t: ["sweep", "clutter", "--trials", "1", "--out", str(_a_file(t))], "is a file"),
    ("study --out is a file", lambda t: ["study", "--trials", "1", "--out", str(_a_file(t))], "is a file"),
    ("record --out is a folder", lambda t: ["record", "--out", str(t)], "is a folder"),
    ("record --out under a file", lambda t: ["record", "--out", str(_a_file(t) / "r.npz")], "which is a file"),
    ("record --out unwritable", lambda t: ["record", "--out", str(_unwritable(t) / "r.npz")], "not writable"),
    ("scene --out missing folder", lambda t: ["scene", "--out", str(t / "no" / "s.png")], "does not exist"),
    ("--resume not a folder", lambda t: ["run", "--resume", str(t / "nothing")], "not a run folder"),
    ("--resume a file", lambda t: ["run", "--resume", str(_a_file(t))], "not a run folder"),
    ("--resume without run.json", lambda t: ["run", "--resume", str(t)], "no run.json"),
    ("sweep --resume without sweep.json", lambda t: ["sweep", "clutter", "--resume", str(t)], "no sweep.json"),
    ("--resume with --out", lambda t: ["run", "--resume", str(t), "--out", str(t / "o")], "alternatives"),
    (
        "foreign folder (trials/, no run.json)",
        lambda t: (t / "f" / "trials").mkdir(parents=True) or _run(t)[:-2] + ["--out", str(t / "f")],
        "stale or foreign",
    ),  # fmt: skip
    ("--net missing", lambda t: _run(t, "--net", str(t / "nope.net.xml")), "nope.net.xml"),
]
