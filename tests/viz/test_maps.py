"""The 2D map figures of the reconstruction, population, resolution and DEM-versus-DEQ chapters fit the book's text
column, with one colour scale per quantity."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from rfmap.core.mesh import grid_mesh  # noqa: E402
from rfmap.paper.reproduce import exact_beltrami_result  # noqa: E402
from rfmap.core.result import MapResult  # noqa: E402
from rfmap.viz import (beltrami_figure, extreme_figure, folded_maps_figure, map_rows_figure,  # noqa: E402
                       query_points_figure, style)
from rfmap.viz.figures import MAX_FIGURE_PX, MIN_DISPLAY_PT, TEXT_COLUMN_PX, display_font_sizes  # noqa: E402


def _map(n, amp):
    """A smooth fold-free map of the n-grid that fixes the boundary, with a density peaked inside."""
    m = grid_mesh(n, 2)
    p = m.points
    mapped = p + amp * np.sin(np.pi * p) * np.sin(2 * np.pi * p[:, ::-1])
    return MapResult(p, mapped, m.elements, 1 + 3 * np.exp(-((p - 0.4) ** 2).sum(1) / 0.02), kind="density")


def _readable(fig):
    fig.canvas.draw()
    _, texts, width = display_font_sizes(fig)
    assert TEXT_COLUMN_PX <= width <= MAX_FIGURE_PX
    assert min(size for _, size in texts) >= MIN_DISPLAY_PT - 1e-6, sorted(texts, key=lambda t: t[1])[:3]


@pytest.mark.parametrize("rows", [1, 4])
def test_map_rows_figure_shares_one_colour_bar_per_quantity(rows):
    with style():
        fig = map_rows_figure({f"f{i}": _map(17, 0.02 * (i + 1)) for i in range(rows)})
        _readable(fig)
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(fig.axes) == 4 * rows + 2 and len(bars) == 2
    assert sorted(ax.get_xlabel() for ax in bars) == [r"$\tilde\rho$ (mean 1)", r"$|\mu|$"]
    assert [ax.get_ylabel() for ax in fig.axes[:4 * rows:4]] == [f"f{i}" for i in range(rows)]
    plt.close(fig)


def test_beltrami_figure_draws_a_row_per_case_and_both_error_histograms():
    rows = {c: (exact_beltrami_result(c, 17), _map(17, 0.01), _map(17, 0.03)) for c in ("T1", "T2")}
    with style():
        fig = beltrami_figure(rows)
        _readable(fig)
    hist_axes = [ax for ax in fig.axes if ax.get_yscale() == "log"]
    assert len(hist_axes) == 2 and all(len(ax.patches) == 2 for ax in hist_axes)  # one step outline per solver
    assert [t.get_text() for t in hist_axes[-1].get_legend().get_texts()] == ["LBS", "paper's method"]
    assert all(ax.get_ylabel() == "triangles" for ax in hist_axes) and "mu" in hist_axes[-1].get_xlabel()
    # the paper's metric per vertex, on one colour bar in units of a power of ten
    assert any("Delta d" in ax.get_xlabel() and "times 10" in ax.get_xlabel() for ax in fig.axes)
    plt.close(fig)


def test_extreme_figure_labels_panels_a_to_g():
    with style():
        fig = extreme_figure(_map(17, 0.0), {"DEM": _map(17, 0.05), "DEQ": _map(17, 0.02)})
        _readable(fig)
    titles = sorted(t for t in (ax.get_title() for ax in fig.axes) if t.startswith("("))
    assert [t[:3] for t in titles] == [f"({c})" for c in "abcdefg"]
    plt.close(fig)


def test_map_rows_figure_gives_the_mapped_density_a_scale_of_its_own():
    with style():
        fig = map_rows_figure({f"f{i}": _map(17, 0.02 * (i + 1)) for i in range(2)}, mapped_range=(0.8, 1.2))
        _readable(fig)
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert sorted(ax.get_xlabel() for ax in bars) == [r"$\tilde\rho$ mapped", r"$\tilde\rho$ original", r"$|\mu|$"]
    mapped = next(ax for ax in bars if ax.get_xlabel() == r"$\tilde\rho$ mapped")
    assert mapped.get_xlim() == pytest.approx((0.8, 1.2))
    plt.close(fig)


def test_folded_maps_figure_counts_the_folds_of_each_map():
    folded = _map(17, 0.0)
    folded.mapped_points[[0, 1]] = folded.mapped_points[[1, 0]]  # two swapped vertices turn triangles over
    with style():
        fig = folded_maps_figure({"raw": folded, "refined": _map(17, 0.02)}, ncols=2)
        _readable(fig)
    titles = [ax.get_title() for ax in fig.axes]
    assert titles[1] == "refined\nnone folded" and titles[0].endswith(" folded (red)")
    assert int(titles[0].split("\n")[1].split()[0]) > 0
    plt.close(fig)


def test_query_points_figure_draws_the_cloud_and_both_histograms():
    grid = _map(17, 0.02)
    with style():
        fig = query_points_figure(grid, grid)
        _readable(fig)
    assert [ax.get_title() for ax in fig.axes[:2]] == ["query cloud", "mapped cloud"]
    assert [t.get_text() for t in fig.axes[2].get_legend().get_texts()] == ["cloud", "grid N = 17"]
    assert fig.axes[2].get_ylabel() and len(fig.axes[2].get_yticks()) > 1  # the histograms' axis is labelled
    plt.close(fig)


@pytest.mark.parametrize("per_element", [True, False])
def test_plot_density_draws_its_triangles_unsnapped(per_element):
    """Snapped to the pixel grid, the triangles along a straight edge leave a saw-tooth of background there."""
    from rfmap.viz import plot_density

    m = grid_mesh(17, 2)
    values = np.ones(len(m.elements) if per_element else len(m.points))
    fig, ax = plt.subplots()
    im = plot_density(ax, m.points, m.elements, values, colorbar=False)
    plt.close(fig)
    assert im.get_snap() is False


def test_grid_lines_end_at_the_mesh():
    """Grid lines are drawn with butt caps, so that no cap pokes past the corners of the mesh."""
    from rfmap.viz import plot_mesh

    m = grid_mesh(9, 2)
    fig, ax = plt.subplots()
    plot_mesh(ax, m.points, n=9, color="w", lw=2)
    assert ax.lines and all(line.get_solid_capstyle() == "butt" for line in ax.lines)
    plt.close(fig)
