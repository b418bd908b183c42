#!/usr/bin/env python3
"""Check the built HTML book: a full-page screenshot of every page, no error output and no broken figure on any page.

Usage: python scripts/book_check.py [--html _build/html] [--out _build/screenshots] [--no-screenshots]

Every page listed in _toc.yml must exist under the HTML folder. Each page is scanned for signs of a failed
notebook or a broken build (traceback or stderr output cells, docutils system messages, unresolved references) and
for broken figures: an image whose file is missing or cannot be read, or a blank one (every pixel the same, up to a
standard deviation of BLANK_STD grey levels). Each page is then captured whole, from top to bottom, by headless
Chromium driven over the DevTools protocol, into the screenshot folder. The exit status is 1 when a page is missing,
shows an error or a broken figure, or cannot be captured.
"""
from __future__ import annotations

import argparse
import asyncio
import base64
import io
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from urllib.parse import unquote, urlparse

ROOT = Path(__file__).resolve().parent.parent
CHROMIUM_FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--hide-scrollbars",
]
#: width of the screenshots (CSS pixels); they cover the whole page, in tiles of at most MAX_HEIGHT pixels
#: (``page.png``, ``page-2.png``, ...)
WIDTH = 1280
MAX_HEIGHT = 16000
#: an image whose grey levels (0-255) have a smaller standard deviation than this is blank
BLANK_STD = 1.0
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


def image_problem(data: bytes, name: str) -> str | None:
    """Why the image ``data`` (PNG, JPEG, GIF, ...; SVG is not rasterised) is not a figure, or None."""
    if name.lower().endswith(".svg") or data.lstrip()[:5] in (b"<svg ", b"<?xml"):
        return None if data.strip() else f"empty image {name}"
    import numpy as np
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as im:
            grey = np.asarray(im.convert("L"), dtype=np.float64)
    except (UnidentifiedImageError, OSError) as e:
        return f"unreadable image {name} ({e})"
    if grey.size == 0 or float(grey.std()) < BLANK_STD:
        return f"blank image {name} ({grey.shape[1]}x{grey.shape[0]} pixels, one grey level)"
    return None


def _image_bytes(page: Path, src: str) -> tuple[bytes | None, str]:
    """The bytes of an ``<img src>`` (a file next to the page or a base64 ``data:`` URI) and a name for it."""
    if src.startswith("data:"):
        head, _, payload = src.partition(",")
        return (base64.b64decode(payload) if ";base64" in head else unquote(payload).encode()), head
    target = (page.parent / unquote(urlparse(src).path)).resolve()
    return (target.read_bytes() if target.is_file() else None), src


def scan_html(page: Path) -> list[str]:
    """Problems found in one HTML page: error output, and missing, unreadable or blank images."""
    text = page.read_text(encoding="utf-8", errors="replace")
    # only the article body: the theme's scripts and the search index are not content
    body = text
    m = re.search(r'<article\b.*?</article>', text, re.DOTALL)
    if m:
        body = m.group(0)
    problems = [f"{why} ({pat.pattern})" for pat, why in ERROR_MARKERS if pat.search(body)]
    for src in IMG_SRC.findall(body):
        if urlparse(src).scheme in ("http", "https"):
            continue
        data, name = _image_bytes(page, src)
        if data is None:
            problems.append(f"missing image {src}")
            continue
        why = image_problem(data, name)
        if why:
            problems.append(why)
    return problems


def find_chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


async def _capture(port: int, url: str, timeout: float) -> list[bytes]:
    """Load ``url`` in the browser listening on ``port`` and capture the whole page (DevTools protocol), as PNG
    tiles from top to bottom."""
    from tornado.websocket import websocket_connect

    targets = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10).read())
    ws_url = next(t["webSocketDebuggerUrl"] for t in targets if t.get("type") == "page")
    conn = await websocket_connect(ws_url, max_message_size=1 << 30)
    ids = iter(range(1, 1 << 30))

    async def wait_for(pred):
        while True:
            raw = await asyncio.wait_for(conn.read_message(), timeout)
            if raw is None:
                raise RuntimeError("the browser closed the connection")
            msg = json.loads(raw)
            if pred(msg):
                return msg

    async def call(method: str, **params):
        i = next(ids)
        conn.write_message(json.dumps({"id": i, "method": method, "params": params}))
        msg = await wait_for(lambda m: m.get("id") == i)
        if "error" in msg:
            raise RuntimeError(f"{method}: {msg['error']}")
        return msg["result"]

    def metrics(height: int) -> dict:
        return {"width": WIDTH, "height": height, "deviceScaleFactor": 1, "mobile": False}

    try:
        await call("Page.enable")
        await call("Emulation.setDeviceMetricsOverride", **metrics(900))
        await call("Page.navigate", url=url)
        await wait_for(lambda m: m.get("method") == "Page.loadEventFired")
        # images decoded and fonts (MathJax's included) loaded before the page is measured
        await call("Runtime.evaluate", awaitPromise=True, expression=(
            "Promise.all([document.fonts.ready, ...Array.from(document.images, i => i.decode().catch(() => 0))])"
            ".then(() => new Promise(r => setTimeout(r, 500)))"))
        size = (await call("Page.getLayoutMetrics"))["cssContentSize"]
        height = max(1, math.ceil(size["height"]))
        await call("Emulation.setDeviceMetricsOverride", **metrics(height))
        tiles = []
        for top in range(0, height, MAX_HEIGHT):
            shot = await call("Page.captureScreenshot", format="png", captureBeyondViewport=True,
                              clip={"x": 0, "y": top, "width": WIDTH, "height": min(MAX_HEIGHT, height - top),
                                    "scale": 1})
            tiles.append(base64.b64decode(shot["data"]))
        return tiles
    finally:
        conn.close()


def screenshot(browser: str, page: Path, out: Path, timeout: float = 120.0) -> str | None:
    """Capture the whole of ``page`` (its full height, not one window) into ``out``; returns an error message or
    None."""
    profile = tempfile.mkdtemp(prefix="rfmap-chromium-")
    proc = subprocess.Popen([browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--remote-debugging-port=0",
                             "about:blank"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        port_file = Path(profile) / "DevToolsActivePort"
        deadline = time.monotonic() + 60
        while not (port_file.exists() and port_file.read_text().strip()):
            if proc.poll() is not None or time.monotonic() > deadline:
                return f"chromium did not start (exit {proc.poll()}): {(proc.stderr.read() or '').strip()[-500:]}"
            time.sleep(0.1)
        port = int(port_file.read_text().split()[0])
        try:
            tiles = asyncio.run(asyncio.wait_for(_capture(port, page.resolve().as_uri(), timeout), timeout))
        except (asyncio.TimeoutError, TimeoutError):
            return f"chromium timed out after {timeout:.0f} s"
        except (OSError, RuntimeError, StopIteration, KeyError) as e:
            return f"screenshot failed: {type(e).__name__}: {e}"
        for old in out.parent.glob(f"{out.stem}-*.png"):  # tiles of an earlier, longer capture
            old.unlink()
        for k, png in enumerate(tiles):
            if png[:8] != b"\x89PNG\r\n\x1a\n":
                return "no PNG screenshot returned"
            (out if k == 0 else out.with_name(f"{out.stem}-{k + 1}.png")).write_bytes(png)
        why = image_problem(tiles[0], out.name)
        return f"the page renders {why}" if why else None
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
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
                extra = len(list(shot.parent.glob(f"{shot.stem}-*.png")))
                print(f"     {doc}: screenshot {os.path.relpath(shot, ROOT)}" + (f" (+{extra} tiles)" if extra else ""))
        for p in problems:
            print(f"FAIL {doc}: {p}")
        failures += bool(problems)
        if not problems:
            print(f"ok   {doc}")
    print(f"{failures} page(s) with problems" if failures else "all pages ok")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
