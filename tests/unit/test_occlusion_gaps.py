"""Occlusion gaps described (docs/method.md §9.4): length, occluder kind, target and ego movement, and the per-episode
gap columns of a filter run, on hand-built scenes whose line of sight is the sensor's own."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Polygon

from soabench.config import MetricsConfig, SensorConfig
from soabench.metrics import delay_episodes
from soabench.sensor import compute_obstacles, line_of_sight
from soabench.tracks.evaluate import GAP_KEYS, track_evaluation
from soabench.tracks.gaps import EGO_MOVED_M, describe_gaps, hiding_kind, hiding_kinds
from soabench.tracks.reemergence import Gap, occlusion_gaps
from soabench.types import Scan, Scans

CAR = np.array([(-1.0, 4.0), (1.0, 4.0), (1.0, 6.0), (-1.0, 6.0)])  # a parked car 4-6 m ahead
BUILDING = np.array([(20.0, -5.0), (30.0, -5.0), (30.0, 5.0), (20.0, 5.0)])
K = 24


def scene(ego_after: int | None = None, vehicle_at: dict[int, np.ndarray] | None = None) -> Scans:
    """Target 0 walks along y = 7 at 1 m per scan behind the parked car (hidden at scans 11-13: 3 scans, 4 m between
    last and next sight); target 1 walks along x = 40 at 2.2 m per scan behind the building (hidden at 7-15: 9 scans,
    22 m). The ego stands at the origin (at (-1, 0) from scan ``ego_after`` on); ``vehicle_at``: a vehicle's
    footprint at those scans."""
    truth = np.stack([np.array([[-12.0 + k, 7.0], [40.0, -25.0 + 2.2 * k]]) for k in range(K)])
    scans, visible = [], np.zeros((K, 2), dtype=bool)
    for k in range(K):
        ego = np.array([-1.0 if ego_after is not None and k >= ego_after else 0.0, 0.0, 0.0])
        polys, kinds = [CAR, BUILDING], ["parked", "building"]
        if vehicle_at and k in vehicle_at:
            polys, kinds = [*polys, vehicle_at[k]], [*kinds, "vehicle"]
        occluders = [Polygon(p) for p in polys]
        visible[k] = line_of_sight(ego[:2], truth[k], occluders)
        obstacles = compute_obstacles(polys, kinds, ego[:2], 50.0)
        scans.append(Scan(k, float(k), ego, np.zeros((0, 2)), obstacles, occluders, Polygon()))
    ones = np.ones((K, 2), dtype=bool)
    return Scans(
        scans, 0.5, [np.zeros(0, int)] * K, truth, ones, ones.copy(), visible, visible.copy(), np.array(["a", "b"])
    )


def test_a_3_scan_gap_behind_a_parked_car_and_a_9_scan_gap_behind_a_building():
    scans = scene()
    gaps = occlusion_gaps(scans.present & scans.in_fov, scans.visible)
    assert [(g.target, g.k_a, g.k_b) for g in gaps] == [(0, 11, 13), (1, 7, 15)]
    car, building = describe_gaps(scans, gaps, d_gate=5.0)
    assert (car.scans, car.seconds, car.occluder, car.moved, car.ego_moved) == (3, 1.5, "parked", False, False)
    assert car.displacement == pytest.approx(4.0) and car.ego_displacement == 0.0
    assert (building.scans, building.seconds, building.occluder, building.moved) == (9, 4.5, "building", True)
    assert building.displacement == pytest.approx(22.0)
    # the same gap scored with a wider gate: not moved
    assert not describe_gaps(scans, gaps[1:], d_gate=30.0)[0].moved


def test_the_ego_moving_across_the_gap():
    scans = scene(ego_after=16)  # moves 1 m between scan 6 (before the building gap) and 16 (after it)
    gaps = occlusion_gaps(scans.present & scans.in_fov, scans.visible)
    building = describe_gaps(scans, [g for g in gaps if g.target == 1], 5.0)[0]
    assert building.ego_displacement == pytest.approx(1.0) and building.ego_moved and EGO_MOVED_M < 1.0
    car = describe_gaps(scans, [g for g in gaps if g.target == 0], 5.0)[0]
    assert not car.ego_moved  # the car gap is over before the ego moves


def test_the_nearest_occluder_hides_and_the_longest_hiding_kind_wins():
    """A vehicle passing between the sensor and the parked car hides target 0 first at scans 11 and 12 (nearer
    than the car), the car alone at 13: the vehicle hid it longest. With the vehicle at scan 11 only, the car hides
    it at 12 and 13: the car wins."""
    truck = np.array([(-3.0, 1.5), (3.0, 1.5), (3.0, 2.5), (-3.0, 2.5)])
    scans = scene(vehicle_at={11: truck, 12: truck})
    assert hiding_kind(scans.scans[11], scans.truth_xy[11, 0]) == "vehicle"
    assert hiding_kind(scans.scans[13], scans.truth_xy[13, 0]) == "parked"
    assert hiding_kind(scans.scans[3], scans.truth_xy[3, 0]) == "other"  # nothing on the sight line
    gap = Gap(0, 11, 13)
    assert describe_gaps(scans, [gap], 5.0)[0].occluder == "vehicle"
    once = scene(vehicle_at={11: truck})
    assert describe_gaps(once, [gap], 5.0)[0].occluder == "parked"
    # a tie (one scan each) goes to the kind that hid the target first
    assert describe_gaps(once, [Gap(0, 11, 12)], 5.0)[0].occluder == "vehicle"


def test_the_sight_lines_of_a_scan_tested_together_hide_as_one_by_one():
    """Both targets, a vehicle between the sensor and the car at some scans, points beyond everything and a NaN:
    each scan's points at once give the kind of each point on its own."""
    truck = np.array([(-3.0, 1.5), (3.0, 1.5), (3.0, 2.5), (-3.0, 2.5)])
    scans = scene(vehicle_at={11: truck, 12: truck})
    extra = np.array([[0.0, 60.0], [25.0, 0.0], [np.nan, 1.0], [0.5, 5.0]])
    for k in range(K):
        points = np.vstack([scans.truth_xy[k], extra])
        assert hiding_kinds(scans.scans[k], points) == [hiding_kind(scans.scans[k], xy) for xy in points]
    assert {*hiding_kinds(scans.scans[11], np.vstack([scans.truth_xy[11], extra]))} >= {"vehicle", "building"}


def test_a_runs_episode_rows_carry_the_gap_and_its_outcome():
    """Target 0 is carried through its gap by track 1 (coasted, identity kept); target 1 is dropped during its gap
    and comes back as track 3 (not coasted, identity lost). Entry episodes have empty gap cells."""
    scans = scene()
    X, labels = [], []
    for k in range(K):
        rows, labs = [scans.truth_xy[k, 0] + 0.2], [1]
        if scans.visible[k, 1]:
            rows.append(scans.truth_xy[k, 1] - 0.2)
            labs.append(2 if k < 10 else 3)
        X.append(np.column_stack([np.array(rows), np.zeros((len(rows), 2))]))
        labels.append(np.array(labs))
    cfg = MetricsConfig()
    assoc = np.ones((K, 2), dtype=bool)
    episodes = delay_episodes(scans.visible, scans.detected, assoc, scans.dt)
    columns, gaps = track_evaluation(scans, X, labels, episodes, cfg, SensorConfig())
    assert len(gaps) == len(episodes) and all(list(g) == list(GAP_KEYS) for g in gaps)
    by_start = {(e.target, e.k0): g for e, g in zip(episodes, gaps, strict=True)}
    for entry in (by_start[(0, 0)], by_start[(1, 0)]):
        assert entry["gap_occluder"] is None and all(math.isnan(v) for k, v in entry.items() if k != "gap_occluder")
    car, building = by_start[(0, 14)], by_start[(1, 16)]
    assert (car["gap_scans"], car["gap_occluder"], car["gap_moved"], car["gap_coasted"], car["gap_id_kept"]) == (
        3, "parked", 0, 1, 1)  # fmt: skip
    assert (building["gap_scans"], building["gap_s"], building["gap_occluder"], building["gap_moved"]) == (
        9, 4.5, "building", 1)  # fmt: skip
    assert (building["gap_coasted"], building["gap_id_kept"], building["gap_ego_moved"]) == (0, 0, 0)
    # the run's pooled numbers are these episodes' cells
    assert (columns["n_gaps"], columns["coasted"], columns["n_id"], columns["id_kept"]) == (2, 0.5, 2, 0.5)
    # an unlabelled tracker: the same gaps, no identity
    _, plain = track_evaluation(scans, X, None, episodes, cfg, SensorConfig())
    assert all(math.isnan(g["gap_id_kept"]) for g in plain)
    assert str([g["gap_coasted"] for g in plain]) == str([g["gap_coasted"] for g in gaps])


def test_the_api_describes_the_gaps_of_scans():
    import soabench.api as sb

    gaps = sb.occlusion_gaps(scene(), d_gate=5.0)
    assert [(g["target"], g["k_a"], g["k_b"], g["scans"], g["occluder"], g["moved"]) for g in gaps] == [
        (0, 11, 13, 3, "parked", False), (1, 7, 15, 9, "building", True)]  # fmt: skip
    with pytest.raises(ValueError, match="Scans"):
        sb.occlusion_gaps([1, 2])
