"""The filter families side by side (docs/user-guide/outputs.md "Filter families"; docs/method.md "LMB filter").

A run that names filter families (``experiment.filters``, e.g. ``--filters gmphd,lmb``) gets, beside the paper's
figures of its GM-PHD family, ``figures/families.png`` (``families_lam<λ>.png`` per clutter rate when it has
several): three panels, (a) the mean tracking delay k̄ (s), (b) the mean absolute cardinality error (targets) and
(c) the mean OSPA (m), per birth model (colour) and family (plain bars GM-PHD, hatched LMB), mean ± σ over trials
with every trial as a dot, in the static mode, the one mode every family runs (§4.6).

The paper's figures of the GM-PHD family are drawn on that family's rows only (:func:`in_family`).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from soabench.config import FAMILIES
from soabench.experiment.reports.tables import RunTables, select
from soabench.experiment.trial.trial import FILTER_COLUMN
from soabench.figures import style as ps
from soabench.figures.bars import grouped_bars
from soabench.figures.drawing import FigureJob
from soabench.figures.gaps import identity_gaps_figure
from soabench.figures.tracks import has_labels

#: how a figure names a filter family (the registry's labels, :data:`soabench.config.FAMILIES`)
FAMILY_LABEL = {name: f.label for name, f in FAMILIES.items()}
#: the bar hatch of a family (the registry's: the GM-PHD plain, the others hatched)
FAMILY_HATCH = {name: f.hatch for name, f in FAMILIES.items()}
#: the mode every family runs (soabench.config.FAMILY_MODES)
SHARED_MODE = "static"
#: the panels: (trials.csv column, y label, title)
PANELS = (
    ("delay_mean", "mean tracking delay k̄ (s)", "tracking delay"),
    ("card_err", "mean abs. cardinality\nerror (targets)", "cardinality error"),
    ("ospa", "mean OSPA (m)", "OSPA"),
)


def run_families(tables: RunTables) -> list[str]:
    """The filter families of the run's rows, in the config's order ([] for a run without a ``filter`` column)."""
    if FILTER_COLUMN not in tables.trials:
        return []
    present = set(tables.trials[FILTER_COLUMN]) - {""}  # a whole tracker's rows belong to no family
    named = tables.meta["config"]["experiment"].get("filters", [])
    return [f for f in named if f in present] + sorted(present - set(named))


def family_only(tables: RunTables, family: str) -> RunTables:
    """The tables of one family: its rows of trials, episodes, timing and steps, and the rows of no family (whole
    trackers, drawn beside every family)."""

    def only(table):
        if FILTER_COLUMN not in table:
            return table
        keep = (table[FILTER_COLUMN] == family) | (table[FILTER_COLUMN] == "")
        return {c: table[c][keep] for c in table}

    return dataclasses.replace(
        tables, trials=only(tables.trials), episodes=only(tables.episodes), timing=only(tables.timing),
        steps=only(tables.steps),
    )  # fmt: skip


def in_family(tables: RunTables, family: str, build, *args) -> Figure:
    """``build(tables of family, *args)``: a figure of the paper drawn on one family's rows (a figure job's builder,
    so that the workers that draw it from the whole run's tables draw it on that family's rows too)."""
    return build(family_only(tables, family), *args)


def families_figure(tables: RunTables, clutter: float) -> Figure:
    """Delay, cardinality error and OSPA per birth model and family, static mode (module docstring)."""

    t = tables.trials
    fams = run_families(tables)
    models = [m for m in tables.models if any(select(t, model=m)[t[FILTER_COLUMN] != ""])]
    with ps.style():
        fig = ps.figure("double", 2.7)
        axes = fig.subplots(1, len(PANELS))
        for ax, letter, (column, ylabel, title) in zip(axes, ps.letters(len(PANELS)), PANELS, strict=True):

            def values(model: str, fam: str, column: str = column):
                keep = select(t, clutter=clutter, model=model, mode=SHARED_MODE) & (t[FILTER_COLUMN] == fam)
                return t[column][keep]

            grouped_bars(ax, models, fams, values, hatch=lambda fam: FAMILY_HATCH.get(fam, "xx"))
            if column == "ospa":
                c = float(tables.meta["config"].get("metrics", {}).get("ospa_c", math.nan))
                if math.isfinite(c):
                    ax.axhline(c, color="k", ls=":", lw=1.0)
                    ax.set_ylim(0, c * 1.05)
            ax.set_ylim(bottom=0)
            ax.set_ylabel(ylabel)
            ax.set_xticks(range(len(models)), [ps.model_label(m) for m in models], rotation=35, ha="right")
            if not any(np.isfinite(values(m, f)).any() for m in models for f in fams):
                ax.text(0.5, 0.5, "no value in any trial", transform=ax.transAxes, ha="center", color="0.4")
            ps.panel_title(ax, letter, title)

        handles = [
            Patch(facecolor="white", edgecolor="k", hatch=FAMILY_HATCH.get(f, "xx"), label=FAMILY_LABEL.get(f, f))
            for f in fams
        ]
        fig.suptitle(
            f"Filter families, static probabilities, λ = {clutter:g} (mean ± σ over trials; dots: trials"
            + ("; dotted: OSPA cut-off c)" if "ospa" in t else ")"),
            fontsize=ps.RC["axes.titlesize"],
        )
        fig.legend(handles=handles, loc="outside lower center", ncol=len(handles))
    return fig


def family_jobs(tables: RunTables, out_dir: Path) -> list[FigureJob]:
    """The families figure of each clutter rate (module docstring), as figure jobs."""
    clutters = tables.clutters
    jobs = []
    for lam in clutters:
        sfx = f"_lam{lam:g}" if len(clutters) > 1 else ""
        jobs.append(FigureJob(Path(out_dir) / f"families{sfx}.png", families_figure, (lam,), weight=1.5))
        if has_labels(tables):
            name = f"identity_gaps_families{sfx}.png"
            jobs.append(FigureJob(Path(out_dir) / name, identity_gaps_by_family, (lam,), weight=2.0))
    return jobs


def identity_gaps_by_family(tables: RunTables, clutter: float) -> Figure:
    """:func:`soabench.figures.gaps.identity_gaps_figure` with one row per filter family."""
    rows = [(FAMILY_LABEL.get(f, f), family_only(tables, f)) for f in run_families(tables)]
    return identity_gaps_figure(tables, clutter, rows)
