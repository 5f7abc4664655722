"""``report.html`` of a run folder and ``index.html`` of a folder of runs (docs/user-guide/replay.md).

A run's page is rendered from what the folder holds, nothing re-run: ``summary.json`` (tables, paired counts, the
Tracks table, failures, and any further section it carries, shown as a generic table), ``trials.csv`` (the
headline: the winner of each metric and S-OA's paired differences with their 95 % intervals,
:mod:`soabench.experiment.reports.headline`; the models' means with their intervals), ``figures/*.png`` and
``run.json`` (the provenance, folded). Its first screen answers "who wins, by how much, how sure": the headline
table, the trade-offs in one sentence each and the forest plot ``figures/paired.png``.

Figures are embedded as PNG data URIs (a run folder's page is one file to share) or, for the pages written over a
folder of runs such as ``results/`` (``embed=False``), linked to the files beside them. Index pages render the
folder's Markdown files with markdown-it-py (tables, code, links, images; raw HTML escaped). Every value read from
the folder is escaped; the page runs only its own small script (sortable tables, figures enlarged on a click).
"""

from __future__ import annotations

import base64
import csv
import html
import json
import math
import posixpath
import re
import shlex
import sys
from collections.abc import Iterable, Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import numpy as np
from markdown_it import MarkdownIt

from soabench.atomic import write_text_atomic
from soabench.birth import LABEL
from soabench.errors import SoabenchError, require
from soabench.experiment.reports.headline import METRICS, Headline, Metric, headline, mean_interval
from soabench.experiment.reports.report import FAMILY_LABEL, families, family_tables, paper_section, table_legend
from soabench.experiment.reports.tables import RunTables, load_tables, select
from soabench.experiment.runs.runmeta import validate_run_meta
from soabench.experiment.runs.store import FORMAT_VERSION, RUN_FILE, RunStore
from soabench.folders import check_out_file, resolve
from soabench.tracks.report import ABSENT, TRACKS_LEGEND

GENERATOR = "soabench report"
REPORT_FILE = "report.html"
INDEX_FILE = "index.html"
REPLAYS_DIR = "replays"
#: the forest plot of S-OA's paired differences (soabench.figures.forest), shown in the headline
PAIRED_FIGURE = "paired.png"
_MARKER = f'<meta name="generator" content="{GENERATOR}">'
#: summary.json keys this page shows in its own sections; any other key gets a generic section
_KNOWN = {
    "net", "net_name", "polys", "scenario", "scenario_config", "config", "versions", "platform",
    "reproduction_tolerance", "warnings", "n_trials", "n_ok", "complete", "failures", "results", "timing",
    "figures", "model_failures",
}  # fmt: skip
_KNOWN_RESULT = {"clutter", "models", "vs_soa", "warning", "tracks", "filter"}


# ------------------------------------------------------------------------------------------------ helpers
def shown_path(path: Path) -> str:
    """``path`` relative to the working folder when it lies below it (a page written from a repository's root names
    ``results/...``, not the machine's absolute path), else absolute."""
    try:
        return path.relative_to(Path.cwd().resolve()).as_posix() or "."
    except ValueError:
        return str(path)


def write_page(target: Path, text: str) -> int:
    """Write ``text`` to ``target`` (atomically) unless the file holds exactly that already, so writing the pages
    of a finished folder again leaves them untouched; returns the size in bytes."""
    data = text.encode("utf-8")
    try:
        if target.is_file() and target.stat().st_size == len(data) and target.read_bytes() == data:
            return len(data)
    except OSError:
        pass
    write_text_atomic(target, text)
    return len(data)


def replay_file(trial: int) -> str:
    """The file name of trial ``trial``'s replay page under ``replays/``."""
    return f"trial_{int(trial):05d}.html"


def asset(name: str) -> str:
    """The page's stylesheet or script, shipped beside this module (package data)."""

    return resources.files("soabench.experiment.reports").joinpath(name).read_text(encoding="utf-8")


def _e(x: Any) -> str:
    return html.escape(str(x))


def _label(model: str) -> str:
    return _e(LABEL.get(model, model))


def _num(x: Any, nd: int = 3) -> str:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return "n/a"
    return f"{x:.{nd}f}".replace("-", "−") if math.isfinite(x) else "n/a"


def _cell(main: str, *sub: str, cls: str = "") -> str:
    """A table cell: the value, and smaller lines below it (its interval, a count), each kept on one line."""
    lines = "".join(f'<span class="s">{x}</span>' for x in sub if x)
    return f'<td class="{cls}"><span class="v">{main}</span>{lines}</td>'


def _table(head: Sequence[str], rows: Iterable[str], cls: str = "sortable") -> str:
    th = "".join(f"<th>{h}</th>" for h in head)
    return (f'<div class="wrap"><table class="{cls}"><thead><tr>{th}</tr></thead><tbody>{"".join(rows)}'
            "</tbody></table></div>")  # fmt: skip


# ------------------------------------------------------------------------------------------------ Markdown
def _markdown() -> MarkdownIt:
    """CommonMark with pipe tables; raw HTML in the text is shown escaped, not inserted."""
    return MarkdownIt("commonmark", {"html": False}).enable("table")


def _relative(url: str, base: str, anchors: Mapping[str, str]) -> str:
    """A link or image address of a Markdown file in folder ``base`` (relative to the page) as seen from the page:
    a Markdown file rendered on the same page becomes its section's anchor."""
    parts = urlsplit(url)
    if parts.scheme or parts.netloc or url.startswith(("#", "/")) or not parts.path:
        return url
    path = posixpath.normpath(posixpath.join(base, parts.path)) if base not in ("", ".") else posixpath.normpath(
        parts.path)  # fmt: skip
    if path in anchors and not parts.fragment:
        return f"#{anchors[path]}"
    return path + (f"#{parts.fragment}" if parts.fragment else "")


def markdown_html(md: str, base: str = ".", anchors: Mapping[str, str] | None = None) -> str:
    """Markdown as HTML (markdown-it-py: headings, pipe tables made sortable, code, lists, links, images); relative
    links and images are rewritten from the Markdown file's folder ``base`` to the page's."""
    renderer = _markdown()
    tokens = renderer.parse(md)
    anchors = anchors or {}
    for tok in tokens:
        for child in [tok, *(tok.children or [])]:
            for attr in ("href", "src"):
                value = child.attrGet(attr)
                if isinstance(value, str):
                    child.attrSet(attr, _relative(value, base, anchors))
            if child.type == "table_open":
                child.attrSet("class", "sortable")
    for tok in tokens:  # one level below the page's section heading
        if tok.type in ("heading_open", "heading_close"):
            tok.tag = f"h{min(int(tok.tag[1]) + 1, 6)}"
    for tok, nxt in zip(tokens, tokens[1:], strict=False):  # a short cell (a number, an interval) keeps one line
        if tok.type == "td_open" and nxt.type == "inline" and len(nxt.content) <= 24:
            tok.attrSet("class", "n")
    return renderer.renderer.render(tokens, renderer.options, {})


# ------------------------------------------------------------------------------------------------ figures
def _png_width(data: bytes) -> int:
    """The pixel width in a PNG file's header (0 if it is not a PNG)."""
    return int.from_bytes(data[16:20], "big") if data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) >= 24 else 0


def _figure(png: Path, page_dir: Path, embed: bool) -> str:
    """A PNG file as a figure: inlined as a data URI (``embed``) or linked relative to the page's folder. A figure
    of one paper column (under 1000 px) takes half the page's width, two side by side; a click enlarges any."""
    name = _e(png.name)
    data = png.read_bytes() if embed else png.open("rb").read(24)
    if embed:
        src = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
    else:
        src = _e(posixpath.relpath(png.resolve().as_posix(), page_dir.resolve().as_posix()))
    cls = ' class="half"' if 0 < _png_width(data) < 1000 else ""
    return (f'<figure{cls}><img alt="{name}" src="{src}" title="click to enlarge">'
            f"<figcaption>{name}</figcaption></figure>")  # fmt: skip


def _figures(run_dir: Path, embed: bool, skip: Sequence[str] = ()) -> str:
    pngs = [p for p in sorted((run_dir / "figures").glob("*.png")) if p.name not in skip]
    return "\n".join(_figure(p, run_dir, embed) for p in pngs) if pngs else "<p>No figures in figures/.</p>"


# ------------------------------------------------------------------------------------------------ headline
def _paired_cell(head: Headline, metric: Metric, mode: str, other: str) -> str:
    p = head.pair(metric.key, mode, other)
    if p is None or p.n == 0:
        return _cell("n/a")
    cls = "even"
    if p.settled:
        cls = "good" if (p.diff < 0) == metric.lower_is_better else "bad"
    interval = f"[{_num(p.low, metric.digits)}, {_num(p.high, metric.digits)}]"
    main = _num(p.diff, metric.digits).replace("−", "−", 1)
    main = main if main.startswith("−") or main == "n/a" else "+" + main
    return _cell(main, interval, f"won {p.wins}/{p.n}", cls=cls)


def _headline_tables(head: Headline) -> str:
    others = list(dict.fromkeys(p.other for p in head.paired))
    out = []
    for mode in head.modes:
        rows = []
        for metric in head.metrics:
            leader = head.leader(metric.key, mode)
            arrow = "↓" if metric.lower_is_better else "↑"
            unit = f" ({_e(metric.unit)})" if metric.unit else ""
            name = f"<td>{_e(metric.label)}{unit} {arrow}</td>"
            best = (_cell(f"<b>{_label(leader.model)}</b>", _num(leader.means[leader.model], metric.digits))
                    if leader else _cell("n/a"))  # fmt: skip
            rows.append("<tr>" + name + best + "".join(_paired_cell(head, metric, mode, o) for o in others) + "</tr>")
        head_cells = ["metric", "best model", *(f"S-OA − {_label(o)}" for o in others)]
        out.append(f"<h3>{_e(mode)}</h3>" + _table(head_cells, rows, "headline"))
    return "\n".join(out)


def _headline_html(head: Headline, forest: Path | None, run_dir: Path, embed: bool) -> str:
    if not head.paired:
        return "<p>No S-OA in this run, or no model beside it: no paired comparison.</p>"
    n = max((p.n for p in head.paired), default=0)
    intro = (
        f'<p class="lead">Each cell: the mean over trials of S-OA − X (paired by trial), its 95 % interval '
        f'(Student t) and the trials S-OA wins of those compared ({n} at most). <span class="good">green</span>: '
        'the interval says S-OA is better; <span class="bad">red</span>: S-OA is worse; no colour: the interval '
        "holds 0. ↓ lower is better, ↑ higher is better; <b>best model</b>: the best mean over trials.</p>"
    )
    trade = "".join(f"<li>{_e(t)}</li>" for t in head.tradeoffs)
    trade_html = f'<p><b>Trade-offs</b></p><ul class="tradeoffs">{trade}</ul>' if trade else ""
    fig = _figure(forest, run_dir, embed) if forest is not None and forest.is_file() else ""
    return intro + trade_html + _headline_tables(head) + fig


# ------------------------------------------------------------------------------------------------ tables
def _interval_cell(values: np.ndarray, nd: int = 3) -> str:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    mean, low, _ = mean_interval(v)
    if not math.isfinite(mean):
        return _cell("n/a")
    half = f"± {_num(mean - low, nd)}" if math.isfinite(low) else ""
    return _cell(_num(mean, nd), half)


def _floats(column: np.ndarray) -> np.ndarray:
    return np.array([math.nan if v in ("", None) else float(v) for v in np.asarray(column).tolist()], dtype=float)


def _models_table(tables: RunTables, clutter: float, result: Mapping) -> str:
    """Per model and mode: every metric's mean over trials with its 95 % interval (from trials.csv), and the
    summary's components and censored counts."""
    t = tables.trials
    metrics = [m for m in METRICS if m.key in t]
    by = {(s["model"], s["mode"]): s for s in result.get("models", [])}
    rows = []
    for (model, mode), s in by.items():
        m = select(t, clutter=clutter, model=model, mode=mode)
        cells = [f"<td>{_label(model)}</td><td>{_e(mode)}</td><td>{s['n_trials']}</td>"]
        cells += [_interval_cell(_floats(t[x.key][m]), x.digits) for x in metrics]
        cells.append(_cell(_num(s.get("components_mean"), 1)))
        cells.append(_cell(f"{s.get('n_censored', 0)} / {s.get('n_episodes', 0)}"))
        rows.append("<tr>" + "".join(cells) + "</tr>")
    head = ["model", "mode", "trials", *(f"{_e(x.label)}" + (f" ({_e(x.unit)})" if x.unit else "") for x in metrics),
            "components", "censored"]  # fmt: skip
    return _table(head, rows) + (
        '<p class="note">Each metric: the mean over trials, ± the half-width of its 95 % interval (Student t over '
        "trials). " + _e(_legend(tables)) + "</p>"
    )


def _legend(tables: RunTables) -> str:
    """The summary's legend of the terms, without its sentence on ± (here ± is an interval)."""
    text = table_legend(tables.meta["config"].get("metrics", {})).replace("**", "")
    return text.replace(" ± is the standard deviation over trials.", "")


def _vs_soa_table(result: Mapping) -> str:
    rows = []
    for c in result.get("vs_soa", []):
        frac = c.get("episode_le_fraction")
        cells = [f"<td>{_e(c['mode'])}</td><td>{_label(c['baseline'])}</td>",
                 _cell(f"{c['wins']} / {c['n_trials']}"), _cell(str(c["ties"])), _cell(str(c["losses"])),
                 _cell(str(c["na"])), _cell(_pct(100 * frac if frac is not None else math.nan)),
                 _cell(_pct(c.get("card_reduction"))), _cell(_pct(c.get("ospa_reduction")))]  # fmt: skip
        rows.append("<tr>" + "".join(cells) + "</tr>")
    if not rows:
        return ""
    head = ["mode", "baseline", "S-OA lower k̄", "ties", "S-OA higher", "n/a", "episodes S-OA ≤ X",
            "card. error reduction", "OSPA reduction"]  # fmt: skip
    return (
        "<h3>Delay wins by trial and by episode, percent reductions</h3>" + _table(head, rows)
        + '<p class="note">Trials in which S-OA has the lower mean delay (ties, losses, n/a apart); episodes counted '
        "for both with delay S-OA ≤ X; percent reduction 100·(M_X − M_S-OA)/M_X of the grand means.</p>"
    )  # fmt: skip


def _pct(x: Any) -> str:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return "n/a"
    return f"{x:.2f}%".replace("-", "−") if math.isfinite(x) else "n/a"


def _tracks_html(result: Mapping) -> str:
    """The Tracks table of summary.json (mean and σ over trials; the delays with σ̄ and their censored counts) and
    S-OA's paired HOTA counts."""
    tr = result.get("tracks") or {}
    if not tr:
        return ""

    def pm(st: Mapping, key: str, nd: int = 3) -> str:
        if not st.get("labelled"):
            return _cell(ABSENT)
        return _cell(_num(st.get(f"{key}_mean"), nd), f"σ {_num(st.get(f'{key}_std'), nd)}")

    def delay(st: Mapping, kind: str) -> str:
        return _cell(_num(st.get(f"delay_{kind}_mean")), f"σ̄ {_num(st.get(f'delay_{kind}_sigma_bar'))}",
                     f"{st.get(f'n_{kind}_censored', 0)} / {st.get(f'n_{kind}', 0)} censored")  # fmt: skip

    rows = []
    for model, mode, st in tr.get("rows", []):
        kept = _cell(_num(st.get("id_kept")), f"of {st.get('n_id', 0)}") if st.get("labelled") else _cell(ABSENT)
        idsw = _cell(_num(st.get("idsw_mean"), 2)) if st.get("labelled") else _cell(ABSENT)
        cells = [f"<td>{_label(model)}</td><td>{_e(mode)}</td>", pm(st, "hota"), pm(st, "assa"), pm(st, "idf1"),
                 idsw, pm(st, "ospa2"), delay(st, "entry"), delay(st, "reemergence"),
                 _cell(_num(st.get("coasted")), f"of {st.get('n_gaps', 0)}"), kept]  # fmt: skip
        rows.append("<tr>" + "".join(cells) + "</tr>")
    head = ["model", "mode", "HOTA", "AssA", "IDF1", "IDSW / trial", "OSPA(2) (m)", "entry delay (s)",
            "re-emergence delay (s)", "coasted", "identity kept"]  # fmt: skip
    out = "<h3>Tracks</h3>" + _table(head, rows)
    versus = []
    for mode, b, c in tr.get("versus", []):
        cells = [f"<td>{_e(mode)}</td><td>{_label(b)}</td>", _cell(f"{c['hota_higher']} / {c['n_trials']}"),
                 _cell(str(c["hota_ties"])), _cell(str(c["hota_lower"])), _cell(str(c["na"])),
                 _cell(_num(c.get("hota_diff"))), _cell(_num(c.get("idf1_diff")))]  # fmt: skip
        versus.append("<tr>" + "".join(cells) + "</tr>")
    if versus:
        head = ["mode", "baseline", "S-OA higher HOTA", "ties", "S-OA lower", "n/a", "ΔHOTA", "ΔIDF1"]
        out += _table(head, versus)
    return out + f'<p class="note">{_e(TRACKS_LEGEND.replace("**", ""))}</p>'


# ------------------------------------------------------------------------------------------------ generic
def _scalar(v: Any) -> str:
    if isinstance(v, float):
        return _num(v, 4) if abs(v) < 1e4 else f"{v:.4g}"
    if isinstance(v, (dict, list)):
        return f"<code>{_e(json.dumps(v, ensure_ascii=False)[:300])}</code>"
    return _e(v)


def generic_html(value: Any, depth: int = 0) -> str:
    """Any JSON value of summary.json as HTML: a list of objects as a table, an object of scalars as a key/value
    table, nested objects as headed parts."""
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        keys = list(dict.fromkeys(k for v in value for k in v))
        rows = ["<tr>" + "".join(_cell(_scalar(v.get(k, ""))) for k in keys) + "</tr>" for v in value]
        return _table([_e(k) for k in keys], rows)
    if isinstance(value, dict):
        flat = {k: v for k, v in value.items() if not isinstance(v, (dict, list)) or not v}
        nested = {k: v for k, v in value.items() if k not in flat}
        out = _table(["key", "value"], (f"<tr><td>{_e(k)}</td>{_cell(_scalar(v))}</tr>" for k, v in flat.items())) \
            if flat else ""  # fmt: skip
        level = min(4 + depth, 6)
        for k, v in nested.items():
            out += f"<h{level}>{_e(k)}</h{level}>" + generic_html(v, depth + 1)
        return out
    if isinstance(value, list):
        return "<p>" + ", ".join(_scalar(v) for v in value) + "</p>"
    return f"<p>{_scalar(value)}</p>"


def headlines(tables: RunTables) -> list[Headline]:
    """The headline of every clutter rate and filter family of a run, each from its family's tables."""
    return [headline(family_tables(tables, f), c, f) for c in tables.clutters for f in families(tables)]


def _title(key: str) -> str:
    return key.replace("_", " ").capitalize()


# ------------------------------------------------------------------------------------------------ extremes
def extreme_trials(run_dir: Path) -> list[dict[str, Any]]:
    """Per (model, mode) of the first clutter rate: the trials of lowest and highest mean delay (NaN excluded; ties
    go to the lower trial index), from ``trials.csv``; one line naming the file and the row when it is damaged (a
    row with too few or too many cells, a cell that is not a number, no newline at its end: a cut-off write)."""
    table = run_dir / "trials.csv"
    if not table.is_file():
        return []
    by: dict[tuple[str, str], list[tuple[float, int]]] = {}
    first_clutter = None
    try:
        with table.open(newline="", encoding="utf-8") as fh:
            text = fh.read()
        reader = csv.DictReader(text.splitlines())
        for line, r in enumerate(reader, start=2):
            try:
                if None in r or None in r.values():
                    raise ValueError(f"{len(reader.fieldnames or ())} columns in the header, other count here")
                lam, trial = float(r["clutter"]), int(r["trial"])
                delay = math.nan if r["delay_mean"] == "" else float(r["delay_mean"])
            except KeyError as exc:
                raise SoabenchError(f"{str(table)!r} has no column {exc}: it is not a run's trials.csv") from None
            except ValueError:
                raise SoabenchError(_damaged(table, f"row {line} is not a whole trials.csv row")) from None
            first_clutter = lam if first_clutter is None else first_clutter
            if lam != first_clutter or math.isnan(delay):
                continue
            by.setdefault((str(r.get("model")), str(r.get("mode"))), []).append((delay, trial))
        if text and not text.endswith("\n"):
            raise SoabenchError(_damaged(table, "its last row has no newline"))
    except (OSError, csv.Error, UnicodeDecodeError) as exc:
        raise SoabenchError(f"cannot read {str(table)!r}: {exc}") from None
    out = []
    for (model, mode), rows in by.items():
        best, worst = min(rows), max(rows, key=lambda r: (r[0], -r[1]))
        out.append({"model": model, "mode": mode, "clutter": first_clutter, "best": best, "worst": worst})
    return out


def _damaged(table: Path, what: str) -> str:
    run = shlex.quote(str(table.parent))
    return (
        f"{str(table)!r} is damaged ({what}: a cut-off or edited file); rebuild it from the trial records with "
        f"soabench run --resume {run}"
    )


def _extremes_html(run_dir: Path, rows: list[dict[str, Any]]) -> str:
    if not rows:
        return "<p>No trials.csv with a counted delay: no best or worst trial.</p>"
    body = []
    for r in rows:
        for what in ("best", "worst"):
            delay, trial = r[what]
            cmd = (f"soabench replay {shlex.quote(shown_path(run_dir))} --trial {trial} --mode {r['mode']} "
                   f"--clutter {r['clutter']:g}")  # fmt: skip
            page = run_dir / REPLAYS_DIR / replay_file(trial)
            link = f' <a href="{REPLAYS_DIR}/{replay_file(trial)}">open replay</a>' if page.is_file() else ""
            cells = (_label(r["model"]), _e(r["mode"]), what, str(trial), _num(delay), f"<code>{_e(cmd)}</code>{link}")
            body.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    return _table(["model", "mode", "which", "trial", "k̄ delay (s)", "replay"], body)


# ------------------------------------------------------------------------------------------------ provenance
def _flat(d: Any, prefix: str = "") -> list[tuple[str, Any]]:
    if isinstance(d, dict):
        out: list[tuple[str, Any]] = []
        for k, v in d.items():
            out += _flat(v, f"{prefix}{k}.")
        return out
    return [(prefix[:-1], d)]


def _provenance_html(raw: dict) -> str:
    rows = _flat({k: v for k, v in raw.items() if k not in ("config",)}) + _flat({"config": raw.get("config", {})})
    body = [f"<tr><td>{_e(k)}</td><td>{_e(v if isinstance(v, str) else json.dumps(v))}</td></tr>" for k, v in rows]
    return (f"<details><summary>run.json: options, versions, platform, seeds ({len(rows)} entries)</summary>"
            + _table(["key", "value"], body) + "</details>")  # fmt: skip


def _failures_html(summary: Mapping) -> str:
    out = ""
    if summary.get("failures"):
        out += "<h3>Failed trials</h3>" + generic_html(summary["failures"])
    if summary.get("model_failures"):
        out += "<h3>Failed model runs</h3>" + generic_html(summary["model_failures"])
    return out


# ------------------------------------------------------------------------------------------------ the page
def _read_summary(run_dir: Path) -> dict | None:
    path = run_dir / "summary.json"
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise SoabenchError(f"cannot read {str(path)!r}: {exc}") from None
    require(isinstance(data, dict), f"{str(path)!r} is not a run summary (a JSON object)")
    return data


def _nav(sections: Sequence[tuple[str, str]]) -> str:
    return "<nav>" + " · ".join(f'<a href="#s{i}">{_e(n)}</a>' for i, (n, _) in enumerate(sections)) + "</nav>"


def _page(title: str, subtitle: str, sections: Sequence[tuple[str, str]]) -> str:
    body = "\n".join(f'<section id="s{i}"><h2>{_e(n)}</h2>\n{c}</section>' for i, (n, c) in enumerate(sections))
    content = f"<header><h1>{_e(title)}</h1><p>{subtitle}</p>{_nav(sections)}</header>\n<main>{body}</main>\n"
    values = {"MARKER": _MARKER, "TITLE": _e(title), "CSS": asset("report.css"), "JS": asset("report.js"),
              "BODY": content}  # fmt: skip
    return re.sub(r"%%([A-Z]+)%%", lambda m: values[m.group(1)], _PAGE)  # one pass: inserted text is not scanned


def _result_name(res: Mapping) -> str:
    family = res.get("filter")
    return f"λ = {float(res['clutter']):g}" + (f", {FAMILY_LABEL.get(family, family)}" if family else "")


def report_html(run_dir: Path, raw: dict, embed: bool = True) -> str:
    """The page of a run folder (``raw``: its ``run.json``); figures inlined (``embed``) or linked."""
    title = f"soabench report: {run_dir.name} ({raw.get('net_name', raw.get('net', '?'))})"
    summary = _read_summary(run_dir)
    if summary is None:
        msg = "<p>No summary.json: the run is unfinished (finish it with <code>soabench run --resume</code>).</p>"
        sections = [("Summary", msg), ("Provenance", _provenance_html(raw))]
        return _page(title, _e(shown_path(run_dir)), sections)
    exp = summary["config"]["experiment"]
    subtitle = _e(
        f"{shown_path(run_dir)}: {summary['n_trials']} trials x {float(exp['duration']):g} s, seed {exp['seed']}, "
        f"modes {', '.join(exp['probabilities'])}, clutter λ = {', '.join(f'{float(c):g}' for c in exp['clutter'])}; "
        f"{summary['n_ok']} of {summary['n_trials']} trials succeeded"
        + (f", {len(summary['failures'])} failed" if summary.get("failures") else "")
    )
    extremes = extreme_trials(run_dir)  # first: a damaged trials.csv is named with its row and the way to rebuild it
    tables = load_tables(run_dir) if (run_dir / "trials.csv").is_file() else None
    heads = headlines(tables) if tables is not None else []
    results = summary.get("results", [])
    first, rest = [], []
    clutters = sorted({float(r["clutter"]) for r in results})
    for res in results:
        name = _result_name(res)
        warn = f'<p class="warn"><b>Warning:</b> {_e(res["warning"])}</p>' if res.get("warning") else ""
        head = next((h for h in heads if h.clutter == float(res["clutter"]) and h.family == res.get("filter")), None)
        sfx = f"_lam{float(res['clutter']):g}" if len(clutters) > 1 else ""
        family = res.get("filter")
        drawn = family is None or family == families(tables)[0]  # the figures are the first family's
        forest = run_dir / "figures" / f"{Path(PAIRED_FIGURE).stem}{sfx}.png" if drawn else None
        if head is not None and not warn:
            first.append((f"Who wins, {name}", _headline_html(head, forest, run_dir, embed)))
        ftables = family_tables(tables, family) if tables is not None else None
        body = warn + (_models_table(ftables, float(res["clutter"]), res) if ftables is not None else "")
        body += _vs_soa_table(res) + _tracks_html(res)
        extra = {k: v for k, v in res.items() if k not in _KNOWN_RESULT}
        body += "".join(f"<h3>{_e(_title(k))}</h3>" + generic_html(v) for k, v in extra.items())
        rest.append((f"Tables, {name}", body))
    sections = first + rest
    if tables is not None:
        paper_md = paper_section(run_dir, family_tables(tables, families(tables)[0]))
        if paper_md:
            heading, _, rest_md = paper_md.partition("\n")
            if heading.startswith("## "):
                sections.append((heading[3:].strip(), markdown_html(rest_md)))
            else:
                sections.append(("Against the paper", markdown_html(paper_md)))
    for key in (k for k in summary if k not in _KNOWN):
        sections.append((_title(key), generic_html(summary[key])))
    failures = _failures_html(summary)
    if failures:
        sections.append(("Failures", failures))
    shown = [f"{Path(PAIRED_FIGURE).stem}_lam{c:g}.png" for c in clutters] + [PAIRED_FIGURE]  # in the headline
    sections.append(("Figures", _figures(run_dir, embed, skip=shown if heads else ())))
    sections.append(("Best and worst trials (mean delay)", _extremes_html(run_dir, extremes)))
    tm = summary.get("timing") or {}
    timing = (
        f"<p>Wall time {_num(tm.get('wall_s'), 1)} s; SUMO {_num(tm.get('sumo_s'), 1)} s and sensor "
        f"{_num(tm.get('sensor_s'), 1)} s summed over trials (timing.csv has every filter stage).</p>"
    )
    sections.append(("Provenance", timing + _provenance_html(raw)))
    return _page(title, subtitle, sections)


def _ours(target: Path) -> bool:
    """``target`` is a page this command wrote."""
    try:
        return _MARKER in target.read_text(encoding="utf-8", errors="replace")[:2000]
    except OSError:
        return False


def _check_ours(target: Path) -> None:
    """An existing file at ``target`` must be a page this command wrote (else it is left alone, with an error)."""
    if not target.exists():
        return
    require(_ours(target), f"{str(target)!r} exists and was not written by soabench report; move it or give --out")


def read_meta(run_dir: str | Path) -> tuple[Path, Any, dict]:
    """A run folder's path, its validated ``run.json`` and the raw dict."""
    path = resolve(run_dir)
    require(path.is_dir() and (path / RUN_FILE).is_file(), f"{str(path)!r} is not a run folder (no {RUN_FILE})")
    store = RunStore(path)
    raw = store.meta()
    return path, validate_run_meta(raw, str(store.run_file)), raw


def write_report(run_dir: str | Path, out: str | Path | None = None, embed: bool = True) -> tuple[Path, int]:
    """Write the report page of a run folder (default ``RUN/report.html``); returns its path and size in bytes.

    ``embed``: figures inlined (one file to share) or linked to ``figures/``. An existing file at the target that
    this command did not write is left alone (an error says so); ``out`` must end in .html and lie in an existing
    folder, as every command's output file does."""
    path, _, raw = read_meta(run_dir)
    target = path / REPORT_FILE if out is None else check_out_file(str(out), ".html")
    _check_ours(target)
    return target, write_page(target, report_html(path, raw, embed))


def refresh_report(run_dir: Path) -> Path | None:
    """The run's ``report.html`` after its summary was written (every finished run, sweep point and study part gets
    one: the page to open in a run folder); a foreign file there is left alone with a warning, the run stands."""
    try:
        return write_report(run_dir)[0]
    except SoabenchError as exc:
        print(f"soabench: warning: no report.html: {exc}", file=sys.stderr)
        return None


# ------------------------------------------------------------------------------------------------ index pages
def find_runs(folder: Path) -> list[Path]:
    """Every protocol run folder under ``folder`` (its ``run.json`` of the run format), sorted by path; other
    folders with a ``run.json`` (a KITTI protocol run) are shown by their Markdown and figures."""
    runs = []
    for p in sorted(folder.rglob(RUN_FILE)):
        try:
            meta = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError):
            meta = None
        if isinstance(meta, dict) and meta.get("format") == FORMAT_VERSION:
            runs.append(p.parent)
    return runs


def _folder_parts(folder: Path, runs: list[Path]) -> list[tuple[Path, list[Path], list[Path]]]:
    """(subfolder, its Markdown files, its PNG files) for every folder under ``folder`` outside the run folders that
    holds some or an index page of ours."""
    inside = set(runs)
    out = []
    for d in sorted([folder, *(p for p in folder.rglob("*") if p.is_dir())]):
        if any(d == r or r in d.parents for r in inside):
            continue
        md, png = sorted(d.glob("*.md")), sorted(d.glob("*.png"))
        if md or png or (d != folder and _ours(d / INDEX_FILE)):
            out.append((d, md, png))
    return out


def _run_row(folder: Path, run: Path) -> str:
    rel = run.relative_to(folder).as_posix()
    try:
        _, meta, raw = read_meta(run)
    except SoabenchError as exc:
        return f"<tr><td>{_e(rel)}</td><td colspan=6>{_e(exc)}</td></tr>"
    exp = meta.config.experiment
    link = f'<a href="{_e(rel)}/{REPORT_FILE}">{_e(rel)}</a>'
    cells = (
        link, _e(raw.get("net_name", meta.net)), str(exp.trials), f"{exp.duration:g} s",
        _e(", ".join(LABEL.get(m, m) for m in exp.models)), _e(", ".join(f"{c:g}" for c in exp.clutter)),
        str(exp.seed),
    )  # fmt: skip
    return "<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>"


def index_html(folder: Path, runs: list[Path]) -> str:
    """The index page of a folder of run folders (a study, ``results/``): its own Markdown and figures, a table
    linking every run's report page (shallow folders first: a study's main run before its sweep points), then the
    folders below with their index pages, Markdown and figures (linked, not copied)."""
    shallow_first = sorted(runs, key=lambda r: (len(r.relative_to(folder).parts), r))  # main/ before sweep points
    head = ["run folder", "scene", "trials", "duration", "models", "λ", "seed"]
    table = _table(head, (_run_row(folder, r) for r in shallow_first))
    parts = _folder_parts(folder, runs)
    anchors = {}
    for i, (_, mds, _png) in enumerate(parts):
        for m in mds:
            anchors[m.relative_to(folder).as_posix()] = f"md{i}-{_slug(m.stem)}"
    rendered = []
    for d, mds, pngs in parts:
        rel = d.relative_to(folder).as_posix() if d != folder else "."
        body = ""
        if d != folder and _ours(d / INDEX_FILE):
            body += f'<p><a href="{_e(rel)}/{INDEX_FILE}">{_e(rel)}/{INDEX_FILE}</a></p>'
        texts = {m: m.read_text(encoding="utf-8") for m in mds}
        # a figure no Markdown file shows (a study's key figure) comes first, the Markdown after it
        body += "".join(_figure(p, folder, embed=False) for p in pngs if not any(p.name in t for t in texts.values()))
        for m, text in texts.items():
            anchor = anchors[m.relative_to(folder).as_posix()]
            body += f'<div class="md" id="{anchor}">' + markdown_html(text, rel, anchors) + "</div>"
        rendered.append((f"{rel}/", body))
    own = [p for p in rendered if p[0] == "./"]  # the folder's own Markdown (comparison.md, README.md) comes first
    sections = [*(("This folder", b) for _, b in own), ("Run folders", table), *(p for p in rendered if p[0] != "./")]
    return _page(f"soabench report: {folder.name}", _e(shown_path(folder)), sections)


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() else "-" for c in text.lower())


def write_index(folder: str | Path, reports: bool = True) -> tuple[Path, int, list[Path]]:
    """Write every run's report under ``folder`` (``reports``; figures linked, not inlined: the folder is shared
    whole) and ``folder/index.html`` linking them; returns the index path, its size in bytes and the run folders.
    Unchanged pages are not rewritten."""
    path = resolve(folder)
    require(path.is_dir(), f"{str(path)!r} is not a folder")
    runs = find_runs(path)
    require(bool(runs), f"{str(path)!r} is not a run folder and holds none (no run.json in it or below)")
    target = path / INDEX_FILE
    _check_ours(target)
    for run in runs if reports else ():
        write_report(run, embed=False)
    return target, write_page(target, index_html(path, runs)), runs


_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">%%MARKER%%
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>%%TITLE%%</title>
<style>
%%CSS%%</style></head>
<body data-status="loading">
%%BODY%%<div id="zoom" hidden><img alt=""></div>
<script>
%%JS%%</script></body></html>
"""
