"""Figures of the sweeps, in the package style (:mod:`soabench.figures.style`).

* :func:`clutter_figure`: precision vs clutter rate λ per model (colour) and mode (static solid, dynamic dashed),
  mean over trials with its 95% confidence interval (paper Fig. 5h, docs/method.md §5.5);
* :func:`births_figure`: k̄_delay vs the expected births per run N_tot (paper §V.C), ± its 95% CI over trials;

Each ``*_figure`` returns the :class:`~matplotlib.figure.Figure`; :func:`soabench.figures.style.save_png` writes it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure

from soabench.figures import style as ps
from soabench.figures.bars import mean_ci

_CLUTTER_LABEL = "clutter rate λ (false alarms per scan)"


def _by_key(rows: Sequence[Mapping], metric: str) -> dict[tuple[str, str, float], np.ndarray]:
    """Per-trial values of ``metric`` per (model, mode, λ), NaN dropped."""
    acc: dict[tuple[str, str, float], list[float]] = {}
    for r in rows:
        v = float(r[metric])
        if math.isfinite(v):
            acc.setdefault((str(r["model"]), str(r["mode"]), float(r["clutter"])), []).append(v)
    return {k: np.asarray(v) for k, v in acc.items()}


def _ordered(found: set[str], preferred: Sequence[str]) -> list[str]:
    return [m for m in preferred if m in found] + sorted(found - set(preferred))


def _precision_vs_clutter(ax, rows: Sequence[Mapping], models: Sequence[str], modes: Sequence[str]) -> None:
    """Mean per-trial precision ± 95% CI vs λ, one line per (model, mode); y from 0 to 1."""
    vals = _by_key(rows, "precision")
    lams = sorted({k[2] for k in vals})
    n_series = max(1, len(models) * len(modes))
    span = 0.02 * (max(lams) - min(lams) if len(lams) > 1 else 1.0)  # small x offsets keep error bars apart
    for i, (model, mode) in enumerate((a, b) for a in models for b in modes):
        pts = [(lam, *mean_ci(vals[(model, mode, lam)])) for lam in lams if (model, mode, lam) in vals]
        if not pts:
            continue
        x, mu, half = (np.array(c, dtype=float) for c in zip(*pts, strict=True))
        st, ms = ps.model_style(model), ps.mode_style(mode)
        ax.errorbar(
            x + (i - (n_series - 1) / 2) * span,
            mu,
            yerr=np.nan_to_num(half),
            fmt=st.marker,
            ls=ms.linestyle,
            color=st.color,
            mfc=st.color if mode == "static" else "white",
            ms=3.5,
            lw=1.1,
            elinewidth=0.7,
            capsize=2,
        )
    ax.set_xticks(lams, [f"{lam:g}" for lam in lams])
    ax.set_ylim(0, 1.02)
    ax.set_xlabel(_CLUTTER_LABEL)
    ax.set_ylabel("precision (mean over trials)")


def clutter_figure(rows: Sequence[Mapping], models: Sequence[str] = (), modes: Sequence[str] = ()) -> Figure:
    """Precision vs λ from a clutter run's per-trial rows (``trials.csv``), mean ± 95% CI over trials."""
    models = list(models) or _ordered({str(r["model"]) for r in rows}, list(ps.MODEL_STYLES))
    modes = list(modes) or _ordered({str(r["mode"]) for r in rows}, list(ps.MODE_STYLES))
    with ps.style():
        fig = ps.figure("single", 3.0)
        ax = fig.add_subplot()
        _precision_vs_clutter(ax, rows, models, modes)
        ps.panel_title(ax, None, "Precision under clutter (paper Fig. 5h)")
        ps.legend_below(
            fig, ps.model_handles(models) + ps.mode_handles(modes), ncol=4, title="error bars: 95% CI over trials"
        )
    return fig


def births_figure(
    table: Sequence[Mapping],
    models: Sequence[str],
    modes: Sequence[str],
    n_true: float,
    half: Sequence[Mapping] | None = None,
) -> Figure:
    """k̄_delay over all counted episodes vs N_tot (``table`` rows: ``N_tot`` and ``delay["model/mode"]``), with
    error bars of half-width ``half[i]["model/mode"]`` (95 % CI over trials) where given."""
    n_series = max(1, len(models) * len(modes))
    x = np.array([r["N_tot"] for r in table], dtype=float)
    span = 0.006 * (x.max() - x.min() if len(x) > 1 else 1.0)  # small x offsets keep the error bars apart
    with ps.style():
        fig = ps.figure("single", 2.9)
        ax = fig.add_subplot()
        for i, (mode, model) in enumerate((b, a) for b in modes for a in models):
            st = ps.model_style(model)
            key = f"{model}/{mode}"
            err = None if half is None else np.nan_to_num(np.array([h[key] for h in half], dtype=float))
            ax.errorbar(
                x + (0.0 if half is None else (i - (n_series - 1) / 2) * span),
                [r["delay"][key] for r in table],
                yerr=err,
                ls=ps.mode_style(mode).linestyle,
                marker=st.marker,
                ms=3,
                color=st.color,
                mfc=st.color if mode == "static" else "white",
                elinewidth=0.6,
                capsize=1.5,
            )
        line = ax.axvline(n_true, color="k", lw=0.8, ls=":", label=f"true births per run N_true = {n_true:g}")
        ax.set_xlabel("expected births per run N_tot")
        ax.set_ylabel("mean tracking delay k̄ (s)")
        ax.set_ylim(bottom=0)
        ps.panel_title(ax, None, "Average delay vs N̂ (paper §V.C)")
        title = None if half is None else "error bars: 95% CI over trials"
        ps.legend_below(fig, ps.model_handles(models) + ps.mode_handles(modes) + [line], ncol=3, title=title)
    return fig
