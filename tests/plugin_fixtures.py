"""Plugins for the tests, named by import path (``plugin_fixtures:Name``): well-behaved and broken ones.

Module-level classes so worker processes can import them (pytest puts tests/ on sys.path; forked workers inherit it).
"""

from __future__ import annotations

import numpy as np

from soabench.api import Births, Estimates, NewbornTerms, births_from, isotropic


class OneBirth:
    """A birth component 10 m ahead of the ego at every scan (weight N_hat); options: ``ahead`` (m)."""

    name = "one"

    def __init__(self, cfg, sensor, scene, rng, ahead: float = 10.0) -> None:
        self.cfg, self.ahead = cfg, ahead

    def __call__(self, ctx) -> Births:
        x, y, th = ctx.scan.ego
        p = np.array([[x + self.ahead * np.cos(th), y + self.ahead * np.sin(th)]])
        return births_from(p, isotropic(2.0, 1), [self.cfg.N_hat], [0], 1.0)


class RaiseAtScan3(OneBirth):
    def __call__(self, ctx) -> Births:
        if ctx.scan.k == 3:
            raise RuntimeError("boom at three")
        return super().__call__(ctx)


class NaNWeights(OneBirth):
    def __call__(self, ctx) -> Births:
        b = super().__call__(ctx)
        if ctx.scan.k == 2:
            b.w = np.array([np.nan])
        return b


class HugeWeights(OneBirth):
    def __call__(self, ctx) -> Births:
        b = super().__call__(ctx)
        b.w = np.full(len(b.w), 1e300)
        return b


class NegativeWeights(OneBirth):
    def __call__(self, ctx) -> Births:
        b = super().__call__(ctx)
        b.w = -b.w
        return b


class WrongShape(OneBirth):
    def __call__(self, ctx) -> Births:
        b = super().__call__(ctx)
        b.m = b.m[:, :2]
        return b


class ReturnsNone(OneBirth):
    def __call__(self, ctx):
        return None


class NegativeNewborn(OneBirth):
    """Newborn terms whose beta is negative: caught when the update calls it."""

    def __call__(self, ctx) -> Births:
        M = len(ctx.scan.Z)
        nb = NewbornTerms(np.zeros((M, 4)), np.tile(np.eye(4), (M, 1, 1)), lambda A, kappa: -np.ones(len(A)))
        b = Births.empty()
        b.newborn = nb
        return b


class BadInit(OneBirth):
    def __init__(self, cfg, sensor, scene, rng) -> None:
        raise ImportError("a dependency of this plugin is missing")


class EchoTracker:
    """Reports every measurement as a target (positions only): a deliberately poor but valid tracker."""

    name = "echo"

    def __init__(self, setup, scale: float = 1.0) -> None:
        self.scale = scale

    def step(self, scan) -> Estimates:
        Z = np.asarray(scan.Z, dtype=float).reshape(-1, 2)
        x, y, th = scan.ego
        p = np.column_stack([x + Z[:, 0] * np.cos(Z[:, 1] + th), y + Z[:, 0] * np.sin(Z[:, 1] + th)])
        return Estimates(p * self.scale if self.scale != 1.0 else p, w=np.ones(len(p)), n_components=len(p))


def cell_code(x: float, y: float) -> int:
    """The 10 m grid cell of (x, y) as one integer (the track label of :class:`LabelledEchoTracker` is 100 times it
    plus the estimate's rank in that cell at the scan)."""
    return (int(x // 10) + 1000) * 10_000 + int(y // 10) + 1000


class LabelledEchoTracker(EchoTracker):
    """EchoTracker whose estimates carry track labels: the 10 m grid cell of each (stable while a target lingers),
    made distinct within a scan by its rank among the scan's estimates in that cell."""

    def step(self, scan) -> Estimates:
        est = super().step(scan)
        cells = [cell_code(x, y) for x, y in np.asarray(est.X)[:, :2]]
        labels = [100 * c + cells[:i].count(c) for i, c in enumerate(cells)]
        est.labels = np.array(labels, dtype=np.int64)
        return est


class SilentTracker(EchoTracker):
    def step(self, scan):
        return None


class NaNTracker(EchoTracker):
    def step(self, scan) -> Estimates:
        return Estimates(np.full((1, 2), np.nan))


class StringTracker(EchoTracker):
    def step(self, scan) -> Estimates:
        return Estimates(np.array([["a", "b"]]))


class NotATracker:
    """No step method."""


class AlwaysRaises(EchoTracker):
    def step(self, scan):
        raise RuntimeError("fails at every scan")


class SysExit(EchoTracker):
    def step(self, scan):
        import sys

        sys.exit(0)


class OsExit(EchoTracker):
    def step(self, scan):
        import os

        os._exit(0)


class RaisesKeyboardInterrupt(EchoTracker):
    def step(self, scan):
        raise KeyboardInterrupt


class SleepsForever(EchoTracker):
    def step(self, scan):
        import time

        time.sleep(1e6)


class Prints(EchoTracker):
    def step(self, scan):
        print("PLUGIN OUTPUT LINE")
        return super().step(scan)


class KillsItsProcess(EchoTracker):
    """Kills the process it runs in at scan 2 (as a crash in native code would)."""

    def step(self, scan):
        import os
        import signal

        if scan.k == 2:
            os.kill(os.getpid(), signal.SIGKILL)
        return super().step(scan)


class CtrlCWhileRunning(EchoTracker):
    """Sends SIGINT to its process at scan 2 and keeps working: what a user's Ctrl-C during a plugin's call does."""

    def step(self, scan):
        import os
        import signal
        import time

        if scan.k == 2:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(2.0)
        return super().step(scan)


def _scribble(scan) -> None:
    """Change everything a scan holds, in place and by reassignment."""
    scan.Z[:] = 1.0
    scan.ego[:2] += 100.0
    for name in ("centroid_range", "theta_min", "theta_max", "r_min", "r_max"):
        getattr(scan.obstacles, name)[:] = 0.0
    for p in scan.obstacles.polygons:
        p[:] = 0.0
    scan.occluders.clear()
    scan.Z = np.zeros((0, 2))
    scan.k = -5


class ScanMutator(EchoTracker):
    """Changes the scan it is given (every array, a list, and by reassignment), then reports nothing."""

    def step(self, scan) -> Estimates:
        _scribble(scan)
        return Estimates.empty()


class ScanMutatingBirth(OneBirth):
    """Changes its configuration when built and every scan it is given."""

    def __init__(self, cfg, sensor, scene, rng) -> None:
        super().__init__(cfg, sensor, scene, rng)
        cfg.N_hat = 99.0
        sensor.r_max = 1.0

    def __call__(self, ctx) -> Births:
        _scribble(ctx.scan)
        return Births.empty()
