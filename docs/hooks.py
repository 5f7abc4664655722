"""MkDocs hook: pages that must not drift from the code are filled in from the code at build time.

* ``<!-- soabench:parameters -->`` becomes the table of every configuration key with its default and meaning, read
  from the dataclasses of :mod:`soabench.config` (the ``#:`` comment after each field is its description);
* ``<!-- soabench:scenario-keys -->`` becomes the table of every scenario TOML key, read from
  :class:`soabench.scenario.config.ScenarioConfig` (defaults, and the ``Attributes:`` section of its docstring);
* ``<!-- soabench:readme HEADING -->`` becomes the README section whose ``## `` heading starts with HEADING (down to
  the next ``## `` heading), so that text both need (file formats, cluster use) has one source;
* ``<!-- soabench:api -->`` becomes one mkdocstrings ``::: module`` block per public module of the package (and of
  the repository's ``baselines`` package while it is a top-level one), grouped by subpackage, so that a new or moved
  module is documented without editing the page;
* ``<!-- soabench:help COMMAND -->`` becomes the ``soabench COMMAND --help`` text of :func:`soabench.cli.build_parser`.

Docstrings and README text cite pages as plain text ("docs/method.md §3.1.4"): :func:`on_page_content` turns every
such citation into a link to that page and section, for the API reference and the included README sections.

Only our own package is imported; nothing is read from user files.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import re
from pathlib import Path

_PARAMS = "<!-- soabench:parameters -->"
_SCENARIO = "<!-- soabench:scenario-keys -->"
_API = "<!-- soabench:api -->"
_README = re.compile(r"<!-- soabench:readme ([^>]*?) -->")
_HELP = re.compile(r"<!-- soabench:help ([a-z]*) -->")

# where each section's formulas and decisions are explained (docs/method.md)
_SECTION_REFS = {
    "sensor": "[§2.3](../method.md#s2.3), register rows [3, 4, 7](../method.md#s7)",
    "filter": "[§2](../method.md#s2), [§4](../method.md#s4), register rows [1, 4, 20, 21, 25, 29](../method.md#s7)",
    "birth": "[§3](../method.md#s3), register rows [9-19, 24, 26-28](../method.md#s7)",
    "metrics": "[§5](../method.md#s5), register rows [5, 6, 22, 23](../method.md#s7)",
    "experiment": "[§5.8](../method.md#s5.8)",
}


def _field_comments(cls: type) -> dict[str, str]:
    """``{field: text}`` of the ``#:`` comments that follow the fields of a dataclass in its source."""
    lines = inspect.getsource(cls).splitlines()
    out = {}
    for node in ast.parse("\n".join(lines)).body[0].body:
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            line = lines[node.lineno - 1]
            if "#:" in line:
                out[node.target.id] = line.split("#:", 1)[1].strip()
    return out


def _fmt_default(value: object) -> str:
    if isinstance(value, tuple):
        value = list(value)
    if isinstance(value, str):
        return f'`"{value}"`'
    if value is None:
        return "not set"
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    return f"`{value!r}`".replace("'", '"')


def _escape(text: str) -> str:
    return text.replace("|", "\\|").replace("<", "&lt;")


def _link_sections(text: str, method_url: str) -> str:
    """Bare "§X.Y" in a description -> a link to that section of the method page (when it exists)."""
    ids = _method_ids()
    return re.sub(
        r"§(\d+(?:\.\d+)*)",
        lambda m: f"[§{m.group(1)}]({method_url}#s{m.group(1)})" if f"s{m.group(1)}" in ids else m.group(0),
        text,
    )


def parameter_table() -> str:
    """Markdown: one table per config section (``[section]`` of a TOML file)."""
    from soabench.config import Config

    parts = []
    cfg = Config()
    for sec in dataclasses.fields(Config):
        obj = getattr(cfg, sec.name)
        if not dataclasses.is_dataclass(obj):  # [plugins.<name>] tables: each plugin's own options
            parts.append(f"### `[{sec.name}]` {{#{sec.name}}}\n")
            parts.append(
                "One table `[plugins.<name>]` per plugin birth model or tracker (an entry-point name or the "
                "`module:Class` you typed); its keys are passed to the plugin's constructor as keyword arguments, "
                "and an option the plugin does not take stops the run before any trial. No defaults here: each "
                "plugin documents its own.\n"
            )
            continue
        cls = type(obj)
        comments = _field_comments(cls)
        doc = (inspect.getdoc(cls) or "").splitlines()[0]
        doc = re.sub(r"\s*\(docs/method\.md[^)]*\)|\s*\(ALGORITHMS\.md[^)]*\)", "", doc).rstrip(".")
        parts.append(f"### `[{sec.name}]` {{#{sec.name}}}\n")
        parts.append(f"{doc}. Method: {_SECTION_REFS.get(sec.name, 'docs/method.md')}.\n")
        parts.append("| key | default | meaning |\n|---|---|---|")
        for f in dataclasses.fields(cls):
            default = getattr(obj, f.name)
            meaning = _link_sections(_escape(comments.get(f.name, "")), "../method.md")
            parts.append(f"| `{f.name}` | {_fmt_default(default)} | {meaning} |")
        parts.append("")
    return "\n".join(parts)


def _attribute_docs(cls: type) -> dict[str, str]:
    """``{attribute: text}`` from the Google-style ``Attributes:`` section of a class docstring."""
    doc = inspect.getdoc(cls) or ""
    out: dict[str, str] = {}
    in_attrs, last = False, None
    for line in doc.splitlines():
        if line.strip() == "Attributes:":
            in_attrs = True
            continue
        if not in_attrs:
            continue
        if line and not line.startswith(" "):
            break
        m = re.match(r"^    ([A-Za-z_][\w, ]*):\s*(.*)$", line)
        if m:
            last = [n.strip() for n in m.group(1).split(",")]
            for n in last:
                out[n] = m.group(2)
        elif last and line.strip():
            for n in last:
                out[n] += " " + line.strip()
    return out


def scenario_table() -> str:
    """Markdown: every ``[section] key`` of a scenario TOML with its default and meaning."""
    from soabench.scenario.config import _KEYS, ScenarioConfig

    cfg = ScenarioConfig()
    docs = _attribute_docs(ScenarioConfig)
    rows = ["| section | key | default | meaning |", "|---|---|---|---|"]
    for section, keys in _KEYS.items():
        for key, attr in keys.items():
            default = getattr(cfg, attr)
            shown = "derived from the network" if default in ("", [], None) and attr != "ego_start_x" else None
            rows.append(
                f"| `[{section}]` | `{key}` | {shown or _fmt_default(default)} | {_escape(docs.get(attr, ''))} |"
            )
    return "\n".join(rows) + "\n"


def cli_help(command: str) -> str:
    """``soabench COMMAND --help`` (``soabench --help`` for an empty command) as a fenced block."""
    import argparse
    import os

    from soabench.cli import build_parser

    os.environ.setdefault("COLUMNS", "100")
    parser = build_parser()
    if command:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[command]
    return "```text\n" + parser.format_help().rstrip() + "\n```"


def readme_section(heading: str, page_src: str = "index.md") -> str:
    """The README section ``## HEADING...`` (without the next section); a missing heading fails the build.

    Relative links of the README (written from the repository root) are rebased for the page ``page_src`` (its
    path under docs/): ``docs/x.md`` becomes a link to that page, anything else a link to the file on disk would
    leave the site, so it is an error.
    """
    lines = (Path(__file__).resolve().parent.parent / "README.md").read_text(encoding="utf-8").splitlines()
    start = next((i for i, line in enumerate(lines) if line.startswith("## " + heading)), None)
    if start is None:
        raise ValueError(f"README.md has no section starting with '## {heading}' (docs include)")
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
    text = "\n".join(lines[start:end]).rstrip() + "\n"
    up = "../" * page_src.count("/")

    def rebase(m: re.Match) -> str:
        target = m.group(1)
        if target.startswith("docs/"):
            return f"]({up}{target[len('docs/') :]})"
        if re.match(r"^[a-z]+://|^#", target):
            return m.group(0)
        raise ValueError(f"README section '{heading}' links to {target!r}, outside docs/: cannot include it")

    return re.sub(r"\]\(([^)\s]+)\)", rebase, text)


_GROUPS = {
    "": "Top level: configuration, errors, seeds, geometry, sensor, metrics, command line",
    "scenario": "Scenario (SUMO)",
    "gmphd": "GM-PHD filter",
    "birth": "Birth models",
    "baselines": "Baseline birth models",
    "experiment": "Experiments: trials, runs, sweeps, reports",
}


def api_blocks() -> str:
    """Markdown: a section per subpackage with a ``::: module`` block for each public module."""
    import pkgutil

    import soabench

    mods = ["soabench"] + [
        m.name for m in pkgutil.walk_packages(soabench.__path__, "soabench.") if not m.name.rsplit(".", 1)[-1][0] == "_"
    ]
    if (_DOCS.parent / "baselines" / "__init__.py").is_file():
        mods += ["baselines"] + [f"baselines.{p.stem}" for p in sorted((_DOCS.parent / "baselines").glob("[!_]*.py"))]
    groups: dict[str, list[str]] = {}
    for name in mods:
        parts = name.split(".")
        key = parts[0] if parts[0] == "baselines" else (parts[1] if len(parts) > 2 or name in _SUBPACKAGES else "")
        groups.setdefault(key if key in _GROUPS else "", []).append(name)
    out = []
    for key, title in _GROUPS.items():
        if key in groups:
            out.append(f"## {title}\n")
            out += [f"::: {name}\n" for name in groups[key]]
    return "\n".join(out)


_SUBPACKAGES = {"soabench.scenario", "soabench.gmphd", "soabench.birth", "soabench.baselines", "soabench.experiment"}


def on_page_markdown(markdown: str, **kwargs) -> str:
    if _PARAMS in markdown:
        markdown = markdown.replace(_PARAMS, parameter_table())
    if _API in markdown:
        markdown = markdown.replace(_API, api_blocks())
    src = kwargs["page"].file.src_uri
    markdown = _README.sub(lambda m: readme_section(m.group(1), src), markdown)
    if _SCENARIO in markdown:
        markdown = markdown.replace(_SCENARIO, scenario_table())
    return _HELP.sub(lambda m: cli_help(m.group(1)), markdown)


_CITE = re.compile(r"docs/((?:user-guide/)?[\w-]+)\.md(?:(?:\s|&nbsp;)+§(\d+(?:\.\d+)*))?")
_DOCS = Path(__file__).resolve().parent


def _method_ids() -> set[str]:
    return set(re.findall(r'<a id="(s[\w.-]+)"></a>', (_DOCS / "method.md").read_text(encoding="utf-8")))


def on_page_content(html: str, page, **kwargs) -> str:
    """Link plain-text citations "docs/PAGE.md [§X.Y]" to the page (and section, when it exists)."""
    prefix = "../" * page.url.count("/")
    ids = _method_ids()

    def link(m: re.Match) -> str:
        name, sec = m.group(1), m.group(2)
        if not (_DOCS / f"{name}.md").is_file():
            return m.group(0)
        target = f"{prefix}{name}/"
        while sec and f"s{sec}" not in ids and "." in sec:
            sec = sec.rsplit(".", 1)[0]
        if sec and f"s{sec}" in ids:
            target += f"#s{sec}"
        return f'<a href="{target}">{m.group(0)}</a>'

    html = _CITE.sub(link, html)
    return _ROLE.sub(lambda m: _role(m, set(re.findall(r'id="([\w.]+)"', html))), html)


# Sphinx cross-reference roles in docstrings (":class:`~soabench.errors.SoabenchError`"), which mkdocstrings shows
# verbatim: the role is dropped, "~" shortens the name, and a full name documented on the page becomes a link.
_ROLE = re.compile(r":(?:class|func|meth|mod|data|attr|exc|obj):<code>(~?)([\w.]+)</code>")


def _role(m: re.Match, ids: set[str]) -> str:
    name = m.group(2)
    shown = name.rsplit(".", 1)[-1] if m.group(1) else name
    if name in ids:
        return f'<a href="#{name}"><code>{shown}</code></a>'
    return f"<code>{shown}</code>"
