"""Comments and docstrings of the package say what the code does and why, now: none cites an issue number
(``issue 31``, ``issues 6/7``, ``#31``); the reason a line exists is written out where it stands."""

from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

import soabench

PACKAGE = Path(soabench.__file__).resolve().parent
#: "issue 31", "Issue 14, item 3", "issues 6/7", "#31" (a GitHub reference), "GH-31"
ISSUE = re.compile(r"\bissues?\s*#?\d+|(?<![\w&#])#\d+\b|\bGH-\d+", re.IGNORECASE)


def _texts(source: str) -> list[tuple[int, str]]:
    """(line, text) of every comment and every docstring of ``source``."""
    out = [
        (tok.start[0], tok.string)
        for tok in tokenize.generate_tokens(io.StringIO(source).readline)
        if tok.type == tokenize.COMMENT
    ]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            doc = ast.get_docstring(node, clean=False)
            if doc is not None:
                out.append((node.body[0].lineno, doc))
    return sorted(out)


def issue_citations(source: str) -> list[tuple[int, str]]:
    """(line, cited text) of each issue number cited by a comment or docstring of ``source``."""
    return [(line, m.group(0)) for line, text in _texts(source) for m in ISSUE.finditer(text)]


def test_the_check_finds_what_it_looks_for():
    source = '"""Resumable runs (issue 7)."""\n\ndef f():\n    """See #31."""\n    return 1  # issues 6/7\n'
    assert [c for _, c in issue_citations(source)] == ["issue 7", "#31", "issues 6"]
    clean = '"""Table II of the paper, §2.9; row 35 of the register."""\nx = "#31"  # a string, not a comment\n'
    assert issue_citations(clean) == []


def test_no_comment_or_docstring_of_the_package_cites_an_issue():
    found = [
        f"{path.relative_to(PACKAGE.parent)}:{line}: {cited}"
        for path in sorted(PACKAGE.rglob("*.py"))
        for line, cited in issue_citations(path.read_text(encoding="utf-8"))
    ]
    assert not found, "comments and docstrings cite issue numbers:\n" + "\n".join(found)
