"""A cell's outputs survive a slow client: its glue keys and its table reach the executed notebook, or the cell
fails (rfmap.paper._execution, loaded by the book build and used by ``make chapter``).

A full-scale build once lost the tail of chapter 09's Table 7 cell (the last glue keys and the table) without any
error: nbclient drops the outputs that arrive more than ``iopub_timeout`` seconds (4) after a cell's reply.  Here a
client that reads each output slowly stands in for a loaded machine."""
import time

import nbformat
import pytest
from nbclient import NotebookClient

from rfmap.paper import _execution

KEYS = 12
#: seconds the client spends on each output of the cell (KEYS of them take longer than nbclient's default wait)
DELAY = 0.5
CELL = f"""\
from tqdm.auto import tqdm
from rfmap.paper.tables import glue_all
for _ in tqdm(range(3), desc="progress"):
    pass
glue_all({{f"k{{i}}": i for i in range({KEYS})}}, "t")
"the table"
"""


def _outputs(client_kwargs: dict, monkeypatch) -> list:
    nb = nbformat.v4.new_notebook()
    nb.cells.append(nbformat.v4.new_code_cell(CELL))
    slow = NotebookClient.process_message

    def process_message(self, msg, cell, cell_index):
        if msg["msg_type"] in ("display_data", "execute_result"):
            time.sleep(DELAY)
        return slow(self, msg, cell, cell_index)

    monkeypatch.setattr(NotebookClient, "process_message", process_message)
    client = NotebookClient(nb, kernel_name="rfmap", timeout=120, **client_kwargs)
    client.execute()
    return nb.cells[0].outputs


def _glued(outputs) -> list[str]:
    return [o["metadata"]["scrapbook"]["name"] for o in outputs
            if o["output_type"] == "display_data" and "scrapbook" in o.get("metadata", {})]


def test_glue_keys_and_table_survive_a_slow_client(monkeypatch):
    monkeypatch.setattr(NotebookClient, "__init__", NotebookClient.__init__)  # undone after the test
    _execution.strict_iopub(timeout=60)
    outputs = _outputs({}, monkeypatch)
    assert _glued(outputs) == [f"t_k{i}" for i in range(KEYS)]
    assert outputs[-1]["output_type"] == "execute_result"
    assert "the table" in outputs[-1]["data"]["text/plain"]


def test_the_default_client_loses_them(monkeypatch):
    """Without the extension the same cell loses its last outputs in silence: the failure the book guards
    against (if nbclient stops doing this, the guard is merely unneeded)."""
    outputs = _outputs({"iopub_timeout": 4, "raise_on_iopub_timeout": False}, monkeypatch)
    assert len(_glued(outputs)) < KEYS
    assert not any(o["output_type"] == "execute_result" for o in outputs)


def test_strict_iopub_sets_the_client_defaults(monkeypatch):
    monkeypatch.setattr(NotebookClient, "__init__", NotebookClient.__init__)
    _execution.strict_iopub(timeout=77)
    _execution.strict_iopub(timeout=99)  # a second call replaces the timeout, it does not wrap twice
    client = NotebookClient(nbformat.v4.new_notebook())
    assert client.iopub_timeout == 99 and client.raise_on_iopub_timeout is True
    explicit = NotebookClient(nbformat.v4.new_notebook(), iopub_timeout=5)
    assert explicit.iopub_timeout == 5


def test_the_book_loads_the_extension():
    from pathlib import Path

    import yaml

    cfg = yaml.safe_load((Path(__file__).resolve().parents[2] / "_config.yml").read_text())
    assert "rfmap.paper._execution" in cfg["sphinx"]["extra_extensions"]
