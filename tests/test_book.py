"""The book's sources: table of contents, figure index, bibliography and notebooks."""
import importlib.util
import json
import re
from pathlib import Path

import pytest

yaml = pytest.importorskip("yaml")  # comes with the book tool chain (dev extra)

ROOT = Path(__file__).resolve().parent.parent

# Every \label{fig:*} and \label{tab:*} of the paper, in order of appearance.
PAPER_LABELS = [
    "fig:illustration",
    "tab:overview",
    "fig:bc_sample",
    "fig:dem_example",
    "fig:modelstructure",
    "fig:bc_eq_mu",
    "tab:reconstruction_results_mu",
    "fig:bc_eq_res",
    "tab:reconstruction_results_res",
    "fig:population_test",
    "tab:population_test",
    "fig:population_test_fb",
    "tab:population_test_fb",
    "fig:resolution_test",
    "tab:resolution_test",
    "fig:extreme_comparison",
    "fig:3d_population_test",
    "tab:3d_population_test",
    "fig:3d_population_test_fb",
    "tab:3d_population_test_fb",
    "fig:3d_resolution_test",
    "tab:3d_resolution_test",
]


def _figures_script():
    spec = importlib.util.spec_from_file_location("make_figures_md", ROOT / "scripts" / "make_figures_md.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _items() -> list[dict]:
    return json.loads((ROOT / "src" / "rfmap" / "data" / "figures.json").read_text(encoding="utf-8"))["items"]


def _toc() -> dict:
    return yaml.safe_load((ROOT / "_toc.yml").read_text(encoding="utf-8"))


def _toc_files() -> list[str]:
    files: list[str] = []

    def walk(node):
        if isinstance(node, dict):
            for key in ("root", "file"):
                if isinstance(node.get(key), str):
                    files.append(node[key])
            for value in node.values():
                walk(value)
        elif isinstance(node, list):
            for value in node:
                walk(value)

    walk(_toc())
    return files


def _resolve(doc: str) -> Path | None:
    p = ROOT / doc
    if p.suffix in (".md", ".ipynb") and p.exists():
        return p
    for suffix in (".md", ".ipynb"):
        if p.with_suffix(suffix).exists():
            return p.with_suffix(suffix)
    return None


NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


# ----------------------------------------------------------------------------------------------- figure index
def test_figures_json_covers_every_label_of_the_paper():
    labels = [it["label"] for it in _items()]
    assert len(labels) == len(set(labels)), "duplicate labels in figures.json"
    assert set(labels) == set(PAPER_LABELS)
    assert len(PAPER_LABELS) == 22


def test_figures_json_entries_are_complete():
    outputs = []
    for it in _items():
        assert it["description"].strip(), it["label"]
        assert it["notebook"].startswith(("notebooks/", "book/")), it["label"]
        if it["notebook"].startswith("notebooks/"):
            assert re.fullmatch(r"notebooks/\d\d_[a-z0-9_]+\.ipynb", it["notebook"]), it["notebook"]
        out = it.get("output")
        if out is None:
            assert it.get("status"), f"{it['label']}: an item without an output file needs an explicit status"
            continue
        kind = "fig" if it["label"].startswith("fig:") else "tab"
        assert out.startswith(f"book/figures/{kind}-"), out
        assert out.endswith(".png" if kind == "fig" else ".md"), out
        outputs.append(out)
    assert len(outputs) == len(set(outputs)), "two items write the same file"


def test_produced_items_have_their_notebook():
    mod = _figures_script()
    for it in _items():
        st = mod.status(it, ROOT)
        if st == "produced" or it.get("status"):
            assert (ROOT / it["notebook"]).exists(), f"{it['label']}: {it['notebook']} is missing"
        if not it.get("status"):
            assert st == ("produced" if (ROOT / it["notebook"]).exists() else "not yet produced")


def test_figures_md_is_up_to_date():
    mod = _figures_script()
    current = (ROOT / "book" / "figures.md").read_text(encoding="utf-8")
    assert current == mod.render(ROOT), "book/figures.md is stale: run python scripts/make_figures_md.py"
    for label in PAPER_LABELS:
        assert f"`{label}`" in current


# ----------------------------------------------------------------------------------------------- toc and config
def test_every_toc_file_exists():
    toc = _toc()
    assert toc["format"] == "jb-book"
    assert toc["root"] == "book/intro"
    files = _toc_files()
    assert len(files) == len(set(files)), "a page is listed twice"
    for doc in files:
        assert _resolve(doc) is not None, f"_toc.yml lists {doc}, which does not exist"


def test_every_notebook_is_in_the_toc():
    listed = {str(Path(f).with_suffix("")) for f in _toc_files()}
    for nb in NOTEBOOKS:
        assert f"notebooks/{nb.stem}" in listed, f"{nb.name} is not in _toc.yml and would not be built"


def test_book_config():
    cfg = yaml.safe_load((ROOT / "_config.yml").read_text(encoding="utf-8"))
    assert cfg["only_build_toc_files"] is True
    assert cfg["execute"]["execute_notebooks"] == "force"
    assert cfg["execute"]["allow_errors"] is False
    assert {"amsmath", "dollarmath", "colon_fence"} <= set(cfg["parse"]["myst_enable_extensions"])
    for bib in cfg["bibtex_bibfiles"]:
        assert (ROOT / bib).exists()
    assert cfg["html"]["use_repository_button"] is False
    for pattern in ("_build", "tests", "src", "scripts", "benchmarks"):
        assert pattern in cfg["exclude_patterns"]


def test_citations_resolve():
    bib = (ROOT / "references.bib").read_text(encoding="utf-8")
    keys = set(re.findall(r"@\w+\{([^,\s]+),", bib))
    assert len(keys) == len(re.findall(r"@\w+\{", bib)), "duplicate or malformed BibTeX keys"
    assert {"huang2026resolution", "gastner2004diffusion", "choi2018density", "ahlfors2006lectures",
            "lui2013texture", "lyu2024bijective", "ronneberger2015unet", "li2021fourier", "lu2021learning"} <= keys
    sources = [p for p in (ROOT / "book").glob("*.md")] + NOTEBOOKS
    cited = set()
    for src in sources:
        for group in re.findall(r"\{cite(?::[a-z]+)?\}`([^`]+)`", src.read_text(encoding="utf-8")):
            cited.update(k.strip() for k in group.split(","))
    assert cited, "the book cites nothing"
    assert cited <= keys, f"unknown citation keys: {sorted(cited - keys)}"
    bibliography_pages = [p for p in sources if "{bibliography}" in p.read_text(encoding="utf-8")]
    assert len(bibliography_pages) == 1


# ----------------------------------------------------------------------------------------------- notebooks
@pytest.mark.parametrize("nb", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_is_committed_without_outputs(nb):
    """Notebooks are committed without outputs or execution counts: the book and nbval execute them."""
    data = json.loads(nb.read_text(encoding="utf-8"))
    assert data["metadata"]["kernelspec"]["name"] == "python3"
    for i, cell in enumerate(data["cells"]):
        if cell["cell_type"] != "code":
            continue
        assert cell.get("outputs") == [], f"{nb.name}: code cell {i} has outputs"
        assert cell.get("execution_count") is None, f"{nb.name}: code cell {i} has an execution count"


@pytest.mark.parametrize("nb", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_cells_have_unique_ids(nb):
    """nbformat 4.5 requires every cell to carry a unique ``id`` (1-64 letters, digits, ``-`` or ``_``); a missing
    one is filled in with a warning today and will be an error in later nbformat versions."""
    data = json.loads(nb.read_text(encoding="utf-8"))
    assert (data["nbformat"], data["nbformat_minor"]) >= (4, 5), f"{nb.name}: nbformat below 4.5"
    ids = [cell.get("id") for cell in data["cells"]]
    missing = [i for i, c in enumerate(ids) if c is None]
    assert not missing, f"{nb.name}: cells {missing} have no id"
    bad = [c for c in ids if not re.fullmatch(r"[A-Za-z0-9_-]{1,64}", c)]
    assert not bad, f"{nb.name}: invalid cell ids {bad}"
    assert len(set(ids)) == len(ids), f"{nb.name}: duplicate cell ids"


# ----------------------------------------------------------------------------------------------- self-containment
def test_project_does_not_read_the_paper_sources():
    needle = re.compile(re.escape("..") + "/" + "shared|" + "shared" + "/paper")
    files = [ROOT / "Makefile", ROOT / "_config.yml", ROOT / "_toc.yml", ROOT / ".ci" / "run"]
    for folder, pattern in [("src", "**/*.py"), ("scripts", "*"), ("book", "*.md"), ("notebooks", "*.ipynb"),
                            ("tests", "*.py"), ("benchmarks", "**/*.py")]:
        files += [p for p in (ROOT / folder).glob(pattern) if p.is_file()]
    for f in files:
        if f.exists():
            assert not needle.search(f.read_text(encoding="utf-8", errors="replace")), f"{f} refers to shared/"
