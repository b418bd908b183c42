#!/usr/bin/env python3
"""Check the built HTML book: a screenshot of every page, and no error output on any page.

Usage: python scripts/book_check.py [--html _build/html] [--out _build/screenshots] [--no-screenshots]

Every page listed in _toc.yml must exist under the HTML folder. Each page is scanned for signs of a failed
notebook or a broken build (traceback or stderr output cells, docutils system messages, unresolved references,
images whose file is missing) and captured with headless Chromium into the screenshot folder. The exit status is 1
when a page is missing, shows an error or cannot be captured.
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from urllib.parse import unquote, urlparse

ROOT = Path(__file__).resolve().parent.parent
CHROMIUM_FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--hide-scrollbars",
    "--window-size=1280,2400",
]
# (pattern, what it means) -- searched in the raw HTML of every page
ERROR_MARKERS = [
    (re.compile(r'class="[^"]*\boutput\s+traceback\b'), "a cell printed a traceback"),
    (re.compile(r'class="[^"]*\boutput\s+stderr\b'), "a cell wrote to stderr"),
    (re.compile(r'class="[^"]*\bsystem-message\b'), "a docutils error or warning is shown on the page"),
    (re.compile(r'class="[^"]*\bproblematic\b'), "an unresolved reference or role"),
    (re.compile(r"Traceback \(most recent call last\)"), "a Python traceback"),
]
IMG_SRC = re.compile(r'<img\b[^>]*\bsrc="([^"]+)"', re.IGNORECASE)


def toc_pages(root: Path = ROOT) -> list[str]:
    """Document paths (no suffix) of _toc.yml, in reading order."""
    import yaml

    pages: list[str] = []

    def walk(node):
        if isinstance(node, dict):
            for key in ("root", "file"):
                if isinstance(node.get(key), str):
                    pages.append(str(Path(node[key]).with_suffix("")))
            for key in ("parts", "chapters", "sections"):
                if key in node:
                    walk(node[key])
        elif isinstance(node, list):
            for value in node:
                walk(value)

    walk(yaml.safe_load((root / "_toc.yml").read_text(encoding="utf-8")))
    return pages


def scan_html(page: Path) -> list[str]:
    """Problems found in one HTML page."""
    text = page.read_text(encoding="utf-8", errors="replace")
    # only the article body: the theme's scripts and the search index are not content
    body = text
    m = re.search(r'<article\b.*?</article>', text, re.DOTALL)
    if m:
        body = m.group(0)
    problems = [f"{why} ({pat.pattern})" for pat, why in ERROR_MARKERS if pat.search(body)]
    for src in IMG_SRC.findall(body):
        parsed = urlparse(src)
        if parsed.scheme in ("http", "https", "data"):
            continue
        target = (page.parent / unquote(parsed.path)).resolve()
        if not target.exists():
            problems.append(f"missing image {src}")
    return problems


def find_chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def screenshot(browser: str, page: Path, out: Path, timeout: float = 120.0) -> str | None:
    """Capture ``page`` into ``out``; returns an error message or None."""
    profile = tempfile.mkdtemp(prefix="rfmap-chromium-")
    try:
        cmd = [browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--screenshot={out}",
               page.resolve().as_uri()]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return f"chromium timed out after {timeout:.0f} s"
        if not out.exists() or out.stat().st_size < 1000 or out.read_bytes()[:8] != b"\x89PNG\r\n\x1a\n":
            return f"no screenshot written (chromium exit {proc.returncode}): {proc.stderr.strip()[-500:]}"
        return None
    finally:
        shutil.rmtree(profile, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--html", type=Path, default=ROOT / "_build" / "html")
    parser.add_argument("--out", type=Path, default=ROOT / "_build" / "screenshots")
    parser.add_argument("--no-screenshots", action="store_true", help="only scan the HTML")
    args = parser.parse_args(argv)

    if not (args.html / "index.html").exists():
        print(f"no built book in {args.html}: run `make book` first", file=sys.stderr)
        return 1
    browser = None
    if not args.no_screenshots:
        browser = find_chromium()
        if browser is None:
            print("chromium not found (Debian: apt-get install -y chromium)", file=sys.stderr)
            return 1
        args.out.mkdir(parents=True, exist_ok=True)

    failures = 0
    for doc in toc_pages():
        page = args.html / f"{doc}.html"
        if not page.exists():
            print(f"FAIL {doc}: page {page} was not built")
            failures += 1
            continue
        problems = scan_html(page)
        if browser is not None:
            shot = args.out / (doc.replace("/", "__") + ".png")
            err = screenshot(browser, page, shot)
            if err:
                problems.append(err)
            else:
                print(f"     {doc}: screenshot {os.path.relpath(shot, ROOT)}")
        for p in problems:
            print(f"FAIL {doc}: {p}")
        failures += bool(problems)
        if not problems:
            print(f"ok   {doc}")
    print(f"{failures} page(s) with problems" if failures else "all pages ok")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
