"""rfmap.core.wording.of_counts: several parts of wholes in one phrase, never "4 of 4, 4 of 4 and 4 of 4"."""
from rfmap.core.wording import of_counts


def test_all_whole_is_said_once():
    s = of_counts([(4, 4), (4, 4), (4, 4)], ["density", "density", "side"])
    assert s == "every one of them (4 densities, 4 densities and 4 sides)"
    assert "4 of 4" not in s


def test_mixed_parts_are_listed():
    assert of_counts([(1, 3), (0, 4)], ["density", "side"]) == "1 of 3 densities and none of the 4 sides"
    assert of_counts([(0, 2), (0, 4)], ["density", "side"]).startswith("none of them")


def test_at_values_names_the_values():
    from rfmap.core.wording import at_values

    assert at_values([64], 4) == "at N = 64 only"
    assert at_values([32, 64], 4) == "at N = 32 and 64"
    assert at_values([32, 51, 64], 4) == "at N = 32, 51 and 64"
    assert at_values([], 4) == "at no side" and at_values([1, 2], 2) == "at every side"
    assert at_values([3], 5, name="k", noun="step") == "at k = 3 only" and at_values([], 2, noun="step") == "at no step"
