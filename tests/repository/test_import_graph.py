"""The import graph of soabench agrees with docs/development.md ("Layers").

The graph is read from the source with ``ast``: every ``import`` statement of every module, those inside functions
included (they run when the function is called); imports under ``if TYPE_CHECKING:`` never run and are left out. The
page's layer table gives each module its layer; an import from a lower layer to a higher one is "upward". The test
fails on an import circle, on an upward import the page does not list with its reason, on a listed one that is no
longer in the code, and on an import inside a function of a name its module already imports at the top.
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from repo_paths import ROOT

PACKAGE = ROOT / "soabench"
PAGE = ROOT / "docs" / "development.md"


@dataclass(frozen=True)
class Edge:
    """One import statement's target module, seen from ``source`` (``line``; ``in_function``: inside a def)."""

    source: str
    target: str
    line: int
    in_function: bool


def module_names() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _targets(node: ast.Import | ast.ImportFrom, module: str, is_package: bool, modules: dict[str, Path]) -> list[str]:
    """The soabench modules an import statement loads (``from a import b`` loads ``a.b`` when it is a module)."""
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names]
    else:
        base = node.module or ""
        if node.level:
            parts = module.split(".") if is_package else module.split(".")[:-1]
            parts = parts[: len(parts) - (node.level - 1)]
            base = ".".join(parts + ([node.module] if node.module else []))
        names = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
    out = []
    for name in names:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        if name.startswith("soabench") and name != module:
            out.append(name)
    return out


def _type_checking(node: ast.AST) -> bool:
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def _imports(node: ast.AST, in_function: bool = False) -> list[tuple[ast.Import | ast.ImportFrom, bool]]:
    """Every import statement under ``node`` that runs, with whether it sits inside a function."""
    out: list[tuple[ast.Import | ast.ImportFrom, bool]] = []
    for child in ast.iter_child_nodes(node):
        if _type_checking(child):
            continue
        if isinstance(child, (ast.Import, ast.ImportFrom)):
            out.append((child, in_function))
        out += _imports(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)))
    return out


@cache
def import_edges() -> tuple[list[Edge], list[str]]:
    """Every import edge of the package, and the imports inside functions of a name already imported at the top."""
    modules = module_names()
    edges: list[Edge] = []
    repeated: list[str] = []
    for module, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        is_package = path.name == "__init__.py"
        top = {
            (getattr(n, "module", None), a.name, a.asname)
            for n in tree.body
            if isinstance(n, (ast.Import, ast.ImportFrom))
            for a in n.names
        }
        for node, in_function in _imports(tree):
            for target in _targets(node, module, is_package, modules):
                edges.append(Edge(module, target, node.lineno, in_function))
            if in_function and any((getattr(node, "module", None), a.name, a.asname) in top for a in node.names):
                repeated.append(f"{module}:{node.lineno}")
    return edges, repeated


def _table(heading: str) -> list[list[str]]:
    """The rows of the first Markdown table under ``heading`` of the page, as lists of cell texts."""
    text = PAGE.read_text(encoding="utf-8")
    section = text.split(heading, 1)[1]
    rows = []
    for line in section.splitlines()[1:]:
        if line.startswith("#"):
            break
        if line.startswith("|") and not re.match(r"\|\s*-", line):
            rows.append([c.strip() for c in line.strip().strip("|").split("|")])
    return rows[1:]  # without the header


def _names(cell: str) -> list[str]:
    return [f"soabench.{n}" if n != "soabench" else n for n in re.findall(r"`([\w.]+)`", cell)]


def layers() -> dict[str, float]:
    """Module prefix -> rank from the page's layer table (rows bottom to top); in a row whose layer is named "in
    this order", a module listed later ranks above one listed earlier."""
    rank: dict[str, float] = {}
    for i, (layer, modules, *_) in enumerate(_table("### Layers")):
        ordered = "in this order" in layer
        for j, name in enumerate(_names(modules)):
            rank[name] = i + (j / 100 if ordered else 0)
    return rank


def layer_of(module: str, rank: dict[str, float]) -> float:
    """The rank of the longest listed name of ``module`` (the bare package ``soabench`` is its ``__init__`` only)."""
    name = module
    while name not in rank or (name == "soabench" != module):
        assert "." in name, f"{module} is in no layer of docs/development.md (### Layers)"
        name = name.rpartition(".")[0]
    return rank[name]


def listed_upward() -> dict[tuple[str, str], str]:
    rows = _table("### Imports that run back up")
    return {(_names(src)[0], _names(dst)[0]): why for src, dst, why in rows}


def upward_edges(edges: list[Edge]) -> dict[tuple[str, str], list[Edge]]:
    rank = layers()
    out: dict[tuple[str, str], list[Edge]] = defaultdict(list)
    for e in edges:
        if layer_of(e.target, rank) > layer_of(e.source, rank):
            out[(e.source, e.target)].append(e)
    return out


def circles(edges: list[Edge]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    graph: dict[str, set[str]] = defaultdict(set)
    for e in edges:
        graph[e.source].add(e.target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_circle_counting_imports_inside_functions():
    edges, _ = import_edges()
    assert any(e.in_function for e in edges)  # the reading sees the imports inside functions
    assert circles(edges) == []


def test_every_upward_import_is_listed_with_its_reason_and_every_listed_one_exists():
    found = upward_edges(import_edges()[0])
    listed = listed_upward()
    unlisted = {f"{s} -> {t} (line {es[0].line})" for (s, t), es in found.items() if (s, t) not in listed}
    assert not unlisted, f"upward imports not listed in docs/development.md: {sorted(unlisted)}"
    assert not set(listed) - set(found), f"listed but no longer imported: {sorted(set(listed) - set(found))}"
    assert all(len(why.split()) >= 4 for why in listed.values()), "every listed upward import says why"


def test_the_page_states_the_numbers_it_lists():
    text = PAGE.read_text(encoding="utf-8")
    listed = listed_upward()
    stated = re.search(r"(\d+) imports? runs? back up", text)
    assert stated and int(stated.group(1)) == len(listed)
    assert "no import circle" in text


def test_no_import_inside_a_function_repeats_one_at_the_top():
    assert import_edges()[1] == []


def test_the_reading_finds_a_circle_and_an_upward_import():
    """The checks can fail: a circle through an import inside a function, and an import from a lower layer."""
    edges = [Edge("soabench.a", "soabench.b", 1, False), Edge("soabench.b", "soabench.a", 9, True)]
    assert circles(edges) == [["soabench.a", "soabench.b"]]
    up = upward_edges([Edge("soabench.sensor", "soabench.figures.style", 3, True)])
    assert list(up) == [("soabench.sensor", "soabench.figures.style")]
