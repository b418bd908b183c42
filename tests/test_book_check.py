"""scripts/book_check.py finds broken figures in built HTML: missing, unreadable and blank images."""
import base64
import importlib.util
import io
from pathlib import Path

import numpy as np
import pytest

Image = pytest.importorskip("PIL.Image")

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def book_check():
    spec = importlib.util.spec_from_file_location("book_check", ROOT / "scripts" / "book_check.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


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
