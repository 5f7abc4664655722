"""S-OA's paired advantage over each baseline per cell of an atlas, with false-discovery control (§5.10).

A *cell* is one value of one axis, or one value pair of two axes; the other axes are pooled. Inside a trial the
points of a cell share the SUMO run (common random numbers), so the unit of replication is the trial: per trial n
the paired differences of every pooled point (and clutter rate, when the base configuration gives several) are
averaged first, then the N per-trial values give a mean and a t-interval. The metrics, each oriented so that a
positive advantage means S-OA is better:

* ``delay_win``: delay win share, the share of paired runs in which S-OA's mean tracking delay is below the
  baseline's (ties count one half; a run without episodes is left out); no advantage at 1/2;
* ``card_red`` / ``ospa_red``: cardinality-error and OSPA reduction, ``100 * mean(X - S-OA) / mean(X)`` (%);
* ``dhota``: ΔHOTA = HOTA(S-OA) - HOTA(X) (only where the tracker gives labels).

Each cell's two-sided one-sample t-test of "no advantage" gives a p-value; the Benjamini-Hochberg procedure at
q = 0.05 over every cell of one metric and baseline (all one-axis and two-axis cells together) marks the
discoveries, and each discovery's interval is widened to the false-coverage-rate level 1 - R q / m
(Benjamini & Yekutieli 2005: R discoveries among m cells), which excludes the no-advantage value exactly for the
marked cells.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from soabench.types import ATLAS_METRICS as METRICS
from soabench.types import ATLAS_NULL as NULL
from soabench.types import AtlasCell as Cell

Q = 0.05  #: false-discovery rate of the markers
REFERENCE = "soa"


def _clean(x: str) -> str:
    """SQL: ``x`` with NaN as NULL (averages skip it)."""
    return f"(CASE WHEN isnan({x}) THEN NULL ELSE {x} END)"


def paired_units(con, axes: Sequence[str], baselines: Sequence[str]) -> bool:
    """Create the DuckDB table ``units``: per (point, clutter, mode, family, trial) and baseline, the oriented
    per-run values of each metric (delay_win, card_d, card_b, ospa_d, ospa_b, dhota) beside the axis columns.

    ``con``: a connection with the view ``trials`` (:func:`soabench.experiment.campaigns.atlas.query.connect`).
    Returns False when no run of S-OA has a paired baseline run.
    """
    keys = ("point", "clutter", "mode", "family", "trial")
    extra = [a for a in axes if a not in keys]
    names = ", ".join("'" + b.replace("'", "''") + "'" for b in baselines) or "''"
    ax = "".join(f', s."{a}"' for a in extra)
    have = {r[0] for r in con.execute("DESCRIBE trials").fetchall()}

    def col(name: str, side: str) -> str:  # a metric a trial kind does not write is missing (NULL)
        return _clean(f"{side}.{name}") if name in have else "CAST(NULL AS DOUBLE)"

    ds, db = col("delay_mean", "s"), col("delay_mean", "b")
    con.execute(
        f"""CREATE TEMP TABLE units AS
        SELECT b.model AS baseline, s.point, s.clutter, s.mode, s.family, s.trial{ax},
            CASE WHEN {ds} IS NULL OR {db} IS NULL THEN NULL WHEN {db} > {ds} THEN 1.0
                 WHEN {db} < {ds} THEN 0.0 ELSE 0.5 END AS delay_win,
            {col("card_err", "b")} - {col("card_err", "s")} AS card_d, {col("card_err", "b")} AS card_b,
            {col("ospa", "b")} - {col("ospa", "s")} AS ospa_d, {col("ospa", "b")} AS ospa_b,
            {col("hota", "s")} - {col("hota", "b")} AS dhota
        FROM (SELECT * FROM trials WHERE model = '{REFERENCE}') s
        JOIN (SELECT * FROM trials WHERE model IN ({names})) b USING (point, clutter, mode, family, trial)"""
    )
    return con.execute("SELECT count(*) FROM units").fetchone()[0] > 0


def _t_interval(x: np.ndarray, null: float, level: float = 0.95) -> tuple[float, float, float, float]:
    """(mean, low, high, two-sided p of mean = null) of per-trial values ``x`` (finite)."""
    from scipy import stats

    n = len(x)
    m = float(np.mean(x)) if n else math.nan
    if n < 2:
        return m, math.nan, math.nan, math.nan
    se = float(np.std(x, ddof=1)) / math.sqrt(n)
    if se == 0.0:  # every trial agrees: the sign is certain unless it is the null itself
        return m, m, m, (1.0 if m == null else 0.0)
    t = stats.t.ppf(0.5 + level / 2, n - 1)
    p = float(2 * stats.t.sf(abs(m - null) / se, n - 1))
    return m, m - t * se, m + t * se, p


PER_TRIAL = ("delay_win", "card_d", "card_b", "ospa_d", "ospa_b", "dhota")


def cell_stats(con, cells_of: Sequence[tuple[str, ...]]) -> list[Cell]:
    """Every cell (one axis, or a pair) of every metric, baseline, mode and family, with the FDR decision; reads
    the table ``units`` of :func:`paired_units` (per-trial means in SQL, the t-intervals here)."""
    cells: list[Cell] = []
    for combo in cells_of:
        group = ["baseline", "mode", "family", *(f'"{a}"' for a in combo)]
        means = ", ".join(f"avg({c}) AS {c}" for c in PER_TRIAL)
        rows = con.execute(
            f"SELECT {', '.join(group)}, trial, {means} FROM units GROUP BY ALL ORDER BY {', '.join(group)}, trial"
        ).fetchall()
        n_key = len(group)
        for key, trial_rows in itertools.groupby(rows, key=lambda r: r[:n_key]):
            b, mode, fam, *vals = key
            arr = np.array([[np.nan if v is None else float(v) for v in r[n_key + 1 :]] for r in trial_rows])
            col = {c: arr[:, i] for i, c in enumerate(PER_TRIAL)}
            for metric in METRICS:
                scale = 1.0
                if metric in ("card_red", "ospa_red"):
                    name = metric[:4]
                    x, base = col[f"{name}_d"], col[f"{name}_b"]
                    ok = np.isfinite(x) & np.isfinite(base)
                    x, base_mean = x[ok], float(base[ok].mean()) if ok.any() else math.nan
                    scale = 100.0 / base_mean if base_mean > 0 else math.nan
                else:
                    x = col[metric][np.isfinite(col[metric])]
                if len(x) == 0 or not math.isfinite(scale):
                    continue
                m, lo, hi, p = _t_interval(x, NULL[metric] if metric == "delay_win" else 0.0)
                if metric == "delay_win":  # a share: its interval inside [0, 1] (the p-value is the t-test's)
                    lo, hi = max(lo, 0.0), min(hi, 1.0)
                cells.append(
                    Cell(metric, b, mode, fam, tuple(combo), tuple(vals), len(x), m * scale, lo * scale, hi * scale, p)
                )
    _fdr(cells)
    return cells


def _fdr(cells: list[Cell]) -> None:
    """Benjamini-Hochberg per (metric, baseline, mode, family) and the false-coverage-adjusted intervals."""
    from scipy import stats

    groups: dict[tuple, list[Cell]] = {}
    for c in cells:
        groups.setdefault((c.metric, c.baseline, c.mode, c.family), []).append(c)
    for family_cells in groups.values():
        tested = [c for c in family_cells if math.isfinite(c.p)]
        m = len(tested)
        if not m:
            continue
        order = sorted(tested, key=lambda c: c.p)
        r = 0
        for i, c in enumerate(order, start=1):
            if c.p <= Q * i / m:
                r = i
        for c in order[:r]:
            c.significant = True
            level = 1 - r * Q / m
            if c.high == c.low:  # no spread: the interval is the point
                c.adj_low, c.adj_high = c.low, c.high
                continue
            t95 = stats.t.ppf(0.975, c.n - 1)
            ta = stats.t.ppf(0.5 + level / 2, c.n - 1)
            half = (c.high - c.low) / 2 * ta / t95
            c.adj_low, c.adj_high = c.estimate - half, c.estimate + half


def axis_pairs(axes: Sequence[str]) -> list[tuple[str, str]]:
    """Every pair of axes with at least two values each (in design order)."""
    return list(itertools.combinations(axes, 2))
