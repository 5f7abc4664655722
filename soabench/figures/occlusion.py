"""The figure of ``soabench sweep occlusion`` (``sweep_occlusion.png``): delay, cardinality error and OSPA against the
parked-car density, in the package style."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from soabench.experiment.reports.paper import read_rows
from soabench.figures import style as ps
from soabench.figures.bars import mean_ci


def _trial_values(
    sweep_dir: Path, points: list[dict], clutter: float, family: str | None = None
) -> dict[tuple, np.ndarray]:
    """Per-trial values of the figure's metrics per (density, model, mode, column), from each point's trials.csv
    (the rows of filter family ``family``; None: a run without a ``filter`` column)."""

    out: dict[tuple, list[float]] = {}
    for p in points:
        for r in read_rows(sweep_dir / "points" / p["name"] / "trials.csv"):
            if float(r["clutter"]) != clutter or r.get("filter") != family:
                continue
            for col, _ in _PANELS:
                out.setdefault((float(p["value"]), str(r["model"]), str(r["mode"]), col), []).append(float(r[col]))
    return {k: np.asarray(v, dtype=float) for k, v in out.items()}


#: (trials.csv column, axis label) per panel of sweep_occlusion.png
_PANELS = (
    ("delay_mean", "mean tracking delay k̄ (s)"),
    ("card_err", "mean cardinality error (targets)"),
    ("ospa", "mean OSPA (m)"),
)


def occlusion_figure(sweep_dir: Path, points: list[dict], rows: list[dict], family: str | None = None) -> Figure:
    """Delay, cardinality error and OSPA per birth model and mode against the parked-car density, mean over trials
    with its 95 % confidence interval (Student t) as error bars (one style module); ``family``: the filter family
    drawn (None: a run without a ``filter`` column)."""
    models = list(dict.fromkeys(r["model"] for r in rows))
    modes = list(dict.fromkeys(r["mode"] for r in rows))
    values = _trial_values(sweep_dir, points, float(rows[0]["clutter"]), family) if rows else {}
    densities = sorted({float(r["density"]) for r in rows})
    n_series = max(1, len(models) * len(modes))
    span = 0.012 * (densities[-1] - densities[0] if len(densities) > 1 else 1.0)  # offsets keep the bars apart
    with ps.style():
        fig = ps.figure("double", 2.6)
        axes = fig.subplots(1, 3, sharex=True)  # one density axis (a point without episodes has no delay)
        for ax, letter, (col, ylabel) in zip(axes, ps.letters(3), _PANELS, strict=True):
            for i, (model, mode) in enumerate((a, b) for a in models for b in modes):
                st = ps.model_style(model)
                pts = [
                    (d, *mean_ci(values[(d, model, mode, col)])) for d in densities if (d, model, mode, col) in values
                ]
                if not pts:
                    continue
                x, mu, half = (np.array(c, dtype=float) for c in zip(*pts, strict=True))
                ax.errorbar(
                    x + (i - (n_series - 1) / 2) * span,
                    mu,
                    yerr=np.nan_to_num(half),
                    fmt=st.marker,
                    ls=ps.mode_style(mode).linestyle,
                    ms=3,
                    color=st.color,
                    mfc=st.color if mode == "static" else "white",
                    elinewidth=0.7,
                    capsize=2,
                )
            ax.set_xlabel("parked cars per 100 m of kerb")
            ax.set_ylabel(ylabel)
            ax.set_ylim(bottom=0)
            ps.panel_title(ax, letter, ylabel.split(" (")[0])
        ps.legend_below(
            fig, ps.model_handles(models) + ps.mode_handles(modes), ncol=4, title="error bars: 95% CI over trials"
        )
    return fig
