"""rfmap.viz.meshes.repair_figure: a folded map beside its repair, with a close-up of the folds."""
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rfmap.core.mesh import grid_mesh  # noqa: E402
from rfmap.viz.meshes import repair_figure  # noqa: E402


def test_repair_figure_adds_a_close_up_of_the_folds():
    mesh = grid_mesh(9, 2)
    x = mesh.points
    folded = x.copy()
    folded[40] = [0.5, 0.36]  # the centre vertex dragged past the row below: a few triangles fold
    fig = repair_figure(folded, x, mesh.elements, n=9)
    axes = fig.axes
    assert len(axes) == 4 and axes[0].get_title().startswith("folded map: ")
    lo, hi = axes[2].get_xlim()
    assert 0 < hi - lo < 1  # the close-up shows less than the whole square
    assert len(axes[0].patches) > 0  # the close-up's square is marked on the whole map
    plt.close(fig)
    flat = repair_figure(x, x, mesh.elements, n=9)
    assert len(flat.axes) == 2  # nothing folded: no close-up
    plt.close(flat)


def test_surface_crossing_panels_share_one_scale():
    from rfmap.fields.hard import self_crossing_map
    from rfmap.finish.repair import repair_map
    from rfmap.viz.repairs import surface_crossing_figure

    ref, bent, el = self_crossing_map(9, 1.3)
    fixed, rep = repair_map(ref, bent, el, boundary="free", grid_n=9)
    fig = surface_crossing_figure(bent, fixed, 9, 1.3, rep["surface_scale"])
    a, b = fig.axes
    assert a.get_xlim() == b.get_xlim() and a.get_ylim() == b.get_ylim()
    plt.close(fig)
