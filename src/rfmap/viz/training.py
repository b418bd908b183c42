"""Training: the fields of a batch, the loss terms element by element, loss and validation curves."""
from __future__ import annotations

import numpy as np

from .meshes import plot_density, plot_mesh
from .studies import plain_log_ticks

__all__ = ["LOSS_TERMS", "VAL_NAMES", "plot_batch", "plot_loss_terms", "training_curves", "learning_curves",
           "validation_vs_time", "race_bars"]


#: the loss terms of training (keys of :func:`rfmap.tasks.task_loss` and :func:`rfmap.losses.loss_integrands`)
LOSS_TERMS = {"density": r"density mismatch $L(\tilde\rho - 1)$", "mu2": r"Beltrami energy $|\mu|^2$",
              "beltrami": r"$\mu$ mismatch $|\mu(u) - \mu_{in}|^2$", "fold": r"fold penalty relu$(\tau - \det J)$",
              "area": "area constraint"}


def plot_batch(axes, batch, *, title: str = "sample"):
    """The random fields of a training batch (:class:`rfmap.tasks.Batch`, 2D), one per axes, on their jittered
    mesh: the unit-mass density at the vertices, or :math:`|\\mu|` per triangle for a Beltrami batch."""
    el = batch.elements.numpy()
    for i, ax in enumerate(axes):
        ref = batch.ref[i].numpy()
        if batch.density is not None:
            plot_density(ax, ref, el, batch.density[i].numpy(), title=f"{title} {i}: density, N = {batch.n}")
        else:
            plot_density(ax, ref, el, batch.mu_target[i].abs().numpy(), cmap="magma", vmin=0,
                         title=f"{title} {i}: $|\\mu|$, N = {batch.n}")
        ax.set_xticks([])
        ax.set_yticks([])


def plot_loss_terms(axes, mapped, elements, terms: dict, *, sample: int = 0, n: int | None = None,
                    keys=None):
    """One sample's map and its loss terms element by element (:func:`rfmap.losses.loss_integrands`) on the
    mapped mesh: ``axes[0]`` the mapped grid, then one panel per key of ``keys`` (default: every element-wise term
    present), titled with the term's value (its weighted mean, as in training)."""
    import torch

    keys = [k for k in (keys or LOSS_TERMS) if k in terms and k != "area"]
    pts = np.asarray(mapped[sample])
    el = np.asarray(elements)
    plot_mesh(axes[0], pts, el, n=n, title="the map $u$")
    for ax in axes:
        for side in ax.spines.values():
            side.set_visible(False)
    axes[0].set_xticks([])
    axes[0].set_yticks([])
    axes[0].set_aspect("equal")
    w = terms["weight"][sample]
    for ax, key in zip(axes[1:], keys):
        vals = terms[key][sample]
        value = float((vals * w).sum() / w.sum()) if isinstance(vals, torch.Tensor) else float(
            np.sum(vals * w) / np.sum(w))
        vals = np.asarray(vals)
        title = f"{LOSS_TERMS[key]}\n= {value:.3g}"
        if float(vals.max()) > 0:
            plot_density(ax, pts, el, vals, cmap="magma", vmin=0, vmax=float(vals.max()), title=title)
        else:  # a colour map of zeros says nothing: say it in words
            plot_mesh(ax, pts, el, n=n, title=title, color="0.75")
            ax.text(0.5, 0.5, "0 on every\nelement", transform=ax.transAxes, ha="center", va="center",
                    bbox=dict(facecolor="white", edgecolor="0.6"))
            ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])


def _read_log(log_path) -> tuple[list[dict], list[dict]]:
    import json

    steps, vals = [], []
    with open(log_path) as f:
        for line in f:
            rec = json.loads(line)
            if "loss" in rec:
                steps.append(rec)
            elif "validation" in rec and not rec.get("final"):
                vals.append(rec)
    return steps, vals


def training_curves(log_path, ax=None):
    """The loss of a training run and each of its terms against the step, from the run's ``log.jsonl``
    (:func:`rfmap.training.loop.train`); a term is not drawn at steps where it is zero (log axis), and one that is
    zero throughout says so in the legend; returns the axes."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    recs, _ = _read_log(log_path)
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 3.4), layout="constrained")
    steps = [r["step"] for r in recs]
    ax.semilogy(steps, [r["loss"] for r in recs], "k-", lw=1.6, label="total loss")
    for key, label in LOSS_TERMS.items():
        if recs and key in recs[0]:
            vals = np.array([r[key] for r in recs], dtype=float)
            vals[vals <= 0] = np.nan  # a log axis has no zero: a step where the term vanishes leaves a gap
            ax.semilogy(steps, vals, lw=1, label=label + (" (0 at every step)" if np.isnan(vals).all() else ""))
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set(xlabel="step", ylabel="loss (batch)")
    ax.legend(fontsize=8)
    return ax


def _val_key(val: list[dict]) -> str | None:
    return next((k for k in ("std_rho_map", "mean_dd") if val and all(k in v for v in val)), None)


#: how a validation metric of the histories is named on an axis
VAL_NAMES = {"std_rho_map": r"Std($\tilde\rho_{map}$)", "mean_dd": r"mean $|\Delta d|$"}


def _percent(x: float) -> str:
    """A share in per cent for a title: whole numbers from 10 % (``2230 %``), two digits below (``1.2 %``)."""
    return f"{x:.0f} %" if x >= 10 else f"{x:.2g} %"


def learning_curves(metas: dict, budgets: dict, *, ncols: int = 2):
    r"""The learning curves of trained models from their metadata (``Surrogate.meta``), one panel per model: the
    running mean of the loss (log scale) and the mean held-out validation metric (right axis, log scale) of the
    model's last run, against the step counted over its whole ``--init`` chain (linear axis; the grey band holds the
    ``cumulative_steps - steps`` steps of its ancestors, whose curves are not stored), with the paper's budget of
    steps (``budgets[name]``) dashed.  The title gives the chain's steps and their share of the paper's, as the
    training chapter's budget table counts them.  ``ncols`` panels per row, 3.6 inches each; returns the figure."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    names = list(metas)
    ncols = max(1, min(ncols, len(names)))
    nrows = -(-len(names) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.6 * ncols, 2.8 * nrows), layout="constrained", squeeze=False)
    for ax, name in zip(axes.flat, names):
        meta, budget = metas[name], budgets[name]
        hist = meta.get("history", {})
        last = int(meta.get("steps", hist["step"][-1] if hist.get("step") else 0))
        total = int(meta.get("cumulative_steps", last))
        offset = max(0, total - last)
        right = max(budget, total) * 1.05
        if offset:
            ax.axvspan(0, offset, color="0.92", lw=0)
            ax.text(offset / 2, 0.04, "earlier\nruns", ha="center", va="bottom", color="0.35",
                    transform=ax.get_xaxis_transform(), clip_on=True)
        ax.semilogy([s + offset for s in hist.get("step", [])], hist.get("loss", []), color="tab:blue", lw=1.2)
        ax.axvline(budget, color="tab:red", ls="--", lw=1)
        left_half = budget < right / 2
        ax.text(budget, 0.97, f" paper: {budget:,} " if left_half else f"paper: {budget:,} ", color="tab:red",
                va="top", ha="left" if left_half else "right", transform=ax.get_xaxis_transform(), clip_on=True)
        plain_log_ticks(ax.yaxis)
        ax.set_title(f"{name}: {total:,} steps,\n{_percent(100 * total / budget)} of the paper's")
        ax.set_xlim(0, right)
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1e3:g}k" if x else "0"))
        ax.set_xlabel("step (whole chain)")
        ax.set_ylabel("loss (running mean)", color="tab:blue")
        val = hist.get("validation", [])
        key = _val_key(val)
        if key:
            ax2 = ax.twinx()
            ax2.semilogy([v["step"] + offset for v in val], [v[key] for v in val], "o-", color="tab:orange", ms=3,
                         lw=1)
            plain_log_ticks(ax2.yaxis)
            ax2.set_ylabel(f"held-out {VAL_NAMES[key]}", color="tab:orange")
            ax2.spines["right"].set_visible(True)
    for ax in list(axes.flat)[len(names):]:
        ax.set_axis_off()
    return fig


def race_bars(metas: dict, ax=None, *, key: str = "std_rho_map"):
    """The outcome of a race of models trained for the same wall time (:func:`rfmap.compare.race`), one bar per
    model: the held-out validation metric ``key`` of its final weights (``meta["final_metrics"]["mean"]``), labelled
    with the steps it made; returns the axes."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(3.6, 3.2), layout="constrained")
    names = list(metas)
    vals = [float(metas[k]["final_metrics"]["mean"][key]) for k in names]
    bars = ax.bar(names, vals, color=[f"C{k}" for k in range(len(names))], width=0.6)
    ax.bar_label(bars, [f"{v:.3g}\n{int(metas[k]['steps']):,} steps" for k, v in zip(names, vals)], padding=2)
    ax.set_ylim(0, max(vals) * 1.35)
    ax.set_ylabel(f"held-out mean {VAL_NAMES.get(key, key)}")
    return ax


def validation_vs_time(metas: dict, ax=None, *, key: str | None = None):
    """The mean held-out validation metric of each model against its training wall time (minutes, cumulative
    over ``--init`` chains), from the metadata histories (``Surrogate.meta``); ``key`` defaults to the metric the
    histories share (``std_rho_map`` for densities, ``mean_dd`` for Beltrami maps); log y axis; returns the axes."""
    import matplotlib.pyplot as plt

    if key is None:
        keys = [_val_key(m.get("history", {}).get("validation", [])) for m in metas.values()]
        key = next((k for k in keys if k), "std_rho_map")
    if ax is None:
        _, ax = plt.subplots(figsize=(5.2, 3.4), layout="constrained")
    for k, (name, meta) in enumerate(metas.items()):
        val = [v for v in meta.get("history", {}).get("validation", []) if v.get("elapsed") is not None and key in v]
        if not val:
            continue
        offset = float(meta.get("cumulative_wall_time", meta.get("wall_time", 0.0))) - float(meta.get("wall_time", 0.0))
        t = [(offset + v["elapsed"]) / 60 for v in val]
        ax.semilogy(t, [v[key] for v in val], "o-", color=f"C{k}", ms=3, lw=1.2, label=name)
        if offset > 0:
            ax.axvline(offset / 60, color=f"C{k}", ls=":", lw=0.8)
    ys = [y for line in ax.get_lines() for y in line.get_ydata()]
    if ys and max(ys) < 3 * min(ys):  # a narrow range reads better on a linear axis
        ax.set_yscale("linear")
    ax.set(xlabel="training wall time (min)", ylabel=f"held-out mean {VAL_NAMES.get(key, key)}")
    ax.legend()
    return ax
