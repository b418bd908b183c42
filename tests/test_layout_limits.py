"""The house rules that keep the library readable: one concept per module (at most 600 lines) and functions of at
most 80 lines (their docstring excluded), in the package, the scripts and the benchmarks."""
from __future__ import annotations

import ast
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
