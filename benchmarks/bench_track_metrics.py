"""Track metrics of one filter run: soabench.tracks against TrackEval's own metric classes, on the same sequence.

A synthetic labelled sequence (walkers with noisy estimates, a label change every ``--relabel`` scans, a few misses
and false tracks) is scored by :func:`soabench.tracks.scores.track_scores` (HOTA, CLEAR MOT and IDF1 in one call)
and by TrackEval's ``HOTA``, ``CLEAR`` and ``Identity`` ``eval_sequence`` (the values are checked equal first); the
ratio of their times is printed, with OSPA(2) timed beside them. Two sizes: a 60 s trial at 10 Hz (600 scans, about
10 truths and 10 estimates) and the paper protocol's filter run (100 scans, 6 truths). Last, on a real S-OA filter
run, every track column of a trial row against the §5 metrics of the same run.

    python benchmarks/bench_track_metrics.py --repeat 5
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from trackeval.metrics import CLEAR, HOTA, Identity

from soabench.tracks.ospa2 import ospa2
from soabench.tracks.scores import track_scores
from soabench.tracks.sequence import TrackSequence

D_GATE = 5.0


def sequence(K: int, n: int, relabel: int, seed: int = 0) -> tuple[list, list, list, list]:
    """K scans of n walkers; estimates within about 1 m, 5 % missed, one false track per scan on average."""
    rng = np.random.default_rng(seed)
    pos = rng.uniform(0, 60, (n, 2))
    labels = np.arange(n)
    gt_ids, gt_xy, est_ids, est_xy = [], [], [], []
    for k in range(K):
        pos += rng.normal(0, 0.15, pos.shape)
        if k and k % relabel == 0:
            labels = labels + n
        gt_ids.append(np.arange(n))
        gt_xy.append(pos.copy())
        seen = rng.random(n) > 0.05
        false = rng.poisson(1.0)
        est_ids.append(np.concatenate([labels[seen], 10**6 + k * 10 + np.arange(false)]))
        est_xy.append(np.concatenate([pos[seen] + rng.normal(0, 1.0, (seen.sum(), 2)), rng.uniform(0, 60, (false, 2))]))
    return gt_ids, gt_xy, est_ids, est_xy


def best_of(f, repeat: int) -> float:
    """Smallest wall time of ``repeat`` calls (s)."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return min(times)


def measure(K: int, n: int, relabel: int, repeat: int) -> None:
    args = sequence(K, n, relabel)
    quiet = {"THRESHOLD": 0.5, "PRINT_CONFIG": False}
    metrics = (HOTA(), CLEAR(dict(quiet)), Identity(dict(quiet)))

    def trackeval():
        data = TrackSequence.of(*args).trackeval_data(D_GATE)
        return [m.eval_sequence(data) for m in metrics]

    ours = track_scores(*args, D_GATE)
    ref = trackeval()
    assert abs(ours.hota - float(np.mean(ref[0]["HOTA"]))) < 1e-12 and ours.idsw == ref[1]["IDSW"]
    t_ours = best_of(lambda: track_scores(*args, D_GATE), repeat)
    t_ref = best_of(trackeval, repeat)
    t_ospa2 = best_of(lambda: ospa2(*args), repeat)
    print(
        f"{K} scans x {n} truths: TrackEval (HOTA + CLEAR + Identity) / soabench.tracks = {t_ref / t_ours:.1f}x; "
        f"OSPA(2) / soabench.tracks scores = {t_ospa2 / t_ours:.2f}x  (HOTA {ours.hota:.3f}, IDSW {ours.idsw})"
    )


def filter_run(duration: float, repeat: int) -> None:
    """One S-OA filter run of trial 0 (intersection): :func:`soabench.tracks.evaluate.evaluate_tracks` (every
    track column) against :func:`soabench.metrics.evaluate` (the §5 metrics of the same run). The estimates are
    labelled by their nearest pedestrian (a stand-in for a labelled filter's tags: the cost does not depend on
    which labels they are)."""
    from soabench import api
    from soabench.config import Config
    from soabench.metrics import evaluate, pairwise_distances
    from soabench.tracks.evaluate import evaluate_tracks

    cfg = Config()
    _, scans = api.simulate_trial("intersection", duration=duration)
    tracker = api.make_tracker("soa", "intersection")
    results = [tracker.step(scan) for scan in scans]
    X = [r.X for r in results]
    labels = []
    for k, x in enumerate(X):
        near = np.argmin(pairwise_distances(x[:, :2], np.nan_to_num(scans.truth_xy[k], nan=1e9)), axis=1)
        again = np.array([np.sum(near[:i] == near[i]) for i in range(len(near))], dtype=np.int64)
        labels.append(near + 10_000 * again)  # two estimates near one pedestrian: the second a track of its own
    metrics = evaluate(scans, results, cfg.metrics, cfg.sensor_at())
    evaluate_tracks(scans, X, labels, metrics.episodes, cfg.metrics, cfg.sensor_at())  # compiled kernels loaded
    t5 = best_of(lambda: evaluate(scans, results, cfg.metrics, cfg.sensor_at()), repeat)
    t9 = best_of(lambda: evaluate_tracks(scans, X, labels, metrics.episodes, cfg.metrics, cfg.sensor_at()), repeat)
    print(f"S-OA filter run of {len(X)} scans: track columns / §5 metrics of the same run = {t9 / t5:.2f}x")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=5)
    a = p.parse_args(argv)
    measure(600, 10, 60, a.repeat)
    measure(100, 6, 30, a.repeat)
    filter_run(100.0, a.repeat)


if __name__ == "__main__":
    main()
