"""A replayed trial as plain JSON-able data: the scene once, then one record per scan (docs/user-guide/replay.md).

Coordinates are metres rounded to 1 cm, with y negated (SVG's y axis points down), so the page draws them as they
come. The per-scan record holds what ``soabench scene --sensor`` draws (ego, FOV, Omega_k, truth, measurements) and
per birth model what ``soabench birth`` draws (the components of that scan, coloured by origin as the paper's
Fig. 2, docs/method.md §3.1, §3.6) plus the filter's estimates and each pedestrian's initiation state (§5.4).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import shapely

from soabench.config import family_label
from soabench.figures.births import SOURCE_COLORS, SOURCE_LABELS, ellipse_params
from soabench.geometry import polar_to_world
from soabench.sensor import fov_polygon, scan_steps
from soabench.types import CLUTTER, SOURCE_MEAS

#: pedestrian states of a scan: visible, occluded (in the FOV, line of sight blocked), outside the FOV, in a building
PED_STATES = ("visible", "occluded", "outside FOV", "in building")
#: a pedestrian's state in a model's panel: not detected yet in its visibility episode (or none), detected but not
#: initiated yet (the delay runs), initiated (docs/method.md §5.4)
INIT_STATES = ("none", "awaiting initiation", "initiated")

_CSS_COLORS = {"black": "#000000", "tab:green": "#2ca02c", "tab:red": "#d62728", "tab:blue": "#1f77b4",
               "tab:purple": "#9467bd", "tab:orange": "#ff7f0e"}  # fmt: skip


def _r(a: Any) -> Any:
    """Rounded to 1 cm as nested lists of floats."""
    return np.round(np.asarray(a, dtype=float), 2).tolist()


def _xy(a: np.ndarray) -> list:
    """(n, 2) world points -> rounded [[x, -y], ...] page points."""
    a = np.asarray(a, dtype=float).reshape(-1, 2)
    return _r(np.column_stack([a[:, 0], -a[:, 1]]))


def path_of(geom: Any, tol: float = 0.0) -> str:
    """An SVG path (even-odd fill) of a shapely (multi)polygon in page coordinates; '' when empty."""
    if geom is None or geom.is_empty:
        return ""
    if tol > 0:
        geom = geom.simplify(tol, preserve_topology=True)
    parts: list[str] = []
    for poly in getattr(geom, "geoms", [geom]):
        if poly.geom_type != "Polygon":
            if hasattr(poly, "geoms"):
                parts.append(path_of(poly, 0.0))
            continue
        for ring in (poly.exterior, *poly.interiors):
            pts = np.asarray(ring.coords)[:-1]
            if len(pts) >= 3:
                parts.append(_ring(pts))
    return "".join(parts)


def _ring(pts: np.ndarray) -> str:
    """One closed subpath: "M x y x y ... Z" (pairs after the first are implicit line-tos)."""
    p = np.round(np.column_stack([pts[:, 0], -pts[:, 1]]), 2)
    return "M" + " ".join(map(str, p.ravel().tolist())) + "Z"


def scene_data(scene: Any) -> dict[str, Any]:
    """The static map: roads, sidewalks and walking areas, crossings, buildings, parked cars, doors, bounds."""
    x0, y0, x1, y1 = (float(v) for v in scene.bounds)
    return {
        "viewBox": [x0, -y1, x1 - x0, y1 - y0],
        "roads": path_of(scene.roads),
        "sidewalk": path_of(scene.sidewalk.union(scene.walking_areas)),
        "crossings": path_of(scene.crossings),
        "buildings": "".join(path_of(b) for b in scene.buildings),
        "parked": "".join(path_of(o) for o in scene.static_occluders),
        "doors": _xy(scene.doors) if len(scene.doors) else [],
    }


def ped_states(scans: Any) -> np.ndarray:
    """(K, P) index into :data:`PED_STATES`, or -1 before a pedestrian first appears (or after it left the scene
    for good). A pedestrian absent between two presences is in a building."""
    present = np.asarray(scans.present, dtype=bool)
    K, P = present.shape
    out = np.full((K, P), -1, dtype=np.int8)
    seen_before = np.cumsum(present, axis=0) > 0
    seen_after = np.flip(np.cumsum(np.flip(present, axis=0), axis=0), axis=0) > 0
    out[~present & seen_before & seen_after] = 3
    out[present & ~np.asarray(scans.in_fov, dtype=bool)] = 2
    out[present & np.asarray(scans.in_fov, dtype=bool) & ~np.asarray(scans.visible, dtype=bool)] = 1
    out[present & np.asarray(scans.visible, dtype=bool)] = 0
    return out


def init_states(metrics: Any, K: int, P: int) -> np.ndarray:
    """(K, P) index into :data:`INIT_STATES` from the run's delay episodes (§5.4): from the first detection k_d of
    an episode to its initiation k_t (or its end, if censored) "awaiting", from k_t to the episode's end
    "initiated"."""
    out = np.zeros((K, P), dtype=np.int8)
    for e in metrics.episodes:
        stop = e.k_end + 1 if e.k_t < 0 else e.k_t
        out[e.k_d : stop, e.target] = 1
        if e.k_t >= 0:
            out[e.k_t : e.k_end + 1, e.target] = 2
    return out


def _birth_arrays(births: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The scan's birth terms (those of measurement newborns included): means (n, 4), covariances (n, 4, 4) and
    origins (n,); none for a whole tracker (``births`` None)."""
    if births is None:
        return np.zeros((0, 4)), np.zeros((0, 4, 4)), np.zeros(0, dtype=int)
    m = [np.asarray(births.m, dtype=float).reshape(-1, 4)]
    P = [np.asarray(births.P, dtype=float).reshape(-1, 4, 4)]
    src = [np.asarray(births.source, dtype=int).reshape(-1)]
    if births.newborn is not None:
        m.append(np.asarray(births.newborn.m, dtype=float).reshape(-1, 4))
        P.append(np.asarray(births.newborn.P, dtype=float).reshape(-1, 4, 4))
        src.append(np.full(len(m[-1]), SOURCE_MEAS))
    return np.concatenate(m), np.concatenate(P), np.concatenate(src)


def _births_of(arrays: tuple[np.ndarray, np.ndarray, np.ndarray]) -> list:
    """[[x, -y, width, height, angle_deg, source], ...]: the 2-sigma ellipses of the position blocks."""
    mm, PP, ss = arrays
    if not len(mm):
        return []
    w, h, a = ellipse_params(PP[:, :2, :2])
    rows = np.column_stack([mm[:, 0], -mm[:, 1], w, h, -a])  # the page's y is negated: angles turn the other way
    return [[*r, int(s)] for r, s in zip(np.round(rows, 2).tolist(), ss.tolist(), strict=True)]


def nearest_birth(arrays: tuple[np.ndarray, np.ndarray, np.ndarray], xy: np.ndarray) -> list | None:
    """The birth term of the scan nearest to the world point ``xy`` in its own position covariance:
    ``[sigmas, metres, source, x, -y]`` (Mahalanobis distance, Euclidean distance, origin, its mean in page
    coordinates), None without births. Its drawn ellipse is 2 sigma: a pedestrian outside every ellipse has no
    birth term there, which is why a model's delay runs (docs/method.md §3.6, §5.4)."""
    mm, PP, ss = arrays
    if not len(mm):
        return None
    d = np.asarray(xy, dtype=float)[None, :] - mm[:, :2]
    sig = np.sqrt(np.einsum("ni,ni->n", d, np.linalg.solve(PP[:, :2, :2], d[:, :, None])[:, :, 0]))
    i = int(np.argmin(sig))
    return [round(float(sig[i]), 2), round(float(np.hypot(*d[i])), 2), int(ss[i]), *_xy(mm[i, :2])[0]]


def _hidden(scene: Any, fov: Any, omega: Any) -> Any:
    """The complement of Omega_k on the sidewalk within the FOV: sidewalk the sensor cannot see (§3.1.4)."""

    base = shapely.clip_by_rect(scene.sidewalk, *fov.bounds).intersection(fov)
    return base.difference(omega) if not base.is_empty else base


def estimate_labels(result: Any) -> list[str] | None:
    """The track label of each estimate of a scan's result, as text, when the tracker gives them (an optional
    ``labels`` sequence beside ``X``, one per row); None otherwise (a GM-PHD's estimates carry no identity)."""
    labels = getattr(result, "labels", None)
    if labels is None:
        return None
    labels = [str(v) for v in np.asarray(labels, dtype=object).reshape(-1).tolist()]
    return labels if len(labels) == len(np.asarray(result.X)) else None


def track_labels(results: list[Any]) -> list[str]:
    """Every track label of a model's run in order of first appearance: label i is drawn in colour i of the page's
    palette in every frame, so a track keeps its colour (and a label switch shows as a colour change)."""
    seen: dict[str, None] = {}
    for res in results:
        for lab in estimate_labels(res) or ():
            seen.setdefault(lab, None)
    return list(seen)


def _label_index(result: Any, tracks: list[str]) -> list[int]:
    """Per estimate: the index of its label in ``tracks`` (-1: no label)."""
    labels = estimate_labels(result)
    if labels is None:
        return [-1] * len(np.asarray(result.X))
    where = {lab: i for i, lab in enumerate(tracks)}
    return [where[lab] for lab in labels]


def frame_data(
    rep: Any, k: int, idx: int, peds: np.ndarray, inits: list[np.ndarray], tracks: list[list[str]]
) -> dict[str, Any]:
    """Scan ``k`` (recording step ``idx``) of a :class:`~soabench.replay.simulate.TrialReplay` as a JSON-able
    record; ``peds`` from :func:`ped_states`, ``inits`` one :func:`init_states` per model, ``tracks`` one
    :func:`track_labels` per model. An estimate is ``[x, y, i]``: its label is ``tracks[model][i]`` (i = -1: none)."""

    scans, rec = rep.scans, rep.recording
    scan = scans.scans[k]
    ego = np.asarray(scan.ego, dtype=float)
    z = polar_to_world(scan.Z, ego) if len(scan.Z) else np.zeros((0, 2))
    clutter = np.asarray(scans.source[k]) == CLUTTER
    vehicles = [_xy(rec.veh_footprint[idx, j]) for j in range(len(rec.veh_ids)) if rec.veh_present[idx, j]]
    ped_rows = []
    for j in np.flatnonzero(peds[k] >= 0):
        xy = scans.truth_xy[k, j]
        if peds[k, j] == 3:  # in a building: drawn where it was last seen
            seen = np.flatnonzero(scans.present[:k, j])
            xy = scans.truth_xy[seen[-1], j]
        ped_rows.append([str(scans.ped_ids[j]), *_xy(xy)[0], int(peds[k, j]), int(bool(scans.detected[k, j])),
                         [int(s[k, j]) for s in inits]])  # fmt: skip
    fov, omega = fov_polygon(ego, rep.scans.sensor), scan.visible_region
    models = []
    for i, (m, labels) in enumerate(zip(rep.models, tracks, strict=True)):
        res, arrays = m.results[k], _birth_arrays(m.births[k])
        est = [[*xy, n] for xy, n in zip(_xy(np.asarray(res.X)[:, :2]), _label_index(res, labels), strict=True)]
        waiting = np.flatnonzero((inits[i][k] == 1) & np.asarray(scans.present[k], dtype=bool))
        why = [[str(scans.ped_ids[j]), *near] for j in waiting if (near := nearest_birth(arrays, scans.truth_xy[k, j]))]
        models.append({"births": _births_of(arrays), "est": est, "why": why,
                       "n_comp": int(res.n_reduced), "sum_w": _num(res.sum_w, 2)})  # fmt: skip
    return {
        "k": k,
        "t": round(float(scan.t), 3),
        "ego": _xy(ego[:2])[0] + [round(float(ego[2]), 4)],
        "ego_box": _xy(rec.ego_footprint[idx]) if not np.isnan(rec.ego_footprint[idx]).any() else [],
        "fov": path_of(fov),
        "omega": path_of(omega, tol=0.05),
        "hidden": path_of(_hidden(rep.scene, fov, omega), tol=0.05),
        "vehicles": vehicles,
        "peds": ped_rows,
        "z": [[*p, int(c)] for p, c in zip(_xy(z), clutter.tolist(), strict=True)],
        "models": models,
    }


def replay_data(rep: Any) -> dict[str, Any]:
    """The whole replay: header, scene, legend tables, per-model episodes and every scan's record."""

    scans = rep.scans
    K, P = np.shape(scans.present)
    peds = ped_states(scans)
    inits = [init_states(m.metrics, K, P) for m in rep.models]
    tracks = [track_labels(m.results) for m in rep.models]
    steps = scan_steps(rep.recording.t, rep.recording.step_length, scans.dt)
    exp = rep.config.experiment
    return {
        "title": f"trial {rep.trial} of {rep.run_dir.name}",
        "run": str(rep.run_dir),
        "trial": rep.trial,
        "seed": exp.seed,
        "sumo_seed": rep.seeds.sumo_seed,
        "mode": rep.mode,
        "filter": family_label(rep.family),
        "clutter": rep.clutter,
        "dt": float(scans.dt),
        "r_max": float(scans.sensor.r_max),
        "notes": list(rep.notes),
        "reproduced": rep.reproduced,
        "scene": scene_data(rep.scene),
        "ped_states": list(PED_STATES),
        "init_states": list(INIT_STATES),
        "sources": [
            {"label": lab, "color": _CSS_COLORS.get(c, c)} for lab, c in zip(SOURCE_LABELS, SOURCE_COLORS, strict=True)
        ],  # fmt: skip
        "models": [
            {
                "name": m.name,
                "label": m.label,
                "delay_mean": _num(m.row.get("delay_mean")),
                "ospa": _num(m.row.get("ospa")),
                "tracks": labels,
                "episodes": [
                    [str(scans.ped_ids[e.target]), e.k0, e.k_end, e.k_d, e.k_t, _num(e.delay), bool(e.censored)]
                    for e in m.metrics.episodes
                ],
            }
            for m, labels in zip(rep.models, tracks, strict=True)
        ],
        "frames": [frame_data(rep, k, int(idx), peds, inits, tracks) for k, idx in enumerate(steps)],
    }


def _num(v: Any, digits: int = 4) -> float | None:
    """A JSON number (None for NaN)."""
    f = float(v)
    return None if f != f else round(f, digits)
