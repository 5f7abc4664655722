"""Compile the numba kernels once per machine, before the first trial, on every core (docs/user-guide/ci-cache.md).

The filter, metric and scan-geometry kernels (:mod:`soabench.gmphd.cycle`, :mod:`soabench.gmphd.kernels`,
:mod:`soabench.metrics_kernels`, :mod:`soabench.geometry_kernels`, :mod:`soabench.tracks.kernels`) are compiled by
numba on first use and cached in the per-user folder of :mod:`soabench.cache`. Left to the trials, every worker
process compiles the same kernels at the same time, one after another inside each process, while the progress line
extrapolates an ETA from trials that were mostly compiling. Instead, the driver of a run calls
:func:`ensure_compiled` before its trials start:

* the kernels are compiled in independent groups (the update, the reduction, the metric and geometry kernels), one
  process per group on up to ``os.cpu_count()`` cores, then the fused cycle's entry points (which link the groups'
  cached code) in a second round;
* the trials then load machine code from the cache (about a second per process) and the ETA counts trials only;
* one line says so, once per run, on its own line; off a terminal (CI, ``2> log``) a line follows every
  :data:`LINE_INTERVAL_S` seconds while it lasts;
* a stamp file in the kernels' cache folder (keyed by their sources, numba and Python: :mod:`soabench.cache`)
  records that they were compiled, so a later run starts no process at all.

Each group calls the kernels with small inputs of the types a trial passes (the filter's own argument packing),
so the trials find exactly these specialisations in the cache. Compiling changes no number: the arithmetic is the
same compiled code whichever process compiled it. A failure here only costs time (the trials then compile what
they need) and is never fatal.
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import sys
import time
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path
from typing import TextIO

import numpy as np
import shapely

from soabench import notice
from soabench.birth import sampling
from soabench.birth.soa import dedup, ego_inside
from soabench.cache import kernel_folder
from soabench.config import BIRTH_MODEL_NAMES, PROBABILITY_MODES, Config, MetricsConfig
from soabench.notice import LINE_INTERVAL_S, is_terminal
from soabench.sensor import FEW_SIGHT_LINES, line_of_sight, segment_meets_convex
from soabench.types import Births, NewbornTerms, Obstacles, Scan

MESSAGE = notice.MESSAGE


def _filter(mode: str):
    # imported when called: numba would slow every start-up
    from soabench.gmphd import GMPHDFilter

    cfg = Config()
    return GMPHDFilter(cfg.filter, cfg.sensor_at(), mode)


def _scan_arrays() -> tuple[np.ndarray, np.ndarray]:
    """Two measurements (range, bearing) and a pose, as :func:`soabench.gmphd.inputs.scan_inputs` returns them."""
    return np.array([[10.0, 0.1], [20.0, -0.2]]), np.array([0.0, 0.0, 0.0])


def _births(n: int = 2):

    m = np.zeros((n, 4))
    m[:, 0] = np.linspace(5.0, 15.0, n)
    return Births(np.full(n, 0.1), m, np.repeat(np.eye(4)[None], n, axis=0), np.zeros(n, dtype=np.int8))


def _predict_update(modes: tuple[str, ...]) -> None:
    """The prediction and the update (EKF and UKF terms, posterior) of the probability modes' argument types."""
    # imported when called: numba would slow every start-up
    from soabench.gmphd import cycle
    from soabench.gmphd.filter import _birth_arrays, _mixture_arrays

    Z, ego = _scan_arrays()
    for mode in _gate_free(modes):
        f = _filter(mode)
        pred = cycle.predict_append(
            *_mixture_arrays(f.mixture), f.F, f.Q, f._pred_pars, *_birth_arrays(_births()), f._beta0, ego, f.next_label
        )
        # the two halves that cycle.update (inlined into its callers, never compiled on its own) calls, with its types
        w, m, P, beta, g = pred[0], pred[1], pred[2], pred[6], pred[8]
        sup = cycle.support(w, m, P, beta, g, f._p_D, Z, ego, f.R, f._r_min, f._gate, f._kappa(Z), f._ukf)
        no_nb, no_origin = np.empty(0), np.int64(0)
        cycle.posterior(*pred[:8], sup, f.R, no_nb, np.empty((0, 4)), np.empty((0, 4, 4)), no_nb, no_origin, no_origin)


def _reduction(modes: tuple[str, ...]) -> None:
    """Pruning, merging (window and grid), capping and extraction."""
    # imported when called: numba would slow every start-up
    from soabench.gmphd import cycle
    from soabench.gmphd.filter import _mixture_arrays
    from soabench.gmphd.mixture import Mixture

    f = _filter("dynamic")
    for J in (3, 200):  # the two merge searches are chosen by size; the types are the same
        rng = np.random.default_rng(0)
        m = np.zeros((J, 4))
        m[:, :2] = rng.uniform(0.0, 50.0, (J, 2))
        mix = Mixture.from_arrays(np.full(J, 0.5), m, np.repeat(np.eye(4)[None], J, axis=0), origin=0, n_det=0,
                                  age=0, beta=f.beta0)  # fmt: skip
        cycle.reduce(*_mixture_arrays(mix), f._red_pars, f.next_label)


def _metrics_geometry(modes: tuple[str, ...]) -> None:
    """The per-run matchings (§5.2-5.6) and the scan-geometry kernels of the birth models and the sensor."""
    # imported when called: numba, scipy would slow every start-up
    from soabench.geometry_kernels import occlusion_layer_arrays, poisson_accept, poisson_first_free
    from soabench.metrics import GATE_COST
    from soabench.metrics_kernels import run_matchings

    c = MetricsConfig()
    E = np.array([[0.0, 0.0], [5.0, 5.0]])
    G = np.array([[[0.5, 0.0], [9.0, 9.0]]])
    args = (float(c.d_gate), float(GATE_COST), float(c.ospa_c), float(c.gospa_c))
    run_matchings(E, np.array([0, 2], dtype=np.int64), G, np.ones((1, 2), dtype=bool), *args)
    square = np.array([[1.0, 1.0], [2.0, 1.0], [2.0, 2.0], [1.0, 2.0]])
    segment_meets_convex(np.zeros(2), np.array([[3.0, 3.0]]), [square])
    sight = np.full((FEW_SIGHT_LINES, 2), 3.0)  # enough lines for the compiled sight-line test
    line_of_sight(np.zeros(2), sight, [shapely.Polygon(square)])
    ego_inside([square], np.zeros(3))
    dedup(np.array([[0.0, 0.0], [0.1, 0.0]]), 1.0)
    t = np.zeros((1, 2))
    occlusion_layer_arrays(0.0, 0.0, t + 1.0, t, t + 5.0, np.array([1.0, 2.0]), 1.0, 1.0, 0.8, True)
    sampling._warm_poisson(poisson_accept, poisson_first_free)


def _no_obstacles():

    return Obstacles([], *(np.zeros(0) for _ in range(7)))


def _fused_steps(modes: tuple[str, ...]) -> None:
    """The fused cycle's entry points as the filter calls them: one call per scan, and the split step of the
    line-of-sight gate (§2.11, §4.4) in the mode "dynamic+occ"."""

    Z, ego = _scan_arrays()
    far = [shapely.box(1000.0, 1000.0, 1001.0, 1001.0)]
    for mode in modes:
        f = _filter(mode)
        for k in range(2):  # the second step has a mixture to predict
            occluders = far if mode == "dynamic+occ" else []
            f.step(Scan(k, 0.1 * k, ego, Z, _no_obstacles(), occluders, shapely.box(0, 0, 1, 1)), _births())


def _newborn_steps(modes: tuple[str, ...]) -> None:
    """The split step of measurement-driven newborn terms (§3.4) in the probability modes."""

    Z, ego = _scan_arrays()
    for mode in _gate_free(modes):
        f = _filter(mode)
        for k in range(2):
            b = _births()
            b.newborn = NewbornTerms(
                np.zeros((2, 4)), np.repeat(np.eye(4)[None], 2, axis=0), lambda A, kappa: 0.1 + 0 * A
            )
            f.step(Scan(k, 0.1 * k, ego, Z, _no_obstacles(), [], shapely.box(0, 0, 1, 1)), b)


def _track_metrics(modes: tuple[str, ...]) -> None:
    """The track metrics' scan loops (§9.3): HOTA's and CLEAR's matchings and OSPA(2)'s windows."""
    from soabench.tracks.ospa2 import ospa2
    from soabench.tracks.scores import track_scores

    ids, xy = [np.array([1, 2])] * 2, [np.array([[0.0, 0.0], [9.0, 9.0]])] * 2
    track_scores(ids, xy, ids, xy, 5.0)
    ospa2(ids, xy, ids, xy)


def _lmb_steps(modes: tuple[str, ...]) -> None:
    """The LMB filter (docs/method.md "LMB filter"): steps with Gaussian births and with newborn terms (the adaptive
    birth), which compile the association marginals on their paths (exact and Gibbs sampling)."""
    from soabench.lmb import LMBFilter

    cfg = Config()
    Z, ego = _scan_arrays()
    f = LMBFilter(cfg.filter, cfg.sensor_at())
    for k in range(3):
        b = _births()
        b.newborn = NewbornTerms(np.zeros((2, 4)), np.repeat(np.eye(4)[None], 2, axis=0), lambda A, kappa: 0 * A)
        f.step(Scan(k, 0.1 * k, ego, Z, _no_obstacles(), [], shapely.box(0, 0, 1, 1)), b)


def _pmbm_steps(modes: tuple[str, ...]) -> None:
    """The PMBM and PMB filters (docs/method.md §10): steps with Gaussian births and newborn terms, which compile the
    clusters, the global hypotheses and Murty's ranked assignments with their solver."""
    from soabench.pmbm import PMBMFilter

    cfg = Config()
    Z, ego = _scan_arrays()
    # the whole cycle (soabench.pmbm.step), its split around the line of sight, and the three-call path (UKF)
    for pmb, occ, whole in itertools.product((False, True), (False, True), (True, False)):
        f = PMBMFilter(dataclasses.replace(cfg.filter, occlusion_pd=occ), cfg.sensor_at(), pmb=pmb)
        f.whole = f.whole and whole
        occluders = [shapely.box(-1.0, -1.0, 0.0, 0.0)] if occ else []
        for k in range(3):
            b = _births()
            b.newborn = NewbornTerms(np.zeros((2, 4)), np.repeat(np.eye(4)[None], 2, axis=0), lambda A, kappa: 0 * A)
            f.step(Scan(k, 0.1 * k, ego, Z, _no_obstacles(), occluders, shapely.box(0, 0, 1, 1)), b)


def _gate_free(modes: tuple[str, ...]) -> tuple[str, ...]:
    """The modes without the line-of-sight gate whose argument types ``modes`` use ("dynamic+occ": "dynamic")."""
    return tuple(dict.fromkeys("dynamic" if m == "dynamic+occ" else m for m in modes))


#: rounds of groups: the groups of a round are independent (no kernel in two of them) and run in parallel; a later
#: round links the earlier rounds' cached kernels. Each group compiles the kernels of the probability modes it is
#: given (those that take no mode ignore them). Within a round the longest go first (the pool starts groups in this
#: order), so that on two cores the short ones run beside the longest instead of after it.
ROUNDS: tuple[tuple[Callable[[tuple[str, ...]], None], ...], ...] = (
    (_reduction, _predict_update, _metrics_geometry),
    (_pmbm_steps, _lmb_steps, _track_metrics, _fused_steps, _newborn_steps),
)

#: the groups whose kernels take no probability mode (compiled once for all)
MODELESS = (_reduction, _metrics_geometry, _lmb_steps, _pmbm_steps, _track_metrics)

#: built-in birth models whose births carry measurement-driven newborn terms (:class:`~soabench.types.NewbornTerms`)
NEWBORN_MODELS = frozenset({"pubm", "atbm"})


def needed(configs: Iterable[Config | dict]) -> dict[Callable[[tuple[str, ...]], None], tuple[str, ...]]:
    """The groups a run of ``configs`` calls and, per group, its probability modes: the GM-PHD family's modes for
    the prediction, update and fused steps; the newborn step only when a birth model may hand newborn terms (one of
    :data:`NEWBORN_MODELS`, or a plugin); the LMB, and the PMBM/PMB, only when their family runs; the metric,
    geometry, reduction and track kernels always (the filters' runs are labelled). A configuration given as a dict
    that does not load asks for every group."""
    groups: dict[Callable[[tuple[str, ...]], None], tuple[str, ...]] = {}

    def add(group, modes):
        groups[group] = tuple(dict.fromkeys(groups.get(group, ()) + tuple(modes)))

    for cfg in configs:
        if isinstance(cfg, dict):
            try:
                cfg = Config.from_dict(cfg)
            except Exception:  # noqa: BLE001 - the run reports a bad configuration itself; here: compile everything
                return everything()
        exp = cfg.experiment
        for group in (_reduction, _metrics_geometry, _track_metrics):
            add(group, ("any",))
        if "gmphd" in exp.filters:
            add(_predict_update, exp.probabilities)
            add(_fused_steps, exp.probabilities)
            if any(m in NEWBORN_MODELS or m not in BIRTH_MODEL_NAMES for m in exp.models):
                add(_newborn_steps, exp.probabilities)
        if "lmb" in exp.filters:
            add(_lmb_steps, ("any",))
        if "pmbm" in exp.filters or "pmb" in exp.filters:
            add(_pmbm_steps, ("any",))
    return groups


def everything() -> dict[Callable[[tuple[str, ...]], None], tuple[str, ...]]:
    """Every group with every probability mode."""

    return {g: ("any",) if g in MODELESS else PROBABILITY_MODES for r in ROUNDS for g in r}


def _run_group(fn: Callable[[tuple[str, ...]], None], modes: tuple[str, ...]) -> None:

    notice.silence()  # the driver announces compilation once; a group process never does
    fn(modes)


def stamp_path(group: Callable | None = None, mode: str = "any") -> Path:
    """The file that marks one group's kernels of one probability mode compiled (no group: the folder's), in their
    cache folder (:func:`soabench.cache.kernel_folder`: keyed by the kernel sources, numba and Python)."""
    name = "all" if group is None else f"{group.__name__.strip('_')}-{mode}"
    return kernel_folder() / f"{name}.ready"


def _missing(groups: dict) -> dict[Callable[[tuple[str, ...]], None], tuple[str, ...]]:
    """The groups and modes of ``groups`` without a stamp."""
    out = {}
    for g, modes in groups.items():
        todo = tuple(m for m in modes if not stamp_path(g, m).exists())
        if todo:
            out[g] = todo
    return out


def compiled(groups: dict | None = None) -> bool:
    """True when every group and mode of ``groups`` (default: :func:`everything`) is stamped compiled."""
    try:
        return not _missing(everything() if groups is None else groups)
    except OSError:
        return False


def ensure_compiled(
    configs: Iterable[Config | dict] | None = None, stream: TextIO | None = None, workers: int | None = None
) -> float:
    """Compile the kernels that runs of ``configs`` call (:func:`needed`; None: every kernel) into the cache unless
    stamps say this was done; returns the seconds spent.

    ``workers``: processes to compile in (default: the number of cores, at most the size of a round). Prints
    :data:`MESSAGE` once to ``stream`` (stderr) when it compiles, the groups done and the seconds so far (redrawn on
    a terminal, a line every :data:`LINE_INTERVAL_S` seconds off one), and the time taken at the end."""
    try:
        todo = _missing(everything() if configs is None else needed(configs))
        todo = {g: modes for g, modes in todo.items() if any(g in r for r in ROUNDS)}
    except OSError:
        todo = {}
    if not todo:
        return 0.0

    stream = stream if stream is not None else sys.stderr
    t0 = time.monotonic()
    print(MESSAGE, file=stream, flush=True)
    notice.silence()  # this process's first steps load what is compiled here: no second notice
    tty = is_terminal(stream)
    rounds = [[g for g in r if g in todo] for r in ROUNDS]
    total, n_done = sum(len(r) for r in rounds), 0
    n = max(1, min(workers or os.cpu_count() or 1, max(len(r) for r in rounds)))
    ok = True

    def report(now: float) -> None:
        line = f"soabench: compiling, {n_done} of {total} groups done, {now - t0:.0f} s so far ..."
        print(("\r" + line) if tty else line, end="" if tty else "\n", file=stream, flush=True)

    try:
        with ProcessPoolExecutor(max_workers=n) as pool:
            last = t0
            for group in rounds:
                pending = {pool.submit(_run_group, g, todo[g]): g for g in group}
                while pending:
                    done, _ = wait(pending, timeout=1.0, return_when=FIRST_COMPLETED)
                    for fut in done:
                        g = pending.pop(fut)
                        n_done += 1
                        if fut.exception() is None:
                            _stamp(g, todo[g])
                        else:
                            ok = False
                    now = time.monotonic()
                    if done or tty or now - last >= LINE_INTERVAL_S:
                        if tty or now - last >= LINE_INTERVAL_S:
                            report(now)
                            last = now
    except Exception:  # noqa: BLE001 - never fatal: the trials compile what they need
        ok = False
    took = time.monotonic() - t0
    if tty:
        print(file=stream)
    if ok:
        print(f"soabench: kernels compiled in {took:.0f} s (cached for later runs)", file=stream, flush=True)
    else:
        print("soabench: compiling ahead failed; the trials compile what they need", file=stream, flush=True)
    return took


def _stamp(group: Callable, modes: tuple[str, ...]) -> None:
    try:
        for m in modes:
            path = stamp_path(group, m)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text("compiled\n")
    except OSError:
        pass
