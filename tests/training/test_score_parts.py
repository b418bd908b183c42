"""rfmap.training.validation.score_parts: which entry of a validation summary ranks it, and score() agrees."""
import pytest

from rfmap.paper.recipes import _selection
from rfmap.training.validation import score, score_parts


@pytest.mark.parametrize("summary,expected,label", [
    ({"std_rho_map": 0.2, "family_score": 0.4, "penalized": 0.3}, (0, 0.4, "family_score"), "Std ratio by family"),
    ({"mean_dd": 1e-3, "penalized": 2e-3}, (0, 2e-3, "penalized"), "mean |Δd|, folds as identity"),
    ({"std_rho_map": 0.2, "penalized": 0.3}, (1, 0.3, "penalized"), "mean Std, folds as identity"),
    ({"std_rho_map": 0.2, "folded_fields": 0}, (1, 0.2, "mean"), "mean Std"),
    ({"std_rho_map": 0.2, "folded_fields": 1, "capped": 0.5}, (2, 0.5, "capped"), "mean Std, folds as identity"),
    ({"std_rho_map": 0.2, "n_flipped": 3}, (2, 0.2, "mean"), "mean Std"),
])
def test_score_parts_names_the_entry_that_ranks_a_summary(summary, expected, label):
    assert score_parts(summary) == expected
    assert score(summary) == expected[:2]
    assert _selection(summary) == (expected[1], label)


def test_a_summary_without_metrics_has_no_selection_score():
    assert _selection({}) == (None, None)
    assert _selection({"folded_fields": 0}) == (None, None)


def test_has_folds_reads_the_raw_map_only_when_asked():
    """A summary that scored the repaired map records no folds of its own but counts the raw map's apart."""
    from rfmap.training.validation import has_folds

    repaired = {"std_rho_map": 0.2, "folded_fields": 0, "raw_folded_fields": 3}
    assert not has_folds(repaired) and has_folds(repaired, raw=True)
    assert not has_folds({**repaired, "raw_folded_fields": 0}, raw=True)
    raw = {"std_rho_map": 0.2, "folded_fields": 2}
    assert has_folds(raw) and has_folds(raw, raw=True)
    assert has_folds({"n_flipped": 4}, raw=True) and not has_folds({"n_flipped": 0}, raw=True)
