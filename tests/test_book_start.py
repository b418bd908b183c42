"""The reader's way in: the landing page's quick start runs as written, and every chapter ends with exercises."""
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
INTRO = ROOT / "book" / "intro.md"
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))
#: the heading of the last cell of every chapter
TRY_IT = "## Try it"


def quick_start_blocks(text: str) -> list[tuple[str, str]]:
    """The fenced blocks of the intro's *Quick start* section, as (language, code), in order."""
    m = re.search(r"^## Quick start\n(.*?)(?=^## )", text, re.S | re.M)
    assert m, "book/intro.md has no '## Quick start' section"
    return [(lang, code) for lang, code in re.findall(r"^```(\w+)\n(.*?)^```", m.group(1), re.S | re.M)]


def test_quick_start_has_install_map_and_training():
    blocks = quick_start_blocks(INTRO.read_text(encoding="utf-8"))
    code = "\n".join(c for _, c in blocks)
    assert "make install" in code and "Surrogate.pretrained(" in code and "--preset ci" in code
    python = [c for lang, c in blocks if lang == "python"]
    # one map in five lines: imports, the map, its metrics
    assert len([ln for ln in python[0].splitlines() if ln.strip()]) <= 7


def test_quick_start_runs_as_written(tmp_path):
    """Every command of the quick start but the installation and the shell's activation, run in order in an empty
    directory with the project's environment: the training writes the weights that the last block loads."""
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1",
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    for lang, code in quick_start_blocks(INTRO.read_text(encoding="utf-8")):
        if lang == "python":
            proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True,
                                  text=True, timeout=600)
            assert proc.returncode == 0, proc.stderr[-2000:]
            assert "std_rho_map=" in proc.stdout
            continue
        for line in code.splitlines():
            if not line.strip() or line.startswith(("make ", "source ")):
                continue
            proc = subprocess.run(shlex.split(line), cwd=tmp_path, env=env, capture_output=True, text=True,
                                  timeout=600)
            assert proc.returncode == 0, f"{line}: {proc.stderr[-2000:]}"
    assert (tmp_path / "runs" / "quick" / "deq2d-square.safetensors").exists()


def code_blocks(text: str) -> list[tuple[str, list[str]]]:
    """The fenced blocks of a MyST page as ``(info string, lines)``: a fence opens with three backticks and an
    optional info string (``python``, ``{eval-rst}``) and closes with a bare fence."""
    blocks, info, lines = [], None, []
    for line in text.splitlines():
        if info is None and line.startswith("```"):
            info, lines = line[3:].strip(), []
        elif info is not None and line.strip() == "```":
            blocks.append((info, lines))
            info = None
        elif info is not None:
            lines.append(line)
    return blocks


def test_code_blocks_are_found_between_their_fences():
    text = "```python\nx = 1\n```\nprose " + "y" * 100 + "\n```{eval-rst}\n.. automodule:: m\n```\n"
    assert code_blocks(text) == [("python", ["x = 1"]), ("{eval-rst}", [".. automodule:: m"])]
    assert CODE_INFO.match("python") and CODE_INFO.match("") and CODE_INFO.match("{code-block} bash")
    assert not CODE_INFO.match("{eval-rst}") and not CODE_INFO.match("{glossary}")


#: Fenced blocks that show code (a language, or none); the other directives (``{eval-rst}``, ``{glossary}``,
#: ``{note}``) hold text that the page lays out itself
CODE_INFO = re.compile(r"^(\w*|\{code(-block|-cell)?\}.*)$")


def test_code_blocks_of_the_pages_fit_88_columns():
    long = []
    for page in sorted((ROOT / "book").rglob("*.md")):
        for info, lines in code_blocks(page.read_text(encoding="utf-8")):
            if not CODE_INFO.match(info):
                continue
            long += [f"{page.relative_to(ROOT)} ({info}): {ln!r}" for ln in lines if len(ln) > 88]
    assert not long, "code lines longer than 88 characters:\n" + "\n".join(long)


def test_docstring_examples_on_the_api_pages_fit_88_columns():
    """The examples of a docstring that an API page renders (``autofunction`` and the like) sit in a code box as
    well: each of their lines, prompts and printed output alike, fits 88 characters."""
    import importlib
    import inspect

    long = []
    for page in sorted((ROOT / "book" / "api").glob("*.md")):
        for name in re.findall(r"^\.\. auto(?:function|class|method)::\s+([\w.]+)", page.read_text(encoding="utf-8"),
                               re.M):
            module, _, attr = name.rpartition(".")
            try:
                obj = getattr(importlib.import_module(module), attr)
            except (ImportError, AttributeError):  # a method (Class.method): its class's module
                owner, _, cls = module.rpartition(".")
                obj = getattr(getattr(importlib.import_module(owner), cls), attr)
            example = False
            for ln in (inspect.getdoc(obj) or "").splitlines():
                example = ln.startswith((">>>", "...")) or (example and bool(ln.strip()))
                if example and len(ln) > 88:
                    long.append(f"{page.name}: {name}: {ln[:60]!r}... ({len(ln)})")
    assert not long, "docstring example lines longer than 88 characters:\n" + "\n".join(long)


@pytest.mark.parametrize("nb", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_chapter_ends_with_try_it(nb):
    """The last cell is a Markdown cell '## Try it' with one to three exercises (a numbered list)."""
    cells = json.loads(nb.read_text(encoding="utf-8"))["cells"]
    last = "".join(cells[-1]["source"])
    assert cells[-1]["cell_type"] == "markdown" and last.startswith(TRY_IT), f"{nb.name} ends without '{TRY_IT}'"
    items = re.findall(r"^\d+\. ", last, re.M)
    assert 1 <= len(items) <= 3, f"{nb.name}: {len(items)} exercises"


@pytest.mark.parametrize("nb", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_code_cells_fit_the_text_column(nb):
    """A code cell the book shows fits 79 characters (the code box of the text column at a 1280 px window); a hidden
    one (``remove-input`` or ``remove-cell``, read in JupyterLab only) fits 88."""
    cells = json.loads(nb.read_text(encoding="utf-8"))["cells"]
    long = []
    for c in cells:
        if c["cell_type"] != "code":
            continue
        hidden = {"remove-input", "remove-cell"} & set(c.get("metadata", {}).get("tags", []))
        width = 88 if hidden else 79
        long += [f"cell {c.get('id')}: {ln[:60]!r}... ({len(ln)} > {width})"
                 for ln in "".join(c["source"]).splitlines() if len(ln) > width]
    assert not long, f"{nb.name}: code lines wider than the text column:\n" + "\n".join(long)


def test_glossary_defines_the_words_of_the_stages_and_measures():
    """The glossary (book/glossary.md, in the table of contents) defines every word the chapters use for the stages
    of a map and its measures; a chapter links a term with {term}`...`, and Sphinx fails the build (-W) on a term
    the glossary lacks."""
    text = (ROOT / "book" / "glossary.md").read_text(encoding="utf-8")
    terms = set()
    for block in re.findall(r"^```\{glossary\}\n(.*?)^```", text, re.S | re.M):
        terms |= {ln.strip() for ln in block.splitlines() if ln.strip() and not ln.startswith(" ")}
    required = {"raw map", "refined map", "repaired map", "shortened map", "delivered map", "working grid", "native",
                "Std(ρ̃)", "α", "Kuhn tetrahedra", "flow solver", "the paper's method"}
    assert required <= terms, f"missing from the glossary: {sorted(required - terms)}"
    assert "file: book/glossary" in (ROOT / "_toc.yml").read_text(encoding="utf-8")
    used = set()
    for nb in NOTEBOOKS:
        for cell in json.loads(nb.read_text(encoding="utf-8"))["cells"]:
            if cell["cell_type"] == "markdown":
                used |= {m.split("<")[-1].rstrip(">").strip()
                         for m in re.findall(r"\{term\}`([^`]+)`", "".join(cell["source"]))}
    assert used and used <= terms, f"terms linked but not defined: {sorted(used - terms)}"
