"""The reproduction helpers: published tables, table output, and the experiment runners on tiny models."""
import csv
import io
from dataclasses import replace

import numpy as np
import pytest
import torch

from rfmap.paper.reproduce import beltrami_table, population_table, resolution_table
from rfmap.paper.tables import Table, format_value, paper_table
from rfmap.surrogate import Surrogate
from rfmap.tasks import TaskSpec


def test_paper_tables_cover_every_table_label():
    for label in ["tab:reconstruction_results_mu", "tab:reconstruction_results_res", "tab:population_test",
                  "tab:population_test_fb", "tab:resolution_test", "tab:3d_population_test",
                  "tab:3d_population_test_fb", "tab:3d_resolution_test"]:
        t = paper_table(label)
        assert len(t["rows"]) == 4
        for row in t["rows"].values():
            assert set(t["columns"]) <= set(row)
    assert paper_table("tab:population_test")["rows"]["sin-cos"]["std_rho_map"] == pytest.approx(0.082541)
    with pytest.raises(ValueError, match="unknown paper table"):
        paper_table("tab:nope")


def test_table_markdown_and_csv_roundtrip(tmp_path):
    t = Table("tab:x_y", "title", ["time", "n_flipped", "alpha"])
    t.add("a", "ours", {"time": 0.5, "n_flipped": 0, "alpha": [1.0, 1.2]})
    t.add("a", "paper", {"time": 1.0})
    md = t.to_markdown().splitlines()
    assert md[0].startswith("| case | method | time")
    assert md[2] == "| a | ours | 500 ms | 0 | (1, 1.2) |"
    assert md[3].endswith("| 1 s | — | — |")
    rows = list(csv.reader(io.StringIO(t.to_csv())))
    assert rows[0] == ["case", "method", "time", "n_flipped", "alpha"]
    assert float(rows[1][2]) == 0.5 and rows[2][3] == ""
    assert t.value("a", "ours", "n_flipped") == 0
    paths = t.save(tmp_path)
    assert [p.name for p in paths] == ["tab-x-y.md", "tab-x-y.csv"]


@pytest.mark.parametrize("value, column, text", [
    (0.0198912, "std_rho_map", "0.01989"), (2.432098, "mean_dd", "2.432"), (-0.0123456, "min_jacobian", "-0.01235"),
    (0.0123456, "time", "12.3 ms"), (2.432098, "time", "2.43 s"), (123.456, "time", "123 s"),
    (0.9997, "time", "1 s"), (0.9994, "time", "999 ms"),
    (41.237, "speedup", "41.2×"), (3, "n_flipped", "3"), (np.int64(7), "n_flipped", "7"), (None, "time", "—"),
    (1.6512e-05, "mean_dd", "1.651 × 10⁻⁵"),
])
def test_cells_have_four_significant_digits_and_times_their_unit(value, column, text):
    assert format_value(value, column) == text


def test_csv_rounds_as_the_markdown_and_keeps_seconds():
    t = Table("tab:x", "title", ["time", "std_rho_map"])
    t.add("a", "ours", {"time": 0.0123456, "std_rho_map": 0.019895123})
    rows = list(csv.reader(io.StringIO(t.to_csv())))
    assert rows[1][2:] == ["0.01235", "0.0199"]


def test_wide_tables_wrap_into_narrow_ones():
    cols = ["time", "speedup", "std_rho_orig", "std_rho_map", "min_jacobian", "n_flipped", "max_mu", "mean_mu",
            "alpha"]
    t = Table("tab:x", "title", cols)
    t.add("sin-cos", "ours", {c: 0.123456 for c in cols})
    parts = t.to_markdown().split("\n\n")
    assert len(parts) == 2
    widths = [len(part.splitlines()[0].split(" | ")) for part in parts]
    assert widths == [2 + 5, 2 + 4]  # case, method and at most six data columns each
    for part in parts:
        assert part.splitlines()[2].startswith("| sin-cos | ours |")
    assert t.to_markdown(max_columns=None).count("\n\n") == 0


def test_beltrami_table_on_untrained_model():
    sur = Surrogate.untrained(TaskSpec("beltrami", 2, "fixed"), base=4, depth=2, name="tiny")
    table, maps = beltrami_table(sur, n=17, maps=("T1",), refine=False, symmetrize=True)
    # an untrained surrogate is the identity: its error is the exact map's mean displacement, and so is that of its
    # average over the square's symmetries
    exact = maps["T1"]["exact"]
    for method in ("ours", "ours, symmetrized"):
        assert table.value("T1", method, "mean_dd") == pytest.approx(
            float(np.linalg.norm(exact.mapped_points - exact.ref_points, axis=1).mean()), rel=1e-6)
    assert maps["T1"]["ours+sym"].info["symmetrize"] == "full"
    assert table.value("T1", "LBS", "mean_dd") < 2e-3
    assert table.value("T1", "paper", "mean_dd") == pytest.approx(0.00943353)


def test_beltrami_table_refinement_rows():
    """With ``refine`` the weight-refined maps get their own rows beside the raw ones: the refined network of a
    trained-looking (random) model has the alpha it reports and a Beltrami objective no larger than the raw map's."""
    torch.manual_seed(0)
    sur = Surrogate.untrained(TaskSpec("beltrami", 2, "fixed"), base=4, depth=2, name="tiny")
    with torch.no_grad():
        sur.model.head.weight.mul_(0).add_(0.05 * torch.randn(sur.model.head.weight.shape))
    table, maps = beltrami_table(sur, n=17, maps=("T2",), refine=True, symmetrize=True)
    methods = [m for c, m, _ in table.rows if c == "T2"]
    assert {"ours", "ours + refinement", "ours, symmetrized", "ours, symmetrized + refinement"} <= set(methods)
    ref = maps["T2"]["ours+refine"]
    assert table.value("T2", "ours + refinement", "alpha") == ref.info["alpha"] and len(ref.info["alpha"]) == 2
    assert ref.info["refine_objective"] <= ref.info["refine_objective_start"] + 1e-15
    assert maps["T2"]["ours+sym+refine"].info["symmetrize"] == "full"


def test_population_and_resolution_tables_on_untrained_model():
    sur = Surrogate.untrained(TaskSpec("density", 2, "square"), base=4, depth=2, name="tiny", n_range=[9, 17])
    table, maps = population_table(sur, ["sin-cos"], n=17, refine=True)
    ours = table.value("sin-cos", "ours", "std_rho_map")
    assert ours == pytest.approx(table.value("sin-cos", "ours", "std_rho_orig"))  # identity map
    assert table.value("sin-cos", "diffusion DEM", "std_rho_map") < 0.5 * ours
    assert table.value("sin-cos", "ours + refinement", "std_rho_map") <= ours + 1e-12
    rt, _ = resolution_table(sur, ns=(9, 17), refine=False, classical=False)
    assert [c for c, m, _ in rt.rows if m == "ours"] == ["9", "17"]


def test_population_table_with_symmetrized_rows_and_summary():
    """``symmetrize`` adds the symmetrized network's rows, their speed-up against the same classical run and the
    summary's symmetrized entries; the best with symmetrization is never above the best without."""
    from rfmap import load_or_train
    from rfmap.paper.reproduce import SYM, SYM_REF, population_summary

    sur = load_or_train("deq2d-square", "ci")
    fields = ["sin-cos", "ring"]
    table, maps = population_table(sur, fields, n=17, refine=True, symmetrize="flips")
    assert {m for _, m, _ in table.rows} >= {"ours", "ours + refinement", SYM, SYM_REF, "diffusion DEM"}
    assert maps["ring"]["ours+sym"].info["symmetrize"] == "flips"
    for f in fields:
        dem_time = table.value(f, "diffusion DEM", "time")
        assert table.value(f, SYM, "speedup") == pytest.approx(dem_time / table.value(f, SYM, "time"))
        assert table.value(f, SYM_REF, "std_rho_map") != table.value(f, "ours + refinement", "std_rho_map")
    values, md = population_summary(table, fields)
    for f in fields:
        assert values[f"{f}_best_sym"] <= values[f"{f}_best"]
        assert values[f"{f}_std_sym"] == table.value(f, SYM, "std_rho_map")
    assert 0 <= values["met_sym"] <= 2 and values["speed_sym"] > 0
    assert "best with symmetrization / paper" in md.splitlines()[0] and len(md.splitlines()) == 4
    plain, md_plain = population_summary(population_table(sur, fields, n=17, refine=True)[0], fields)
    assert "met_sym" not in plain and SYM not in md_plain


def test_resolution_table_with_refinement_adds_refined_rows():
    sur = Surrogate.untrained(TaskSpec("density", 3, "square"), base=4, depth=2, name="tiny3d", n_range=[6, 8])
    rt, maps = resolution_table(sur, ns=(6, 8), refine=True, classical=False)
    assert "alpha" in rt.columns
    for n in ("6", "8"):
        raw = rt.value(n, "ours", "std_rho_map")
        assert raw == pytest.approx(rt.value(n, "ours", "std_rho_orig"))  # untrained: identity map
        assert rt.value(n, "ours + refinement", "std_rho_map") <= raw + 1e-12
        assert set(maps[n]) >= {"ours", "ours+refine"}


def test_reproduce_dem3d_writes_every_table(tmp_path, monkeypatch):
    """``rfmap reproduce dem3d`` writes the cube, free-boundary and resolution tables (Markdown and CSV) from the
    shipped models; the table builders are shrunk to one small case so this runs in seconds."""
    import rfmap.paper.reproduce as E

    pop, res = E.population_table, E.resolution_table
    monkeypatch.setattr(E, "population_table", lambda sur, refine=True, symmetrize=False: pop(
        sur, ["sin-cos-3d"], n=9, refine=refine, symmetrize=symmetrize))
    monkeypatch.setattr(E, "resolution_table", lambda sur, refine=True, symmetrize=False: res(
        sur, ns=(9,), refine=refine, symmetrize=symmetrize))
    paths = E.reproduce("dem3d", tmp_path, refine=True, symmetrize="cyclic")
    assert sorted(p.name for p in paths) == sorted(
        f"tab-{s}.{ext}" for s in ("3d-population-test", "3d-population-test-fb", "3d-resolution-test")
        for ext in ("md", "csv"))
    text = (tmp_path / "tab-3d-resolution-test.md").read_text()
    assert "ours + refinement" in text and "diffusion DEM" in text and "ours, symmetrized + refinement" in text
    assert "paper's method: native + refinement" in text  # the paper's method beside the delivered rows
    with pytest.raises(ValueError, match="unknown experiment"):
        E.reproduce("dem4d", tmp_path)


def test_refine_defaults_agree_so_a_table_by_hand_matches_rfmap_reproduce(monkeypatch, tmp_path):
    """Every table function refines by default, as ``reproduce`` (``rfmap reproduce``) does, and ``reproduce``
    hands its ``refine`` to every table it writes, so ``beltrami_table(sur)`` gives the rows of the command."""
    import inspect

    import rfmap.paper.reproduce as E

    for f in (E.beltrami_table, E.beltrami_resolution_table, E.population_table, E.resolution_table, E.reproduce):
        assert inspect.signature(f).parameters["refine"].default is True, f.__name__
    seen = []

    class Probe:
        def save(self, out):
            return []

    def record(name):
        return lambda sur, refine=None, symmetrize=False: (seen.append((name, refine)) or Probe(), None)

    for name in ("beltrami_table", "beltrami_resolution_table", "population_table", "resolution_table"):
        monkeypatch.setattr(E, name, record(name))
    monkeypatch.setattr(E, "Surrogate", type("S", (), {"pretrained": staticmethod(lambda name, device: name)}))
    for experiment in ("beltrami", "dem2d", "dem3d"):
        for refine in (True, False):
            seen.clear()
            E.reproduce(experiment, tmp_path, refine=refine)
            assert seen and all(r is refine for _, r in seen), (experiment, seen)


def test_generalization_table_compares_with_the_classical_solver_on_unseen_fields():
    """Rows per kind of field and for all of them; the classical solver equalizes the unseen densities far below
    their input variation, and the report set is not the validation set that chooses checkpoints."""
    from rfmap import load_or_train
    from rfmap.paper.generalization import generalization_table
    from rfmap.training.validation import validation_fields

    sur = load_or_train("deq2d-square", "ci")
    t = generalization_table(sur, count=4, n=17, refine=False, symmetrize=True)
    assert {c for c, _, _ in t.rows} == {"smooth", "steps", "peak", "ramp", "all"}
    assert {m for _, m, _ in t.rows} == {"ours", "ours, symmetrized", "classical (diffusion DEM)"}
    assert t.value("all", "ours, symmetrized", "mean") != t.value("all", "ours", "mean")
    assert t.value("all", "classical (diffusion DEM)", "mean") < 0.2
    assert t.value("all", "ours", "worst") >= t.value("all", "ours", "mean") > 0
    x = np.random.default_rng(0).random((20, 2))
    rep = validation_fields("density", 2, 4, stream="report")
    val = validation_fields("density", 2, 4)
    assert not np.allclose(rep[0].field(x), val[0].field(x))


def test_displacement_demand_of_an_identity_network():
    """An untrained network (zero head) is the identity map: it reaches nowhere and leaves all the non-uniformity,
    while the classical map moves points and leaves little; the ramps ask for larger moves than the training draws."""
    from rfmap.paper.generalization import displacement_demand
    from rfmap.tasks import TaskSpec

    sur = Surrogate.untrained(TaskSpec("density", 2, "square"), base=4, depth=2, name="deq2d-square", n_range=[9, 17])
    t, recs = displacement_demand(sur, count=4, train_count=3, n=17)
    assert [c for c, _, _ in t.rows] == ["training", "smooth", "steps", "peak", "ramp", "paper"]
    assert len(recs) == 3 + 4 + 4
    for r in recs:
        assert r["demand"] > 1e-3 and r["reach"] == 0.0
        assert r["left_net"] == pytest.approx(1.0, abs=1e-12) and r["left_classical"] < 0.5
    assert t.value("training", "training draws", "reach_ratio") == 0.0
    assert t.value("ramp", "ours", "demand_median") > t.value("training", "training draws", "demand_p90")
    with pytest.raises(ValueError, match="density model"):
        displacement_demand(Surrogate.untrained(TaskSpec("beltrami", 2, "fixed"), base=4, depth=2, name="beltrami2d"))


def test_recipe_table_reads_the_training_recipe_from_the_metadata():
    """The recipe table states each model's training fields, fold penalty, learning rate, budget and recorded
    validation exactly as its metadata holds them."""
    from rfmap.training.config import get_config
    from rfmap.paper.recipes import recipe_markdown, recipe_table, training_fields_text

    cfg = get_config("deq2d-square", "full").with_overrides(lr=2e-4).to_dict()
    cfg["density_field"]["ramp_scale"] = 2.5
    cfg["loss"]["fold"], cfg["loss"]["fold_threshold"] = 100.0, 0.05
    meta = {"config": cfg, "steps": 300, "cumulative_steps": 1300, "wall_time": 60.0, "cumulative_wall_time": 600.0,
            "final_metrics": {"mean": {"std_rho_map": 0.125, "n_flipped": 7, "folded_fields": 2}}}
    sur = Surrogate.untrained(TaskSpec("density", 2, "square"), base=4, depth=2, **meta)
    old = Surrogate.untrained(TaskSpec("beltrami", 2, "fixed"), base=4, depth=2, steps=5, wall_time=30.0)
    t = recipe_table({"new": sur, "old": old})
    assert t.value("new", "unet", "fields") == \
        "modes (every field), box steps 30 %, patches 20 %, noise 10 %, peaks 15 %, ramps 15 % (height ×2.5), single hard ramps or peaks 30 %"
    assert t.value("new", "unet", "fold") == "100 from 0.05"
    assert t.value("new", "unet", "lr") == 2e-4 and t.value("new", "unet", "ema") is None
    sur.meta["config"]["ema"] = 0.999
    assert recipe_table({"new": sur}).value("new", "unet", "ema") == 0.999
    assert t.value("new", "unet", "steps") == 1300 and t.value("new", "unet", "train_time") == 10.0
    assert t.value("new", "unet", "val_n") == "51/128"
    assert t.value("new", "unet", "held_out") == 0.125 and t.value("new", "unet", "folded_maps") == 2
    assert t.value("new", "unet", "scored") == "raw"
    assert t.value("old", "unet", "fields") is None and t.value("old", "unet", "steps") == 5
    # the selection score where the metadata records it: a folded map counted as the identity, not its huge Std
    sur.meta["final_metrics"]["mean"].update({"std_rho_map": 40.0, "capped": 0.2, "penalized": 0.25})
    assert recipe_table({"new": sur}).value("new", "unet", "held_out") == 0.25
    assert recipe_table({"new": sur}).value("new", "unet", "score_kind") == "mean Std, folds as identity"
    # the family score of Std ratios, where recorded, is the score that chose the weights
    sur.meta["final_metrics"]["mean"]["family_score"] = 0.4
    by_family = recipe_table({"new": sur})
    assert by_family.value("new", "unet", "held_out") == 0.4
    assert "| new | 51/128 | 0.4 | Std ratio by family |" in recipe_markdown(by_family)
    # every part of the table is followed by the legend of its columns
    from rfmap.paper.recipes import RECIPE_LEGENDS
    md = recipe_markdown(by_family)
    assert all(legend in md for legend in RECIPE_LEGENDS.values()) and "*folded maps*" in md
    del sur.meta["final_metrics"]["mean"]["family_score"]
    # scored on the default maps (val_repair): the maps the network itself folded are counted apart
    sur.meta["final_metrics"]["mean"].update({"folded_fields": 0, "path": "repaired", "raw_folded_fields": 3})
    again = recipe_table({"new": sur})
    assert again.value("new", "unet", "scored") == "default" and again.value("new", "unet", "folded_maps") == 3
    assert "| new | unet | modes (every field), box steps" in t.to_markdown()
    bel = get_config("beltrami2d", "full")
    for low, text in ((0.0, "coefficients of random maps that fix the boundary"),
                      (0.3, "coefficients of random maps that fix the boundary; 30 % of them low-frequency "
                            "(a few slow modes)")):
        cfg = bel.with_overrides(beltrami_field=replace(bel.beltrami_field, low=low))
        assert training_fields_text(cfg.to_dict()) == text
    for name in ("dem3d-free", "dem3d-cube"):
        assert training_fields_text(get_config(name, "full").to_dict()) == \
            "modes (every field), box steps 30 %, patches 20 %, noise 10 %, peaks 15 %, ramps 15 %, single hard ramps or peaks 15 %"
    for name in ("deq2d-square", "deq2d-free", "dem2d-square"):
        assert training_fields_text(get_config(name, "full").to_dict()) == \
            "modes (every field), box steps 30 %, patches 20 %, noise 10 %, peaks 15 %, ramps 15 %, single hard ramps or peaks 30 %"


def test_distortion_table_puts_models_side_by_side_on_unseen_fields():
    """The identity network leaves every field as it came (Std of the input, |mu| = 0, ratio 0 against the reference
    model); the reference's own ratio is exactly 1; a Beltrami or 3D model is refused."""
    from rfmap import load_or_train
    from rfmap.paper.generalization import distortion_table
    from rfmap.tasks import TaskSpec

    ci = load_or_train("deq2d-square", "ci")
    ident = Surrogate.untrained(TaskSpec("density", 2, "square"), base=4, depth=2, name="deq2d-square",
                                n_range=[9, 17])
    t = distortion_table({"trained": ci, "identity": ident}, count=4, n=17)
    assert [(c, m) for c, m, _ in t.rows][-2:] == [("all", "trained"), ("all", "identity")]
    assert {c for c, _, _ in t.rows} == {"smooth", "steps", "peak", "ramp", "all"}
    assert t.value("all", "trained", "mu_ratio") == pytest.approx(1.0, abs=1e-12)
    assert t.value("all", "identity", "mean_mu") == pytest.approx(0.0, abs=1e-6)
    assert t.value("all", "identity", "mu_ratio") == pytest.approx(0.0, abs=1e-5)
    assert t.value("all", "trained", "mean_mu") > 1e-3
    assert t.value("all", "trained", "std_rho_map") < t.value("all", "identity", "std_rho_map")
    with pytest.raises(ValueError, match="2D density"):
        distortion_table({"b": load_or_train("beltrami2d", "ci")}, count=4, n=17)
    with pytest.raises(ValueError, match="at least one"):
        distortion_table({}, count=4)


def test_the_classical_solver_is_timed_like_the_surrogate(monkeypatch):
    """Warm-up, then the fastest of three runs; a single timed run when the warm-up was slow."""
    import rfmap.solvers as solvers
    from rfmap.paper.reproduce import _classical

    real, times = solvers.solve_dem, iter([0.5, 0.2, 0.3, 0.9])
    calls = []

    def fake(density, **kw):
        calls.append(kw)
        res = real(density, **kw)
        res.time = next(times)
        return res

    monkeypatch.setattr(solvers, "solve_dem", fake)
    res = _classical("sin-cos", 11, "square")
    assert len(calls) == 4 and res.time == 0.2  # the warm-up's 0.5 is not among the candidates
    calls.clear()
    times = iter([0.5, 0.7])
    assert _classical("sin-cos", 11, "square", slow=0.0).time == 0.7 and len(calls) == 2


@pytest.mark.parametrize("value, text", [
    (0.0198912, "0.0199"), (2.432098, "2.43"), (3.814e-05, "3.81 × 10⁻⁵"), (123456.0, "1.23 × 10⁵"), (0.0, "0"),
    (7, "7"), (None, "—"), (float("nan"), "—"), (12345.0, "12,300"), (1234.5, "1,230"), (999.5, "1,000"),
])
def test_headline_numbers_have_three_significant_digits_and_small_ones_a_power_of_ten(value, text):
    from rfmap.paper.tables import format_sig
    assert format_sig(value) == text


def test_headline_counts_met_cases_and_leaves_missing_paper_values_out():
    from rfmap.paper.tables import headline
    h = headline("t", "Std", {"a": 0.04, "b": 0.06, "c": 0.05}, {"a": 0.05, "b": 0.05}, {"a": 0.01})
    assert (h.met, h.compared) == (1, 2)
    md = h.to_markdown()
    assert "| a | 0.04 | 0.05 | 0.01 | 0.8× | yes |" in md and "| b | 0.06 | 0.05 | — | 1.2× | no |" in md
    assert "| c | 0.05 | — | — | — | — |" in md
    higher = headline("t", "speed-up", {"a": 2.0}, {"a": 1.5}, lower_is_better=False)
    assert higher.met == 1


def test_population_headline_counts_as_the_summary():
    from rfmap.paper.reproduce import population_headline, population_summary
    t = Table("tab:x", "t", ["std_rho_map", "n_flipped", "speedup", "time"])
    for f, (o, r, d, p) in {"a": (0.05, 0.04, 0.01, 0.045), "b": (0.06, 0.07, 0.02, 0.05)}.items():
        for m, v in (("ours", o), ("ours + refinement", r), ("diffusion DEM", d), ("paper", p)):
            t.add(f, m, {"std_rho_map": v, "n_flipped": 0, "speedup": 2.0, "time": 0.1})
    h = population_headline(t, ["a", "b"], "t")
    values, _ = population_summary(t, ["a", "b"])
    assert h.met == values["met"] == 1
    assert [r[1] for r in h.rows] == [0.04, 0.06] and [r[3] for r in h.rows] == [0.01, 0.02]


def test_a_range_or_a_change_whose_ends_print_alike_is_said_as_one_value():
    from rfmap.paper.tables import change_text, span_text

    assert span_text(0.4123, 0.5712) == "0.412 to 0.571" and span_text(0.19234, 0.19231) == "0.192"
    assert span_text(5.04, 5.1, ".2g") == "5 to 5.1" and span_text(5.14, 5.1, ".2g") == "5.1"
    assert change_text(1.08313, 0.11620) == "goes from 1.083 to 0.1162"
    assert change_text(0.00012, 0.00003) == "goes from 1.200 × 10⁻⁴ to 3.000 × 10⁻⁵"  # never "to 0.0000"
    assert change_text(1.08313, 0.11620, ".4f") == "goes from 1.0831 to 0.1162"
    assert change_text(0.192344, 0.192305) == "stays at 0.1923 (to the digits shown)"


def test_agreement_text_says_identical_for_zero_and_never_uses_e_notation():
    from rfmap.paper.tables import agreement_text

    assert agreement_text(0.0) == agreement_text(-0.0) == "identical (largest difference 0)"
    assert agreement_text(2.384e-08) == "equal to within 2.4 × 10⁻⁸"
    assert agreement_text(0.0123) == "equal to within 0.012"
