"""The tables of appendix B (rfmap.paper.flow_studies): small numbers as powers of ten, times with their unit."""
from rfmap.paper.flow_studies import convergence_table, floor_table, rotation_table, sea_table, warm_table


def test_floor_and_warm_tables_print_small_numbers_as_powers_of_ten():
    row = {"n": 256, "method": "flow", "std": 0.005918, "smooth": 7.68e-5, "element_fraction": 0.987,
           "time": 0.273, "n_flipped": 0}
    floor = floor_table([row]).text.splitlines()
    assert floor[2] == "| 256 | flow | 0.005918 | 7.68 × 10⁻⁵ | 98.7 % | 273 ms | 0 |"
    warm = warm_table([row]).text.splitlines()
    assert warm[2] == "| 256 | flow | 0.005918 | 7.68 × 10⁻⁵ | 98.7 % | 273 ms |"
    assert "e-05" not in floor_table([row])._repr_markdown_()


def test_convergence_rotation_and_sea_tables_have_one_row_per_field():
    conv = [{"field": f, "setting": s, "std_ratio": 1.1, "time_ratio": 0.2, "rotation": 0.05,
             "rotation_diffusion": 0.02} for f in ("a", "b") for s in ("default", "rtol=0.02")]
    assert convergence_table(conv).text.splitlines()[0] == \
        "| field | default: Std / time | rtol=0.02: Std / time |"
    assert rotation_table(conv).text.splitlines()[3] == "| b | 1.1 | 0.02 | 0.05 | 2.5 |"
    sea = [{"field": "ramp-3", "ratio_abrupt": 5.36, "ratio_default": 1.04, "ratio_blended": 1.04,
            "stalled": True, "time_default": 0.31, "shift": 10.4}]
    assert sea_table(sea).text.splitlines()[2] == "| ramp-3 | 5.36 | 1.04 | 1.04 | yes | 0.31 | 10.4 |"
    assert "| abrupt sea stalled |" in sea_table(sea).text.splitlines()[0]  # whose first pass stalled
