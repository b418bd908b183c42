"""The book says once how to read its timings (book/reproduce.md) and every chapter that tables times points there
with the same one-line note, beside its first table with times."""
import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
NOTE = ("*Times are wall-clock on the machine that built this page and vary with its load; compare them as ratios "
        "within one table ({ref}`how to read the timings <reading-timings>`).*")
#: the chapters whose tables give times
TIMED_CHAPTERS = ["05_beltrami_reconstruction", "06_dem_deq_2d", "07_resolution_2d", "08_dem_vs_deq", "09_dem_3d",
                  "11_fast_classical_and_hybrid", "13_cartogram"]


def test_the_reproduce_page_says_how_to_read_the_timings():
    page = (ROOT / "book" / "reproduce.md").read_text(encoding="utf-8")
    assert re.search(r"^\(reading-timings\)=\n## How to read the timings$", page, re.M)


@pytest.mark.parametrize("chapter", TIMED_CHAPTERS)
def test_a_chapter_with_timed_tables_carries_the_note_once(chapter):
    cells = json.loads((ROOT / "notebooks" / f"{chapter}.ipynb").read_text(encoding="utf-8"))["cells"]
    notes = [c for c in cells if c["cell_type"] == "markdown" and "".join(c["source"]).strip() == NOTE]
    assert len(notes) == 1
    text = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "markdown")
    assert text.count("reading-timings") == 1  # the note alone points there; no second caveat
