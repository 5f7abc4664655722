"""The KITTI protocol's figures (paper Figs. 6-8, §V; docs/method.md §5.9), in the package style
(:mod:`soabench.figures.style`), from the numbers :mod:`soabench.experiment.campaigns.kitti.report` computes."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from soabench.figures import style as ps


def delay_histogram(delays: Mapping[str, np.ndarray], censored: Mapping[str, int], dt: float, path: Path) -> str:
    """Fig. 6: histogram of the per-target delays (s), grouped bars per model; the legend counts the episodes and
    those never initiated. Returns the file name."""
    models = list(delays)
    top = max([float(d.max()) for d in delays.values() if len(d)] + [dt])
    step = dt * max(1, math.ceil(top / dt / 15))  # at most ~16 bins, each a whole number of frames
    bins = (np.arange(int(round(top / step)) + 2) - 0.5) * step  # centred on 0, step, 2 step, ...
    width = step / (len(models) + 1)
    with ps.style():
        fig = ps.figure("double", 2.8)
        ax = fig.add_subplot()
        for i, m in enumerate(models):
            counts, _ = np.histogram(delays[m], bins)
            label = f"{ps.model_label(m)} (n = {len(delays[m])}, {censored[m]} never initiated)"
            ax.bar(bins[:-1] + (i + 1) * width, counts, width, label=label, color=ps.model_style(m).color)
        ax.yaxis.get_major_locator().set_params(integer=True)
        ax.set_xlabel("tracking delay $k_{delay}$ (s)")
        ax.set_ylabel("number of targets")
        ps.panel_title(ax, None, "tracking delays of all target episodes (paper Fig. 6)")
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, frameon=False)  # below: never over a bar
        ax.grid(axis="y", alpha=0.3)
    return ps.save_png(fig, path).name


def components_per_sequence(seqs: Sequence[str], components: Mapping[str, Sequence[float]], path: Path) -> str:
    """Fig. 7: mean posterior components per sequence, grouped bars per model. Returns the file name."""
    models = list(components)
    width = 0.8 / len(models)
    x = np.arange(len(seqs))
    with ps.style():
        fig = ps.figure(max(ps.DOUBLE, 0.3 * len(seqs) + 1.5), 2.8)
        ax = fig.add_subplot()
        for i, m in enumerate(models):
            offset = (i - (len(models) - 1) / 2) * width
            ax.bar(x + offset, components[m], width, label=ps.model_label(m), color=ps.model_style(m).color)
        ax.set_xticks(x, list(seqs), rotation=90 if len(seqs) > 8 else 0)
        ax.set_xlabel("sequence")
        ax.set_ylabel("mean posterior components")
        ps.panel_title(ax, None, "components of the posterior intensity (paper Fig. 7)")
        ax.set_ylim(0, 1.25 * ax.get_ylim()[1])
        ax.legend(ncols=len(models), loc="upper center")
        ax.grid(axis="y", alpha=0.3)
    return ps.save_png(fig, path).name


def nhat_sweep(sweep: Mapping[str, Mapping], path: Path) -> str:
    """Fig. 8: mean delay against the N-hat offset per model, the std of the means in the legend. Returns the file
    name."""
    with ps.style():
        fig = ps.figure("double", 2.8)
        ax = fig.add_subplot()
        for m, s in sweep.items():
            st = ps.model_style(m)
            ax.plot(
                s["offsets"], s["mean_delay"], marker=st.marker, ms=3, color=st.color,
                label=f"{ps.model_label(m)} (std of means {s['std_of_means']:.3f} s)",
            )  # fmt: skip
        ax.xaxis.get_major_locator().set_params(integer=True)
        ax.set_xlabel(r"$N_{tot} - N_{true}$ (expected births per sequence)")
        ax.set_ylabel(r"mean delay $\bar{k}_{delay}$ (s)")
        ps.panel_title(ax, None, r"sensitivity to $\hat{N}_k$ (paper Fig. 8)")
        ax.legend()
        ax.grid(alpha=0.3)
    return ps.save_png(fig, path).name
