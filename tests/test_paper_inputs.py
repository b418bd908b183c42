"""The search of the paper's under-specified test inputs (benchmarks/paper_inputs.py): the sums over elements that give
every box's Std(rho~_orig) at once agree with the project's own metric, candidate by candidate."""
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from rfmap.core.geometry import grid_cell_simplices
from rfmap.core.mesh import element_centroids, grid_mesh
from rfmap.fields import get_field

SPEC = importlib.util.spec_from_file_location("paper_inputs",
                                              Path(__file__).resolve().parents[1] / "benchmarks" / "paper_inputs.py")
paper_inputs = importlib.util.module_from_spec(SPEC)
sys.modules["paper_inputs"] = paper_inputs  # dataclasses look their module up by name
SPEC.loader.exec_module(paper_inputs)
Family, Candidate = paper_inputs.Family, paper_inputs.Candidate

RNG = np.random.default_rng(0)


def _random_boxes(bs, count):
    return [tuple(RNG.integers(len(bs.labels), size=bs.family.dim)) for _ in range(count)]


@pytest.mark.parametrize("family", [Family("sin-cos", 21, 0.05), Family("sin-cos", 21, 0.1, shift=False),
                                    Family("multi-freq-3d", 9, 0.25), Family("shell-3d", 9, 0.25)])
@pytest.mark.parametrize("variant", ["add", "replace"])
def test_every_box_at_once_is_compute_metrics(family, variant):
    """0.05 is below the sin-cos minimum (1 on the grid): a replaced box then sets the shift."""
    bs = paper_inputs.box_sums(family)
    for value in (0.05, 1.0, 3.5):
        std = paper_inputs.box_std(bs, variant, value)
        for ix in _random_boxes(bs, 4):
            c = Candidate(family, tuple(bs.labels[i] for i in ix), variant, value, std[ix])
            if np.isfinite(c.std):
                assert c.std == pytest.approx(c.verify(), rel=1e-11, abs=0)


def _direct_centroid_std(family, box, variant, value):
    """Element means of the (shifted) background, the box term taken at each element's centroid."""
    mesh = grid_mesh(family.n, family.dim)
    b = get_field(family.background)(mesh.points)
    low = min(b.min(), value) if variant == "replace" else b.min()
    b = b - low + 0.1 if family.shift else b
    value = value - low + 0.1 if family.shift and variant == "replace" else value
    rho = b[mesh.elements].mean(1)
    cen = element_centroids(mesh.points, mesh.elements)
    inside = np.ones(len(rho), dtype=bool)
    for a, lab in enumerate(box):
        lo, hi = (float(s) for s in lab[1:-1].split(","))
        t = cen[:, a]
        inside &= (t >= lo if lab[0] == "[" else t > lo) & (t <= hi if lab[-1] == "]" else t < hi)
    rho = rho + value * inside if variant == "add" else np.where(inside, value, rho)
    return rho.std(ddof=1) / rho.mean()


@pytest.mark.parametrize("family", [Family("sin-cos", 21, 0.1, "centroid"),
                                    Family("octant-3d", 8, 0.2, "centroid", shift=False)])
@pytest.mark.parametrize("variant", ["add", "replace"])
def test_centroid_sampling_against_the_element_centroids(family, variant):
    bs = paper_inputs.box_sums(family)
    for value in (0.5, 2.0):
        std = paper_inputs.box_std(bs, variant, value)
        for ix in _random_boxes(bs, 4):
            box = tuple(bs.labels[i] for i in ix)
            assert std[ix] == pytest.approx(_direct_centroid_std(family, box, variant, value), rel=1e-11)


def test_intervals_are_distinct_and_labelled_closed_first():
    labels, ind = paper_inputs.axis_intervals(51, 0.1)
    rows = ind["vertex"]
    assert len({r.tobytes() for r in rows}) == len(labels) == rows.shape[0]
    assert labels[0] == "[0, 0.1]" and "(0, 0.1)" in labels  # 0.1 is the vertex 5/50: open and closed differ
    labels48, _ = paper_inputs.axis_intervals(48, 0.1)
    assert "[0.1, 0.2]" in labels48 and "(0.1, 0.2)" not in labels48  # no vertex of the 48-grid on 0.1 or 0.2
    assert len(grid_cell_simplices(3)) == 6 and len(paper_inputs.axis_intervals(9, 0.25, "centroid", 3)[1]) == 3


def test_a_box_over_every_minimum_would_change_the_shift():
    bs = paper_inputs.box_sums(Family("sin-cos", 21, 0.5))
    whole = bs.labels.index("[0, 1]")
    assert np.isnan(paper_inputs.box_std(bs, "add", 1.0)[whole, whole])
    # below the minimum the shift is the box's own
    assert np.isfinite(paper_inputs.box_std(bs, "replace", 0.5)[whole, whole])


def test_the_project_fields_are_candidates_of_the_search():
    """rect-peak is sin-cos + 2 on [0.6, 0.8] x [0.2, 0.4]; prism-peak-3d is Eq. (peak-3d) as printed."""
    rect = Candidate(Family("sin-cos", 51), ("[0.6, 0.8]", "[0.2, 0.4]"), "add", 2.0, np.nan)
    assert rect.verify() == pytest.approx(paper_inputs.project_std("rect-peak"), rel=1e-12)
    box = ("(0.6, 1)", "(0, 0.4)", "(0.4, 0.8)")
    prism = Candidate(Family("multi-freq-3d", 48), box, "replace", 1.0, np.nan)
    assert prism.verify() == pytest.approx(paper_inputs.project_std("prism-peak-3d"), rel=1e-12)
    published = paper_inputs.published_std
    assert (published("rect-peak"), published("prism-peak-3d")) == (0.480728, 0.366671)


def test_solved_values_reproduce_the_target():
    bs = paper_inputs.box_sums(Family("sin-cos", 21, 0.1))
    for variant in ("add", "replace"):
        roots = paper_inputs.solve_value(bs, variant, 0.480728)
        assert any(np.isfinite(r).any() for r in roots)
        for r in roots:
            for ix in list(zip(*np.nonzero(np.isfinite(r))))[:20]:
                assert paper_inputs.box_std(bs, variant, r[ix])[ix] == pytest.approx(0.480728, abs=1e-12)


def test_search_counts_the_matches_and_the_printed_box():
    family = Family("multi-freq-3d", 9, 0.2)
    bs = paper_inputs.box_sums(family)
    ix = (1, 2, 3)
    target = round(float(paper_inputs.box_std(bs, "add", 1.5)[ix]), 6)
    row = paper_inputs.search(bs, target, values=(1.5,), variants=("add",), top=3)[0]
    brute = int((np.round(paper_inputs.box_std(bs, "add", 1.5), 6) == target).sum())
    assert row["matches"] == brute >= 1 and 1 <= row["distinct"] <= brute
    assert round(row["best"][0].std, 6) == target
    valid = int(np.isfinite(paper_inputs.box_std(bs, "add", 1.5)).sum())
    assert row["candidates"] == valid > 0.99 * len(bs.labels) ** 3
    box = ((0.6, 1.0), (0.0, 0.4), (0.4, 0.8))
    printed = paper_inputs.printed_box_candidates(bs, box, values=(1.0,))
    assert printed and all(c.box[0].endswith("1]") or c.box[0].endswith("1)") for c in printed)
    assert paper_inputs.printed_box_candidates(bs, None) == []
    assert paper_inputs.SEARCHES["prism-peak-3d"][3] == box


def test_main_prints_the_tables(capsys):
    paper_inputs.main(["--field", "rect-peak", "--step", "0.25", "--values", "1", "2", "--top", "2"])
    out = capsys.readouterr().out
    assert "### rect-peak: published Std(rho~_orig) = 0.480728, the project's field 0.570863" in out
    assert "| sin-cos, vertex, shift | add |" in out and "| sin-cos, centroid, no shift | replace |" in out
