"""The paper's result figures from a run's CSV files (Fig. 5 a–h, Fig. 6, Fig. 7; docs/method.md §5.4–5.7).

Figures are drawn on ``matplotlib.figure.Figure`` with the Agg canvas (no pyplot, no global backend state), and
saved atomically under ``figures/``:

* ``fig5{a..e}_delay_<model>.png``: per-trial mean delay k̄ with ±0.5σ bounds, static vs dynamic (a S-OA, b PUBM,
  c UBM, d GMBM, e ATBM, the paper's order);
* ``fig5f_cardinality.png``, ``fig5g_ospa.png``: mean ± σ over trials per model and mode;
* ``fig5h_precision.png``: cumulative precision vs time averaged over trials (top) and sorted per-trial precision
  (bottom) for S-OA and ATBM at every clutter rate present (§5.5);
* ``fig6_delay_hist.png``: histogram of per-episode delays per model; ``fig7_components.png``: mean posterior
  components per trial per model.

With several clutter rates, figures 5a–g, 6 and 7 are drawn per rate with a ``_lam<λ>`` suffix.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from soabench.birth import LABEL
from soabench.experiment.store import write_bytes_atomic

if TYPE_CHECKING:
    from soabench.experiment.report import RunTables

LETTER = {"soa": "a", "pubm": "b", "ubm": "c", "gmbm": "d", "atbm": "e"}
MODE_STYLE = {"static": ("tab:blue", "-"), "dynamic": ("tab:orange", "--"), "dynamic+occ": ("tab:green", ":")}
MODEL_COLOR = {"soa": "tab:green", "pubm": "tab:blue", "ubm": "tab:purple", "atbm": "tab:red", "gmbm": "tab:gray"}


def _figure(w: float = 6.0, h: float = 4.0):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: Path) -> Path:
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120, bbox_inches="tight")
    write_bytes_atomic(path, buf.getvalue())
    return path


def _integer_ticks(ax) -> None:
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))


def _sel(table, **where):
    from soabench.experiment.report import select

    return select(table, **where)


def fig_delay(tables: RunTables, model: str, clutter: float, path: Path) -> Path:
    """Fig. 5a–e: k̄_delay per trial with ±0.5σ bounds, one line per probability mode."""
    t = tables.trials
    fig = _figure()
    ax = fig.add_subplot()
    for mode in tables.modes:
        m = _sel(t, clutter=clutter, model=model, mode=mode)
        order = np.argsort(t["trial"][m], kind="stable")
        x, mu, sd = t["trial"][m][order], t["delay_mean"][m][order], t["delay_std"][m][order]
        color, ls = MODE_STYLE.get(mode, ("k", "-"))
        finite = mu[np.isfinite(mu)]
        kbar = f"{finite.mean():.2f} s" if finite.size else "n/a"
        ax.plot(x, mu, ls, color=color, lw=1.2, label=f"{mode}: k̄ = {kbar}")
        ax.fill_between(x, mu - 0.5 * sd, mu + 0.5 * sd, color=color, alpha=0.2, lw=0)
    _integer_ticks(ax)
    ax.set_xlabel("trial")
    ax.set_ylabel("mean tracking delay k̄ (s)")
    ax.set_title(f"({LETTER.get(model, '?')}) {LABEL.get(model, model)}, λ = {clutter:g} (±0.5σ)")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    return _save(fig, path)


def fig_bars(tables: RunTables, column: str, ylabel: str, title: str, clutter: float, path: Path) -> Path:
    """Fig. 5f/g: mean ± σ over trials of a per-trial metric, per model and mode."""
    t = tables.trials
    fig = _figure()
    ax = fig.add_subplot()
    models, modes = tables.models, tables.modes
    width = 0.8 / max(1, len(modes))
    for j, mode in enumerate(modes):
        means, stds = [], []
        for model in models:
            v = t[column][_sel(t, clutter=clutter, model=model, mode=mode)]
            v = v[~np.isnan(v)]
            means.append(v.mean() if v.size else math.nan)
            stds.append(v.std() if v.size else math.nan)
        x = np.arange(len(models)) + (j - (len(modes) - 1) / 2) * width
        color, _ = MODE_STYLE.get(mode, ("k", "-"))
        ax.bar(x, means, width, yerr=stds, capsize=3, color=color, alpha=0.8, label=mode)
    ax.set_xticks(np.arange(len(models)), [LABEL.get(m, m) for m in models])
    ax.set_ylabel(ylabel)
    ax.set_title(f"{title}, λ = {clutter:g} (±σ over trials)")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    return _save(fig, path)


def cumulative_precision(tables: RunTables, clutter: float, model: str, mode: str) -> tuple[np.ndarray, np.ndarray]:
    """(k, mean over trials of ΣTP/Σ(TP+FP) up to k) from steps.csv (§5.5 "precision curves" (i))."""
    s = tables.steps
    m = _sel(s, clutter=clutter, model=model, mode=mode)
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


def fig_precision(tables: RunTables, path: Path, models: tuple[str, ...] = ("soa", "atbm")) -> Path:
    """Fig. 5h: precision curves of S-OA and ATBM at every clutter rate (top: vs time; bottom: sorted per trial)."""
    models = tuple(m for m in models if m in tables.models) or tuple(tables.models[:2])
    modes = tables.modes
    fig = _figure(4.2 * len(modes), 6.5)
    axes = fig.subplots(2, len(modes), squeeze=False)
    clutters = tables.clutters
    widths = np.linspace(0.8, 2.2, max(1, len(clutters)))
    dt = float(tables.meta["config"]["sensor"]["dt"])
    t = tables.trials
    for j, mode in enumerate(modes):
        top, bottom = axes[0, j], axes[1, j]
        for model in models:
            for lam, lw in zip(clutters, widths, strict=False):
                k, p = cumulative_precision(tables, lam, model, mode)
                lab = f"{LABEL.get(model, model)} λ={lam:g}"
                top.plot(k * dt, p, color=MODEL_COLOR.get(model, "k"), lw=lw, label=lab)
                v = t["precision"][_sel(t, clutter=lam, model=model, mode=mode)]
                v = np.sort(v[~np.isnan(v)])[::-1]
                bottom.plot(np.arange(1, v.size + 1), v, color=MODEL_COLOR.get(model, "k"), lw=lw, label=lab)
        top.set_title(f"(h) precision, {mode}")
        top.set_xlabel("time (s)")
        top.set_ylabel("cumulative precision (mean over trials)")
        bottom.set_xlabel("trial rank")
        bottom.set_ylabel("per-trial precision (sorted)")
        for ax in (top, bottom):
            ax.set_ylim(-0.02, 1.02)
            ax.grid(alpha=0.3)
        top.legend(fontsize=7)
    return _save(fig, path)


def fig_delay_hist(tables: RunTables, clutter: float, path: Path, max_bin: int = 10) -> Path:
    """Fig. 6: distribution of per-episode delays per model (counted episodes), one panel per mode.

    Delays are multiples of dt: grouped bars give the share of each model's counted episodes at 0, 1, ...,
    ``max_bin`` scans, and one overflow bar beyond (the long GMBM tail would otherwise flatten every other bar).
    """
    e = tables.episodes
    modes = tables.modes
    models = tables.models
    fig = _figure(5.5 * len(modes), 3.8)
    axes = fig.subplots(1, len(modes), squeeze=False)[0]
    have = bool(e) and "delay" in e and len(e["delay"]) > 0
    dt = float(tables.meta["config"]["sensor"]["dt"])
    x = np.arange(max_bin + 2)
    width = 0.8 / max(len(models), 1)
    for ax, mode in zip(axes, modes, strict=False):
        for i, model in enumerate(models):
            share = np.zeros(max_bin + 2)
            if have:
                m = _sel(e, clutter=clutter, model=model, mode=mode) & (e["censored"] == 0) & ~np.isnan(e["delay"])
                steps = np.rint(e["delay"][m] / dt).astype(int)
                if steps.size:
                    share = np.bincount(np.minimum(steps, max_bin + 1), minlength=max_bin + 2) / steps.size
            ax.bar(
                x + (i - (len(models) - 1) / 2) * width,
                share,
                width,
                label=LABEL.get(model, model),
                color=MODEL_COLOR.get(model, "k"),
            )
        ax.set_xticks(x, [f"{k * dt:g}" for k in range(max_bin + 1)] + [f">{max_bin * dt:g}"])
        ax.set_xlabel("tracking delay k_delay (s)")
        ax.set_ylabel("share of counted episodes")
        ax.set_title(f"Fig. 6: delays, {mode}, λ = {clutter:g}")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3, axis="y")
    return _save(fig, path)


def fig_components(tables: RunTables, clutter: float, path: Path) -> Path:
    """Fig. 7: mean posterior component count per trial per model, one panel per mode."""
    t = tables.trials
    modes = tables.modes
    fig = _figure(4.5 * len(modes), 3.8)
    axes = fig.subplots(1, len(modes), squeeze=False)[0]
    for ax, mode in zip(axes, modes, strict=False):
        for model in tables.models:
            m = _sel(t, clutter=clutter, model=model, mode=mode)
            order = np.argsort(t["trial"][m], kind="stable")
            ax.plot(
                t["trial"][m][order],
                t["mean_components"][m][order],
                "o-",
                ms=2.5,
                lw=1,
                color=MODEL_COLOR.get(model, "k"),
                label=LABEL.get(model, model),
            )
        _integer_ticks(ax)
        ax.set_xlabel("trial")
        ax.set_ylabel("mean posterior components")
        ax.set_title(f"Fig. 7: components, {mode}, λ = {clutter:g}")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    return _save(fig, path)


def make_figures(tables: RunTables, out_dir: Path) -> list[Path]:
    """Every figure of the run (module docstring); returns the written paths."""
    out_dir = Path(out_dir)
    paths: list[Path] = []
    clutters = tables.clutters
    if not clutters:
        return paths
    for lam in clutters:
        sfx = f"_lam{lam:g}" if len(clutters) > 1 else ""
        for model in sorted(tables.models, key=lambda m: LETTER.get(m, "z")):
            paths.append(
                fig_delay(tables, model, lam, out_dir / f"fig5{LETTER.get(model, 'x')}_delay_{model}{sfx}.png")
            )
        paths.append(
            fig_bars(
                tables,
                "card_err",
                "mean abs. cardinality error",
                "(f) cardinality error",
                lam,
                out_dir / f"fig5f_cardinality{sfx}.png",
            )
        )
        paths.append(fig_bars(tables, "ospa", "mean OSPA (m)", "(g) OSPA", lam, out_dir / f"fig5g_ospa{sfx}.png"))
        paths.append(fig_delay_hist(tables, lam, out_dir / f"fig6_delay_hist{sfx}.png"))
        paths.append(fig_components(tables, lam, out_dir / f"fig7_components{sfx}.png"))
    paths.append(fig_precision(tables, out_dir / "fig5h_precision.png"))
    return paths
