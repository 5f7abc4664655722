"""The track figure of a run (docs/method.md §9.3, §9.4): (a) HOTA against its localisation threshold α per model
and mode, (b) the entry and the re-emergence delay of each model side by side.

Panel (a) is the curve TrackEval plots for HOTA: the mean over trials of HOTA_α with its 95 % confidence band;
a model whose curve falls early localises poorly, a model low everywhere associates poorly. Panel (b) puts, per
model and mode, the mean over trials of the per-trial mean delay of entry episodes (plain bar) beside that of
re-emergence episodes (dark bar), with σ̄ / 2 whiskers as the paper's Fig. 5 and every trial as a dot: what
occlusion-aware birth is for is the right-hand bar. Trackers without labels have no curve in (a) and say so.

A run's report draws it per clutter rate as ``tracks.png`` (``tracks_lam<λ>.png`` with several rates) when some
model or tracker of the run labels its estimates (:func:`has_labels`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from soabench.experiment.reports.tables import RunTables, select
from soabench.figures import style as ps
from soabench.figures.bars import mean_ci
from soabench.tracks.evaluate import ALPHA_KEYS
from soabench.tracks.scores import ALPHAS

#: episode kinds of panel (b) and their bar opacity: entry light, re-emergence dark
KINDS = (("entry", 0.35), ("reemergence", 0.9))


def _floats(values: np.ndarray) -> np.ndarray:
    """A trials.csv column as floats: an empty cell (a label column of an unlabelled tracker) is NaN."""
    return np.array([np.nan if v is None or v == "" else float(v) for v in np.asarray(values).tolist()], dtype=float)


def has_labels(tables: RunTables) -> bool:
    """Whether some trial of the run has a HOTA: some model or tracker labelled its estimates."""
    t = tables.trials
    return "hota" in t and bool(np.isfinite(_floats(t["hota"])).any())


def run_tracks_figure(tables: RunTables, clutter: float) -> Figure:
    """:func:`tracks_figure` of a run's trials at one clutter rate: every model and tracker with trials there, in
    the run's order."""
    t = tables.trials
    present = [
        (mo, md) for mo in tables.models for md in tables.modes if select(t, clutter=clutter, model=mo, mode=md).any()
    ]
    models = [mo for mo in tables.models if any(p[0] == mo for p in present)]
    modes = [md for md in tables.modes if any(p[1] == md for p in present)]

    def col(key: str, model: str, mode: str) -> np.ndarray:
        m = select(t, clutter=clutter, model=model, mode=mode)
        return _floats(t[key][m]) if key in t else np.full(int(m.sum()), np.nan)

    return tracks_figure(col, models, modes, clutter)


def tracks_figure(
    col: Callable[[str, str, str], np.ndarray], models: Sequence[str], modes: Sequence[str], clutter: float
) -> Figure:
    """The two panels for one clutter rate; ``col(column, model, mode)`` is that run's per-trial column (NaN where
    a trial has no value)."""
    with ps.style():
        fig = ps.figure("double", 2.9)
        ax, bars = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.25]})
        unlabelled, top = [], 0.0
        for model in models:
            st = ps.model_style(model)
            for mode in modes:
                H = np.column_stack([col(key, model, mode) for key in ALPHA_KEYS])
                if not len(H):  # no trial of this model in this mode
                    continue
                if not np.isfinite(H).any():
                    unlabelled.append(ps.model_label(model))
                    continue
                mean_ci_a = [mean_ci(H[:, a]) for a in range(len(ALPHAS))]
                mu, half = np.array([m for m, _ in mean_ci_a]), np.nan_to_num(np.array([h for _, h in mean_ci_a]))
                ax.plot(ALPHAS, mu, color=st.color, ls=ps.mode_style(mode).linestyle, marker=st.marker, ms=2.5)
                # light bands: with many models and modes they overlap, the curves must stay readable
                ax.fill_between(ALPHAS, mu - half, mu + half, color=st.color, alpha=0.07, lw=0)
                top = max(top, float(np.nanmax(mu + half)))
        ax.set_xlim(0, 1)
        ax.set_ylim(0, min(1.0, 1.1 * top) if top > 0 else 1.0)
        ax.set_xlabel("localisation threshold α (match when S ≥ α)")
        ax.set_ylabel("HOTA_α (mean over trials; band: 95% CI)")
        note = f"; no labels: {', '.join(sorted(set(unlabelled)))}" if unlabelled else ""
        ps.panel_title(ax, "a", f"HOTA against α, λ = {clutter:g}{note}")
        _delay_bars(bars, col, models, modes)
        ps.panel_title(bars, "b", "entry vs re-emergence delay (mean ± σ̄/2; dots: trials)")
        handles = ps.model_handles(models) + ps.mode_handles_combined(modes)
        ps.legend_below(fig, handles, [ps.model_label(m) for m in models] + list(modes), ncol=len(handles))
    return fig


def _delay_bars(ax, col: Callable[[str, str, str], np.ndarray], models: Sequence[str], modes: Sequence[str]) -> None:
    """Per model one group: per mode (hatched when not static) the entry bar and the re-emergence bar side by
    side, trials as dots."""
    rng = np.random.default_rng(0)  # jitter of the dots only; fixed so the figure is reproducible
    n_bars = 2 * len(modes)
    width = 0.84 / n_bars
    for i, model in enumerate(models):
        st = ps.model_style(model)
        for j, mode in enumerate(modes):
            for k, (kind, alpha) in enumerate(KINDS):
                x = i + (2 * j + k - (n_bars - 1) / 2) * width
                mu = np.asarray(col(f"delay_{kind}_mean", model, mode), dtype=float)
                sd = np.asarray(col(f"delay_{kind}_std", model, mode), dtype=float)
                if not mu.size:  # no trial of this model in this mode
                    continue
                mu = mu[np.isfinite(mu)]
                if not mu.size:
                    ax.text(x, 0.02, "none", rotation=90, ha="center", va="bottom", fontsize=5,
                            transform=ax.get_xaxis_transform())  # fmt: skip
                    continue
                mean = float(mu.mean())
                half = 0.5 * float(np.nanmean(sd)) if np.isfinite(sd).any() else 0.0
                ax.bar(x, mean, width * 0.9, yerr=[[min(half, mean)], [half]], color=st.color, alpha=alpha,
                       hatch=ps.mode_style(mode).hatch, edgecolor="k", linewidth=0.5,
                       error_kw={"elinewidth": 0.7, "capsize": 1.5}, zorder=2)  # fmt: skip
                jitter = rng.uniform(-0.3, 0.3, mu.size) * width
                ax.plot(x + jitter, mu, ".", color=st.color, mec="k", mew=0.2, ms=2.2, alpha=0.8, zorder=3)
    if len(models) > 5:  # many names: one line each, slanted, so neighbours never run into each other
        ax.set_xticks(np.arange(len(models)), [ps.model_label(m) for m in models], rotation=25, ha="right")
    else:
        ax.set_xticks(np.arange(len(models)), [ps.tick_label(m) for m in models])
    ax.set_xlim(-0.5, len(models) - 0.5)
    ax.set_ylabel("mean tracking delay (s)")
    ax.set_ylim(0, 1.25 * ax.get_ylim()[1])  # headroom for the legend above the tallest whisker
    ax.grid(axis="x", visible=False)

    kinds = [Patch(facecolor="0.4", alpha=a, edgecolor="k", label=f"{k.replace('reem', 're-em')} episodes")
             for k, a in KINDS]  # fmt: skip
    ax.legend(handles=kinds, loc="upper left")
