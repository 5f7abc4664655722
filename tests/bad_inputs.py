"""The catalogue of bad inputs: every case must give ONE line on stderr and exit status 2, without a traceback,
without running a trial or a simulation, and without writing into a folder that is not the command's own. Used by
tests/test_hardening_cli.py (in-process, through :func:`soabench.cli.main.main`) and benchmarks/bench_reliability.py
tests/hardening/test_command_line.py (in-process, through :func:`soabench.cli.main`) and benchmarks/bench_reliability.py
(each case in a forked process with a time bound, counted as clean / traceback / silent / hang / unclear).

Each case is ``(name, make_argv(tmp) -> argv, needle)``: ``make_argv`` may write files under ``tmp`` (a fresh
folder per case, also the working directory); ``needle`` must appear in the error line. The catalogue is organised
by command (:data:`BY_COMMAND`); :func:`catalogue` adds the cases of ``tests/bad_inputs_more.py`` when that module
exists (its ``CASES`` list has the same format).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from soabench.experiment.execution.options import RunOptions

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


_CONFIG_AND_RUN: list[Case] = [
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
        "1000000000",
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


# ------------------------------------------------------------------------------------------------ shared material
OSM_FIXTURE = Path(__file__).parent / "data" / "crossroads.osm"


def _kitti_root(tmp: Path) -> str:
    from kitti_files import write_dataset

    return str(write_dataset(tmp / "kitti", n=2, n_frames=6))


def _suite(tmp: Path, scenarios: str, extra: str = "") -> str:
    """A check suite with the given ``[[scenario]]`` text and one absolute threshold."""
    p = tmp / "suite.toml"
    p.write_text(f'[suite]\nname = "t"\n{extra}\n{scenarios}\n[[threshold]]\nmetric = "ospa"\nmax = 100.0\n')
    return str(p)


GOOD_SCENARIO = '[[scenario]]\nname = "a"\nnet = "intersection"\nduration = 5\n'


#: modification time (ns) of each foreign folder made by :func:`_foreign`, by path
_FOREIGN_MTIME: dict[str, int] = {}


def _foreign(tmp: Path, name: str = "theirs") -> Path:
    """A folder holding someone else's files (never to be written into, nor probed: its modification time must not
    change)."""
    d = tmp / name
    d.mkdir()
    (d / "README.md").write_text("mine\n")
    (d / "notes.txt").write_text("mine\n")
    _FOREIGN_MTIME[str(d)] = d.stat().st_mtime_ns
    return d


def foreign_untouched(tmp: Path) -> bool:
    """The foreign folder ``tmp/theirs`` (if a case made one) holds its two files and was not modified (no file
    created in it, even for a moment)."""
    theirs = tmp / "theirs"
    if not theirs.is_dir():
        return True
    same = _FOREIGN_MTIME.get(str(theirs), theirs.stat().st_mtime_ns) == theirs.stat().st_mtime_ns
    return same and sorted(p.name for p in theirs.iterdir()) == ["README.md", "notes.txt"]


#: the commands with a valid argument list each (a bad value or flag is put into them)
def _base(command: str, tmp: Path) -> list[str]:
    out = str(tmp / "o")
    quick = ["--trials", "1", "--duration", "5", "--workers", "1"]
    return {
        "scene": ["scene", "--out", str(tmp / "s.png")],
        "record": ["record", "--out", str(tmp / "r.npz")],
        "birth": ["birth", "--out", str(tmp / "b.png")],
        "run": ["run", *quick, "--out", out],
        "sweep clutter": ["sweep", "clutter", *quick, "--out", out],
        "sweep births": ["sweep", "births", *quick, "--out", out],
        "sweep occlusion": ["sweep", "occlusion", *quick, "--out", out],
        "study": ["study", *quick, "--births-trials", "1", "--out", out],
        "sensitivity": ["sensitivity", "--main", str(tmp / "main"), "--out", out],
        "results": ["results", "--out", out, "--scenes", "intersection", "--kitti-scenes", "none", "--trials", "1"],
        "kitti": ["kitti", "--root", _kitti_root(tmp), "--out", out],
        "export": ["export", "kitti", "--trials", "1", "--duration", "5", "--out", out],
        "check": ["check", "--suite", _suite(tmp, GOOD_SCENARIO), "--out", out],
        "import": ["import", "osm", str(OSM_FIXTURE), "--out", out],
        "scenes": ["scenes"],
        "atlas": ["atlas", *quick, "--axis", "sensor.p_D=0.8,0.9", "--out", out],
        "query": ["query", str(tmp), "SELECT 1"],
    }[command]


def _with(command: str, *extra: str) -> Callable[[Path], list[str]]:
    return lambda t: [*_base(command, t), *extra]


def _needle(value: str) -> str:
    """How an error line names ``value``: quoted when empty, a float as Python prints it (1e300 -> 1e+300)."""
    if value == "":
        return "''"
    if "e" in value:
        try:
            return repr(float(value))
        except ValueError:
            pass
    return value


# ------------------------------------------------------------------------------------------------ every command
#: bad values by kind of option
COUNT = ("x", "1.5", "", "0", "-1", "1000000000")
SEED = ("x", "1.5", "", "-1", "99999999999999999999999")
INDEX = ("x", "1.5", "", "-1")
WORKERS = ("x", "0", "-1", "1000000")
SECONDS = ("x", "nan", "inf", "-inf", "-1", "0", "1e300", "")
RATES = ("x", "nan", "inf", "-1", "", ",", "1,x", "1e300")
OFFSETS = ("x", "3:1", "1:2:0", "1:2:3:4", "", "0:1000000000", "0,1000000000", "1.5:3")

#: (command, option, bad values)
OPTION_VALUES: list[tuple[str, str, tuple[str, ...]]] = [
    ("scene", "--seed", SEED),
    ("scene", "--trial", INDEX),
    ("scene", "--time", SECONDS),
    ("record", "--seed", SEED),
    ("record", "--trial", INDEX),
    ("record", "--duration", SECONDS),
    ("birth", "--seed", SEED),
    ("birth", "--trial", INDEX),
    ("birth", "--time", SECONDS),
    ("run", "--trials", COUNT),
    ("run", "--duration", SECONDS),
    ("run", "--seed", SEED),
    ("run", "--workers", WORKERS),
    ("run", "--clutter", RATES),
    ("sweep clutter", "--trials", COUNT),
    ("sweep clutter", "--duration", SECONDS),
    ("sweep clutter", "--seed", SEED),
    ("sweep clutter", "--workers", WORKERS),
    ("sweep clutter", "--values", RATES),
    ("sweep births", "--trials", COUNT),
    ("sweep births", "--duration", SECONDS),
    ("sweep births", "--seed", SEED),
    ("sweep births", "--offsets", OFFSETS),
    ("sweep births", "--clutter", RATES),
    ("sweep occlusion", "--trials", COUNT),
    ("sweep occlusion", "--values", RATES),
    ("study", "--trials", COUNT),
    ("study", "--duration", SECONDS),
    ("study", "--seed", SEED),
    ("study", "--workers", WORKERS),
    ("study", "--sweep-trials", COUNT),
    ("study", "--births-trials", COUNT),
    ("study", "--sensitivity-trials", COUNT),
    ("sensitivity", "--trials", COUNT),
    ("sensitivity", "--workers", WORKERS),
    ("results", "--trials", COUNT),
    ("results", "--duration", SECONDS),
    ("results", "--seed", SEED),
    ("results", "--births-trials", COUNT),
    ("results", "--scene-trials", COUNT),
    ("results", "--density-trials", COUNT),
    ("results", "--kitti-sequences", COUNT),
    ("results", "--kitti-duration", SECONDS),
    ("results", "--kitti-folds", COUNT),
    ("results", "--workers", WORKERS),
    ("kitti", "--folds", ("x", "1.5", "", "0", "-1", "1")),  # more folds than sequences: one per sequence
    ("kitti", "--seed", SEED),
    ("kitti", "--score-min", ("x", "nan", "inf", "")),
    ("kitti", "--nhat-sweep", OFFSETS),
    ("kitti", "--sequences", ("x", "3-1", "-1", "", "0-99999999", "0,99999999999999999999", "0-3-5", "a-b")),
    ("export", "--trials", COUNT),
    ("export", "--duration", SECONDS),
    ("export", "--seed", SEED),
    ("export", "--fov-deg", SECONDS),
    ("check", "--workers", WORKERS),
]


def _option_cases() -> list[Case]:
    cases: list[Case] = []
    for command, option, values in OPTION_VALUES:
        for v in values:
            if command == "results" and option == "--kitti-sequences" and v == "1.5":
                continue
            cases.append((f"{command} {option} {v!r}", _with(command, f"{option}={v}"), _needle(v)))
    return cases


ALL_COMMANDS = (
    "scene", "record", "birth", "run", "sweep clutter", "sweep births", "sweep occlusion", "study", "sensitivity",
    "results", "kitti", "export", "check", "import", "scenes", "atlas", "query",
)  # fmt: skip


def _usage_cases() -> list[Case]:
    """Unknown options, a missing value, stray arguments: for every command."""
    cases: list[Case] = [
        ("no command", lambda t: [], "COMMAND"),
        ("unknown command", lambda t: ["frobnicate"], "frobnicate"),
        ("unknown top-level option", lambda t: ["--frobnicate", "scenes"], "--frobnicate"),
        ("sweep unknown kind", lambda t: ["sweep", "wind", "--trials", "1"], "wind"),
        ("export unknown format", lambda t: ["export", "motchallenge", "--trials", "1", "--out", "x"], "motchallenge"),
        ("import unknown kind", lambda t: ["import", "shapefile", "x.shp", "--out", "x"], "shapefile"),
        ("run --dask remote", _with("run", "--dask", "remote"), "remote"),
        ("birth --probability sometimes", _with("birth", "--probability", "sometimes"), "sometimes"),
        ("kitti --probability sometimes", _with("kitti", "--probability", "sometimes"), "sometimes"),
        ("run --probabilities sometimes", _with("run", "--probabilities", "sometimes"), "sometimes"),
        ("run --models ''", _with("run", "--models="), "''"),
        ("run --models ,", _with("run", "--models", ","), "','"),
        ("kitti --models nope", _with("kitti", "--models", "nope"), "nope"),
        ("kitti --classes ''", _with("kitti", "--classes="), "''"),
        ("results --scenes nowhere", _with("results", "--scenes", "nowhere"), "nowhere"),
        ("results --kitti-scenes nowhere", _with("results", "--kitti-scenes", "nowhere"), "nowhere"),
        ("export without --trials", lambda t: ["export", "kitti", "--out", str(t / "e")], "--trials"),
        ("check without --suite", lambda t: ["check"], "--suite"),
        ("sensitivity without --main", lambda t: ["sensitivity"], "--main"),
        ("import without --out", lambda t: ["import", "osm", str(OSM_FIXTURE)], "--out"),
        ("scene without --out", lambda t: ["scene"], "--out"),
    ]
    for command in ALL_COMMANDS:
        cases.append((f"{command} unknown option", _with(command, "--frobnicate", "1"), "--frobnicate"))
        cases.append((f"{command} stray argument", _with(command, "stray"), "stray"))
    for command, option in (
        ("run", "--trials"), ("run", "--seed"), ("scene", "--time"), ("record", "--scans-x"),
        ("study", "--births-trials"),
        ("kitti", "--folds"), ("export", "--fov-deg"), ("check", "--workers"), ("results", "--seed"),
        ("sensitivity", "--trials"), ("sweep births", "--offsets"), ("sweep clutter", "--values"),
    ):  # fmt: skip
        cases.append((f"{command} {option} without a value", _with(command, option), option))
    return cases


# ------------------------------------------------------------------------------------------------ output paths
def _sensitivity(tmp: Path, out: str, finished: bool = True) -> list[str]:
    """``sensitivity --main`` a (fake) run of 2 trials, finished or with one trial missing."""

    import fake_trial as ft

    from soabench.config import Config
    from soabench.experiment.reports.finished import run_experiment

    cfg = Config()
    cfg.experiment = dataclasses.replace(cfg.experiment, trials=2, duration=10.0, models=("soa",))
    kw = dict(
        options=RunOptions(workers=1, progress=False, figures=False), trial_fn=ft.fake_trial, load_fn=ft.fake_load
    )
    run_experiment(cfg.validate(), "intersection", out=tmp / "main", **kw)
    if not finished:
        (tmp / "main" / "trials" / "trial_00001.json").unlink()
    return ["sensitivity", "--main", str(tmp / "main"), "--out", out, "--workers", "1"]


def _out_is(command: str, make_out: Callable[[Path], str], flag: str = "--out") -> Callable[[Path], list[str]]:
    """``command``'s valid argument list with its output path replaced by ``make_out(tmp)``."""

    def make(tmp: Path) -> list[str]:
        argv = _base(command, tmp)
        out = make_out(tmp)
        if flag in argv:
            argv[argv.index(flag) + 1] = out
            return argv
        return [*argv, flag, out]

    return make


FOLDER_COMMANDS = ("run", "sweep clutter", "sweep births", "study", "kitti", "export", "check", "import", "results")
FILE_COMMANDS = ("scene", "record", "birth")


def _output_cases() -> list[Case]:
    cases: list[Case] = []
    for c in FOLDER_COMMANDS:
        cases += [
            (f"{c}: --out ''", _out_is(c, lambda t: ""), "--out ''"),
            (f"{c}: --out is a file", _out_is(c, lambda t: str(_a_file(t))), "is a file"),
            (f"{c}: --out under a file", _out_is(c, lambda t: str(_a_file(t) / "x")), "which is a file"),
            (f"{c}: --out unwritable", _out_is(c, lambda t: str(_unwritable(t) / "x")), "not writable"),
            (f"{c}: --out a foreign folder", _out_is(c, lambda t: str(_foreign(t))), "not empty"),
            (f"{c}: --out the working folder", _out_is(c, lambda t: (_a_file(t), ".")[1]), "not empty"),
        ]
    for c in FILE_COMMANDS:
        suffix = ".npz" if c == "record" else ".png"
        cases += [
            (f"{c}: --out ''", _out_is(c, lambda t: ""), "--out"),
            (f"{c}: --out is a folder", _out_is(c, lambda t: str(t)), "is a folder"),
            (f"{c}: --out under a file", _out_is(c, lambda t, x=suffix: str(_a_file(t) / f"x{x}")), "which is a file"),
            (f"{c}: --out unwritable", _out_is(c, lambda t, x=suffix: str(_unwritable(t) / f"x{x}")), "not writable"),
            (f"{c}: --out missing folder", _out_is(c, lambda t, x=suffix: str(t / "no" / f"x{x}")), "does not exist"),
            (f"{c}: --out wrong suffix", _out_is(c, lambda t: str(t / "x.xyz")), "x.xyz"),
        ]
    cases += [
        ("sensitivity: --out a foreign folder", lambda t: _sensitivity(t, str(_foreign(t))), "not empty"),
        ("sensitivity: --out is the main run", lambda t: _sensitivity(t, str(t / "main")), "main"),
        ("sensitivity: --main not finished", lambda t: _sensitivity(t, str(t / "o"), finished=False), "not finished"),
        ("sensitivity: --main a foreign folder", lambda t: ["sensitivity", "--main", str(_foreign(t))], "no run.json"),
        ("record --scans same as --out", _with("record", "--scans", "r.npz"), "--scans"),
        ("record --scans is a folder", _with("record", "--scans", "."), "is a folder"),
        ("record --scans wrong suffix", _with("record", "--scans", "r.txt"), "r.txt"),
    ]
    return cases


# ------------------------------------------------------------------------------------------------ inputs: files
def _input_cases() -> list[Case]:
    cases: list[Case] = []
    for c in ("scene", "record", "birth", "run", "sweep clutter", "export"):
        cases += [
            (f"{c} --net missing", _with(c, "--net", "nope.net.xml"), "nope.net.xml"),
            (f"{c} --net not XML", _with_file(c, "--net", "n.net.xml", "not xml"), "n.net.xml"),
            (f"{c} --net unknown scene", _with(c, "--net", "atlantis"), "atlantis"),
            (f"{c} --poly missing", _with(c, "--poly", "nope.poly.xml"), "nope.poly.xml"),
            (f"{c} --scenario missing", _with(c, "--scenario", "nope.toml"), "nope.toml"),
            (f"{c} --scenario not TOML", _with_file(c, "--scenario", "s.toml", "[x"), "s.toml"),
            (f"{c} --config missing", _with(c, "--config", "nope.toml"), "nope.toml"),
            (f"{c} --config unknown section", _with_file(c, "--config", "c.toml", "[nope]\na = 1\n"), "nope"),
        ]  # fmt: skip
    cases += [
        ("study --poly", _with("study", "--poly", "b.poly.xml"), "b.poly.xml"),
        ("study --scenario", _with("study", "--scenario", "s.toml"), "s.toml"),
        ("study --net missing", _with("study", "--net", "nope.net.xml"), "nope.net.xml"),
        ("study --net unknown scene", _with("study", "--net", "atlantis"), "atlantis"),
        ("study --config missing", _with("study", "--config", "nope.toml"), "nope.toml"),
    ]
    return cases


def _with_file(command: str, option: str, name: str, text: str) -> Callable[[Path], list[str]]:
    """``command``'s valid arguments and ``option FILE``, FILE holding ``text``."""
    return lambda t: [*_base(command, t), option, _text(t, name, text)]


def _text(tmp: Path, name: str, text: str) -> str:
    p = tmp / name
    p.write_text(text)
    return str(p)


# ------------------------------------------------------------------------------------------------ kitti
def _kitti_cases() -> list[Case]:
    def root_with(edit: Callable[[Path], None]) -> Callable[[Path], list[str]]:
        def make(tmp: Path) -> list[str]:
            argv = _base("kitti", tmp)
            edit(Path(argv[2]))
            return argv

        return make

    return [
        ("kitti without --root", lambda t: ["kitti", "--out", str(t / "o")], "--root"),
        ("kitti without --out", lambda t: ["kitti", "--root", _kitti_root(t)], "--out"),
        ("kitti --root missing", lambda t: ["kitti", "--root", str(t / "no"), "--out", "o"], "is not a folder"),
        ("kitti --root is a file", lambda t: ["kitti", "--root", str(_a_file(t)), "--out", "o"], "not a folder"),
        ("kitti --root without label_02", lambda t: ["kitti", "--root", str(t), "--out", str(t / "o")], "label_02"),
        ("kitti --detections missing", _with("kitti", "--detections", "nodets"), "nodets"),
        ("kitti --semantics missing", _with("kitti", "--semantics", "nosem"), "nosem"),
        ("kitti --sequences not labelled", _with("kitti", "--sequences", "7"), "0007"),
        ("kitti --config missing", _with("kitti", "--config", "nope.toml"), "nope.toml"),
        ("kitti --resume missing", lambda t: ["kitti", "--resume", str(t / "none")], "none"),
        ("kitti --resume with --root", lambda t: ["kitti", "--resume", str(t), "--root", str(t)], "--root"),
        ("kitti --resume a foreign folder", lambda t: ["kitti", "--resume", str(_foreign(t))], "theirs"),
        ("kitti detections extra sequence", root_with(lambda r: (r / "detections" / "0009.txt").touch()), "0009"),
        ("kitti no detections for a sequence", root_with(lambda r: (r / "detections" / "0001.txt").unlink()), "0001"),
        ("kitti label row too short", root_with(lambda r: (r / "label_02" / "0000.txt").write_text("0 1\n")), "0000"),
    ]  # fmt: skip


# ------------------------------------------------------------------------------------------------ check suites
def _suite_case(name: str, scenarios: str, needle: str, extra: str = "") -> Case:
    return (
        f"check suite {name}",
        lambda t: ["check", "--suite", _suite(t, scenarios, extra), "--out", str(t / "o")],
        needle,
    )


def _check_cases() -> list[Case]:
    s = GOOD_SCENARIO
    return [
        _suite_case("scenario name ../../x", '[[scenario]]\nname = "../../../../x"\nnet = "intersection"\n', "../../"),
        _suite_case("scenario name absolute", '[[scenario]]\nname = "/tmp/x"\nnet = "intersection"\n', "/tmp/x"),
        _suite_case("scenario name with a slash", '[[scenario]]\nname = "a/b"\nnet = "intersection"\n', "a/b"),
        _suite_case("scenario name empty", '[[scenario]]\nname = ""\nnet = "intersection"\n', "''"),
        _suite_case("scenario name ..", '[[scenario]]\nname = ".."\nnet = "intersection"\n', "'..'"),
        _suite_case("scenario name a number", '[[scenario]]\nname = 5\nnet = "intersection"\n', "5"),
        _suite_case("scenario name with NUL", '[[scenario]]\nname = "a\\u0000b"\nnet = "intersection"\n', "a\\x00b"),
        _suite_case("scenario without net", '[[scenario]]\nname = "a"\n', "net"),
        _suite_case("no scenario", "", "[[scenario]]"),
        _suite_case("unknown suite key", s, "colour", extra="colour = 1"),
        _suite_case("scenario unknown key", s + "colour = 1\n", "colour"),
        _suite_case("trials 0", s + "trials = 0\n", "trials"),
        _suite_case("trials 10^9", s + "trials = 1000000000\n", "trials"),
        _suite_case("seeds empty", s + "seeds = []\n", "seeds"),
        _suite_case("seeds negative", s + "seeds = [-1]\n", "seeds"),
        _suite_case("duration nan", '[[scenario]]\nname = "a"\nnet = "intersection"\nduration = nan\n', "duration"),
        _suite_case("duration 1e12", '[[scenario]]\nname = "a"\nnet = "intersection"\nduration = 1e12\n', "duration"),
        _suite_case("clutter -1", s + "clutter = [-1.0]\n", "clutter"),
        _suite_case("models not a list", s + 'models = "soa"\n', "models"),
        _suite_case("models unknown", s + 'models = ["nope"]\n', "nope"),
        _suite_case("probabilities unknown", s + 'probabilities = ["sometimes"]\n', "sometimes"),
        _suite_case("net missing file", '[[scenario]]\nname = "a"\nnet = "nets/none.net.xml"\n', "none.net.xml"),
        _suite_case("names repeat", s + s, "repeat"),
        _suite_case("baseline outside the suite folder", s, "../b.json", extra='baseline = "../b.json"'),
        _suite_case("baseline absolute", s, "/tmp/b.json", extra='baseline = "/tmp/b.json"'),
        _suite_case("baseline missing", s + '[[threshold]]\nmetric = "ospa"\nmax_increase = 0.1\n', "none.json",
                    extra='baseline = "none.json"'),
        ("check suite relative threshold without baseline",
         lambda t: ["check", "--suite", _text(t, "s.toml", s + '[[threshold]]\nmetric = "ospa"\nmax_increase = 0.1\n'),
                    "--out", str(t / "o")], "baseline"),
        ("check suite missing", lambda t: ["check", "--suite", str(t / "none.toml"), "--out", "o"], "none.toml"),
        ("check suite not TOML", lambda t: ["check", "--suite", _text(t, "s.toml", "[suite"), "--out", "o"], "s.toml"),
        ("check suite is a folder", lambda t: ["check", "--suite", str(t), "--out", str(t / "o")], "does not exist"),
        ("check --plugin not module:Class", _with("check", "--plugin", "nocolon"), "nocolon"),
    ]  # fmt: skip


# ------------------------------------------------------------------------------------------------ import osm
def _osm(tmp: Path, text: str, name: str = "m.osm") -> str:
    return _text(tmp, name, text)


def _import_cases() -> list[Case]:
    def imp(make_file: Callable[[Path], str], needle: str, name: str) -> Case:
        return (f"import osm {name}", lambda t: ["import", "osm", make_file(t), "--out", str(t / "scene")], needle)

    def into(make_out: Callable[[Path], str], needle: str, name: str) -> Case:
        return (f"import osm --out {name}", lambda t: ["import", "osm", str(OSM_FIXTURE), "--out", make_out(t)], needle)

    def with_scene(t: Path) -> str:
        d = t / "done"
        d.mkdir()
        (d / "scenario.toml").write_text("")
        return str(d)

    return [
        imp(lambda t: str(t / "none.osm"), "none.osm", "missing file"),
        imp(lambda t: str(t), "does not exist", "a folder"),
        imp(lambda t: _osm(t, "<osm"), "not valid XML", "not XML"),
        imp(lambda t: _osm(t, "<gpx/>"), "gpx", "not OSM"),
        imp(lambda t: _osm(t, "<osm></osm>"), "no roads", "no roads"),
        imp(lambda t: _osm(t, '<osm><way id="1"><tag k="highway" v="track"/><tag k="foot" v="no"/></way></osm>'),
            "walkable", "no walkway"),
        imp(lambda t: _osm(t, '<!DOCTYPE osm [<!ENTITY a "aa">]><osm>&a;</osm>'), "m.osm", "entity"),
        imp(lambda t: (Path(t / "b.osm").write_bytes(b"\xff\xfe<osm>"), str(t / "b.osm"))[1], "b.osm", "not UTF-8"),
        into(with_scene, "already holds a scene", "holding a scene"),
        into(lambda t: str(_foreign(t)), "not empty", "a foreign folder"),
        into(lambda t: str(_a_file(t)), "is a file", "a file"),
        into(lambda t: str(t / "no" / "such" / "scene"), "does not exist", "under a missing folder"),
        into(lambda t: "", "--out ''", "''"),
        into(lambda t: (_a_file(t), ".")[1], "not empty", "the working folder"),
    ]  # fmt: skip


# ------------------------------------------------------------------------------------------------ replay, report
def _replay_cases() -> list[Case]:
    def bad_run(t: Path) -> str:
        (t / "r").mkdir()
        (t / "r" / "run.json").write_text("[1")
        return str(t / "r")

    return [
        ("replay missing run", lambda t: ["replay", str(t / "nope"), "--trial", "0"], "is not a run folder"),
        ("replay folder without run.json", lambda t: ["replay", str(t), "--trial", "0"], "no run.json"),
        ("replay run.json not JSON", lambda t: ["replay", bad_run(t), "--trial", "0"], "run.json"),
        ("replay --trial -1", lambda t: ["replay", str(t), "--trial", "-1"], "--trial -1"),
        ("replay --trial x", lambda t: ["replay", str(t), "--trial", "x"], "'x'"),
        ("replay without --trial", lambda t: ["replay", str(t)], "--trial"),
        ("report missing run", lambda t: ["report", str(t / "nope")], "is not a run folder"),
        ("report folder without runs", lambda t: ["report", str(t)], "no run.json"),
        ("report run.json not JSON", lambda t: ["report", bad_run(t)], "run.json"),
    ]  # fmt: skip


# ------------------------------------------------------------------------------------------------ atlas, query
def _atlas(*extra: str) -> Callable[[Path], list[str]]:
    quick = ["--trials", "1", "--duration", "5", "--workers", "1", "--no-progress"]
    return lambda t: ["atlas", *quick, "--out", str(t / "atl"), *extra]


def _not_an_atlas(tmp: Path) -> str:
    d = tmp / "notes"
    d.mkdir()
    (d / "x.txt").write_text("mine\n")
    return str(d)


def _atlas_cases() -> list[Case]:
    return [
        ("atlas axis unknown key", _atlas("--axis", "nope.x=1,2"), "axis 'nope.x' is unknown"),
        ("atlas axis value out of range", _atlas("--axis", "sensor.p_D=1.5,0.9"), "sensor.p_D = 1.5 is out of range"),
        ("atlas axis empty", _atlas("--axis", "sensor.p_D="), "axis sensor.p_D is empty"),
        ("atlas axis clutter -1", _atlas("--axis", "experiment.clutter=-1"), "clutter = -1.0 is out of range"),
        ("atlas axis NaN", _atlas("--axis", "birth.N_hat=nan"), "value 'nan' is not allowed"),
        ("atlas axis value twice", _atlas("--axis", "sensor.p_D=0.9,0.9"), "names 0.9 twice"),
        ("atlas axis unknown family", _atlas("--axis", "filters=kalman"), "'kalman' is unknown"),
        ("atlas axis unknown scene", _atlas("--axis", "net=atlantis"), "'atlantis'"),
        ("atlas axis count 1e12", _atlas("--axis", "pedestrians.count=1e12"), "pedestrians.count = 1000000000000"),
        ("atlas too many trials", _atlas("--axis", "sensor.p_D=0.5,0.6,0.7", "--trials=10000"), "add --force"),
        ("atlas sobol without points", _atlas("--axis", "sensor.p_D=0.5:0.9", "--sample", "sobol"), "--points"),
        ("query not an atlas", lambda t: ["query", _not_an_atlas(t), "SELECT 1"], "neither an atlas"),
        ("query missing folder", lambda t: ["query", str(t / "nowhere"), "SELECT 1"], "is not a folder"),
        ("query failing SQL", lambda t: ["query", _atlas_run(t), "SELEC 1"], "the SQL failed"),
        ("query unknown column", lambda t: ["query", _atlas_run(t), "SELECT nope FROM trials"], "the SQL failed"),
        ("query SQL writing a file", lambda t: ["query", _atlas_run(t), f"COPY (SELECT 1) TO '{t / 'leak.csv'}'"],
         "file system operations are disabled"),
        ("query SQL reading a file", lambda t: ["query", _atlas_run(t), "SELECT * FROM read_csv('/etc/passwd')"],
         "file system operations are disabled"),
        ("query empty SQL", lambda t: ["query", _atlas_run(t), ""], "the SQL is empty"),
        ("query --out wrong suffix", lambda t: ["query", _atlas_run(t), "SELECT 1", "--out", str(t / "q.txt")],
         "a .csv or .parquet file"),
        ("query --out missing folder",
         lambda t: ["query", _atlas_run(t), "SELECT 1", "--out", str(t / "no" / "q.csv")], "does not exist"),
    ]  # fmt: skip


def _atlas_run(tmp: Path) -> str:
    """A finished run folder of the tests' fake trial (what ``query`` reads besides an atlas)."""
    import fake_trial as ft

    from soabench.config import Config
    from soabench.experiment.reports.finished import run_experiment

    cfg = Config()
    cfg.experiment = dataclasses.replace(cfg.experiment, trials=2, duration=10.0, models=("soa",))
    opts = RunOptions(workers=1, progress=False, figures=False)
    run_experiment(cfg.validate(), "x", out=tmp / "r", options=opts, trial_fn=ft.fake_trial, load_fn=ft.fake_load)
    return str(tmp / "r")


# ------------------------------------------------------------------------------------------------ the catalogue
def _sections() -> dict[str, list[Case]]:
    return {
        "configuration and run": _CONFIG_AND_RUN,
        "option values": _option_cases(),
        "usage": _usage_cases(),
        "output paths": _output_cases(),
        "input files": _input_cases(),
        "kitti": _kitti_cases(),
        "check suites": _check_cases(),
        "import osm": _import_cases(),
        "replay and report": _replay_cases(),
        "atlas and query": _atlas_cases(),
    }


SECTIONS = _sections()
CASES: list[Case] = [c for cases in SECTIONS.values() for c in cases]


def command_of(argv: list[str]) -> str:
    """The command a case exercises (``sweep`` with its kind), for the per-command counts."""
    if not argv or argv[0].startswith("-"):
        return "(none)"
    if argv[0] == "sweep" and len(argv) > 1 and not argv[1].startswith("-"):
        return f"sweep {argv[1]}"
    return argv[0]


def catalogue() -> list[Case]:
    """This module's cases and, when present, those of ``tests/bad_inputs_more.py`` (same format)."""
    import importlib.util

    more = Path(__file__).with_name("bad_inputs_more.py")
    if not more.is_file():
        return list(CASES)
    spec = importlib.util.spec_from_file_location("bad_inputs_more", more)
    module = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(module)
    return [*CASES, *module.CASES]


# ------------------------------------------------------------------------------------------------ running a case
class WorkStarted(BaseException):
    """Raised by the stubs of :func:`work_stubbed`: the input was accepted and real work (a trial, a SUMO simulation,
    a KITTI sequence, netconvert) would have started. A BaseException, so that no error handler records it as a
    failed trial; :data:`STARTED` counts the calls in case one does."""


STARTED: list[str] = []


def _started(*args, **kwargs):
    STARTED.append("work")
    raise WorkStarted


@contextmanager
def work_stubbed(setattr_: Callable) -> Iterator[None]:
    """A block in which every entry point of real work is :func:`_started`: the built-in trial kind (through the
    registry's public hook) and, with ``setattr_`` (pytest's ``monkeypatch.setattr``), the SUMO simulation, the KITTI
    sequence and netconvert."""
    import soabench.experiment.campaigns.kitti.protocol
    import soabench.scenario
    import soabench.scenario.osm
    from soabench.experiment.trial import registry

    setattr_(soabench.scenario, "simulate", _started)
    setattr_(soabench.experiment.campaigns.kitti.protocol, "run_sequence", _started)
    setattr_(soabench.scenario.osm, "_tool", _started)
    with registry.registered({registry.DEFAULT_TRIAL_KIND: _started}):
        yield


def messages(err: str) -> list[str]:
    """stderr without the periodic progress lines (off a terminal a run reports progress there)."""
    return [ln for ln in err.strip().splitlines() if not ln.startswith("progress:")]


def verdict(code: object, out: str, err: str, needle: str) -> str:
    """``clean`` (exit 2, one line ``soabench: error: ...`` naming ``needle``), ``traceback``, ``silent`` (any
    other exit, or work started) or ``unclear`` (exit 2 but not one line naming the value)."""
    if "Traceback" in out or "Traceback" in err:
        return "traceback"
    if code != 2:
        return "silent"
    lines = messages(err)
    ok = len(lines) == 1 and lines[0].startswith("soabench: error: ") and needle in lines[0]
    return "clean" if ok else "unclear"
