"""scripts/book_check.py finds broken figures in built HTML: missing, unreadable and blank images."""
import base64
import importlib.util
import io
from pathlib import Path

import numpy as np
import pytest

Image = pytest.importorskip("PIL.Image")

ROOT = Path(__file__).resolve().parent.parent


def _script(name: str):
    """A script of scripts/ loaded as a module."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def book_check():
    return _script("book_check")


def _png(pixels: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(pixels.astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def _page(tmp_path: Path, body: str) -> Path:
    page = tmp_path / "notebooks" / "chapter.html"
    page.parent.mkdir(parents=True, exist_ok=True)
    page.write_text(f"<html><body><nav><img src='logo-missing.png'></nav><article class='bd-article'>{body}"
                    "</article></body></html>", encoding="utf-8")
    return page


@pytest.fixture()
def images(tmp_path):
    d = tmp_path / "_images"
    d.mkdir()
    rng = np.random.default_rng(0)
    (d / "figure.png").write_bytes(_png(rng.integers(0, 256, (40, 60, 3))))
    (d / "white.png").write_bytes(_png(np.full((40, 60, 3), 255)))
    (d / "nearly-white.png").write_bytes(_png(np.where(rng.random((40, 60)) < 0.001, 254, 255)))
    (d / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n not really")
    (d / "drawing.svg").write_text("<svg xmlns='http://www.w3.org/2000/svg'><circle r='3'/></svg>")
    return d


def test_a_real_figure_passes(book_check, tmp_path, images):
    page = _page(tmp_path, '<img alt="" src="../_images/figure.png"><img src="../_images/drawing.svg">')
    assert book_check.scan_html(page) == []


@pytest.mark.parametrize("name, why", [("white.png", "blank image"), ("nearly-white.png", "blank image"),
                                       ("broken.png", "unreadable image"), ("absent.png", "missing image")])
def test_broken_figures_are_reported(book_check, tmp_path, images, name, why):
    page = _page(tmp_path, f'<p>text</p><img class="x" src="../_images/{name}">')
    problems = book_check.scan_html(page)
    assert len(problems) == 1 and problems[0].startswith(why) and name in problems[0]


def test_inline_images_are_checked_too(book_check, tmp_path):
    blank = base64.b64encode(_png(np.zeros((8, 8)))).decode()
    page = _page(tmp_path, f'<img src="data:image/png;base64,{blank}">')
    assert [p.split(" ")[0:2] for p in book_check.scan_html(page)] == [["blank", "image"]]


@pytest.mark.parametrize("shown, why", [
    ("[PosixPath('/srv/x/book/figures/tab-a.md')]", "a printed pathlib path"),
    ("{root}/src/rfmap/data/design.json", "the repository's folder"),
    ("wrote {tmp}/tmpab12cd_x/cartogram.geojson", "a temporary file's path"),
])
def test_machine_paths_are_reported(book_check, tmp_path, shown, why):
    import tempfile

    text = shown.format(root=book_check.ROOT.resolve(), tmp=tempfile.gettempdir())
    problems = book_check.scan_html(_page(tmp_path, f"<pre>{text}</pre>"))
    assert len(problems) == 1 and problems[0].startswith(why)


def test_relative_paths_pass(book_check, tmp_path):
    page = _page(tmp_path, "<p>book/figures/tab-a.md, src/rfmap/data/design.json, wrote cartogram.geojson</p>")
    assert book_check.scan_html(page) == []


def test_images_outside_the_article_are_ignored(book_check, tmp_path):
    assert book_check.scan_html(_page(tmp_path, "<p>no figures</p>")) == []


def test_main_fails_on_a_page_with_a_blank_figure(book_check, tmp_path, images, monkeypatch, capsys):
    html = tmp_path
    (html / "index.html").write_text("<html></html>")
    _page(tmp_path, '<img src="../_images/white.png">')
    monkeypatch.setattr(book_check, "toc_pages", lambda: ["notebooks/chapter"])
    assert book_check.main(["--html", str(html), "--no-screenshots"]) == 1
    assert "FAIL notebooks/chapter: blank image" in capsys.readouterr().out


@pytest.fixture(scope="module")
def text_check():
    return _script("book_text_check")


@pytest.mark.parametrize("body, found", [
    ("<td>{t4_std_rho_map_sin-cos_paper}</td>", "unresolved placeholder {t4_std_rho_map_sin-cos_paper}"),
    ("<p>met on {t7n_std_rho_map_met:s} sides</p>", "unresolved placeholder {t7n_std_rho_map_met:s}"),
    ("<p>{glue:text}`../notebooks/06.ipynb::key:s`</p>", "unresolved placeholder {glue:text}`../notebooks/06.ipynb::"),
    ("<p>see {doc}`figures`</p>", "unresolved placeholder {doc}"),
])
def test_unresolved_placeholders_are_reported_with_their_key(book_check, text_check, tmp_path, body, found):
    page = _page(tmp_path, body)
    problems = text_check.page_problems(page)
    assert len(problems) == 1 and problems[0].startswith(found), problems
    assert any(p.startswith(found) for p in book_check.scan_html(page))  # make book-check reports it too


@pytest.mark.parametrize("body", [
    "<pre>print(f'{key}')</pre>", "<p>the dict <code class='literal'>{prefix}_{key}</code></p>",
    '<span class="math notranslate nohighlight">\\(\\frac{a}{b} + \\mathrm{Std}\\)</span>',
    '<div class="math notranslate nohighlight">\\[x^{n}_{ij}\\]</div>', "<p>\\(\\tilde\\rho_{map}\\)</p>",
    "<p>the set {0, 1} and 0.08254</p>",
    '<dl><dt class="sig sig-object py"><span class="pre">NAMES</span> = <span class="pre">{\'a\': \'$\\rho_{map}$\'}</span>'
    "</dt><dd>doc</dd></dl>",
])
def test_braces_in_code_math_and_plain_text_pass(text_check, tmp_path, body):
    assert text_check.page_problems(_page(tmp_path, body)) == []


@pytest.mark.parametrize("shown, why", [
    ("&lt;rfmap.surrogate.Surrogate object at 0x7f3a2c&gt;", "an object's default repr"),
    ("MultiResUNet(\n  (lift): Conv2d(3, 8, kernel_size=(1, 1))\n)", "a torch module printout"),
    ("Surrogate('deq2d-square', TaskSpec(kind='density'))", "a repr of an rfmap object"),
    ("{'std_rho_map': 0.0812, 'n_flipped': 0}", "a printed dict of metrics"),
])
def test_raw_reprs_in_outputs_are_reported(text_check, tmp_path, shown, why):
    body = f'<div class="output text_plain highlight-myst-ansi notranslate"><div class="highlight"><pre>{shown}</pre>'
    problems = text_check.page_problems(_page(tmp_path, body + "</div></div>"))
    assert len(problems) == 1 and problems[0].startswith(why), problems


def test_the_text_check_fails_the_build_naming_page_and_key(text_check, tmp_path, capsys):
    (tmp_path / "index.html").write_text("<html><article><p>fine</p></article></html>")
    _page(tmp_path, "<td>{t4_verdict}</td>")
    assert text_check.main(["--html", str(tmp_path)]) == 1
    assert "FAIL notebooks/chapter: unresolved placeholder {t4_verdict}" in capsys.readouterr().out
    (tmp_path / "notebooks" / "chapter.html").write_text("<html><article><p>0.0812</p></article></html>")
    assert text_check.main(["--html", str(tmp_path)]) == 0


def test_the_text_check_fails_on_a_missing_glue_key(text_check, tmp_path, monkeypatch, capsys):
    """A glue key a chapter or a page of book/ refers to, absent from the build's glue data, fails the check
    (a missing key renders as nothing, so the pages alone cannot show it)."""
    import json

    nb = tmp_path / "09_dem_3d.ipynb"
    nb.write_text(json.dumps({"cells": [{"cell_type": "markdown", "source": [
        "meets on {glue:text}`t7_met` densities; ratio {glue:text}`t7_ratio:.3f`"]}]}))
    page = tmp_path / "figures.md"
    page.write_text("| {glue:text}`../notebooks/09_dem_3d.ipynb::t7_verdict:s` |")
    glue = tmp_path / "glue"
    glue.mkdir()
    (glue / "09_dem_3d.glue.json").write_text(json.dumps({"t7_met": {}, "t7_ratio": {}}))
    monkeypatch.setattr(text_check, "ROOT", tmp_path)
    assert text_check.glue_problems([nb], glue) == []
    assert text_check.glue_problems([nb, page], glue) == [
        "figures.md: missing glue key 't7_verdict' of 09_dem_3d"]
    html = tmp_path / "html"
    html.mkdir()
    (html / "index.html").write_text("<html><article><p>fine</p></article></html>")
    monkeypatch.setattr(text_check, "book_sources", lambda: [nb, page])
    assert text_check.main(["--html", str(html), "--glue", str(glue)]) == 1
    assert "FAIL glue: figures.md: missing glue key 't7_verdict'" in capsys.readouterr().out


def test_a_glue_role_shown_as_code_is_an_example_not_a_use(text_check, tmp_path, monkeypatch):
    """A page that shows the role syntax inside a code span or a fenced block (book/reproduce.md does) refers to
    no key; a real role beside it is still checked."""
    import json

    page = tmp_path / "reproduce.md"
    page.write_text("the paste ``{glue:text}`../notebooks/06_dem_deq_2d.ipynb::sq_met:s` `` shown\n\n"
                    "```md\n{glue:text}`../notebooks/06_dem_deq_2d.ipynb::other:s`\n```\n\n"
                    "real: {glue:text}`../notebooks/06_dem_deq_2d.ipynb::t6_verdict:s`\n")
    glue = tmp_path / "glue"
    glue.mkdir()
    (glue / "06_dem_deq_2d.glue.json").write_text(json.dumps({"t6_other": {}}))
    monkeypatch.setattr(text_check, "ROOT", tmp_path)
    assert text_check.glue_refs(page) == [("06_dem_deq_2d", "t6_verdict")]
    assert text_check.glue_problems([page], glue) == [
        "reproduce.md: missing glue key 't6_verdict' of 06_dem_deq_2d"]


def _titled(shift: int = 0) -> bytes:
    """A white page with a dark title block at x = 288..700, y = 135..230, drawn ``shift`` pixels to the left."""
    page = np.full((400, 1280), 255)
    page[140:225, 288 - shift:700 - shift] = 30
    return _png(page)


def test_a_capture_shows_the_title_where_the_page_places_it(book_check):
    box = {"left": 288, "top": 135, "width": 412, "height": 95}
    assert book_check.title_problem(_titled(), box) is None
    assert book_check.title_problem(_titled(), None) is None  # a page without a title is not judged


@pytest.mark.parametrize("shift", [208, 600])
def test_a_capture_shifted_sideways_is_reported(book_check, shift):
    """Chromium has drawn a page shifted to the left (no sidebar, the title cut at the left edge)."""
    box = {"left": 288, "top": 135, "width": 412, "height": 95}
    why = book_check.title_problem(_titled(shift), box)
    assert why and "shifted sideways" in why


def test_the_capture_uses_the_laid_out_viewport(book_check):
    """The whole page is the viewport; the capture does not ask Chromium to render beyond it again."""
    source = (ROOT / "scripts" / "book_check.py").read_text(encoding="utf-8")
    assert "captureBeyondViewport=False" in source and "captureBeyondViewport=True" not in source


def _tables(k: int) -> str:
    return "".join(f"<table><tr><td>{i}</td></tr></table>" for i in range(k))


def test_a_chapter_with_more_tables_than_the_limit_fails(text_check, tmp_path):
    limit = text_check.MAX_TABLES
    assert text_check.page_problems(_page(tmp_path, _tables(limit))) == []
    problems = text_check.page_problems(_page(tmp_path, _tables(limit + 1)))
    assert problems == [f"{limit + 1} tables shown (at most {limit}; collapse the others with hide-output)"]


def test_collapsed_tables_and_pages_outside_the_chapters_do_not_count(text_check, tmp_path):
    limit = text_check.MAX_TABLES
    hidden = (f'<div class="cell tag_hide-output docutils container"><div>{_tables(3)}</div><br></div>'
              f"<details><summary>more</summary>{_tables(3)}</details>")
    assert text_check.shown_tables(_tables(limit) + hidden) == limit
    assert text_check.page_problems(_page(tmp_path, _tables(limit) + hidden)) == []
    other = tmp_path / "book" / "design.html"
    other.parent.mkdir(parents=True)
    other.write_text(f"<html><body><article>{_tables(limit + 5)}</article></body></html>", encoding="utf-8")
    assert text_check.page_problems(other) == []
