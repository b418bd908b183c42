"""The prose of the experiment chapters quotes results only through glue: no hand-typed measurements."""
import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

#: Chapters whose every number in prose is a result of the page: each must come from the notebook (myst_nb.glue)
GLUED_CHAPTERS = ["05_beltrami_reconstruction", "06_dem_deq_2d", "07_resolution_2d", "08_dem_vs_deq",
                  "10_bijectivity", "11_fast_classical_and_hybrid", "12_unet_vs_fno", "14_appendix_repair",
                  "15_appendix_flow"]

#: what a typed result looks like: a decimal number (0.43, 1.0) or a percentage (10 %, 30%)
TYPED_RESULT = re.compile(r"(?<![\w.])\d+\.\d+(?![\w.])|(?<![\w.])\d+\s?%")


def _prose(markdown: str) -> str:
    """The running text of a Markdown cell: without code, math, MyST roles (glue, cite, ref) and link targets."""
    text = re.sub(r"```.*?```", " ", markdown, flags=re.S)
    text = re.sub(r"\$\$.*?\$\$", " ", text, flags=re.S)
    text = re.sub(r"\$[^$]*\$", " ", text)
    text = re.sub(r"\{[a-z:-]+\}`[^`]*`", " ", text)
    text = re.sub(r"`[^`]*`", " ", text)
    return re.sub(r"\]\([^)]*\)", "]", text)


def test_prose_filter_keeps_text_and_drops_markup():
    md = "Std falls to {glue:text}`x:.3f` (paper 0.0737), $a = 0.5$, `f(0.2)`, and 10 % of draws; see [a](b/0.1)."
    assert TYPED_RESULT.findall(_prose(md)) == ["0.0737", "10 %"]


@pytest.mark.parametrize("chapter", GLUED_CHAPTERS)
def test_results_in_prose_are_glued(chapter):
    """A decimal number or a percentage typed in a chapter's prose goes stale when the models or the code change:
    compute it in the notebook and glue it (a threshold too: a named constant in the notebook, glued)."""
    nb = json.loads((ROOT / "notebooks" / f"{chapter}.ipynb").read_text(encoding="utf-8"))
    found = []
    for cell in nb["cells"]:
        if cell["cell_type"] == "markdown":
            text = _prose("".join(cell["source"]))
            found += [f"cell {cell['id']}: {m.group()!r} in ...{text[max(0, m.start() - 50):m.end() + 20]!r}"
                      for m in TYPED_RESULT.finditer(text)]
    assert not found, "typed numbers in prose:\n" + "\n".join(found)
