"""MkDocs hook: pages that must not drift from the code are filled in from the code at build time.

* ``<!-- soabench:parameters -->`` becomes the table of every configuration key with its default and meaning, read
  from the dataclasses of :mod:`soabench.config` (the ``#:`` comment after each field is its description);
* ``<!-- soabench:help COMMAND -->`` becomes the ``soabench COMMAND --help`` text of :func:`soabench.cli.build_parser`.

Only our own package is imported; nothing is read from user files.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import re

_PARAMS = "<!-- soabench:parameters -->"
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


def parameter_table() -> str:
    """Markdown: one table per config section (``[section]`` of a TOML file)."""
    from soabench.config import Config

    parts = []
    cfg = Config()
    for sec in dataclasses.fields(Config):
        obj = getattr(cfg, sec.name)
        cls = type(obj)
        comments = _field_comments(cls)
        doc = (inspect.getdoc(cls) or "").splitlines()[0]
        doc = re.sub(r"\s*\(docs/method\.md[^)]*\)|\s*\(ALGORITHMS\.md[^)]*\)", "", doc).rstrip(".")
        parts.append(f"### `[{sec.name}]` {{#{sec.name}}}\n")
        parts.append(f"{doc}. Method: {_SECTION_REFS.get(sec.name, 'docs/method.md')}.\n")
        parts.append("| key | default | meaning |\n|---|---|---|")
        for f in dataclasses.fields(cls):
            default = getattr(obj, f.name)
            parts.append(f"| `{f.name}` | {_fmt_default(default)} | {_escape(comments.get(f.name, ''))} |")
        parts.append("")
    return "\n".join(parts)


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


def on_page_markdown(markdown: str, **kwargs) -> str:
    if _PARAMS in markdown:
        markdown = markdown.replace(_PARAMS, parameter_table())
    return _HELP.sub(lambda m: cli_help(m.group(1)), markdown)
