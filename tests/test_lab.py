"""The chapters run as a reader runs them: JupyterLab from `.venv`, the project kernel, working directory `notebooks/`.

These tests check the set-up: JupyterLab and the kernel `make install` registers (``rfmap``), and where figures go.
The chapters themselves are executed by `make test`: nbval runs every notebook through the ``rfmap`` kernel, which
starts in ``notebooks/`` as in JupyterLab, at ``RFMAP_SCALE=ci``, and the book build executes them again with a
temporary directory as working directory (``execute.run_in_temp`` in ``_config.yml``), so between them the two runs
show that a chapter does not depend on where it is started from.
"""
import importlib.util
import re
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
