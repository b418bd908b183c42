#!/usr/bin/env python3
"""Open a chapter in JupyterLab, as `make lab` starts it, and check that it uses the project's kernel and renders MyST.

Usage: python scripts/lab_check.py [--notebook notebooks/06_dem_deq_2d.ipynb ...] [--all] [--out _build/screenshots]
                                   [--timeout 180] [--startup 300]

JupyterLab is started by ``make lab`` itself (the environment of the book, the default kernel ``rfmap``, the
repository as root folder), on a free port with a random token and without a browser, and with user settings and
workspaces of its own (a temporary folder), so that the check sees JupyterLab's defaults, leaves the user's layout
alone and never saves the chapter (autosave off). Headless Chromium, driven as in ``scripts/book_check.py``, opens
the chapter and waits until every cell is shown, the kernel is idle and the page stops changing. A screenshot of the
window goes to ``lab-<chapter>.png`` in the output folder, the notebook's HTML beside it, and :func:`page_problems`
checks that HTML:

* the kernel named in the notebook's toolbar is "Python (rfmap)" (the ``rfmap`` kernel, not ``python3``);
* every Markdown cell is rendered by jupyterlab-myst, and its prose (math and code left out) shows no raw MyST: no
  role (``{cite:p}``, ``{ref}``, ``{glue:text}``, ...), no ``:::`` fence, no ``(label)=`` target, no directive
  shown as code;
* every citation key of the source is shown as a citation, every cross-reference role as a reference.

The server must also name ``rfmap`` as its default kernel and run the chapter in it, and the chapter's file must be
unchanged afterwards. The exit status is 1 with one ``FAIL`` line per problem, else 0. JupyterLab and Chromium are
stopped at the end, on error too.

Three things JupyterLab cannot show are counted in ``note`` lines and not failed, since only the book build has
what they need: jupyterlab-myst (2.7) reads no ``.bib`` file, so a citation shows its key with a "Citation Not
Found" mark instead of author and year; it sees one notebook at a time, so a reference to a label of another chapter
(``{ref}`label```) shows the label with a "Cross Reference Not Found" mark; and a glue role (``{glue:text}`key```)
shows its key instead of its value, since the values exist only in an executed notebook (myst-nb pastes them in the
book). A chapter that JupyterLab marks modified as soon as it opens (it fills in ``metadata.language_info`` from
the kernel) is noted too: with autosave on, merely opening it rewrites the file.
"""
from __future__ import annotations

import argparse
import asyncio
import base64
import contextlib
import hashlib
import json
import os
import re
import secrets
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from urllib.parse import quote

sys.path.insert(0, str(Path(__file__).resolve().parent))
from book_check import ChromiumError, DevTools, chromium, find_chromium, image_problem, stop_group  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
KERNEL, KERNEL_DISPLAY = "rfmap", "Python (rfmap)"
#: size of the browser window (CSS pixels)
WIDTH, HEIGHT = 1400, 1000
#: a MyST role as it reads when left unparsed: ``{name}`` or ``{domain:name}`` (the target follows in code)
RAW_ROLE = re.compile(r"\{([a-z][\w-]*(?::[\w-]+)?)\}")
RAW_FENCE = re.compile(r"^\s*:::", re.M)
RAW_TARGET = re.compile(r"^\s*\([\w-]+\)=\s*$", re.M)
CITE_ROLE = re.compile(r"\{cite(?::\w+)?\}`([^`]*)`")
XREF_ROLE = re.compile(r"\{(?:ref|numref|doc|eq)\}`[^`]*`")
#: JupyterLab settings of the check: no autosave (the chapter is never written), no news or update pop-ups
LAB_SETTINGS = {
    "@jupyterlab/docmanager-extension/plugin.jupyterlab-settings": {"autosave": False},
    "@jupyterlab/apputils-extension/notification.jupyterlab-settings": {"fetchNews": "false",
                                                                        "checkForUpdates": False},
}


class LabError(RuntimeError):
    """JupyterLab did not start or the chapter did not open."""


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _api(base: str, token: str, path: str, method: str = "GET", timeout: float = 10.0):
    """The JSON answer of the Jupyter server's REST API at ``path``."""
    req = urllib.request.Request(f"{base}{path}", method=method, headers={"Authorization": f"token {token}"},
                                 data=b"" if method == "POST" else None)
    with urllib.request.urlopen(req, timeout=timeout) as r:
        body = r.read()
    return json.loads(body) if body.strip() else None


def lab_flags(port: int, token: str, home: Path) -> list[str]:
    """What the check adds to `make lab` (its ``LAB_FLAGS``): no browser, the port, the token, and settings and
    workspaces in ``home``."""
    return ["--no-browser", f"--ServerApp.port={port}", "--ServerApp.port_retries=0",
            f"--IdentityProvider.token={token}", f"--LabApp.user_settings_dir={home / 'settings'}",
            f"--LabApp.workspaces_dir={home / 'workspaces'}"]


def _stop(proc: subprocess.Popen, base: str, token: str):
    """Shut the server down through its API (it stops its kernels), else stop `make lab`'s process group."""
    with contextlib.suppress(OSError):
        _api(base, token, "/api/shutdown", method="POST")
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        stop_group(proc)


@contextlib.contextmanager
def jupyterlab(home: Path, startup: float):
    """Run `make lab` with :func:`lab_flags`; yields the server's address and token once it answers, and stops it on
    leaving the block (on error too). Its output goes to ``home/lab.log``."""
    for name, value in LAB_SETTINGS.items():
        path = home / "settings" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(value), encoding="utf-8")
    port, token = free_port(), secrets.token_hex(24)
    base = f"http://127.0.0.1:{port}"
    make = os.environ.get("MAKE", "make")
    log = (home / "lab.log").open("w", encoding="utf-8")
    command = [make, "--no-print-directory", "lab", "LAB_FLAGS=" + " ".join(lab_flags(port, token, home))]
    proc = subprocess.Popen(command, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + startup
        while True:
            try:
                _api(base, token, "/api/status", timeout=2)
                break
            except (OSError, ValueError):
                pass
            if proc.poll() is not None or time.monotonic() > deadline:
                tail = (home / "lab.log").read_text(encoding="utf-8", errors="replace").strip().splitlines()[-3:]
                why = f"exited with status {proc.returncode}" if proc.poll() is not None else \
                    f"did not answer within {startup:.0f} s"
                raise LabError(f"`make lab` {why}: {' | '.join(tail)}")
            time.sleep(0.5)
        yield base, token
    finally:
        _stop(proc, base, token)
        log.close()


# ------------------------------------------------------------------------------------------ checks of the page
#: rendered MyST that is not prose: math (KaTeX keeps its TeX source in the page) and code
NOT_PROSE = ".katex, .katex-display, .MathJax, mjx-container, math, code, pre"
#: how jupyterlab-myst marks a citation whose entry it cannot find (it reads no .bib file), and a reference whose
#: target it cannot find (it sees one notebook, not the labels of the others)
CITATION_NOT_FOUND, XREF_NOT_FOUND = "Citation Not Found", "Cross Reference Not Found"


def markdown_sources(notebook: Path) -> list[tuple[int, str]]:
    """(index, source) of every Markdown cell of ``notebook``."""
    cells = json.loads(notebook.read_text(encoding="utf-8"))["cells"]
    return [(i, c["source"] if isinstance(c["source"], str) else "".join(c["source"]))
            for i, c in enumerate(cells) if c["cell_type"] == "markdown"]


def _soup(html: str):
    from bs4 import BeautifulSoup

    return BeautifulSoup(html, "html.parser")


def prose_text(node) -> str:
    """The text of a rendered cell without its math and code (where MyST's own syntax may legitimately appear)."""
    node = _soup(str(node))
    for tag in node.select(NOT_PROSE):
        tag.decompose()
    return node.get_text("\n")  # a fence or a target is a line of its own


def _excerpt(text: str, start: int, end: int) -> str:
    return " ".join(text[max(0, start - 30):end + 30].split())


def cell_problems(rendered, source: str) -> list[str]:
    """What is wrong with one rendered Markdown cell (the ``.myst`` element jupyterlab-myst fills in) given its
    source: MyST left raw in the prose, fewer citations shown than the source cites, or fewer links than it has
    cross-reference roles."""
    problems = []
    text = prose_text(rendered)
    for m in RAW_ROLE.finditer(text):
        problems.append(f"raw MyST role {{{m.group(1)}}} in the rendered text: '{_excerpt(text, *m.span())}'")
    for pattern, what in ((RAW_FENCE, "raw ::: fence"), (RAW_TARGET, "raw (label)= target")):
        for m in pattern.finditer(text):
            problems.append(f"{what} in the rendered text: '{_excerpt(text, *m.span())}'")
    for code in rendered.select('code[class*="language-{"]'):
        problems.append(f"a directive shown as code ({' '.join(code.get('class', []))})")
    cited = sum(len([k for k in re.split(r"[,;]", keys) if k.strip()]) for keys in CITE_ROLE.findall(source))
    shown = len(rendered.select(f'cite, [title="{CITATION_NOT_FOUND}"]'))
    if shown < cited:
        problems.append(f"{cited} citation(s) in the source, {shown} rendered as citations")
    xrefs = len(XREF_ROLE.findall(source))
    links = len(rendered.select(f'a.hover-link, a.link, [title="{XREF_NOT_FOUND}"]'))
    if links < xrefs:
        problems.append(f"{xrefs} cross-reference(s) in the source, {links} rendered as references")
    return problems


def page_problems(html: str, sources: list[tuple[int, str]]) -> list[str]:
    """Problems of a chapter as JupyterLab shows it: ``html`` is the notebook panel's HTML, ``sources`` the
    chapter's Markdown cells (:func:`markdown_sources`). The toolbar must name the project's kernel, and every
    Markdown cell must be rendered by jupyterlab-myst without raw MyST (:func:`cell_problems`)."""
    soup = _soup(html)
    problems = []
    kernel = soup.select_one(".jp-Toolbar-kernelName")
    shown = kernel.get_text(strip=True) if kernel is not None else None
    if shown != KERNEL_DISPLAY:
        problems.append(f"the notebook's toolbar shows the kernel {shown!r}, not {KERNEL_DISPLAY!r}")
    cells = soup.select(".jp-MarkdownCell")
    if len(cells) != len(sources):
        problems.append(f"{len(cells)} Markdown cells shown, the chapter has {len(sources)}")
    for (i, source), cell in zip(sources, cells):
        rendered = cell.select_one(".jp-InputArea .myst")
        if rendered is None:
            problems.append(f"cell {i}: not rendered by jupyterlab-myst (no .myst element)")
            rendered = cell.select_one(".jp-RenderedMarkdown")
            if rendered is None:
                continue
        problems += [f"cell {i}: {p}" for p in cell_problems(rendered, source)]
    return problems


def page_notes(html: str, sources: list[tuple[int, str]]) -> list[str]:
    """What JupyterLab cannot show by design, counted: citations without their bibliography entry, references to
    labels of other chapters, and glue roles, whose values exist only in an executed notebook."""
    notes = []
    soup = _soup(html)
    missing = len(soup.select(f'[title="{CITATION_NOT_FOUND}"]'))
    if missing:
        notes.append(f"{missing} citation(s) shown by their key: jupyterlab-myst reads no .bib file")
    elsewhere = len(soup.select(f'[title="{XREF_NOT_FOUND}"]'))
    if elsewhere:
        notes.append(f"{elsewhere} reference(s) shown by their label: jupyterlab-myst sees no labels of other "
                     "chapters")
    glued = sum(len(re.findall(r"\{glue(?::\w+)?\}`", s)) for _, s in sources)
    if glued:
        notes.append(f"{glued} glue role(s) show their key, not their value: values exist only after a run")
    return notes


# ------------------------------------------------------------------------------------------ the browser
#: the state of the notebook page, as JSON: cells shown, Markdown cells rendered, the toolbar's kernel and status
STATE_JS = r"""JSON.stringify((() => {
  const panel = document.querySelector('.jp-NotebookPanel:not(.lm-mod-hidden)');
  const dialog = document.querySelector('.jp-Dialog');
  if (dialog) return {panel: !!panel, dialog: dialog.innerText.replace(/\s+/g, ' ').trim()};
  if (!panel) return {panel: false};
  const kernel = panel.querySelector('.jp-Toolbar-kernelName');
  const status = panel.querySelector('.jp-Notebook-ExecutionIndicator');
  return {panel: true, cells: panel.querySelectorAll('.jp-Cell').length,
          markdown: panel.querySelectorAll('.jp-MarkdownCell').length,
          rendered: panel.querySelectorAll(
            '.jp-MarkdownCell .jp-InputArea > .myst, .jp-MarkdownCell .jp-RenderedMarkdown').length,
          kernel: kernel ? kernel.textContent.trim() : '', status: status ? status.getAttribute('data-status') : '',
          size: panel.outerHTML.length, dirty: !!document.querySelector('.lm-TabBar-tab.lm-mod-current.jp-mod-dirty')};
})())"""
PANEL_JS = "document.querySelector('.jp-NotebookPanel:not(.lm-mod-hidden)').outerHTML"


def _ready(state: dict, cells: int, markdown: int) -> bool:
    """Whether the page of :data:`STATE_JS` shows all ``cells`` cells, all ``markdown`` rendered, and an idle
    kernel."""
    return (state.get("panel", False) and "dialog" not in state and state["cells"] == cells
            and state["rendered"] >= markdown and state["kernel"] not in ("", "No Kernel", "Kernel")
            and state["status"] == "idle")


async def open_chapter(page: DevTools, url: str, cells: int, markdown: int,
                       timeout: float) -> tuple[str, bytes, str, dict]:
    """Open ``url`` (a notebook in JupyterLab) and wait until its ``cells`` cells are shown, its ``markdown``
    Markdown cells rendered, its kernel idle and the panel unchanged for a second; returns the panel's HTML, a
    screenshot (PNG), why the wait ended early (empty when it did not: a dialog waiting for an answer, or the
    timeout) and the last state seen (:data:`STATE_JS`)."""
    await page.call("Page.navigate", url=url)
    deadline, state, sizes, late = time.monotonic() + timeout, {}, [], ""
    while True:
        await asyncio.sleep(0.5)
        with contextlib.suppress(RuntimeError):  # the page is still loading
            state = json.loads(await page.evaluate(STATE_JS))
        sizes = sizes[-2:] + [state["size"] if _ready(state, cells, markdown) else state.get("dialog")]
        if len(sizes) == 3 and sizes[0] is not None and len(set(sizes)) == 1:
            if "dialog" in state:  # it waits for an answer: a kernel to choose, an error to acknowledge
                late = f"JupyterLab shows a dialog instead of the chapter: '{state['dialog']}'"
            break
        if time.monotonic() > deadline:
            late = f"the chapter did not finish opening within {timeout:.0f} s (last state {state})"
            break
    html = (await page.evaluate(PANEL_JS)) if state.get("panel") else ""
    shot = base64.b64decode((await page.call("Page.captureScreenshot", format="png"))["data"])
    return html, shot, late, state


def session_problems(base: str, token: str, path: str) -> list[str]:
    """The server's side: the chapter at ``path`` (relative to the root folder) runs in a session of the ``rfmap``
    kernel."""
    sessions = [s for s in _api(base, token, "/api/sessions") if s.get("path") == path]
    if not sessions:
        return ["the server has no kernel session for the chapter"]
    return [f"the chapter runs in the kernel {s['kernel']['name']!r} on the server, not {KERNEL!r}"
            for s in sessions if s["kernel"]["name"] != KERNEL]


def _close_sessions(base: str, token: str, path: str):
    for s in _api(base, token, "/api/sessions"):
        if s.get("path") == path:
            _api(base, token, f"/api/sessions/{s['id']}", method="DELETE")


async def _check_chapter(page: DevTools, base: str, token: str, notebook: Path, out: Path,
                         timeout: float) -> tuple[list[str], list[str]]:
    """Open one chapter, save its screenshot (and the panel's HTML beside it) and check it; returns its problems
    and notes."""
    path = notebook.relative_to(ROOT).as_posix()
    cells = len(json.loads(notebook.read_text(encoding="utf-8"))["cells"])
    sources = markdown_sources(notebook)
    url = f"{base}/lab/workspaces/lab-check/tree/{quote(path)}?reset&token={token}"
    before = _digest(notebook)
    html, shot, late, state = await open_chapter(page, url, cells, len(sources), timeout)
    png = out / f"lab-{notebook.stem}.png"
    png.write_bytes(shot)
    png.with_suffix(".html").write_text(html, encoding="utf-8")
    problems = [late] if late else []
    why = image_problem(shot, png.name)
    if why:
        problems.append(f"the screenshot is a {why}")
    problems += page_problems(html, sources) if html else ["JupyterLab showed no notebook"]
    problems += session_problems(base, token, path)
    _close_sessions(base, token, path)
    if _digest(notebook) != before:
        problems.append("the chapter's file changed while JupyterLab had it open")
    notes = page_notes(html, sources)
    if state.get("dirty"):  # JupyterLab fills in metadata.language_info from the kernel; the check never saves
        notes.append("JupyterLab marks the chapter modified on opening: with autosave on it rewrites the file")
    return problems, notes


async def _check_chapters(port: int, base: str, token: str, notebooks: list[Path], out: Path,
                          timeout: float) -> dict[Path, tuple[list[str], list[str]]]:
    page = await DevTools.open(port, timeout)
    try:
        await page.call("Page.enable")
        await page.call("Emulation.setDeviceMetricsOverride", width=WIDTH, height=HEIGHT, deviceScaleFactor=1,
                        mobile=False)
        return {nb: await _check_chapter(page, base, token, nb, out, timeout) for nb in notebooks}
    finally:
        page.close()


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def run_checks(notebooks: list[Path], out: Path, timeout: float, startup: float) -> dict[str, list[str]]:
    """Start JupyterLab and Chromium, check every chapter of ``notebooks`` and stop both; returns the problems
    (and, under keys ``note <name>``, the notes) by chapter name, and under ``lab`` those of the set-up."""
    browser = find_chromium()
    if browser is None:
        return {"lab": ["chromium not found (Debian: apt-get install -y chromium)"]}
    results: dict[str, list[str]] = {"lab": []}
    total = timeout * len(notebooks) + 60
    try:
        with tempfile.TemporaryDirectory(prefix="rfmap-lab-") as home, \
                jupyterlab(Path(home), startup) as (base, token), chromium(browser) as port:
            default = _api(base, token, "/api/kernelspecs").get("default")
            if default != KERNEL:
                results["lab"].append(f"the server's default kernel is {default!r}, not {KERNEL!r}")
            checked = asyncio.run(asyncio.wait_for(_check_chapters(port, base, token, notebooks, out, timeout), total))
    except (LabError, ChromiumError) as e:
        return {"lab": [str(e)]}
    except (asyncio.TimeoutError, TimeoutError):
        return {"lab": [f"the browser did not finish within {total:.0f} s"]}
    except (OSError, RuntimeError, KeyError, StopIteration, ValueError) as e:
        return {"lab": [f"{type(e).__name__}: {e}"]}
    for nb, (problems, notes) in checked.items():
        results[nb.stem], results[f"note {nb.stem}"] = problems, notes
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--notebook", type=Path, action="append",
                        help="a chapter to open (repeatable; default notebooks/06_dem_deq_2d.ipynb)")
    parser.add_argument("--all", action="store_true", help="open every chapter of notebooks/")
    parser.add_argument("--out", type=Path, default=ROOT / "_build" / "screenshots")
    parser.add_argument("--timeout", type=float, default=180.0, help="seconds a chapter may take to open")
    parser.add_argument("--startup", type=float, default=300.0, help="seconds `make lab` may take to answer")
    args = parser.parse_args(argv)

    notebooks = sorted((ROOT / "notebooks").glob("*.ipynb")) if args.all else \
        [p.resolve() for p in args.notebook or [ROOT / "notebooks" / "06_dem_deq_2d.ipynb"]]
    for nb in notebooks:
        if not nb.is_file() or not nb.is_relative_to(ROOT):
            print(f"FAIL {nb}: not a notebook of this repository", file=sys.stderr)
            return 1
    args.out.mkdir(parents=True, exist_ok=True)
    results = run_checks(notebooks, args.out, args.timeout, args.startup)
    failures = 0
    for name, problems in results.items():
        if name.startswith("note "):
            for note in problems:
                print(f"note {name[5:]}: {note}")
            continue
        for p in problems:
            print(f"FAIL {name}: {p}")
        failures += bool(problems)
        if not problems and name != "lab":
            shot = args.out / f"lab-{name}.png"
            print(f"ok   {name}: {KERNEL_DISPLAY}, MyST rendered; screenshot {os.path.relpath(shot, ROOT)}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
