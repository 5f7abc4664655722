"""Speed and agreement of the soabench GM-PHD filter against Stone Soup 1.9 (plain script, not a test).

    python benchmarks/bench_filter_vs_stonesoup.py [--quick]

Identical inputs go to both implementations: J prior components (already predicted) and M range-bearing
measurements relative to one ego pose, for J in {50, 200, 1000} and M in {5, 20}.

Agreement tolerance: weights 1e-5 relative, means 1e-5 m, because Stone Soup's EKF linearises with a
finite-difference Jacobian (``compute_jac``) where ours is analytic; the component sets must be identical (same
gate, same (j, l) pairs).

* soabench, two paths: the array path ``update`` (EKF, log domain, chi-square gate 13.8155) plus
  ``prune_merge_cap`` (Vo & Ma: T = 1e-5, U = 4, J_max = 1000), whose inner loops are compiled kernels
  (``soabench/gmphd/kernels.py``) called from numpy code; and the fused cycle, ``GMPHDFilter.step`` with
  ``fused=True`` (``soabench/gmphd/cycle.py``), given F = I, Q = 0 and p_S = 1 so that it does what Stone Soup does
  here (plus its FOV gate and state extraction), checked against the array path to 1e-12 before timing. The
  agreement checks run first, so compilation (or loading the cached machine code) is never inside a timed call.
* Stone Soup: ``GaussianMixtureHypothesiser`` over a ``DistanceHypothesiser`` (``SquaredMahalanobis`` measure,
  missed_distance = 13.8155, a ``KalmanPredictor`` that is the identity because the components and detections
  share one timestamp), ``ExtendedKalmanUpdater`` with ``CartesianToBearingRange`` (state order [x, vx, y, vy],
  measurement order (bearing, range)), ``PHDUpdater`` (p_S = 1 so it does not re-apply survival), and
  ``GaussianMixtureReducer`` (prune 1e-5, merge 4, at most 1000 components).

Agreement is checked on the updated mixtures before reduction (same components, weights and means). Stone Soup's
known departures from Vo & Ma (why the reduced mixtures are not compared):

* its merge caps a merged weight at 1 (``if weight_sum > 1: weight_sum = 1``);
* pruning (and truncation) hands the removed weight back to the remaining components;
* merging is pairwise and sequential: later candidates are tested against the already-merged component, with a
  strict ``<`` threshold;
* components tagged "birth" get no missed-detection term (a birth-intensity convention, not Vo & Ma's);
* q is ``multivariate_normal.pdf`` on the raw (bearing, range) difference: the bearing innovation is not wrapped
  (inputs here keep every bearing within +-89 deg of the heading, so no raw bearing difference reaches pi and
  this does not matter; with bearings all round, a wide component near the ego showed a 12x weight difference).
"""

from __future__ import annotations

import argparse
import datetime
import math
import sys
import time

import numpy as np

from soabench.geometry import wrap
from soabench.gmphd import GMPHDFilter, Mixture
from soabench.gmphd.models import GATE_999, cv_model, h, measurement_noise, predict, update
from soabench.gmphd.reduction import prune_merge_cap

P_D = 0.98
KAPPA = 3.0 / (49.5 * 2 * math.pi)  # lambda = 3 over [0.5, 50] m x 2 pi
SIGMA_B = math.radians(5.0)
R = measurement_noise(1.0, SIGMA_B)
EGO = np.array([3.0, -2.0, 0.4])
SS_ORDER = [0, 2, 1, 3]  # ours [x, y, vx, vy] -> Stone Soup [x, vx, y, vy]


def make_inputs(J: int, M: int, seed: int) -> tuple[Mixture, np.ndarray]:
    """A filter-like predicted mixture: means in the FOV (bearings within +-86 deg of the heading), velocities
    N(0, 1), covariances F blkdiag(s^2 I, I) F^T + Q with s in [0.5, 2.5] m (predicted birth components),
    weights log-uniform in [1e-4, 1]; M measurements: 70 % from random components (h(m) + noise), 30 % clutter."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(2.0, 48.0, J)
    b = rng.uniform(-1.5, 1.5, J) + EGO[2]
    m = np.column_stack([EGO[0] + r * np.cos(b), EGO[1] + r * np.sin(b), rng.normal(0.0, 1.0, (J, 2))])
    F, Q = cv_model(1.0, 0.5)
    s = rng.uniform(0.5, 2.5, J)
    P0 = np.zeros((J, 4, 4))
    P0[:, 0, 0] = P0[:, 1, 1] = s**2
    P0[:, 2, 2] = P0[:, 3, 3] = 1.0
    P = F @ P0 @ F.T + Q
    w = 10.0 ** rng.uniform(-4.0, 0.0, J)
    n_t = int(round(0.7 * M))
    idx = rng.choice(J, n_t, replace=False)
    z_t = h(m[idx], EGO) + rng.normal(0.0, [1.0, SIGMA_B], (n_t, 2))
    z_c = np.column_stack([rng.uniform(0.5, 50.0, M - n_t), rng.uniform(-1.55, 1.55, M - n_t)])
    Z = np.vstack([z_t, z_c])
    Z[:, 1] = wrap(Z[:, 1])
    return Mixture.from_arrays(w, m, P), Z


# ---------------------------------------------------------------------------------------------------------------------
# Stone Soup side


def stonesoup_setup(mix: Mixture, Z: np.ndarray):
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.gaussianmixture import GaussianMixtureHypothesiser
    from stonesoup.measures import SquaredMahalanobis
    from stonesoup.mixturereducer.gaussianmixture import GaussianMixtureReducer
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.angle import Bearing
    from stonesoup.types.array import CovarianceMatrix, StateVector
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import TaggedWeightedGaussianState
    from stonesoup.updater.kalman import ExtendedKalmanUpdater
    from stonesoup.updater.pointprocess import PHDUpdater

    t0 = datetime.datetime(2026, 1, 1)
    model = CartesianToBearingRange(
        ndim_state=4,
        mapping=(0, 2),
        noise_covar=np.diag([SIGMA_B**2, 1.0]),  # (bearing, range) order
        translation_offset=StateVector([EGO[0], EGO[1]]),
        rotation_offset=StateVector([0.0, 0.0, EGO[2]]),
    )
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.25), ConstantVelocity(0.25)])
    predictor = KalmanPredictor(transition)
    ekf = ExtendedKalmanUpdater(model)
    hyp = GaussianMixtureHypothesiser(
        DistanceHypothesiser(predictor, ekf, SquaredMahalanobis(state_covar_inv_cache_size=None), GATE_999),
        order_by_detection=True,
    )
    phd = PHDUpdater(ekf, clutter_spatial_density=KAPPA, prob_detection=P_D, prob_survival=1.0)
    reducer = GaussianMixtureReducer(prune_threshold=1e-5, merge_threshold=4.0, max_number_components=1000)
    comps = [
        TaggedWeightedGaussianState(
            StateVector(mix.m[j, SS_ORDER]),
            CovarianceMatrix(mix.P[j][np.ix_(SS_ORDER, SS_ORDER)]),
            weight=float(mix.w[j]),
            tag=f"c{j}",
            timestamp=t0,
        )
        for j in range(len(mix))
    ]
    dets = {Detection(StateVector([Bearing(z[1]), z[0]]), timestamp=t0, measurement_model=model) for z in Z}
    # check the model convention once: h(x) in (bearing, range) order equals ours
    if len(mix):
        zz = model.function(comps[0])
        ours = h(mix.m[:1], EGO)[0]
        assert abs(float(zz[0]) - ours[1]) < 1e-12 and abs(float(zz[1]) - ours[0]) < 1e-12, (zz, ours)
    return dict(comps=comps, dets=dets, t0=t0, hyp=hyp, phd=phd, reducer=reducer)


def stonesoup_update(ss: dict) -> list:
    hypotheses = ss["hyp"].hypothesise(ss["comps"], ss["dets"], ss["t0"])
    return list(ss["phd"].update(hypotheses))


def stonesoup_reduce(ss: dict, comps: list) -> list:
    return ss["reducer"].reduce(comps)


def ss_arrays(comps: list) -> tuple[np.ndarray, np.ndarray]:
    w = np.array([float(c.weight) for c in comps])
    m = np.array([np.asarray(c.state_vector, dtype=float).ravel()[[0, 2, 1, 3]] for c in comps])
    return w, m.reshape(-1, 4)


def compare(mix: Mixture, Z: np.ndarray, ss_comps: list) -> tuple[int, int, float, float]:
    """Component-by-component comparison of the updated mixtures (before reduction).

    Each Stone Soup component is tagged with its prior component j (missed-detection terms come last, in prior
    order); ours are traced to j through the ``age`` field (set to j on input). Detection terms of the same j are
    matched by nearest mean. Returns (n ours, n Stone Soup, max relative weight error, max |mean| error).
    """
    tagged = Mixture(mix.w, mix.m, mix.P, mix.origin, mix.n_det, np.arange(len(mix), dtype=np.int32))
    ours = update(tagged, Z, EGO, P_D, KAPPA, R).mix
    w_s, m_s = ss_arrays(ss_comps)
    J = len(mix)
    if len(ours) != len(ss_comps):
        return len(ours), len(ss_comps), math.inf, math.inf
    rel_w, err_m = [], []
    # missed-detection terms: the last J Stone Soup components, ours first J
    rel_w.append(np.abs(ours.w[:J] - w_s[-J:]) / w_s[-J:])
    err_m.append(np.abs(ours.m[:J] - m_s[-J:]).max(axis=1))
    det = np.arange(J, len(ours))
    for i, c in enumerate(ss_comps[: len(ss_comps) - J]):
        j = int(c.tag[1:])
        cand = det[ours.age[det] == j]
        if not len(cand):
            return len(ours), len(ss_comps), math.inf, math.inf
        d = np.abs(ours.m[cand] - m_s[i]).max(axis=1)
        k = cand[d.argmin()]
        rel_w.append(np.array([abs(ours.w[k] - w_s[i]) / w_s[i]]))
        err_m.append(np.array([d.min()]))
    return len(ours), len(ss_comps), float(np.concatenate(rel_w).max()), float(np.concatenate(err_m).max())


# ---------------------------------------------------------------------------------------------------------------------
# timing


def best_of(fn, n: int) -> float:
    best = math.inf
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def ss_reps(J: int, M: int, quick: bool) -> int:
    """Smallest rep count that gave stable timings (Stone Soup is slow): more reps for the small cases."""
    if quick:
        return 1
    return 3 if J * M <= 1000 else (2 if J * M <= 4000 else 1)


def fused_update_reduce(mix: Mixture, Z: np.ndarray):
    """``GMPHDFilter.step`` (fused) from ``mix`` with F = I, Q = 0, p_S = 1: update, reduce and extract only."""
    from shapely.geometry import Polygon

    from soabench.config import FilterConfig, Sensor
    from soabench.types import Births, Scan

    filt = GMPHDFilter(FilterConfig(p_S=1.0, p_D=P_D), Sensor())
    filt.F, filt.Q = np.eye(4), np.zeros((4, 4))  # Stone Soup's side: components and detections share a timestamp
    scan = Scan(1, 1.0, EGO, Z, None, [], Polygon())
    births = Births.empty()

    def step():
        filt.mixture = mix
        return filt.step(scan, births)

    step.filt = filt
    return step


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one Stone Soup rep, J in {50, 200} only")
    ap.add_argument("--reps", type=int, default=30, help="best-of reps for soabench")
    args = ap.parse_args()
    Js = (50, 200) if args.quick else (50, 200, 1000)
    Ms = (5, 20)
    W_TOL, M_TOL = 1e-5, 1e-5  # Stone Soup's EKF uses a finite-difference Jacobian (compute_jac)
    F, Q = cv_model(1.0, 0.5)
    rows = []
    ok_all = True
    for J in Js:
        for M in Ms:
            mix, Z = make_inputs(J, M, seed=1000 * J + M)
            # agreement before reduction
            t_ss_u = math.inf
            t_ss_ur = math.inf
            cmp = None
            for _ in range(ss_reps(J, M, args.quick)):
                ss = stonesoup_setup(mix, Z)  # fresh objects: the reducer mutates weights in place
                t0 = time.perf_counter()
                ss_comps = stonesoup_update(ss)
                t1 = time.perf_counter()
                if cmp is None:  # before the reducer, which mutates weights and tags in place
                    cmp = compare(mix, Z, ss_comps)
                ss_red = stonesoup_reduce(ss, list(ss_comps))
                t2 = time.perf_counter()
                t_ss_u = min(t_ss_u, t1 - t0)
                t_ss_ur = min(t_ss_ur, t2 - t0)
            n_o, n_s, rel_w, err_m = cmp
            agree = n_o == n_s and rel_w <= W_TOL and err_m <= M_TOL
            ok_all &= agree
            t_u = best_of(lambda mix=mix, Z=Z: update(mix, Z, EGO, P_D, KAPPA, R), args.reps)

            def upd_red(mix=mix, Z=Z):
                return prune_merge_cap(update(mix, Z, EGO, P_D, KAPPA, R).mix, 1e-5, 4.0, 1000)

            t_ur = best_of(upd_red, args.reps)

            def full(mix=mix, Z=Z):
                pred = predict(mix, F, Q, 0.99)
                return prune_merge_cap(update(pred, Z, EGO, P_D, KAPPA, R).mix, 1e-5, 4.0, 1000)

            t_full = best_of(full, args.reps)
            red = upd_red()
            fused_step = fused_update_reduce(mix, Z)
            fused_step()
            fm = fused_step.filt.mixture
            same = len(fm) == len(red.mix) and all(
                np.allclose(getattr(fm, f), getattr(red.mix, f), rtol=1e-12, atol=1e-12) for f in ("w", "m", "P")
            )
            if not same:
                print(f"J={J} M={M}: fused step and array path DIFFER", flush=True)
            ok_all &= same
            t_fused = best_of(fused_step, args.reps)
            rows.append(
                (J, M, n_o, len(red.mix), len(ss_red), rel_w, err_m, agree, t_u, t_ss_u, t_ur, t_ss_ur, t_full, t_fused)
            )
            print(
                f"J={J:5d} M={M:3d}: posterior {n_o} (Stone Soup {n_s}), max rel dw {rel_w:.1e}, max |dm| {err_m:.1e}"
                f" -> {'agree' if agree else 'DISAGREE'}; update {t_u * 1e3:.2f} ms vs {t_ss_u * 1e3:.0f} ms",
                flush=True,
            )

    # one full filter step through the public API (predict + update + reduce + extract), J = 1000, M = 20
    step_ms = math.nan
    if not args.quick:
        from shapely.geometry import Polygon

        from soabench.config import FilterConfig, Sensor
        from soabench.types import Births, Scan

        mix, Z = make_inputs(1000, 20, seed=7)
        filt = GMPHDFilter(FilterConfig(), Sensor())
        scan = Scan(1, 1.0, EGO, Z, None, [], Polygon())

        def step():
            filt.mixture = mix
            return filt.step(scan, Births.empty())

        step_ms = best_of(step, args.reps) * 1e3

    print()
    print(
        f"agreement before reduction: weights rel <= {W_TOL:g}, means abs <= {M_TOL:g} m -> "
        f"{'all agree' if ok_all else 'SOME DISAGREE'}"
    )
    print()
    hdr = (
        "|    J |  M | post | reduced (ours/SS) | upd+red SS ms | upd+red array ms | ratio |"
        " fused step us | ratio | array step ms |"
    )
    print(hdr)
    print("|" + "|".join("-" * (len(c)) for c in hdr.split("|")[1:-1]) + "|")
    for J, M, n_o, n_r, n_rs, _rw, _em, _ag, _t_u, _t_ss_u, t_ur, t_ss_ur, t_full, t_fused in rows:
        print(
            f"| {J:4d} | {M:2d} | {n_o:4d} | {n_r:7d} / {n_rs:7d} | {t_ss_ur * 1e3:13.0f} | {t_ur * 1e3:16.2f} |"
            f" {t_ss_ur / t_ur:5.0f} | {t_fused * 1e6:13.1f} | {t_ss_ur / t_fused:5.0f} | {t_full * 1e3:13.2f} |"
        )
    if not math.isnan(step_ms):
        print(f"\nGMPHDFilter.step, J = 1000, M = 20 (predict + update + reduce + extract): {step_ms:.2f} ms")
    worst = min(r[11] / r[10] for r in rows)
    worst_fused = min(r[11] / r[13] for r in rows)
    print(f"smallest speed ratio, array path: {worst:.0f}x; fused step: {worst_fused:.0f}x (target >= 1000x)")
    return 0 if ok_all else 1


if __name__ == "__main__":
    sys.exit(main())
