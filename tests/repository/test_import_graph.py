"""The import graph of soabench agrees with docs/development.md ("Layers").

The graph is read from the source with ``ast``: every ``import`` statement of every module, those inside functions
included (they run when the function is called); imports under ``if TYPE_CHECKING:`` never run and are left out. The
page's layer table gives each module its layer; an import from a lower layer to a higher one is "upward". The test
fails on an import circle, on an upward import the page does not list with its reason, on a listed one that is no
longer in the code, on an import inside a function of a name its module already imports at the top, and on an
import inside a function that defers nothing: one whose modules the importing module's own unconditional top-level
imports load already (followed through soabench's modules; an import inside a function is there to put off loading
something costly, matplotlib, numba kernels, libsumo, an optional extra, or to break a circle).
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


@dataclass(frozen=True)
class Loads:
    """What each module's unconditional top-level imports name (soabench modules; other modules as
    :func:`_other_modules` names them), and its imports inside functions: (line, soabench modules, other names)."""

    top: dict[str, set[str]]
    top_other: dict[str, set[str]]
    inside: dict[str, list[tuple[int, tuple[str, ...], tuple[str, ...]]]]


def _other_modules(node: ast.Import | ast.ImportFrom) -> tuple[str, ...]:
    """What an import statement loads outside soabench: ``X`` for ``import X``, ``X:a`` for ``from X import a``
    (``a`` may be a submodule of ``X`` that ``X`` alone does not load)."""
    if isinstance(node, ast.Import):
        return tuple(a.name for a in node.names if a.name.split(".")[0] != "soabench")
    module = node.module or ""
    if node.level or module.split(".")[0] == "soabench":
        return ()
    return tuple(f"{module}:{a.name}" for a in node.names)


@cache
def loads() -> Loads:
    modules = module_names()
    top: dict[str, set[str]] = defaultdict(set)
    top_other: dict[str, set[str]] = defaultdict(set)
    inside: dict[str, list[tuple[int, tuple[str, ...], tuple[str, ...]]]] = defaultdict(list)
    for module, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        body = {id(n) for n in tree.body}
        for node, in_function in _imports(tree):
            targets = tuple(_targets(node, module, path.name == "__init__.py", modules))
            if in_function:
                inside[module].append((node.lineno, targets, _other_modules(node)))
            elif id(node) in body:  # unconditional (an import under try/if may not happen)
                top[module].update(targets)
                top_other[module].update(_other_modules(node))
    return Loads(top, top_other, inside)


def loaded_at_import(module: str, top: dict[str, set[str]]) -> set[str]:
    """The soabench modules importing ``module`` loads through unconditional top-level imports (its packages
    included)."""

    def with_packages(name: str) -> list[str]:
        parts = name.split(".")
        return [".".join(parts[: i + 1]) for i in range(len(parts))]

    seen: set[str] = set()
    stack = with_packages(module)
    while stack:
        name = stack.pop()
        if name not in seen:
            seen.add(name)
            for target in top.get(name, ()):
                stack += with_packages(target)
    return seen


def deferring_nothing(graph: Loads) -> list[str]:
    """``module:line`` of every import inside a function whose modules are loaded when its module is."""
    out = []
    for module, statements in graph.inside.items():
        loaded = loaded_at_import(module, graph.top)
        other = set().union(*(graph.top_other.get(m, set()) for m in loaded))
        other |= {f"{name.rpartition('.')[0]}:{name.rpartition('.')[2]}" for name in other if "." in name}
        for line, targets, others in statements:
            if (targets or others) and set(targets) <= loaded and set(others) <= other:
                out.append(f"{module}:{line}")
    return sorted(out)


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


def test_every_import_inside_a_function_defers_something():
    found = deferring_nothing(loads())
    assert not found, f"imports inside functions of what their module loads already (import at the top): {found}"


def test_the_reading_finds_an_import_inside_a_function_that_defers_nothing():
    """The check can fail: ``a`` loads ``b`` (and with it numpy, scipy.stats, matplotlib) at the top, so importing
    those inside a function of ``a`` defers nothing, while a submodule nothing loads is deferred."""
    graph = Loads(
        top={"soabench.a": {"soabench.b"}},
        top_other={"soabench.b": {"numpy", "scipy.stats", "matplotlib"}},
        inside={"soabench.a": [(5, ("soabench.b",), ()), (6, (), ("numpy",)), (7, (), ("scipy:stats",)),
                               (8, (), ("matplotlib:patheffects",)), (9, (), ("shapely",))]},
    )  # fmt: skip
    # matplotlib is loaded, but not its patheffects; shapely not at all
    assert deferring_nothing(graph) == ["soabench.a:5", "soabench.a:6", "soabench.a:7"]


def test_the_reading_finds_a_circle_and_an_upward_import():
    """The checks can fail: a circle through an import inside a function, and an import from a lower layer."""
    edges = [Edge("soabench.a", "soabench.b", 1, False), Edge("soabench.b", "soabench.a", 9, True)]
    assert circles(edges) == [["soabench.a", "soabench.b"]]
    up = upward_edges([Edge("soabench.sensor", "soabench.figures.style", 3, True)])
    assert list(up) == [("soabench.sensor", "soabench.figures.style")]
