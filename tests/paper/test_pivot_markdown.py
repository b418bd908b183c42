"""The Markdown tables of the appendix's unseen-field studies: one call per table, the number of fields shown."""
from rfmap.paper.generalization import columns_markdown, pivot_markdown
from rfmap.paper.tables import Table


def _table(scale: float) -> Table:
    t = Table("tab:x", "x", ["mean", "worst"])
    for kind, n in (("smooth", 2), ("ramp", 3), ("all", 5)):
        for method in ("ours", "classical (diffusion DEM)"):
            t.add(kind, method, {"mean": scale * n, "worst": 2e-5 * n, "fields": n})
    return t


def test_pivot_markdown_gives_each_kind_its_count_and_one_column_per_entry():
    a, b = _table(1.0), _table(0.5)
    text = pivot_markdown({"a, raw": (a, "ours"), "b, DEM": (b, "classical (diffusion DEM)")}, title="T")
    lines = text.splitlines()
    assert lines[0] == "**T**"
    assert lines[2] == "| fields | n | a, raw | b, DEM |"
    assert lines[4] == "| smooth | 2 | 2 | 1 |"
    assert lines[-1] == "| all | 5 | 5 | 2.5 |"


def test_columns_markdown_selects_rows_and_writes_powers_of_ten():
    t = _table(1.0)
    text = columns_markdown(t, {"worst": "worst"}, case="all", first="all fields", title="")
    assert text.splitlines() == ["| all fields | worst |", "|---|---|", "| ours | 1.00 × 10⁻⁴ |",
                                 "| classical (diffusion DEM) | 1.00 × 10⁻⁴ |"]
    by_method = columns_markdown(t, {"mean": "mean"}, method="ours")
    assert by_method.splitlines()[0] == "**x**" and "| ramp | 3 |" in by_method
