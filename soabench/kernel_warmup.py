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
* a stamp file in the cache folder records that the kernels of this soabench, numba and Python (and these kernel
  sources: path and content, as numba's own cache key) were compiled, so a later run starts no process at all.

Each group calls the kernels with small inputs of the types a trial passes (the filter's own argument packing),
so the trials find exactly these specialisations in the cache. Compiling changes no number: the arithmetic is the
same compiled code whichever process compiled it. A failure here only costs time (the trials then compile what
they need) and is never fatal.
"""

from __future__ import annotations

import hashlib
import os
import sys
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path
from typing import TextIO

import numpy as np

from soabench import notice
from soabench.birth import sampling
from soabench.birth.soa import dedup, ego_inside
from soabench.cache import configure_numba_cache
from soabench.config import Config, MetricsConfig
from soabench.experiment.execution.progress import LINE_INTERVAL_S, is_terminal
from soabench.sensor import segment_meets_convex
from soabench.types import Births, NewbornTerms, Obstacles, Scan

#: the modules whose kernels are compiled here (their source files key the stamp, as they key numba's cache)
KERNEL_MODULES = (
    "soabench.gmphd.clock",
    "soabench.gmphd.kernels",
    "soabench.gmphd.cycle",
    "soabench.metrics_kernels",
    "soabench.geometry_kernels",
    "soabench.tracks.kernels",
    "soabench.lmb.gibbs",
    "soabench.lmb.tracks",
)
MESSAGE = notice.MESSAGE


def _filter(mode: str):
    # imported when called: numba would slow every start-up
    from soabench.gmphd import GMPHDFilter

    cfg = Config()
    return GMPHDFilter(cfg.filter, cfg.sensor, mode)


def _scan_arrays() -> tuple[np.ndarray, np.ndarray]:
    """Two measurements (range, bearing) and a pose, as :func:`soabench.gmphd.inputs.scan_inputs` returns them."""
    return np.array([[10.0, 0.1], [20.0, -0.2]]), np.array([0.0, 0.0, 0.0])


def _births(n: int = 2):

    m = np.zeros((n, 4))
    m[:, 0] = np.linspace(5.0, 15.0, n)
    return Births(np.full(n, 0.1), m, np.repeat(np.eye(4)[None], n, axis=0), np.zeros(n, dtype=np.int8))


def _predict_update() -> None:
    """The prediction and the update (EKF and UKF terms, posterior) of both probability modes' argument types."""
    # imported when called: numba would slow every start-up
    from soabench.gmphd import cycle
    from soabench.gmphd.filter import _birth_arrays, _mixture_arrays

    Z, ego = _scan_arrays()
    for mode in ("static", "dynamic"):
        f = _filter(mode)
        pred = cycle.predict_append(
            *_mixture_arrays(f.mixture), f.F, f.Q, f._pred_pars, *_birth_arrays(_births()), f._beta0, ego, f.next_label
        )
        cycle.update(*pred[:9], f._p_D, Z, ego, f.R, f._r_min, f._gate, f._kappa(Z), f._ukf)


def _reduction() -> None:
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


def _metrics_geometry() -> None:
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
    ego_inside([square], np.zeros(3))
    dedup(np.array([[0.0, 0.0], [0.1, 0.0]]), 1.0)
    t = np.zeros((1, 2))
    occlusion_layer_arrays(0.0, 0.0, t + 1.0, t, t + 5.0, np.array([1.0, 2.0]), 1.0, 1.0, 0.8, True)
    sampling._warm_poisson(poisson_accept, poisson_first_free)


def _no_obstacles():

    return Obstacles([], *(np.zeros(0) for _ in range(7)))


def _fused_steps() -> None:
    """The fused cycle's entry points as the filter calls them: one call per scan (both probability modes), and the
    split step of the line-of-sight gate (§2.11, §4.4)."""
    import shapely

    Z, ego = _scan_arrays()
    far = [shapely.box(1000.0, 1000.0, 1001.0, 1001.0)]
    for mode in ("static", "dynamic", "dynamic+occ"):
        f = _filter(mode)
        for k in range(2):  # the second step has a mixture to predict
            occluders = far if mode == "dynamic+occ" else []
            f.step(Scan(k, 0.1 * k, ego, Z, _no_obstacles(), occluders, shapely.box(0, 0, 1, 1)), _births())


def _newborn_steps() -> None:
    """The split step of measurement-driven newborn terms (§3.4) in both probability modes."""
    import shapely

    Z, ego = _scan_arrays()
    for mode in ("static", "dynamic"):
        f = _filter(mode)
        for k in range(2):
            b = _births()
            b.newborn = NewbornTerms(
                np.zeros((2, 4)), np.repeat(np.eye(4)[None], 2, axis=0), lambda A, kappa: 0.1 + 0 * A
            )
            f.step(Scan(k, 0.1 * k, ego, Z, _no_obstacles(), [], shapely.box(0, 0, 1, 1)), b)


def _track_metrics() -> None:
    """The track metrics' scan loops (§9.3): HOTA's and CLEAR's matchings and OSPA(2)'s windows."""
    from soabench.tracks.ospa2 import ospa2
    from soabench.tracks.scores import track_scores

    ids, xy = [np.array([1, 2])] * 2, [np.array([[0.0, 0.0], [9.0, 9.0]])] * 2
    track_scores(ids, xy, ids, xy, 5.0)
    ospa2(ids, xy, ids, xy)


def _lmb_steps() -> None:
    """The LMB filter (docs/method.md "LMB filter"): steps with Gaussian births and with newborn terms (the adaptive
    birth), and the association marginals on both of their paths (enumeration and Gibbs sampling)."""
    import shapely

    from soabench.config import Config
    from soabench.lmb import LMBFilter
    from soabench.lmb.gibbs import association_marginals
    from soabench.types import NewbornTerms, Scan

    cfg = Config()
    Z, ego = _scan_arrays()
    f = LMBFilter(cfg.filter, cfg.sensor)
    for k in range(3):
        b = _births()
        b.newborn = NewbornTerms(np.zeros((2, 4)), np.repeat(np.eye(4)[None], 2, axis=0), lambda A, kappa: 0 * A)
        f.step(Scan(k, 0.1 * k, ego, Z, _no_obstacles(), [], shapely.box(0, 0, 1, 1)), b)
    association_marginals(np.zeros((2, 4)), 10, np.uint32(0), True)


#: rounds of groups: the groups of a round are independent (no kernel in two of them) and run in parallel; a later
#: round links the earlier rounds' cached kernels
ROUNDS: tuple[tuple[Callable[[], None], ...], ...] = (
    (_reduction, _predict_update, _metrics_geometry),
    (_fused_steps, _newborn_steps, _lmb_steps, _track_metrics),
)


def _run_group(fn: Callable[[], None]) -> None:

    notice.silence()  # the driver announces compilation once; a group process never does
    fn()


def stamp_path() -> Path:
    """The file that marks this soabench's kernels compiled for this numba and Python in the cache folder."""
    import importlib.metadata
    import importlib.util

    try:
        own = importlib.metadata.version("soabench")
    except importlib.metadata.PackageNotFoundError:  # run from a checkout on PYTHONPATH: the digests below key it
        own = "checkout"
    parts = [sys.version, importlib.metadata.version("numba"), own]
    for name in KERNEL_MODULES:
        spec = importlib.util.find_spec(name)
        origin = spec.origin if spec is not None and spec.origin else ""
        digest = hashlib.sha256(Path(origin).read_bytes()).hexdigest()
        parts += [origin, digest]  # numba keys its cache on the path and the content of the source file too
    key = hashlib.sha256("\n".join(parts).encode()).hexdigest()[:16]
    return configure_numba_cache() / f"soabench-kernels-{key}.ready"


def compiled() -> bool:
    """True when :func:`ensure_compiled` completed for this soabench, numba and Python (stamp present)."""
    try:
        return stamp_path().exists()
    except OSError:
        return False


def ensure_compiled(stream: TextIO | None = None, workers: int | None = None) -> float:
    """Compile every kernel into the cache unless the stamp says this was done; returns the seconds spent.

    ``workers``: processes to compile in (default: the number of cores, at most the size of a round). Prints
    :data:`MESSAGE` once to ``stream`` (stderr) when it compiles, a line every :data:`LINE_INTERVAL_S` seconds off a
    terminal, and the time taken at the end."""
    if compiled():
        return 0.0

    stream = stream if stream is not None else sys.stderr
    t0 = time.monotonic()
    print(MESSAGE, file=stream, flush=True)
    notice.silence()  # this process's first steps load what is compiled here: no second notice
    tty = is_terminal(stream)
    n = max(1, min(workers or os.cpu_count() or 1, max(len(r) for r in ROUNDS)))
    ok = True
    try:
        with ProcessPoolExecutor(max_workers=n) as pool:
            last = t0
            for group in ROUNDS:
                pending = {pool.submit(_run_group, fn) for fn in group}
                while pending:
                    done, pending = wait(pending, timeout=1.0, return_when=FIRST_COMPLETED)
                    for fut in done:
                        ok = ok and fut.exception() is None
                    now = time.monotonic()
                    if not tty and now - last >= LINE_INTERVAL_S:
                        print(f"soabench: compiling, {now - t0:.0f} s so far ...", file=stream, flush=True)
                        last = now
    except Exception:  # noqa: BLE001 - never fatal: the trials compile what they need
        ok = False
    took = time.monotonic() - t0
    if ok:
        try:
            stamp_path().write_text(f"compiled in {took:.1f} s\n")
        except OSError:
            pass
        print(f"soabench: kernels compiled in {took:.0f} s (cached for later runs)", file=stream, flush=True)
    else:
        print("soabench: compiling ahead failed; the trials compile what they need", file=stream, flush=True)
    return took
