"""How the API reference reads the comments of constants (a Sphinx extension).

A constant is documented by a ``#:`` comment, and ``sphinx.ext.napoleon`` reads the first line of such a docstring
as ``type: description``: a comment whose first line holds a colon ("cells per side: the raster's ...") comes out
cut at that colon, its start shown as the constant's type.  The constants' comments are prose, never types, so this
extension puts an invisible first line (a zero-width space) before napoleon reads them, which leaves the text
whole.  Loaded through ``_config.yml`` (``sphinx: extra_extensions``), before napoleon's handler runs.
"""
from __future__ import annotations

#: napoleon handles ``autodoc-process-docstring`` at Sphinx's default priority, 500; lower runs first
PRIORITY = 400
#: the invisible line napoleon takes for the (empty) type and description
GUARD = "\u200b"


def keep_whole(app, what: str, name: str, obj, options, lines: list[str]) -> None:
    """Before napoleon: a constant's or attribute's docstring gets the :data:`GUARD` line first, in place."""
    if what in ("data", "attribute") and any(":" in line for line in lines[:1]):
        lines.insert(0, GUARD)


def setup(app):
    app.setup_extension("sphinx.ext.autodoc")  # its event must exist before the handler is connected
    app.connect("autodoc-process-docstring", keep_whole, priority=PRIORITY)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
