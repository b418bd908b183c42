"""The house rules that keep the library readable: one concept per module (at most 600 lines) and functions of at
most 80 lines (their docstring excluded), in the package, the scripts and the benchmarks."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MAX_MODULE_LINES, MAX_FUNCTION_LINES = 600, 80
FILES = sorted(p for d in ("src/rfmap", "scripts", "benchmarks") for p in (ROOT / d).rglob("*.py"))


def function_lengths(source: str) -> dict[str, int]:
    """Lines of every function's body after its docstring, by qualified-ish name (``outer.inner``)."""
    out = {}

    def visit(node, prefix=""):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                body = child.body
                first = body[0]
                docstring = isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and \
                    isinstance(first.value.value, str)
                start = (body[1].lineno if len(body) > 1 else first.end_lineno + 1) if docstring else first.lineno
                out[prefix + child.name] = child.end_lineno - start + 1
                visit(child, prefix + child.name + ".")
            elif isinstance(child, ast.ClassDef):
                visit(child, prefix + child.name + ".")
            else:
                visit(child, prefix)

    visit(ast.parse(source))
    return out


def test_function_lengths_skip_the_docstring():
    src = 'def f():\n    """doc\n\n    more\n    """\n    a = 1\n    return a\n\n\nclass C:\n    def g(self):\n        pass\n'
    assert function_lengths(src) == {"f": 2, "C.g": 1}


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_modules_and_functions_stay_short(path):
    source = path.read_text(encoding="utf-8")
    assert source.count("\n") <= MAX_MODULE_LINES, f"{path.name}: {source.count(chr(10))} lines"
    long = {k: n for k, n in function_lengths(source).items() if n > MAX_FUNCTION_LINES}
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines: {long}"


# ------------------------------------------------------------------------------------------- the architecture's targets
PACKAGE = ROOT / "src" / "rfmap"
MAX_PARAMETERS = 8
#: a comparison of a task kind with one of the built-in kinds' names
KIND_COMPARISON = re.compile(r"""(==|!=|\bin)\s*\(?\s*["'](density|beltrami)["']|["'](density|beltrami)["']\)?\s*(==|!=)""")


def public_parameter_counts(source: str) -> dict[str, int]:
    """Parameters of every public function and method (``self``/``cls`` and ``*args``/``**kwargs`` not counted)."""
    out = {}

    def visit(node, prefix="", in_class=False):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = child.args
                names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
                if in_class and names and names[0] in ("self", "cls"):
                    names = names[1:]
                if not (child.name.startswith("_") or prefix.startswith("_")):
                    out[prefix + child.name] = len(names)
            elif isinstance(child, ast.ClassDef):
                visit(child, prefix + child.name + ".", True)

    visit(ast.parse(source))
    return out


def test_parameter_counts_skip_self_and_private_names():
    src = "def f(a, b, *c, d=1, **e):\n    pass\n\n\ndef _g(a):\n    pass\n\n\nclass C:\n    def h(self, x):\n        pass\n"
    assert public_parameter_counts(src) == {"f": 3, "C.h": 1}


def test_no_public_function_takes_more_than_eight_parameters():
    """Long keyword lists are options objects (``MapOptions``, ``FlowOptions``, ``RunOptions``, ...)."""
    long = {f"{p.relative_to(PACKAGE)}:{name}": k for p in sorted(PACKAGE.rglob("*.py"))
            for name, k in public_parameter_counts(p.read_text(encoding="utf-8")).items() if k > MAX_PARAMETERS}
    assert not long, f"public functions with more than {MAX_PARAMETERS} parameters: {long}"


def test_the_kinds_are_compared_only_in_the_tasks():
    """Everything that depends on the kind of map asks its task (``spec.task``); at most three comparisons with a
    built-in kind's name are left outside :mod:`rfmap.tasks`."""
    found = [f"{p.relative_to(PACKAGE)}:{i}" for p in sorted(PACKAGE.rglob("*.py")) if "tasks" not in p.parts
             for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if KIND_COMPARISON.search(line)]
    assert len(found) <= 3, found


def test_the_top_level_holds_at_most_four_modules():
    """The packages name the architecture; at most four modules stay beside them."""
    top = sorted(p.name for p in PACKAGE.glob("*.py") if p.name not in ("__init__.py", "_version.py"))
    assert len(top) <= 4, top
