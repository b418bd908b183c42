"""How the API reference reads the comments of constants and the attribute lists of classes (a Sphinx extension).

A constant is documented by a ``#:`` comment, and ``sphinx.ext.napoleon`` reads the first line of such a docstring as
``type: description``: a comment whose first line holds a colon ("cells per side: the raster's ...") comes out cut at
that colon, its start shown as the constant's type (a property's docstring too).  The constants' comments are prose,
never types, so this extension puts an invisible first line (a zero-width space) before napoleon reads them, which
leaves the text whole, and takes that line out again once napoleon is done, so that the page does not carry it.

A constant whose comment hides its value (``:meta hide-value:``, for a long text or table that reads badly as a quoted
value) is shown with its value as text instead: a string as a paragraph, its ``*emphasis*`` kept, a dict as a list.

An ``Attributes`` section may name several attributes in one entry (``regions, mapped : ndarray``), as numpy style
allows for parameters; napoleon would make one attribute of the first name with the others as its type.  Such an
entry is written out as one entry per name, each with the entry's type and description.

A dataclass field with a ``default_factory`` has the default ``<factory>`` in the signature that autodoc writes,
which is no Python: the whole signature is then shown as raw text, every annotation with its module path and a
tilde.  The default is written as the factory's call instead (``list()``), or ``...`` for an unnamed factory.

Loaded through ``_config.yml`` (``sphinx: extra_extensions``), before napoleon's handler runs.
"""
from __future__ import annotations

import dataclasses
import re

#: napoleon handles ``autodoc-process-docstring`` at Sphinx's default priority, 500; lower runs first
PRIORITY = 400
#: the priority of the handler that removes the guard again, after napoleon's
AFTER_NAPOLEON = 600
#: the invisible line napoleon takes for the (empty) type and description
GUARD = "\u200b"
#: an entry of a numpy-style section that names several attributes: indentation, the names, the type (if any)
MULTI_NAME = re.compile(r"^(\s*)([A-Za-z_]\w*(?:\s*,\s*[A-Za-z_]\w*)+)\s*(?::\s*(.*))?$")


def keep_whole(app, what: str, name: str, obj, options, lines: list[str]) -> None:
    """Before napoleon: a constant's, attribute's or property's docstring gets the :data:`GUARD` line first, in
    place."""
    if what in ("data", "attribute", "property") and any(":" in line for line in lines[:1]):
        lines.insert(0, GUARD)


def drop_guard(app, what: str, name: str, obj, options, lines: list[str]) -> None:
    """After napoleon: the :data:`GUARD` that :func:`keep_whole` put first is taken out again, in place."""
    if lines and lines[0].startswith(GUARD):
        rest = lines[0][len(GUARD):]
        if rest.strip():
            lines[0] = rest
        else:
            del lines[0]


def _escaped(text: str) -> str:
    """``text`` with the characters that reStructuredText reads as markup escaped, ``*emphasis*`` apart."""
    text = text.replace("\\", "\\\\").replace("|", "\\|").replace("`", "\\`")
    return re.sub(r"(?<=\w)_(?=\W|$)", r"\\_", text)


def show_text(app, what: str, name: str, obj, options, lines: list[str]) -> None:
    """A constant whose value is hidden (``:meta hide-value:``) gets its value as text, in place: a string as a
    paragraph, a dict or a tuple of pairs as a list of ``key``: value items, a tuple of strings as a list."""
    if what != "data" or not any(line.strip() == ":meta hide-value:" for line in lines):
        return
    if isinstance(obj, str):
        lines += ["", _escaped(obj), ""]
        return
    pairs = list(obj.items()) if isinstance(obj, dict) else list(obj) if isinstance(obj, tuple) else []
    if pairs and all(isinstance(p, tuple) and len(p) == 2 for p in pairs):
        lines += [""] + [f"* ``{k}``: {_escaped(str(v))}" for k, v in pairs] + [""]
    elif pairs and all(isinstance(p, str) for p in pairs):
        lines += [""] + [f"* ``{p}``" for p in pairs] + [""]


def factory_defaults(app, what: str, name: str, obj, options, signature, return_annotation):
    """The signature of a dataclass with ``<factory>`` defaults replaced by the factories' calls, so that it parses."""
    if not signature or "<factory>" not in signature or not dataclasses.is_dataclass(obj):
        return None
    for f in dataclasses.fields(obj):
        if f.init and f.default_factory is not dataclasses.MISSING:
            factory = getattr(f.default_factory, "__name__", "<lambda>")
            signature = signature.replace("<factory>", f"{factory}()" if factory.isidentifier() else "...", 1)
    return signature, return_annotation


def _is_header(lines: list[str], i: int) -> bool:
    """Whether ``lines[i]`` is a numpy-style section title (underlined by dashes on the next line)."""
    return (i + 1 < len(lines) and bool(lines[i].strip())
            and set(lines[i + 1].strip()) == {"-"} and len(lines[i + 1].strip()) >= 3)


def split_attributes(app, what: str, name: str, obj, options, lines: list[str]) -> None:
    """Before napoleon: every entry of an ``Attributes`` section that names several attributes becomes one entry
    per name, in place."""
    out, i, section = [], 0, None
    while i < len(lines):
        if _is_header(lines, i):
            section = lines[i].strip()
            out += lines[i:i + 2]
            i += 2
            continue
        m = MULTI_NAME.match(lines[i]) if section == "Attributes" else None
        if m is None:
            out.append(lines[i])
            i += 1
            continue
        indent, names, kind = m.group(1), m.group(2), m.group(3)
        j = i + 1  # the entry's description: the lines indented deeper (and blank lines between them)
        while j < len(lines) and not _is_header(lines, j) and (
                not lines[j].strip() or len(lines[j]) - len(lines[j].lstrip()) > len(indent)):
            j += 1
        while j > i + 1 and not lines[j - 1].strip():
            j -= 1
        for one in (n.strip() for n in names.split(",")):
            out.append(f"{indent}{one} : {kind}" if kind else f"{indent}{one}")
            out += lines[i + 1:j]
        i = j
    lines[:] = out


def setup(app):
    app.setup_extension("sphinx.ext.autodoc")  # its event must exist before the handler is connected
    app.connect("autodoc-process-docstring", keep_whole, priority=PRIORITY)
    app.connect("autodoc-process-docstring", split_attributes, priority=PRIORITY)
    app.connect("autodoc-process-docstring", show_text, priority=PRIORITY)
    app.connect("autodoc-process-docstring", drop_guard, priority=AFTER_NAPOLEON)
    app.connect("autodoc-process-signature", factory_defaults)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
