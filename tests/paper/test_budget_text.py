"""The sentences of appendix C's budget section (rfmap.paper.budget_text), on small hand-made records."""
from rfmap.paper.budget_text import (budget_glue, budget_sentences, fold_states_text, kept_early_text,
                                     names_text, raw_folds_text, scored_text, times_text)


def _v(step, folded=0, **extra):
    return {"step": step, "std_rho_map": 0.3 + 0.01 * step, "folded_fields": folded, "n_flipped": 5 * folded, **extra}


def test_names_and_multiples_read_as_a_sentence_prints_them():
    assert [names_text(n) for n in ([], ["a"], ["a", "b"], ["a", "b", "c"])] == [
        "none", "a", "a and b", "a, b and c"]
    assert (times_text(25.51), times_text(4.43), times_text(0.5)) == ("25.5", "4.4", "0.5")


def test_budget_sentences_name_the_models_short_of_the_paper_and_the_others_spread():
    out = budget_sentences({"a": 4400, "b": 25510, "c": 500}, {"a": 1000, "b": 1000, "c": 1000})
    assert out["budget_text"] == ("Every model except c made more steps than the paper's epochs, read as steps, "
                                  "from 4.4 to 25.5 times as many; c made 50 % of the paper's 1,000.")
    assert out["budget_summary"] == "every model but c ran past the paper's epochs, by 4.4 to 25.5 times"
    assert budget_sentences({"a": 2000}, {"a": 1000})["budget_summary"] == (
        "every model ran past the paper's epochs, by 2 times")


def test_kept_early_names_the_models_shipping_an_earlier_state_or_their_start():
    metas = {"a": {"steps": 100, "selected_step": 0}, "b": {"steps": 100, "selected_step": 100}}
    assert kept_early_text(metas) == (
        "For a the shipped state comes before the end of the last run, so the shipped weights hold fewer steps "
        "than the chain spent. For a it is the state the last run started from: that run never improved on the "
        "weights it continued from, and those weights were shipped.")
    assert kept_early_text({"b": metas["b"]}) == "Every model ships the last state of its last run."


def test_raw_folds_count_each_folding_model_and_the_rest_in_words():
    assert raw_folds_text({"a": (0, 4), "b": (0, 4)}) == (
        "The raw map of no shipped model folds on its validation fields.")
    assert raw_folds_text({"x": (1, 8), "y": (3, 8), "a": (0, 8), "b": (0, 8)}) == (
        "The raw map of the shipped weights folds on 1 of 8 validation fields for x and 3 of 8 for y, "
        "and on none for the other two models.")


def test_fold_states_sort_models_into_every_no_and_some_states():
    def meta(*folds):
        return {"history": {"validation": [_v(i + 1, f) for i, f in enumerate(folds)]}, "selected_step": 1}

    text = fold_states_text({"a": meta(1, 1), "b": meta(0, 0), "c": meta(1, 0)})
    assert text == ("The raw map of a folded on some validation field at every validated state of the last run; "
                    "the raw map of b folded at no validated state; that of the other model at some states "
                    "only.")


def test_scored_text_names_the_runs_that_scored_the_repaired_map():
    raw = {"history": {"validation": [_v(1, family_score=0.4)]}}
    cube = {"history": {"validation": [_v(1, raw_folded_fields=1)]}}
    assert scored_text({"a": raw}) == ""
    assert scored_text({"a": raw, "cube": cube}).startswith("The runs of cube scored the map a user gets by default")
    assert scored_text({"a": raw, "cube": cube}).endswith("a folded map counting as the identity.")


def test_budget_glue_holds_every_key_the_appendix_quotes():
    metas = {"dem3d-cube": {"steps": 10, "selected_step": 10, "final_metrics": {"mean": {}, "f": {"n_flipped": 2}},
                            "history": {"validation": [_v(10, 1)]}}}
    out = budget_glue(metas, {"dem3d-cube": 20}, {"dem3d-cube": 10})
    assert set(out) == {"budget_text", "budget_summary", "kept_early", "budget_fold_text", "budget_fold_dem3d-cube",
                        "budget_states_text", "budget_scored_text"}
    assert out["budget_fold_dem3d-cube"] == "1 of 1"
