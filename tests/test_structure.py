"""The package's structure, read from its source with ``ast`` (nothing is imported): imports
run one way. An import inside a function counts as much as one at the top of a module: a
cycle hidden in a function body is still a cycle.

There is no import cycle, and every import goes down the layers of docs/development.md
("Layers"), which ``LAYERS`` writes down: a new module is placed in a layer here before it
passes."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import diffcontrol

PACKAGE = Path(diffcontrol.__file__).parent


def _modules() -> dict[str, Path]:
    modules = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        modules[name] = path
    return modules


def import_graph() -> dict[str, set[str]]:
    """Each module of the package and the package's modules it imports, anywhere in it (a
    ``from .. import x`` imports the package itself, then ``x``)."""
    modules = _modules()
    graph: dict[str, set[str]] = defaultdict(set)
    for name, path in modules.items():
        here = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parent = here[: len(here) - node.level + 1]
                    base = ".".join([*parent, *([node.module] if node.module else [])])
                targets = [base, *(f"{base}.{alias.name}" for alias in node.names)]
            else:
                continue
            for target in targets:
                while target and target not in modules:
                    target = target.rpartition(".")[0]
                if target and target != name:
                    graph[name].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(component)

    for v in list(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_a_cycle_hidden_in_a_function():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [{"a", "b", "c"}]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle():
    found = [sorted(c) for c in cycles(import_graph())]
    assert not found, f"import cycles: {found}"


LAYERS = [
    "errors _version _registry _shell _timing _interrupts _jax_setup _fingerprint io _run_dir "
    "config settings controllers policies",
    "systems",
    "tasks",
    "rollout checks _checks _gym",
    "training identify mpc evaluation envs wrappers plots animation optimal _run_files deploy",
    "runs",
    "compare cli",
    "builtin",
]
"""The package's layers, lowest first, by the first name under ``diffcontrol.``: a module
imports its own layer and those below it (never one above); the package face
(``diffcontrol/__init__.py``) is outside the layers."""


def _layer(module: str) -> int:
    top = module.removeprefix("diffcontrol.").split(".")[0]
    for i, names in enumerate(LAYERS):
        if top in names.split():
            return i
    raise AssertionError(f"{module} is in no layer of LAYERS: place it there")


def test_every_import_goes_down_the_layers():
    graph = import_graph()
    upward = [
        f"{module} -> {target}"
        for module, targets in graph.items()
        if module != "diffcontrol"
        for target in targets
        if target != "diffcontrol" and _layer(target) > _layer(module)
    ]
    assert not upward, f"imports of a layer above: {sorted(upward)}"


def test_the_layer_check_sees_an_upward_import():
    assert _layer("diffcontrol.runs._loop") > _layer("diffcontrol.identify.fitted")
    assert _layer("diffcontrol.builtin.trebuchet.runs") == len(LAYERS) - 1


def test_the_package_face_and_the_base_import_no_layer():
    """``diffcontrol/__init__.py`` imports the public names lazily (by name, which no
    import statement shows), and the base modules import nothing above them."""
    graph = import_graph()
    base = {
        "diffcontrol.errors",
        "diffcontrol._registry",
        "diffcontrol._shell",
        "diffcontrol._version",
    }
    assert graph["diffcontrol"] <= base, graph["diffcontrol"]
    for module in base:
        assert graph.get(module, set()) <= base, (module, graph[module])
