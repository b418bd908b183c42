"""CITATION.cff and the book's "Cite" section name the paper as references.bib does."""
import re
from pathlib import Path

import pytest

yaml = pytest.importorskip("yaml")

ROOT = Path(__file__).resolve().parent.parent


def _bib_entry(key: str) -> dict:
    bib = (ROOT / "references.bib").read_text(encoding="utf-8")
    body = re.search(r"@\w+\{" + re.escape(key) + r",(.*?)\n\}", bib, re.S).group(1)
    return {k: v.strip() for k, v in re.findall(r"(\w+)\s*=\s*\{(.*)\},?", body)}


def test_citation_cff_prefers_the_paper_as_in_the_bibliography():
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software"
    from rfmap import __version__

    assert str(cff["version"]) == __version__
    paper = cff["preferred-citation"]
    bib = _bib_entry("huang2026resolution")
    assert paper["title"] == bib["title"]
    assert str(paper["year"]) == bib["year"]
    names = [f"{a['family-names']}, {a['given-names']}" for a in paper["authors"]]
    assert names == [a.strip() for a in bib["author"].split(" and ")]
    assert "doi" not in paper  # none is known


def test_book_has_a_cite_section_with_the_bibtex_entry():
    intro = (ROOT / "book" / "intro.md").read_text(encoding="utf-8")
    assert "\n## Cite\n" in intro
    # BibTeX reads a line break in a field as a space: the entry may wrap to fit the page's code width
    assert " ".join(_bib_entry("huang2026resolution")["title"].split()) in " ".join(intro.split())
    assert "CITATION.cff" in intro
