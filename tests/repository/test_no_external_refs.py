"""NOTE: a repository-wide check, kept in its own file on purpose.

The product never points readers at files outside the repository: the developers' notes are not shipped, so README,
docs/, docstrings, messages, tests, baselines, benchmarks, the shipped networks and the committed results must cite
the docs/ pages instead (docs/method.md §X.Y for formulas and decisions, docs/user-guide/sumo.md for SUMO facts,
docs/development.md for the code's layout and habits). Branches written before docs/ existed are brought in line by
the maintainers' rewrite script; this test fails, naming file and line, until that is done.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from repo_paths import ROOT

SCOPE = ("README.md", "docs", "soabench", "tests", "baselines", "benchmarks", "sumo_nets", "results", "pyproject.toml")
TEXT = {".py", ".md", ".toml", ".txt", ".cfg", ".sh", ".yml", ".yaml", ".xml", ""}
# the names are split so that this file does not match itself
_PARTS = (("ALGORITHMS", ".md"), ("SUMO_", "NOTES"), ("DESIGN", ".md"), ("../", "shared"), ("/work/", "shared"))
FORBIDDEN = re.compile("|".join(re.escape(a + b) for a, b in _PARTS))


def _files() -> list[Path]:
    try:
        out = subprocess.run(["git", "ls-files", *SCOPE], cwd=ROOT, check=True, capture_output=True, text=True)
        names = out.stdout.splitlines()
    except (OSError, subprocess.CalledProcessError):  # not a git checkout: walk the folders
        names = [str(p.relative_to(ROOT)) for s in SCOPE for p in [ROOT / s, *(ROOT / s).rglob("*")] if p.is_file()]
    return [ROOT / n for n in names if Path(n).suffix in TEXT and (ROOT / n).is_file()]


def test_scope_is_not_empty():
    files = {p.relative_to(ROOT).parts[0] for p in _files()}
    assert {"README.md", "soabench", "tests", "docs"} <= files


def test_no_reference_to_files_outside_the_repository():
    hits = []
    for path in _files():
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        for n, line in enumerate(text.splitlines(), 1):
            if FORBIDDEN.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()[:100]}")
    assert not hits, "references to files outside the repository (cite docs/ instead):\n" + "\n".join(hits)
