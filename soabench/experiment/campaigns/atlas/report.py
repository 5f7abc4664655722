"""An atlas's report: the cells' statistics, the phase diagrams, the cells named in words, one page (§5.10).

Written into ``report/`` of the atlas from its Parquet dataset alone (so it can be redrawn at any time, and an
unfinished atlas is reported on the trials it has): ``cells.csv`` (every cell of :mod:`.stats`),
``pairs_<x>__<y>_<metric>.png`` (one heatmap panel per baseline), ``axes_<metric>.png`` (the one-axis curves),
``summary.md`` (the words and the tables) and ``index.html``.
"""

from __future__ import annotations

import csv
import html
import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from soabench.atomic import write_text_atomic
from soabench.experiment.campaigns.atlas import stats, store
from soabench.experiment.campaigns.atlas.stats import METRICS, NULL


def axis_label(key: str) -> str:
    """A readable axis name with units."""
    return {
        "parking.density": "parked cars / 100 m",
        "pedestrians.count": "pedestrians",
        "vehicles.count": "vehicles",
        "experiment.clutter": "clutter λ (per scan)",
        "sensor.p_D": "detection probability p_D",
        "filter.p_D": "filter's p_D",
        "birth.N_hat": "N̂ (births per scan)",
        "birth.N_hat_offset": "N_tot offset from the true count",
        "net": "scene",
        "filters": "filter family",
        "clutter": "clutter λ (per scan)",
    }.get(key, key)


def analysed_axes(con, meta: dict) -> tuple[list[str], dict[str, str]]:
    """The axes with two values or more among the trial rows (their column names) and column -> axis key; a base
    configuration with several clutter rates (and no clutter axis) adds ``clutter``."""
    col_of = {a["key"].replace(".", "_"): a["key"] for a in meta["design"]["axes"]}
    have = {r[0] for r in con.execute("DESCRIBE trials").fetchall()}
    varying = [
        c for c in col_of if c in have and con.execute(f'SELECT count(DISTINCT "{c}") FROM trials').fetchone()[0] >= 2
    ]
    if (
        "experiment_clutter" not in col_of
        and con.execute("SELECT count(DISTINCT clutter) FROM trials").fetchone()[0] >= 2
    ):
        varying.append("clutter")
        col_of["clutter"] = "clutter"
    return varying, col_of


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def _where(cell: stats.Cell, col_of: dict[str, str]) -> str:
    return " and ".join(f"{col_of.get(a, a)} = {_fmt(v)}" for a, v in zip(cell.axes, cell.values, strict=True))


def _value(c: stats.Cell) -> str:
    unit = "" if c.metric in ("delay_win", "dhota") else " %"
    digits = ".2f" if c.metric in ("delay_win", "dhota") else ".0f"
    return f"{c.estimate:{digits}}{unit} [{c.low:{digits}}, {c.high:{digits}}]"


def _sig(c: stats.Cell) -> str:
    if not c.significant:
        return ", not significant"
    return ", significantly better" if c.estimate > NULL[c.metric] else ", significantly worse"


def words(cells: Sequence[stats.Cell], col_of: dict[str, str], label: Any) -> list[str]:
    """The cells a user would look at first, per baseline and metric, in sentences: how many two-axis cells show a
    significant advantage or disadvantage, and where the advantage is largest and smallest."""
    lines = []
    pairs = [c for c in cells if len(c.axes) == 2]
    use = pairs or [c for c in cells if len(c.axes) == 1]
    keys = sorted({(c.baseline, c.mode, c.family) for c in use})
    for b, mode, fam in keys:
        parts = []
        for metric in ("delay_win", "ospa_red", "card_red", "dhota"):
            sel = [c for c in use if (c.baseline, c.mode, c.family, c.metric) == (b, mode, fam, metric)]
            if not sel:
                continue
            null = NULL[metric]
            good = sum(c.significant and c.estimate > null for c in sel)
            bad = sum(c.significant and c.estimate < null for c in sel)
            best = max(sel, key=lambda c: c.estimate)
            worst = min(sel, key=lambda c: c.estimate)
            verdict = (
                "pays off in every cell"
                if good == len(sel)
                else "is worse in every cell"
                if bad == len(sel)
                else f"pays off in {good} of {len(sel)} cells and is worse in {bad}"
            )
            parts.append(
                f"{METRICS[metric]}: S-OA {verdict} (significant after BH-FDR); largest when {_where(best, col_of)} "
                f"({_value(best)}{_sig(best)}), smallest when {_where(worst, col_of)} ({_value(worst)}{_sig(worst)})."
            )
        if parts:
            lines.append(f"**S-OA vs {label(b)}** ({mode}, {fam}):")
            lines.append("")
            lines += [f"- {p}" for p in parts]
            lines.append("")
    return lines


def write_report(root: Path) -> str:
    """Write ``report/`` (module docstring) and return the summary (Markdown)."""
    root = Path(root)
    meta = store.read_meta(root)
    from soabench.birth import LABEL
    from soabench.experiment.campaigns.atlas.query import connect

    def label(m: str) -> str:
        return LABEL.get(m, m)

    out = root / "report"
    out.mkdir(exist_ok=True)
    con = connect(root, threads=1)  # sums in row order: the same cells bit for bit, whatever the layout
    try:
        varying, col_of = analysed_axes(con, meta)
        models = {r[0] for r in con.execute("SELECT DISTINCT model FROM trials").fetchall()}
        per_point = [r[0] for r in con.execute("SELECT count(DISTINCT trial) FROM trials GROUP BY point").fetchall()]
        baselines = [m for m in meta["config"]["experiment"]["models"] if m != stats.REFERENCE and m in models]
        paired = stats.REFERENCE in models and bool(baselines) and stats.paired_units(con, varying, baselines)
        combos: list[tuple[str, ...]] = [(a,) for a in varying] + list(stats.axis_pairs(varying))
        cells = stats.cell_stats(con, combos) if paired else []
    finally:
        con.close()
    n_points = len(meta["points"])
    n_min, n_max = (min(per_point), max(per_point)) if per_point else (0, 0)
    complete = n_min == meta["trials"] and len(per_point) == n_points
    head = [
        f"# Atlas: {meta['net']}",
        "",
        f"{n_points} points ({meta['design']['kind']} design over "
        + ", ".join(f"{a['key']}" for a in meta["design"]["axes"])
        + f"), {meta['trials']} trials per point planned; "
        + (
            "complete."
            if complete
            else f"**incomplete**: {len(per_point)} points have trials, {n_min} to {n_max} trials per point."
        ),
        "",
    ]
    if not paired:
        md = "\n".join([*head, "No paired statistics: the atlas needs S-OA and at least one baseline."]) + "\n"
        write_text_atomic(out / "summary.md", md)
        return md
    _write_cells(out / "cells.csv", cells, col_of)
    figures = _draw(out, cells, varying, col_of, baselines, label)
    body = [
        "S-OA's paired advantage over each baseline per cell (the other axes pooled; the trial is the unit: "
        "per-trial means of the paired differences, t-intervals). A cell is **significant** when its false-coverage-"
        f"adjusted interval excludes no advantage after Benjamini-Hochberg at q = {stats.Q:g} over the cells of one "
        "metric and baseline. Every cell: `cells.csv`.",
        "",
        *words(cells, col_of, label),
    ]
    one = [c for c in cells if len(c.axes) == 1]
    if one:
        body += [
            "## One axis at a time",
            "",
            "| baseline | metric | axis | value | n | estimate [95 % CI] | significant |",
        ]
        body.append("|---|---|---|---|---:|---|---|")
        for c in one:
            body.append(
                f"| {label(c.baseline)} | {METRICS[c.metric]} | {col_of.get(c.axes[0], c.axes[0])} | "
                f"{_fmt(c.values[0])} | {c.n} | {_value(c)} | {'yes' if c.significant else 'no'} |"
            )
        body.append("")
    body += ["## Figures", ""] + [f"- `{f.name}`: {cap}" for f, cap in figures]
    md = "\n".join([*head, *body]) + "\n"
    write_text_atomic(out / "summary.md", md)
    _write_index(out, meta, md, figures)
    return md


def _write_cells(path: Path, cells: Sequence[stats.Cell], col_of: dict[str, str]) -> None:

    buf = io.StringIO()
    rows = [c.as_row() for c in cells]
    for r in rows:
        r["axis_x"] = col_of.get(r["axis_x"], r["axis_x"])
        r["axis_y"] = col_of.get(r["axis_y"], r["axis_y"]) if r["axis_y"] else ""
    if rows:
        w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    write_text_atomic(path, buf.getvalue())


def _draw(out: Path, cells, varying, col_of, baselines, label) -> list[tuple[Path, str]]:
    # imported when called: matplotlib would slow every start-up
    from soabench.figures.atlas import axis_curves, pair_heatmaps
    from soabench.figures.style import save_png, style

    figs: list[tuple[Path, str]] = []
    names = {c: axis_label(col_of.get(c, c)) for c in varying}
    keys = sorted({(c.mode, c.family) for c in cells})
    for mode, fam in keys:
        tag = "" if len(keys) == 1 else f"_{mode}_{fam}".replace("+", "-")
        sel = [c for c in cells if (c.mode, c.family) == (mode, fam)]
        for metric in METRICS:
            msel = [c for c in sel if c.metric == metric]
            if not msel:
                continue
            for x, y in stats.axis_pairs(varying):
                pc = [c for c in msel if c.axes == (x, y)]
                if not pc:
                    continue
                path = out / f"pairs_{x}__{y}_{metric}{tag}.png"
                with style():
                    save_png(pair_heatmaps(pc, x, y, names, baselines, label, metric), path)
                figs.append((path, f"{METRICS[metric]} over {names[x]} × {names[y]} ({mode}, {fam})"))
            ac = [c for c in msel if len(c.axes) == 1]
            if ac:
                path = out / f"axes_{metric}{tag}.png"
                with style():
                    save_png(axis_curves(ac, varying, names, baselines, label, metric), path)
                figs.append((path, f"{METRICS[metric]} along each axis ({mode}, {fam})"))
    return figs


def _write_index(out: Path, meta: dict, md: str, figures) -> None:
    """``index.html``: the summary and every figure on one page (no script, no external resource)."""
    try:
        from markdown_it import MarkdownIt

        body = MarkdownIt("commonmark").enable("table").render(md)
    except ImportError:  # pragma: no cover - plain text
        body = f"<pre>{html.escape(md)}</pre>"
    figs = "\n".join(
        f'<figure><img src="{html.escape(p.name)}" alt="{html.escape(cap)}" style="max-width:100%">'
        f"<figcaption>{html.escape(cap)}</figcaption></figure>"
        for p, cap in figures
    )
    page = (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>Atlas: {html.escape(str(meta['net']))}</title>"
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 6px}</style></head><body>\n"
        f"{body}\n{figs}\n</body></html>\n"
    )
    write_text_atomic(out / "index.html", page)
