"""The package's dependency graph: no cycle, and every import and every call points down the layers.

Every module of :mod:`rfmap` is parsed (not imported) and all its imports are collected, absolute and relative,
at module level and inside functions alike: an import inside a function still ties the two modules together.  An
import of a package counts as an edge to its ``__init__`` only for names that are not submodules.

A module also depends on another when it calls, at run time, a method of an object of a class defined there, even
without importing it (``compare_methods(density, surrogate)`` calling ``surrogate.map``).  Such calls are found by
name: ``x.name(...)`` where ``name`` is a public method of exactly one module's classes and of no builtin, numpy,
torch, scipy, matplotlib or standard-library type the package uses (those names are ambiguous); calls on an
imported name (a module or a class) are imports already.

Layers, from the bottom: the core (grids, geometry, fields, metrics, results) <- classical solvers, the network and
the losses <- tasks, training, refinement and the surrogate <- the paper layer, applications and plotting <- the
command line.
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
    "rfmap._version": 0, "rfmap.core": 0, "rfmap.core.device": 0, "rfmap.core.geometry": 0, "rfmap.core.mesh": 0, "rfmap.core.inputs": 0, "rfmap.fields.paper": 0,
    "rfmap.fields.random": 0, "rfmap.fields": 0, "rfmap.fields.hard": 0, "rfmap.core.metrics": 0, "rfmap.core.result": 0,
    "rfmap.core.surface": 0, "rfmap.core.folds": 0, "rfmap.core.wording": 0,
    # classical solvers, the network, the losses
    "rfmap.solvers": 1, "rfmap.solvers.lbs": 1, "rfmap.solvers.diffusion": 1, "rfmap.solvers.flow": 1,
    "rfmap.solvers.spectral": 1, "rfmap.solvers.raster": 1, "rfmap.solvers.cartoflow": 1,
    "rfmap.solvers.cartodiffusion": 1, "rfmap.solvers.cosine": 1, "rfmap.solvers.heun": 1, "rfmap.solvers.bs32": 1,
    "rfmap.solvers.heatflow": 1, "rfmap.solvers.heatfield": 1, "rfmap.solvers.locate": 1,
    "rfmap.solvers.residual": 1,
    "rfmap.nn": 1, "rfmap.nn.blocks": 1, "rfmap.nn.model": 1, "rfmap.nn.grow": 1, "rfmap.nn.fno": 1, "rfmap.nn.registry": 1,
    "rfmap.tasks.losses": 1, "rfmap.nn.symmetry": 1,
    # tasks, training, refinement, inference, post-processing, plotting
    "rfmap.tasks": 2, "rfmap.tasks.base": 2, "rfmap.tasks.heldout": 2, "rfmap.tasks.density": 2,
    "rfmap.tasks.beltrami": 2, "rfmap.training.config": 2, "rfmap.training": 2, "rfmap.training.__main__": 2,
    "rfmap.training.data": 2, "rfmap.training.averaging": 2, "rfmap.training.state": 2, "rfmap.training.loop": 2,
    "rfmap.training.cli": 2, "rfmap.training.lineage": 2, "rfmap.finish.refine": 2, "rfmap.surrogate": 2,
    "rfmap.finish": 2, "rfmap.finish.report": 2, "rfmap.finish.draft": 2, "rfmap.finish.quality": 2,
    "rfmap.finish.query": 2, "rfmap.finish.stages": 2, "rfmap.finish.pipeline": 2,
    "rfmap.pretrained": 2, "rfmap.finish.repair": 2, "rfmap.finish.repair.dispatch": 2,
    "rfmap.finish.repair.lbs": 2, "rfmap.finish.repair.local": 2, "rfmap.finish.repair.scale": 2, "rfmap.finish.repair.embedding": 2,
    "rfmap.finish.shorten": 2, "rfmap.training.validation": 2, "rfmap.tasks.teacher": 2, "rfmap.training.selection": 2, "rfmap.finish.polish": 2, "rfmap.tasks.objectives": 2,
    # the paper layer, the applications and plotting, then the command line and the package's front door
    "rfmap.viz": 3, "rfmap.viz.figures": 3, "rfmap.viz.meshes": 3, "rfmap.viz.volumes": 3, "rfmap.viz.diffusion": 3, "rfmap.viz.architecture": 3,
    "rfmap.viz.training": 3, "rfmap.viz.cartograms": 3, "rfmap.viz.studies": 3,
    "rfmap.viz.repairs": 3, "rfmap.viz.wall_time": 3,
    "rfmap.paper": 3, "rfmap.paper.tables": 3, "rfmap.paper.reproduce": 3,
    "rfmap.paper.generalization": 3, "rfmap.paper.recipes": 3, "rfmap.paper.budget_text": 3, "rfmap.paper.benchmarks": 3,
    "rfmap.paper.flow_studies": 3, "rfmap.paper.design": 3, "rfmap.paper.cartograms": 3, "rfmap.paper.comparison": 3,
    "rfmap.paper.ablations": 3, "rfmap.paper.folding": 3, "rfmap.paper._execution": 3, "rfmap.paper._apidocs": 3,
    "rfmap.cartogram": 3, "rfmap.cartogram.resize": 3, "rfmap.cartogram.options": 3,
    "rfmap.cartogram.data": 3, "rfmap.cartogram.series": 3, "rfmap.cartogram.metrics": 3,
    "rfmap.cartogram.synthetic": 3, "rfmap.cartogram.output": 3, "rfmap.cartogram.html": 3,
    "rfmap.cartogram.reprojection": 3,
    "rfmap.cartogram.insets": 3, "rfmap.cartogram.passmap": 3, "rfmap.cartogram.methods": 3,
    "rfmap.cartogram.methods.base": 3, "rfmap.cartogram.methods.flow": 3, "rfmap.cartogram.methods.diffusion": 3,
    "rfmap.cartogram.methods.neural": 3, "rfmap.paper.verdicts": 3,
    "rfmap.cartogram.regions": 3, "rfmap.cartogram.projection": 3, "rfmap.paper.compare": 3, "rfmap.training.records": 3,
    "rfmap.cli": 4, "rfmap.cli.__main__": 4, "rfmap.cli.commands": 4, "rfmap.cli.base": 4, "rfmap.cli.cartogram": 4, "rfmap.cli.lazy_parser": 4,
    "rfmap.cli.reference": 4,
    "rfmap": 4,
}

CORE = ("rfmap.core.mesh", "rfmap.core.geometry", "rfmap.fields", "rfmap.core.metrics")
ABOVE_CORE = ("rfmap.nn", "rfmap.tasks", "rfmap.training", "rfmap.surrogate",
              "rfmap.paper", "rfmap.cli.commands")


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


def _foreign_methods() -> set[str]:
    """Method names of the builtin, numpy, torch, scipy, matplotlib and standard-library types the package calls
    methods on: a call of one of these names may be on such an object, so it is no evidence of a dependency."""
    import argparse
    import io
    import multiprocessing
    import queue
    import threading

    import matplotlib
    import numpy as np
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
    import torch

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    plt.close(fig)
    types = (dict, list, set, str, bytes, tuple, int, float, complex, np.ndarray, np.random.Generator, torch.Tensor,
             torch.nn.Module, torch.optim.Optimizer, io.TextIOWrapper, queue.Queue, threading.Thread, threading.Event,
             argparse.ArgumentParser, sp.csr_matrix, type(spla.splu(sp.csc_matrix(np.eye(2)))), fig, ax,
             multiprocessing.get_context("spawn").Queue)
    return {name for t in types for name in dir(t)}


def _calls(trees: dict[str, ast.Module]) -> dict[str, set[str]]:
    """``{module: the modules whose classes' methods it calls}``, by method name (see the module docstring)."""
    owners: dict[str, set[str]] = {}
    for name, tree in trees.items():
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                for f in node.body:
                    if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef)) and not f.name.startswith("_"):
                        owners.setdefault(f.name, set()).add(name)
    foreign = _foreign_methods()
    owner = {m: next(iter(mods)) for m, mods in owners.items() if len(mods) == 1 and m not in foreign}
    out: dict[str, set[str]] = {}
    for name, tree in trees.items():
        imported = {(a.asname or a.name).split(".")[0] for node in ast.walk(tree)
                    if isinstance(node, (ast.Import, ast.ImportFrom)) for a in node.names}
        out[name] = {owner[node.func.attr] for node in ast.walk(tree)
                     if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                     and node.func.attr in owner and owner[node.func.attr] != name
                     and not (isinstance(node.func.value, ast.Name) and node.func.value.id in imported)}
    return out


@pytest.fixture(scope="module")
def parsed() -> tuple[dict[str, tuple[str, bool]], dict[str, ast.Module]]:
    mods = _modules()
    return mods, {name: ast.parse(open(path, encoding="utf-8").read(), filename=path) for name, (path, _) in mods.items()}


@pytest.fixture(scope="module")
def graph(parsed) -> dict[str, set[str]]:
    """The imports."""
    mods, trees = parsed
    known = set(mods)
    return {name: _imports(name, path, is_pkg, known) for name, (path, is_pkg) in mods.items()}


@pytest.fixture(scope="module")
def calls(parsed) -> dict[str, set[str]]:
    """The calls at run time."""
    return _calls(parsed[1])


@pytest.fixture(scope="module")
def depends(graph, calls) -> dict[str, set[str]]:
    """Imports and calls together."""
    return {name: graph[name] | calls[name] for name in graph}


def _reachable(graph, start: str) -> set[str]:
    seen, todo = set(), [start]
    while todo:
        for nxt in graph[todo.pop()]:
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return seen


def test_the_walk_finds_the_package(graph):
    assert {"rfmap.core.mesh", "rfmap.surrogate", "rfmap.training", "rfmap.solvers.diffusion", "rfmap.nn.model"} <= set(graph)
    assert "rfmap.core.geometry" in graph["rfmap.core.mesh"]
    assert "rfmap.tasks.losses" in graph["rfmap.tasks.base"]  # "from .. import losses": a submodule imported by name
    assert "rfmap.solvers.lbs" in graph["rfmap.solvers"]


def _cycles(graph) -> list[list[str]]:
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
    return cycles


def test_no_import_cycle(graph):
    cycles = _cycles(graph)
    assert not cycles, f"import cycles among: {cycles}"


def test_the_call_walk_finds_calls(calls):
    assert "rfmap.surrogate" in calls["rfmap.training.validation"]  # evaluate(sur, ...) calls sur.map
    assert "rfmap.surrogate" in calls["rfmap.paper.benchmarks"]  # compare_methods calls surrogate.map


def test_no_cycle_of_imports_and_calls(depends):
    """A module that calls another at run time while that one imports it (or calls it) is a cycle too."""
    cycles = _cycles(depends)
    assert not cycles, f"cycles of imports and run-time calls among: {cycles}"


def test_every_module_has_a_layer(graph):
    missing = sorted(set(graph) - set(LAYERS))
    assert not missing, f"place these modules in a layer of LAYERS in tests/test_imports.py: {missing}"


def test_imports_point_down_the_layers(graph):
    upward = [(a, b) for a, deps in graph.items() for b in deps
              if a in LAYERS and b in LAYERS and LAYERS[b] > LAYERS[a]]
    assert not upward, f"imports from a higher layer: {sorted(upward)}"


def test_calls_point_down_the_layers(calls):
    upward = [(a, b) for a, deps in calls.items() for b in deps
              if a in LAYERS and b in LAYERS and LAYERS[b] > LAYERS[a]]
    assert not upward, f"run-time calls into a higher layer: {sorted(upward)}"


def test_inference_does_not_depend_on_training(depends):
    reach = _reachable(depends, "rfmap.surrogate")
    assert not {m for m in reach if m.startswith(("rfmap.training", "rfmap.pretrained"))}, sorted(reach)


@pytest.mark.parametrize("core", CORE)
def test_core_modules_stay_below_the_applications(depends, core):
    reach = _reachable(depends, core) | {core}
    above = sorted(m for m in reach if any(m == a or m.startswith(a + ".") for a in ABOVE_CORE))
    assert not above, f"{core} depends on {above}"
