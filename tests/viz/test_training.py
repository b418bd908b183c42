"""Figures of the training chapter: learning curves from metadata, loss terms on a batch."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402

from rfmap.tasks.losses import loss_integrands  # noqa: E402
from rfmap.tasks import TaskSpec, sample_batch  # noqa: E402
from rfmap.viz import learning_curves, loss_terms_figure, plot_batch, plot_loss_terms  # noqa: E402


def test_learning_curves_mark_the_budget_and_tolerate_old_metadata():
    metas = {"new": {"steps": 300, "history": {"step": [10, 100, 300], "loss": [1.0, 0.5, 0.2],
                                               "elapsed": [1.0, 9.0, 30.0],
                                               "validation": [{"step": 100, "std_rho_map": 0.3},
                                                              {"step": 300, "std_rho_map": 0.2}]}},
             "old": {"steps": 50, "history": {"step": [10, 50], "loss": [0.1, 0.05], "validation": []}}}
    fig = learning_curves(metas, {"new": 250, "old": 4000})
    loss_new, val_new, loss_old, val_old = fig.axes
    assert "1.2× the paper's" in loss_new.get_title() and "1.25 % of the paper's" in loss_old.get_title()
    # the paper's budget (250 steps) falls inside the stored steps of "new": dashed on both of its panels
    for ax in (loss_new, val_new):
        dashed = [ln for ln in ax.lines if ln.get_linestyle() == "--"]
        assert dashed and dashed[0].get_xdata()[0] == 250
    # ... and outside those of "old" (4,000 against 10-50): no line, the axis stays on the data
    assert not [ln for ln in loss_old.lines if ln.get_linestyle() == "--"]
    assert loss_old.get_xlim()[1] < 100
    assert not val_old.axison  # the old metadata has no validation: said in words, no empty axes
    plt.close(fig)


def test_learning_curves_can_draw_the_selection_score():
    """With ``score`` the validation panel draws the score that chose the kept weights, not the plain mean that a
    folded map inflates, and a star marks the kept weights at their step with the value the metadata records."""
    val = [{"step": 0, "std_rho_map": 9.0, "penalized": 0.3, "capped": 0.3, "folded_fields": 1},
           {"step": 100, "std_rho_map": 0.2, "penalized": 0.2, "capped": 0.2},
           {"step": 200, "std_rho_map": 40.0, "penalized": 0.35, "capped": 0.3, "folded_fields": 2},
           {"step": 200, "std_rho_map": 0.2, "penalized": 0.2, "capped": 0.2}]
    meta = {"steps": 200, "cumulative_steps": 1200, "selected_step": 100,
            "history": {"step": [50, 200], "loss": [1.0, 0.5], "validation": val}}
    fig = learning_curves({"m": meta}, {"m": 100}, score=True)
    ax_val = fig.axes[1]
    line, star = ax_val.lines[:2]
    assert list(line.get_ydata()) == [0.3, 0.2, 0.35] and list(line.get_xdata()) == [1000, 1100, 1200]
    assert list(star.get_xdata()) == [1100] and list(star.get_ydata()) == [0.2] and star.get_marker() == "*"
    assert "folds as identity" in ax_val.get_ylabel()
    assert len(ax_val.lines) == 2  # no open circles on the penalized score unless asked for
    ax_marked = learning_curves({"m": meta}, {"m": 100}, score=True, mark_folded=True).axes[1]
    opened = [ln for ln in ax_marked.lines if ln.get_markerfacecolor() == "white"]
    assert [list(ln.get_xdata()) for ln in opened] == [[1000, 1200]] and "○" in ax_marked.get_title()
    small = {"steps": 10, "selected_step": 10, "history": {"step": [10], "loss": [1.0], "validation": [
        {"step": 0, "mean_dd": 7e-4, "penalized": 7e-4}, {"step": 10, "mean_dd": 6e-4, "penalized": 6e-4}]}}
    ax_small = learning_curves({"b": small}, {"b": 100}, score=True).axes[1]
    assert "×10⁻⁴" in ax_small.get_ylabel() and abs(ax_small.lines[1].get_ydata()[0] - 6.0) < 1e-9
    plt.close("all")


def test_training_curves_give_every_quantity_its_own_axis(tmp_path):
    """One panel per quantity, each on a linear axis from zero with its own range (no log axis reaching down to
    round-off), the step axis spanning the logged steps; a term that is zero throughout says so."""
    import json

    from rfmap.viz import training_curves

    log = tmp_path / "log.jsonl"
    recs = [{"step": s, "loss": 1.0 / s, "density": 0.9 / s, "mu2": 1e-15 * s, "fold": 0.0} for s in range(5, 51, 5)]
    log.write_text("\n".join(json.dumps(r) for r in recs) + "\n")
    fig = training_curves(log)
    panels = [ax for ax in fig.axes if ax.axison]
    assert [ax.get_title() for ax in panels][0] == "total loss" and len(panels) == 4
    for ax in panels:
        assert ax.get_yscale() == "linear" and ax.get_ylim()[0] == 0
        assert ax.get_xlim() == (5.0, 50.0)
    assert panels[2].get_ylim()[1] < 1e-12  # the tiny term on its own range
    assert any("0 at every step" in t.get_text() for t in panels[3].texts)
    plt.close(fig)


def test_loss_term_panels_carry_the_batch_values():
    spec = TaskSpec("density", 2, "square")
    batch = sample_batch(spec, seed=0, step=0, indices=range(2), n=9)
    mapped = batch.ref + 0.01 * torch.randn_like(batch.ref)
    terms = loss_integrands(batch.ref, mapped, batch.elements, density=batch.density)
    fig, axes = plt.subplots(2, 4)
    plot_batch(axes[0][:2], batch)
    plot_loss_terms(axes[1], mapped, batch.elements, terms, n=9, keys=["density", "mu2", "fold"])
    value = float((terms["density"][0] * terms["weight"][0]).sum() / terms["weight"][0].sum())
    assert axes[1][1].get_title().endswith(f"= {value:.3g}")
    assert "fold penalty" in axes[1][3].get_title()
    plt.close(fig)


def test_loss_terms_figure_draws_each_models_own_terms_and_names_the_zero_ones():
    spec = TaskSpec("density", 2, "square")
    batch = sample_batch(spec, seed=0, step=0, indices=range(1), n=9)
    mapped = batch.ref + 0.01 * torch.randn_like(batch.ref)
    terms = loss_integrands(batch.ref, mapped, batch.elements, density=batch.density)
    terms["beltrami"] = terms["mu2"]  # a stand-in mu mismatch for a second model
    terms["fold"] = torch.zeros_like(terms["fold"])  # a term that is zero on every element
    fig = loss_terms_figure({"DEQ": (mapped, batch.elements, terms, ["density", "mu2", "fold"]),
                             "Beltrami": (mapped, batch.elements, terms, ["beltrami", "fold"])}, n=9)
    cells = {}  # (row, column) -> the title of that panel (colour bars have no grid cell)
    for ax in fig.axes:
        if ax.get_subplotspec() is not None and ax.axison:
            spec = ax.get_subplotspec()
            cells[spec.rowspan.start, spec.colspan.start] = ax.get_title()
    # one grid of 3 equal columns: the DEQ model's three panels fill the first row, the Beltrami model's two the
    # first two cells of the next, its map below the other map at the same size
    assert cells[0, 0].startswith("DEQ: the map") and "density mismatch" in cells[0, 1]
    assert "Beltrami energy" in cells[0, 2] and len(cells) == 5  # the zero fold penalty is not drawn
    assert cells[1, 0].startswith("Beltrami: the map") and "mismatch" in cells[1, 1]
    assert all(ax.get_subplotspec().colspan.stop - ax.get_subplotspec().colspan.start == 1
               for ax in fig.axes if ax.get_subplotspec() is not None)  # every panel one cell wide
    note = fig.get_supxlabel().replace("\n", " ")
    assert "fold penalty (DEQ)" in note and "fold penalty (Beltrami)" in note
    plt.close(fig)


def test_loss_terms_figure_puts_every_row_on_one_grid_of_equal_cells():
    spec = TaskSpec("density", 2, "square")
    batch = sample_batch(spec, seed=0, step=0, indices=range(1), n=9)
    mapped = batch.ref + 0.2 * torch.randn_like(batch.ref)  # large enough to fold: every term drawn
    terms = loss_integrands(batch.ref, mapped, batch.elements, density=batch.density)
    terms["beltrami"] = terms["mu2"]
    fig = loss_terms_figure({"DEQ": (mapped, batch.elements, terms, ["density", "mu2", "fold"]),
                             "four terms": (mapped, batch.elements, terms, ["density", "mu2", "beltrami", "fold"])},
                            n=9)
    spans = sorted((ax.get_subplotspec().rowspan.start, ax.get_subplotspec().colspan.start,
                    ax.get_subplotspec().colspan.stop) for ax in fig.axes if ax.get_subplotspec() is not None)
    # 5 panels (map and four terms) in rows of 3 and 2, so a grid of 3 columns; the 4 of the DEQ model two by two
    # in the same cells, filled from the left; every short row leaves its last cell empty
    assert spans == [(0, 0, 1), (0, 1, 2), (1, 0, 1), (1, 1, 2),
                     (2, 0, 1), (2, 1, 2), (2, 2, 3), (3, 0, 1), (3, 1, 2)]
    plt.close(fig)


def test_learning_rates_are_drawn_on_a_log_axis_one_line_per_schedule():
    from rfmap.viz import plot_learning_rates

    fig, ax = plt.subplots()
    plot_learning_rates(ax, {"step decay": [1e-5, 1e-5, 5e-6, 5e-6], "warm-up": [0.0, 1e-4, 2e-4]})
    assert ax.get_yscale() == "log" and len(ax.lines) == 2
    assert list(ax.lines[0].get_xdata()) == [1, 2, 3, 4]
    assert list(ax.lines[1].get_xdata()) == [2, 3]  # the zero rate is left out of the log axis
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["step decay", "warm-up"]
    plt.close(fig)


def test_a_schedule_stopped_by_its_time_limit_is_marked_where_it_stopped():
    from rfmap.viz import plot_learning_rates

    fig, ax = plt.subplots()
    plot_learning_rates(ax, {"nominal": [1e-4, 1e-4, 5e-5, 1e-5], "as run": [1e-4, 3e-5, 1e-6]},
                        stops=["as run"])
    assert len(ax.lines) == 3  # two schedules and one cross
    cross = ax.lines[2]
    assert list(cross.get_xdata()) == [3] and list(cross.get_ydata()) == [1e-6]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["nominal", "as run", "time limit reached"]
    plt.close(fig)


def test_plot_batch_can_draw_the_jittered_meshes():
    import numpy as np

    from rfmap.training.config import get_config

    cfg = get_config("deq2d-square", "ci")
    batch = sample_batch(cfg.task, seed=0, step=0, indices=range(2), n=9, jitter=cfg.jitter,
                         density_cfg=cfg.density_field)
    fig, axes = plt.subplots(1, 4)
    plot_batch(axes[:2], batch)
    plot_batch(axes[2:], batch, mesh=True)
    for ax in axes[:2]:
        assert not ax.lines
    for i, ax in enumerate(axes[2:]):  # the edges drawn through the sample's own jittered vertices
        xs = np.concatenate([line.get_xdata() for line in ax.lines])
        xs = xs[np.isfinite(xs)]
        assert np.isin(xs, batch.ref[i].numpy()[:, 0]).all()
        assert not np.allclose(batch.ref[i].numpy(), batch.ref[1 - i].numpy())
    plt.close(fig)
