"""Figures of the training chapter: learning curves from metadata, loss terms on a batch."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402

from rfmap.losses import loss_integrands  # noqa: E402
from rfmap.tasks import TaskSpec, sample_batch  # noqa: E402
from rfmap.viz import learning_curves, plot_batch, plot_loss_terms  # noqa: E402


def test_learning_curves_mark_the_budget_and_tolerate_old_metadata():
    metas = {"new": {"steps": 300, "history": {"step": [10, 100, 300], "loss": [1.0, 0.5, 0.2],
                                               "elapsed": [1.0, 9.0, 30.0],
                                               "validation": [{"step": 100, "std_rho_map": 0.3},
                                                              {"step": 300, "std_rho_map": 0.2}]}},
             "old": {"steps": 50, "history": {"step": [10, 50], "loss": [0.1, 0.05], "validation": []}}}
    fig = learning_curves(metas, {"new": 1000, "old": 4000}, ncols=2)
    axes = fig.axes
    assert "30 % of the paper's" in axes[0].get_title() and "1.2 % of the paper's" in axes[1].get_title()
    budget_lines = [ln for ln in axes[0].lines if ln.get_linestyle() == "--"]
    assert budget_lines and budget_lines[0].get_xdata()[0] == 1000
    assert len(axes) == 3  # two panels and one validation axis (the old metadata has none)
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
