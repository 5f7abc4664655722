"""Every figure function renders a reviewer-grade PNG: a non-empty file, labelled axes with units, a legend where
the figure needs one, and the defects these tests guard against absent (no ±σ below 0 s, shared y-ranges, the OSPA
cut-off, all models in Fig. 5h, dashed "dynamic" in the clutter legend, holes of map polygons left open).

Synthetic run tables (two clutter rates, three models including a plugin name, two modes, six trials) keep
these tests fast; nothing here runs SUMO.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.collections import LineCollection
from matplotlib.colors import to_rgb
from shapely.geometry import Point, Polygon, box

from soabench.experiment.reports.tables import RunTables
from soabench.figures import results as plots
from soabench.figures import style as ps
from soabench.figures.origins import components_origin_figure, fig_components_origin
from soabench.figures.sweeps import births_figure, clutter_figure
from soabench.origins import ORIGIN_KEYS

MODELS = ("soa", "atbm", "myplugin")
MODES = ("static", "dynamic")
CLUTTERS = (0.5, 3.0)
N_TRIALS, N_STEPS = 6, 12
STEP_BASE = ("trial", "clutter", "model", "mode", "k", "tp", "fp", "n_components")


def _origin_split(model: str, n: int) -> dict[str, int]:
    """A made-up split of ``n`` posterior components by origin: S-OA 3 occlusion + 2 semantic newborns, ATBM one
    measurement-driven newborn, the rest surviving; the plugin's components have no source."""
    c = dict.fromkeys(ORIGIN_KEYS, 0)
    if model == "soa":
        c.update(n_born_occl=3, n_born_sem=2, n_surv_occl=n - 5)
    elif model == "atbm":
        c.update(n_born_meas=1, n_surv_meas=n - 1)
    else:
        c.update(n_unsourced=n)
    return c


def _run_tables() -> RunTables:
    """Per-trial, per-step and per-episode tables of a small made-up run (deterministic)."""
    rng = np.random.default_rng(1)
    trials: dict[str, list] = {c: [] for c in ("trial", "clutter", "model", "mode", "delay_mean", "delay_std",
                                              "card_err", "ospa", "precision", "mean_components")}  # fmt: skip
    steps: dict[str, list] = {c: [] for c in (*STEP_BASE, *ORIGIN_KEYS)}
    episodes: dict[str, list] = {c: [] for c in ("trial", "clutter", "model", "mode", "delay", "censored")}
    for lam in CLUTTERS:
        for model in MODELS:
            for mode in MODES:
                for tr in range(N_TRIALS):
                    # atbm: small mean delay with a large spread, so a ±0.5σ band would reach below 0 s;
                    # myplugin: a long tail (20 s) that forces the shared delay axis to be non-linear above
                    mean = {"soa": 1.2, "atbm": 0.3, "myplugin": 20.0 if tr == 0 else 1.5}[model]
                    row = dict(trial=tr, clutter=lam, model=model, mode=mode, delay_mean=mean,
                               delay_std=2.0 if model == "atbm" else 0.4, card_err=1.0 + rng.random(),
                               ospa=30 + 10 * rng.random(), precision=rng.uniform(0.5, 1.0),
                               mean_components=20 + 2 * tr)  # fmt: skip
                    for c, v in row.items():
                        trials[c].append(v)
                    for k in range(N_STEPS):
                        for c, v in zip(STEP_BASE, (tr, lam, model, mode, k, 1, k % 2, 10 + k), strict=True):
                            steps[c].append(v)
                        for c, v in _origin_split(model, 10 + k).items():  # n_components by origin (Fig. 7b)
                            steps[c].append(v)
                    for d in (0.0, 1.0, 2.0, 14.0):
                        for c, v in zip(episodes, (tr, lam, model, mode, d, 0), strict=True):
                            episodes[c].append(v)

    def arrays(t: dict) -> dict:
        return {c: np.array(v, dtype=object if c in ("model", "mode") else float) for c, v in t.items()}

    meta = {
        "config": {
            "experiment": {"models": list(MODELS), "probabilities": list(MODES)},
            "sensor": {"dt": 1.0},
            "metrics": {"ospa_c": 100.0, "ospa_p": 1.0},
        }
    }
    t = arrays(trials)
    for c in ("model", "mode"):
        t[c] = t[c].astype(str)
    s, e = arrays(steps), arrays(episodes)
    for d in (s, e):
        for c in ("model", "mode"):
            d[c] = d[c].astype(str)
    return RunTables(trials=t, episodes=e, steps=s, timing={}, meta=meta)


@pytest.fixture(scope="module")
def tables() -> RunTables:
    return _run_tables()


def _legend_labels(fig) -> list[str]:
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    return [t.get_text() for leg in legends for t in leg.get_texts()]


def _rendered(fig, tmp_path, name: str) -> None:
    """The figure writes a non-empty PNG, every x axis is labelled, a y label names its unit (or is a count or
    a ratio), panel titles are unique "(a) ..." style and models go by their display names."""
    path = ps.save_png(fig, tmp_path / f"{name}.png")
    assert path.stat().st_size > 5_000
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    data_axes = [ax for ax in fig.axes if ax.has_data()]
    assert data_axes
    for ax in data_axes:  # a panel's x axis is labelled on itself or on a panel sharing it (the bottom row)
        siblings = ax.get_shared_x_axes().get_siblings(ax)
        assert any(a.get_xlabel() for a in siblings) or ax.get_xticklabels(), f"{name}: an unlabelled x axis"
    dimensionless = (
        "share of counted episodes",
        "cumulative precision",
        "precision per trial",
        "posterior components J",
        "components J",
    )
    ylabels = [ax.get_ylabel() for ax in data_axes]
    assert any("(" in y or y in dimensionless for y in ylabels), f"{name}: no y label with a unit in {ylabels}"
    titles = [ax.get_title(loc="left") for ax in fig.axes if ax.get_title(loc="left")]
    assert len(titles) == len(set(titles)), f"{name}: duplicate panel titles {titles}"
    assert not any(t.startswith("Fig.") for t in titles)
    assert not any("soa" in t.split() for t in titles + _legend_labels(fig))


def test_plotstyle_models_modes_and_titles():
    assert [ps.model_label(m) for m in ("soa", "pubm", "ubm", "ubm-ws", "atbm", "gmbm")] == [
        "S-OA",
        "PUBM",
        "UBM (FOV)",
        "UBM (workspace)",
        "ATBM",
        "GMBM",
    ]
    assert ps.model_label("myplugin") == "myplugin"
    assert ps.model_style("myplugin") == ps.model_style("myplugin")  # stable across calls
    assert len({ps.model_style(m).color for m in ("soa", "pubm", "ubm", "ubm-ws", "atbm", "gmbm")}) == 6
    assert ps.mode_style("static").linestyle == "-" and ps.mode_style("dynamic").linestyle == "--"
    with ps.style():
        fig = ps.figure("single", 2.0)
        ax = fig.add_subplot()
        ps.panel_title(ax, "a", "delay")
    assert ax.get_title(loc="left") == "(a) delay"
    assert fig.get_size_inches()[0] == pytest.approx(ps.SINGLE)


def test_fig5_delay_markers_no_band_below_zero_and_shared_range(tables, tmp_path):
    limits = plots.delay_limits(tables, 3.0)
    assert limits[1] is not None  # myplugin's 20 s tail: linear to the typical top, log above
    fig = plots.delay_figure(tables, "atbm", 3.0, limits)
    _rendered(fig, tmp_path, "fig5e")
    ax = fig.axes[0]
    assert "(s)" in ax.get_ylabel()
    # trials are markers, not a line through the trials (the only drawn lines are the 2-point mean lines)
    assert all(len(line.get_xdata()) <= 2 or line.get_linestyle() == "None" for line in ax.lines)
    lows = [
        seg[:, 1].min() for coll in ax.collections if isinstance(coll, LineCollection) for seg in coll.get_segments()
    ]
    assert lows and min(lows) >= 0.0  # ±0.5σ bars clipped at 0 s although 0.3 - 0.5 * 2.0 < 0
    assert ax.get_ylim()[0] == 0.0
    other = plots.delay_figure(tables, "soa", 3.0, limits)
    assert other.axes[0].get_ylim() == ax.get_ylim()  # one y-range for all of Fig. 5a-e
    labels = _legend_labels(fig)
    assert any(lab.startswith("static: k̄ =") for lab in labels) and any(lab.startswith("dynamic") for lab in labels)


@pytest.mark.slow
def test_make_figures_shares_the_delay_axis_across_models(tables, tmp_path):
    paths = plots.make_figures(tables, tmp_path / "figures")
    names = {p.name for p in paths}
    assert {"fig5a_delay_soa_lam3.png", "fig5e_delay_atbm_lam3.png", "fig5g_ospa_lam0.5.png",
            "fig5h_precision.png", "fig5h_precision_trials.png", "fig7_components_lam3.png",
            "fig7b_components_origin_lam3.png", "fig7b_components_origin_lam0.5.png"} <= names  # fmt: skip
    assert all(p.stat().st_size > 5_000 for p in paths)


def test_fig5fg_bars_and_ospa_cutoff(tables, tmp_path):
    fig = plots.bars_figure(tables, "ospa", "mean OSPA (m)", "OSPA", 3.0, "g")
    _rendered(fig, tmp_path, "fig5g")
    ax = fig.axes[0]
    cut = [line for line in ax.lines if line.get_label().startswith("cut-off c = 100 m")]
    assert cut and np.allclose(cut[0].get_ydata(), 100.0)
    assert ax.get_ylim()[1] >= 100.0
    assert {"static", "dynamic"} <= set(_legend_labels(fig))
    assert [t.get_text() for t in ax.get_xticklabels()] == ["S-OA", "ATBM", "myplugin"]
    fig = plots.bars_figure(tables, "card_err", "mean abs. cardinality error (targets)", "cardinality error", 3.0, "f")
    _rendered(fig, tmp_path, "fig5f")
    assert fig.axes[0].get_title(loc="left").startswith("(f) ")


def test_fig5h_all_models_unique_titles(tables, tmp_path):
    fig = plots.precision_figure(tables)
    _rendered(fig, tmp_path, "fig5h")
    assert len(fig.axes) == len(MODES) * len(CLUTTERS)
    assert {"S-OA", "ATBM", "myplugin", "static", "dynamic"} <= set(_legend_labels(fig))
    assert all(len(ax.lines) == len(MODELS) for ax in fig.axes)
    assert all(ax.get_ylim() == (0.0, 1.02) for ax in fig.axes)
    fig = plots.precision_trials_figure(tables)
    _rendered(fig, tmp_path, "fig5h_trials")
    assert {"S-OA", "ATBM", "myplugin"} <= set(_legend_labels(fig))


def test_fig6_and_fig7_per_mode_panels(tables, tmp_path):
    fig = plots.delay_hist_figure(tables, 3.0)
    _rendered(fig, tmp_path, "fig6")
    assert [ax.get_title(loc="left") for ax in fig.axes] == ["(a) static, λ = 3", "(b) dynamic, λ = 3"]
    assert fig.axes[0].get_ylim() == fig.axes[1].get_ylim()
    assert all("(s)" in ax.get_xlabel() for ax in fig.axes)
    fig = plots.components_figure(tables, 3.0)
    _rendered(fig, tmp_path, "fig7")
    for ax in fig.axes:
        assert len(ax.lines) == len(MODELS) and "(s)" in ax.get_xlabel()  # one mean curve per model, vs time
    assert "S-OA: run mean 25 static, 25 dynamic" in _legend_labels(fig)  # mean_components = 20 + 2 trial
    assert [line.get_linestyle() for line in fig.axes[1].lines] == ["--"] * len(MODELS)


def _rows(tables: RunTables) -> list[dict]:
    t = tables.trials
    return [{c: t[c][i] for c in t} for i in range(len(t["trial"]))]


def test_clutter_sweep_figure_legend_has_dashed_dynamic_and_error_bars(tables, tmp_path):
    fig = clutter_figure(_rows(tables), MODELS, MODES)
    _rendered(fig, tmp_path, "sweep_clutter")
    leg = fig.legends[0]
    styles = {t.get_text(): h for t, h in zip(leg.get_texts(), leg.legend_handles, strict=True)}
    assert styles["dynamic"].get_linestyle() == "--" and styles["static"].get_linestyle() == "-"
    ax = fig.axes[0]
    assert len(ax.containers) == len(MODELS) * len(MODES) and all(c.has_yerr for c in ax.containers)
    assert ax.get_ylim() == (0.0, 1.02) and "clutter rate λ" in ax.get_xlabel()


def test_births_sweep_figure(tmp_path):
    table = [{"N_tot": n, "delay": {"soa/static": 1.0 + 1 / n, "pubm/static": 1.2 + 1 / n}} for n in (1, 3, 6, 9)]
    fig = births_figure(table, ["soa", "pubm"], ["static"], 6)
    _rendered(fig, tmp_path, "sweep_births")
    assert {"S-OA", "PUBM", "static", "true births per run N_true = 6"} <= set(_legend_labels(fig))
    half = [{"soa/static": 0.1, "pubm/static": 0.2} for _ in table]
    fig = births_figure(table, ["soa", "pubm"], ["static"], 6, half)
    ax = fig.axes[0]
    assert len(ax.containers) == 2 and all(c.has_yerr for c in ax.containers)
    assert fig.legends[0].get_title().get_text() == "error bars: 95% CI over trials"


def test_pooled_mean_ci_is_the_trial_cluster_interval():
    """Pooled over trials with equal counts, the ratio estimator's CI is the Student-t CI of the trial means."""
    from scipy.stats import t as student_t

    from soabench.figures.bars import mean_ci, pooled_mean_ci

    rng = np.random.default_rng(4)
    values, trials = rng.exponential(1.5, 40), np.repeat(np.arange(8), 5)
    means = np.array([values[trials == t].mean() for t in range(8)])
    assert pooled_mean_ci(values, trials) == pytest.approx(mean_ci(means)[1], rel=1e-12)
    # unequal counts: (sum_t (S_t - R n_t)^2 T/(T-1))^0.5 / N times the t quantile
    trials = np.array([0] * 3 + [1] * 10 + [2] * 27)
    s, n = np.bincount(trials, values), np.bincount(trials)
    r = s.sum() / n.sum()
    want = student_t.ppf(0.975, 2) * np.sqrt(3 / 2 * np.sum((s - r * n) ** 2)) / n.sum()
    assert pooled_mean_ci(values, trials) == pytest.approx(want, rel=1e-12)
    assert np.isnan(pooled_mean_ci(values[:3], trials[:3]))  # one trial: no interval


def test_forest_plot_of_paired_differences_names_the_better_side(tables, tmp_path):
    """The key figure: one panel per metric, the models paired with S-OA as rows, x = S-OA − X with its unit and the
    side where S-OA is better; an interval far wider than the others is cut at the axis' edge, with its numbers."""
    from soabench.experiment.reports.headline import KEY_METRICS, headline
    from soabench.figures.forest import _limit, forest_figure

    fig = forest_figure(headline(tables, 3.0), KEY_METRICS)
    path = ps.save_png(fig, tmp_path / "key_figure.png")
    assert path.stat().st_size > 5_000
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title(loc="left") for ax in axes] == [
        "(a) tracking delay k̄", "(b) cardinality error", "(c) OSPA", "(d) precision"]  # fmt: skip
    assert axes[0].get_xlabel() == "S-OA − X (s)\n← S-OA better"
    assert axes[3].get_xlabel() == "S-OA − X\nS-OA better →"
    assert [t.get_text() for t in axes[0].get_yticklabels()] == ["ATBM", "myplugin"]
    lo, hi = axes[0].get_xlim()
    assert lo == -hi and hi > 0.9  # symmetric about 0; ATBM's +0.9 s inside
    assert _limit([0.10, 0.12, 0.11, 5.0]) == pytest.approx(1.15 * 0.12)  # the outlier is cut, the rest fit
    assert _limit([0.10, 0.12, 0.11, 0.3]) == pytest.approx(1.15 * 0.3)
    assert {"static", "dynamic"} <= set(_legend_labels(fig))


# ---------------------------------------------------------------------------------------------------- maps
def _ring_scene():
    """A looped block: a sidewalk ring (polygon with a hole), a road inside the hole, a building, a door."""
    from soabench.scenario.scene import SceneMap

    outer, inner = box(0, 0, 100, 100), box(10, 10, 90, 90)
    return SceneMap(
        name="ring",
        world_box=box(-5, -5, 105, 105),
        sidewalk=Polygon(outer.exterior.coords, [inner.exterior.coords]),
        crossings=Polygon(),
        walking_areas=Polygon(),
        roads=box(20, 20, 80, 80),
        buildings=[box(40, 40, 60, 60)],
        static_occluders=[Point(30, 70).buffer(2)],
        doors=np.array([[50.0, 39.0]]),
        sidewalk_lines=None,
    )


def _fake_recording():
    n = 5
    foot = np.array([[25.0, 25.0], [29.0, 25.0], [29.0, 27.0], [25.0, 27.0]])
    return SimpleNamespace(
        t=np.arange(n, dtype=float),
        veh_ids=["v0"],
        veh_present=np.ones((n, 1), dtype=bool),
        veh_footprint=np.broadcast_to(foot + [10, 0], (n, 1, 4, 2)),
        ego_footprint=np.broadcast_to(foot, (n, 4, 2)),
        ped_ids=["p0"],
        ped_present=np.ones((n, 1), dtype=bool),
        ped_xy=np.stack([np.linspace(2, 2, n), np.linspace(5, 60, n)], axis=1)[:, None, :],
        meta={},
        net="ring",
        seed=3,
    )


def test_scene_legend_and_polygon_holes_keep_roads_visible(tmp_path):
    from soabench.figures.scene import ROAD, plot_scene, scene_figure

    scene = _ring_scene()
    fig, ax = scene_figure(scene)
    plot_scene(scene, _fake_recording(), ax=ax)
    _rendered(fig, tmp_path, "scene")
    assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "y (m)"
    labels = set(_legend_labels(fig))
    assert {"road", "sidewalk / walking area", "building", "building door", "parked car / static occluder",
            "ego vehicle (sensor)", "other vehicle", "pedestrian track", "track start (appears)",
            "track end (leaves / now)"} <= labels  # fmt: skip
    # the road inside the sidewalk ring's hole is drawn in road grey, not covered by the background colour
    fig.canvas.draw()
    rgb = np.asarray(fig.canvas.buffer_rgba())[..., :3] / 255.0
    x, y = ax.transData.transform((25.0, 50.0))
    pixel = rgb[int(round(fig.bbox.height - y)), int(round(x))]
    assert np.allclose(pixel, to_rgb(ROAD), atol=0.02), pixel


def test_birth_overlay_extends_the_scene_legend(tmp_path):
    from soabench.figures.births import draw_births
    from soabench.figures.scene import plot_scene, scene_figure
    from soabench.types import SOURCE_OCCL, SOURCE_SEM, Births

    scene = _ring_scene()
    fig, ax = scene_figure(scene, legend_rows=5)
    plot_scene(scene, ax=ax)
    P = np.broadcast_to(np.diag([4.0, 1.0, 1.0, 1.0]), (2, 4, 4))
    births = Births(np.ones(2), np.array([[5.0, 50, 0, 0], [50, 5, 0, 0]]), P, np.array([SOURCE_OCCL, SOURCE_SEM]))
    draw_births(ax, births)
    _rendered(fig, tmp_path, "births")
    labels = _legend_labels(fig)
    assert "road" in labels and "occlusion (1)" in labels and "semantic (1)" in labels
    assert len(fig.legends) + sum(a.get_legend() is not None for a in fig.axes) == 1  # one legend, extended


def test_fig7b_components_by_origin(tables, tmp_path):
    fig = components_origin_figure(tables, 3.0)
    _rendered(fig, tmp_path, "fig7b")
    panels = [ax for ax in fig.axes if ax.get_title(loc="left")]
    assert [ax.get_title(loc="left") for ax in panels[:3]] == ["(a) S-OA, static", "(b) S-OA, dynamic",
                                                               "(c) ATBM, static"]  # fmt: skip
    assert len(panels) == len(MODELS) * len(MODES) and len({ax.get_ylim() for ax in panels}) == 1  # one y-axis
    labels = [lab for lab in _legend_labels(fig) if lab]  # only the origins present in the run, in words
    assert sorted(labels) == sorted(["surviving (born at an earlier scan)", "born this scan: occlusion",
                                     "born this scan: semantic", "born this scan: measurement-driven",
                                     "no known birth source"])  # fmt: skip
    # the stacked layers of S-OA add up to its component count 10 + k (drawn against time k dt, dt = 1 s)
    top = max(panels[0].collections, key=lambda c: c.get_paths()[0].vertices[:, 1].max())
    assert top.get_paths()[0].vertices[:, 1].max() == pytest.approx(10 + N_STEPS - 1)
    assert "mean J = 15.5, born this scan 5.0" in [t.get_text() for t in panels[0].texts]


@pytest.mark.slow
def test_fig7b_is_skipped_for_a_run_without_origin_columns(tables, tmp_path):
    old = dataclasses.replace(tables, steps={c: v for c, v in tables.steps.items() if c not in ORIGIN_KEYS})
    assert fig_components_origin(old, 3.0, tmp_path / "fig7b.png") is None and not (tmp_path / "fig7b.png").exists()
    assert not any(p.name.startswith("fig7b") for p in plots.make_figures(old, tmp_path / "figures"))


def test_fig7b_draws_a_run_whose_posteriors_stay_empty(tables, tmp_path):
    """Every origin count 0 (a short run that never keeps a component): the panels stay empty, nothing fails."""
    steps = {c: np.zeros_like(v) if c in ORIGIN_KEYS else v for c, v in tables.steps.items()}
    fig = components_origin_figure(dataclasses.replace(tables, steps=steps), 3.0)
    assert ps.save_png(fig, tmp_path / "fig7b_empty.png").stat().st_size > 5_000
    assert not any(ax.collections for ax in fig.axes)
    assert "mean J = 0.0, born this scan 0.0" in [t.get_text() for t in fig.axes[0].texts]


def test_tracks_figure_is_drawn_per_clutter_rate_only_when_some_model_labels(tables, tmp_path):
    from soabench.figures.tracks import run_tracks_figure
    from soabench.tracks.evaluate import TRACK_KEYS

    assert not any(j.path.name.startswith("tracks") for j in plots.figure_jobs(tables, tmp_path))
    n = len(tables.trials["model"])
    labelled = tables.trials["model"] == "soa"  # S-OA labels its estimates; the others leave the cells empty
    cols = {k: np.where(labelled, 0.5 + 0.1 * np.arange(n) / n, np.nan) for k in TRACK_KEYS}
    cols |= {k: np.full(n, 1.0) for k in ("delay_entry_mean", "delay_reemergence_mean")}
    cols |= {k: np.full(n, 0.2) for k in ("delay_entry_std", "delay_reemergence_std")}
    with_tracks = dataclasses.replace(tables, trials={**tables.trials, **cols})
    names = [j.path.name for j in plots.figure_jobs(with_tracks, tmp_path)]
    assert [x for x in names if x.startswith("tracks")] == [f"tracks_lam{lam:g}.png" for lam in CLUTTERS]
    fig = run_tracks_figure(with_tracks, CLUTTERS[0])
    curves = fig.axes[0]
    assert len(curves.get_lines()) == len(MODES)  # S-OA's curve per mode, no curve for the unlabelled models
    assert "no labels: ATBM, myplugin" in curves.get_title(loc="left")
    _rendered(fig, tmp_path, "tracks")
