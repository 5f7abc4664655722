"""``report.html``: one self-contained page for a run folder (docs/user-guide/replay.md).

It shows what the folder holds, nothing recomputed: the summary (``summary.md``'s headings, text and tables, the
tables sortable by a click on a header), every figure of ``figures/`` inlined as a PNG data URI, the best and worst
trial of each model by mean delay (from ``trials.csv``) with the ``soabench replay`` command of each (and a link to
its page where ``replays/`` holds one), and the provenance (``run.json``: options, versions, platform, seeds).
Every value read from the folder is escaped: the page runs only its own small script.
"""

from __future__ import annotations

import base64
import csv
import html
import json
import math
import re
import shlex
import sys
from pathlib import Path
from typing import Any

from soabench.atomic import write_text_atomic
from soabench.birth import LABEL
from soabench.errors import SoabenchError, require
from soabench.folders import check_out_file, resolve
from soabench.replay.page import asset, fill
from soabench.replay.simulate import read_run

GENERATOR = "soabench report"
REPORT_FILE = "report.html"
INDEX_FILE = "index.html"
REPLAYS_DIR = "replays"
_MARKER = f'<meta name="generator" content="{GENERATOR}">'


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


def _inline(text: str) -> str:
    """Escaped Markdown inline text with `code` and **bold**."""
    s = html.escape(text)
    s = re.sub(r"`([^`]+)`", r"<code>\1</code>", s)
    return re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", s)


def markdown_html(md: str) -> str:
    """The subset of Markdown ``summary.md`` uses: headings, pipe tables (made sortable), paragraphs."""
    out: list[str] = []
    lines = md.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i].rstrip()
        if line.startswith("|"):
            block = []
            while i < len(lines) and lines[i].startswith("|"):
                block.append([c.strip() for c in lines[i].strip().strip("|").split("|")])
                i += 1
            rows = [r for r in block if not all(re.fullmatch(r":?-+:?", c) for c in r)]
            head = "".join(f"<th>{_inline(c)}</th>" for c in rows[0])
            body = "".join("<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in r) + "</tr>" for r in rows[1:])
            out.append(f'<table class="sortable"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>')
            continue
        m = re.match(r"(#{1,4})\s+(.*)", line)
        if m:
            level = len(m.group(1)) + 1
            out.append(f"<h{level}>{_inline(m.group(2))}</h{level}>")
        elif line:
            out.append(f"<p>{_inline(line)}</p>")
        i += 1
    return "\n".join(out)


def _figure(png: Path) -> str:
    """A PNG file inlined as a data URI, captioned with its name."""
    data = base64.b64encode(png.read_bytes()).decode("ascii")
    name = html.escape(png.name)
    return f'<figure><img alt="{name}" src="data:image/png;base64,{data}"><figcaption>{name}</figcaption></figure>'


def _figures(run_dir: Path) -> str:
    parts = [_figure(png) for png in sorted((run_dir / "figures").glob("*.png"))]
    return "\n".join(parts) if parts else "<p>No figures in figures/.</p>"


def _replay_cells(run_dir: Path, model: str, mode: str, clutter: float, trial: int) -> str:
    cmd = f"soabench replay {shlex.quote(shown_path(run_dir))} --trial {trial} --mode {mode} --clutter {clutter:g}"
    page = run_dir / REPLAYS_DIR / replay_file(trial)
    link = f' <a href="{REPLAYS_DIR}/{replay_file(trial)}">open replay</a>' if page.is_file() else ""
    return f"<code>{html.escape(cmd)}</code>{link}"


def _extremes_html(run_dir: Path, rows: list[dict[str, Any]]) -> str:
    if not rows:
        return "<p>No trials.csv with a counted delay: no best or worst trial.</p>"

    body = []
    for r in rows:
        for what in ("best", "worst"):
            delay, trial = r[what]
            cells = (
                html.escape(LABEL.get(r["model"], r["model"])), html.escape(r["mode"]), what, str(trial),
                f"{delay:.3f}", _replay_cells(run_dir, r["model"], r["mode"], r["clutter"], trial),
            )  # fmt: skip
            body.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    head = "".join(f"<th>{h}</th>" for h in ("model", "mode", "which", "trial", "k̄ delay (s)", "replay"))
    return f'<table class="sortable"><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody></table>'


def _flat(d: Any, prefix: str = "") -> list[tuple[str, Any]]:
    if isinstance(d, dict):
        out: list[tuple[str, Any]] = []
        for k, v in d.items():
            out += _flat(v, f"{prefix}{k}.")
        return out
    return [(prefix[:-1], d)]


def _provenance_html(raw: dict) -> str:
    rows = _flat({k: v for k, v in raw.items() if k not in ("config",)})
    rows += _flat({"config": raw.get("config", {})})
    body = "".join(
        f"<tr><td>{html.escape(k)}</td><td>{html.escape(json.dumps(v) if not isinstance(v, str) else v)}</td></tr>"
        for k, v in rows
    )
    return f'<table class="sortable"><thead><tr><th>key</th><th>value</th></tr></thead><tbody>{body}</tbody></table>'


def report_html(run_dir: Path, raw: dict) -> str:
    """The page of a run folder (``raw``: its ``run.json``)."""
    md_file = run_dir / "summary.md"
    summary = (
        markdown_html(md_file.read_text(encoding="utf-8"))
        if md_file.is_file()
        else "<p>No summary.md: the run is unfinished (finish it with <code>soabench run --resume</code>).</p>"
    )
    title = html.escape(f"soabench report: {run_dir.name} ({raw.get('net_name', raw.get('net', '?'))})")
    sections = [
        ("Summary", summary),
        ("Best and worst trials (mean delay)", _extremes_html(run_dir, extreme_trials(run_dir))),
        ("Figures", _figures(run_dir)),
        ("Provenance (run.json)", _provenance_html(raw)),
    ]
    toc = " · ".join(f'<a href="#s{i}">{html.escape(n)}</a>' for i, (n, _) in enumerate(sections))
    body = "\n".join(f'<section id="s{i}"><h2>{html.escape(n)}</h2>\n{c}</section>' for i, (n, c) in
                     enumerate(sections))  # fmt: skip
    content = f"<h1>{title}</h1><p>{html.escape(shown_path(run_dir))}</p><nav>{toc}</nav>\n{body}\n"
    return fill(_PAGE, MARKER=_MARKER, TITLE=title, CSS=asset("report.css"), BODY=content, JS=asset("report.js"))


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


def write_report(run_dir: str | Path, out: str | Path | None = None) -> tuple[Path, int]:
    """Write the report page of a run folder (default ``RUN/report.html``); returns its path and size in bytes.

    An existing file at the target that this command did not write is left alone (an error says so); ``out`` must
    end in .html and lie in an existing folder, as every command's output file does."""
    path, _, raw = read_run(run_dir)
    target = path / REPORT_FILE if out is None else check_out_file(str(out), ".html")
    _check_ours(target)
    return target, write_page(target, report_html(path, raw))


def refresh_report(run_dir: Path) -> Path | None:
    """The run's ``report.html`` after its summary was written (every finished run, sweep point and study part gets
    one: the page to open in a run folder); a foreign file there is left alone with a warning, the run stands."""
    try:
        return write_report(run_dir)[0]
    except SoabenchError as exc:
        print(f"soabench: warning: no report.html: {exc}", file=sys.stderr)
        return None


def find_runs(folder: Path) -> list[Path]:
    """Every protocol run folder under ``folder`` (its ``run.json`` of the run format), sorted by path; other
    folders with a ``run.json`` (a KITTI protocol run) are shown by their Markdown and figures."""
    # imported when called: scipy would slow every start-up
    from soabench.experiment.runs.store import FORMAT_VERSION, RUN_FILE

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
        _, meta, raw = read_run(run)
    except SoabenchError as exc:
        return f"<tr><td>{html.escape(rel)}</td><td colspan=6>{html.escape(str(exc))}</td></tr>"
    exp = meta.config.experiment
    link = f'<a href="{html.escape(rel)}/{REPORT_FILE}">{html.escape(rel)}</a>'
    cells = (
        link, html.escape(str(raw.get("net_name", meta.net))), str(exp.trials), f"{exp.duration:g} s",
        html.escape(", ".join(exp.models)), html.escape(", ".join(f"{c:g}" for c in exp.clutter)), str(exp.seed),
    )  # fmt: skip
    return "<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>"


def index_html(folder: Path, runs: list[Path]) -> str:
    """The index page of a folder of run folders (a study, ``results/``): its own Markdown and figures, a table
    linking every run's report page (shallow folders first: a study's main run before its sweep points), then the
    folders below with their index pages, Markdown and figures."""
    head = "".join(f"<th>{h}</th>" for h in ("run folder", "scene", "trials", "duration", "models", "λ", "seed"))
    shallow_first = sorted(runs, key=lambda r: (len(r.relative_to(folder).parts), r))  # main/ before sweep points
    table = (f'<table class="sortable"><thead><tr>{head}</tr></thead><tbody>'
             + "".join(_run_row(folder, r) for r in shallow_first) + "</tbody></table>")  # fmt: skip
    parts = []
    for d, mds, pngs in _folder_parts(folder, runs):
        rel = d.relative_to(folder).as_posix() if d != folder else "."
        body = ""
        if d != folder and _ours(d / INDEX_FILE):
            body += f'<p><a href="{html.escape(rel)}/{INDEX_FILE}">{html.escape(rel)}/{INDEX_FILE}</a></p>'
        body += "".join(markdown_html(m.read_text(encoding="utf-8")) for m in mds)
        body += "".join(_figure(p) for p in pngs)
        parts.append((f"{rel}/", body))
    own = [p for p in parts if p[0] == "./"]  # the folder's own Markdown (comparison.md, README.md) comes first
    sections = [*(("This folder", b) for _, b in own), ("Run folders", table), *(p for p in parts if p[0] != "./")]
    title = html.escape(f"soabench report: {folder.name}")
    toc = " · ".join(f'<a href="#s{i}">{html.escape(n)}</a>' for i, (n, _) in enumerate(sections))
    body = "\n".join(f'<section id="s{i}"><h2>{html.escape(n)}</h2>\n{c}</section>' for i, (n, c) in
                     enumerate(sections))  # fmt: skip
    content = f"<h1>{title}</h1><p>{html.escape(shown_path(folder))}</p><nav>{toc}</nav>\n{body}\n"
    return fill(_PAGE, MARKER=_MARKER, TITLE=title, CSS=asset("report.css"), BODY=content, JS=asset("report.js"))


def write_index(folder: str | Path, reports: bool = True) -> tuple[Path, int, list[Path]]:
    """Write every run's report under ``folder`` (``reports``) and ``folder/index.html`` linking them; returns the
    index path, its size in bytes and the run folders. Unchanged pages are not rewritten."""

    path = resolve(folder)
    require(path.is_dir(), f"{str(path)!r} is not a folder")
    runs = find_runs(path)
    require(bool(runs), f"{str(path)!r} is not a run folder and holds none (no run.json in it or below)")
    target = path / INDEX_FILE
    _check_ours(target)
    for run in runs if reports else ():
        write_report(run)
    return target, write_page(target, index_html(path, runs)), runs


_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">%%MARKER%%
<title>%%TITLE%%</title>
<style>
%%CSS%%</style></head>
<body data-status="loading">
%%BODY%%<script>
%%JS%%</script></body></html>
"""
