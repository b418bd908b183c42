#!/usr/bin/env python3
"""Check the built HTML book: a full-page screenshot of every page, no error output and no broken figure on any page.

Usage: python scripts/book_check.py [--html _build/html] [--out _build/screenshots] [--figures book/figures]
                                    [--no-screenshots]

Every page listed in _toc.yml must exist under the HTML folder. Each page is scanned for signs of a failed
notebook or a broken build (traceback or stderr output cells, docutils system messages, unresolved references,
unresolved placeholders and raw reprs as scripts/book_text_check.py finds them), for
paths of the machine that built it (a printed ``PosixPath``, the repository's folder, a temporary file), and
for broken figures: an image whose file is missing or cannot be read, or a blank one (every pixel the same, up to a
standard deviation of BLANK_STD grey levels). Each page is then captured whole, from top to bottom, by headless
Chromium driven over the DevTools protocol, into the screenshot folder. The viewport is set to the page's
full height and captured as it is laid out (Chromium's capture "beyond the viewport" re-renders the page and has
shifted its content sideways, hiding the sidebar); a capture whose page title is not drawn where the laid-out page
places it (:func:`title_problem`) fails the check.

Every figure a chapter saves must be on its page. A chapter saves a figure under a label ``fig:...`` (a string
constant passed to ``rfmap.viz.save_figure`` or to a plotting helper that saves under it), which names the file
``book/figures/fig-....png``. The chapter's source is read without running it (:func:`figure_source_problems`):
the cell that saves the figure saves only that one, shows it (``plt.show()``) and displays nothing else, and carries
the cell metadata ``mystnb.figure`` with the file's name as ``name`` and a caption that opens with "Reproduces
Fig. n of the paper" (n: the number of the paper's figure with that label) or with "Beyond the paper". In the built
page (:func:`page_figure_problems`) the figure must then be there: a ``<figure>`` with that id, an image and that
caption. A figure saved only under a condition that did not hold in the build (its file is absent) is not asked for.

The exit status is 1 when a page is missing, shows an error or a broken figure, lacks a figure its chapter saves, or
cannot be captured.
"""
from __future__ import annotations

import argparse
import ast
import asyncio
import base64
import contextlib
import io
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import NamedTuple
from urllib.parse import unquote, urlparse

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
from book_text_check import placeholder_problems, repr_problems  # noqa: E402  (a sibling script)
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


def machine_path_markers(root: Path = ROOT) -> list[tuple[re.Pattern, str]]:
    """(pattern, what it means) of a path of the machine that built the book: a printed ``pathlib`` path, the
    repository's folder, the home folder, or a temporary file. A page shows paths relative to the project."""
    home, repo = os.path.expanduser("~"), re.escape(str(root.resolve())) + r"\b"
    # a checkout cloned into a temporary folder: its own paths count once, as the repository's
    markers = [(re.compile(r"\b(?:Posix|Windows)Path\("), "a printed pathlib path"),
               (re.compile(repo), "the repository's folder on this machine"),
               (re.compile(f"(?!{repo})" + re.escape(tempfile.gettempdir()) + r"/tmp[\w.-]{6,}"),
                "a temporary file's path")]
    if len(home) > 1 and not str(root.resolve()).startswith(home):
        markers.append((re.compile(re.escape(home) + "/"), "the home folder of this machine"))
    return markers


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


#: JavaScript: the box (CSS pixels, from the top left of the page) of the text of the page's title, its first shown
#: ``<h1>``, or null
TITLE_BOX = """(() => {
  const h = [...document.querySelectorAll('h1')].find(e => e.getBoundingClientRect().width > 0);
  if (!h) return null;
  const range = document.createRange();
  range.selectNodeContents(h.firstChild || h);
  const b = range.getBoundingClientRect();
  return {left: b.left + window.scrollX, top: b.top + window.scrollY, width: b.width, height: b.height};
})()"""
#: a grey level below this is ink (the title's text)
INK = 128


def title_problem(png: bytes, box: dict | None) -> str | None:
    """Why a page's screenshot ``png`` does not show the page as laid out, or None: the title's text, whose box
    (:data:`TITLE_BOX`) the browser reports, must start at that box's left edge, with ink just inside it and none in
    the strip just left of it. A capture shifted sideways (no sidebar, text cut at the left edge) draws the title's
    letters across that strip, or elsewhere altogether."""
    if not box or box["width"] < 8 or box["height"] < 8:
        return None
    import numpy as np
    from PIL import Image

    with Image.open(io.BytesIO(png)) as im:
        grey = np.asarray(im.convert("L"), dtype=np.float64)
    top, bottom = int(box["top"]), int(math.ceil(box["top"] + box["height"]))
    left = int(round(box["left"]))
    if bottom > grey.shape[0] or left + 8 > grey.shape[1]:
        return "the screenshot does not reach the page's title"
    rows = grey[top:bottom]
    inside = rows[:, left:left + min(40, int(box["width"]))]
    outside = rows[:, max(0, left - 28):max(0, left - 4)]
    if not (inside < INK).any() or (outside.size and (outside < INK).any()):
        return (f"the title is not drawn where the page places it (x = {left} px): the capture is shifted "
                "sideways or cut")
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
    problems += placeholder_problems(body) + repr_problems(body)  # scripts/book_text_check.py
    for pat, why in machine_path_markers():
        m = pat.search(body)
        if m:
            problems.append(f"{why}: {body[m.start():m.end() + 40]!r}")
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


# ----------------------------------------------------------------------------------------------- saved figures
#: a figure label, as the chapters pass it to rfmap.viz.save_figure (or to a helper that saves under it)
FIG_LABEL = re.compile(r"fig:[A-Za-z0-9_-]+")
#: how a caption names the figure's counterpart in the paper
PAPER_CAPTION = "Reproduces Fig. {n} of the paper"
BEYOND_CAPTION = "Beyond the paper"


def figure_stem(label: str) -> str:
    """The file name (without ``.png``) that :func:`rfmap.viz.save_figure` gives the figure ``label``."""
    return label.replace(":", "-").replace("_", "-")


def paper_figure_numbers(root: Path = ROOT) -> dict[str, int]:
    """The number of every figure of the paper by its label: the figures of ``src/rfmap/data/figures.json``, which
    lists the paper's items in the order of the paper, counted from 1."""
    items = json.loads((root / "src" / "rfmap" / "data" / "figures.json").read_text(encoding="utf-8"))["items"]
    labels = [it["label"] for it in items if it["label"].startswith("fig:")]
    return {label: k for k, label in enumerate(labels, start=1)}


def expected_caption(label: str, numbers: dict[str, int]) -> str:
    """How the caption of the figure ``label`` must open."""
    return PAPER_CAPTION.format(n=numbers[label]) if label in numbers else BEYOND_CAPTION


class SavedFigure(NamedTuple):
    """A figure that a chapter saves: its label, the cell that saves it (index and id), and whether the saving
    statement runs only under a condition (inside ``if``, a loop, ``try`` or a function)."""

    label: str
    cell: int
    cell_id: str
    conditional: bool

    @property
    def stem(self) -> str:
        return figure_stem(self.label)


def _call_name(node: ast.Call) -> str:
    f = node.func
    return f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""


def _scan_cell(source: str) -> tuple[list[tuple[str, bool]], list[str], ast.Module | None]:
    """The figure labels a code cell saves under (with whether each save is conditional), what cannot be checked
    in it, and its syntax tree (None when it does not parse)."""
    try:
        tree = ast.parse(source)
    except SyntaxError as e:
        return [], [f"does not parse ({e.msg}, line {e.lineno}), so its figures cannot be checked"], None
    labels: list[tuple[str, bool]] = []
    problems: list[str] = []

    def visit(node: ast.AST, conditional: bool):
        if isinstance(node, ast.Call):
            if _call_name(node) == "savefig":
                problems.append("saves a figure with savefig: save it with rfmap.viz.save_figure under a fig: label")
            for arg in [*node.args, *(k.value for k in node.keywords)]:
                if isinstance(arg, ast.Constant) and isinstance(arg.value, str) and FIG_LABEL.fullmatch(arg.value):
                    labels.append((arg.value, conditional))
                elif (isinstance(arg, ast.JoinedStr) and arg.values and isinstance(arg.values[0], ast.Constant)
                      and str(arg.values[0].value).startswith("fig:")):
                    problems.append("saves a figure under a computed label: give the label as a string constant")
        inner = conditional or isinstance(node, (ast.If, ast.IfExp, ast.For, ast.AsyncFor, ast.While, ast.Try,
                                                 ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
        for child in ast.iter_child_nodes(node):
            visit(child, inner)

    visit(tree, False)
    return labels, problems, tree


def _cell_source(cell: dict) -> str:
    src = cell.get("source", "")
    return src if isinstance(src, str) else "".join(src)


def saved_figures(notebook: Path) -> list[SavedFigure]:
    """Every figure the chapter ``notebook`` saves, read from its source."""
    nb = json.loads(notebook.read_text(encoding="utf-8"))
    out = []
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] == "code":
            labels, _, _ = _scan_cell(_cell_source(cell))
            out += [SavedFigure(label, i, cell.get("id", ""), cond) for label, cond in labels]
    return out


def _shows_only_the_figure(tree: ast.Module) -> str | None:
    """Why a figure cell does not display its figure, and only its figure, or None."""
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)]
    if not any(_call_name(c) == "show" and isinstance(c.func, ast.Attribute) and isinstance(c.func.value, ast.Name)
               and c.func.value.id == "plt" for c in calls):
        return "does not show its figure with plt.show()"
    if any(_call_name(c) == "display" for c in calls):
        return "displays more than its figure (display(...)): move the other output to a cell of its own"
    last = tree.body[-1] if tree.body else None
    if isinstance(last, ast.Expr) and not (isinstance(last.value, ast.Call)
                                           and _call_name(last.value) in ("show", "print", "glue")):
        return "ends in an expression whose value is displayed beside the figure"
    return None


def figure_source_problems(notebook: Path, numbers: dict[str, int] | None = None) -> list[str]:
    """What keeps a figure saved by the chapter ``notebook`` from being shown on its page with its caption, read
    from the source (see the module docstring); an empty list when nothing does."""
    numbers = paper_figure_numbers() if numbers is None else numbers
    nb = json.loads(notebook.read_text(encoding="utf-8"))
    problems = []
    seen: dict[str, int] = {}
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] != "code":
            continue
        where = f"{notebook.name}: cell {i} ({cell.get('id', 'no id')})"
        labels, cell_problems, tree = _scan_cell(_cell_source(cell))
        problems += [f"{where} {p}" for p in cell_problems]
        if not labels:
            if (cell.get("metadata", {}).get("mystnb") or {}).get("figure"):
                problems.append(f"{where} has figure metadata but saves no figure")
            continue
        if len(labels) > 1:
            problems.append(f"{where} saves {len(labels)} figures ({', '.join(lab for lab, _ in labels)}): one "
                            "figure per cell, so that each is shown with its own caption")
            continue
        label = labels[0][0]
        stem = figure_stem(label)
        if stem in seen:
            problems.append(f"{where} saves {stem}.png, which cell {seen[stem]} saves too")
        seen[stem] = i
        why = _shows_only_the_figure(tree)
        if why:
            problems.append(f"{where} saves {stem}.png but {why}")
        fig_meta = (cell.get("metadata", {}).get("mystnb") or {}).get("figure") or {}
        if fig_meta.get("name") != stem:
            problems.append(f"{where} saves {stem}.png: its metadata mystnb.figure.name must be {stem!r} "
                            f"(found {fig_meta.get('name')!r})")
        want = expected_caption(label, numbers)
        caption = str(fig_meta.get("caption", ""))
        if not caption.startswith(want):
            problems.append(f"{where} saves {stem}.png: its caption (metadata mystnb.figure.caption) must open with "
                            f"{want!r} (found {caption[:60]!r})")
    return problems


def page_figure_problems(page: Path, saved: list[SavedFigure], numbers: dict[str, int],
                         figures: Path | None = None) -> list[str]:
    """Figures of ``saved`` (those of the page's chapter) that the built ``page`` lacks, or shows without an image
    or without their caption. A figure saved under a condition whose file is absent from ``figures`` was not saved
    in this build and is not asked for."""
    text = page.read_text(encoding="utf-8", errors="replace")
    problems = []
    for fig in saved:
        m = re.search(rf'<figure\b[^>]*\bid="{re.escape(fig.stem)}"[^>]*>(.*?)</figure>', text, re.DOTALL)
        if m is None:
            if fig.conditional and figures is not None and not (figures / f"{fig.stem}.png").exists():
                continue
            problems.append(f"figure {fig.stem}.png, saved by cell {fig.cell} ({fig.cell_id}), is not on the page")
            continue
        inner = m.group(1)
        if not IMG_SRC.search(inner):
            problems.append(f"figure {fig.stem} is on the page without an image")
        cap = re.search(r"<figcaption\b.*?</figcaption>", inner, re.DOTALL)
        caption = " ".join(re.sub(r"<[^>]+>", " ", cap.group(0)).split()) if cap else ""
        want = expected_caption(fig.label, numbers)
        if want not in caption:
            problems.append(f"figure {fig.stem} is on the page without a caption saying {want!r}")
    return problems


def unclaimed_figures(figures: Path, notebooks: list[Path]) -> list[Path]:
    """PNG files in ``figures`` that no chapter saves (left over from an earlier build, for instance)."""
    stems = {f.stem for nb in notebooks for f in saved_figures(nb)}
    return sorted(p for p in figures.glob("*.png") if p.stem not in stems) if figures.is_dir() else []


def find_chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


class ChromiumError(RuntimeError):
    """Chromium did not start."""


@contextlib.contextmanager
def chromium(browser: str, startup: float = 60.0):
    """Run headless Chromium with a fresh profile and remote debugging; yields its DevTools port, and stops the
    browser and removes the profile on leaving the block (on error too). Raises ChromiumError when it does not
    start within ``startup`` seconds."""
    profile = tempfile.mkdtemp(prefix="rfmap-chromium-")
    proc = subprocess.Popen([browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--remote-debugging-port=0",
                             "about:blank"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        port_file = Path(profile) / "DevToolsActivePort"
        deadline = time.monotonic() + startup
        while not (port_file.exists() and port_file.read_text().strip()):
            if proc.poll() is not None or time.monotonic() > deadline:
                raise ChromiumError(f"chromium did not start (exit {proc.poll()}): "
                                    f"{(proc.stderr.read() if proc.poll() is not None else '').strip()[-500:]}")
            time.sleep(0.1)
        yield int(port_file.read_text().split()[0])
    finally:
        stop_group(proc)
        for _ in range(20):  # a helper process may still write into the profile as it exits
            shutil.rmtree(profile, ignore_errors=True)
            if not os.path.exists(profile):
                break
            time.sleep(0.1)


def stop_group(proc: subprocess.Popen):
    """Stop a process started in a session of its own, with every process it started (Chromium's helpers)."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, sig)
        try:
            proc.wait(timeout=10)
            break
        except subprocess.TimeoutExpired:
            continue


class DevTools:
    """The first page of the browser listening on ``port``, driven over the DevTools protocol (JSON commands and
    events on a websocket); every wait gives up after ``timeout`` seconds."""

    def __init__(self, conn, timeout: float):
        self.conn, self.timeout = conn, timeout
        self._ids = iter(range(1, 1 << 30))

    @classmethod
    async def open(cls, port: int, timeout: float) -> "DevTools":
        from tornado.websocket import websocket_connect

        targets = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10).read())
        ws_url = next(t["webSocketDebuggerUrl"] for t in targets if t.get("type") == "page")
        return cls(await websocket_connect(ws_url, max_message_size=1 << 30), timeout)

    async def wait_for(self, pred) -> dict:
        """The next message for which ``pred(message)`` is true."""
        while True:
            raw = await asyncio.wait_for(self.conn.read_message(), self.timeout)
            if raw is None:
                raise RuntimeError("the browser closed the connection")
            msg = json.loads(raw)
            if pred(msg):
                return msg

    async def call(self, method: str, **params) -> dict:
        """Send the command ``method`` and return its result."""
        i = next(self._ids)
        self.conn.write_message(json.dumps({"id": i, "method": method, "params": params}))
        msg = await self.wait_for(lambda m: m.get("id") == i)
        if "error" in msg:
            raise RuntimeError(f"{method}: {msg['error']}")
        return msg["result"]

    async def evaluate(self, expression: str):
        """The value of a JavaScript expression in the page (a promise is awaited)."""
        result = await self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"JavaScript error: {result['exceptionDetails'].get('text', '')}")
        return result["result"].get("value")

    def close(self):
        self.conn.close()


def _metrics(height: int) -> dict:
    return {"width": WIDTH, "height": height, "deviceScaleFactor": 1, "mobile": False}


async def _capture(port: int, url: str, timeout: float) -> list[bytes]:
    """Load ``url`` in the browser listening on ``port`` and capture the whole page (DevTools protocol), as PNG
    tiles from top to bottom, with the box of the page's title (:data:`TITLE_BOX`)."""
    page = await DevTools.open(port, timeout)
    try:
        await page.call("Page.enable")
        await page.call("Emulation.setDeviceMetricsOverride", **_metrics(900))
        await page.call("Page.navigate", url=url)
        await page.wait_for(lambda m: m.get("method") == "Page.loadEventFired")
        # images decoded and fonts (MathJax's included) loaded before the page is measured
        await page.evaluate(
            "Promise.all([document.fonts.ready, ...Array.from(document.images, i => i.decode().catch(() => 0))])"
            ".then(() => new Promise(r => setTimeout(r, 500)))")
        size = (await page.call("Page.getLayoutMetrics"))["cssContentSize"]
        height = max(1, math.ceil(size["height"]))
        # the viewport covers the whole page, so the capture needs nothing beyond it: captureBeyondViewport makes
        # Chromium lay the page out again for the capture, which has drawn it shifted sideways
        await page.call("Emulation.setDeviceMetricsOverride", **_metrics(height))
        await page.evaluate("window.scrollTo(0, 0); new Promise(r => requestAnimationFrame(() => setTimeout(r, 200)))")
        box = await page.evaluate(TITLE_BOX)
        tiles = []
        for top in range(0, height, MAX_HEIGHT):
            shot = await page.call("Page.captureScreenshot", format="png", captureBeyondViewport=False,
                                   clip={"x": 0, "y": top, "width": WIDTH, "height": min(MAX_HEIGHT, height - top),
                                         "scale": 1})
            tiles.append(base64.b64decode(shot["data"]))
        return tiles, box
    finally:
        page.close()


def screenshot(browser: str, page: Path, out: Path, timeout: float = 120.0) -> str | None:
    """Capture the whole of ``page`` (its full height, not one window) into ``out``; returns an error message or
    None."""
    try:
        with chromium(browser) as port:
            tiles, box = asyncio.run(asyncio.wait_for(_capture(port, page.resolve().as_uri(), timeout), timeout))
    except ChromiumError as e:
        return str(e)
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
    if why:
        return f"the page renders {why}"
    return title_problem(tiles[0], box) if box and box["top"] + box["height"] <= MAX_HEIGHT else None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--html", type=Path, default=ROOT / "_build" / "html")
    parser.add_argument("--out", type=Path, default=ROOT / "_build" / "screenshots")
    parser.add_argument("--figures", type=Path,
                        default=Path(os.environ.get("RFMAP_FIGURES") or ROOT / "book" / "figures"),
                        help="where the chapters saved their figures (default: $RFMAP_FIGURES, else book/figures)")
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
    numbers = paper_figure_numbers()
    notebooks = []
    for doc in toc_pages():
        page = args.html / f"{doc}.html"
        source = ROOT / f"{doc}.ipynb"
        saved = []
        problems = []
        if source.exists():
            notebooks.append(source)
            saved = saved_figures(source)
            problems += figure_source_problems(source, numbers)
        if not page.exists():
            print(f"FAIL {doc}: page {page} was not built")
            failures += 1
            continue
        problems += scan_html(page)
        problems += page_figure_problems(page, saved, numbers, args.figures)
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
    for p in unclaimed_figures(args.figures, notebooks):
        print(f"note {os.path.relpath(p, ROOT)}: saved by no chapter (left from an earlier build?)")
    print(f"{failures} page(s) with problems" if failures else "all pages ok")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
