"""The S-OA birth model of Menezes & Campbell: gamma_k = gamma_occl + gamma_sem + gamma_fov (paper eqs. 7-17).

docs/method.md §3.1. Three sources of Gaussian birth components, all passed through the FOV-only rule of §3.0:

* occlusion terms (§3.1.2-3.1.3, eqs. 8-11): L layers at spacing delta_r behind the tangent point of both tangent
  rays of every obstacle, with covariance sigma_par^2 u u^T + sigma_perp^2 u_perp u_perp^T aligned with the ray,
  de-duplicated within delta_r / 2;
* semantic terms (§3.1.4, eqs. 12-14): means in Omega_k = ``scan.visible_region`` placed by Poisson-disk sampling
  (default: sampled once per trial over the static sidewalk region and clipped per step), a hexagonal lattice,
  i.i.d. uniform points or DBSCAN clusters; covariance sigma_sem^2 I;
* FOV-boundary terms (§3.1.5, eq. 15): N_fov = max(1, floor(length / d_fov)) points on the range boundary inset by
  sigma_fov (world-frame phase on the 360 deg circle), or on the visibility-clipped boundary; covariance
  sigma_fov^2 I.

Weights (§3.1.6, eq. 16 and the formula after it): w_i = N_hat rho_s(i) / sum_j rho_s(j) over the instantiated
components, so the birth mass is exactly N_hat.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import shapely
from shapely import STRtree
from shapely.geometry import LineString, Point
from shapely.geometry.base import BaseGeometry

from soabench.birth.base import FOVRule, births_from, isotropic
from soabench.birth.sampling import dbscan_clusters, grid_points, hex_lattice, poisson_disk, uniform_points
from soabench.config import BirthConfig, SensorConfig
from soabench.notice import announced
from soabench.scenario.scene import SceneMap
from soabench.sensor import fov_polygon, shadow_polygons
from soabench.types import SOURCE_FOV, SOURCE_OCCL, SOURCE_SEM, BirthContext, Births, Obstacles, Scan

#: speed of the optional occlusion velocity prior (m/s), §3.1.3 ``occl_velocity_prior``
OCCL_SPEED = 0.8
#: spacing of the DBSCAN candidate grid over Omega (m), §3.1.4
DBSCAN_GRID = 0.5


# ---------------------------------------------------------------------------------------------------------------------
# occlusion terms (eqs. 8-11)
# ---------------------------------------------------------------------------------------------------------------------


def ego_inside(polygons: list[np.ndarray], e: np.ndarray) -> np.ndarray:
    """(N,) True where the sensor position ``e`` is inside or on convex polygon j (§3.1.2: skip such obstacles, T15).

    ``e`` is inside a convex polygon iff the cross products of every edge with ``e`` share one sign (zero allowed,
    within 1e-12 of the largest coordinate), whatever the winding: one compiled pass over all edges
    (:func:`soabench.geometry_kernels.convex_contains`).
    """
    N = len(polygons)
    if N == 0:
        return np.zeros(0, dtype=bool)
    # imported when called: numba would slow every start-up
    from soabench.geometry_kernels import convex_contains, flat_polygons

    x, y, starts, counts = flat_polygons(polygons)
    tol = 1e-12 * max(1.0, float(np.abs(x).max()), float(np.abs(y).max()))
    e = np.asarray(e, dtype=float)
    return announced("geometry.convex", convex_contains, x, y, starts, counts, float(e[0]), float(e[1]), tol)


def occlusion_layers(
    obstacles: Obstacles, ego: np.ndarray, cfg: BirthConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Candidate occlusion components of eqs. 9-11, vectorised over obstacles x {min, max} rays x L layers.

    For ray b in {min, max} of obstacle j and l = 1..L: r_l = r^b + l delta_r, p = e + r_l u(theta_b),
    P_p = R(theta_b) diag(sigma_par^2, sigma_perp^2) R(theta_b)^T (§3.1.3). r^b is the tangent-point range
    (``ray_start = tangent``, register row 9) or the centroid range r'_j (``centroid``). Obstacles containing the
    sensor give nothing (T15).

    Returns:
        ``(p, P_p, v, r)``: (J, 2) means, (J, 2, 2) covariances, (J, 2) velocity means (zero unless
        ``occl_velocity_prior``: 0.8 m/s along -u_perp(theta_min) / +u_perp(theta_max), out of the cone) and (J,)
        ranges r_l, in obstacle-major, then ray (min, max), then layer order.
    """
    e = np.asarray(ego, dtype=float)
    N = len(obstacles)
    if N == 0 or cfg.L == 0:
        return np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros((0, 2)), np.zeros(0)
    keep = ~ego_inside(obstacles.polygons, e)
    theta = np.column_stack([obstacles.theta_min, obstacles.theta_max])[keep]  # (N', 2)
    if cfg.ray_start == "centroid":
        rb = np.repeat(np.asarray(obstacles.centroid_range, dtype=float)[keep, None], 2, axis=1)
    else:
        rb = np.column_stack([obstacles.r_min, obstacles.r_max])[keep]
    layers = cfg.delta_r * np.arange(1, cfg.L + 1)
    # u(theta_b) = (cos, sin) by numpy; r = r_b + l delta_r, p = e + r u, P_p = sigma_par^2 u u^T + sigma_perp^2
    # u_perp u_perp^T with u_perp = (-sin, cos), and the velocity prior (out of the cone: clockwise of theta_min,
    # counter-clockwise of theta_max) in one compiled pass (soabench.geometry_kernels.occlusion_layer_arrays)
    from soabench.geometry_kernels import occlusion_layer_arrays

    return announced(
        "geometry.layers",
        occlusion_layer_arrays,
        float(e[0]),
        float(e[1]),
        np.ascontiguousarray(np.cos(theta)),
        np.ascontiguousarray(np.sin(theta)),
        np.ascontiguousarray(rb, dtype=float),
        layers,
        float(cfg.sigma_par**2),
        float(cfg.sigma_perp**2),
        float(OCCL_SPEED),
        bool(cfg.occl_velocity_prior),
    )


def dedup(xy: np.ndarray, d_dup: float) -> np.ndarray:
    """(J,) keep-mask: greedy in order, a point within ``d_dup`` of an already kept point is dropped (§3.1.3)."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if len(xy) < 2:
        return np.ones(len(xy), dtype=bool)
    # imported when called: numba would slow every start-up
    from soabench.geometry_kernels import greedy_dedup  # compiled: one pass over the pairs

    return announced("geometry.dedup", greedy_dedup, xy[:, 0].copy(), xy[:, 1].copy(), float(d_dup))


def visible_obstacles(obstacles: Obstacles, ego: np.ndarray, sensor: SensorConfig) -> np.ndarray:
    """(N,) obstacles whose footprint is not fully occluded (option ``occluders_from_detections``, §3.1.1).

    Obstacle j is kept if some of its footprint inside FOV_k lies outside every other obstacle together with its
    shadow (:func:`soabench.sensor.shadow_polygons`), i.e. a detector could see part of it.
    """
    N = len(obstacles)
    if N == 0:
        return np.zeros(0, dtype=bool)
    hulls = shadow_polygons(np.asarray(ego, dtype=float)[:2], obstacles, sensor.r_max)
    verts = [np.asarray(v, dtype=float).reshape(-1, 2) for v in obstacles.polygons]
    owner = np.repeat(np.arange(N), [len(v) for v in verts])
    footprints = shapely.polygons(shapely.linearrings(np.concatenate(verts), indices=owner))
    seen = shapely.intersection(footprints, fov_polygon(ego, sensor))
    out = np.zeros(N, dtype=bool)
    for j in range(N):
        others = np.delete(hulls, j)
        part = shapely.difference(seen[j], shapely.union_all(others)) if len(others) else seen[j]
        out[j] = part.area > 1e-9
    return out


# ---------------------------------------------------------------------------------------------------------------------
# FOV boundary (eq. 15)
# ---------------------------------------------------------------------------------------------------------------------


def sector_boundary_points(sensor: SensorConfig, inset: float, d_fov: float) -> np.ndarray:
    """Ego-frame FOV-boundary means of a sector FOV (§3.1.5): (N_fov, 2).

    The polyline is the ray at -Theta/2 (offset inward by ``inset``) out to radius r_max - inset, the arc of that
    radius, and the ray at +Theta/2 back; N_fov = max(1, floor(length / d_fov)) points at the centres of equal
    arc-length pieces.
    """
    half = 0.5 * sensor.fov
    rf = sensor.r_max - inset
    s1 = math.sqrt(max(rf * rf - inset * inset, 0.0))
    s0 = min(math.sqrt(max((sensor.r_min + inset) ** 2 - inset * inset, 0.0)), s1)
    a_in = math.asin(min(inset / rf, 1.0)) if rf > 0 else 0.0

    def ray(sign: float) -> np.ndarray:
        a = sign * half
        u = np.array([math.cos(a), math.sin(a)])
        n = -sign * np.array([-math.sin(a), math.cos(a)])  # inward normal
        return np.array([s0 * u + inset * n, s1 * u + inset * n])

    arc_a = np.linspace(-half + a_in, half - a_in, 181) if half - a_in > -half + a_in else np.array([0.0])
    arc = rf * np.column_stack([np.cos(arc_a), np.sin(arc_a)])
    line = LineString(np.concatenate([ray(-1.0), arc, ray(1.0)[::-1]]))
    n_fov = max(1, int(math.floor(line.length / d_fov)))
    s = (np.arange(n_fov) + 0.5) * line.length / n_fov
    return shapely.get_coordinates(shapely.line_interpolate_point(line, s))


def visible_boundary_points(
    ego: np.ndarray, sensor: SensorConfig, occluders: list[BaseGeometry], inset: float, d_fov: float
) -> np.ndarray:
    """World-frame means on the visibility-clipped FOV boundary (option ``fov_boundary = visible``, §3.1.5).

    Rays in 1 deg bins, rho(phi) = min(r_max, first occluder hit), polyline e + (rho(phi) - inset) u(phi), and
    N_fov = max(1, floor(length / d_fov)) points at equal arc-length spacing.
    """
    e = np.asarray(ego, dtype=float)
    full = sensor.fov_deg >= 360.0
    n_bins = 360 if full else max(2, int(round(sensor.fov_deg)) + 1)
    rel = np.linspace(0.0, 2.0 * np.pi, n_bins, endpoint=False) if full else np.linspace(-0.5, 0.5, n_bins) * sensor.fov
    phi = (rel if full else rel + e[2])[:, None]
    u = np.hstack([np.cos(phi), np.sin(phi)])
    rho = np.full(n_bins, sensor.r_max)
    occluders = [g for g in occluders if not g.covers(Point(e[0], e[1]))]  # one around the sensor blocks nothing
    if occluders:
        rays = shapely.linestrings(np.stack([np.broadcast_to(e[:2], u.shape), e[:2] + sensor.r_max * u], axis=1))
        occ = np.array(occluders, dtype=object)
        i_ray, i_occ = STRtree(occluders).query(rays, predicate="intersects")
        if len(i_ray):
            hit = shapely.distance(Point(e[0], e[1]), shapely.intersection(rays[i_ray], occ[i_occ]))
            np.minimum.at(rho, i_ray, hit)
    pts = e[:2] + np.maximum(rho - inset, 0.0)[:, None] * u
    if full:
        pts = np.vstack([pts, pts[:1]])
    line = LineString(pts)
    n_fov = max(1, int(math.floor(line.length / d_fov)))
    s = (np.arange(n_fov) + (0.0 if full else 0.5)) * line.length / n_fov
    return shapely.get_coordinates(shapely.line_interpolate_point(line, s))


# ---------------------------------------------------------------------------------------------------------------------
# the model
# ---------------------------------------------------------------------------------------------------------------------


def combined_weights(source: np.ndarray, rho: tuple[float, float, float], N_hat: float, norm: str) -> np.ndarray:
    """Weights of eq. 16 and the formula after it (§3.1.6); ``source`` holds SOURCE_OCCL/SEM/FOV codes (0, 1, 2).

    ``component`` (paper): w_i = N_hat rho_s(i) / sum_j rho_s(j). ``source``: w_i = N_hat (rho_s / sum_s' rho_s')
    / J_s, the sum running over the sources present this step. Both sum to N_hat when some rho_s(i) > 0.
    """
    r = np.asarray(rho, dtype=float)[source]
    if len(r) == 0 or r.sum() <= 0.0:
        return np.zeros(len(r))
    if norm == "component":
        return N_hat * r / r.sum()
    J_s = np.bincount(source, minlength=3).astype(float)
    present = np.flatnonzero(J_s > 0)
    total = np.asarray(rho, dtype=float)[present].sum()
    if total <= 0.0:
        return np.zeros(len(r))
    return N_hat * (r / total) / J_s[source]


class SOABirth:
    """Semantic- and occlusion-aware birth (§3.1). ``SOABirth(cfg, sensor, scene, rng)(ctx) -> Births``.

    The constructor does all per-trial work: the semantic point set (Poisson-disk over the static sidewalk region
    with the placement ``rng``, or the hex lattice), its time-invariant part of the FOV-only rule, and the FOV
    boundary geometry. Each call clips and filters arrays only.
    """

    name = "soa"
    #: births read only the scan (not ``ctx.prev`` nor ``ctx.p_D_b``): one call per scan serves every probability mode
    mode_free = True

    def __init__(self, cfg: BirthConfig, sensor: SensorConfig, scene: SceneMap, rng: np.random.Generator) -> None:
        cfg.validate()
        self.cfg, self.sensor, self.scene = cfg, sensor, scene
        self.rule = FOVRule(cfg, sensor, scene)
        self.extra: BaseGeometry | None = None  # crossings and walking areas (sem_include_crossings)
        omega = scene.sidewalk
        if cfg.sem_include_crossings:
            self.extra = shapely.union(scene.crossings, scene.walking_areas)
            omega = shapely.union(omega, self.extra)
            shapely.prepare(self.extra)
        self.omega_static = omega
        self.step_seed = int(rng.integers(2**63))  # per-(trial, k) streams for step-wise placements
        self.sem_pts = np.zeros((0, 2))
        if cfg.sem_mode == "poisson" and cfg.sem_resample == "trial":
            self.sem_pts = poisson_disk(omega, cfg.d_min, rng, cfg.poisson_k)
        elif cfg.sem_mode == "hex":
            self.sem_pts = hex_lattice(omega, cfg.d_min)
        elif cfg.sem_mode == "dbscan":
            self.sem_pts = grid_points(omega, DBSCAN_GRID)
        self.sem_static_ok = self.rule.static_mask(self.sem_pts)
        self.sem_extra = (
            shapely.contains_xy(self.extra, self.sem_pts[:, 0], self.sem_pts[:, 1])
            if self.extra is not None
            else np.zeros(len(self.sem_pts), dtype=bool)
        )
        # FOV boundary: world-frame angles on the 360 deg circle, ego-frame points of the sector polyline
        self.r_fov = sensor.r_max - cfg.sigma_fov
        if sensor.fov_deg >= 360.0:
            n_fov = max(1, int(math.floor(2.0 * math.pi * max(self.r_fov, 0.0) / cfg.d_fov)))
            phi = 2.0 * np.pi * np.arange(n_fov) / n_fov
            self.fov_local = self.r_fov * np.column_stack([np.cos(phi), np.sin(phi)])  # translate only
        else:
            self.fov_local = sector_boundary_points(sensor, cfg.sigma_fov, cfg.d_fov)  # rotate by theta_e

    # -- sources -------------------------------------------------------------------------------------------------

    def occlusion(self, scan: Scan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Occlusion candidates (p, P_p, v) after the range cut r_l <= r_max - delta_in (§3.1.3)."""
        obs = scan.obstacles
        if self.cfg.occluders_from_detections and len(obs):
            vis = visible_obstacles(obs, scan.ego, self.sensor)
            obs = _subset(obs, vis)
        p, P_p, v, r = occlusion_layers(obs, scan.ego, self.cfg)
        ok = r <= self.sensor.r_max - self.cfg.delta_in
        return p[ok], P_p[ok], v[ok]

    def omega_k(self, scan: Scan) -> BaseGeometry:
        """Omega_k as a region: ``scan.visible_region`` (plus crossings/walking areas in the FOV if configured)."""
        if self.extra is None:
            return scan.visible_region
        return shapely.union(scan.visible_region, shapely.intersection(self.extra, fov_polygon(scan.ego, self.sensor)))

    def in_omega(self, xy: np.ndarray, scan: Scan, extra: np.ndarray | None = None) -> np.ndarray:
        """(J,) points of Omega_k: in ``scan.visible_region``, or (with crossings) in the extra region and in line
        of sight of the sensor (the sensor's visible region covers sidewalks only)."""
        ok = _in_visible_region(scan, xy)
        if self.extra is not None and len(xy):
            if extra is None:
                extra = shapely.contains_xy(self.extra, xy[:, 0], xy[:, 1])
            cand = np.flatnonzero(extra & ~ok)
            if len(cand) and scan.occluders:
                e = np.broadcast_to(scan.ego[:2], (len(cand), 2))
                sight = shapely.linestrings(np.stack([e, xy[cand]], axis=1))
                blocked = np.unique(self.rule.occluder_index(scan).query(sight, predicate="intersects")[0])
                cand = np.delete(cand, blocked)
            ok[cand] = True
        return ok

    def semantic(self, scan: Scan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Semantic candidates (p, P_p, static_ok) in Omega_k (§3.1.4, eqs. 12-14)."""
        cfg = self.cfg
        mode = cfg.sem_mode
        if (mode == "poisson" and cfg.sem_resample == "trial") or mode in ("hex", "dbscan"):
            pre = self.sem_static_ok.copy()
            pre[pre] &= self.rule.in_fov(self.sem_pts[pre], scan)
            idx = np.flatnonzero(pre)
            idx = idx[self.in_omega(self.sem_pts[idx], scan, self.sem_extra[idx])]
            pts = self.sem_pts[idx]
            if mode != "dbscan":
                return pts, isotropic(cfg.sigma_sem, len(pts)), np.ones(len(pts), dtype=bool)
            mu, s2 = dbscan_clusters(
                pts,
                cfg.dbscan_eps,
                cfg.dbscan_min_samples,
                DBSCAN_GRID**2,
                cfg.d_min if cfg.dbscan_split else None,
                seed=int(np.random.SeedSequence([self.step_seed, scan.k]).generate_state(1)[0]),
            )
            return mu, isotropic(np.sqrt(s2), len(mu)), self.rule.static_mask(mu)
        rng_k = np.random.default_rng([self.step_seed, int(scan.k)])
        region = self.omega_k(scan)
        if mode == "poisson":  # sem_resample = "step"
            pts = poisson_disk(region, cfg.d_min, rng_k, cfg.poisson_k)
        else:  # uniform: J_sem = ceil(area(Omega_k) / d_min^2) i.i.d. points
            pts = uniform_points(region, int(math.ceil(region.area / cfg.d_min**2)), rng_k)
        pts = pts[self.in_omega(pts, scan)] if self.extra is not None else pts
        return pts, isotropic(cfg.sigma_sem, len(pts)), self.rule.static_mask(pts)

    def fov_boundary(self, scan: Scan) -> np.ndarray:
        """FOV-boundary candidate means (§3.1.5, eq. 15)."""
        e = np.asarray(scan.ego, dtype=float)
        if self.cfg.fov_boundary == "visible":
            return visible_boundary_points(e, self.sensor, list(scan.occluders), self.cfg.sigma_fov, self.cfg.d_fov)
        if self.sensor.fov_deg >= 360.0:
            return e[:2] + self.fov_local
        c, s = math.cos(e[2]), math.sin(e[2])
        return e[:2] + self.fov_local @ np.array([[c, s], [-s, c]])

    # -- gamma_k -------------------------------------------------------------------------------------------------

    def __call__(self, ctx: BirthContext) -> Births:
        """gamma_k = gamma_occl + gamma_sem + gamma_fov (eq. 17) after the FOV-only rule, with total mass N_hat."""
        return self.weigh(self.cfg, self.candidates(ctx))

    def candidates(self, ctx: BirthContext) -> SOACandidates:
        """The components of gamma_k before their weights (eq. 17 after the FOV-only rule and the de-duplication).

        They read only the scan's geometry (pose, O_k, occluders, Omega_k), not Z_k nor N_hat, so one set serves
        every probability mode, clutter rate and N_hat of a trial (:meth:`weigh`; docs/method.md §5.8).
        """
        scan, cfg = ctx.scan, self.cfg
        p_o, P_o, v_o = self.occlusion(scan)
        p_s, P_s, ok_s = self.semantic(scan)
        p_f = self.fov_boundary(scan)
        P_f = isotropic(cfg.sigma_fov, len(p_f))
        xy = np.concatenate([p_o, p_s, p_f])
        src = np.repeat(np.array([SOURCE_OCCL, SOURCE_SEM, SOURCE_FOV]), [len(p_o), len(p_s), len(p_f)])
        # the FOV-only rule (FOVRule.mask): the semantic means carry their static part; the others' is asked only of
        # those in FOV_k, in one query
        keep = self.rule.in_fov(xy, scan)
        sem = src == SOURCE_SEM
        keep[sem] &= ok_s
        ask = np.flatnonzero(keep & ~sem)
        keep[ask] = self.rule.static_mask(xy[ask])
        keep[keep] &= ~self.rule.in_occluder(xy[keep], scan)
        occl = np.flatnonzero(keep[: len(p_o)])
        keep[occl[~dedup(p_o[occl], 0.5 * cfg.delta_r)]] = False
        P_p = np.concatenate([P_o, P_s, P_f])[keep]
        v = np.concatenate([v_o, np.zeros((len(p_s) + len(p_f), 2))])[keep]
        return SOACandidates(xy[keep], P_p, v, src[keep])

    @staticmethod
    def weigh(cfg: BirthConfig, c: SOACandidates) -> Births:
        """gamma_k from its candidates: weights N_hat rho_s(i) / sum_j rho_s(j) (eq. 16), zero weights dropped."""
        w = combined_weights(c.source, cfg.rho, cfg.N_hat, cfg.rho_norm)
        nz = w > 0.0
        return births_from(c.p[nz], c.P_p[nz], w[nz], c.source[nz], cfg.sigma_v_birth, c.v[nz])


class SOACandidates(NamedTuple):
    """S-OA's birth components of one scan before weighting (:meth:`SOABirth.candidates`)."""

    p: np.ndarray  #: (J, 2) position means
    P_p: np.ndarray  #: (J, 2, 2) position covariances
    v: np.ndarray  #: (J, 2) velocity means (occlusion velocity prior; else 0)
    source: np.ndarray  #: (J,) SOURCE_OCCL / SOURCE_SEM / SOURCE_FOV


def _in_visible_region(scan: Scan, xy: np.ndarray) -> np.ndarray:
    """(J,) points in the interior of Omega_k: ``scan.in_visible_region`` (which does not build a deferred
    region's polygon), or ``contains_xy`` on ``scan.visible_region`` for a duck-typed scan without it."""
    test = getattr(scan, "in_visible_region", None)
    if test is not None:
        return test(xy)
    return shapely.contains_xy(scan.visible_region, xy[:, 0], xy[:, 1])


def _subset(obs: Obstacles, keep: np.ndarray) -> Obstacles:
    """The obstacles selected by the boolean mask ``keep``."""
    idx = np.flatnonzero(keep)
    return Obstacles(
        polygons=[obs.polygons[i] for i in idx],
        kind=np.asarray(obs.kind)[idx],
        centroid_range=np.asarray(obs.centroid_range)[idx],
        centroid_bearing=np.asarray(obs.centroid_bearing)[idx],
        theta_min=np.asarray(obs.theta_min)[idx],
        theta_max=np.asarray(obs.theta_max)[idx],
        r_min=np.asarray(obs.r_min)[idx],
        r_max=np.asarray(obs.r_max)[idx],
    )
