"""The validation-record readers of rfmap.paper.compare, on small hand-made records."""
from rfmap.paper.compare import budget_folds, kept_state, learning_summary, shipped_raw_folds, validated_states


def _v(step, mean, folded=0, score=None, jac=0.1):
    v = {"step": step, "std_rho_map": mean, "folded_fields": folded, "n_flipped": 5 * folded, "min_jacobian": jac,
         "elapsed": float(step)}
    if score is not None:
        v["family_score"] = score
    return v


def _meta(hist, kept, final):
    return {"history": {"validation": hist}, "selected_step": kept, "final_metrics": final}


def test_the_repeated_last_step_counts_once():
    kept = _v(2, 0.3, folded=1, score=0.4)
    meta = _meta([_v(1, 0.2, score=0.5), kept, _v(3, 0.5, folded=2, score=0.45), {**kept, "step": 3}], 2,
                 {"mean": kept, "ramp-3@128": {"n_flipped": 7}, "smooth-0@51": {"n_flipped": 0}})
    assert [v["step"] for v in validated_states(meta)] == [1, 2, 3]
    k = kept_state(meta)
    assert k["rule"] == "checkpoint score" and k["step"] == 2 and k["folds"] == [("ramp-3", 128, 7)]
    assert (k["fold_free_step"], k["fold_free_mean"], k["fold_free_score"]) == (1, 0.2, 0.5)


def test_an_old_record_s_closing_re_evaluation_is_not_a_state():
    kept = _v(2, 0.3)
    meta = _meta([_v(1, 0.6, folded=1), kept, _v(3, 0.2, folded=1), {**kept, "step": 4}], 2, {"mean": kept})
    assert [v["step"] for v in validated_states(meta)] == [1, 2, 3]
    s = learning_summary(meta, last=2)
    assert s["states"] == 3 and s["folded"] == 2 and s["fold_free_steps"] == [2]
    assert s["last_steps"] == [2, 3] and s["best_step"] == 3
    k = kept_state(meta)
    assert k["rule"] == "fold-free mean" and k["folds"] == [] and k["fold_free_step"] == 2
    assert k["score"] is None and k["fold_free_score"] is None


def test_a_record_with_the_mean_counting_folds_as_identity_names_the_earlier_rule():
    kept = {**_v(2, 0.3, folded=1), "penalized": 0.35}
    meta = _meta([_v(1, 0.4), kept], 2, {"mean": kept})
    k = kept_state(meta)
    assert k["rule"] == "earlier rule" and k["score"] is None and k["fold_free_step"] == 1
    from rfmap.paper.compare import kept_rules

    text = kept_rules({"U-Net": k})
    assert text.startswith("Every kept step was chosen by the earlier rule.")
    assert "a folded map counted as the identity: step 2, plain held-out mean 0.300" in text


def test_the_rules_text_says_what_the_fold_free_rule_keeps():
    from rfmap.paper.compare import kept_rules

    scored = {"step": 5000, "rule": "checkpoint score", "mean": 0.251, "folds": [("ramp-3", 128, 208)],
              "fold_free_step": 4000, "fold_free_mean": 0.224, "fold_free_score": 0.348, "score": 0.337}
    old = {"step": 2500, "rule": "fold-free mean", "mean": 0.308, "folds": [], "fold_free_step": 2500,
           "fold_free_mean": 0.308, "fold_free_score": None, "score": None}
    text = kept_rules({"U-Net": scored, "FNO": old})
    assert text.startswith("The kept steps were chosen by different rules.")
    assert "ramp-3 at N = 128, 208 flipped triangles" in text
    assert "The FNO's rule would have kept the U-Net's step 4,000" in text and "0.348 against 0.337" in text
    same = kept_rules({"U-Net": {**scored, "folds": [], "fold_free_step": 5000}})
    assert same.startswith("Every kept step was chosen by the checkpoint score.") and "would have" not in same


def test_learning_texts_name_steps_not_counts():
    from types import SimpleNamespace

    from rfmap.paper.compare import learning_verdict

    kept = _v(2, 0.3)
    meta = _meta([_v(1, 0.6, folded=1), kept, _v(3, 0.4, folded=1), _v(4, 0.5), {**kept, "step": 4}], 2,
                 {"mean": kept})
    learn = {"A": learning_summary(meta, last=3)}
    text = learning_verdict(learn, {"A": SimpleNamespace(meta={**meta, "steps": 4})})
    assert text == ("The A may still have been improving: its lowest plain mean, 0.300, came at step 2, among its"
                    " last three validations.")
    text = learning_verdict(learn, {"A": SimpleNamespace(meta={**meta, "steps": 5})})
    assert text.endswith("The A's record holds no validation of its last step, 5, so its curve ends at step 4.")
    flat = {**learn["A"], "improving": False}
    surs = {k: SimpleNamespace(meta={**meta, "steps": 4}) for k in "AB"}
    assert learning_verdict({"A": flat, "B": flat}, surs) == (
        "In this one run per network, neither reached a lower plain mean after its lowest: the A's lowest plain mean,"
        " 0.300, came at step 2 and the B's, 0.300, at step 2, each before its last three validations, which range from 0.300 to 0.500"
        " and from 0.300 to 0.500.")
    one = learning_verdict({"A": flat, "B": learn["A"]}, surs)
    assert one.startswith("The A reached no lower plain mean after its lowest in its run: its lowest plain mean,")


def test_the_model_table_names_each_configuration_and_prints_as_the_prose():
    from rfmap.nn import MultiResUNet
    from rfmap.paper.compare import model_table
    from rfmap.surrogate import Surrogate
    from rfmap.tasks import TaskSpec

    final = {"mean": {"std_rho_map": 0.2514, "penalized": 0.2201, "family_score": 0.3374}}
    meta = {"name": "unet-x", "selected_step": 5000, "wall_time": 2687.0, "final_metrics": final}
    sur = Surrogate(MultiResUNet(2, 1, 4, 2), TaskSpec("density", 2, "square"), meta)
    md = model_table({"U-Net": sur, "long U-Net": sur}).to_markdown()
    head, _, one, two = md.splitlines()
    assert head.startswith("| model | configuration | parameters | kept step | training (min) | held-out mean |")
    assert one.startswith("| U-Net | unet-x | ") and one.endswith("| 5,000 | 44.8 | 0.251 | 0.220 | 0.337 |")
    assert two.startswith("| long U-Net | unet-x (U-Net) |")


def test_shipped_raw_folds_reads_the_raw_flag_where_the_repaired_map_was_validated():
    repaired = {"final_metrics": {"mean": {}, "a": {"n_flipped": 0, "raw_folded": True},
                                  "b": {"n_flipped": 0, "raw_folded": False}}}
    raw = {"final_metrics": {"mean": {}, "a": {"n_flipped": 12}, "b": {"n_flipped": 0}, "c": {"n_flipped": 1}}}
    assert shipped_raw_folds(repaired) == (1, 2)
    assert shipped_raw_folds(raw) == (2, 3)
    assert shipped_raw_folds({}) == (0, 0)


def test_budget_folds_counts_raw_folds_and_the_shipped_step_over_the_chain():
    """A record that validated the repaired map counts its raw folds, not the repaired map's none; the shipped step
    is counted over the whole chain; a step validated twice counts once."""
    repaired = [dict(_v(0, 0.3), raw_folded_fields=2), dict(_v(50, 0.2), raw_folded_fields=0),
                dict(_v(100, 0.25), raw_folded_fields=1), dict(_v(100, 0.25), raw_folded_fields=1)]
    metas = {"cube": {"steps": 100, "cumulative_steps": 1100, "selected_step": 50,
                      "history": {"validation": repaired},
                      "final_metrics": {"mean": {}, "a": {"raw_folded": True}, "b": {"raw_folded": False}}},
             "square": {"steps": 200, "selected_step": 200,
                        "history": {"validation": [_v(100, 0.4, folded=1), _v(200, 0.3)]}}}
    t = budget_folds(metas, {"cube": 500, "square": 1000})
    assert t.loc["cube", "steps spent"] == 1100 and t.loc["cube", "shipped at step"] == 1050
    assert t.loc["cube", "validated states whose raw map folds"] == "2 of 3"
    assert t.loc["cube", "validation fields on which the shipped raw map folds"] == "1 of 2"
    assert t.loc["square", "shipped at step"] == 200 and t.loc["square", "paper's epochs"] == 1000
    assert t.loc["square", "validated states whose raw map folds"] == "1 of 2"
    assert t.loc["square", "validation fields on which the shipped raw map folds"] == "0 of 0"
