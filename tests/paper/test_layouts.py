"""The book's layouts of the paper tables: headlines and whole tables narrow enough for the text column."""
import pytest

from rfmap.paper.generalization import generalization_summary
from rfmap.paper.reproduce import SYM, SYM_REF, beltrami_headline, cases_markdown, population_headline
from rfmap.paper.tables import Table


def _beltrami():
    t = Table("tab:reconstruction_results_mu", "x", ["time", "speedup", "mean_dd", "n_flipped", "alpha"])
    for case, (o, r, s, lbs, paper) in {"T1": (0.05, 0.04, 0.03, 1e-4, 0.045), "T2": (0.02, 0.03, 0.01, 2e-5,
                                                                                       0.01)}.items():
        t.add(case, "ours", {"time": 0.009, "speedup": 0.4, "mean_dd": o, "n_flipped": 0})
        t.add(case, "ours + refinement", {"time": 0.3, "speedup": 0.01, "mean_dd": r, "n_flipped": 0,
                                          "alpha": (1.01, 0.99)})
        t.add(case, SYM, {"time": 0.05, "speedup": 0.1, "mean_dd": s, "n_flipped": 0})
        t.add(case, "LBS", {"time": 0.004, "mean_dd": lbs, "n_flipped": 0})
        if case == "T1":
            t.add(case, "paper", {"time": 0.18, "mean_dd": paper})
    return t


def test_beltrami_headline_takes_the_best_delivered_row():
    t = _beltrami()
    h = beltrami_headline(t, ["T1", "T2"], "t")
    assert [r[1] for r in h.rows] == [0.04, 0.02] and [r[3] for r in h.rows] == [1e-4, 2e-5]
    assert [r[2] for r in h.rows] == [0.045, None] and (h.met, h.compared) == (1, 1)
    assert [r[1] for r in beltrami_headline(t, ["T1", "T2"], "t", symmetrized=True).rows] == [0.03, 0.01]


def test_cases_markdown_gives_a_table_per_case_at_three_digits():
    md = cases_markdown(_beltrami(), "map")
    tables = [p for p in md.split("\n\n") if p.startswith("|")]
    assert [p.split(" |")[0] for p in tables] == ["| map T1", "| map T2"]
    head, _, *rows = tables[0].splitlines()
    assert head == "| map T1 | ours | + refinement | symmetrized | LBS | paper |"
    assert len(head.split(" | ")) <= 7
    assert "| mean \\|Δd\\| | 0.05 | 0.04 | 0.03 | 1.00 × 10⁻⁴ | 0.045 |" in rows
    assert "| time | 9 ms | 300 ms | 50 ms | 4 ms | 180 ms |" in rows
    assert "| α | — | 1.01, 0.99 | — | — | — |" in rows


def test_generalization_summary_compares_the_best_surrogate_with_the_solver():
    t = Table("tab:g", "g", ["mean", "worst", "n_flipped", "time"])
    for kind, scale in (("smooth", 1.0), ("all", 2.0)):
        for method, v in (("ours", 0.04), ("ours + refinement", 0.03), (SYM_REF, 0.02),
                          ("classical (diffusion DEM)", 0.01)):
            t.add(kind, method, {"mean": v * scale, "worst": v, "n_flipped": 0, "time": 0.1})
    lines = generalization_summary(t).splitlines()
    assert lines[2] == ("| fields | ours | + refinement | symmetrized + refinement | diffusion DEM "
                        "| best ours / classical |")
    assert lines[4] == "| smooth | 0.04 | 0.03 | 0.02 | 0.01 | 2× |"
    t.add("tiny", "ours", {"mean": 0.00112})  # one power of ten in a row: the whole row in that notation
    t.add("tiny", "classical (diffusion DEM)", {"mean": 6.46e-5})
    row = generalization_summary(t).splitlines()[-1]
    assert row == "| tiny | 1.12 × 10⁻³ | — | — | 6.46 × 10⁻⁵ | 17.3× |"


def test_population_headline_of_a_table_without_refinement_or_paper_rows():
    t = Table("tab:resolution_test", "t", ["std_rho_map"])
    for n, (o, d) in {"17": (0.05, 0.01), "32": (0.04, 0.02)}.items():
        t.add(n, "ours", {"std_rho_map": o})
        t.add(n, "diffusion DEM", {"std_rho_map": d})
    t.add("32", "paper", {"std_rho_map": 0.045})
    h = population_headline(t, ["17", "32"], "t")
    assert [r[1:] for r in h.rows] == [(0.05, None, 0.01), (0.04, 0.045, 0.02)]
    assert (h.met, h.compared) == (1, 1)
