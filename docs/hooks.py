"""MkDocs hook and page generator: what must not drift from the code is generated from the code.

Generated blocks are written into the page files, so a page reads the same on a code host as on the built site, and
refreshed again at build time. A block is the text between an opening and a closing comment::

    <!-- soabench:KIND ARG -->
    ...generated text...
    <!-- /soabench -->

with KIND one of

* ``parameters``: the table of every configuration key with its default and meaning, read from the dataclasses of
  :mod:`soabench.config` (the ``#:`` comment after each field is its description);
* ``scenario-keys``: the table of every scenario TOML key, read from
  :class:`soabench.scenario.config.ScenarioConfig` (defaults, and the ``Attributes:`` section of its docstring);
* ``kitti-keys``: the table of the ``[kitti]`` section's keys (:class:`soabench.kitti.config.KittiConfig`);
* ``commands``: a section per command of :func:`soabench.cli.main.build_parser` with its ``--help`` text;
* ``check-metrics``: the metric names a ``soabench check`` threshold may use (the columns of ``trials.csv``);
* ``python-api``: every public name of :mod:`soabench.api` with its signature, docstring and example.

``python docs/hooks.py`` rewrites the blocks of every page from the installed code; ``python docs/hooks.py --check``
lists the pages whose blocks are stale (``tests/repository/test_docs.py`` runs the check).

Three things only the built site can show are filled in at build time and stay a sentence in the page file:

* the API reference: the sentence between ``<!-- soabench:api -->`` and ``<!-- /soabench:api -->`` becomes one
  mkdocstrings ``::: module`` block per public module;
* the committed reports of ``results/``: the sentence between ``<!-- soabench:include PATH -->`` and
  ``<!-- /soabench:include -->`` becomes the report's text without its title (reports change with every
  regeneration of ``results/``, which should not need a documentation commit);
* the repository files outside ``docs/`` that a page links to, as a code host resolves them
  (``../../results/intersection/key_figure.png`` from ``docs/results/index.md``): the build checks that the file
  exists, serves a copy of an image or data file, and shows a Markdown file as its path (it is not a page).

Docstrings cite pages as plain text ("docs/method.md §3.1.4"): :func:`on_page_content` turns every such citation
into a link to that page and section, for the API reference.

Only our own package is imported; nothing is read from user files.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import re
from pathlib import Path

#: the API reference's stand-in: a sentence in the page file, the mkdocstrings blocks on the site
_API = re.compile(r"<!-- soabench:api -->.*?<!-- /soabench:api -->", re.S)
#: a generated block: the opening comment names what is generated, the closing comment ends it
_BLOCK = re.compile(r"(<!-- soabench:(?P<kind>[a-z-]+) -->\n)(?P<body>.*?)(<!-- /soabench -->)", re.S)
_DOCS = Path(__file__).resolve().parent
_ROOT = _DOCS.parent
#: the width of the generated ``--help`` text (the terminal's width would make the page depend on who built it)
_HELP_WIDTH = 100

# where each section's formulas and decisions are explained (docs/method.md)
_SECTION_REFS = {
    "sensor": "[§2.3](../method.md#s2.3), register rows [3, 4, 7](../method.md#s7)",
    "filter": "[§2](../method.md#s2), [§4](../method.md#s4), register rows [1, 4, 20, 21, 25, 29](../method.md#s7)",
    "birth": "[§3](../method.md#s3), register rows [9-19, 24, 26-28](../method.md#s7)",
    "metrics": "[§5](../method.md#s5), register rows [5, 6, 22, 23](../method.md#s7)",
    "experiment": "[§5.8](../method.md#s5.8)",
    "lmb": "[LMB filter](../method.md#lmb), register row [33](../method.md#r33)",
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
            parts.append(f"### `[{sec.name}]`\n")  # the heading's anchor is #{sec.name}
            parts.append(
                "One table `[plugins.<name>]` per plugin birth model or tracker (an entry-point name or the "
                "`module:Class` you typed); its keys are passed to the plugin's constructor as keyword arguments, "
                "and an option the plugin does not take stops the run before any trial. No defaults here: each "
                "plugin documents its own.\n"
            )
            continue
        doc = (inspect.getdoc(type(obj)) or "").splitlines()[0]
        doc = re.sub(r"\s*\(docs/method\.md[^)]*\)", "", doc).rstrip(".")
        parts.append(f"### `[{sec.name}]`\n")
        parts.append(f"{doc}. Method: {_SECTION_REFS.get(sec.name, 'docs/method.md')}.\n")
        parts.append(key_table(obj))
    return "\n".join(parts)


def key_table(obj: object) -> str:
    """Markdown: the fields of the dataclass instance ``obj`` with their values as defaults and ``#:`` comments."""
    comments = _field_comments(type(obj))
    rows = ["| key | default | meaning |", "|---|---|---|"]
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        meaning = _link_sections(_escape(comments.get(f.name, "")), "../method.md")
        rows.append(f"| `{f.name}` | {_fmt_default(getattr(obj, f.name))} | {meaning} |")
    return "\n".join(rows) + "\n"


def kitti_table() -> str:
    """Markdown: the keys of the ``[kitti]`` section (:class:`soabench.kitti.config.KittiConfig`)."""
    from soabench.kitti.config import KittiConfig

    return key_table(KittiConfig())


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
    """``soabench COMMAND --help`` (``soabench --help`` for an empty command) as a fenced block, 100 columns wide."""
    from soabench.cli.main import build_parser

    parser = build_parser()
    if command:
        parser = _subcommands(parser)[command]
    formatter = parser.formatter_class
    parser.formatter_class = lambda prog: formatter(prog, width=_HELP_WIDTH)  # type: ignore[misc]
    try:
        text = parser.format_help().rstrip()
    finally:
        parser.formatter_class = formatter
    return "```text\n" + text + "\n```"


def _subcommands(parser) -> dict:
    """``{name: subparser}`` of the ``soabench`` parser, in the order ``soabench --help`` lists them."""
    import argparse

    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def commands_section() -> str:
    """Markdown: ``soabench --help``, then a section per command with its one-line summary and ``--help`` text."""
    import argparse

    from soabench.cli.main import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    summary = {a.dest: a.help for a in sub._choices_actions}
    parts = ["### soabench\n", cli_help("") + "\n"]
    for name in _subcommands(parser):
        parts.append(f"### soabench {name}\n")
        parts.append(f"{summary[name][0].upper()}{summary[name][1:]}.\n")
        parts.append(cli_help(name) + "\n")
    return "\n".join(parts)


def _plain_signature(obj: object) -> str:
    """``name(a, b=1, *, c=None)``: the parameters and defaults, without the annotations."""
    sig = inspect.signature(obj)
    params = [p.replace(annotation=inspect.Parameter.empty) for p in sig.parameters.values()]
    return str(sig.replace(parameters=params, return_annotation=inspect.Signature.empty))


_SECTION = re.compile(r"^(Args|Arguments|Returns|Raises|Example|Examples|Attributes):\s*$")


def _docstring_markdown(obj: object) -> tuple[str, str]:
    """(the docstring as Markdown without its example, the example's doctest lines) of a public object: the
    ``Args:`` / ``Returns:`` / ``Attributes:`` sections become lists of their entries."""
    doc = inspect.getdoc(obj) or ""
    out: list[str] = []
    example: list[str] = []
    section = ""
    for line in doc.splitlines():
        m = _SECTION.match(line)
        if m:
            section = m.group(1)
            if section not in ("Example", "Examples"):
                out += ["", f"**{section}**", ""]
            continue
        if section in ("Example", "Examples"):
            if line.strip():
                example.append(line[4:] if line.startswith("    ") else line)
            continue
        if section and line.startswith("    ") and not line.startswith("        "):
            name, sep, text = line.strip().partition(": ")
            out.append(f"* `{name}`: {text}" if sep and " " not in name.strip(",") else f"* {line.strip()}")
        elif section and line.startswith("        "):
            out.append("  " + line.strip())
        else:
            out.append(line)
    text = re.sub(
        r":(?:class|func|meth|mod|data|attr|exc|obj):`~?([\w.]+)`", lambda m: f"`{m.group(1)}`", "\n".join(out)
    )
    return re.sub(r"\n{3,}", "\n\n", text).strip(), "\n".join(example)


def python_api() -> str:
    """Markdown: every public function of ``soabench.api`` with its signature, docstring and runnable example, then
    every public class with its signature and docstring (``tests/repository/test_api_examples.py`` runs the
    examples)."""
    import soabench.api as sb

    functions = [n for n in sb.__all__ if inspect.isfunction(getattr(sb, n))]
    classes = [n for n in sb.__all__ if inspect.isclass(getattr(sb, n))]
    parts = ["## Functions\n"]
    for name in functions:
        text, example = _docstring_markdown(getattr(sb, name))
        parts.append(f"### `{name}`\n\n```python\nsb.{name}{_plain_signature(getattr(sb, name))}\n```\n\n{text}\n")
        if example:
            parts.append(f"Example:\n\n```python\n{example}\n```\n")
    parts.append("## Data and extension points\n")
    for name in classes:
        text, _ = _docstring_markdown(getattr(sb, name))
        try:
            signature = f"\n```python\nsb.{name}{_plain_signature(getattr(sb, name))}\n```\n"
        except (TypeError, ValueError):
            signature = ""
        parts.append(f"### `{name}`\n{signature}\n{text}\n")
    constants = [n for n in sb.__all__ if n not in functions and n not in classes]
    parts.append("## Constants\n\n" + "\n".join(f"* `{n}` = `{getattr(sb, n)!r}`" for n in constants) + "\n")
    return "\n".join(parts)


def check_metrics() -> str:
    """Markdown: every name a ``soabench check`` threshold may give as ``metric`` (the numeric columns of
    ``trials.csv``), grouped as the method groups them."""
    from soabench.experiment.runs.store import METRIC_COLUMNS, TIMING_COLUMNS
    from soabench.tracks.evaluate import TRACK_KEYS

    tracks = [c for c in METRIC_COLUMNS if c in TRACK_KEYS]
    positions = [c for c in METRIC_COLUMNS if c not in TRACK_KEYS]
    names = lambda cols: ", ".join(f"`{c}`" for c in cols)  # noqa: E731
    return "\n".join([
        f"* the set and delay metrics ([method §5](../method.md#s5)): {names(positions)};",
        f"* the track metrics of a tracker that labels its estimates ([method §9](../method.md#9-tracks)): "
        f"{names(tracks)};",
        f"* the wall-clock columns (never baselined): {names(TIMING_COLUMNS)}.",
    ])  # fmt: skip


_GENERATORS = {
    "check-metrics": lambda: check_metrics(),
    "python-api": lambda: python_api(),
    "parameters": lambda: parameter_table(),
    "scenario-keys": lambda: scenario_table(),
    "commands": lambda: commands_section(),
    "kitti-keys": lambda: kitti_table(),
}


def refresh(markdown: str) -> str:
    """``markdown`` with every generated block rewritten from the code (an unknown kind is an error)."""

    def fill(m: re.Match) -> str:
        kind = m.group("kind")
        if kind not in _GENERATORS:
            raise ValueError(f"unknown generated block 'soabench:{kind}'; known: {', '.join(_GENERATORS)}")
        return m.group(1) + "\n" + _GENERATORS[kind]().strip() + "\n\n" + m.group(4)

    return _BLOCK.sub(fill, markdown)


def pages() -> list[Path]:
    """Every Markdown page of the documentation."""
    return sorted(_DOCS.rglob("*.md"))


def stale_pages() -> list[Path]:
    """The pages whose generated blocks differ from what the installed code generates now."""
    return [p for p in pages() if refresh(text := p.read_text(encoding="utf-8")) != text]


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


# ----------------------------------------------------------------------------------- repository files outside docs/
_REPO_LINK = re.compile(r"(!?)\[([^\]]*)\]\(((?:\.\./)+)([^)\s#]+)(#[^)\s]*)?\)")


def _repository_links(markdown: str, src_uri: str):
    """``(match, repository path)`` of every link of the page ``src_uri`` that leaves ``docs/``."""
    depth = src_uri.count("/")
    for m in _REPO_LINK.finditer(markdown):
        ups = len(m.group(3)) // 3
        if ups <= depth:
            continue  # a link to another page or file of the site
        path = m.group(4)
        if ups > depth + 1 or not (_ROOT / path).exists():
            raise ValueError(f"docs/{src_uri} links to {m.group(3)}{path}, which is not a file of the repository")
        yield m, path


def on_files(files, config, **kwargs):
    """Serve a copy of every repository file outside ``docs/`` that a page links to (images, data; not Markdown)."""
    wanted: set[str] = set()
    for page in pages():
        src_uri = page.relative_to(_DOCS).as_posix()
        text = page.read_text(encoding="utf-8")
        text = _INCLUDE.sub(lambda m: include_report(m.group("path"), src_uri), text)  # noqa: B023
        for _m, path in _repository_links(text, src_uri):
            if (_ROOT / path).is_file() and not path.endswith(".md"):
                wanted.add(path)
    from mkdocs.structure.files import File

    for path in sorted(wanted):
        if files.get_file_from_path(path) is None:
            files.append(File(path, str(_ROOT), config["site_dir"], config["use_directory_urls"]))
    return files


def _site_links(markdown: str, src_uri: str) -> str:
    """Links leaving ``docs/`` pointed at the served copies; a Markdown file or a folder shown as its path."""
    up = "../" * src_uri.count("/")
    out, last = [], 0
    for m, path in _repository_links(markdown, src_uri):
        out.append(markdown[last : m.start()])
        if (_ROOT / path).is_file() and not path.endswith(".md"):
            out.append(f"{m.group(1)}[{m.group(2)}]({up}{path}{m.group(5) or ''})")
        elif path.rstrip("/").endswith(m.group(2).strip("`").rstrip("/")):  # the label is (the end of) the path
            out.append(f"`{path}`")
        else:
            out.append(f"{m.group(2)} (`{path}` in the repository)")
        last = m.end()
    out.append(markdown[last:])
    return "".join(out)


#: a committed report of ``results/`` shown on the site: a sentence linking the file in the page file, the report's
#: text (links rebased) on the site
_INCLUDE = re.compile(r"<!-- soabench:include (?P<path>\S+) -->.*?<!-- /soabench:include -->", re.S)
_LINK = re.compile(r"(!?\[[^\]]*\])\(([^)\s#]+)(#[^)\s]*)?\)")


def _included_reports() -> dict[str, str]:
    """``{report path: page src_uri}`` of every report a page shows."""
    return {
        m.group("path"): page.relative_to(_DOCS).as_posix()
        for page in pages()
        for m in _INCLUDE.finditer(page.read_text(encoding="utf-8"))
    }


def include_report(path: str, src_uri: str) -> str:
    """The report ``path`` (a Markdown file under ``results/``) for the page ``src_uri``: its title dropped (the
    page has its own), links rebased (to a docs page, to the page showing another report, or to the repository file)."""
    import posixpath

    target = (_ROOT / path).resolve()
    if _ROOT / "results" not in target.parents or target.suffix != ".md" or not target.is_file():
        raise ValueError(f"docs/{src_uri} includes {path!r}: only Markdown reports under results/ are shown")
    text = re.sub(r"\A# .*\n", "", target.read_text(encoding="utf-8"))  # the page has its own title
    text = re.sub(r"^# ", "## ", text, flags=re.M)  # a second title becomes a section
    here, depth = posixpath.dirname(path), src_uri.count("/")
    shown = _included_reports()

    def rebase(m: re.Match) -> str:
        label, link, anchor = m.group(1), m.group(2), m.group(3) or ""
        if re.match(r"^[a-z]+:", link):
            return m.group(0)
        repo = posixpath.normpath(posixpath.join(here, link)) + ("/" if link.endswith("/") else "")
        if repo.startswith("docs/"):
            return f"{label}({'../' * depth}{repo[len('docs/') :]}{anchor})"
        if repo in shown:
            page = shown[repo]
            return f"{label}({posixpath.relpath(page, posixpath.dirname(src_uri) or '.')}{anchor})"
        return f"{label}({'../' * (depth + 1)}{repo}{anchor})"

    return _LINK.sub(rebase, text)


def on_page_markdown(markdown: str, **kwargs) -> str:
    src = kwargs["page"].file.src_uri
    markdown = refresh(markdown)
    markdown = _API.sub(lambda m: api_blocks(), markdown)
    markdown = _INCLUDE.sub(lambda m: include_report(m.group("path"), src), markdown)
    return _site_links(markdown, src)


_CITE = re.compile(r"docs/((?:user-guide/)?[\w-]+)\.md(?:(?:\s|&nbsp;)+§(\d+(?:\.\d+)*))?")


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


def main(argv: list[str] | None = None) -> int:
    """``python docs/hooks.py [--check]``: rewrite (or, with ``--check``, list) the pages with stale blocks."""
    import sys

    args = sys.argv[1:] if argv is None else argv
    stale = stale_pages()
    for page in stale:
        if "--check" in args:
            print(f"stale: {page.relative_to(_ROOT)} (regenerate with: python docs/hooks.py)")
        else:
            page.write_text(refresh(page.read_text(encoding="utf-8")), encoding="utf-8")
            print(f"rewrote {page.relative_to(_ROOT)}")
    return 1 if stale and "--check" in args else 0


if __name__ == "__main__":
    raise SystemExit(main())
