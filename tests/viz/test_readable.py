"""Figures of the training, 3D and FNO chapters fit the book's text column and say what their numbers are."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from rfmap.tasks.losses import loss_integrands  # noqa: E402
from rfmap.training.records import example_field, example_text  # noqa: E402
from rfmap.tasks import TaskSpec, sample_batch  # noqa: E402
from rfmap.viz import learning_curves, plot_loss_terms, style, time_accuracy_figure  # noqa: E402
from rfmap.viz.figures import MAX_FIGURE_PX, MIN_DISPLAY_PT, display_font_sizes  # noqa: E402
from rfmap.viz.training import race_bars  # noqa: E402


def _readable(fig):
    fig.canvas.draw()  # the layout first: the width is that of the saved image
    _, texts, width = display_font_sizes(fig)
    assert width <= MAX_FIGURE_PX
    assert min(size for _, size in texts) >= MIN_DISPLAY_PT - 1e-6, sorted(texts, key=lambda t: t[1])[:3]


def test_learning_curves_count_the_whole_chain():
    """A warm-started run is drawn after its ancestors' steps, on an axis that spans the stored steps (the earlier
    runs named in its label, not drawn as an empty stretch), one axis per quantity (no twin axes); the title gives
    the chain's steps as a multiple of the paper's budget (4×), or a share in per cent below it (never as 4e+02 %)."""
    meta = {"steps": 300, "cumulative_steps": 4000, "history": {"step": [10, 100, 300], "loss": [1.0, 0.5, 0.2],
                                                                "validation": [{"step": 300, "std_rho_map": 0.2}]}}
    with style():
        fig = learning_curves({"chain": meta, "single": {"steps": 50, "history": {"step": [10, 50],
                                                                                    "loss": [0.1, 0.05]}}},
                              {"chain": 1000, "single": 4000})
        loss, val = fig.axes[0], fig.axes[1]
        assert loss.get_title() == "chain: 4,000 steps,\n4× the paper's epochs as steps"
        assert list(loss.lines[0].get_xdata()) == [3710, 3800, 4000]
        lo, hi = loss.get_xlim()
        assert 3600 < lo < 3710 and 4000 < hi < 4100 and "3,700" in loss.get_xlabel()
        assert val.lines[0].get_xdata()[0] == 4000 and "Std" in val.get_ylabel()
        assert "1.25 % of the paper's" in fig.axes[2].get_title()
        assert all(len(ax.get_shared_x_axes().get_siblings(ax)) == 1 for ax in fig.axes)  # no twins
        _readable(fig)
    plt.close(fig)


def test_validation_against_time_spans_the_stored_run():
    """Curves start at zero, in the wall time of the stored run; the earlier runs of a chain are in the legend."""
    from rfmap.viz import validation_vs_time

    def meta(elapsed, total):
        return {"wall_time": elapsed[-1], "cumulative_wall_time": total,
                "history": {"validation": [{"elapsed": e, "std_rho_map": 0.3 / (1 + i)} for i, e in enumerate(elapsed)]}}

    with style():
        ax = validation_vs_time({"A": meta([60.0, 600.0], 36600.0), "B": meta([30.0, 1200.0], 1200.0)})
        assert ax.get_xlim()[0] == 0 and ax.get_xlim()[1] < 25  # minutes of the stored runs, not 600
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert labels == ["A (after 600 min of earlier runs)", "B"]
        _readable(ax.figure)
    plt.close(ax.figure)


def test_the_wall_time_figure_gives_each_model_a_panel_and_one_legend_below():
    """One titled panel per model, a group starting a new row (the empty cell switched off), and one legend below
    every panel naming the filled and the open markers."""
    from rfmap.viz.wall_time import validation_time_figure

    def meta(folded):
        return {"wall_time": 600.0, "cumulative_wall_time": 3000.0,
                "history": {"validation": [{"elapsed": 60.0 * (i + 1), "std_rho_map": 0.3 / (1 + i),
                                            "folded_fields": int(folded and i == 0)} for i in range(4)]}}

    with style():
        fig = validation_time_figure({"2D": {"a": meta(True), "b": meta(False), "c": meta(False)},
                                      "3D": {"d": meta(True)}})
        shown = [ax for ax in fig.axes if ax.axison]
        assert [ax.get_title().split("\n")[0] for ax in shown] == ["2D: a", "2D: b", "2D: c", "3D: d"]
        assert "after 40 min of earlier runs" in shown[0].get_title()
        assert len(fig.axes) == 6 and len(fig.legends) == 1
        fig.canvas.draw()
        legend_box = fig.legends[0].get_window_extent()
        assert all(legend_box.y1 <= ax.get_window_extent().y0 + 1 for ax in shown)
        _readable(fig)
    plt.close(fig)


def test_a_term_that_vanishes_everywhere_is_said_in_words():
    spec = TaskSpec("density", 2, "square")
    batch = sample_batch(spec, seed=0, step=0, indices=range(1), n=9)
    terms = loss_integrands(batch.ref, batch.ref.clone(), batch.elements, density=batch.density)
    assert float(terms["fold"].max()) == 0.0  # the identity folds nothing
    fig, axes = plt.subplots(1, 3)
    plot_loss_terms(axes, batch.ref, batch.elements, terms, n=9, keys=["density", "fold"])
    assert [t.get_text() for t in axes[2].texts] == ["0 on every\nelement"]
    assert not axes[2].collections or all(c.get_array() is None for c in axes[2].collections)
    plt.close(fig)


def test_time_accuracy_figure_is_a_readable_grid():
    rows = [dict(dim=d, n=n, boundary=b, method=m, time=t, std_rho_map=s)
            for d, n, b in [(2, 33, "square"), (2, 33, "free"), (3, 16, "square"), (3, 16, "free"), (2, 65, "free")]
            for m, t, s in [("diffusion", 0.5, 0.01), ("flow", 0.05, 0.012), ("hybrid", 0.02, 0.011)]]
    with style():
        fig = time_accuracy_figure(rows)
        panels = [ax for ax in fig.axes if ax.axison]
        assert len(panels) == 5 and len({round(ax.get_position().x0, 2) for ax in panels}) == 2  # two columns
        assert fig.axes[5].get_legend() is not None  # the legend in the empty sixth panel
        _readable(fig)
    plt.close(fig)


def test_race_bars_show_the_final_metric_and_the_steps():
    metas = {"U-Net": {"steps": 120, "final_metrics": {"mean": {"std_rho_map": 0.25}}},
             "FNO": {"steps": 300, "final_metrics": {"mean": {"std_rho_map": 0.5}}}}
    with style():
        ax = race_bars(metas)
        assert [p.get_height() for p in ax.patches] == [0.25, 0.5]
        labels = [t.get_text() for t in ax.texts]
        assert labels == ["0.25\n120 steps", "0.5\n300 steps"]
        _readable(ax.figure)
    plt.close(ax.figure)


def test_the_quoted_example_is_true_to_its_numbers():
    values = {"a_best": 0.0775, "a_std_paper": 0.0737, "b_best": 0.3, "b_std_paper": 0.1}
    text = example_text(example_field(values, ["a", "b"]))
    assert text == "the closest is a: 0.0775, 1.05 times the paper's 0.0737"
    values["b_best"] = 0.09
    assert example_text(example_field(values, ["a", "b"])) == "for example b: 0.09 against the paper's 0.1"


@pytest.mark.parametrize("clip", ["plane", True])
def test_render_volume_cuts_along_flat_faces(clip):
    pytest.importorskip("pyvista")
    from rfmap.core.mesh import grid_mesh
    from rfmap.core.result import MapResult
    from rfmap.viz.volumes import _cut

    from rfmap.core.result import to_pyvista

    mesh = grid_mesh(5, 3)
    res = MapResult(mesh.points, mesh.points.copy(), mesh.elements, np.ones(len(mesh.points)), kind="density")
    grid = to_pyvista(res)
    cut = _cut(grid, clip)
    assert 0 < cut.volume < grid.volume
    # a flat cut: the kept volume is exactly that of the half-space (plane) or of the cube less an octant
    expected = 0.5 if clip == "plane" else 7 / 8
    assert cut.volume == pytest.approx(expected, abs=1e-9)


def test_validation_against_time_can_give_each_runs_minutes():
    from rfmap.viz import validation_vs_time

    meta = {"wall_time": 2688.0,
            "history": {"validation": [{"elapsed": e, "std_rho_map": 0.2} for e in (60.0, 2688.0)]}}
    with style():
        ax = validation_vs_time({"U-Net": meta}, minutes=True)
        assert [t.get_text() for t in ax.get_legend().get_texts()] == ["U-Net, 44.8 min"]
    plt.close(ax.figure)


def test_resolution_panels_mark_a_folded_raw_map_instead_of_plotting_it():
    """A folded raw map (Std 127) is a cross at the top of the raw panel, not a point that stretches the axis."""
    from rfmap.paper.tables import Table
    from rfmap.viz import resolution_panels

    t = Table("tab:x", "x", ["raw_std", "std_rho_map", "n_flipped"])
    for n, raw, flips in ((32, 0.1, 0), (64, 0.12, 0), (256, 127.0, 8264)):
        t.add(str(n), "U-Net (native)", {"raw_std": raw, "std_rho_map": 0.1, "n_flipped": flips})
    with style():
        fig = resolution_panels(t)
        raw = fig.axes[0]
        values = [y for line in raw.get_lines() if line.get_transform() == raw.transData for y in line.get_ydata()]
        assert max(values) < 1 and raw.get_ylim()[1] < 10
        assert all(ax.get_legend() is None for ax in fig.axes) and len(fig.legends) == 1
        assert "folded (not plotted)" in [t.get_text() for t in fig.legends[0].get_texts()]
        fig.canvas.draw()  # the legend lies below the panels, over no point
        legend_box = fig.legends[0].get_window_extent()
        assert all(legend_box.y1 <= ax.get_window_extent().y0 + 1 for ax in fig.axes)
        _readable(fig)
    plt.close(fig)


def test_resolution_panels_label_a_tick_below_the_lowest_values():
    """Values of 0.0737 and 0.0759 under a lowest round label of 0.1 get a labelled tick at 0.07 and minor steps."""
    from rfmap.paper.tables import Table
    from rfmap.viz import resolution_panels

    t = Table("tab:x", "x", ["raw_std", "std_rho_map", "n_flipped"])
    for n, raw in ((32, 0.124), (64, 0.0737), (128, 0.0759), (256, 0.244)):
        t.add(str(n), "U-Net (work)", {"raw_std": raw, "std_rho_map": raw, "n_flipped": 0})
    with style():
        fig = resolution_panels(t)
        fig.canvas.draw()
        labels = [lab.get_text() for lab in fig.axes[0].get_yticklabels()]
        assert labels[0] == "0.07" and "0.1" in labels
        assert any(abs(v - 0.08) < 1e-9 for v in fig.axes[0].yaxis.get_minorticklocs())
        _readable(fig)
    plt.close(fig)


def test_displacement_demand_legend_sits_below_the_panels():
    from rfmap.viz import displacement_demand_figure

    records = [{"group": g, "demand": d, "reach": 0.9 * d, "left_net": 0.3, "left_classical": 0.05}
               for g, ds in (("training", (0.1, 0.2, 0.3)), ("ramp", (0.39, 0.4))) for d in ds]
    with style():
        fig = displacement_demand_figure(records)
        assert all(ax.get_legend() is None for ax in fig.axes) and len(fig.legends) == 1
        fig.canvas.draw()
        legend_box = fig.legends[0].get_window_extent()
        assert all(legend_box.y1 <= ax.get_window_extent().y0 + 1 for ax in fig.axes)
        _readable(fig)
    plt.close(fig)


def test_a_cartogram_title_says_over_which_regions_its_error_is_taken():
    from types import SimpleNamespace

    from rfmap.viz.cartograms import _error_title

    judged = SimpleNamespace(max_error=0.0035, n_minor=17, max_error_minor=5462.4)
    title = _error_title(SimpleNamespace(min_share=1e-4), judged)
    assert title.startswith("cartogram: max area error 0.0035\n")
    assert "at least 0.01 % of the total" in title and "17 regions too small" in title
    assert "5462" not in title  # a ratio that would read like a bug without the text
    plain = SimpleNamespace(max_error=0.0049, n_minor=0, max_error_minor=0.0)
    assert _error_title(SimpleNamespace(min_share=0.0), plain) == "cartogram: max area error 0.0049"


def test_encoding_figure_says_what_a_shorter_row_holds():
    import matplotlib.pyplot as plt

    from rfmap.viz import encoding_figure, style

    dens, belt = np.zeros((1, 3, 5, 5)), np.zeros((1, 4, 5, 5))
    with style():
        fig = encoding_figure([dens, belt], [["x1", "x2", "log p"], ["x1", "x2", "Re mu", "Im mu"]])
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert texts == ["3 channels:\n2 coordinates,\n1 field channel"]
    plt.close(fig)


@pytest.mark.parametrize("lo, hi", [(0.096, 0.19), (0.085, 0.22), (3.0, 14.0), (0.0502, 0.0508)])
def test_a_narrow_log_axis_is_labelled_at_round_values(lo, hi):
    """Data spanning less than a factor of five get two or three labels inside the data's range, at round values
    (1, 1.5, 2, 3, 4, 5, 6, 8 times a power of ten) where two such values fall inside, never at 0.096 or 0.13."""
    from rfmap.viz.studies import plain_log_ticks

    fig, ax = plt.subplots()
    ax.semilogy([0, 1], [lo, hi])
    plain_log_ticks(ax.yaxis)
    ticks = [t for t in ax.yaxis.get_majorticklocs() if lo * 0.9 <= t <= hi * 1.1]
    assert 2 <= len(ticks) <= 3, ticks
    mantissas = {round(t / 10.0 ** np.floor(np.log10(t)), 6) for t in ticks}
    round_inside = [m * 10.0**e for e in range(-3, 3) for m in (1, 1.5, 2, 3, 4, 5, 6, 8) if lo <= m * 10.0**e <= hi]
    if len(round_inside) >= 2:
        assert mantissas <= {1, 1.5, 2, 3, 4, 5, 6, 8}, ticks
    plt.close(fig)
