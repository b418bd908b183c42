"""The time-to-accuracy targets of chapter 11 (rfmap.paper.benchmarks): checks, headline and summary table."""
import pytest

from rfmap.finish.polish import UNGUARDED
from rfmap.paper.benchmarks import (FLOW_TIME, HYBRID_TIME, STD_TOL, hybrid_findings, refinement_fields, summarize,
                                    summary_table, target_checks, targets_headline)


def _rows(flow_time: float, flow_std: float, hybrid_time: float, hybrid_std: float) -> list[dict]:
    """One field of a 2D and a 3D case; diffusion takes 1 s at Std 0.1 and is the best classical solver."""
    rows = []
    for dim, n in ((2, 33), (3, 16)):
        base = {"field": "f", "dim": dim, "n": n, "boundary": "square", "n_flipped": 0}
        rows += [dict(base, method="diffusion", std_rho_map=0.1, time=1.0),
                 dict(base, method="flow", std_rho_map=0.1 * flow_std, time=flow_time),
                 dict(base, method="surrogate", std_rho_map=0.3, time=0.05),
                 dict(base, method=UNGUARDED, std_rho_map=0.1 * hybrid_std, time=hybrid_time / 2, start="warm",
                      kept="warm"),
                 dict(base, method="hybrid", std_rho_map=0.1 * hybrid_std, time=hybrid_time, start="warm",
                      kept="warm")]
    return rows


CASES = [(2, 33, "square"), (3, 16, "square")]


def test_targets_met_exactly_at_the_limits_and_missed_beyond():
    ok = target_checks(summarize(_rows(FLOW_TIME, STD_TOL, HYBRID_TIME, STD_TOL)), CASES)
    assert all(c["flow_met"] and c["hybrid_met"] for c in ok)
    assert ok[0]["flow_time"] == pytest.approx(FLOW_TIME, rel=1e-12)
    slow = target_checks(summarize(_rows(1.01 * FLOW_TIME, 1.0, 1.01 * HYBRID_TIME, 1.0)), CASES)
    assert not any(c["flow_met"] or c["hybrid_met"] for c in slow)
    rough = target_checks(summarize(_rows(0.1 * FLOW_TIME, 1.01 * STD_TOL, 0.1, 1.0)), CASES)
    assert [(c["flow_met"], c["hybrid_met"]) for c in rough] == [(False, True)] * 2


def test_headline_counts_each_criterion_and_names_the_target_column():
    h = targets_headline(target_checks(summarize(_rows(0.1, 1.0, 1.0, 1.0)), CASES))
    assert (h.met, h.compared) == (6, 8)  # per case: flow time and Std met, hybrid Std met, hybrid time missed
    md = h.to_markdown()
    assert "| case | measured | target | measured / target | met |" in md
    assert "| 2D N = 33 square: flow time / diffusion | 0.1 | 0.2 | 0.5× | yes |" in md


def test_summary_table_is_one_table_of_every_method_and_findings_quote_the_cases():
    rows = _rows(0.1, 1.0, 0.4, 1.0)
    table = summary_table(summarize(rows))
    lines = table.to_markdown().splitlines()
    assert len(table.rows) == 2 * 5 and sum(line.startswith("|---") for line in lines) == 1
    found = hybrid_findings(rows, dict(zip((2, 3), CASES)))
    assert found["flow_speed2"] == "10.0" and found["guard_warm"] == 2 and found["guard_worse"] == 0
    assert found["hyb_time3"] == "0.400" and found["hyb_std3"] == "1.00"
    # against the flow (0.1 s, Std 0.1): the surrogate 0.05 s at Std 0.3, the hybrid 0.4 s; times with their unit
    assert (found["sur_vs_flow2"], found["sur_abs2"], found["sur_std_vs_flow2"]) == ("0.500", "0.300", "3.00")
    assert found["hyb_vs_flow3"] == "4.00" and found["ng_vs_flow3"] == "2.00" and found["flow_wall2"] == "100 ms"
    assert (found["n_methods"], found["method_names"]) == (4, "diffusion, flow, surrogate, hybrid")


def test_targets_table_is_one_row_per_case_with_the_hybrid_against_the_flow():
    from rfmap.paper.benchmarks import targets_table

    checks = target_checks(summarize(_rows(0.1, 1.0, 0.4, 1.0)), CASES)
    assert checks[0]["hybrid_vs_flow"] == pytest.approx(4.0)
    md = targets_table(checks)._repr_markdown_()
    lines = [line for line in md.splitlines() if line.startswith("| ")]
    assert len(lines) == 1 + len(CASES)
    assert "hybrid time / flow" in lines[0] and f"(≤ {FLOW_TIME:g})" in lines[0]
    # ratios keep three significant digits, trailing zeros included
    assert lines[1] == "| 2D, N = 33, square | 0.100 (met) | 1.00 (met) | 0.400 (met) | 1.00 (met) | 4.00 |"


def test_cases_keep_the_order_they_were_run_in():
    rows = _rows(0.1, 1.0, 0.4, 1.0)
    free = [dict(r, boundary="free") for r in rows if r["dim"] == 2]
    summary = summarize(rows[:5] + free + rows[5:])
    cases = list(dict.fromkeys((r["dim"], r["n"], r["boundary"]) for r in summary))
    assert cases == [(2, 33, "square"), (2, 33, "free"), (3, 16, "square")]


def test_findings_state_the_hybrids_cost_against_the_flow_once():
    found = hybrid_findings(_rows(0.1, 1.0, 0.4, 1.0), dict(zip((2, 3), CASES)))
    assert (found["hyb_flow_range"], found["hyb_slower_cases"], found["hyb_verdict"]) == ("4.00", "both cases",
                                                                                         "does not pay")
    assert found["hyb_cost_text"] == ("it took longer than the flow alone in every case of the time table, 4.00 times"
                                      " the flow's time")
    quick = hybrid_findings(_rows(0.5, 1.0, 0.4, 1.0), dict(zip((2, 3), CASES)))
    assert quick["hyb_verdict"] == "pays" and quick["hyb_flow_range"] == "0.800"


def test_method_tables_pivot_methods_into_columns():
    from rfmap.paper.benchmarks import method_tables

    std, time = method_tables(summarize(_rows(0.1, 1.0, 0.4, 1.0)))
    head = std.text.splitlines()[0]
    assert head == f"| case | diffusion | flow | surrogate | {UNGUARDED} | hybrid |"
    assert std.text.splitlines()[2] == "| 2D, N = 33, square | 0.1 | 0.1 | 0.3 | 0.1 | 0.1 |"
    assert time.text.splitlines()[2].startswith("| 2D, N = 33, square | 1 s | 100 ms | 50 ms |")


def test_findings_say_where_refinement_raised_the_std_and_why():
    rows = _rows(0.1, 1.0, 0.4, 1.0)
    extra = []
    for r in rows:
        if r["method"] == "surrogate":
            r["coarser"] = r["dim"] == 3  # the 3D network map folded: the default map came from a coarser grid
            extra.append(dict(r, method="surrogate+refine", coarser=False,
                              std_rho_map=0.35 if r["dim"] == 3 else 0.25))
    found = hybrid_findings(rows + extra, dict(zip((2, 3), CASES)))
    assert found["ref_worse_fields"] == "1 of 2 fields" and found["ref_worse_coarser"] == 1
    assert found["ref_effect3"] == "raises it from 0.300 to 0.350"
    # the chapter's table of those fields counts them as the sentence does and lists each with both Stds
    table = refinement_fields(rows + extra)._repr_markdown_()
    assert "on 1 of 2 fields mapped both ways" in table
    assert "| 3D, N = 16, square | f | 0.3 | 0.35 | yes |" in table and "2D, N = 33" not in table


def test_findings_word_the_counts_as_sentences():
    from rfmap.paper.benchmarks import _refine_worse_text

    assert _refine_worse_text(3, 40, 3) == ("Field by field, refinement raised the Std on 3 of 40 fields; on all 3 the "
                                            "network's own map folded and the default map came from a coarser grid.")
    assert _refine_worse_text(0, 40, 0) == "Field by field, refinement raised the Std on none of the 40 fields."
    assert _refine_worse_text(2, 40, 1).endswith("on 1 of them the network's own map folded and the default map "
                                                 "came from a coarser grid.")
    found = hybrid_findings(_rows(0.1, 1.0, 0.4, 1.0), dict(zip((2, 3), CASES)))
    assert found["flow_hybrid_flips_text"] == "Neither the flow nor the hybrid folded an element in any case."


def test_time_ratio_table_gives_each_field_and_the_median():
    from rfmap.paper.benchmarks import time_ratio_table

    rows = _rows(0.1, 1.0, 0.4, 1.0)
    # a second field on the 2D case whose network map folded: 4 times the flow's time, from a coarser grid
    rows += [dict(r, field="g", time=0.4 if r["method"] == "surrogate" else r["time"],
                  coarser=r["method"] == "surrogate") for r in rows if r["dim"] == 2]
    lines = time_ratio_table(rows, CASES[0]).text.splitlines()
    assert lines[0] == "| field | surrogate / flow |"  # no refined rows: no column for them
    assert lines[2:] == ["| f | 0.500 |", "| g (coarser grid) | 4.00 |", "| median | 2.25 |"]
