"""Property-based fuzzing of everything soabench reads: the TOML config and scenario loaders, the run-folder readers
(run.json, trial records, CSV tables), the KITTI readers (labels, detections, calib, oxts, semantics, velodyne
.bin/.label) and the plugin boundary (births, estimates, track labels).

Each target draws an input (Hypothesis), writes it into a fresh case folder and calls the reader there. The
property: a correct result (checked: validated values, consistent shapes, finite numbers; births accepted at the
boundary run through a filter step), or the library's one-line error (:class:`~soabench.errors.SoabenchError`, whose
line the command line prints with exit status 2; at the plugin boundary a ``PluginOutputError``); never any other
exception, never an error of several lines, never a file written outside the case folder.

Used by ``tests/hardening/test_fuzz.py`` (a short, derandomized budget: the same inputs on every run) and by
``benchmarks/bench_reliability.py --fuzz MINUTES`` (a long random budget that counts inputs and failures).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import re
import shutil
import tempfile
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from soabench.errors import SoabenchError

ROOT = Path(__file__).resolve().parents[1]


class FuzzFailure(AssertionError):
    """A target broke its property; the message says how (and holds the traceback of an unexpected exception)."""


# ------------------------------------------------------------------------------------------------ shared values
SCALARS = st.one_of(
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, 1, 3, -1, 0.5, 1e300, -1e300, 5e-324, 2**63, "", "soa", "lmb", "static", "nan", "\x00"]),
    st.text(max_size=8),
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=8,
)


def _toml_value(v: Any) -> str:
    """``v`` written as a TOML value (NaN and infinities as TOML spells them; strings as JSON strings, which TOML
    reads, or refuses with an error of its own for a lone surrogate)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(str(k))} = {_toml_value(x)}" for k, x in v.items()) + "}"


def toml_text(tables: dict[str, dict[str, Any]]) -> str:
    return "".join(
        f"[{sec}]\n" + "".join(f"{json.dumps(k)} = {_toml_value(v)}\n" for k, v in table.items())
        for sec, table in tables.items()
    )


@st.composite
def mutated(draw, seed: bytes) -> bytes:
    """``seed`` with a few byte edits: a span deleted, duplicated or replaced by random bytes or a token."""
    data = bytearray(seed)
    for _ in range(draw(st.integers(1, 4))):
        n = len(data)
        i = draw(st.integers(0, n))
        j = min(n, i + draw(st.integers(0, 16)))
        what = draw(st.sampled_from(["delete", "insert", "replace", "token", "truncate"]))
        if what == "delete":
            del data[i:j]
        elif what == "insert":
            data[i:i] = data[i:j]
        elif what == "replace":
            data[i:j] = draw(st.binary(max_size=8))
        elif what == "token":
            tok = draw(
                st.sampled_from([b"nan", b"inf", b"-1", b"1e300", b"0", b"\n", b" ", b"[", b'"', b"=", b",", b"\xff"])
            )
            data[i:j] = tok
        else:
            del data[i:]
    return bytes(data)


# ------------------------------------------------------------------------------------------------ running a case
def _one_line(exc: BaseException) -> str | None:
    """Why ``exc``'s message is not one line (None if it is)."""
    text = str(exc)
    if not text.strip():
        return "an empty message"
    if "\n" in text.strip():
        return f"a message of {text.strip().count(chr(10)) + 1} lines"
    return None


def _listing(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()}


@contextlib.contextmanager
def case_folder() -> Any:
    """A fresh case folder (also the working directory) inside a sandbox; afterwards the sandbox must hold nothing
    but the case folder (nothing written beside it, e.g. into the working directory's parent)."""
    with tempfile.TemporaryDirectory(prefix="soabench-fuzz-") as box:
        sandbox = Path(box)
        case = sandbox / "case"
        case.mkdir()
        with contextlib.chdir(case):
            yield case
        extra = _listing(sandbox) - {"case"}
        if extra:
            raise FuzzFailure(f"files written outside the case folder: {sorted(extra)}")


def judged(reader: Callable[[], Any], check: Callable[[Any], None], allowed: tuple[type, ...] = ()) -> str:
    """Call ``reader``: a result passes ``check``; a SoabenchError (or one of ``allowed``) has one line. Returns
    "ok" or "refused"; raises :class:`FuzzFailure` otherwise."""
    try:
        result = reader()
    except (SoabenchError, *allowed) as exc:
        why = _one_line(exc)
        if why is not None:
            raise FuzzFailure(f"{type(exc).__name__} with {why}: {str(exc)[:300]!r}") from None
        return "refused"
    except Exception as exc:  # noqa: BLE001 - what the fuzzer looks for
        raise FuzzFailure(f"{type(exc).__name__}: {exc}\n" + traceback.format_exc()) from None
    try:
        check(result)
    except AssertionError as exc:
        raise FuzzFailure(f"a wrong result: {exc}") from None
    except Exception as exc:  # noqa: BLE001 - a result the check cannot even read is wrong too
        raise FuzzFailure(f"a wrong result: {type(exc).__name__}: {exc}\n" + traceback.format_exc()) from None
    return "ok"


# ------------------------------------------------------------------------------------------------ config loader
def _config_fields() -> dict[str, dict[str, Any]]:
    from soabench.config import Config

    cfg = Config()
    out = {}
    for sec in dataclasses.fields(cfg):
        value = getattr(cfg, sec.name)
        if dataclasses.is_dataclass(value):
            out[sec.name] = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
    return out


@st.composite
def config_texts(draw) -> bytes:
    """A config TOML: real sections and keys (sometimes unknown ones) with valid or arbitrary values, or a byte
    mutation of such a file."""
    fields = _config_fields()
    tables: dict[str, dict[str, Any]] = {}
    for sec in draw(st.lists(st.sampled_from([*fields, "plugins", "bogus"]), max_size=4, unique=True)):
        known = fields.get(sec, {})
        tables[sec] = {}
        for key in draw(st.lists(st.sampled_from([*known, "nope"]), max_size=5, unique=True)):
            default = known.get(key)
            if default is not None and draw(st.booleans()):
                value = list(default) if isinstance(default, tuple) else default
            else:
                value = draw(VALUES)
            tables[sec][key] = value
    text = toml_text(tables).encode("utf-8", "surrogatepass")
    return draw(mutated(text)) if draw(st.integers(0, 3)) == 0 else text


def config_target(data: bytes) -> str:
    from soabench.config import Config, load_config

    def check(cfg: Config) -> None:
        again = Config.from_dict(cfg.to_dict()).validate()
        assert again.to_dict() == cfg.to_dict(), "the validated config does not survive to_dict/from_dict"

    with case_folder() as case:
        (case / "c.toml").write_bytes(data)
        return judged(lambda: load_config(case / "c.toml"), check)


# ------------------------------------------------------------------------------------------------ scenario loader
def _scenario_seed() -> str:
    from soabench.scenario import shipped_root

    root = shipped_root() / "intersection"
    text = (root / "scenario.toml").read_text(encoding="utf-8")
    text = text.replace('"intersection.net.xml"', json.dumps(str(root / "intersection.net.xml")))
    return re.sub(r'"(\w+\.poly\.xml)"', lambda m: json.dumps(str(root / m.group(1))), text)


@st.composite
def scenario_texts(draw) -> bytes:
    """The shipped intersection scenario with one value replaced by an arbitrary one, or bytes mutated."""
    text = _scenario_seed()
    keys = re.findall(r"^(\w+) = ", text, flags=re.M)
    if draw(st.booleans()):
        key = draw(st.sampled_from(keys))
        text = re.sub(rf"^{key} = .*?$", lambda m: f"{key} = {_toml_value(draw(VALUES))}", text, count=1, flags=re.M)
        return text.encode("utf-8", "surrogatepass")
    return draw(mutated(text.encode("utf-8")))


def scenario_target(data: bytes) -> str:
    from soabench.scenario.config import load_scenario

    def check(sc: Any) -> None:
        assert sc is not None

    with case_folder() as case:
        (case / "scenario.toml").write_bytes(data)
        return judged(lambda: load_scenario(case / "scenario.toml"), check)


# ------------------------------------------------------------------------------------------------ run folders
_RUN_CACHE: dict[str, Path] = {}


def fake_run() -> Path:
    """A finished 3-trial run folder of the tests' fake trial (made once per process, copied per case)."""
    if "run" not in _RUN_CACHE:
        import fake_trial as ft

        from soabench.config import Config
        from soabench.experiment.execution.options import RunOptions
        from soabench.experiment.reports.finished import run_experiment

        cfg = Config()
        cfg.experiment = dataclasses.replace(cfg.experiment, trials=3, duration=10.0, clutter=(3.0,), models=("soa",))
        run = Path(tempfile.mkdtemp(prefix="soabench-fuzz-run-")) / "run"
        opts = RunOptions(workers=1, progress=False, figures=False)
        with contextlib.redirect_stdout(None):
            run_experiment(cfg.validate(), "x", out=run, options=opts, trial_fn=ft.fake_trial, load_fn=ft.fake_load)
        _RUN_CACHE["run"] = run
    return _RUN_CACHE["run"]


def _paths(obj: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix]
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj[:3]):
            out += _paths(v, (*prefix, i))
    return out


@st.composite
def edited_json(draw, seed: Any) -> bytes:
    """``seed`` with a few values replaced, deleted or added at random paths, or its JSON text mutated."""
    obj = json.loads(json.dumps(seed))
    if draw(st.integers(0, 3)) == 0:
        return draw(mutated(json.dumps(obj).encode()))
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(_paths(obj)))
        if not path:
            obj = draw(VALUES) if draw(st.integers(0, 9)) == 0 else obj
            continue
        parent = obj
        for p in path[:-1]:
            parent = parent[p]
        action = draw(st.sampled_from(["set", "set", "delete", "add"]))
        if action == "delete" and isinstance(parent, dict):
            parent.pop(path[-1], None)
        elif action == "add" and isinstance(parent, dict):
            parent[draw(st.text(max_size=6))] = draw(VALUES)
        else:
            parent[path[-1]] = draw(VALUES)
    return json.dumps(obj, allow_nan=True).encode()


def run_json_texts() -> st.SearchStrategy[bytes]:
    return st.deferred(lambda: edited_json(json.loads((fake_run() / "run.json").read_text())))


def run_json_target(data: bytes) -> str:
    from soabench.experiment.runs.files import read_json
    from soabench.experiment.runs.runmeta import validate_run_meta

    def check(meta: Any) -> None:
        assert meta.trials >= 1 and meta.config.experiment.trials >= 1, meta.trials

    with case_folder() as case:
        (case / "run.json").write_bytes(data)
        return judged(lambda: validate_run_meta(read_json(case / "run.json"), "run.json"), check)


def record_texts() -> st.SearchStrategy[tuple[int, bytes]]:
    return st.deferred(
        lambda: st.tuples(
            st.integers(0, 4), edited_json(json.loads((fake_run() / "trials" / "trial_00001.json").read_text()))
        )
    )


def record_target(value: tuple[int, bytes]) -> str:
    """A trial record (any trial file name) in a finished run: moved aside or kept, then every kept record loads and
    the tables merge."""
    from soabench.experiment.runs.store import RunStore

    trial, data = value

    def read() -> Any:
        store = RunStore(case / "run")
        store.reject_foreign_records(3)
        done = store.done_trials()
        for t in done:
            store.load_trial(t)
        store.merge(["soa"], ["static", "dynamic", "dynamic+occ"])
        return done

    def check(done: Any) -> None:
        assert set(done) <= {0, 1, 2, 3, 4}, done

    with case_folder() as case:
        shutil.copytree(fake_run(), case / "run")
        (case / "run" / "trials" / f"trial_{trial:05d}.json").write_bytes(data)
        return judged(read, check)


def csv_texts() -> st.SearchStrategy[tuple[str, bytes]]:
    names = ("trials.csv", "episodes.csv", "steps.csv")
    return st.deferred(
        lambda: st.sampled_from(names).flatmap(
            lambda n: st.tuples(st.just(n), mutated((fake_run() / n).read_bytes()[:4000]))
        )
    )


def csv_target(value: tuple[str, bytes]) -> str:
    """A table of a run folder: read into columns of one length; trials.csv also through the report's reader."""
    from soabench.experiment.reports.html import extreme_trials
    from soabench.experiment.runs.files import read_csv

    name, data = value

    def read() -> Any:
        cols = read_csv(case / name)
        if name == "trials.csv":
            extreme_trials(case)
        return cols

    def check(cols: dict) -> None:
        assert len({len(v) for v in cols.values()}) <= 1, {k: len(v) for k, v in cols.items()}

    with case_folder() as case:
        (case / name).write_bytes(data)
        return judged(read, check)


# ------------------------------------------------------------------------------------------------ KITTI readers
def _kitti_seed(tmp: Path) -> Path:
    from kitti_files import write_dataset

    return write_dataset(tmp / "kitti", n=1, n_frames=4)


CALIB_SEED = (
    "P0: 7.2e+02 0 6.0e+02 0 0 7.2e+02 1.7e+02 0 0 0 1 0\nP2: 7.2e+02 0 6.0e+02 4.5e+01 0 7.2e+02 1.7e+02 -3.4e-01 0 0 "
    "1 4.9e-03\nR_rect 1 0 0 0 1 0 0 0 1\nTr_velo_cam 0 -1 0 0 0 0 -1 -0.08 1 0 0 -0.27\nTr_imu_velo 1 0 0 -0.8 0 1 "
    "0 0.3 0 0 1 -0.8\n"
)
SEMANTICS_SEED = "0 sidewalk 0 0 10 0 10 10\n1 building 5 5 8 5 8 8 5 8\n"


def kitti_texts() -> st.SearchStrategy[tuple[str, bytes]]:
    def seed(kind: str) -> bytes:
        with tempfile.TemporaryDirectory() as d:
            root = _kitti_seed(Path(d))
            if kind == "label":
                return (root / "label_02" / "0000.txt").read_bytes()
            if kind == "detections":
                return (root / "detections" / "0000.txt").read_bytes()
            if kind == "oxts":
                return (root / "oxts" / "0000.txt").read_bytes()
        return (CALIB_SEED if kind == "calib" else SEMANTICS_SEED).encode()

    tok = st.one_of(
        st.sampled_from(["nan", "inf", "-1", "1e300", "0", "x", "", "Pedestrian", "DontCare", "9" * 30]),
        st.floats().map(repr),
        st.integers().map(str),
    )

    @st.composite
    def row(draw, line: str) -> str:
        """``line`` with some of its tokens (and up to two more) replaced."""
        old = line.split() + ["0", "0"]
        n = draw(st.integers(max(0, len(old) - 4), len(old)))
        return " ".join(draw(tok) if draw(st.integers(0, 3)) == 0 else old[i] for i in range(n))

    def tokens(kind: str) -> st.SearchStrategy[bytes]:
        """Rows of the seed's shape with some tokens replaced."""
        rows = seed(kind).decode().splitlines()
        return st.lists(st.sampled_from(rows).flatmap(row), max_size=6).map(lambda rs: ("\n".join(rs) + "\n").encode())

    kinds = ("label", "detections", "calib", "oxts", "semantics")
    return st.sampled_from(kinds).flatmap(
        lambda k: st.tuples(st.just(k), st.one_of(tokens(k), mutated(seed(k)), st.binary(max_size=64)))
    )


def kitti_target(value: tuple[str, bytes]) -> str:
    from soabench.kitti.formats import parse_calib, parse_objects, parse_oxts, parse_semantics

    kind, data = value
    readers = {
        "label": lambda p: parse_objects(p, "label")[0],
        "detections": lambda p: parse_objects(p, "detections")[0],
        "calib": parse_calib,
        "oxts": parse_oxts,
        "semantics": parse_semantics,
    }

    def check(result: Any) -> None:
        if kind in ("label", "detections"):
            n = {len(getattr(result, f)) for f in ("frame", "track_id", "type", "hwl", "xyz", "score")}
            assert len(n) == 1, f"columns of lengths {n}"
            assert np.isfinite(result.xyz).all() and np.isfinite(result.hwl).all(), "non-finite box"
        elif kind == "oxts":
            assert result.ndim == 2 and np.isfinite(result).all(), "non-finite oxts"
        elif kind == "semantics":
            for polys in result.values():
                for _, xy in polys:
                    assert np.isfinite(xy).all() and xy.shape[1] == 2, "bad polygon"

    with case_folder() as case:
        (case / "0000.txt").write_bytes(data)
        return judged(lambda: readers[kind](case / "0000.txt"), check)


@st.composite
def velodyne_frames(draw) -> tuple[bytes, bytes]:
    """A scan (float32 x y z intensity rows, some values extreme or non-finite) and its label file, sizes sometimes
    inconsistent."""
    n = draw(st.integers(0, 40))
    coords = st.one_of(st.floats(-60, 60, width=32), st.sampled_from([0.0, 1e38, -1e38, 3e38, np.nan, np.inf]))
    pts = draw(hnp.arrays(np.float32, (n, 4), elements=coords))
    labels = draw(hnp.arrays(np.uint32, (n,), elements=st.sampled_from([0, 40, 48, 50, 48 | (7 << 16), 2**32 - 1])))
    scan, lab = pts.astype("<f4").tobytes(), labels.astype("<u4").tobytes()
    cut = draw(st.sampled_from([None, None, None, "scan", "label"]))
    if cut == "scan":
        scan = scan[: draw(st.integers(0, len(scan)))]
    elif cut == "label":
        lab = lab + draw(st.binary(max_size=7))
    return scan, lab


def velodyne_target(value: tuple[bytes, bytes]) -> str:
    """One frame through the checks, the reader and the region builder (the sidewalk class)."""
    from soabench.kitti.lidar import LidarParams, class_ids, frame_files, frame_regions, read_frame

    scan, lab = value

    def read() -> Any:
        ((s, labels, _),) = frame_files(case / "velodyne", case / "labels", "0000", 1)
        pts, cl = read_frame(s, labels)
        return frame_regions(pts, cl, class_ids(("sidewalk",)), LidarParams(), 50.0)

    def check(polys: Any) -> None:
        for _, xy in polys:
            assert np.isfinite(xy).all() and (np.abs(xy) <= 51.0).all(), "a region beyond r_max"

    with case_folder() as case:
        for d in ("velodyne", "labels"):
            (case / d / "0000").mkdir(parents=True)
        (case / "velodyne" / "0000" / "000000.bin").write_bytes(scan)
        (case / "labels" / "0000" / "000000.label").write_bytes(lab)
        return judged(read, check)


# ------------------------------------------------------------------------------------------------ plugin boundary
_ELEMENTS = st.one_of(st.floats(-100, 100), st.sampled_from([0.0, 1.0, -1.0, 1e300, -1e300, 1e-300, np.nan, np.inf]))


def _array(shape: tuple[int, ...]) -> st.SearchStrategy[Any]:
    """An array of ``shape`` (or of another shape, dtype, or not an array at all)."""
    good = hnp.arrays(np.float64, shape, elements=_ELEMENTS)
    other = st.one_of(
        st.none(),
        hnp.arrays(np.float64, hnp.array_shapes(min_dims=0, max_dims=3, max_side=5), elements=_ELEMENTS),
        hnp.arrays(np.dtype("U2"), (shape[0],) if shape else ()),
        hnp.arrays(np.complex128, shape),
        st.lists(SCALARS, max_size=3),
    )
    return st.one_of(good, good, good, other)


@st.composite
def births(draw) -> tuple[Any, int]:
    """Births of J components (sometimes with newborn terms for M measurements): each field well formed, extreme,
    or malformed; covariances from A A^T (positive semi-definite) or arbitrary."""
    from soabench.types import Births, NewbornTerms

    J, M = draw(st.integers(0, 4)), draw(st.integers(0, 3))
    w = draw(_array((J,)))
    m = draw(_array((J, 4)))
    if draw(st.booleans()):
        A = draw(hnp.arrays(np.float64, (J, 4, 4), elements=st.floats(-10, 10)))
        P = A @ np.swapaxes(A, 1, 2) + draw(st.sampled_from([0.0, 1e-9, 1.0])) * np.eye(4)
    else:
        P = draw(_array((J, 4, 4)))
    source = draw(st.one_of(st.just(np.zeros(J, dtype=np.int8)), _array((J,))))
    newborn = None
    if draw(st.booleans()):
        beta_out = draw(_array((M,)))
        newborn = NewbornTerms(draw(_array((M, 4))), draw(_array((M, 4, 4))), lambda A, kappa, b=beta_out: b)
    return Births(w, m, P, source, newborn), M


def births_target(value: tuple[Any, int]) -> str:
    """A birth model's output through the harness's check; accepted births run through a GM-PHD step."""
    from shapely.geometry import Polygon

    from soabench.config import FilterConfig, Sensor
    from soabench.experiment.trial.guard import BIRTH_W_MAX, PluginOutputError, check_births
    from soabench.gmphd import GMPHDFilter
    from soabench.types import Scan

    b, M = value
    rng = np.random.default_rng(M)
    Z = np.column_stack([rng.uniform(1, 40, M), rng.uniform(-1, 1, M)])
    scan = Scan(0, 0.0, np.zeros(3), Z, None, [], Polygon())

    def read() -> Any:
        ok = check_births(b, scan, "fuzz:Births")
        res = GMPHDFilter(FilterConfig(), Sensor(), "dynamic").step(scan, ok)
        return ok, res

    def check(value: Any) -> None:
        ok, res = value
        assert np.isfinite(ok.w).all() and (ok.w >= 0).all() and (ok.w <= BIRTH_W_MAX).all(), ok.w
        assert np.isfinite(res.X).all() and np.isfinite(res.sum_w), "a non-finite filter output"

    with case_folder():
        return judged(read, check, (PluginOutputError,))


@st.composite
def estimates(draw) -> Any:
    """A tracker's output: Estimates with well formed, extreme or malformed states, weights, counts and labels; or
    not an Estimates at all."""
    n = draw(st.integers(0, 4))
    cols = draw(st.sampled_from([2, 4]))
    labels = draw(
        st.one_of(
            st.none(),
            hnp.arrays(np.int64, (n,), elements=st.integers(-(2**63), 2**63 - 1)),
            hnp.arrays(np.uint64, (n,)),
            hnp.arrays(np.bool_, (n,)),
            _array((n,)),
        )
    )
    card = draw(st.one_of(st.none(), st.floats(allow_nan=True), st.sampled_from([0, -1, 2**70])))
    n_comp = draw(st.one_of(st.none(), st.integers(-3, 10), st.floats(), st.just("3")))
    args = (draw(_array((n, cols))), draw(st.one_of(st.none(), _array((n,)))), n_comp, card, labels)
    made = EstimatesArgs(args)  # built inside the target: Estimates checks its arguments when it is made
    return draw(st.one_of(st.just(made), st.just(made), st.sampled_from([None, [], "x", 3])))


class EstimatesArgs(tuple):
    """The arguments a plugin gives :class:`~soabench.types.Estimates` (the target makes the object)."""


def estimates_target(est: Any) -> str:
    from soabench.experiment.trial.guard import PluginOutputError, check_estimates
    from soabench.types import Estimates, Scan

    scan = Scan(0, 0.0, np.zeros(3), np.zeros((0, 2)), None, [], None)

    def check(res: Any) -> None:
        assert res.X.ndim == 2 and res.X.shape[1] == 4 and np.isfinite(res.X).all(), res.X
        if res.labels is not None:
            assert len(np.unique(res.labels)) == len(res.labels) == len(res.X), res.labels

    def read() -> Any:  # the plugin makes its Estimates, then the harness checks them
        return check_estimates(Estimates(*est) if isinstance(est, EstimatesArgs) else est, scan, 0.01)

    with case_folder():
        return judged(read, check, (PluginOutputError,))


# ------------------------------------------------------------------------------------------------ the targets
#: name -> (strategy, target); a target returns "ok" or "refused" and raises FuzzFailure otherwise
TARGETS: dict[str, tuple[Callable[[], st.SearchStrategy[Any]], Callable[[Any], str]]] = {
    "config TOML": (config_texts, config_target),
    "scenario TOML": (scenario_texts, scenario_target),
    "run.json": (run_json_texts, run_json_target),
    "trial records": (record_texts, record_target),
    "run CSVs": (csv_texts, csv_target),
    "KITTI text files": (kitti_texts, kitti_target),
    "KITTI .bin/.label": (velodyne_frames, velodyne_target),
    "plugin births": (births, births_target),
    "plugin estimates and labels": (estimates, estimates_target),
}


def short_id(exc: BaseException) -> str:
    """The first line of a failure (for counting distinct failures)."""
    return str(exc).strip().splitlines()[0][:200] if str(exc).strip() else type(exc).__name__
