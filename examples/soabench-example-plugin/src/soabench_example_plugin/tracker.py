"""An example tracker that is not a GM-PHD: nearest-neighbour Kalman filtering with M-of-N confirmation.

Each track is a constant-velocity Kalman filter in the world frame (state [p_x, p_y, v_x, v_y]). A range-bearing
measurement z = (r, b) is converted to a world position p = ego + r [cos(b + theta), sin(b + theta)] with the
linearised covariance J R J^T, so the update is linear. Per scan: predict every track, gate measurements by
Mahalanobis distance (chi-square, 2 degrees of freedom), assign greedily by increasing distance (global nearest
neighbour, greedy), update the assigned tracks, start a tentative track on every unassigned measurement. A track
is confirmed once it was updated in ``m`` of its last ``n`` scans and deleted after ``max_misses`` scans in a row
without a measurement. The estimates are the confirmed tracks, each labelled with its track number (1, 2, ... in
the order the tracks were started), so the harness can score identities too.
"""

from __future__ import annotations

import numpy as np

from soabench.api import Estimates, Scan, TrackerSetup


class NearestNeighbourKF:
    """``NearestNeighbourKF(setup, m=2, n=3, gate=13.8, max_misses=2, sigma_a=1.0, sigma_v0=2.0)``.

    Options (``[plugins.nnkf]``): ``m``-of-``n`` confirmation, ``gate`` (squared Mahalanobis distance; 13.8 is
    the 99.9 % chi-square quantile for 2 degrees of freedom), ``max_misses`` before deletion, ``sigma_a`` the
    acceleration noise std (m/s^2), ``sigma_v0`` the initial velocity std (m/s).
    """

    name = "nnkf"

    def __init__(
        self,
        setup: TrackerSetup,
        m: int = 2,
        n: int = 3,
        gate: float = 13.8,
        max_misses: int = 2,
        sigma_a: float = 1.0,
        sigma_v0: float = 2.0,
    ) -> None:
        if not (isinstance(m, int) and isinstance(n, int) and 1 <= m <= n):
            raise ValueError(f"m = {m!r}, n = {n!r}: integers with 1 <= m <= n are required")
        s = setup.sensor
        dt = float(s.dt)
        self.F = np.eye(4)
        self.F[0, 2] = self.F[1, 3] = dt
        G = np.array([[dt**2 / 2, 0], [0, dt**2 / 2], [dt, 0], [0, dt]])
        self.Q = sigma_a**2 * G @ G.T
        self.R = np.diag([s.sigma_r**2, np.radians(s.sigma_b_deg) ** 2])
        self.m, self.n, self.gate, self.max_misses, self.sigma_v0 = m, n, float(gate), int(max_misses), sigma_v0
        self.x = np.zeros((0, 4))
        self.P = np.zeros((0, 4, 4))
        self.hits = np.zeros((0, n), dtype=bool)  # hit history, newest last
        self.misses = np.zeros(0, dtype=int)
        self.confirmed = np.zeros(0, dtype=bool)
        self.ids = np.zeros(0, dtype=np.int64)  # track number of each track: its label
        self.next_id = 1

    def _measurements(self, scan: Scan) -> tuple[np.ndarray, np.ndarray]:
        """World positions (M, 2) and covariances (M, 2, 2) of the scan's measurements."""
        Z = np.asarray(scan.Z, dtype=float).reshape(-1, 2)
        x, y, theta = np.asarray(scan.ego, dtype=float)
        r, a = Z[:, 0], Z[:, 1] + theta
        c, s = np.cos(a), np.sin(a)
        p = np.column_stack([x + r * c, y + r * s])
        J = np.stack([np.stack([c, -r * s], -1), np.stack([s, r * c], -1)], 1)  # (M, 2, 2)
        return p, J @ self.R @ np.swapaxes(J, 1, 2)

    def step(self, scan: Scan) -> Estimates:
        p, Rp = self._measurements(scan)
        # predict
        self.x = self.x @ self.F.T
        self.P = self.F @ self.P @ self.F.T + self.Q
        T, M = len(self.x), len(p)
        assigned = np.full(T, -1)
        if T and M:
            S = self.P[:, None, :2, :2] + Rp[None]  # (T, M, 2, 2)
            d = p[None] - self.x[:, None, :2]
            d2 = np.einsum("tmi,tmi->tm", d, np.linalg.solve(S, d[..., None])[..., 0])
            used = np.zeros(M, dtype=bool)
            for flat in np.argsort(d2, axis=None):
                t, j = divmod(int(flat), M)
                if d2[t, j] > self.gate:
                    break
                if assigned[t] < 0 and not used[j]:
                    assigned[t], used[j] = j, True
        # update the assigned tracks
        for t in np.flatnonzero(assigned >= 0):
            j = assigned[t]
            S = self.P[t, :2, :2] + Rp[j]
            K = self.P[t, :, :2] @ np.linalg.inv(S)
            self.x[t] = self.x[t] + K @ (p[j] - self.x[t, :2])
            self.P[t] = (np.eye(4) - K @ np.eye(2, 4)) @ self.P[t]
        hit = assigned >= 0
        self.hits = np.column_stack([self.hits[:, 1:], hit]) if T else self.hits
        self.misses = np.where(hit, 0, self.misses + 1)
        self.confirmed |= self.hits.sum(axis=1) >= self.m
        # delete, then start tentative tracks on the unassigned measurements
        keep = self.misses <= self.max_misses
        self.x, self.P, self.hits = self.x[keep], self.P[keep], self.hits[keep]
        self.misses, self.confirmed, self.ids = self.misses[keep], self.confirmed[keep], self.ids[keep]
        new = np.setdiff1d(np.arange(M), assigned[assigned >= 0])
        if len(new):
            x0 = np.zeros((len(new), 4))
            x0[:, :2] = p[new]
            P0 = np.zeros((len(new), 4, 4))
            P0[:, :2, :2] = Rp[new]
            P0[:, 2, 2] = P0[:, 3, 3] = self.sigma_v0**2
            h0 = np.zeros((len(new), self.n), dtype=bool)
            h0[:, -1] = True
            self.x, self.P = np.concatenate([self.x, x0]), np.concatenate([self.P, P0])
            self.hits = np.concatenate([self.hits, h0])
            self.misses = np.concatenate([self.misses, np.zeros(len(new), dtype=int)])
            self.confirmed = np.concatenate([self.confirmed, np.full(len(new), self.m <= 1)])
            self.ids = np.concatenate([self.ids, np.arange(self.next_id, self.next_id + len(new), dtype=np.int64)])
            self.next_id += len(new)
        X = self.x[self.confirmed]
        return Estimates(X.copy(), n_components=len(self.x), labels=self.ids[self.confirmed].copy())
