"""Training: the fields of a batch, the loss terms element by element, loss and validation curves."""
from __future__ import annotations

import numpy as np

from .meshes import plot_density, plot_mesh

__all__ = ["LOSS_TERMS", "plot_batch", "plot_loss_terms", "training_curves", "learning_curves", "validation_vs_time"]


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
    w = terms["weight"][sample]
    for ax, key in zip(axes[1:], keys):
        vals = terms[key][sample]
        value = float((vals * w).sum() / w.sum()) if isinstance(vals, torch.Tensor) else float(
            np.sum(vals * w) / np.sum(w))
        vals = np.asarray(vals)
        plot_density(ax, pts, el, vals, cmap="magma", vmin=0, vmax=float(vals.max()) or 1.0,
                     title=f"{LOSS_TERMS[key]}\n= {value:.3g}")
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
    (:func:`rfmap.training.loop.train`); returns the axes."""
    import matplotlib.pyplot as plt

    recs, _ = _read_log(log_path)
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 3.4), layout="constrained")
    steps = [r["step"] for r in recs]
    ax.semilogy(steps, [r["loss"] for r in recs], "k-", lw=1.6, label="total loss")
    for key, label in LOSS_TERMS.items():
        if recs and key in recs[0]:
            ax.semilogy(steps, [max(r[key], 1e-12) for r in recs], lw=1, label=label)
    ax.set(xlabel="step", ylabel="loss (batch)")
    ax.legend(fontsize=7)
    return ax


def _val_key(val: list[dict]) -> str | None:
    return next((k for k in ("std_rho_map", "mean_dd") if val and all(k in v for v in val)), None)


def learning_curves(metas: dict, budgets: dict, *, ncols: int = 3):
    """The learning curves of trained models from their metadata (``Surrogate.meta``): the running mean of the
    loss against the step (log axes) and the mean validation metric (right axis), with the paper's budget of
    steps (``budgets[name]``) marked; returns the figure."""
    import matplotlib.pyplot as plt

    names = list(metas)
    nrows = -(-len(names) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.1 * ncols, 3.0 * nrows), layout="constrained", squeeze=False)
    for ax, name in zip(axes.flat, names):
        meta, budget = metas[name], budgets[name]
        hist = meta.get("history", {})
        steps = [max(s, 1) for s in hist.get("step", [])]
        ax.loglog(steps, hist.get("loss", []), color="tab:blue", lw=1.2)
        ax.axvline(budget, color="tab:red", ls="--", lw=1)
        ax.text(budget, 0.97, f" paper\n {budget:,}", color="tab:red", fontsize=7, va="top", ha="right",
                transform=ax.get_xaxis_transform())
        done = int(meta.get("steps", steps[-1] if steps else 0))
        ax.set_title(f"{name}\n{done:,} steps, {100 * done / budget:.2g} % of the paper's")
        ax.set_xlabel("step")
        ax.set_ylabel("loss (running mean)", color="tab:blue")
        ax.set_xlim(left=max(1, min(steps) if steps else 1), right=budget * 1.6)
        val = hist.get("validation", [])
        key = _val_key(val)
        if key:
            ax2 = ax.twinx()
            ax2.plot([v["step"] for v in val], [v[key] for v in val], "o-", color="tab:orange", ms=3, lw=1)
            ax2.set_ylabel(f"validation, mean {key}", color="tab:orange")
            ax2.spines["right"].set_visible(True)
    for ax in list(axes.flat)[len(names):]:
        ax.set_axis_off()
    return fig


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
    ax.set(xlabel="training wall time (min)", ylabel=f"held-out mean {key}")
    ax.legend(fontsize=8)
    return ax
