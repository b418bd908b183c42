"""The chapters run as a reader runs them: JupyterLab from `.venv`, the project kernel, working directory `notebooks/`.

These tests check the set-up: JupyterLab and the kernel `make install` registers (``rfmap``), and where figures go.
The chapters themselves are executed by `make test`: nbval runs every notebook through the ``rfmap`` kernel, which
starts in ``notebooks/`` as in JupyterLab, at ``RFMAP_SCALE=ci``, and the book build executes them again with a
temporary directory as working directory (``execute.run_in_temp`` in ``_config.yml``), so between them the two runs
show that a chapter does not depend on where it is started from.
"""
import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from rfmap.viz import figures_dir, repository_root

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOK_DIR = ROOT / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
FIGURES = ROOT / "book" / "figures"
KERNEL = "rfmap"
# inside the repository's .venv `make install` has registered the kernel and installed JupyterLab: a missing one is a
# failure there, and a skip in any other environment (a conda environment, a bare `pip install -e .`)
IN_VENV = Path(sys.prefix).resolve() == (ROOT / ".venv").resolve()


def _missing(what: str):
    msg = f"{what}: run `make install` (installs the lab extra and registers the {KERNEL!r} kernel in .venv)"
    if IN_VENV:
        pytest.fail(msg)
    pytest.skip(msg)


def _kernel_spec():
    from jupyter_client.kernelspec import KernelSpecManager, NoSuchKernel

    try:
        return KernelSpecManager().get_kernel_spec(KERNEL)
    except NoSuchKernel:
        _missing(f"no Jupyter kernel named {KERNEL!r}")


def _code(nb_path: Path) -> str:
    import nbformat

    nb = nbformat.read(nb_path, as_version=4)
    return "\n".join(c.source for c in nb.cells if c.cell_type == "code")


def test_jupyterlab_starts_from_the_venv():
    jupyter = Path(sys.executable).with_name("jupyter")
    if importlib.util.find_spec("jupyterlab") is None or not jupyter.exists():
        _missing("JupyterLab is not installed in this environment")
    out = subprocess.run([jupyter, "lab", "--version"], capture_output=True, text=True, check=True).stdout.strip()
    assert int(out.split(".")[0]) >= 4, out


def test_project_kernel_is_this_python_with_the_books_environment():
    spec = _kernel_spec()
    assert spec.language == "python"
    assert Path(spec.argv[0]).resolve() == Path(sys.executable).resolve()  # the venv's interpreter, not a system one
    assert spec.env.get("VTK_DEFAULT_OPENGL_WINDOW") == "vtkEGLRenderWindow"  # off-screen PyVista, as the book
    bin_dir = spec.env.get("PATH", "").split(":")[0]
    assert Path(bin_dir).resolve() == Path(sys.executable).parent.resolve()  # the rfmap command comes first
    assert "RFMAP_SCALE" not in spec.env  # passed through from the server's environment


@pytest.mark.parametrize("where", ["root", "notebooks", "elsewhere"])
def test_figures_go_to_the_book_from_any_working_directory(where, monkeypatch, tmp_path):
    monkeypatch.delenv("RFMAP_FIGURES", raising=False)
    monkeypatch.chdir({"root": ROOT, "notebooks": NOTEBOOK_DIR, "elsewhere": tmp_path}[where])
    assert repository_root() == ROOT
    assert figures_dir() == FIGURES
    monkeypatch.setenv("RFMAP_FIGURES", str(tmp_path / "figs"))
    assert figures_dir() == tmp_path / "figs" and (tmp_path / "figs").is_dir()


def test_repository_root_walks_up_to_the_book(tmp_path):
    checkout, other = tmp_path / "checkout", tmp_path / "other"
    (checkout / "book").mkdir(parents=True)
    (checkout / "notebooks").mkdir()
    (checkout / "_config.yml").write_text("title: x\n")
    other.mkdir()
    assert repository_root(checkout / "notebooks") == checkout
    assert repository_root(checkout) == checkout
    assert repository_root(other) is None


@pytest.mark.parametrize("nb_path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_chapter_names_no_paths_of_its_own(nb_path):
    """Paths come from the library (``figures_dir``), never from the working directory or ``sys.path``."""
    code = _code(nb_path)
    for pattern in (r"sys\.path", r"os\.chdir", r"^\s*%cd\b", r"\.\./", r"book/figures", r"Path\.cwd"):
        assert not re.search(pattern, code, re.M), f"{nb_path.name}: {pattern}"


# ------------------------------------------------------------------ scripts/lab_check.py, without a browser
LAB_CELL = ROOT / "tests" / "data" / "lab_markdown_cell.html"
# the roles of the saved cell (notebooks/06_dem_deq_2d.ipynb, cell 0), as its source has them
LAB_CELL_SOURCE = ("shrink {cite:p}`gastner2004diffusion`, $\\lambda$ = {glue:text}`lam`, close to conformal "
                   "{cite:p}`lyu2024bijective`; the {ref}`metrics box of chapter 2 <metrics>`; Std$(\\tilde\\rho_{"
                   "\\text{map}})$")


@pytest.fixture(scope="module")
def lab_check():
    pytest.importorskip("bs4")
    spec = importlib.util.spec_from_file_location("lab_check", ROOT / "scripts" / "lab_check.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _notebook_html(kernel: str, *cells: str) -> str:
    toolbar = f'<jp-button class="jp-Toolbar-kernelName"><span>{kernel}</span></jp-button>'
    return f'<div class="jp-NotebookPanel">{toolbar}<div class="jp-Notebook">{"".join(cells)}</div></div>'


def _myst_cell(inner: str, renderer: str = "myst") -> str:
    return f'<div class="jp-Cell jp-MarkdownCell"><div class="jp-InputArea"><div class="{renderer}">{inner}</div>' \
           "</div></div>"


def test_saved_jupyterlab_myst_cell_passes(lab_check):
    """A cell as JupyterLab shows it with jupyterlab-myst: citations and the reference rendered, the glue role
    showing its key, the TeX of the math (``\\text{map}``) and the hidden editor's raw source not read as prose."""
    html = LAB_CELL.read_text(encoding="utf-8")
    assert "{cite:p}" in html  # in the hidden editor, which holds the source
    assert lab_check.page_problems(html, [(0, LAB_CELL_SOURCE)]) == []
    notes = lab_check.page_notes(html, [(0, LAB_CELL_SOURCE)])
    assert notes[0].startswith("2 citation(s) shown by their key") and notes[1].startswith("1 glue role(s)")


def test_other_kernel_fails(lab_check):
    html = LAB_CELL.read_text(encoding="utf-8").replace("Python (rfmap)", "Python 3 (ipykernel)")
    problems = lab_check.page_problems(html, [(0, LAB_CELL_SOURCE)])
    assert problems == ["the notebook's toolbar shows the kernel 'Python 3 (ipykernel)', not 'Python (rfmap)'"]


def test_markdown_without_jupyterlab_myst_fails(lab_check):
    """JupyterLab's own Markdown renderer leaves roles, fences and targets as text."""
    cell = _myst_cell("<p>(fig-a)=</p><p>shrink {cite:p}<code>gastner2004diffusion</code>, "
                      "{glue:text}<code>lam</code></p><p>::: {note}</p>", renderer="jp-RenderedMarkdown")
    source = "(fig-a)=\n\nshrink {cite:p}`gastner2004diffusion`, {glue:text}`lam`\n\n::: {note}\n:::"
    problems = lab_check.page_problems(_notebook_html("Python (rfmap)", cell), [(3, source)])
    assert problems[0] == "cell 3: not rendered by jupyterlab-myst (no .myst element)"
    text = "\n".join(problems)
    for what in ("raw MyST role {cite:p}", "raw MyST role {glue:text}", "raw MyST role {note}", "raw ::: fence",
                 "raw (label)= target", "1 citation(s) in the source, 0 rendered as citations"):
        assert what in text, what


def test_math_and_code_may_show_braces(lab_check):
    cell = _myst_cell('<p><span class="katex">\\text{map}</span> and <code>{cite:p}`key`</code></p>'
                      "<pre>{glue:text}</pre>")
    assert lab_check.page_problems(_notebook_html("Python (rfmap)", cell), [(0, "$\\text{map}$")]) == []


def test_citations_and_links_are_counted(lab_check):
    source = "{cite:p}`a, b` and {cite:t}`c`; {doc}`02_diffusion_dem` and {ref}`x <y>`"
    two = '<span class="cite-group"><cite>A 2004</cite><span title="Citation Not Found">b</span></span>'
    cell = _myst_cell(f'<p>{two} and <a class="link" href="#">02</a></p>')
    problems = lab_check.page_problems(_notebook_html("Python (rfmap)", cell), [(0, source)])
    assert problems == ["cell 0: 3 citation(s) in the source, 2 rendered as citations",
                        "cell 0: 2 cross-reference(s) in the source, 1 rendered as references"]
    # a label of another chapter: jupyterlab-myst renders the reference, marked as not found (a note, not a failure)
    elsewhere = '<span class="text-yellow-600" title="Cross Reference Not Found">y</span>'
    html = _notebook_html("Python (rfmap)", _myst_cell(f'<p>{two} and <a class="link" href="#">02</a> {elsewhere}</p>'))
    assert lab_check.page_problems(html, [(0, source)]) == ["cell 0: 3 citation(s) in the source, 2 rendered as "
                                                            "citations"]
    assert lab_check.page_notes(html, [(0, source)])[1].startswith("1 reference(s) shown by their label")


def test_every_markdown_cell_must_be_shown(lab_check):
    html = _notebook_html("Python (rfmap)", _myst_cell("<p>one</p>"))
    assert lab_check.page_problems(html, [(0, "one"), (2, "two")]) == ["1 Markdown cells shown, the chapter has 2"]


def test_markdown_sources_in_notebook_order(lab_check, tmp_path):
    nb = tmp_path / "c.ipynb"
    nb.write_text('{"cells": [{"cell_type": "markdown", "source": ["# T", "itle"]}, {"cell_type": "code", '
                  '"source": "x"}, {"cell_type": "markdown", "source": "b"}]}', encoding="utf-8")
    assert lab_check.markdown_sources(nb) == [(0, "# Title"), (2, "b")]


def test_make_lab_takes_the_checks_flags(lab_check, tmp_path):
    """The check starts `make lab` unchanged: its environment, the rfmap default kernel, the repository as root
    folder, plus the check's own flags (printed by ``make -n``, nothing started)."""
    if shutil.which("make") is None:
        pytest.skip("make is not installed")
    flags = lab_check.lab_flags(8888, "abc", tmp_path)
    out = subprocess.run(["make", "-n", "--no-print-directory", "lab", "LAB_FLAGS=" + " ".join(flags)], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout
    command = next(line for line in out.replace("\\\n", " ").splitlines() if "jupyter lab" in line)
    assert "VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow" in command and "RFMAP_SCALE=" in command
    assert f'--ServerApp.root_dir="{ROOT}"' in command
    assert "--MappingKernelManager.default_kernel_name=rfmap" in command
    assert command.split()[-len(flags):] == flags
    assert ("--allow-root" in command.split()) == (os.geteuid() == 0)


def test_browser_that_does_not_start_is_reported(lab_check):
    with pytest.raises(lab_check.ChromiumError, match="did not start"):
        with lab_check.chromium("/bin/false", startup=10):
            pass
