"""More bad command-line inputs, in the Case format of tests/bad_inputs.py: values given twice (which counted trials
twice), files nested too deeply or not UTF-8, scenario values of the wrong type or place, polygon files that are
not polygons, out-of-range snapshot indices, ``--resume --save-estimates`` on a run without estimates, and KITTI
files and options that were accepted but read wrong. Every one must give ONE line on stderr and exit status 2,
without a traceback and without running a trial. Used by tests/hardening/test_accepted_values.py.

Each case is ``(name, make_argv(tmp) -> argv, needle)``; ``make_argv`` may write files under ``tmp``.
"""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Callable
from pathlib import Path

import kitti_files
from bad_inputs import Case, _cfg, _run, _toml

from soabench.config import Config
from soabench.scenario import shipped_root

DEEP = 100_000  #: nesting depth of the "nested too deeply" files (far beyond the parsers' recursion limit)


# ------------------------------------------------------------------------------------------------ helpers
def _sweep(kind: str, *flags: str):
    return lambda t: ["sweep", kind, *flags, "--trials", "1", "--workers", "1", "--out", str(t / "sw")]


def _deep_toml(tmp: Path) -> str:
    return _toml(tmp, "a = " + "[" * DEEP + "]" * DEEP + "\n")


def _scenario(tmp: Path, edit: tuple[str, str] | None = None) -> str:
    """The shipped intersection scenario with absolute file paths, one line (regex) replaced by ``edit``."""
    root = shipped_root() / "intersection"
    text = (root / "scenario.toml").read_text(encoding="utf-8")
    text = text.replace('"intersection.net.xml"', json.dumps(str(root / "intersection.net.xml")))
    text = re.sub(r'"(\w+\.poly\.xml)"', lambda m: json.dumps(str(root / m.group(1))), text)
    if edit is not None:
        text, n = re.subn(edit[0], edit[1], text, flags=re.M | re.S)
        assert n == 1, edit
    p = tmp / "scenario.toml"
    p.write_text(text, encoding="utf-8")
    return str(p)


def _scen(edit: tuple[str, str], needle: str, name: str) -> Case:
    return (f"scenario {name}", lambda t: _run(t, "--scenario", _scenario(t, edit)), needle)


def _poly(tmp: Path, body: str) -> str:
    p = tmp / "extra.poly.xml"
    p.write_text(f"<additional>{body}</additional>\n", encoding="utf-8")
    return str(p)


def _poly_case(name: str, body: str, needle: str) -> Case:
    return (f"--poly {name}", lambda t: _run(t, "--poly", _poly(t, body)), needle)


def _building(shape: str, pid: str = "b1") -> str:
    return f'<poly id="{pid}" type="building" color="red" fill="1" shape="{shape}"/>'


def _deep_run_json(tmp: Path) -> list[str]:
    d = tmp / "run"
    d.mkdir()
    (d / "run.json").write_text("[" * DEEP + "]" * DEEP)
    return ["run", "--resume", str(d)]


def _run_without_estimates(tmp: Path) -> list[str]:
    """A run folder (run.json only) started without --save-estimates, resumed with it."""
    d = tmp / "run"
    d.mkdir()
    cfg = Config()
    cfg.experiment.trials = 1
    meta = {"format": 1, "config": cfg.to_dict(), "net": "intersection", "polys": [], "scenario": None,
            "trials": 1, "save_estimates": False}  # fmt: skip
    (d / "run.json").write_text(json.dumps(meta))
    return ["run", "--resume", str(d), "--save-estimates", "--workers", "1"]


def _suite_not_utf8(tmp: Path) -> list[str]:
    p = tmp / "suite.toml"
    p.write_bytes('[suite]\nname = "caf\xe9"\n'.encode("latin-1"))
    return ["check", "--suite", str(p), "--out", str(tmp / "chk")]


def _suite_deep_baseline(tmp: Path) -> list[str]:
    src = Path(__file__).resolve().parents[1] / "examples" / "check" / "suite.toml"
    shutil.copy(src, tmp / "suite.toml")
    (tmp / "baseline.json").write_text("[" * DEEP + "]" * DEEP)
    return ["check", "--suite", str(tmp / "suite.toml"), "--out", str(tmp / "chk")]


def _kitti(mutate=None, *flags: str):
    """``soabench kitti`` on a small hand-made dataset (tests/kitti_files.py), after ``mutate(root)``."""

    def make(tmp: Path) -> list[str]:
        root = kitti_files.write_dataset(tmp / "kitti", n=3, n_frames=12)
        if mutate is not None:
            mutate(root)
        extra = [str(root / "semantics") if f == "SEMANTICS" else f for f in flags]
        return ["kitti", "--root", str(root), "--folds", "3", "--models", "soa", "--out", str(tmp / "kout"), *extra]

    return make


def _labels(edit):
    def mutate(root: Path) -> None:
        p = root / "label_02" / "0001.txt"
        p.write_text(edit(p.read_text()))

    return mutate


def _semantics(text: str):
    def mutate(root: Path) -> None:
        (root / "semantics").mkdir()
        (root / "semantics" / "0001.txt").write_text(text)

    return mutate


CASES: list[Case] = [
    # values given twice: every row written twice and the trials counted twice
    ("--clutter 3,3", lambda t: _run(t, "--clutter", "3,3"), "names 3.0 twice"),
    ("--clutter 3,3.0", lambda t: _run(t, "--clutter", "3,3.0"), "names 3.0 twice"),
    ("--probabilities static,static", lambda t: _run(t, "--probabilities", "static,static"), "'static' twice"),
    _cfg("[experiment]\nclutter = [3.0, 3]\n", "names 3.0 twice"),
    _cfg('[experiment]\nprobabilities = ["dynamic", "dynamic"]\n', "'dynamic' twice"),
    ("sweep clutter --values 3,3", _sweep("clutter", "--values", "3,3"), "names 3.0 twice"),
    ("sweep occlusion --values 4,4", _sweep("occlusion", "--values", "4,4"), "names 4.0 twice"),
    ("sweep births --offsets 0,0", _sweep("births", "--offsets", "0,0"), "offsets = [0, 0] names 0 twice"),
    # files nested too deeply or not UTF-8: one line, not a RecursionError or UnicodeDecodeError
    ("config nested too deeply", lambda t: _run(t, "--config", _deep_toml(t)), "too deeply"),
    ("scenario nested too deeply", lambda t: _run(t, "--scenario", _deep_toml(t)), "too deeply"),
    ("run.json nested too deeply", _deep_run_json, "maximum recursion depth"),
    ("check suite not UTF-8", _suite_not_utf8, "not UTF-8"),
    ("check baseline nested too deeply", _suite_deep_baseline, "is not valid JSON"),
    # scenario values: types, names, places
    _scen((r"^world_box = .*?$", "world_box = 5"), "simulation.world_box = 5", "world_box = 5"),
    _scen((r"^points = \[.*?\n\]", "points = [1, 2]"), "doors.points = [1, 2]", "doors.points = [1, 2]"),
    _scen((r"^points = \[.*?\n\]", "points = [[nan, 0.0]]"), "doors.points", "door at nan"),
    _scen((r"^points = \[.*?\n\]", "points = [[1e7, 1e7]]"), "at most 30 m", "door at (1e7, 1e7)"),
    _scen((r'^name = "intersection"$', "name = 123"), "scenario.name = 123", "name = 123"),
    _scen((r"^sources = .*?$", 'sources = ["nope"]'), "vehicles.sources edge 'nope'", "vehicle source unknown"),
    _scen((r"^start_x = .*?$", "start_x = 5000.0"), "ego start", "ego start_x off its edge"),
    # polygon files
    (
        "--poly a .net.xml",
        lambda t: _run(t, "--poly", str(shipped_root() / "intersection" / "intersection.net.xml")),
        "is a SUMO network",
    ),  # fmt: skip
    _poly_case("one-point polygon", _building("1,1"), "needs at least 3"),
    _poly_case("empty polygon", _building(""), "0 point(s)"),
    _poly_case("NaN polygon", _building("0,0 nan,0 1,1"), "coordinate nan"),
    _poly_case("1e30 m polygon", _building("0,0 1e30,0 1e30,1e30"), "coordinate 1e+30"),
    _poly_case("duplicate polygon id", _building("0,0 10,0 10,10") + _building("20,0 30,0 30,10"), "'b1' twice"),
    # snapshot indices
    ("scene --trial 10^23", lambda t: ["scene", "--trial", str(10**23), "--out", str(t / "s.png")], "--trial 1"),
    ("scene --seed 10^23", lambda t: ["scene", "--seed", str(10**23), "--out", str(t / "s.png")], "--seed 1"),
    # --resume with --save-estimates: refused (the finished trials have no estimates)
    ("--resume --save-estimates", _run_without_estimates, "--save-estimates does not apply to --resume"),
    # KITTI
    ("kitti empty label file", _kitti(_labels(lambda s: "")), "sequence 0001 is empty"),
    ("kitti lowercase type", _kitti(_labels(lambda s: s.replace("Pedestrian", "pedestrian"))), "not a KITTI type"),
    ("kitti negative box size", _kitti(_labels(lambda s: s.replace(" 0.6 0.8 ", " -0.6 0.8 "))), "is negative"),
    (
        "kitti track id 1e20",
        _kitti(_labels(lambda s: s.replace("0 0 Pedestrian", f"0 {10**20} Pedestrian", 1))),
        "track id '100000000000000000000' is out of range",
    ),  # fmt: skip
    ("kitti semantics malformed", _kitti(_semantics("0 sidewalk 0 0 1 1 x 1\n"), "--semantics", "SEMANTICS"), "'x'"),
    ("kitti semantics NaN", _kitti(_semantics("0 sidewalk 0 0 1 1 nan 1\n"), "--semantics", "SEMANTICS"), "finite"),
    (
        "kitti semantics 1e300 m",
        _kitti(_semantics("0 sidewalk 0 0 1e300 0 1e300 1e300\n"), "--semantics", "SEMANTICS"),
        "coordinate 1e+300 is out of range",
    ),  # fmt: skip
    (
        "kitti semantics frame 999999999",
        _kitti(_semantics("999999999 sidewalk 0 0 10 0 10 10\n"), "--semantics", "SEMANTICS"),
        "frame 999999999",
    ),  # fmt: skip
    ("kitti --score-min inf", _kitti(None, "--score-min", "inf"), "kitti.score_min = inf"),
    ("kitti --classes Foo", _kitti(None, "--classes", "Foo"), "'Foo' is not a KITTI object type"),
    ("kitti --classes pedestrian", _kitti(None, "--classes", "pedestrian"), "'pedestrian' is not a KITTI"),
    ("kitti --nhat-sweep 0,0", _kitti(None, "--nhat-sweep", "0,0"), "names 0 twice"),
]


# ------------------------------------------------------------------------------------------------ filter families
FAMILIES = '[experiment]\nfilters = ["gmphd", "lmb"]\n'


def _suite_with_config(text: str, threshold: str = "") -> Callable[[Path], list[str]]:
    """A one-scenario check suite whose ``[suite] config`` file holds ``text`` (and ``threshold`` lines added to its
    threshold row)."""

    def make(tmp: Path) -> list[str]:
        (tmp / "c.toml").write_text(text)
        suite = tmp / "suite.toml"
        suite.write_text(
            '[suite]\nname = "t"\nconfig = "c.toml"\n[[scenario]]\nname = "a"\nnet = "intersection"\nduration = 5\n'
            f'[[threshold]]\nmetric = "ospa"\nmax = 100.0\n{threshold}'
        )
        return ["check", "--suite", str(suite), "--out", str(tmp / "chk")]

    return make


def _suite_with_scenario(lines: str) -> Callable[[Path], list[str]]:
    """A one-scenario check suite whose scenario holds ``lines``."""

    def make(tmp: Path) -> list[str]:
        suite = tmp / "suite.toml"
        suite.write_text(
            f'[suite]\nname = "t"\n[[scenario]]\nname = "a"\nnet = "intersection"\nduration = 5\n{lines}'
            '[[threshold]]\nmetric = "ospa"\nmax = 100.0\n'
        )
        return ["check", "--suite", str(suite), "--out", str(tmp / "chk")]

    return make


def _with_config(*argv: str) -> Callable[[Path], list[str]]:
    return lambda t: [*argv, "--config", _toml(t, FAMILIES)]


FAMILY_CASES: list[Case] = [
    ("run --filters kalman", lambda t: _run(t, "--filters", "kalman"), "'kalman'"),
    ("run --filters lmb,lmb", lambda t: _run(t, "--filters", "lmb,lmb"), "names 'lmb' twice"),
    ("run --filters lmb dynamic only", lambda t: _run(t, "--filters", "lmb", "--probabilities", "dynamic"), "static"),
    _cfg("[experiment]\nfilters = []\n", "filters must name at least one"),
    _cfg('[experiment]\nfilters = "lmb"\n', "must be a list"),
    _cfg("[lmb]\nr_B_max = 0.3\n", "runs no LMB filter"),
    _cfg('[experiment]\nfilters = ["lmb"]\n[lmb]\nr_B_max = 1.0\n', "lmb.r_B_max = 1.0 is out of range"),
    _cfg('[experiment]\nfilters = ["lmb"]\n[lmb]\nmax_tracks = 0\n', "lmb.max_tracks = 0 is out of range"),
    _cfg('[experiment]\nfilters = ["lmb"]\n[lmb]\nmax_hypotheses = 2.5\n', "must be an integer"),
    _cfg("[lmb]\nr_B = 0.3\n", "unknown config key lmb.r_B"),
    ("run --filters pmbm dynamic only", lambda t: _run(t, "--filters", "pmbm", "--probabilities", "dynamic"), "static"),
    _cfg("[pmbm]\nJ_h = 3\n", "runs no PMBM or PMB filter"),
    _cfg('[experiment]\nfilters = ["pmb"]\n[pmbm]\nM_max = 0\n', "pmbm.M_max = 0 is out of range"),
    _cfg('[experiment]\nfilters = ["pmbm"]\n[pmbm]\nw_floor = nan\n', "pmbm.w_floor = nan is out of range"),
    _cfg('[experiment]\nfilters = ["pmbm"]\n[pmbm]\nmarginals = "lbp"\n', "pmbm.marginals = 'lbp' is not allowed"),
    (
        "sweep --filters kalman",
        lambda t: ["sweep", "clutter", "--filters", "kalman", "--out", str(t / "sw")],
        "'kalman'",
    ),
    (
        "sweep births --filters lmb dynamic",
        lambda t: ["sweep", "births", "--filters", "lmb", "--probabilities", "dynamic", "--out", str(t / "sw")],
        "filter family 'lmb' runs the probability modes static, static+occ only",
    ),
    (
        "study --filters lmb",
        lambda t: ["study", "--filters", "lmb", "--trials", "1", "--out", str(t / "st")],
        "add gmphd",
    ),
    ("scene config filters", _with_config("scene", "--out", "s.png"), "`soabench scene` runs the GM-PHD"),
    ("kitti --filters kalman", _kitti(None, "--filters", "kalman"), "filter family 'kalman' is unknown"),
    (
        "kitti --filters lmb dynamic",
        _kitti(None, "--filters", "gmphd,lmb", "--probability", "dynamic"),
        "filter family 'lmb' runs the probability modes static, static+occ only",
    ),
    _cfg('[experiment]\nfilters = ["lmb"]\n[lmb]\nbirth_mapping = "pairs"\n', "lmb.birth_mapping = 'pairs'"),
    _cfg('[experiment]\nfilters = ["lmb"]\n[lmb]\nextract_r = nan\n', "lmb.extract_r = nan is out of range"),
    ("run --probabilities NaN", lambda t: _run(t, "--probabilities", "static,nan"), "probability mode 'nan'"),
    ("check suite config filters", _suite_with_config(FAMILIES), "[experiment] filters is set per scenario"),
    ("check scenario filter kalman", _suite_with_scenario('filter = "kalman"\n'), "filter = 'kalman' is not a filter"),
    (
        "check scenario filter lmb dynamic",
        _suite_with_scenario('filter = "lmb"\nprobabilities = ["static", "dynamic"]\n'),
        "filter family 'lmb' runs the probability modes static, static+occ only, and probabilities names 'dynamic'",
    ),
    ("check threshold filter", _suite_with_config("", 'filter = "lmb"\n'), "unknown key 'filter'"),
]
CASES += FAMILY_CASES


# ------------------------------------------------------------------------------------------------ third pass
def _fake_run(tmp: Path, trials: int = 3) -> Path:
    """A finished run folder of the tests' fake trial whose run.json names the built-in trial kind (so that
    ``report`` and ``replay`` read it as a run of ``soabench run``)."""
    import dataclasses

    import fake_trial as ft

    from soabench.experiment.execution.options import RunOptions
    from soabench.experiment.reports.finished import run_experiment
    from soabench.experiment.trial import registry

    cfg = Config()
    cfg.experiment = dataclasses.replace(cfg.experiment, trials=trials, duration=10.0, clutter=(3.0,), models=("soa",))
    run = tmp / "run"
    opts = RunOptions(workers=1, progress=False, figures=False)
    run_experiment(cfg.validate(), "intersection", out=run, options=opts, trial_fn=ft.fake_trial, load_fn=ft.fake_load)
    meta = json.loads((run / "run.json").read_text())
    meta["trial_kind"], meta["scene_loader"] = registry.DEFAULT_TRIAL_KIND, registry.DEFAULT_SCENE_LOADER
    (run / "run.json").write_text(json.dumps(meta))
    return run


def _cut_trials(keep: float):
    def make(tmp: Path) -> list[str]:
        run = _fake_run(tmp)
        data = (run / "trials.csv").read_bytes()
        (run / "trials.csv").write_bytes(data[: int(len(data) * keep)])
        (run / "report.html").unlink(missing_ok=True)
        return ["report", str(run)]

    return make


def _suite_threshold(metric: str, bounds: str) -> Callable[[Path], list[str]]:
    def make(tmp: Path) -> list[str]:
        suite = tmp / "suite.toml"
        suite.write_text(
            '[suite]\nname = "t"\n[[scenario]]\nname = "a"\nnet = "intersection"\nduration = 5\n'
            f'[[threshold]]\nmetric = "{metric}"\n{bounds}\n'
        )
        return ["check", "--suite", str(suite), "--out", str(tmp / "chk")]

    return make


def _kitti_config(text: str, *flags: str):
    def make(tmp: Path) -> list[str]:
        argv = _kitti()(tmp)
        root = Path(argv[argv.index("--root") + 1])
        (root / "semantics").mkdir(exist_ok=True)
        extra = [str(root / f.lower()) if f in ("SEMANTICS", "VELODYNE") else f for f in flags]
        return [*argv, "--config", _toml(tmp, text), *extra]

    return make


NO_SEMANTIC_CLASSES = "[kitti]\nsemantic_classes = []\n"

THIRD_PASS: list[Case] = [
    # a damaged trials.csv is named, not read as "no trials"
    ("report trials.csv cut mid-row", _cut_trials(0.5), "is damaged (row"),
    ("report trials.csv cut before its newline", _cut_trials(0.9999), "trials.csv' is damaged"),
    # output files: as every command's (an existing folder, the format's ending)
    ("report --out under a missing folder", lambda t: ["report", str(_fake_run(t)), "--out", str(t / "no" / "r.html")],
     "does not exist"),
    ("report --out wrong suffix", lambda t: ["report", str(_fake_run(t)), "--out", str(t / "r.txt")],
     "must end in .html"),
    ("replay --out under a missing folder",
     lambda t: ["replay", str(_fake_run(t)), "--trial", "0", "--out", str(t / "no" / "r.html")], "does not exist"),
    ("replay --out wrong suffix", lambda t: ["replay", str(_fake_run(t)), "--trial", "0", "--out", str(t / "r.txt")],
     "r.txt"),
    # check thresholds outside their metric's range
    ("check threshold hota max 2", _suite_threshold("hota", "max = 2.0"), "hota max = 2.0 is outside"),
    ("check threshold hota min -1", _suite_threshold("hota", "min = -1.0"), "hota min = -1.0 is outside"),
    ("check threshold idsw min -5", _suite_threshold("idsw", "min = -5"), "idsw min = -5 is outside"),
    ("check threshold precision max 1.5", _suite_threshold("precision", "max = 1.5"), "range [0, 1]"),
    ("check threshold mota max 2", _suite_threshold("mota", "max = 2.0"), "range [-inf, 1]"),
    ("check threshold ospa max -1", _suite_threshold("ospa", "max = -1.0"), "ospa max = -1.0 is outside"),
    ("check threshold min above max", _suite_threshold("ospa", "min = 5.0\nmax = 1.0"), "is above max = 1.0"),
    # a semantic source with no semantic class
    ("kitti semantic_classes [] --point-labels", _kitti_config(NO_SEMANTIC_CLASSES, "--point-labels", "SEMANTICS"),
     "kitti.semantic_classes = [] names no class of the birth region --point-labels gives"),
    ("kitti semantic_classes [] --semantics", _kitti_config(NO_SEMANTIC_CLASSES, "--semantics", "SEMANTICS"),
     "kitti.semantic_classes = [] names no class of the birth region --semantics gives"),
]  # fmt: skip
CASES += THIRD_PASS

LMB = '[experiment]\nfilters = ["lmb"]\n'
FAMILY_CASES_MORE: list[Case] = [
    ("run --filters gmphd,LMB", lambda t: _run(t, "--filters", "gmphd,LMB"), "filter family 'LMB' is unknown"),
    ("run --filters ''", lambda t: _run(t, "--filters="), "--filters"),
    _cfg('[experiment]\nfilters = ["gmphd", "nope"]\n', "filter family = 'nope' is not allowed"),
    _cfg(LMB + 'probabilities = ["dynamic+occ"]\n', "filter family 'lmb' runs the probability modes static"),
    _cfg(LMB + "[lmb]\nprune_r = 1.0\n", "lmb.prune_r = 1.0 is out of range"),
    _cfg(LMB + "[lmb]\nextract_r = nan\n", "lmb.extract_r = nan is out of range"),
    _cfg(LMB + "[lmb]\nmax_components = 0\n", "lmb.max_components = 0 is out of range"),
    _cfg(LMB + "[lmb]\nr_B_max = -0.1\n", "lmb.r_B_max = -0.1 is out of range"),
    _cfg(LMB + "[lmb]\nmax_hypotheses = 100000000\n", "lmb.max_hypotheses = 100000000 is out of range"),
    _cfg(LMB + '[lmb]\nr_B_max = "0.3"\n', "lmb.r_B_max"),
]
CASES += FAMILY_CASES_MORE

PMBM = '[experiment]\nfilters = ["pmbm"]\n'
PMBM_CASES: list[Case] = [
    _cfg("[pmbm]\nM_max = 50\n", "runs no PMBM or PMB filter"),
    _cfg(PMBM + "[pmbm]\nM_max = 0\n", "pmbm.M_max = 0 is out of range"),
    _cfg(PMBM + "[pmbm]\nw_floor = nan\n", "pmbm.w_floor = nan is out of range"),
    _cfg(PMBM + '[pmbm]\nmarginals = "magic"\n', "pmbm.marginals = 'magic' is not allowed"),
    _cfg('[experiment]\nfilters = ["pmb"]\n[pmbm]\nr_floor = 1.0\n', "pmbm.r_floor = 1.0 is out of range"),
    _cfg(PMBM + "[pmbm]\nJ_h = 2.5\n", "pmbm.J_h = 2.5 must be an integer"),
    _cfg(PMBM + "[pmbm]\nr_B_max = 0.3\n", "unknown config key pmbm.r_B_max"),
    _cfg('[experiment]\nfilters = ["pmb"]\nprobabilities = ["dynamic"]\n', "filter family 'pmb' runs the probability"),
]
CASES += PMBM_CASES
