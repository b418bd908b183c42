"""The index of the API reference (book/api.md) names, for each page, exactly the modules the page documents, and
every page of the reference gives each module a heading of its own."""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
INDEX = ROOT / "book" / "api.md"
PAGES = sorted((ROOT / "book" / "api").glob("*.md"))
AUTOMODULE = re.compile(r"^\.\. automodule:: (\S+)", re.M)


def _entries() -> dict[str, str]:
    """page stem -> the text of its bullet in the index (continuation lines joined)."""
    text = INDEX.read_text(encoding="utf-8")
    bullets = re.findall(r"^\* \{doc\}`api/(\w+)`:(.*?)(?=^\* |\Z)", text, re.M | re.S)
    return {stem: " ".join(body.split()) for stem, body in bullets}


def test_the_index_has_one_entry_per_page():
    assert sorted(_entries()) == sorted(p.stem for p in PAGES)


@pytest.mark.parametrize("page", PAGES, ids=[p.stem for p in PAGES])
def test_the_index_names_the_modules_of_the_page(page):
    """The modules of a page's entry (the backquoted names after its last ';') are its ``automodule`` targets."""
    entry = _entries()[page.stem]
    listed = re.findall(r"`(rfmap[\w.]*)`", entry.rsplit(";", 1)[-1])
    documented = AUTOMODULE.findall(page.read_text(encoding="utf-8"))
    assert listed == documented, f"book/api.md lists {listed} for {page.name}, which documents {documented}"


@pytest.mark.parametrize("page", PAGES, ids=[p.stem for p in PAGES])
def test_every_module_has_a_heading(page):
    """Each ``automodule`` comes under a heading that names its module (on the command line's page too, in the part
    written by hand below the section that scripts/make_cli_md.py generates)."""
    text = page.read_text(encoding="utf-8")
    for module in AUTOMODULE.findall(text):
        at = text.index(f".. automodule:: {module}\n")
        heading = re.findall(r"^#{2,4} .*$", text[:at], re.M)[-1]
        assert f"`{module}`" in heading, f"{page.name}: {module} follows the heading {heading!r}"
