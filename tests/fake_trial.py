"""A fast, deterministic stand-in for ``soabench.experiment.trial.trial.run_trial`` (same TrialResult schema).

Module-level functions so worker processes (process pool, Dask) can import them. Numbers depend only on
``(config.experiment.seed, trial)`` and the (clutter, model, mode) indices; the ``t_*`` timing columns are real
wall-clock measurements, so they differ between runs (as the real ones do).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from soabench.errors import SoabenchError
from soabench.experiment.trial.trial import FILTER_COLUMN, family_runs
from soabench.seeding import trial_seeds

FAIL_TRIALS = frozenset({2})
#: per-model delay scale: ATBM fastest, GMBM slowest (the paper's ordering, §5.9)
DELAY_SCALE = {"atbm": 0.5, "soa": 1.0, "pubm": 1.3, "ubm": 2.0, "ubm-ws": 2.5, "gmbm": 6.0}
#: per-model false-alarm rate growth with clutter
FP_RATE = {"atbm": 0.15, "soa": 0.01, "pubm": 0.03, "ubm": 0.05, "ubm-ws": 0.04, "gmbm": 0.02}


@dataclass
class FakeTrialResult:
    rows: list[dict]
    episodes: list[dict]
    steps: list[dict]
    timing: dict
    estimates: list[dict] | None = None
    extra: dict = field(default_factory=dict)


def fake_load(net, polys=(), scenario=None):
    """Stand-in for ``soabench.scenario.load``."""
    if net == "no-such-net":
        raise SoabenchError(f"network {net!r} not found")
    return f"scene:{net}", {"name": str(net), "duration": 100.0}


def fake_trial(trial, config, scene, scenario, *, save_estimates=False):
    t0 = time.perf_counter()
    exp = config.experiment
    seeds = trial_seeds(exp.seed, trial)
    truth = np.random.default_rng(seeds.scenario)
    K = int(round(exp.duration / config.sensor.dt))
    n_targets = 4
    present = truth.random((K, n_targets)) < 0.7
    n_gt = present.sum(axis=1)
    vis_runs = []  # (target, k0, k_d, end)
    for i in range(n_targets):
        k = 0
        while k < K:
            if present[k, i]:
                k0 = k
                while k < K and present[k, i]:
                    k += 1
                vis_runs.append((i, k0, min(k0 + int(truth.integers(0, 2)), k - 1), k - 1))
            k += 1
    t_sumo = time.perf_counter() - t0
    rows, episodes, steps, estimates = [], [], [], []
    for ci, lam in enumerate(exp.clutter):
        for mi, model in enumerate(exp.models):
            for pi, (mode, fam) in enumerate(family_runs(exp.probabilities, exp.filters)):
                n0 = (len(rows), len(episodes), len(steps))
                t1 = time.perf_counter()
                rng = np.random.default_rng([exp.seed, trial, ci, mi, pi, 7])
                scale = DELAY_SCALE[model] * (0.9 if mode == "dynamic" else 1.0)
                scale *= (0.06 / max(config.birth.N_hat, 1e-3)) ** 0.3  # fewer expected births: later tracks
                delays, n_cens = [], 0
                for i, k0, kd, end in vis_runs:
                    d = int(rng.geometric(1.0 / (1.0 + scale))) - 1
                    kt = kd + d
                    censored = kt > end
                    n_cens += int(censored)
                    if not censored:
                        delays.append(float(d) * config.sensor.dt)
                    episodes.append(
                        {
                            "trial": trial,
                            "clutter": float(lam),
                            "model": model,
                            "mode": mode,
                            "target": f"ped{i}",
                            "k0": k0,
                            "k_end": end,
                            "k_d": kd,
                            "k_t": -1 if censored else kt,
                            "delay": float("nan") if censored else float(d) * config.sensor.dt,
                            "delay_lb": float(min(d, end - kd + 1)) * config.sensor.dt,
                            "censored": bool(censored),
                        }
                    )
                fp = rng.poisson(FP_RATE[model] * (1.0 + lam), K)
                fn = np.minimum(n_gt, rng.binomial(n_gt, 0.1 * DELAY_SCALE[model] / 6.0))
                tp = n_gt - fn
                n_est = tp + fp
                card = np.abs(n_est - n_gt).astype(float)
                loc = rng.random(K)
                nmax = np.maximum(n_est, n_gt)
                ospa = np.where(nmax > 0, (tp * loc + 100.0 * np.abs(n_est - n_gt)) / np.maximum(nmax, 1), 0.0)
                sum_w = n_est + rng.normal(0.0, 0.2, K)
                comps = rng.integers(10, 50, K) * (1 + 4 * (model == "ubm"))
                for k in range(K):
                    steps.append(
                        {
                            "trial": trial,
                            "clutter": float(lam),
                            "model": model,
                            "mode": mode,
                            "k": k,
                            "n_gt": int(n_gt[k]),
                            "n_est": int(n_est[k]),
                            "tp": int(tp[k]),
                            "fp": int(fp[k]),
                            "fn": int(fn[k]),
                            "ospa": float(ospa[k]),
                            "gospa": float(ospa[k] / 10),
                            "card_err": float(card[k]),
                            "sum_w": float(sum_w[k]),
                            "n_components": int(comps[k]),
                        }
                    )
                    if save_estimates:
                        estimates.append(
                            {"clutter": float(lam), "model": model, "mode": mode, "k": k, "xy": rng.random((2, 2))}
                        )
                dl = np.array(delays)
                dlb = np.array(delays + [float(end - kd + 1) for i, k0, kd, end in vis_runs][:n_cens])
                s_tp, s_fp = int(tp.sum()), int(fp.sum())
                t_filter = time.perf_counter() - t1
                rows.append(
                    {
                        "trial": trial,
                        "seed": exp.seed,
                        "sumo_seed": seeds.sumo_seed,
                        "clutter": float(lam),
                        "N_hat": config.birth.N_hat,
                        "model": model,
                        "mode": mode,
                        "delay_mean": float(dl.mean()) if dl.size else float("nan"),
                        "delay_std": float(dl.std()) if dl.size else float("nan"),
                        "delay_mean_lb": float(dlb.mean()) if dlb.size else float("nan"),
                        "n_episodes": len(vis_runs),
                        "n_censored": n_cens,
                        "card_err": float(card.mean()),
                        "card_err_sumw": float(np.abs(sum_w - n_gt).mean()),
                        "ospa": float(ospa.mean()),
                        "ospa_loc": float(loc.mean()),
                        "ospa_card": float(ospa.mean() - loc.mean()),
                        "gospa": float(ospa.mean() / 10),
                        "precision": s_tp / (s_tp + s_fp) if s_tp + s_fp else float("nan"),
                        "recall": s_tp / int(n_gt.sum()) if n_gt.sum() else float("nan"),
                        "tp": s_tp,
                        "fp": s_fp,
                        "fn": int(fn.sum()),
                        "mean_components": float(comps.mean()),
                        "max_components": int(comps.max()),
                        "cap_hits": 0,
                        "mean_pD": 0.98,
                        "t_birth": 0.1 * t_filter,
                        "t_predict": 0.2 * t_filter,
                        "t_update": 0.5 * t_filter,
                        "t_reduce": 0.1 * t_filter,
                        "t_metrics": 0.1 * t_filter,
                        "t_filter_total": t_filter,
                    }
                )
                if fam is not None:  # a run naming filter families: the family as every table's last column
                    for d in (*rows[n0[0] :], *episodes[n0[1] :], *steps[n0[2] :]):
                        d[FILTER_COLUMN] = fam
    timing = {"sumo": t_sumo, "sensor": 0.5 * t_sumo}
    return FakeTrialResult(rows, episodes, steps, timing, estimates if save_estimates else None)


def slow_trial(trial, config, scene, scenario, *, save_estimates=False):
    """``fake_trial`` after a short sleep (for the kill-and-resume test)."""
    time.sleep(0.3)
    return fake_trial(trial, config, scene, scenario, save_estimates=save_estimates)


def failing_trial(trial, config, scene, scenario, *, save_estimates=False):
    """``fake_trial``, except that the trials in ``FAIL_TRIALS`` raise."""
    if trial in FAIL_TRIALS:
        raise RuntimeError(f"forced failure of trial {trial}")
    return fake_trial(trial, config, scene, scenario, save_estimates=save_estimates)


def crashing_trial(trial, config, scene, scenario, *, save_estimates=False):
    """``fake_trial``, except that trial 3 kills its worker process (only ever inside a child process)."""
    import multiprocessing
    import os

    if trial == 3 and multiprocessing.parent_process() is not None:
        os._exit(13)
    time.sleep(0.05)
    return fake_trial(trial, config, scene, scenario, save_estimates=save_estimates)


# the fakes are registered trial kinds / scene loaders, so a run made with them can be resumed by name (a run
# folder names what it needs; it never spells out an import path)
from soabench.experiment.trial import registry  # noqa: E402
from soabench.experiment.trial.registry import register_scene_loader, register_trial_kind  # noqa: E402


def small_config(**experiment):
    """The default configuration with ``experiment``'s keys replaced in its ``[experiment]`` table, validated."""
    import dataclasses

    from soabench.config import Config

    cfg = Config()
    cfg.experiment = dataclasses.replace(cfg.experiment, **experiment)
    return cfg.validate()


def run_fake(config, out, net="intersection", **kw):
    """:func:`soabench.experiment.reports.finished.run_experiment` of ``config`` on ``net`` with :func:`fake_trial` and
    :func:`fake_load`, serial, without progress or figures (``kw`` overrides any of these): the fake run the tests
    share. Returns the run's outcome."""
    from soabench.experiment.execution.options import RunOptions
    from soabench.experiment.reports.finished import run_experiment

    fields = {f.name for f in dataclasses.fields(RunOptions)}
    options = dict(workers=1, progress=False, figures=False) | {k: v for k, v in kw.items() if k in fields}
    rest = dict(trial_fn=fake_trial, load_fn=fake_load) | {k: v for k, v in kw.items() if k not in fields}
    return run_experiment(config, net, out=out, options=RunOptions(**options), **rest)


def as_builtins(trial=fake_trial, loader=fake_load):
    """A block in which the built-in trial kind and scene loader (the names ``soabench run`` uses) are ``trial`` and
    ``loader`` (None: that one stays the real one), through the public hook :func:`registry.registered`."""
    return registry.registered(
        {registry.DEFAULT_TRIAL_KIND: trial} if trial is not None else None,
        {registry.DEFAULT_SCENE_LOADER: loader} if loader is not None else None,
    )


register_scene_loader("fake-load", fake_load)
for _name, _fn in (
    ("fake", fake_trial),
    ("fake-slow", slow_trial),
    ("fake-failing", failing_trial),
    ("fake-crashing", crashing_trial),
):
    register_trial_kind(_name, _fn)


def renumbered(record: dict, trial: int) -> dict:
    """A copy of a trial record as trial ``trial``'s: its ``trial`` and the trial cell of every packed table."""
    import json

    out = json.loads(json.dumps(record))
    out["trial"] = trial
    for name in ("rows", "episodes", "steps"):
        table = out.get(name)
        if table:
            j = table["columns"].index("trial")
            for row in table["rows"]:
                row[j] = trial
    return out
