"""Counts in messages agree with their number (rfmap.core.wording)."""
import pytest

from rfmap.core.wording import counted


@pytest.mark.parametrize("n, noun, text", [
    (1, "pass", "1 pass"), (0, "pass", "0 passes"), (3, "pass", "3 passes"),
    (2, "folded element", "2 folded elements"), (1, "folded element", "1 folded element"),
    (2, "region without data", "2 regions without data"), (4, "pair of neighbours", "4 pairs of neighbours"),
    (2, "vertex", "2 vertices"), (5, "box", "5 boxes"), (2, "CUDA device", "2 CUDA devices"),
])
def test_counted_inflects_the_noun_of_the_phrase(n, noun, text):
    assert counted(n, noun) == text


def test_an_explicit_plural_wins_and_numpy_counts_are_plain_integers():
    import numpy as np

    assert counted(2, "child", "children") == "2 children" and counted(1, "child", "children") == "1 child"
    assert counted(np.int64(2), "run") == "2 runs"
