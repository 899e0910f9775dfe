"""pamrun's layers point one way: no import cycle, and config/ imports no other pamrun module.

Every ``import``/``from ... import`` of a pamrun module is read with ``ast`` (function-level
imports included, since they are edges too), not by importing anything.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pamrun
from pamrun import muscle
from pamrun.config import DYNAMICS_NAMES, FORCE_LAW_NAMES

PACKAGE = Path(pamrun.__file__).parent


def module_names() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


def import_graph() -> dict[str, set[str]]:
    """Module -> the pamrun modules it imports (a ``from pkg import name`` of a submodule counts as it)."""
    modules = module_names()

    def owner(name: str) -> str:
        while name not in modules and "." in name:
            name = name.rsplit(".", 1)[0]
        return name if name in modules else ""

    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in modules else node.module
                           for a in node.names]
            for target in targets:
                if target.split(".")[0] == "pamrun" and owner(target) not in ("", name):
                    graph[name].add(owner(target))
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_no_import_cycle():
    graph = import_graph()
    assert len(graph) > 15 and "pamrun.evaluate" in graph["pamrun.sweep"]  # the graph is really read
    assert cycles(graph) == []


def test_the_cycle_finder_finds_one():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_config_is_the_bottom_layer():
    upward = {name: sorted(t for t in targets if not t.startswith("pamrun.config"))
              for name, targets in import_graph().items() if name.startswith("pamrun.config")}
    assert {k: v for k, v in upward.items() if v} == {}


def test_config_names_the_muscle_registries():
    assert set(muscle.FORCE_LAWS) == set(FORCE_LAW_NAMES)
    assert set(muscle.DYNAMICS) == set(DYNAMICS_NAMES)
