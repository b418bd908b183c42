"""The four-way comparisons of the paper's tables (rfmap.paper.comparison): one criterion, one number format, the
scoreboard's keys, and the runners on untrained models (the identity map, whose errors are known exactly)."""
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from rfmap.paper.comparison import (Case, Comparison, beltrami_comparison, compare_density, format_number,
                                    format_time, native_side_by_side, resolution_comparison, score_row, timed)
from rfmap.core.result import MapResult
from rfmap.surrogate import Surrogate
from rfmap.tasks import TaskSpec

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("value, text", [
    (0.0825411, "0.08254"), (0.0297, "0.02970"), (3.8104e-05, "3.810 × 10⁻⁵"), (1234.5, "1234"),
    (12000.0, "12000"), (0.00099996, "0.001000"),
    (-0.0123456, "-0.01235"), (7, "7"), (np.int64(3), "3"), (None, "—"), (float("nan"), "—"), (True, "yes"),
])
def test_one_number_format_of_four_significant_digits(value, text):
    assert format_number(value) == text


def test_times_carry_their_unit():
    assert (format_time(0.0123456), format_time(2.4321), format_time(None)) == ("12.3 ms", "2.43 s", "—")
    # three significant digits in every cell, trailing zeros kept; no e-notation above 100 s
    assert (format_time(0.084), format_time(0.9996), format_time(1234.5)) == ("84.0 ms", "1.00 s", "1,234 s")


def test_a_published_value_keeps_the_digits_it_was_printed_with():
    assert format_number(0.000006, printed=True) == "6 × 10⁻⁶" and format_number(0.05, printed=True) == "0.05"
    assert format_number(0.082541, printed=True) == "0.08254"
    assert score_row(0.000006, 0.0000051, None, None)["paper"] == "6 × 10⁻⁶"


def _comparison() -> Comparison:
    """Two fields; the paper's method meets the paper on the first only, the classical solver beats it on both."""
    cases = [Case("a", "sin-cos", 9), Case("b", "ring", 9)]
    c = Comparison("tab:population_test", "t", ["std_rho_map"], cases, "flow solver")
    for name, (paper, native, delivered, classical) in {"a": (0.08, 0.05, 0.04, 0.01),
                                                        "b": (0.04, 0.06, 0.05, 0.02)}.items():
        for method, v in zip(("paper", "native", "delivered", "classical"), (paper, native, delivered, classical)):
            c.values[(name, method)] = {"std_rho_map": v, "time": 0.01 if method != "native" else 0.02}
    return c


def test_native_side_by_side_sets_each_models_method_against_the_paper():
    a, b = _comparison(), _comparison()
    b.values[("b", "native")]["std_rho_map"] = 0.03  # the second model meets the paper on b too
    lines = native_side_by_side({"old": a, "new": b}).splitlines()
    assert lines[0] == ("| case | paper Std(ρ̃_map) | old, paper's method | new, paper's method | flow solver |")
    assert lines[2] == "| a | 0.08000 | 0.05000 (met) | 0.05000 (met) | 0.01000 |"
    assert lines[3] == "| b | 0.04000 | 0.06000 (missed) | 0.03000 (met) | 0.02000 |"
    b.comparable = lambda case: case != "b"  # b's input is not the paper's: marked, not scored
    assert native_side_by_side({"new": b}).splitlines()[3] == "| b | 0.04000 | 0.03000 (n/c) | 0.02000 |"
    b.cases = b.cases[:1]
    with pytest.raises(ValueError, match="differs"):
        native_side_by_side({"old": a, "new": b})
    with pytest.raises(ValueError, match="at least one"):
        native_side_by_side({})


def test_met_is_the_paper_method_at_most_the_paper():
    c = _comparison()
    assert (c.met("a", "std_rho_map"), c.met("b", "std_rho_map")) == (True, False)
    assert c.count("std_rho_map") == (1, 2) and c.classical_better("std_rho_map") == (2, 2)
    assert c.mean("paper", "std_rho_map") == pytest.approx(0.06)
    assert c.speed() == {"a": pytest.approx(0.5), "b": pytest.approx(0.5)}
    v = c.score_values()
    assert v["std_rho_map_met"] == "1 of 2" and v["std_rho_map_classical_better"] == "both"
    assert v["std_rho_map_paper"] == "0.06000" and v["std_rho_map_b_met"] == "no (1.50×)"  # a miss by how much
    assert v["std_rho_map_a_met"] == "yes" and v["nc"] == "—" and v["verdict"] == "partly (1 of 2)"
    # beside the means, the median over the cases of the ratio to the paper (0.625 and 1.5): not a ratio of means
    assert (v["std_rho_map_native_ratio"], v["std_rho_map_delivered_ratio"]) == ("1.06×", "0.875×")
    assert v["std_rho_map_classical_ratio"] == "0.312×"
    assert "1 of 2" in c.verdict() and "flow solver does better than the paper's method on both." in c.verdict()
    assert score_row(None, 0.1, 0.1, 0.1)["met"] == "—"


def test_score_values_print_a_metric_in_one_notation():
    """Where one value of a metric is below 10⁻³ (a power of ten), the scoreboard's column prints every value of
    that metric as a power of ten, with the digits it had; other metrics and the counts keep theirs."""
    c = _comparison()
    c.values[("a", "native")]["std_rho_map"] = 2.8215e-4
    v = c.score_values()
    v = {k: t.replace("\u00a0", " ") for k, t in v.items()}  # a power of ten is joined by non-breaking spaces
    assert v["std_rho_map_a_native"] == "2.822 × 10⁻⁴" and v["std_rho_map_b_delivered"] == "5.000 × 10⁻²"
    assert v["std_rho_map_a_paper"] == "8 × 10⁻²"  # the paper's value with the digits it was printed with
    assert c.score_values()["std_rho_map_a_native"] == "2.822\u00a0×\u00a010⁻⁴"  # never split over two lines
    assert v["std_rho_map_met"] == "1 of 2" and v["verdict"] == c.verdict_word(short=True)
    assert v["close"]  # near or shared misses as a sentence, "—" for none (rfmap.paper.verdicts.close_calls)


def test_table_is_shaped_like_the_paper_one_block_per_case():
    lines = _comparison().to_markdown().splitlines()
    assert lines[0] == "| case | quantity | paper | paper's method | delivered | flow solver | met |"
    assert lines[2] == "| a | Std(ρ̃_map) | 0.08 | 0.05000 | 0.04000 | 0.01000 | yes |"  # the paper's as printed
    assert lines[3] == "|  | time | 10.0 ms | 20.0 ms | 10.0 ms | 10.0 ms |  |"
    assert len(lines) == 2 + 2 * 2


def test_score_values_are_the_keys_the_scoreboard_pastes():
    """The chapter glues comparison.score_values() under the item's prefix: the keys are exactly those that
    scripts/make_figures_md.py pastes for it."""
    spec = importlib.util.spec_from_file_location("make_figures_md", ROOT / "scripts" / "make_figures_md.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    items = json.loads((ROOT / "src" / "rfmap" / "data" / "figures.json").read_text(encoding="utf-8"))["items"]
    item = next(it for it in items if it["label"] == "tab:population_test")
    score = item["score"]
    cases = [Case(f, f, 9) for f in score["cases"]]
    c = Comparison(item["label"], "t", list(score["metrics"]), cases, "flow solver")
    for case in cases:
        for method in ("paper", "native", "delivered", "classical"):
            c.values[(case.name, method)] = {m: 0.1 for m in score["metrics"]}
    summary, per_case = mod.score_keys(item)
    assert {f"{score['key']}_{k}" for k in c.score_values()} == set(summary) | set(per_case)


def test_timed_keeps_the_fastest_run_after_a_warm_up():
    times = iter([5.0, 3.0, 1.0, 2.0])
    calls = []

    def run():
        calls.append(1)
        return MapResult(np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((0, 3), int), np.ones(1), time=next(times))

    assert timed(run).time == 1.0 and len(calls) == 4  # warm-up, then three timed runs


def test_density_comparison_of_an_untrained_model():
    """An untrained surrogate is the identity: its Std(ρ̃_map) is the input's, the flow solver's is far lower, and
    the paper's method ran on the requested grid while the delivered map used the working grid."""
    sur = Surrogate.untrained(TaskSpec("density", 2, "square"), base=4, depth=2, name="tiny", n_range=[17, 17])
    c = compare_density(sur, [Case("sin-cos", "sin-cos", 13)], "tab:population_test", "t")
    ours = c.value("sin-cos", "native", "std_rho_map")
    assert ours == pytest.approx(c.value("sin-cos", "native", "std_rho_orig"), rel=1e-6)
    assert c.value("sin-cos", "classical", "std_rho_map") < 0.5 * ours
    assert c.value("sin-cos", "native", "work_n") == 13 and c.value("sin-cos", "delivered", "work_n") == 17
    assert c.maps["sin-cos"]["delivered"].info["symmetrize"] == "full"
    assert c.value("sin-cos", "paper", "std_rho_map") == pytest.approx(0.082541)
    assert c.metrics == ["std_rho_map", "mean_mu"] and c.met("sin-cos", "std_rho_map") is False


def test_beltrami_comparison_of_an_untrained_model():
    sur = Surrogate.untrained(TaskSpec("beltrami", 2, "fixed"), base=4, depth=2, name="tiny")
    c = beltrami_comparison(sur, n=13)
    exact = c.maps["T1"]["exact"]
    expected = float(np.linalg.norm(exact.mapped_points - exact.ref_points, axis=1).mean())
    assert c.value("T1", "native", "mean_dd") == pytest.approx(expected, rel=1e-6)
    assert c.value("T1", "classical", "mean_dd") < 0.1 * expected and c.classical == "LBS"
    assert [case.name for case in c.cases] == ["T1", "T2", "T3", "T4"]


def test_resolution_comparison_keys_the_rows_by_the_paper_sides():
    sur = Surrogate.untrained(TaskSpec("density", 2, "square"), base=4, depth=2, name="tiny", n_range=[9, 17])
    with pytest.raises(ValueError, match="paper's sides"):
        resolution_comparison(sur, {32: 9})
    c = resolution_comparison(sur, {32: 9, 64: 11, 128: 13, 256: 17})
    assert [case.name for case in c.cases] == ["32", "64", "128", "256"]
    assert c.cases[0].title() == "32 (run at 9)" and c.value("32", "native", "work_n") == 9
    assert c.value("256", "paper", "std_rho_map") == pytest.approx(0.134581)


def test_native_lesson_names_the_sides_where_the_native_map_is_worse():
    c = _comparison()
    for name, (wn, wd) in {"a": (9, 9), "b": (64, 48)}.items():
        c.values[(name, "native")]["work_n"], c.values[(name, "delivered")]["work_n"] = wn, wd
    assert "(N = b)" in c.native_lesson() and "accurate only near" in c.native_lesson()  # 0.06 > 1.1 * 0.05
    assert "within 1.3 times" in c.native_lesson(tol=1.3)
    c.values[("b", "native")]["work_n"] = 48
    assert "same grid at every side" in c.native_lesson()


def test_models_compared_on_one_density_share_the_flow_map():
    from rfmap.paper.comparison import compare_models

    models = {name: Surrogate.untrained(TaskSpec("density", 2, "square"), base=4, depth=2, name=name,
                                        n_range=[13, 13]) for name in ("DEM", "DEQ")}
    c = compare_models(models, "ring", 13, "fig:extreme_comparison", "t")
    assert [case.name for case in c.cases] == ["DEM", "DEQ"]
    assert c.maps["DEM"]["classical"] is c.maps["DEQ"]["classical"]
    assert c.value("DEM", "native", "std_rho_map") == pytest.approx(c.value("DEM", "native", "std_rho_orig"))
    assert c.met("DEM", "std_rho_map") is None and c.count("mean_mu") == (0, 0)


def test_a_case_whose_input_is_not_the_papers_is_not_scored():
    """rect-peak as this project defines it has Std(rho~_orig) 0.5709 on the paper's grid against the paper's
    0.4807: it is not comparable (n/c) and left out of the counts and the verdict; sin-cos agrees to 5e-7."""
    from rfmap.paper.verdicts import COMPARABLE_RTOL, input_std

    assert abs(input_std("sin-cos", 51) / 0.453812 - 1) < COMPARABLE_RTOL
    assert abs(input_std("rect-peak", 51) / 0.480728 - 1) > 100 * COMPARABLE_RTOL
    cases = [Case("sin-cos", "sin-cos", 9), Case("rect-peak", "rect-peak", 9)]
    c = Comparison("tab:population_test", "t", ["std_rho_map"], cases, "flow solver")
    for name, paper_orig, (paper, native) in [("sin-cos", 0.453812, (0.08, 0.07)),
                                              ("rect-peak", 0.480728, (0.09, 0.12))]:
        c.values[(name, "paper")] = {"std_rho_map": paper, "std_rho_orig": paper_orig}
        for method in ("native", "delivered", "classical"):
            c.values[(name, method)] = {"std_rho_map": native, "std_rho_orig": 0.6, "time": 0.01}
    assert c.comparable("sin-cos") and not c.comparable("rect-peak")
    assert c.met("rect-peak", "std_rho_map") is None and c.count("std_rho_map") == (1, 1)
    v = c.score_values()
    # 0.12 / 0.6 against 0.09 / 0.48; the scoreboards give the word and its count of comparable pairs, the n/c
    # clause and the Std ratios in a footnote
    # the clause gives the size of the gap: 0.2 / 0.1875 = 1.07
    assert c.verdict_word() == ("reproduced on the comparable cases (1 of 1); the n/c case’s Std ratio is 1.1 times "
                                "the paper’s")
    assert v["verdict"] == "reproduced (1 of 1 comparable)"  # the n/c clause is in the scoreboards' footnotes
    nc = "20 % of its input’s spread against the paper’s 18.7 % (1.1 times as much)"
    assert v["nc"] == nc.replace(" %", "\u00a0%")  # a per cent sign never wraps away from its number
    c.values[("rect-peak", "native")]["std_rho_map"] = 0.09
    # a better n/c case is given by its ratio too: 0.15 / 0.1875 = 0.8
    assert c.verdict_word() == (
        "reproduced on the comparable cases (1 of 1); the n/c case’s Std ratio is 0.8 times the paper’s")
    c.values[("rect-peak", "native")]["std_rho_map"] = 0.12
    # the means beside the verdict are over the comparable case only
    assert (v["std_rho_map_native"], v["std_rho_map_paper"]) == ("0.07000", "0.08000")
    assert c.mean("native", "std_rho_map") == pytest.approx(0.095)
    assert v["std_rho_map_rect-peak_met"] == "n/c"
    # the met cell stays short; the Std ratios go in the note under the table
    assert c.to_markdown().splitlines()[4].endswith("| n/c |")
    assert c.to_markdown().endswith(
        "lower is better: rect-peak, paper's method 0.2 and paper 0.187.")
    assert c.nc_note().startswith("*n/c*: not comparable")
    # a table of unscored rows has no n/c mark, so no note under it either
    assert "n/c" not in c.to_markdown(["time"])
    c.values[("sin-cos", "native")]["std_rho_map"] = 0.09  # now the one comparable case misses
    assert c.verdict_word() == (
        "not reproduced on the comparable cases (0 of 1); the n/c case’s Std ratio is 1.1 times the paper’s")
    assert c.score_values()["verdict"] == "not reproduced (0 of 1 comparable)"


def test_verdict_words_follow_the_stated_rule():
    from rfmap.paper.verdicts import VERDICTS, verdict

    assert [verdict(f) for f in ([True] * 3, [True, False, None], [False, None], [None, None], [])] == list(VERDICTS)


def test_an_item_with_no_scored_pair_is_not_scored_not_not_comparable():
    """No (case, metric) pair at all (the paper prints no number, Fig. 10) is *not scored*; cases whose inputs are
    none of them the paper's are *not comparable*, with or without the clause on the n/c cases."""
    from rfmap.paper.verdicts import VERDICT_RULE, qualified_verdict, verdict

    assert verdict([]) == qualified_verdict([]) == "not scored"
    assert verdict([None, None]) == qualified_verdict([None]) == "not comparable"
    assert qualified_verdict([None], [True]).startswith("not comparable; ")
    assert "*not scored*: the paper prints no number" in VERDICT_RULE


def test_the_nc_clause_agrees_in_number():
    from rfmap.paper.verdicts import nc_clause

    assert nc_clause([]) == ""
    assert nc_clause([True, False]) == "1 of the 2 n/c cases is worse by Std ratio"
    assert nc_clause([True, True, False]) == "2 of the 3 n/c cases are worse by Std ratio"


def test_full_table_sets_the_methods_as_columns():
    """Every quantity measured, a row per quantity in each case's block and a column per method: as narrow as the
    paper-shaped table however many quantities there are."""
    c = _comparison()
    c.values[("a", "native")].update(network_time=0.004, alpha=(0.5, 0.25), n_flipped=2)
    lines = c.full_markdown().splitlines()
    assert lines[0] == "| case | quantity | paper | paper's method | delivered | flow solver |"
    assert lines[2:7] == ["| a | Std(ρ̃_map) | 0.08 | 0.05000 | 0.04000 | 0.01000 |",
                          "|  | flips | — | 2 | — | — |",
                          "|  | α | — | 0.5, 0.25 | — | — |",
                          "|  | time | 10.0 ms | 20.0 ms | 10.0 ms | 10.0 ms |",
                          "|  | network time | — | 4.00 ms | — | — |"]
    assert len(lines) == 2 + 2 * 5


def test_a_raw_column_and_no_empty_paper_column():
    c = _comparison()
    for name in ("a", "b"):
        del c.values[(name, "paper")]
        c.values[(name, "raw")] = {"std_rho_map": 0.5, "time": None}
    assert c.methods() == ["raw", "native", "delivered", "classical"]
    lines = c.to_markdown().splitlines()
    assert lines[0] == "| case | quantity | raw network | paper's method | delivered | flow solver |"
    assert lines[2] == "| a | Std(ρ̃_map) | 0.5000 | 0.05000 | 0.04000 | 0.01000 |"


def test_a_folded_raw_map_reads_folded_not_a_std():
    """A raw map that folds has no meaningful Std(ρ̃_map) (negative areas): its cell says how many elements fold, as
    the headline tables' ``folded_cell`` does; a refined map's Std stays a number."""
    c = _comparison()
    c.values[("a", "raw")] = {"std_rho_map": 17.8, "n_flipped": 537, "time": None}
    c.values[("a", "native")]["n_flipped"] = 2
    lines = c.to_markdown(["std_rho_map", "n_flipped"]).splitlines()
    assert lines[2] == "| a | Std(ρ̃_map) | 0.08 | folded (537 flips) | 0.05000 | 0.04000 | 0.01000 | yes |"
    assert lines[3] == "|  | flips | — | 537 | 2 | — | — |  |"


def test_side_by_side_of_a_quantity_that_is_shown_not_scored():
    a, b = _comparison(), _comparison()
    for t in (a, b):
        for name in ("a", "b"):
            for method in ("paper", "native", "classical"):
                t.values[(name, method)]["max_mu"] = 0.4
    lines = native_side_by_side({"old": a, "new": b}, "max_mu").splitlines()
    # a word joiner after each bar, so that the header never wraps between "|" and "μ"
    assert lines[0] == "| case | paper max \\|\u2060μ\\|\u2060 | old, paper's method | new, paper's method | flow solver |"
    assert lines[2] == "| a | 0.4000 | 0.4000 | 0.4000 | 0.4000 |"  # no met mark: max |mu| is not scored
    with pytest.raises(ValueError, match="differs"):
        native_side_by_side({"old": a, "new": _comparison()}, "max_mu")


def test_paper_shaped_table_with_chosen_rows_keeps_the_verdict():
    """``to_markdown(quantities)``: the rows asked for in each case's block, the met column only on scored rows."""
    c = _comparison()
    c.values[("a", "native")]["min_jacobian"] = 0.25
    lines = c.to_markdown(["std_rho_map", "min_jacobian"]).splitlines()
    assert lines[0] == "| case | quantity | paper | paper's method | delivered | flow solver | met |"
    assert lines[2] == "| a | Std(ρ̃_map) | 0.08 | 0.05000 | 0.04000 | 0.01000 | yes |"
    assert lines[3] == "|  | min det J | — | 0.2500 | — | — |  |"
    assert len(lines) == 2 + 2 * 2


def test_the_classical_lead_over_several_tables_reads_every_or_a_count():
    """The introduction's summary: on how many cases of several tables the classical solver is below the paper's
    method, and by how many times."""
    from rfmap.paper.verdicts import classical_lead, times_lower

    a, b = _comparison(), _comparison()
    assert classical_lead([t.classical_better("std_rho_map") for t in (a, b)], "density") == "every density"
    ratios = [t.value(c.name, "native", "std_rho_map") / t.value(c.name, "classical", "std_rho_map")
              for t in (a, b) for c in t.cases]
    assert times_lower(ratios) == "3 to 5 times lower than"  # 0.06 / 0.02 and 0.05 / 0.01
    b.values[("b", "classical")]["std_rho_map"] = 0.07  # above the paper's method's 0.06
    assert classical_lead([t.classical_better("std_rho_map") for t in (a, b)], "density") == "3 of 4 densities"


def test_a_table_of_unscored_quantities_has_no_empty_columns():
    """Rows the paper does not report (flips, the network's grid) get no paper column and no verdict column; a
    table with a scored metric keeps both."""
    cases = [Case("sin-cos", "sin-cos", 9)]
    c = Comparison("tab:population_test", "t", ["std_rho_map"], cases, "flow solver")
    c.values[("sin-cos", "paper")] = {"std_rho_map": 0.08}
    for method in ("native", "delivered", "classical"):
        c.values[("sin-cos", method)] = {"std_rho_map": 0.07, "n_flipped": 0, "time": 0.01}
    details = c.to_markdown(["n_flipped"]).splitlines()
    assert details[0] == "| case | quantity | paper's method | delivered | flow solver |"
    assert all(line.count("|") == 6 for line in details)
    assert c.to_markdown().splitlines()[0] == "| case | quantity | paper | paper's method | delivered | flow solver | met |"


def test_fig10_checks_answer_yes_no_or_tie_for_the_second_model():
    from types import SimpleNamespace

    from rfmap.paper.verdicts import fig10_checks, fig10_text

    values = {("DEM", "raw"): (5, 0.5), ("DEQ", "raw"): (3, 0.5), ("DEM", "native"): (0, 0.3),
              ("DEQ", "native"): (2, 0.28), ("DEM", "delivered"): (0, 0.3), ("DEQ", "delivered"): (0, 0.31)}
    table = SimpleNamespace(cases=[SimpleNamespace(name="DEM"), SimpleNamespace(name="DEQ")],
                            values={k: {"n_flipped": f, "mean_mu": mu} for k, (f, mu) in values.items()})
    answers = {m: [word for word, *_ in fig10_checks(table, m).values()] for m in ("raw", "native", "delivered")}
    assert answers == {"raw": ["yes", "tie"], "native": ["no", "yes"], "delivered": ["tie", "no"]}
    assert fig10_checks(table, "native")["fewer folded triangles"] == ("no", 2, 0)
    text = fig10_text(table)
    assert "DEQ map against DEM map, the paper's method:\n  fewer folded triangles: no (2 against 0)" in text
    assert text.count("map against") == 3
