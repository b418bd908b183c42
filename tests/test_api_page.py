"""The API reference (book/api.md and the pages of book/api/) documents every public module and name of the package."""
import importlib
import pkgutil
import re
from pathlib import Path

import pytest

import rfmap

ROOT = Path(__file__).resolve().parent.parent
INDEX = ROOT / "book" / "api.md"
PAGES = sorted((ROOT / "book" / "api").glob("*.md"))
#: an autodoc directive, or a hand-written ``py:`` description of a name that has no docstring of its own
DIRECTIVE = re.compile(r"^\.\. (auto\w+|py:\w+):: (\S+?)(?:\([^\n]*\))?\n((?:[ \t]+:[^\n]*\n)*)", re.M)


def _public_modules() -> list[str]:
    """Every module of the package whose dotted name has no part starting with an underscore."""
    names = ["rfmap"] + [m.name for m in pkgutil.walk_packages(rfmap.__path__, "rfmap.")]
    return sorted(n for n in names if not any(part.startswith("_") for part in n.split(".")))


MODULES = _public_modules()


def _directives() -> list[tuple[str, str, str, str]]:
    """(page, directive, target, options) of every autodoc or ``py:`` directive of the API pages; a target
    given with a ``:module:`` option is returned with its module."""
    out = []
    for page in [INDEX, *PAGES]:
        for kind, target, options in DIRECTIVE.findall(page.read_text(encoding="utf-8")):
            module = re.search(r":module:[ \t]*(\S+)", options)
            out.append((page.name, kind, f"{module.group(1)}.{target}" if module else target, options))
    return out


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


def _members(options: str, mod) -> list[str]:
    """The names an ``automodule`` documents: its ``__all__`` for a bare ``:members:``, the listed names for
    ``:members: a, b``, none without the option."""
    m = re.search(r":members:[ \t]*(.*)\n", options)
    if m is None:
        return []
    listed = [name.strip() for name in m.group(1).split(",") if name.strip()]
    return listed or list(mod.__all__)


def _documented() -> set[tuple[str, int]]:
    """(name, id(object)) of everything the pages document: explicit directives, and the members of every
    ``automodule``."""
    seen = set()
    for _, kind, target, options in _directives():
        if kind == "automodule":
            mod = importlib.import_module(target)
            seen |= {(name, id(getattr(mod, name))) for name in _members(options, mod)}
        else:
            seen.add((target.rsplit(".", 1)[-1], id(_resolve(target))))
    return seen


def test_the_package_has_its_modules():
    assert {"rfmap", "rfmap.surrogate", "rfmap.solvers.flow", "rfmap.paper.tables", "rfmap.cli.commands"} <= set(MODULES)


def test_every_public_module_has_a_page():
    """Each public module is the target of an ``automodule`` on one API page, exactly once."""
    targets = [target for _, kind, target, _ in _directives() if kind == "automodule"]
    missing = [m for m in MODULES if m not in targets]
    assert not missing, f"no API page documents the modules {missing}"
    twice = sorted({t for t in targets if targets.count(t) > 1})
    assert not twice, f"modules documented twice: {twice}"


@pytest.mark.parametrize("module", [m for m in MODULES if hasattr(importlib.import_module(m), "__all__")])
def test_pages_list_every_public_name(module):
    seen = _documented()
    mod = importlib.import_module(module)
    missing = [name for name in mod.__all__ if (name, id(getattr(mod, name))) not in seen]
    assert not missing, f"the API pages do not document {module}: {missing}"


def test_every_directive_names_an_importable_object():
    for _, _, target, _ in _directives():
        _resolve(target)


def test_pages_are_in_the_toc_and_autodoc_is_enabled():
    yaml = pytest.importorskip("yaml")
    cfg = yaml.safe_load((ROOT / "_config.yml").read_text(encoding="utf-8"))
    assert {"sphinx.ext.autodoc", "sphinx.ext.napoleon"} <= set(cfg["sphinx"]["extra_extensions"])
    toc = (ROOT / "_toc.yml").read_text(encoding="utf-8")
    assert "file: book/api\n" in toc
    missing = [p.stem for p in PAGES if f"file: book/api/{p.stem}\n" not in toc]
    assert PAGES and not missing, f"API pages missing from _toc.yml: {missing}"


def test_no_page_is_the_whole_reference():
    """The reference is split by module group: no page holds more than a quarter of the directives."""
    per_page = {}
    for page, *_ in _directives():
        per_page[page] = per_page.get(page, 0) + 1
    assert len(per_page) >= 8 and max(per_page.values()) <= sum(per_page.values()) / 4, per_page


# ------------------------------------------------------------------------------------------- examples and values
def _examples(page: Path) -> list[tuple[str, str]]:
    """(language, code) of the fenced blocks of a page's *Example* section."""
    m = re.search(r"^## Example\n(.*?)(?=^## )", page.read_text(encoding="utf-8"), re.S | re.M)
    return re.findall(r"^```(\w+)\n(.*?)^```", m.group(1), re.S | re.M) if m else []


def test_every_page_has_an_example():
    missing = [p.name for p in PAGES if not _examples(p)]
    assert not missing, f"API pages without an '## Example' code block: {missing}"


@pytest.mark.parametrize("page", PAGES, ids=[p.stem for p in PAGES])
def test_examples_run_as_written(page, tmp_path):
    """Each example runs in an empty directory with the project's environment: Python blocks as scripts, shell
    blocks line by line (a line ending in a backslash continues)."""
    import os
    import shlex
    import subprocess
    import sys

    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", MPLBACKEND="Agg",
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    for lang, code in _examples(page):
        if lang == "python":
            commands = [[sys.executable, "-c", code]]
        else:
            commands = [shlex.split(line) for line in code.replace("\\\n", " ").splitlines()
                        if line.strip() and not line.lstrip().startswith("#")]
        for cmd in commands:
            proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
            assert proc.returncode == 0, f"{page.name}: {cmd[:3]}: {proc.stderr[-2000:]}"


def _attr_docs(module: str) -> set[str]:
    from sphinx.pycode import ModuleAnalyzer

    return {name for (_, name) in ModuleAnalyzer.for_module(module).find_attr_docs()}


def test_explicit_data_has_its_own_description():
    """``autodata`` of a constant without a ``#:`` comment shows its type's docstring ("int([x]) -> integer"):
    such a constant gets a ``py:data`` directive with a description instead."""
    bare = []
    for page, kind, target, _ in _directives():
        if kind == "autodata":
            module, name = target.rsplit(".", 1)
            if name not in _attr_docs(module):
                bare.append(f"{page}: {target}")
    assert not bare, f"autodata without a '#:' comment in the source: {bare}"


def test_no_machine_path_in_documented_values():
    """A documented constant whose value is a path on this machine is shown without its value (``:no-value:``)."""
    shown = []
    for page, kind, target, options in _directives():
        if kind == "automodule":
            mod = importlib.import_module(target)
            documented = _attr_docs(target)
            excluded = re.search(r":exclude-members:[ \t]*(.*)\n", options)
            excluded = {n.strip() for n in excluded.group(1).split(",")} if excluded else set()
            names = [n for n in _members(options, mod) if n in documented and n not in excluded]
            values = [(f"{target}.{n}", getattr(mod, n)) for n in names]
        elif kind == "autodata" and ":no-value:" not in options:
            values = [(target, _resolve(target))]
        else:
            continue
        shown += [f"{page}: {name}" for name, v in values
                  if isinstance(v, Path) or str(ROOT) in repr(v) or "PosixPath" in repr(v)]
    assert not shown, f"values that print a path of this machine: {shown}"


def test_a_reexported_class_or_function_is_documented_where_it_is_defined():
    """A bare ``:members:`` documents a module's ``__all__``, re-exports included: a class or function that a module
    imports from another documented module is excluded there (``:exclude-members:``), so that each is documented
    once, where it is defined (a package's own page of "start here" names excepted)."""
    homes = {target for _, kind, target, options in _directives() if kind == "automodule" and ":members:" in options}
    twice = []
    for page, kind, target, options in _directives():
        if kind != "automodule" or not re.search(r":members:[ \t]*\n", options):
            continue
        mod = importlib.import_module(target)
        if not hasattr(mod, "__all__") or hasattr(mod, "__path__") and target.count(".") < 2:
            continue
        excluded = re.search(r":exclude-members:[ \t]*(.*)\n", options)
        excluded = {n.strip() for n in excluded.group(1).split(",")} if excluded else set()
        for name in mod.__all__:
            obj = getattr(mod, name)
            home = getattr(obj, "__module__", target) if callable(obj) else target
            if home != target and home in homes and name not in excluded:
                twice.append(f"{page}: {target}.{name} (defined in {home})")
    assert not twice, "documented again where re-exported:\n" + "\n".join(twice)
