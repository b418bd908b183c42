"""Tests of :mod:`rfmap.training.records`: study files from training logs, budgets over a chain, the quoted example."""
from __future__ import annotations

import json

import pytest

from rfmap.training import records as S


def _log(path, records):
    path.mkdir(parents=True)
    (path / "log.jsonl").write_text("\n".join(json.dumps(r) for r in records) + "\n")


def _val(step, elapsed, score, final=False, selected=None):
    rec = {"step": step, "elapsed": elapsed,
           "validation": {"mean": {"family_score": score, "families": {"smooth": score, "ramp": score},
                                   "folded_fields": 0}}}
    if final:
        rec.update(final=True, selected_step=selected)
    return rec


def test_collect_reads_curves_and_keeps_the_final_point_only_for_the_last_state(tmp_path):
    _log(tmp_path / "a", [{"step": 10, "loss": 1.0, "elapsed": 5.0}, _val(10, 6.0, 0.5), _val(20, 12.0, 0.4),
                          {"step": 25, "loss": 0.5, "elapsed": 14.0}, _val(25, 15.0, 0.45, True, 20)])
    _log(tmp_path / "b", [_val(10, 6.0, 0.7), {"step": 12, "loss": 1.0, "elapsed": 8.0}, _val(12, 9.0, 0.6, True, 12)])
    out = S.collect("t", {"A": tmp_path / "a", "B": tmp_path / "b"}, description="d", commands={"A": "x"},
                    out=tmp_path / "t.json")
    data = json.loads(out.read_text())
    a, b = data["runs"]["A"], data["runs"]["B"]
    assert a["step"] == [10, 20] and a["score"] == [0.5, 0.4]  # the final record scores step 20's state: skipped
    assert b["step"] == [10, 12] and b["total_steps"] == 12 and b["total_time"] == 9.0
    v = S.study_values(data)
    assert v["winner"] == "A" and v["margin"] == pytest.approx(0.6 / 0.4) and v["run1_steps"] == 12
    assert v["run0_best_at_end"] and v["run1_best_at_end"] and v["still_improving"]  # both best at the end
    # per step: B stopped at step 12 (score 0.6); A's score there lies between its 0.5 at 10 and 0.4 at 20
    assert v["short_label"] == "B" and v["short_step"] == 12 and v["short_score"] == 0.6
    assert v["long_at_short"] == pytest.approx(0.48)
    data["runs"]["B"]["score"] = [0.6, 0.7]
    v = S.study_values(data)
    assert v["run0_best_at_end"] and not v["run1_best_at_end"] and not v["still_improving"]
    table = S.study_table(data)
    assert table.loc["A", "at step"] == 20 and table.loc["B", "best score"] == 0.6
    # two narrower tables for a page: the runs' scores, then the families at the best state
    runs, families = S.study_table(data, "runs"), S.study_table(data, "families")
    assert list(runs.columns) + list(families.columns) == list(table.columns)
    assert list(runs.columns)[-1] == "last score"
    assert list(families.columns) == ["smooth (best)", "ramp (best)", "folded (best)"]
    with pytest.raises(ValueError, match="part"):
        S.study_table(data, "scores")


def test_training_budget_counts_every_run_of_a_chain():
    meta = {"steps": 100, "wall_time": 360.0, "command": "rfmap train --config x --batch 4",
            "cumulative_steps": 300, "cumulative_wall_time": 7200.0,
            "lineage": [{"steps": 150, "command": "rfmap train --config x"},
                        {"steps": 50, "command": "rfmap train --config x --batch 8 --init x"}]}
    b = S.training_budget(meta, preset_batch=2)
    assert b == {"runs": 3, "steps": 300, "samples": 150 * 2 + 50 * 8 + 100 * 4, "hours": 2.0}
    assert S.teacher_of({"config": {"teacher": {"method": "flow", "weight": 0.1}}}) == "flow"
    assert S.teacher_of({"config": {}}) == "none"


def test_example_field_meets_whenever_a_field_does():
    values = {"a_best": 0.08, "a_std_paper": 0.07, "b_best": 0.12, "b_std_paper": 0.28, "c_best": 0.2,
              "c_std_paper": 0.1}
    ex = S.example_field(values, ["a", "b", "c"])
    assert ex["field"] == "b" and ex["verb"] == "meets"
    ex = S.example_field(values, ["a", "c"])
    assert ex["field"] == "a" and ex["verb"] == "misses" and ex["ratio"] == pytest.approx(0.08 / 0.07)


def test_to_markdown_formats_integers_and_small_numbers():
    import pandas as pd

    df = pd.DataFrame({"steps": [3190, 900], "score": [0.44344, 3.8e-05], "run": ["x", "y"]}).set_index("run")
    md = S.to_markdown(df)
    assert "| x | 3,190 | 0.443 |" in md and "| y | 900 | 3.80 × 10⁻⁵ |" in md


def test_stored_studies_load_and_unknown_ones_are_refused():
    for name in S.study_names():
        study = S.load_study(name)
        assert study["runs"] and all(r["score"] for r in study["runs"].values())
    with pytest.raises(ValueError, match="unknown study"):
        S.load_study("no-such-study")


def test_budget_markdown_marks_the_fields_of_a_shrinking_batch_as_an_upper_bound():
    import pandas as pd

    metas = {"a": {"config": {"batch": 4}}, "b": {"config": {"batch": 8, "batch_points": 20000}}}
    assert S.shrinking_batches(metas) == ["b"]
    budget = pd.DataFrame({"model": ["a", "b"], "steps": [100, 200], "× fields, assumed batch": [0.5, 23.41]}
                          ).set_index("model")
    lines = S.budget_markdown(budget, metas, ["steps", "× fields, assumed batch"]).splitlines()
    assert lines[2] == "| a | 100 | 0.5 |"
    assert lines[3] == "| b | 200 | ≤ 23.4 |"
