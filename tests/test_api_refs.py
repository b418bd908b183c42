"""The cross-references in the docstrings of the API pages lead somewhere.

A role such as :func:`read_regions` written in a docstring resolves only when the name is documented under the
current module (or given in full); otherwise Sphinx renders it as code that looks like a link and is none.  The
book's nitpicky build does not catch a short name (its ``nitpick_ignore_regex`` lets every name outside ``rfmap.``
pass, for the names of other libraries), so this test builds the API pages with Sphinx and lists every reference
written as a role that resolves to nothing, other libraries' names apart.
"""
import builtins
import importlib.util
import shutil
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
#: the pages checked: every API page
CHECKED = tuple(sorted(page.stem for page in (ROOT / "book" / "api").glob("*.md")))
#: the settings of the book's Sphinx configuration that shape the API pages
KEYS = ("autodoc_", "napoleon_", "python_", "toc_object_entries")


def _external(target: str) -> bool:
    """Whether ``target`` names something of Python or of another library (not documented in this book)."""
    first = target.lstrip("~.").split(".")[0]
    if first in dir(builtins):
        return True
    return first != "rfmap" and "." in target and importlib.util.find_spec(first) is not None


@pytest.fixture(scope="module")
def dead_references(tmp_path_factory) -> list[tuple[str, str, str]]:
    """(page, target, where) of every role in the API pages' docstrings that resolves to nothing."""
    sphinx_app = pytest.importorskip("sphinx.application")
    pytest.importorskip("myst_parser")
    src = tmp_path_factory.mktemp("api")
    (src / "api").mkdir()
    pages = sorted((ROOT / "book" / "api").glob("*.md"))
    for page in pages:
        shutil.copy(page, src / "api" / page.name)
    toctree = "\n".join(f"api/{page.stem}" for page in pages)
    (src / "index.md").write_text(f"# API\n\n```{{toctree}}\n{toctree}\n```\n", encoding="utf-8")
    book = yaml.safe_load((ROOT / "_config.yml").read_text(encoding="utf-8"))["sphinx"]
    settings = {k: v for k, v in book["config"].items() if k.startswith(KEYS)}
    extensions = ["myst_parser"] + [e for e in book["extra_extensions"] if e.startswith(("rfmap", "sphinx.ext"))]
    (src / "conf.py").write_text(
        f"extensions = {extensions!r}\nmyst_enable_extensions = ['amsmath', 'dollarmath', 'colon_fence']\n"
        + "".join(f"{k} = {v!r}\n" for k, v in settings.items()), encoding="utf-8")
    found = []

    def missing(app, env, node, contnode):
        from docutils import nodes

        # a role in the text renders as a literal; the types of fields and signatures render otherwise
        if node.get("refdomain") == "py" and type(contnode) is nodes.literal:
            found.append((env.docname.split("/")[-1], node["reftarget"], str(node.source).split("docstring of ")[-1]))

    app = sphinx_app.Sphinx(str(src), str(src), str(src / "_build"), str(src / "_doctrees"), "dummy",
                            status=None, warning=None, freshenv=True)
    app.connect("missing-reference", missing, priority=900)
    app.build()
    return [(page, target, where) for page, target, where in found if not _external(target)]


@pytest.mark.parametrize("page", CHECKED)
def test_every_reference_of_the_page_resolves(dead_references, page):
    dead = sorted({(target, where) for p, target, where in dead_references if p == page})
    assert not dead, f"references on book/api/{page} that lead nowhere (target, docstring): {dead}"


def test_a_short_name_of_another_module_is_found(tmp_path):
    """The check itself: a role naming a function of another module by its short name counts as dead."""
    assert not _external("read_regions") and not _external("_layout") and not _external("rfmap.x.y")
    assert _external("pandas.DataFrame") and _external("ValueError")
