"""The package's import graph: no cycle, and every import points down the layers.

Every module of :mod:`rfmap` is parsed (not imported) and all its imports are collected, absolute and relative,
at module level and inside functions alike: an import inside a function still ties the two modules together.  An
import of a package counts as an edge to its ``__init__`` only for names that are not submodules.

Layers, from the bottom: the core (grids, geometry, fields, metrics, results) <- classical solvers, the network and
the losses <- tasks, training, refinement and the surrogate <- the paper's experiments <- the command line.
"""
from __future__ import annotations

import ast
import importlib.util
import pkgutil

import pytest

import rfmap

#: Layer of every module, lowest first.  A module may import from its own layer or a lower one.
LAYERS: dict[str, int] = {
    # core
    "rfmap._version": 0, "rfmap.device": 0, "rfmap.geometry": 0, "rfmap.mesh": 0, "rfmap.inputs": 0, "rfmap.paper_fields": 0,
    "rfmap.random_fields": 0, "rfmap.fields": 0, "rfmap.metrics": 0, "rfmap.result": 0,
    "rfmap.surface": 0,
    # classical solvers, the network, the losses
    "rfmap.solvers": 1, "rfmap.solvers.lbs": 1, "rfmap.solvers.diffusion": 1, "rfmap.solvers.flow": 1,
    "rfmap.nn": 1, "rfmap.nn.blocks": 1, "rfmap.nn.model": 1, "rfmap.nn.fno": 1, "rfmap.nn.registry": 1,
    "rfmap.losses": 1, "rfmap.symmetry": 1,
    # tasks, training, refinement, inference, post-processing, plotting
    "rfmap.tasks": 2, "rfmap.config": 2, "rfmap.train": 2, "rfmap.refine": 2, "rfmap.surrogate": 2,
    "rfmap.pretrained": 2, "rfmap.repair": 2, "rfmap.validation": 2, "rfmap.teacher": 2, "rfmap.selection": 2, "rfmap.hybrid": 2, "rfmap.stress": 2, "rfmap.viz": 2,
    # the paper's experiments and applications, then the command line and the package's front door
    "rfmap.experiments": 3, "rfmap.cartogram": 3, "rfmap.compare": 3, "rfmap.studies": 3,
    "rfmap.cli": 4, "rfmap": 4,
}

CORE = ("rfmap.mesh", "rfmap.geometry", "rfmap.fields", "rfmap.metrics")
ABOVE_CORE = ("rfmap.nn", "rfmap.tasks", "rfmap.train", "rfmap.surrogate", "rfmap.experiments", "rfmap.cli")


def _modules() -> dict[str, tuple[str, bool]]:
    """``{name: (source path, is_package)}`` for rfmap and every module below it."""
    out = {"rfmap": (rfmap.__file__, True)}
    for info in pkgutil.walk_packages(rfmap.__path__, "rfmap."):
        spec = importlib.util.find_spec(info.name)
        out[info.name] = (spec.origin, info.ispkg)
    return out


def _imports(name: str, path: str, is_pkg: bool, known: set[str]) -> set[str]:
    """The rfmap modules that module ``name`` imports anywhere in its source."""
    tree = ast.parse(open(path, encoding="utf-8").read(), filename=path)
    package = name if is_pkg else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
            for t in targets:  # "import rfmap.a.b" imports rfmap.a.b (and its packages, which are always above)
                found.add(t)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            for alias in node.names:
                sub = f"{mod}.{alias.name}"
                found.add(sub if sub in known else mod)
    return {m for m in found if m in known and m != name}


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    mods = _modules()
    known = set(mods)
    return {name: _imports(name, path, is_pkg, known) for name, (path, is_pkg) in mods.items()}


def _reachable(graph, start: str) -> set[str]:
    seen, todo = set(), [start]
    while todo:
        for nxt in graph[todo.pop()]:
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return seen


def test_the_walk_finds_the_package(graph):
    assert {"rfmap.mesh", "rfmap.surrogate", "rfmap.train", "rfmap.solvers.diffusion", "rfmap.nn.model"} <= set(graph)
    assert "rfmap.geometry" in graph["rfmap.mesh"]
    assert "rfmap.losses" in graph["rfmap.tasks"]  # "from . import losses": a submodule imported by name
    assert "rfmap.solvers.lbs" in graph["rfmap.solvers"]


def test_no_import_cycle(graph):
    """Tarjan's strongly connected components: any component of more than one module is a cycle."""
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles among: {cycles}"


def test_every_module_has_a_layer(graph):
    missing = sorted(set(graph) - set(LAYERS))
    assert not missing, f"place these modules in a layer of LAYERS in tests/test_imports.py: {missing}"


def test_imports_point_down_the_layers(graph):
    upward = [(a, b) for a, deps in graph.items() for b in deps
              if a in LAYERS and b in LAYERS and LAYERS[b] > LAYERS[a]]
    assert not upward, f"imports from a higher layer: {sorted(upward)}"


def test_inference_does_not_depend_on_training(graph):
    reach = _reachable(graph, "rfmap.surrogate")
    assert not reach & {"rfmap.train", "rfmap.pretrained", "rfmap.config"}, sorted(reach)


@pytest.mark.parametrize("core", CORE)
def test_core_modules_stay_below_the_applications(graph, core):
    reach = _reachable(graph, core) | {core}
    above = sorted(m for m in reach if any(m == a or m.startswith(a + ".") for a in ABOVE_CORE))
    assert not above, f"{core} depends on {above}"
