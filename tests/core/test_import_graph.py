"""Dependencies point one way: no import cycle between modules, and none between packages beyond
the ones listed below as known debt (each with the reason it is still there).

The graph is read from the source with `ast` (nothing is imported): every `import` and
`from ... import` of a project module, at module level or inside a function (a function-level
import still makes a cycle; it only hides it until the call). `from pkg import name` counts as an
edge to `pkg.name` when that is a module, else to `pkg`. `if TYPE_CHECKING:` blocks are skipped.
A new cycle fails the test; so does a listed one that disappeared (then delete it from the list).
"""

from __future__ import annotations

import ast
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("envs", "actors", "learner", "kb_service", "evals", "viewer", "modeling")

#: Module cycles still present. Empty is the goal.
KNOWN_MODULE_CYCLES: set[frozenset[str]] = set()

#: Package cycles still present (a package: a top-level package, an `envs` subpackage, or one
#: domain). Empty: envs.core <- envs.data <- envs.rewards / kb_service <- envs.registry <- envs.env
#: <- modeling <- actors <- learner <- evals / viewer (docs/architecture order in README "Layout").
KNOWN_PACKAGE_CYCLES: set[frozenset[str]] = set()


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for package in PACKAGES for p in (ROOT / package).rglob("*.py")}


def import_edges() -> dict[str, set[str]]:
    """module -> the project modules it imports (module level and inside functions)."""
    modules = _modules()

    def resolve(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    edges: dict[str, set[str]] = defaultdict(set)
    for module, path in modules.items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        stack: list[ast.AST] = [ast.parse(path.read_text(encoding="utf-8"))]
        while stack:
            node = stack.pop()
            for child in ast.iter_child_nodes(node):
                if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.dump(child.test):
                    continue
                targets: list[str] = []
                if isinstance(child, ast.Import):
                    targets = [alias.name for alias in child.names]
                elif isinstance(child, ast.ImportFrom):
                    base = child.module or ""
                    if child.level:
                        parts = package.split(".")
                        parts = parts[: len(parts) - (child.level - 1)]
                        base = ".".join(parts + ([base] if base else []))
                    targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in child.names]
                for target in targets:
                    found = resolve(target)
                    if found and found != module:
                        edges[module].add(found)
                stack.append(child)
    return edges


def cycles(edges: dict[str, set[str]]) -> set[frozenset[str]]:
    """Strongly connected components of more than one node (Tarjan)."""
    sys.setrecursionlimit(max(10_000, sys.getrecursionlimit()))
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: set[frozenset[str]] = set()

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.add(frozenset(component))

    for node in list(edges):
        if node not in index:
            visit(node)
    return found


def package_of(module: str) -> str:
    parts = module.split(".")
    if parts[0] == "envs" and len(parts) > 2 and parts[1] == "domains":
        return ".".join(parts[:3])
    if parts[0] == "envs" and len(parts) > 1:
        return ".".join(parts[:2])
    return parts[0]


def test_no_import_cycle_between_modules():
    found = cycles(import_edges())
    assert found - KNOWN_MODULE_CYCLES == set(), f"new module import cycles: {found - KNOWN_MODULE_CYCLES}"
    assert KNOWN_MODULE_CYCLES - found == set(), f"fixed, remove from KNOWN_MODULE_CYCLES: {KNOWN_MODULE_CYCLES - found}"


def test_no_import_cycle_between_packages():
    edges: dict[str, set[str]] = defaultdict(set)
    for module, targets in import_edges().items():
        for target in targets:
            if package_of(module) != package_of(target):
                edges[package_of(module)].add(package_of(target))
    found = cycles(edges)
    assert found - KNOWN_PACKAGE_CYCLES == set(), f"new package import cycles: {sorted(map(sorted, found - KNOWN_PACKAGE_CYCLES))}"
    assert KNOWN_PACKAGE_CYCLES - found == set(), f"fixed, remove from KNOWN_PACKAGE_CYCLES: {KNOWN_PACKAGE_CYCLES - found}"


def test_the_graph_reader_sees_function_level_imports_and_cycles(tmp_path):
    """The detector itself: a function-level import closing a loop is a cycle."""
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(edges) == {frozenset({"a", "b", "c"})}
    assert "learner.tasks" in import_edges()["learner.sft"], "function-level import in learner.sft not seen"
