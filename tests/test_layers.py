"""pamrun's layers point one way: each package imports only the packages below it in
:data:`LAYERS`, no module import cycle, and the package graph at most 8 layers deep; and no
module or function is too long to read (:func:`test_sizes`).

Every ``import``/``from ... import`` of a pamrun module is read with ``ast`` (function-level
imports included, since they are edges too), not by importing anything.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pamrun
from pamrun.config import DYNAMICS_NAMES, FORCE_LAW_NAMES
from pamrun.physics import muscle

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
    assert len(graph) > 15 and "pamrun.evaluation.evaluate" in graph["pamrun.sweep.grid"]  # the graph is really read
    assert cycles(graph) == []


def test_the_cycle_finder_finds_one():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


# pamrun's packages from the bottom up: a package may import its own modules and those of the
# packages before it, never one after it. Packages on one line are side by side (neither imports
# the other). ``pamrun`` itself (its __init__ only registers the env with Gymnasium) sits below
# them all, and pamrun.cli above them all.
LAYERS = (
    ("config",),
    ("runs", "physics"),
    ("task",),
    ("learning",),
    ("evaluation",),
    ("training", "bench"),
    ("sweep",),
)
MAX_DEPTH = 8  # longest chain of package imports, the top-level modules included


def package_of(module: str) -> str:
    """``pamrun.task.env`` -> ``task``; ``pamrun`` -> ``root``; ``pamrun.cli`` -> ``top``."""
    parts = module.split(".")
    if len(parts) == 1:
        return "root"
    return parts[1] if len(parts) > 2 or (PACKAGE / parts[-1]).is_dir() else "top"


def ranks() -> dict[str, int]:
    return {"root": -1, **{name: i for i, layer in enumerate(LAYERS) for name in layer}, "top": len(LAYERS)}


def package_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for name, targets in graph.items():
        out.setdefault(package_of(name), set()).update(package_of(t) for t in targets)
    return {k: v - {k} for k, v in out.items()}


def depth(graph: dict[str, set[str]]) -> int:
    """The longest import chain, counted in modules (packages) along it."""
    memo: dict[str, int] = {}

    def d(v: str) -> int:
        if v not in memo:
            memo[v] = 1 + max((d(w) for w in graph[v]), default=0)
        return memo[v]

    return max(map(d, graph))


def test_every_package_has_a_layer_and_a_one_line_docstring():
    packages = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()}
    assert packages == {name for layer in LAYERS for name in layer}
    for name in packages:
        doc = ast.get_docstring(ast.parse((PACKAGE / name / "__init__.py").read_text()))
        assert doc and "\n" not in doc.strip(), f"pamrun.{name} needs a one-line docstring"


def test_packages_import_only_the_layers_below():
    rank = ranks()
    upward = {(package_of(m), package_of(t)) for m, targets in import_graph().items() for t in targets
              if package_of(m) != package_of(t) and rank[package_of(t)] >= rank[package_of(m)]}
    assert upward == set()


def test_the_layer_check_sees_an_upward_import():
    graph = import_graph()
    graph["pamrun.physics.body"] = graph["pamrun.physics.body"] | {"pamrun.task.env"}
    assert ("physics", "task") in {(a, b) for a, bs in package_graph(graph).items() for b in bs}
    assert ranks()["task"] > ranks()["physics"]


def test_the_package_graph_is_shallow():
    packages = package_graph(import_graph())
    assert "evaluation" in packages["training"]  # the graph is really read
    assert depth(packages) <= MAX_DEPTH
    assert depth({"a": {"b"}, "b": {"c"}, "c": set()}) == 3


def test_config_names_the_muscle_registries():
    assert set(muscle.FORCE_LAWS) == set(FORCE_LAW_NAMES)
    assert set(muscle.DYNAMICS) == set(DYNAMICS_NAMES)


MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 60


def oversized(modules: dict[str, Path]) -> list[str]:
    """Every module longer than MAX_MODULE_LINES and every function (or method) longer than
    MAX_FUNCTION_LINES, its decorators and docstring included."""
    found = []
    for name, path in sorted(modules.items()):
        text = path.read_text()
        if len(text.splitlines()) > MAX_MODULE_LINES:
            found.append(f"{name}: {len(text.splitlines())} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
                if node.end_lineno - first + 1 > MAX_FUNCTION_LINES:
                    found.append(f"{name}.{node.name} (line {node.lineno}): {node.end_lineno - first + 1} lines")
    return found


def test_sizes():
    assert oversized(module_names()) == []


def test_the_size_check_sees_a_long_function(tmp_path):
    path = tmp_path / "long.py"
    path.write_text("def f():\n" + "    x = 1\n" * MAX_FUNCTION_LINES)
    assert oversized({"long": path}) == [f"long.f (line 1): {MAX_FUNCTION_LINES + 1} lines"]
