"""rfmap.paper.folding.repaired_mu and the figures of chapter 10 (rfmap.viz.repairs) on a small folded grid map."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402

from rfmap.core.mesh import element_measures, grid_mesh  # noqa: E402
from rfmap.core.result import MapResult  # noqa: E402
from rfmap.finish.repair import DELTA, repair_map  # noqa: E402
from rfmap.paper.folding import repaired_mu  # noqa: E402
from rfmap.viz.repairs import fold_repair_figure, surface_crossing_figure  # noqa: E402

N = 9


def _folded_pair():
    mesh = grid_mesh(N, 2)
    mapped = mesh.points.copy()
    k = 4 * N + 4  # the centre vertex, pushed past its neighbours
    mapped[k] += (0.2, 0.17)
    fixed, _ = repair_map(mesh.points, mapped, mesh.elements, boundary="square", grid_n=N)
    ones = np.ones(len(mesh.points))
    return (MapResult(mesh.points, mapped, mesh.elements, ones),
            MapResult(mesh.points, np.asarray(fixed), mesh.elements, ones))


def test_repaired_mu_keeps_mu_outside_the_moved_triangles():
    raw, fixed = _folded_pair()
    assert (element_measures(raw.mapped_points, raw.elements) <= 0).any()
    assert (element_measures(fixed.mapped_points, fixed.elements) > 0).all()
    rep = repaired_mu(raw, fixed)
    assert 0 < rep["moved"] < len(raw.elements) and rep["same_outside"]
    assert rep["max_mu"] < 1 and rep["over_cap"] >= 0
    assert (rep["over_cap"] > 0) == (rep["max_mu"] > 1 - DELTA)


def test_chapter_10_figures_draw():
    raw, fixed = _folded_pair()
    fig = fold_repair_figure(raw, fixed, N)
    assert len(fig.axes) == 4 and fig.axes[0].get_title().startswith("(a) raw map:")
    # the close-ups: the raw map and the repaired map side by side, on the same limits
    assert fig.axes[2].get_title().startswith("(c) raw map") and fig.axes[3].get_title().startswith("(d) repaired")
    assert fig.axes[2].get_xlim() == fig.axes[3].get_xlim()
    cube = grid_mesh(5, 3).points
    fig = surface_crossing_figure(cube, cube, 5, 1.3, 0.5)
    assert "1.3 turns" in fig.axes[0].get_title() and "0.500" in fig.axes[1].get_title()
