#!/usr/bin/env python3
"""Fail on text a reader should never see in the built book: unresolved placeholders and raw object reprs.

Usage: python scripts/book_text_check.py [--html _build/html]

Every HTML page of the book (``_build/html/**/*.html`` but the theme's own pages) is read as a reader sees it: the
article only, without code (``<pre>``, ``<code>``, the API's signatures), math (MathJax spans and blocks) and
scripts.  Two kinds of
problem are reported, one line each, naming the page and what was found:

* an **unresolved placeholder**: a ``{key}`` or ``{key:format}`` left in the text (a scoreboard template whose key
  the generator did not turn into a glue role), or a raw ``{glue:...}`` / ``{glue}`` role that the build did not
  resolve;
* a **raw repr** in a cell's output: ``<... object at 0x...>``, a torch module printout (``(name): Conv2d(``), a
  dataclass repr of the package (``Surrogate(``, ``TaskSpec(``, ``MapResult(``, ``MapMetrics(``) or a printed
  ``dict`` of metric names.

A chapter (a page under ``notebooks/``) also fails when it shows more than :data:`MAX_TABLES` tables: a table in a
collapsed output (a cell tagged ``hide-output``, or inside a ``<details>`` block) does not count, since the reader
opens it on demand.

A fourth check reads the sources rather than the pages: every key a ``{glue:...}`` role of a chapter or of a page
of ``book/`` refers to must be in the glue data the build recorded for its notebook
(``_build/jupyter_execute/notebooks/NAME.glue.json``).  A key that is missing renders as nothing at all (a
sentence ending in ": ."), so it is reported as ``missing glue key``, naming the notebook and the key.

The exit status is 1 when any page has a problem.  ``make book`` runs this after the build, and
``scripts/book_check.py`` (``make book-check``) reports the same problems per page.
"""
from __future__ import annotations

import argparse
import html
import json
import re
import sys
from html.parser import HTMLParser
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: elements whose text is not prose: code, math and scripts (removed before the placeholder search)
NOT_PROSE = re.compile(
    r"<(pre|code|script|style|mjx-container)\b.*?</\1>"
    r"|<(span|div)\b[^>]*class=\"[^\"]*\bmath\b[^\"]*\"[^>]*>.*?</\2>"
    r"|<dt\b[^>]*class=\"[^\"]*\bsig\b[^\"]*\"[^>]*>.*?</dt>",  # an API signature (values as Python literals)
    re.DOTALL | re.IGNORECASE)
#: inline and display math delimiters MathJax reads in plain text
TEX = re.compile(r"\\\(.*?\\\)|\\\[.*?\\\]|\$\$.*?\$\$", re.DOTALL)
TAG = re.compile(r"<[^>]+>")
PLACEHOLDER = re.compile(r"\{glue(?::\w+)?\}`?[^`\s]*`?|\{[A-Za-z_][A-Za-z0-9_-]*(?::[^{}\s]*)?\}")
#: the text of a cell's plain-text output
OUTPUT = re.compile(r'<div class="output text_plain[^"]*">.*?<pre>(.*?)</pre>', re.DOTALL)
REPRS = [
    (re.compile(r"<[\w.]+ object at 0x[0-9a-fA-F]+>"), "an object's default repr"),
    (re.compile(r"^\s*\(\w+\): [A-Z]\w*\(", re.MULTILINE), "a torch module printout"),
    (re.compile(r"\b(?:Surrogate|TaskSpec|MapResult|MapMetrics|MapOptions|FinishOptions|PredictOptions|TrainConfig)"
                r"\((?:'|\w+=)"),
     "a repr of an rfmap object"),
    (re.compile(r"\{'(?:std_rho_map|std_rho_orig|mean_mu|max_mu|mean_dd|mean_dmu|min_jacobian|n_flipped)'"),
     "a printed dict of metrics"),
]


#: the most tables a chapter shows before its reader opens a collapsed output
MAX_TABLES = 8
#: HTML elements without an end tag
VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}


class _ShownTables(HTMLParser):
    """Counts the ``<table>`` elements that are not inside a collapsed output (``tag_hide-output`` or
    ``<details>``)."""

    def __init__(self):
        super().__init__()
        self.hidden: list[bool] = []
        self.shown = 0

    def handle_starttag(self, tag, attrs):
        classes = (dict(attrs).get("class") or "").split()
        hidden = (bool(self.hidden) and self.hidden[-1]) or tag == "details" or "tag_hide-output" in classes
        self.shown += tag == "table" and not hidden
        if tag not in VOID:
            self.hidden.append(hidden)

    def handle_endtag(self, tag):
        if tag not in VOID and self.hidden:
            self.hidden.pop()


def shown_tables(body: str) -> int:
    """The number of tables an article's HTML shows without opening a collapsed output."""
    parser = _ShownTables()
    parser.feed(body)
    return parser.shown


def article(text: str) -> str:
    """The ``<article>`` of a page (the whole text where there is none)."""
    m = re.search(r"<article\b.*?</article>", text, re.DOTALL)
    return m.group(0) if m else text


def placeholder_problems(body: str) -> list[str]:
    """Unresolved placeholders and raw glue roles in the prose of an article's HTML."""
    prose = TEX.sub(" ", html.unescape(TAG.sub(" ", NOT_PROSE.sub(" ", body))))
    found = list(dict.fromkeys(m.group(0) for m in PLACEHOLDER.finditer(prose)))
    return [f"unresolved placeholder {f}" for f in found]


def repr_problems(body: str) -> list[str]:
    """Raw reprs in the plain-text outputs of an article's cells."""
    out = []
    for m in OUTPUT.finditer(body):
        text = html.unescape(TAG.sub("", m.group(1)))
        for pat, why in REPRS:
            hit = pat.search(text)
            if hit:
                out.append(f"{why} in a cell's output: {hit.group(0).strip()[:60]!r}")
    return list(dict.fromkeys(out))


def page_problems(page: Path) -> list[str]:
    body = article(page.read_text(encoding="utf-8", errors="replace"))
    problems = placeholder_problems(body) + repr_problems(body)
    if page.parent.name == "notebooks" and (n := shown_tables(body)) > MAX_TABLES:
        problems.append(f"{n} tables shown (at most {MAX_TABLES}; collapse the others with hide-output)")
    return problems


#: a glue role and its target: {glue:text}`key:fmt`, {glue}`key`, {glue:text}`../notebooks/NB.ipynb::key:fmt`
GLUE_ROLE = re.compile(r"\{glue(?::\w+)?\}`([^`]+)`")
#: code the page shows rather than runs (fenced blocks and double-backtick spans): a role there is an example
SHOWN_CODE = re.compile(r"^```.*?^```|``.+?``", re.DOTALL | re.MULTILINE)


def glue_refs(source: Path) -> list[tuple[str, str]]:
    """(notebook stem, key) of every glue role in ``source`` (a notebook's Markdown cells or a Markdown page); a
    role without ``path::`` refers to the notebook itself."""
    if source.suffix == ".ipynb":
        cells = json.loads(source.read_text(encoding="utf-8"))["cells"]
        text = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "markdown")
    else:
        text = source.read_text(encoding="utf-8")
    out = []
    for target in GLUE_ROLE.findall(SHOWN_CODE.sub("", text)):
        path, _, key = target.rpartition("::")
        stem = Path(path).stem if path else source.stem
        out.append((stem, key.split(":", 1)[0]))
    return list(dict.fromkeys(out))


def glue_problems(sources: list[Path], glue_dir: Path) -> list[str]:
    """``missing glue key`` for every glue role of ``sources`` whose key the build did not record in
    ``glue_dir/NB.glue.json`` (every key of a notebook whose glue data is absent)."""
    data: dict[str, set[str] | None] = {}
    out = []
    for source in sources:
        for stem, key in glue_refs(source):
            if stem not in data:
                f = glue_dir / f"{stem}.glue.json"
                data[stem] = set(json.loads(f.read_text(encoding="utf-8"))) if f.exists() else None
            keys = data[stem]
            if keys is None:
                out.append(f"{source.relative_to(ROOT)}: no glue data for {stem} (looked for {stem}.glue.json)")
            elif key not in keys:
                out.append(f"{source.relative_to(ROOT)}: missing glue key {key!r} of {stem}")
    return list(dict.fromkeys(out))


def book_sources() -> list[Path]:
    """The chapters (``notebooks/*.ipynb``) and the Markdown pages of ``book/`` the build renders."""
    return sorted((ROOT / "notebooks").glob("*.ipynb")) + sorted((ROOT / "book").glob("*.md"))


def book_pages(html_dir: Path) -> list[Path]:
    """The book's pages: every HTML file but the theme's (search, genindex, _static, _sources)."""
    skip = {"search.html", "genindex.html", "py-modindex.html"}
    return sorted(p for p in html_dir.rglob("*.html")
                  if p.name not in skip and not any(part.startswith("_") for part in p.relative_to(html_dir).parts))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--html", type=Path, default=ROOT / "_build" / "html")
    parser.add_argument("--glue", type=Path, default=None,
                        help="the build's glue data (default: jupyter_execute/notebooks beside --html)")
    args = parser.parse_args(argv)
    glue_dir = args.glue or args.html.parent / "jupyter_execute" / "notebooks"
    pages = book_pages(args.html)
    if not pages:
        print(f"book_text_check: error: no built pages in {args.html}", file=sys.stderr)
        return 1
    bad = 0
    for page in pages:
        for p in page_problems(page):
            print(f"FAIL {page.relative_to(args.html).with_suffix('')}: {p}")
        bad += bool(page_problems(page))
    missing = glue_problems(book_sources(), glue_dir) if glue_dir.is_dir() else []
    for p in missing:
        print(f"FAIL glue: {p}")
    bad_glue = bool(missing)
    if not glue_dir.is_dir():
        print(f"book_text_check: no glue data in {glue_dir}; glue keys not checked")
    else:
        print(f"book_text_check: {len(missing)} missing glue key(s)" if missing
              else "book_text_check: every glue key the sources use was recorded")
    print(f"book_text_check: {bad} of {len(pages)} page(s) with unresolved placeholders, raw reprs or too many "
          "tables" if bad else f"book_text_check: {len(pages)} pages, no unresolved placeholder, no raw repr and no "
          f"chapter with more than {MAX_TABLES} tables shown")
    return 1 if bad or bad_glue else 0


if __name__ == "__main__":
    sys.exit(main())
