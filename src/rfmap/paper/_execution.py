"""How the book executes its notebooks: no output of a cell may be lost without an error (a Sphinx extension).

The book runs every chapter through ``nbclient`` (myst-nb, ``execute_notebooks: force``).  Once a cell's
``execute_reply`` has arrived, ``nbclient`` waits only ``iopub_timeout`` seconds (4 by default) for the cell's
remaining outputs, and when they are late it drops them *silently* (``raise_on_iopub_timeout`` is off by default
and its warning goes to a logger that has no handler).  On a loaded machine a cell that glues many values and then
shows a table can lose the tail of its outputs that way: the last glue keys and the table vanish, and the build only
reports the glue references that no longer resolve.  This extension waits longer and turns a timeout into a cell
error, so that the build fails on the chapter instead of rendering it without its outputs.

Loaded through ``_config.yml`` (``sphinx: extra_extensions``); :func:`strict_iopub` does the same without Sphinx.
"""
from __future__ import annotations

#: seconds nbclient waits, after a cell's reply, for the rest of its outputs
IOPUB_TIMEOUT = 300


def strict_iopub(timeout: int = IOPUB_TIMEOUT) -> None:
    """Make every ``nbclient.NotebookClient`` created from now on wait ``timeout`` seconds for a cell's late
    outputs and raise (the cell fails) when they do not come, instead of dropping them.  Values given to the
    client explicitly are kept; calling this again only changes the timeout."""
    from nbclient import NotebookClient

    init = getattr(NotebookClient.__init__, "_rfmap_wrapped", NotebookClient.__init__)

    def __init__(self, nb, km=None, **kw):
        kw.setdefault("iopub_timeout", int(timeout))
        kw.setdefault("raise_on_iopub_timeout", True)
        init(self, nb, km, **kw)

    __init__._rfmap_wrapped = init
    NotebookClient.__init__ = __init__


def setup(app):
    strict_iopub()
    return {"parallel_read_safe": True, "parallel_write_safe": True}
