"""The API reference (book/api.md) documents every public name of the package."""
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "book" / "api.md"
#: the modules whose ``__all__`` the page must cover: the package and the modules a user imports from
MODULES = ["rfmap", "rfmap.surrogate", "rfmap.pretrained", "rfmap.result", "rfmap.solvers", "rfmap.fields",
           "rfmap.paper_fields", "rfmap.random_fields", "rfmap.metrics", "rfmap.repair", "rfmap.surface", "rfmap.refine",
           "rfmap.symmetry", "rfmap.config", "rfmap.train", "rfmap.tasks", "rfmap.losses", "rfmap.validation",
           "rfmap.device", "rfmap.nn", "rfmap.mesh", "rfmap.geometry", "rfmap.experiments", "rfmap.viz", "rfmap.cartogram",
           "rfmap.training", "rfmap.folds", "rfmap.shorten", "rfmap.regions", "rfmap.paper.tables",
           "rfmap.paper.reproduce", "rfmap.paper.generalization", "rfmap.paper.recipes", "rfmap.paper.benchmarks",
           "rfmap.paper.flow_studies", "rfmap.finish", "rfmap.finish.report", "rfmap.finish.draft",
           "rfmap.finish.stages", "rfmap.finish.query", "rfmap.finish.quality", "rfmap.finish.pipeline",
           "rfmap.viz.figures", "rfmap.viz.meshes", "rfmap.viz.volumes", "rfmap.viz.architecture",
           "rfmap.viz.training", "rfmap.viz.cartograms", "rfmap.viz.studies", "rfmap.teacher", "rfmap.selection",
           "rfmap.studies"]
DIRECTIVE = re.compile(r"^\.\. (auto\w+):: (\S+)\n((?:[ \t]+:[^\n]*\n)*)", re.M)


def _directives() -> list[tuple[str, str, str]]:
    return DIRECTIVE.findall(PAGE.read_text(encoding="utf-8"))


def _resolve(dotted: str):
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(dotted)


def _documented() -> set[tuple[str, int]]:
    """(name, id(object)) of everything the page documents: explicit directives, and the ``__all__`` of every
    ``automodule`` with ``:members:`` (autodoc documents exactly those)."""
    seen = set()
    for kind, target, options in _directives():
        if kind == "automodule":
            if re.search(r":members:\s*\n", options):
                mod = importlib.import_module(target)
                seen |= {(name, id(getattr(mod, name))) for name in mod.__all__}
        else:
            seen.add((target.rsplit(".", 1)[-1], id(_resolve(target))))
    return seen


def _public(module: str):
    mod = importlib.import_module(module)
    return [(name, getattr(mod, name)) for name in mod.__all__]


@pytest.mark.parametrize("module", MODULES)
def test_page_lists_every_public_name(module):
    seen = _documented()
    missing = [name for name, obj in _public(module) if (name, id(obj)) not in seen]
    assert not missing, f"book/api.md does not document {module}: {missing}"


def test_every_directive_names_an_importable_object():
    for _, target, _ in _directives():
        _resolve(target)


def test_page_is_in_the_toc_and_autodoc_is_enabled():
    yaml = pytest.importorskip("yaml")
    cfg = yaml.safe_load((ROOT / "_config.yml").read_text(encoding="utf-8"))
    assert {"sphinx.ext.autodoc", "sphinx.ext.napoleon"} <= set(cfg["sphinx"]["extra_extensions"])
    assert "file: book/api" in (ROOT / "_toc.yml").read_text(encoding="utf-8")
