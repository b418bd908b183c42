"""What weight refinement does to the paper's test fields (rfmap.paper.ablations), on an untrained model."""
import pytest
import torch

from rfmap.paper.ablations import refinement_markdown, refinement_study, refinement_summary
from rfmap.paper.tables import Table
from rfmap.surrogate import Surrogate
from rfmap.tasks import TaskSpec


def test_refinement_never_raises_its_objective_and_the_metric_is_reported_beside_it():
    torch.manual_seed(0)
    sur = Surrogate.untrained(TaskSpec("density", 2, "square"), base=4, depth=2, name="tiny", n_range=[13, 13])
    with torch.no_grad():  # a network that moves the points, so that alpha matters
        sur.model.head.weight.mul_(0).add_(0.05 * torch.randn(sur.model.head.weight.shape))
    t = refinement_study(sur, ["sin-cos", "ring"], 13)
    assert [(c, m) for c, m, _ in t.rows][:2] == [("sin-cos", "α = 1"), ("sin-cos", "refined")]
    for f in ("sin-cos", "ring"):
        assert t.value(f, "refined", "objective") <= t.value(f, "α = 1", "objective") + 1e-12
        assert t.value(f, "α = 1", "alpha") == [1.0, 1.0]
    s = refinement_summary(t)
    assert s["fields"] == 2 and s["objective_lowered"] == 2
    assert s["metric_lowered"] + s["metric_raised"] <= 2
    assert "| tiny | 2 | 2 |" in refinement_markdown({"tiny": t})


def test_summary_names_the_field_whose_metric_rose_most():
    t = Table("tab:refinement", "t", ["metric", "objective", "alpha"])
    for f, (a, r) in {"a": (0.10, 0.08), "b": (0.20, 0.23), "c": (0.10, 0.11)}.items():
        t.add(f, "α = 1", {"metric": a, "objective": 1.0})
        t.add(f, "refined", {"metric": r, "objective": 0.9})
    s = refinement_summary(t)
    assert (s["metric_lowered"], s["metric_raised"]) == (1, 2)
    assert s["worst"] == "b, from 0.2000 to 0.2300"
    assert s["raised_unprinted"] == []
    t.add("d", "α = 1", {"metric": 0.1000001, "objective": 1.0})  # a rise the table does not print
    t.add("d", "refined", {"metric": 0.1000002, "objective": 0.9})
    s = refinement_summary(t)
    # unrounded values compared: a rise below the printed precision is a rise, and named as unprinted
    assert s["metric_raised"] == 3 and s["raised"] == ["b", "c", "d"] and s["raised_unprinted"] == ["d"]
    assert refinement_summary(Table("tab:refinement", "t", ["metric"]))["worst"] == "none"


def test_a_beltrami_model_is_scored_by_its_vertex_error():
    """An untrained surrogate is the identity whatever alpha: its error is the exact map's mean displacement."""
    import numpy as np

    from rfmap.paper.reproduce import exact_beltrami_result

    sur = Surrogate.untrained(TaskSpec("beltrami", 2, "fixed"), base=4, depth=2, name="tiny")
    t = refinement_study(sur, ["T1"], 13)
    exact = exact_beltrami_result("T1", 13)
    shift = float(np.linalg.norm(exact.mapped_points - exact.ref_points, axis=1).mean())
    for method in ("α = 1", "refined"):
        assert t.value("T1", method, "metric") == pytest.approx(shift, rel=1e-6)
