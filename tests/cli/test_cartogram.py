"""The cartogram command's report (rfmap.cli.cartogram)."""


def test_long_lists_in_the_report_are_cut_to_ten_names():
    """A county map may cut overlaps in a thousand pairs: the report names ten and counts the rest."""
    from rfmap.cli.cartogram import LISTED_CUTS, _listed

    assert _listed(["a", "b"]) == "a, b"
    line = _listed([f"r{i}" for i in range(1492)], LISTED_CUTS)
    assert line.startswith("r0, r1,") and "r9 and 1482 more" in line and "r10" not in line
    assert line.endswith('lists them all)')
