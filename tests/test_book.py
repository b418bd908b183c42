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


def _book_check():
    spec = importlib.util.spec_from_file_location("book_check", ROOT / "scripts" / "book_check.py")
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
    numbers = mod.paper_numbers(_items())
    index = current.split("## Index", 1)[1]
    for label in PAPER_LABELS:  # every item by the paper's number, never by its LaTeX label
        assert f"| {numbers[label]} |" in index and label not in current


def test_intro_scoreboard_is_up_to_date():
    mod = _figures_script()
    current = (ROOT / "book" / "intro.md").read_text(encoding="utf-8")
    assert current.count(mod.BEGIN) == 1 and current.count(mod.END) == 1
    assert current == mod.render_intro(ROOT), "the scoreboard is stale: run python scripts/make_figures_md.py"


def _glued_key_patterns(nb: Path) -> list[re.Pattern]:
    """The keys a notebook glues, as patterns: glue("key", ...) exactly, glue(f"a_{x}", ...) as a_.* (a part may
    be empty), and glue_all(values, "prefix") as prefix_.+ (rfmap.paper.tables.glue_all)."""
    source = "\n".join("".join(c["source"]) for c in json.loads(nb.read_text(encoding="utf-8"))["cells"]
                       if c["cell_type"] == "code")
    patterns = [re.escape(k) for k in re.findall(r"\bglue\(\s*[\"']([^\"'{}]+)[\"']", source)]
    fstrings = re.findall(r"\bglue\(\s*f[\"']([^\"']+)[\"']", source)
    patterns += [re.sub(r"\\\{[^}]*\\\}", ".*", re.escape(k)) for k in fstrings]
    patterns += [re.escape(p) + "_.+" for p in re.findall(r"\bglue_all\([^,]+,\s*[\"']([^\"']+)[\"']", source)]
    return [re.compile(p) for p in patterns]


def test_every_item_has_a_score_computed_by_its_chapter():
    """Each item says how it compares with the paper (or that it only illustrates); a scored item names its glue
    prefix, metrics and the paper's cases, and its chapter glues every key the scoreboards paste: numbers are
    never typed, in the notes neither."""
    mod = _figures_script()
    prefixes = []
    for it in _items():
        score = it.get("score")
        assert score and score.get("kind") in ("score", "illustration", "see"), it["label"]
        if score["kind"] == "score":
            assert re.fullmatch(r"[tf]\d+", score["key"]) and score["metrics"] and it["short"].strip(), it["label"]
            assert all(isinstance(c, str) and c for c in score["cases"]), it["label"]
            prefixes.append(score["key"])
            texts = [it["short"], *score["footnotes"], *score["metrics"].values()]
        elif score["kind"] == "see":  # a figure of the maps that a table scores: listed with that table
            assert score["scored_with"].startswith("tab:") and score["scored_with"] in PAPER_LABELS
            texts = []
        else:
            assert score["note"].strip() and "met" not in score
            texts = [score["note"]]
        for text in texts:
            assert not re.search(r"\d\.\d", text), f"{it['label']}: typed decimal in {text!r}"
        keys = mod.glue_keys(it)
        if keys:
            patterns = _glued_key_patterns(ROOT / it["notebook"])
            for key in keys:
                assert any(p.fullmatch(key) for p in patterns), f"{it['label']}: {it['notebook']} glues no {key!r}"
    assert len(prefixes) == len(set(prefixes)) == 9


def test_scoreboard_numbers_the_items_as_the_paper_and_fits_one_screen():
    """Items are named by their number in the paper (counted in the paper's order), never by a LaTeX label; the
    intro's scoreboard has one row per scored table or figure and metric, under one stated criterion."""
    mod = _figures_script()
    numbers = mod.paper_numbers(_items())
    assert numbers["tab:overview"] == "Table 1" and numbers["tab:population_test"] == "Table 4"
    assert numbers["tab:3d_resolution_test"] == "Table 9" and numbers["fig:3d_resolution_test"] == "Fig. 13"
    board = mod.scoreboard(ROOT)
    assert "tab:" not in board and "fig:" not in board
    # each item links to its section of the chapter, which marks it with the item's target
    assert "{ref}`Table 4 (Fig. 7) <paper-tab-population-test>`" in board
    for it in _items():
        if it["score"]["kind"] == "score" and it["notebook"].endswith(".ipynb"):
            assert f"<{mod.item_target(it)}>`" in board, it["label"]
    rows = [line for line in board.splitlines() if line.startswith("| ")]
    n_metrics = sum(len(it["score"]["metrics"]) + len(it["score"].get("shown", {}))
                    for it in _items() if it["score"]["kind"] == "score")
    assert len(rows) == 1 + n_metrics <= 19
    # the rules in brief above the table, in full (once) above the case-by-case scoreboard
    assert board.count("**How to read it.**") == 1 and "is at most the paper's value" in board
    assert "*not comparable*" in board and f"<{mod.RULES_TARGET}>" in board
    head = rows[0]
    for col in ("Verdict", "Paper", "Paper's method", "Delivered", "Classical"):
        assert col in head
    full = mod.full_scoreboard(ROOT)
    assert full.count("**Criterion.**") == 1 and full.count("**Verdict.**") == 1
    assert full.count(f"({mod.RULES_TARGET})=") == 1
    # the rule in two sentences, then the rules in full in a closed dropdown, then the table
    target, fold, criterion, table = (full.index(t) for t in (f"({mod.RULES_TARGET})=", ":::{dropdown}",
                                                                "**Criterion.**", "| Paper item"))
    assert target < fold < criterion < table and full.index("\n:::\n", criterion) < table
    for key in ("t4_std_rho_map_rect-peak_native", "t9_std_rho_map_64_met", "t7_verdict", "f10_verdict"):
        assert f"::{key}:s`" in full, key  # pasted by a glue role, not left as text
    for text in (board, full):  # every placeholder became a glue role (a key with a hyphen too)
        left = re.sub(r"\{glue:text\}`[^`]*`", "", text)
        left = re.sub(r"\{(doc|term|ref)\}`[^`]*`", "", left)
        left = re.sub(r"^:::\{(dropdown|container)\}", "", left, flags=re.M)  # a directive, not a placeholder
        assert not mod.PLACEHOLDER.search(left), mod.PLACEHOLDER.search(left)
    scored = [it for it in _items() if it["score"]["kind"] == "score"]
    refs, defs = mod._footnotes(scored)
    assert len({d.split("]:")[0] for d in defs}) == len(defs)  # a caveat two items share is defined once
    brief = mod._footnotes(scored, intro=True)[1]
    assert set(brief) < set(defs)  # the intro keeps the notes that change a row's reading, figures.md has all
    for text, notes in ((board, brief), (full, defs)):  # every caveat is defined once and referenced
        for d in notes:
            name = d.split("]:")[0] + "]"
            assert text.count("\n" + name + ":") == 1 and text.count(name) >= 2, name
    for it in _items():
        notes = it["score"].get("footnotes", [])
        assert refs.get(it["label"], "").count("[^") == len(notes), it["label"]


def test_scoreboard_pastes_from_the_chapters():
    mod = _figures_script()
    row = mod.paste("{sq_met} of 4, {res_std_max:.3g}, {t4_mean_mu_sin-cos_met}", "notebooks/06_dem_deq_2d.ipynb")
    assert row == ("{glue:text}`../notebooks/06_dem_deq_2d.ipynb::sq_met:s` of 4, "
                   "{glue:text}`../notebooks/06_dem_deq_2d.ipynb::res_std_max:.3g`, "
                   "{glue:text}`../notebooks/06_dem_deq_2d.ipynb::t4_mean_mu_sin-cos_met:s`")
    assert "\\|" in mod.paste("|Δd| {k}", "notebooks/05_beltrami_reconstruction.ipynb")  # pipes escaped in a table


def test_chapter_times_name_existing_chapters():
    mod = _figures_script()
    times = mod.load_times(ROOT)
    assert set(times) <= {"about", "ci", "full"}
    stems = {nb.stem for nb in NOTEBOOKS}
    for scale in ("ci", "full"):
        info = times.get(scale) or {}
        for stem, seconds in (info.get("seconds") or {}).items():
            assert stem in stems and seconds > 0, (scale, stem, seconds)
        if info.get("seconds"):
            assert info.get("how") and info.get("machine"), f"{scale}: say how and where the times were measured"
    assert mod._duration(None) == "not measured yet" and mod._duration(90) == "90 s"
    assert mod._duration(600) == "10.0 min"


def test_make_chapter_runs_one_notebook_through_the_kernel():
    make = (ROOT / "Makefile").read_text(encoding="utf-8")
    recipe = make[make.index("\nchapter:"):make.index("\npages:")]
    assert "--ExecutePreprocessor.kernel_name=$(KERNEL)" in recipe and "$(NB_ENV)" in recipe
    assert "RFMAP_SCALE=$(RFMAP_SCALE)" in recipe and "scripts/chapter_times.py record" in recipe
    assert "make chapter NB=" in (ROOT / "book" / "reproduce.md").read_text(encoding="utf-8")


def test_chapter_times_are_read_from_a_record(tmp_path):
    spec = importlib.util.spec_from_file_location("chapter_times", ROOT / "scripts" / "chapter_times.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "06_dem_deq_2d.time.json"
    assert mod.main(["record", "06_dem_deq_2d", "--start", "100.0", "--end", "162.5", "--scale", "ci",
                     "--out", str(out)]) == 0
    times, machine = mod.from_chapters(tmp_path, "ci")
    assert times == {"06_dem_deq_2d": 62.5} and machine
    assert mod.from_chapters(tmp_path, "full")[0] == {}


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
def test_notebook_opens_with_the_project_kernel(nb):
    """A chapter names the kernel that `make install` registers, so JupyterLab, nbval and the book build run it
    with the interpreter and environment of .venv."""
    spec = json.loads(nb.read_text(encoding="utf-8"))["metadata"]["kernelspec"]
    assert (spec["name"], spec["display_name"], spec["language"]) == ("rfmap", "Python (rfmap)", "python")


@pytest.mark.parametrize("nb", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_is_committed_without_outputs(nb):
    """Notebooks are committed without outputs or execution counts: the book and nbval execute them."""
    data = json.loads(nb.read_text(encoding="utf-8"))
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


def test_reproduce_page_gives_the_nbval_command_of_make_test():
    """`make test` runs the notebooks with nbval through the project's kernel (not the test process's interpreter),
    from notebooks/; the reproduction page shows the same command."""
    make = (ROOT / "Makefile").read_text(encoding="utf-8")
    kernel = re.search(r"^KERNEL := (\S+)$", make, re.M).group(1)
    flags = re.search(r"^NBVAL_FLAGS := (.+)$", make, re.M).group(1).replace("$(KERNEL)", kernel)
    assert kernel == "rfmap" and "--nbval-lax" in flags and "--nbval-current-env" not in flags
    assert re.search(r"^\tscripts/run_tests\.sh \$\(BIN\) \"\$\(NBVAL_FLAGS\)\" \"\$\(BOOK_FLAGS\)\"$", make, re.M)
    runner = (ROOT / "scripts" / "run_tests.sh").read_text(encoding="utf-8")
    assert re.search(r'^\(cd notebooks && .*\$BIN/pytest" \$NBVAL_FLAGS \.\)', runner, re.M)
    assert "export RFMAP_SCALE=ci" in runner and 'jupyter-book" build . $BOOK_FLAGS' in runner
    page = (ROOT / "book" / "reproduce.md").read_text(encoding="utf-8")
    assert f"pytest {flags} ." in re.sub(r"\s*\\\n\s*", " ", page)  # a command continued over lines reads as one


# ----------------------------------------------------------------------------------------------- saved figures
@pytest.mark.parametrize("nb", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_every_saved_figure_is_shown_with_its_caption(nb):
    """Every figure a chapter saves is shown where it is made, alone in its cell's output, as a named figure whose
    caption names its counterpart in the paper (scripts/book_check.py checks the built page the same way)."""
    problems = _book_check().figure_source_problems(nb)
    assert not problems, "\n".join(problems)


#: how the prose of a chapter cites a figure of the paper: "the paper's Fig. 5", "its Table 3 and Fig. 6" (in a
#: sentence about the paper), "paper Fig. 4", or "Fig. 5 of the paper"
PAPER_FIGURE = re.compile(r"(?:the paper's|\bits|\bpaper) (?:Tables? [\d ,and]+)?(?:Fig\.|Figs\.) \d+"
                          r"|Figs?\. \d+(?: and \d+)? of the paper", re.I)


def test_the_book_numbers_none_of_its_own_figures():
    """Jupyter Book numbers captioned figures across the whole book unless told not to; those numbers would clash
    with the paper's, which the text cites. With numfig off, every "Fig. n" in the book is the paper's, and the
    chapters say so where they cite one."""
    cfg = yaml.safe_load((ROOT / "_config.yml").read_text(encoding="utf-8"))
    # sphinx-jupyterbook-latex would set numfig back to True in every build
    assert cfg["sphinx"]["config"]["numfig"] is False and cfg["latex"]["use_jupyterbook_latex"] is False
    bare = []
    for nb in NOTEBOOKS:
        cells = json.loads(nb.read_text(encoding="utf-8"))["cells"]
        for cell in cells:
            texts = ["".join(cell["source"])] if cell["cell_type"] == "markdown" else []
            texts.append(str(cell["metadata"].get("mystnb", {}).get("figure", {}).get("caption", "")))
            for text in texts:
                text = " ".join(text.split())
                cited = {m.start() + m.group().index("Fig") for m in PAPER_FIGURE.finditer(text)}
                bare += [f"{nb.stem} {cell['id']}: ...{text[max(0, m.start() - 40):m.end()]}"
                         for m in re.finditer(r"Figs?\. \d+|Figures? \d+", text) if m.start() not in cited]
    assert not bare, "a figure number not said to be the paper's:\n" + "\n".join(bare)


def test_paper_figure_numbers_follow_the_paper():
    """The captions' "Fig. n" count the paper's figures in the order of figures.json, which is the paper's."""
    assert [it["label"] for it in _items()] == PAPER_LABELS
    numbers = _book_check().paper_figure_numbers(ROOT)
    assert list(numbers) == [label for label in PAPER_LABELS if label.startswith("fig:")]
    assert numbers["fig:illustration"] == 1 and numbers["fig:3d_resolution_test"] == 13


def test_figure_file_names_are_those_of_save_figure(tmp_path, monkeypatch):
    plt = pytest.importorskip("matplotlib.pyplot")
    from rfmap.viz import save_figure

    monkeypatch.setenv("RFMAP_FIGURES", str(tmp_path))
    fig = plt.figure(figsize=(1, 1))
    try:
        path = save_figure(fig, "fig:a_b-c")
    finally:
        plt.close(fig)
    assert path == tmp_path / (_book_check().figure_stem("fig:a_b-c") + ".png") and path.exists()


def _notebook(tmp_path: Path, *cells) -> Path:
    """A notebook of code cells given as (source, figure metadata or None)."""
    nb = {"cells": [{"cell_type": "code", "id": f"c{i}", "metadata": {"mystnb": {"figure": meta}} if meta else {},
                     "execution_count": None, "outputs": [], "source": src} for i, (src, meta) in enumerate(cells)],
          "metadata": {}, "nbformat": 4, "nbformat_minor": 5}
    path = tmp_path / "chapter.ipynb"
    path.write_text(json.dumps(nb), encoding="utf-8")
    return path


def test_the_figure_check_reads_the_source(tmp_path):
    check = _book_check()
    ok = {"name": "fig-bc-sample", "caption": "Reproduces Fig. 2 of the paper: circles."}
    beyond = {"name": "fig-extra", "caption": "Beyond the paper: a picture."}
    good = _notebook(tmp_path, ('with style():\n    save_figure(fig, "fig:bc_sample")\n    plt.show()', ok),
                     ('if x:\n    save_figure(fig, "fig:extra")\n    plt.show()', beyond), ("print(1)", None))
    assert check.figure_source_problems(good) == []
    assert [(f.stem, f.conditional) for f in check.saved_figures(good)] == [("fig-bc-sample", False),
                                                                            ("fig-extra", True)]
    cases = {
        "not show": ('save_figure(fig, "fig:bc_sample")', ok),
        "displays more": ('save_figure(fig, "fig:bc_sample")\nplt.show()\ndisplay(table)', ok),
        "ends in an expression": ('save_figure(fig, "fig:bc_sample")\nplt.show()\nMarkdown(t)', ok),
        "saves 2 figures": ('save_figure(f, "fig:bc_sample")\nsave_figure(g, "fig:extra")\nplt.show()', ok),
        "name must be": ('save_figure(fig, "fig:bc_sample")\nplt.show()', {**ok, "name": "other"}),
        "Reproduces Fig. 2": ('save_figure(fig, "fig:bc_sample")\nplt.show()', beyond),
        "Beyond the paper": ('save_figure(fig, "fig:extra")\nplt.show()', ok),
        "savefig": ('fig.savefig("x.png")\nplt.show()', None),
        "computed label": ('save_figure(fig, f"fig:{name}")\nplt.show()', None),
        "saves no figure": ("plt.show()", ok),
    }
    for why, cell in cases.items():
        problems = check.figure_source_problems(_notebook(tmp_path, cell))
        assert any(why in p for p in problems), (why, problems)


def test_the_figure_check_reads_the_built_page(tmp_path):
    check = _book_check()
    numbers = {"fig:bc_sample": 2}
    saved = [check.SavedFigure("fig:bc_sample", 3, "c06", False), check.SavedFigure("fig:extra", 5, "c08", True)]
    page = tmp_path / "chapter.html"

    def problems(body):
        page.write_text(f"<html><article>{body}</article></html>", encoding="utf-8")
        return check.page_figure_problems(page, saved, numbers, tmp_path)

    def figure(stem, caption, img='<img alt="" src="../_images/a.png" />'):
        return (f'<figure class="align-default" id="{stem}"><div class="cell_output">{img}</div><figcaption><p>'
                f'<span class="caption-number">Fig. 1 </span><span class="caption-text">{caption}</span></p>'
                "</figcaption></figure>")

    shown = figure("fig-bc-sample", "Reproduces Fig. 2 of the <em>paper</em>: circles")
    assert problems(shown) == []  # fig:extra is conditional and its file is absent: not saved in this build
    (tmp_path / "fig-extra.png").write_bytes(b"")
    assert problems(shown) == ["figure fig-extra.png, saved by cell 5 (c08), is not on the page"]
    assert problems(shown + figure("fig-extra", "Beyond the paper: x")) == []
    assert "without an image" in problems(figure("fig-bc-sample", "Reproduces Fig. 2 of the paper", img=""))[0]
    assert "without a caption" in problems(figure("fig-bc-sample", "Reproduces Fig. 3 of the paper"))[0]
    assert "is not on the page" in problems('<img src="../_images/a.png">')[0]


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
