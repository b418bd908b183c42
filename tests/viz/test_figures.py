"""Plotting helpers of rfmap.viz."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from rfmap.nn.model import MultiResUNet  # noqa: E402
from rfmap.viz import architecture_diagram  # noqa: E402


@pytest.mark.parametrize("dim,n_params,base,depth,attention", [(2, 1, 16, 3, True), (3, 1, 4, 1, False),
                                                               (2, 2, 8, 2, True)])
def test_architecture_diagram_reads_the_model(dim, n_params, base, depth, attention):
    model = MultiResUNet(dim, n_params, base, depth, attention)
    ax = architecture_diagram(model)
    texts = [t.get_text() for t in ax.texts]
    edc = [t for t in texts if "EDC" in t]
    assert len(edc) == 2 * depth + 1  # encoder stages, bottleneck, decoder stages
    assert all(("attn" in t) == attention for t in edc)
    ch = [base * 2**i for i in range(depth + 1)]
    assert any(f"{ch[-2]}→{ch[-1]}" in t and "bottleneck" in t for t in edc)
    for i in range(depth):  # decoders concatenate the skip: 2 c_i -> c_i
        assert any(f"decoder {i}" in t and f"{2 * ch[i]}→{ch[i]}" in t for t in edc)
        assert any(t == f"skip, {ch[i]} ch" for t in texts)
    assert any(f"{dim + n_params} channels" in t for t in texts)
    assert any(f"1×1: {dim + n_params}→{base} each" in t for t in texts)
    assert any(f"{base}→{dim}" in t and "head" in t for t in texts)
    plt.close(ax.figure)


def test_architecture_diagram_draws_into_a_given_axes():
    fig, ax = plt.subplots()
    assert architecture_diagram(MultiResUNet(2, 1, 4, 2), ax=ax) is ax
    assert len(ax.patches) == 2 * 2 + 1 + 4  # EDC stages + input, lift, head, output
    plt.close(fig)


def test_vertex_error_panels_show_the_error_of_each_map():
    from rfmap.core.result import MapResult
    from rfmap.core.mesh import grid_mesh
    from rfmap.viz import vertex_error_panels

    n = 9
    mesh = grid_mesh(n, 2)
    exact = MapResult(mesh.points, mesh.points.copy(), mesh.elements, None, kind="density")
    shifted = MapResult(mesh.points, mesh.points + [0.01, 0.0], mesh.elements, None, kind="density")
    fig = vertex_error_panels({"ours": shifted, "exact": exact}, exact, n=n)
    titles = [ax.get_title() for ax in fig.axes[:2]]
    assert titles == ["ours: mean 0.01", "exact: mean 0"]
    img = fig.axes[0].images[0].get_array()
    np.testing.assert_allclose(img, 0.01)
    with pytest.raises(ValueError, match="grid"):
        vertex_error_panels({"ours": shifted}, exact, n=n + 1)
    plt.close(fig)


def test_save_figure_refuses_figures_unreadable_in_the_text_column(tmp_path, monkeypatch):
    import matplotlib.pyplot as plt
    from rfmap.viz import style
    from rfmap.viz.figures import MIN_DISPLAY_PT, TEXT_COLUMN_PX, display_font_sizes, save_figure

    monkeypatch.setenv("RFMAP_FIGURES", str(tmp_path))
    with style():
        fine, ax = plt.subplots(figsize=(6, 3))
        ax.plot([0, 1], [0, 1])
        ax.set_title("readable")
        scale, texts, width = display_font_sizes(fine)
        assert width <= TEXT_COLUMN_PX * 1.5 and min(s for _, s in texts) >= MIN_DISPLAY_PT
        assert save_figure(fine, "fig:fine").is_file()
        wide, axes = plt.subplots(1, 10, figsize=(40, 3))  # ten panels in a row: 9 pt text shown at about 2.4 pt
        with pytest.raises(ValueError, match="unreadable"):
            save_figure(wide, "fig:wide")
        small, ax = plt.subplots(figsize=(6, 3))
        ax.set_title("tiny", fontsize=4)
        with pytest.raises(ValueError, match="tiny"):
            save_figure(small, "fig:small")
    plt.close("all")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig-fine.png"]


def test_cartogram_column_width_follows_the_books_text_column():
    from rfmap.viz.cartograms import TEXT_COLUMN_IN
    from rfmap.viz.figures import TEXT_COLUMN_PX

    assert TEXT_COLUMN_IN == TEXT_COLUMN_PX / 96


def test_folded_states_are_read_from_old_and_new_histories():
    from rfmap.training.validation import has_folds as _folded_state

    assert _folded_state({"folded_fields": 2, "n_flipped": 0})
    assert not _folded_state({"folded_fields": 0, "n_flipped": 5})  # counted fields win
    assert _folded_state({"n_flipped": 3}) and not _folded_state({"n_flipped": 0}) and not _folded_state({})


def test_the_diffusion_chapters_figures_draw_their_data():
    from rfmap.core.mesh import grid_mesh
    from rfmap.core.result import MapResult
    from rfmap.viz import boundaries_figure, grid_convergence_figure, solve_cost_figure, volume_panels_figure

    fig = grid_convergence_figure([9, 17, 33], [0.1, 0.03, 0.01], title="t")
    ax = fig.axes[0]
    assert ax.get_xscale() == ax.get_yscale() == "log"
    assert [t.get_text() for t in ax.get_xticklabels()] == ["1/8", "1/16", "1/32"]
    np.testing.assert_allclose(ax.lines[0].get_xdata(), [1 / 8, 1 / 16, 1 / 32])
    plt.close(fig)
    fig = solve_cost_figure({2: [(17, 289, 0.1), (33, 1089, 0.3)], 3: [(5, 125, 0.2, 7), (9, 729, 1.0, 9)]})
    ax = fig.axes[0]
    assert [line.get_label() for line in ax.lines] == ["2D", "3D"]
    np.testing.assert_allclose(ax.lines[1].get_ydata(), [0.2, 1.0])
    fig.canvas.draw()
    assert not any("e+" in t.get_text() for t in ax.get_xticklabels())  # 1000, not 1e+03
    plt.close(fig)
    # data over less than a decade: labels at 1, 2, 3, 5, 7 times a power of ten cover the range
    fig = grid_convergence_figure([17, 33, 65, 97], [0.038, 0.02, 0.01, 0.0068])
    ticks = fig.axes[0].get_yticks()
    assert len(ticks) >= 3 and max(ticks) >= 0.03 and min(ticks) <= 0.007
    plt.close(fig)
    m = grid_mesh(9, 2)
    res = MapResult(m.points, m.points * 1.1, m.elements, np.ones(len(m.points)), kind="density")
    fig = boundaries_figure({"a": res, "b": res}, np.ones(len(m.elements)), n=9)
    assert [ax.get_title() for ax in fig.axes[:2]] == ["a", "b"]
    assert "tilde" in fig.axes[2].get_xlabel()  # the colour bar of the carried values
    plt.close(fig)
    fig = volume_panels_figure([np.zeros((4, 4, 3))] * 3, ["x", "y", "z"], clim=(0, 2), label="rho")
    assert [ax.get_title() for ax in fig.axes[:3]] == ["x", "y", "z"] and fig.axes[3].get_xlabel() == "rho"
    plt.close(fig)


def test_residual_parts_figure_draws_each_map_and_a_close_up():
    from rfmap.fields.paper import sample_density
    from rfmap.solvers import solve_dem
    from rfmap.viz.diffusion import residual_parts_figure

    res = solve_dem(sample_density("sin-cos", 17))
    fig = residual_parts_figure({"a": res, "b": res}, cells=4)
    axes = np.array(fig.axes[:6]).reshape(2, 3)
    for row in axes:
        lo, hi = row[2].get_xlim()
        assert hi - lo == pytest.approx(4 / 16)  # the close-up spans 4 of the 16 cells
        assert 0.0 <= lo and hi <= 1.0
    assert [ax.get_title() for ax in axes[0]][0].startswith("residual")
    assert len(fig.axes) == 8  # six panels and two colour bars
    plt.close(fig)
