"""The paper's result figures from a run's CSV files (Fig. 5 a–h, Fig. 6, Fig. 7; docs/method.md §5.4–5.7).

Every figure is drawn in the package style (:mod:`soabench.figures.style`: paper sizes, one colour and marker per
model, static solid / dynamic dashed or hatched, panels titled "(a) ...") and saved under ``figures/``:

* ``fig5{a..e}_delay_<model>.png``: the per-trial mean delay k̄ of every trial as a marker with its ±0.5σ bounds
  (clipped at 0 s), the mean over trials with its 95% confidence interval, and a box plot per mode; one y-range
  for the paper's five models (a S-OA, b PUBM, c UBM over the workspace, d GMBM, e ATBM, the paper's order; UBM
  clipped to the FOV and plugins as fig5x_delay_<model>.png);
* ``fig5f_cardinality.png``, ``fig5g_ospa.png``: mean ± σ over trials per model and mode, with every trial as a
  dot; Fig. 5g marks the OSPA cut-off c;
* ``fig5h_precision.png``: cumulative precision vs time, mean over trials, every model, one panel per mode and
  clutter rate; ``fig5h_precision_trials.png``: the per-trial precision per model and clutter rate (§5.5);
* ``fig6_delay_hist.png``: share of counted episodes per delay, per model, one panel per mode;
* ``fig7_components.png``: posterior component count vs time, mean over trials with the 10–90 % band across trials,
  one panel per mode;
* ``fig7b_components_origin.png``: the same counts by origin (born this scan per birth source, or surviving),
  stacked, mean over trials, one panel per model and mode (:mod:`soabench.figures.origins`; not drawn for
  a run written before ``steps.csv`` had the origin columns);
* ``tracks.png``: HOTA against its threshold α and the entry vs re-emergence delay per model and mode
  (:mod:`soabench.figures.tracks`; drawn when some model or tracker labels its estimates);
* ``identity_gaps.png``: identity kept against the occlusion gap's length, per occluder kind
  (:mod:`soabench.figures.gaps`; drawn with ``tracks.png``; a run of several filter families adds
  ``identity_gaps_families.png``, one row per family).

With several clutter rates, figures 5a–g, 6, 7, 7b and tracks are drawn per rate with a ``_lam<λ>`` suffix.

Each ``*_figure`` function returns the :class:`~matplotlib.figure.Figure`; each ``fig_*`` function writes it.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FixedLocator, FormatStrFormatter, MaxNLocator, NullLocator

from soabench.experiment.reports.tables import RunTables, select
from soabench.figures import style as ps
from soabench.figures.bars import grouped_bars, mean_ci, offsets
from soabench.figures.drawing import FigureJob, draw_all
from soabench.figures.families import family_jobs, family_only, in_family, run_families
from soabench.figures.forest import paired_figure
from soabench.figures.gaps import identity_gaps_figure
from soabench.figures.origins import components_origin_figure, has_origins
from soabench.figures.tracks import has_labels, run_tracks_figure

#: the paper's Fig. 5 panels (its UBM is the workspace grid); other models are drawn as fig5x_delay_<model>.png
LETTER = {"soa": "a", "pubm": "b", "ubm-ws": "c", "gmbm": "d", "atbm": "e"}


# ------------------------------------------------------------------------------------------------------- helpers
def _dt(tables: RunTables) -> float:
    return float(tables.meta["config"]["sensor"]["dt"])


# ------------------------------------------------------------------------------------------------- Fig. 5a–e
def delay_limits(tables: RunTables, clutter: float) -> tuple[float, float | None]:
    """The y-range shared by Fig. 5a–e at one clutter rate: (top, linthresh or None).

    The top is the largest k̄ + 0.5σ over every model and mode. When one model's delays reach far beyond the
    others' (GMBM's long tail), the axis is linear up to the typical model's largest value and logarithmic above
    (``linthresh``), so every panel stays readable on the same scale.
    """
    t = tables.trials
    tops = []
    for model in tables.models:
        m = select(t, clutter=clutter, model=model)
        hi = t["delay_mean"][m] + 0.5 * np.nan_to_num(t["delay_std"][m])
        hi = hi[np.isfinite(hi)]
        if hi.size:
            tops.append(float(hi.max()))
    if not tops:
        return 1.0, None
    top, typical = max(tops), float(np.median(tops))
    if top > 3.0 * typical and typical > 0:
        return top * 1.15, math.ceil(typical * 2) / 2  # linear to the next half second above the typical top
    return top * 1.05, None


def delay_figure(
    tables: RunTables, model: str, clutter: float, limits: tuple[float, float | None] | None = None
) -> Figure:
    """Fig. 5a–e: per-trial k̄ with ±0.5σ bounds, mean over trials ± 95% CI, and a box plot per mode."""
    t = tables.trials
    top, linthresh = limits or delay_limits(tables, clutter)
    modes = tables.modes
    with ps.style():
        fig = ps.figure("single", 2.9)
        ax, box = fig.subplots(1, 2, sharey=True, gridspec_kw={"width_ratios": [4, 1]})
        st = ps.model_style(model)
        handles = []
        for j, mode in enumerate(modes):
            m = select(t, clutter=clutter, model=model, mode=mode)
            order = np.argsort(t["trial"][m], kind="stable")
            x = t["trial"][m][order] + offsets(len(modes), 0.5)[j]
            mu, sd = t["delay_mean"][m][order], np.nan_to_num(t["delay_std"][m][order])
            ok = np.isfinite(mu)
            ms = ps.mode_style(mode)
            face = st.color if mode == "static" else "white"
            ax.errorbar(
                x[ok],
                mu[ok],
                yerr=[np.minimum(0.5 * sd[ok], mu[ok]), 0.5 * sd[ok]],
                fmt=ms.marker,
                ms=2.2,
                mfc=face,
                mec=st.color,
                mew=0.6,
                ecolor=st.color,
                elinewidth=0.4,
                capsize=0,
                alpha=0.85,
                zorder=3,
            )
            mean, half = mean_ci(mu)
            if math.isfinite(mean):
                ax.axhline(mean, color="k", ls=ms.linestyle, lw=1.0, zorder=4)
                if math.isfinite(half):
                    ax.axhspan(mean - half, mean + half, color=st.color, alpha=0.18, lw=0, zorder=1)
            ci = f" ± {half:.2f}" if math.isfinite(half) else ""

            handles.append(
                Line2D(
                    [],
                    [],
                    color="k",
                    ls=ms.linestyle,
                    marker=ms.marker,
                    mfc=face,
                    mec=st.color,
                    label=f"{mode}: k̄ = {mean:.2f}{ci} s" if math.isfinite(mean) else f"{mode}: no counted episode",
                )
            )
            box.boxplot(
                [mu[ok]] if ok.any() else [[]],
                positions=[j],
                widths=0.6,
                patch_artist=True,
                boxprops={"facecolor": face, "edgecolor": st.color, "hatch": ms.hatch},
                medianprops={"color": "k"},
                whiskerprops={"color": st.color},
                capprops={"color": st.color},
                flierprops={"marker": ".", "ms": 2, "mec": st.color},
            )
        if linthresh is not None:
            ax.set_yscale("symlog", linthresh=linthresh, linscale=2.0)
            step = 0.5 if linthresh <= 3 else 1.0
            ticks = list(np.arange(0.0, linthresh + 1e-9, step))
            ticks += [v for v in (5, 10, 20, 50, 100, 200, 500, 1000) if linthresh * 1.5 < v <= top]
            ax.yaxis.set_major_locator(FixedLocator(ticks))
            ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
            ax.yaxis.set_minor_locator(NullLocator())
            ax.set_ylabel(f"mean tracking delay k̄ (s)\n(linear to {linthresh:g} s, log above)")
        else:
            ax.set_ylabel("mean tracking delay k̄ (s)")
        ax.set_ylim(0, top)
        ax.set_xlabel("trial")
        _integer_ticks(ax)
        ax.grid(axis="x", visible=False)
        box.set_xticks(np.arange(len(modes)), [m[:3] + "." if len(m) > 7 else m for m in modes], rotation=90)
        box.set_xlim(-0.6, len(modes) - 0.4)
        box.grid(axis="x", visible=False)
        ps.panel_title(ax, LETTER.get(model), f"{ps.model_label(model)}, λ = {clutter:g}: k̄ ± 0.5σ per trial")
        fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), title="mean over trials ± 95% CI")
    return fig


def _integer_ticks(ax) -> None:

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))


def fig_delay(tables: RunTables, model: str, clutter: float, path: Path, limits=None) -> Path:
    """Write Fig. 5a–e of ``model`` (:func:`delay_figure`)."""
    return ps.save_png(delay_figure(tables, model, clutter, limits), path)


# ------------------------------------------------------------------------------------------------- Fig. 5f–g
def bars_figure(tables: RunTables, column: str, ylabel: str, title: str, clutter: float, letter: str) -> Figure:
    """Fig. 5f/g: mean ± σ over trials of a per-trial metric per model (colour) and mode (hatch), trials as dots.

    For ``column == "ospa"`` the cut-off c of the run's config is drawn and named.
    """
    t = tables.trials
    models, modes = tables.models, tables.modes
    with ps.style():
        fig = ps.figure("single", 2.6)
        ax = fig.add_subplot()
        grouped_bars(ax, models, modes, lambda mo, md: t[column][select(t, clutter=clutter, model=mo, mode=md)])
        handles = ps.mode_handles(modes, bars=True)
        if column == "ospa":
            mc = tables.meta["config"].get("metrics", {})
            c, p = float(mc.get("ospa_c", math.nan)), mc.get("ospa_p", 1)
            if math.isfinite(c):
                line = ax.axhline(c, color="k", ls=":", lw=1.0, label=f"cut-off c = {c:g} m (p = {p:g})")
                handles.append(line)
                ax.set_ylim(0, c * 1.05)
        ax.set_ylim(bottom=0)
        ax.set_ylabel(ylabel)
        ps.panel_title(ax, letter, f"{title}, λ = {clutter:g} (mean ± σ over trials)")
        fig.legend(handles=handles, loc="outside lower center", ncol=len(handles))
    return fig


def fig_bars(
    tables: RunTables, column: str, ylabel: str, title: str, clutter: float, path: Path, letter: str = ""
) -> Path:
    """Write Fig. 5f or 5g (:func:`bars_figure`)."""
    return ps.save_png(bars_figure(tables, column, ylabel, title, clutter, letter), path)


# --------------------------------------------------------------------------------------------------- Fig. 5h
def cumulative_precision(tables: RunTables, clutter: float, model: str, mode: str) -> tuple[np.ndarray, np.ndarray]:
    """(k, mean over trials of ΣTP/Σ(TP+FP) up to k) from steps.csv (§5.5 "precision curves" (i))."""
    s = tables.steps
    m = select(s, clutter=clutter, model=model, mode=mode)
    if not m.any():
        return np.array([]), np.array([])
    trials, k, tp, fp = s["trial"][m], s["k"][m], s["tp"][m], s["fp"][m]
    ks = np.unique(k)
    curves = []
    for tr in np.unique(trials):
        mt = trials == tr
        order = np.argsort(k[mt], kind="stable")
        ctp, cfp = np.cumsum(tp[mt][order]), np.cumsum(fp[mt][order])
        with np.errstate(invalid="ignore", divide="ignore"):
            prec = np.where(ctp + cfp > 0, ctp / np.maximum(ctp + cfp, 1e-300), np.nan)
        full = np.full(ks.size, np.nan)
        full[np.searchsorted(ks, k[mt][order])] = prec
        curves.append(full)
    arr = np.vstack(curves)
    with np.errstate(invalid="ignore"):
        cnt = np.sum(~np.isnan(arr), axis=0)
        mean = np.where(cnt > 0, np.nansum(arr, axis=0) / np.maximum(cnt, 1), np.nan)
    return ks, mean


def precision_figure(tables: RunTables) -> Figure:
    """Fig. 5h (i): cumulative precision vs time, mean over trials, every model; rows = modes, columns = λ."""
    modes, clutters, models = tables.modes, tables.clutters, tables.models
    dt = _dt(tables)
    with ps.style():
        fig = ps.figure("double", 0.6 + 1.7 * len(modes))
        axes = fig.subplots(len(modes), len(clutters), squeeze=False, sharex=True, sharey=True)
        for i, mode in enumerate(modes):
            for j, lam in enumerate(clutters):
                ax = axes[i, j]
                for model in models:
                    k, p = cumulative_precision(tables, lam, model, mode)
                    st = ps.model_style(model)
                    ax.plot(
                        k * dt,
                        p,
                        ps.mode_style(mode).linestyle,
                        color=st.color,
                        marker=st.marker,
                        ms=2.5,
                        markevery=max(1, k.size // 8),
                    )  # fmt: skip  (markers tell overlapping curves apart)
                ps.panel_title(ax, None, f"{mode}, λ = {lam:g}")
                ax.set_ylim(0, 1.02)
                if i == len(modes) - 1:
                    ax.set_xlabel("time (s)")
                if j == 0:
                    ax.set_ylabel("cumulative precision")
        fig.suptitle("(h) cumulative precision ΣTP / Σ(TP + FP) up to time t, mean over trials", x=0.0, ha="left")
        fig.legend(
            handles=ps.model_handles(models) + ps.mode_handles(modes),
            loc="outside lower center",
            ncol=len(models) + len(modes),
        )
    return fig


def precision_trials_figure(tables: RunTables) -> Figure:
    """Fig. 5h (ii): the per-trial precision of every model at every clutter rate, one panel per mode."""
    t = tables.trials
    modes, clutters, models = tables.modes, tables.clutters, tables.models
    with ps.style():
        fig = ps.figure("double", 2.4)
        axes = fig.subplots(1, len(modes), squeeze=False, sharey=True)[0]
        for ax, mode, letter in zip(axes, modes, ps.letters(len(modes)), strict=False):
            for i, model in enumerate(models):
                st = ps.model_style(model)
                vals = []
                for lam in clutters:
                    v = t["precision"][select(t, clutter=lam, model=model, mode=mode)]
                    vals.append(v[np.isfinite(v)])
                pos = np.arange(len(clutters)) + offsets(len(models))[i]
                keep = [n for n, v in enumerate(vals) if v.size]
                if keep:
                    ax.boxplot(
                        [vals[n] for n in keep],
                        positions=pos[keep],
                        widths=0.8 / max(len(models), 1) * 0.85,
                        patch_artist=True,
                        boxprops={"facecolor": st.color, "alpha": 0.6, "edgecolor": "k", "linewidth": 0.5},
                        medianprops={"color": "k", "linewidth": 0.8},
                        whiskerprops={"linewidth": 0.6},
                        capprops={"linewidth": 0.6},
                        flierprops={"marker": ".", "ms": 2, "mfc": st.color, "mec": st.color},
                    )
            ax.set_xticks(np.arange(len(clutters)), [f"{lam:g}" for lam in clutters])
            ax.set_xlim(-0.5, len(clutters) - 0.5)
            ax.set_ylim(0, 1.02)
            ax.set_xlabel("clutter rate λ (false alarms per scan)")
            ax.grid(axis="x", visible=False)
            ps.panel_title(ax, letter, f"per-trial precision, {mode}")
        axes[0].set_ylabel("precision per trial")
        fig.legend(handles=ps.model_handles(models, marker=False), loc="outside lower center", ncol=len(models))
    return fig


def fig_precision(tables: RunTables, path: Path) -> Path:
    """Write Fig. 5h (:func:`precision_figure`)."""
    return ps.save_png(precision_figure(tables), path)


def fig_precision_trials(tables: RunTables, path: Path) -> Path:
    """Write Fig. 5h (ii) (:func:`precision_trials_figure`)."""
    return ps.save_png(precision_trials_figure(tables), path)


# --------------------------------------------------------------------------------------------------- Fig. 6
def delay_hist_figure(tables: RunTables, clutter: float, max_bin: int = 10) -> Figure:
    """Fig. 6: distribution of per-episode delays per model (counted episodes), one panel per mode.

    Delays are multiples of dt: grouped bars give the share of each model's counted episodes at 0, 1, ...,
    ``max_bin`` scans, and one overflow bar beyond (the long GMBM tail would otherwise flatten every other bar).
    """
    e = tables.episodes
    modes, models = tables.modes, tables.models
    have = bool(e) and "delay" in e and len(e["delay"]) > 0
    dt = _dt(tables)
    x = np.arange(max_bin + 2)
    width = 0.8 / max(len(models), 1)
    with ps.style():
        fig = ps.figure("double", 2.4)
        axes = fig.subplots(1, len(modes), squeeze=False, sharey=True)[0]
        for ax, mode, letter in zip(axes, modes, ps.letters(len(modes)), strict=False):
            for i, model in enumerate(models):
                share = np.zeros(max_bin + 2)
                if have:
                    m = select(e, clutter=clutter, model=model, mode=mode) & (e["censored"] == 0)
                    m &= ~np.isnan(e["delay"])
                    steps = np.rint(e["delay"][m] / dt).astype(int)
                    if steps.size:
                        share = np.bincount(np.minimum(steps, max_bin + 1), minlength=max_bin + 2) / steps.size
                st = ps.model_style(model)
                ax.bar(x + offsets(len(models))[i], share, width, color=st.color, hatch=ps.mode_style(mode).hatch,
                       edgecolor="k", linewidth=0.3)  # fmt: skip
            ax.set_xticks(x, [f"{k * dt:g}" for k in range(max_bin + 1)] + [f">{max_bin * dt:g}"])
            ax.set_xlabel("tracking delay k_delay (s)")
            ax.grid(axis="x", visible=False)
            ps.panel_title(ax, letter, f"{mode}, λ = {clutter:g}")
        axes[0].set_ylabel("share of counted episodes")
        axes[0].set_ylim(0, None)
        fig.legend(handles=ps.model_handles(models, marker=False), loc="outside lower center", ncol=len(models))
    return fig


def fig_delay_hist(tables: RunTables, clutter: float, path: Path, max_bin: int = 10) -> Path:
    """Write Fig. 6 (:func:`delay_hist_figure`)."""
    return ps.save_png(delay_hist_figure(tables, clutter, max_bin), path)


# --------------------------------------------------------------------------------------------------- Fig. 7
def components_over_time(tables: RunTables, clutter: float, model: str, mode: str):
    """(k, mean, 10th and 90th percentile over trials) of the posterior component count per scan (§5.7)."""
    s = tables.steps
    m = select(s, clutter=clutter, model=model, mode=mode)
    if not m.any() or "n_components" not in s:
        return (np.array([]),) * 4
    trials, k, n = s["trial"][m], s["k"][m], s["n_components"][m]
    ks, tr = np.unique(k), np.unique(trials)
    grid = np.full((tr.size, ks.size), np.nan)
    grid[np.searchsorted(tr, trials), np.searchsorted(ks, k)] = n
    with warnings.catch_warnings():  # a scan no trial reached is NaN, not a warning
        warnings.simplefilter("ignore", RuntimeWarning)
        return ks, np.nanmean(grid, 0), np.nanpercentile(grid, 10, 0), np.nanpercentile(grid, 90, 0)


def components_figure(tables: RunTables, clutter: float) -> Figure:
    """Fig. 7: posterior components vs time, mean over trials with the 10–90 % band, one panel per mode."""
    t = tables.trials
    modes, models = tables.modes, tables.models
    dt = _dt(tables)
    with ps.style():
        fig = ps.figure("double", 3.0)
        axes = fig.subplots(1, len(modes), squeeze=False, sharey=True)[0]
        run_means: dict[str, list[str]] = {model: [] for model in models}
        for ax, mode, letter in zip(axes, modes, ps.letters(len(modes)), strict=False):
            for model in models:
                st = ps.model_style(model)
                k, mean, lo, hi = components_over_time(tables, clutter, model, mode)
                ax.plot(k * dt, mean, ps.mode_style(mode).linestyle, color=st.color)
                ax.fill_between(k * dt, lo, hi, color=st.color, alpha=0.15, lw=0)
                avg, _ = mean_ci(t["mean_components"][select(t, clutter=clutter, model=model, mode=mode)])
                run_means[model].append(f"{avg:.0f} {mode}")
            ax.set_xlabel("time (s)")
            ps.panel_title(ax, letter, f"{mode}, λ = {clutter:g}")
        labels = [f"{ps.model_label(m)}: run mean {', '.join(run_means[m])}" for m in models]
        ps.legend_below(fig, ps.model_handles(models, marker=False), labels, ncol=3)  # the panel titles name the mode
        axes[0].set_ylabel("posterior components J")
        axes[0].set_ylim(0, None)
        fig.suptitle("posterior components after pruning and merging: mean over trials, 10–90 % band", x=0.0, ha="left")
    return fig


def fig_components(tables: RunTables, clutter: float, path: Path) -> Path:
    """Write Fig. 7 (:func:`components_figure`)."""
    return ps.save_png(components_figure(tables, clutter), path)


# -------------------------------------------------------------------------------------------------- all
def figure_jobs(tables: RunTables, out_dir: Path, by_family: bool = True) -> list[FigureJob]:
    """Every figure of the run (module docstring) as a :class:`~soabench.figures.drawing.FigureJob`, in order; for a
    run that names filter families, those of its GM-PHD family, then the families side by side
    (:mod:`soabench.figures.families`); ``by_family`` False: the paper's figures of all the rows given."""
    if by_family and run_families(tables):
        first = run_families(tables)[0]
        jobs = [
            FigureJob(j.path, in_family, (first, j.build, *j.args), j.weight)
            for j in figure_jobs(family_only(tables, first), out_dir, by_family=False)
        ]
        return jobs + family_jobs(tables, out_dir)
    out_dir = Path(out_dir)
    jobs: list[FigureJob] = []
    clutters = tables.clutters
    if not clutters:
        return jobs
    origins, labelled = has_origins(tables), has_labels(tables)
    for lam in clutters:
        sfx = f"_lam{lam:g}" if len(clutters) > 1 else ""
        limits = delay_limits(tables, lam)
        if "soa" in tables.models and len(tables.models) > 1:  # the headline's forest plot
            jobs.append(FigureJob(out_dir / f"paired{sfx}.png", paired_figure, (lam,), weight=1.5))
        for model in sorted(tables.models, key=lambda m: LETTER.get(m, "z")):
            name = f"fig5{LETTER.get(model, 'x')}_delay_{model}{sfx}.png"
            jobs.append(FigureJob(out_dir / name, delay_figure, (model, lam, limits)))
        card = ("card_err", "mean abs. cardinality error (targets)", "cardinality error", lam, "f")
        jobs.append(FigureJob(out_dir / f"fig5f_cardinality{sfx}.png", bars_figure, card))
        ospa = ("ospa", "mean OSPA (m)", "OSPA", lam, "g")
        jobs.append(FigureJob(out_dir / f"fig5g_ospa{sfx}.png", bars_figure, ospa))
        jobs.append(FigureJob(out_dir / f"fig6_delay_hist{sfx}.png", delay_hist_figure, (lam,), weight=1.5))
        jobs.append(FigureJob(out_dir / f"fig7_components{sfx}.png", components_figure, (lam,), weight=1.5))
        if origins:
            panels = len(tables.models) * len(tables.modes)  # its drawing time grows with the panels
            name = f"fig7b_components_origin{sfx}.png"
            jobs.append(FigureJob(out_dir / name, components_origin_figure, (lam,), weight=0.4 * panels))
        if labelled:
            jobs.append(FigureJob(out_dir / f"tracks{sfx}.png", run_tracks_figure, (lam,), weight=2.0))
            jobs.append(FigureJob(out_dir / f"identity_gaps{sfx}.png", identity_gaps_figure, (lam,), weight=1.5))
    jobs.append(FigureJob(out_dir / "fig5h_precision.png", precision_figure, (), weight=1.5))
    jobs.append(FigureJob(out_dir / "fig5h_precision_trials.png", precision_trials_figure, ()))
    return jobs


def make_figures(tables: RunTables, out_dir: Path) -> list[Path]:
    """Draw every figure of the run (:func:`figure_jobs`); returns the written paths, in order.

    Tables read from a run folder (``tables.run_dir``) are drawn by the process pool of
    :func:`soabench.figures.drawing.parallel` when one is open (each worker reads the folder's tables itself).
    """

    return draw_all(figure_jobs(tables, out_dir), tables)
