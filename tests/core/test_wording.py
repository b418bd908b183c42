"""Counts in messages agree with their number (rfmap.core.wording)."""
import pytest

from rfmap.core.wording import counted, of_count


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


@pytest.mark.parametrize("k, n, noun, text", [
    (4, 4, "density", "all 4 densities"), (0, 4, "density", "none of the 4 densities"), (3, 4, "side", "3 of 4 sides"),
    (4, 4, "", "all 4"), (0, 4, "", "none of the 4"), (1, 4, "", "1 of 4"), (2, 2, "map", "both maps"),
    (0, 2, "", "neither of the 2"), (1, 1, "case", "the one case"), (0, 1, "case", "not the one case"),
])
def test_of_count_says_all_and_none_in_words(k, n, noun, text):
    assert of_count(k, n, noun) == text


def test_of_count_refuses_a_part_larger_than_the_whole():
    with pytest.raises(ValueError):
        of_count(5, 4)
