"""Headline cells of the U-Net/FNO comparison: folded maps are named, not averaged (rfmap.paper.compare)."""
from rfmap.paper.compare import folded_cell, side_by_side
from rfmap.paper.tables import Table


def test_a_folded_map_reads_folded_with_its_flips():
    assert folded_cell(127.0, 8264) == "folded (8,264 flips)"
    assert folded_cell(0.0652, 0) == "0.0652"
    assert folded_cell(0.152, 109, 3) == "0.152 (3 folded, 109 flips)"
    assert folded_cell(None) == "—"


def test_side_by_side_marks_the_raw_column_only():
    t = Table("tab:x", "x", ["raw_std", "std_rho_map", "n_flipped"])
    t.add("256", "U-Net (native)", {"raw_std": 127.0, "std_rho_map": 0.22, "n_flipped": 8264})
    md = side_by_side(t, {"raw": ("U-Net (native)", "raw_std"),
                          "repaired": ("U-Net (native)", "std_rho_map")}, "N")
    assert md.splitlines()[-1] == "| 256 | folded (8,264 flips) | 0.22 |"


def test_side_by_side_shows_as_a_table_when_it_is_a_cells_value():
    t = Table("tab:x", "x", ["raw_std"])
    t.add("32", "FNO", {"raw_std": 0.2})
    md = side_by_side(t, {"raw": ("FNO", "raw_std")}, "N")
    assert isinstance(md, str) and md._repr_markdown_() == str(md)


def test_speed_table_gives_each_methods_time_with_its_unit():
    from rfmap.paper.compare import speed_table

    md = speed_table({"U-Net": {"time": 0.0123, "std_rho_map": 0.08},
                      "flow solver": {"time": 1.5, "std_rho_map": 0.01}})
    assert md.splitlines()[2:] == ["| U-Net | 12.3 ms | 0.08 |", "| flow solver | 1.50 s | 0.01 |"]


def test_speed_table_gives_one_row_per_grid_side():
    from rfmap.paper.compare import speed_table

    one = {"U-Net": {"time": 0.0123, "std_rho_map": 0.08}, "flow solver": {"time": 1.5, "std_rho_map": 0.01}}
    md = speed_table({51: one, 256: one})
    assert md.splitlines()[0] == "| N | U-Net, time | U-Net, Std | flow solver, time | flow solver, Std |"
    assert md.splitlines()[3] == "| 256 | 12.3 ms | 0.08 | 1.50 s | 0.01 |"
