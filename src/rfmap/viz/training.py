"""Training: the fields of a batch, the loss terms element by element, loss and validation curves."""
from __future__ import annotations

import numpy as np

from ..core.wording import format_sig
from ..training.validation import has_folds
from .meshes import plot_density, plot_mesh
from .studies import plain_log_ticks

__all__ = ["LOSS_TERMS", "VAL_NAMES", "plot_batch", "plot_loss_terms", "loss_terms_figure", "training_curves",
           "learning_curves", "validation_vs_time", "race_bars", "plot_learning_rates"]


#: the loss terms of training (keys of :func:`rfmap.tasks.base.task_loss` and :func:`rfmap.tasks.losses.loss_integrands`)
LOSS_TERMS = {"density": r"density mismatch $L(\tilde\rho - 1)$", "mu2": r"Beltrami energy $|\mu|^2$",
              "beltrami": r"$\mu$ mismatch $|\mu(u) - \mu_{in}|^2$", "fold": r"fold penalty relu$(\tau - \det J)$",
              "area": "area constraint"}


def plot_batch(axes, batch, *, title: str = "sample", mesh: bool = False):
    """The random fields of a training batch (:class:`rfmap.tasks.base.Batch`, 2D), one per axes, on their jittered
    mesh: the unit-mass density at the vertices, or :math:`|\\mu|` per triangle for a Beltrami batch.

    Parameters
    ----------
    axes : iterable of matplotlib Axes
        One per sample drawn, from the first.
    batch : rfmap.tasks.base.Batch
        A 2D batch (:func:`rfmap.tasks.base.sample_batch`).
    title : str
        Start of every panel's title, followed by the sample's index, what is drawn and the grid side.
    mesh : bool
        Also draw the edges of each sample's jittered mesh, in thin white lines over the colours, so that the
        irregular point set the network sees shows.
    """
    el = batch.elements.numpy()
    for i, ax in enumerate(axes):
        ref = batch.ref[i].numpy()
        if batch.density is not None:
            plot_density(ax, ref, el, batch.density[i].numpy(), title=f"{title} {i}: density, N = {batch.n}")
        else:
            plot_density(ax, ref, el, batch.mu_target[i].abs().numpy(), cmap="magma", vmin=0,
                         title=f"{title} {i}: $|\\mu|$, N = {batch.n}")
        if mesh:
            ax.triplot(ref[:, 0], ref[:, 1], el, color="white", lw=0.3, alpha=0.8)
        ax.set_xticks([])
        ax.set_yticks([])


def plot_loss_terms(axes, mapped, elements, terms: dict, *, sample: int = 0, n: int | None = None,
                    keys=None):
    """One sample's map and its loss terms element by element (:func:`rfmap.tasks.losses.loss_integrands`) on the
    mapped mesh: ``axes[0]`` the mapped grid (at most 16 lines a direction), then one panel per key of ``keys``
    (default: every element-wise term present), titled with the term's value (its weighted mean, as in training)."""
    import torch

    keys = [k for k in (LOSS_TERMS if keys is None else keys) if k in terms and k != "area"]
    pts = np.asarray(mapped[sample])
    el = np.asarray(elements)
    # at most 16 grid lines a direction, so that a strongly squeezed region stays readable
    plot_mesh(axes[0], pts, el, n=n, max_lines=16, title="the map $u$")
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
        title = f"{LOSS_TERMS[key]}\n= {format_sig(value, 3)}"
        top = float(vals.max())
        if top > 0:
            # a colour bar of small values in units of a power of ten, named in the title
            scale = int(np.floor(np.log10(top))) if top < 1e-2 else 0
            if scale:
                vals, top = vals / 10.0 ** scale, top / 10.0 ** scale
                title += f"  (bar ×10{str(scale).translate(_SUPERSCRIPT)})"
            plot_density(ax, pts, el, vals, cmap="magma", vmin=0, vmax=top, title=title)
        else:  # a colour map of zeros says nothing: say it in words
            plot_mesh(ax, pts, el, n=n, title=title, color="0.75")
            ax.text(0.5, 0.5, "0 on every\nelement", transform=ax.transAxes, ha="center", va="center",
                    bbox=dict(facecolor="white", edgecolor="0.6"))
            ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])


def _panel_rows(count: int, ncols: int) -> list[int]:
    """How many panels each row of one model's block holds: as few rows of at most ``ncols`` as hold ``count``
    panels, filled evenly (4 panels in rows of 2 and 2, 3 in one row, 5 in rows of 3 and 2)."""
    nrows = -(-count // ncols)
    per_row = -(-count // nrows)
    return [min(per_row, count - i * per_row) for i in range(nrows)]


def loss_terms_figure(columns: dict, *, n: int | None = None, sample: int = 0, ncols: int = 3):
    """The loss terms of one sample of several models (:func:`plot_loss_terms`): ``columns`` maps a model's title
    (``"DEQ model"``) to ``(mapped, elements, terms, keys)`` as ``rfmap.tasks.batch_loss_terms`` returns them, with
    the terms of its loss to draw. Each model's panels (its map, then each of its terms that is not zero on every
    element of the sample) form a block of rows below the previous model's, as few rows of at most ``ncols``
    panels as hold them, filled evenly. Every row shares one grid of equal cells, as many as the widest row has
    panels, filled from the left: the maps of all models sit in the first column at one size, and a shorter row
    leaves its last cells empty. The terms that are zero everywhere are named in a line under the panels instead of drawn. 7.2 inches
    wide. Returns the figure."""
    import matplotlib.pyplot as plt
    import torch

    def zero(terms, key):
        v = terms[key][sample]
        return float(v.max() if isinstance(v, torch.Tensor) else np.max(v)) <= 0

    drawn, zeros = {}, []
    for title, (_, _, terms, keys) in columns.items():
        keys = [k for k in keys if k in terms and k != "area"]
        drawn[title] = [k for k in keys if not zero(terms, k)]
        zeros += [f"{LOSS_TERMS[k].split(' $')[0].split(' relu')[0]} ({title})" for k in keys if zero(terms, k)]
    rows = {title: _panel_rows(1 + len(keys), ncols) for title, keys in drawn.items()}
    widest = max(max(r) for r in rows.values())  # the columns of the one grid of every row
    nrows = sum(len(r) for r in rows.values())
    height = 0.86 * 7.2 / widest  # a panel about as tall as wide, with its title
    fig = plt.figure(figsize=(7.2, nrows * height + (0.3 if zeros else 0)), layout="constrained")
    gs = fig.add_gridspec(nrows, widest)
    row = 0
    for title, (mapped, elements, terms, _) in columns.items():
        panels = []
        for k in rows[title]:
            panels += [fig.add_subplot(gs[row, j]) for j in range(k)]
            row += 1
        plot_loss_terms(panels, mapped, elements, terms, sample=sample, n=n, keys=drawn[title])
        panels[0].set_title(f"{title}: the map $u$")
    if zeros:
        import textwrap

        fig.supxlabel(textwrap.fill("zero on every element of this sample, not drawn: " + "; ".join(zeros), 80))
    return fig


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


def training_curves(log_path, fig=None, *, ncols: int = 2):
    """The loss of a training run and each of its terms against the step, from the run's ``log.jsonl``
    (:func:`rfmap.training.loop.train`): one panel per quantity (the total loss first), each with a linear axis from
    zero and its own range, the step axis spanning the logged steps; a term that is zero at every step says so in
    its panel. ``ncols`` panels per row; returns the figure."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    recs, _ = _read_log(log_path)
    keys = [k for k in LOSS_TERMS if recs and k in recs[0]]
    quantities = [("loss", "total loss")] + [(k, LOSS_TERMS[k]) for k in keys]
    ncols = max(1, min(ncols, len(quantities)))
    nrows = -(-len(quantities) // ncols)
    if fig is None:
        fig = plt.figure(figsize=(7.2, 2.2 * nrows + 0.4), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True)
    steps = np.array([r["step"] for r in recs], dtype=float)
    for ax, (key, label) in zip(axes.flat, quantities):
        vals = np.array([r[key] for r in recs], dtype=float)
        ax.plot(steps, vals, color="k" if key == "loss" else "tab:blue", lw=1.2)
        ax.set_title(label)
        ax.set_ylim(0, float(vals.max()) * 1.08 if len(vals) and vals.max() > 0 else 1.0)
        if not len(vals) or float(vals.max()) <= 0:
            ax.text(0.5, 0.5, "0 at every step", transform=ax.transAxes, ha="center", va="center")
        if len(steps):
            ax.set_xlim(steps.min(), max(steps.max(), steps.min() + 1))
        ax.xaxis.set_major_locator(MaxNLocator(5, integer=True))
    for ax in axes[-1]:
        ax.set_xlabel("step")
    for ax in list(axes.flat)[len(quantities):]:
        ax.set_axis_off()
    return fig


def _val_key(val: list[dict]) -> str | None:
    return next((k for k in ("std_rho_map", "mean_dd") if val and all(k in v for v in val)), None)


#: how a validation metric of the histories is named on an axis
VAL_NAMES = {"std_rho_map": r"Std($\tilde\rho_{map}$)", "mean_dd": r"mean $|\Delta d|$"}


def _times(ratio: float) -> str:
    """A multiple for a title to three significant digits, as the budget table prints it: ``25.5×`` or ``1.5×``
    from 1 on, a share in per cent below (``57.3 % of``)."""
    if ratio >= 1:
        return f"{ratio:.3g}×"
    return f"{100 * ratio:.3g} % of"


def _chain_axis(ax, xs, offset: int, budget: int):
    """Fit the step axis to the stored steps ``xs`` (counted over the whole chain); mark the paper's budget when it
    falls inside."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    lo, hi = (min(xs), max(xs)) if xs else (offset, offset + 1)
    pad = 0.03 * max(hi - lo, 1)
    ax.set_xlim(lo - pad, hi + pad)
    if lo - pad <= budget <= hi + pad:
        ax.axvline(budget, color="tab:red", ls="--", lw=1)
        ax.text(budget, 0.97, " paper ", color="tab:red", va="top", ha="left", transform=ax.get_xaxis_transform())
    ax.xaxis.set_major_locator(MaxNLocator(4))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1e3:g}k" if abs(x) >= 1e3 else f"{x:g}"))
    ax.set_xlabel("step of the chain" + (f" (0–{offset:,}: earlier runs, not shown)" if offset else ""))


def learning_curves(metas: dict, budgets: dict, *, ncols: int = 1, mark_folded: bool = False,
                    score: bool = False, mark_kept: bool = False):
    r"""The learning curves of trained models from their metadata (``Surrogate.meta``): for each model one panel
    for the running mean of the loss and one for the mean held-out validation metric of its last run (log scales),
    against the step counted over its whole ``--init`` chain. The step axis spans the stored steps: the
    ``cumulative_steps - steps`` steps of the earlier runs, whose curves are not stored, are named in its label,
    and the paper's budget of steps (``budgets[name]``) is dashed where it falls inside. The loss panel's title
    gives the chain's steps as a multiple of the paper's (``22.3× the paper's epochs``), or a share below it, as the
    training chapter's budget table counts them.
    ``ncols`` models per row (two panels each), 7.2 inches wide in all; ``mark_folded`` draws open markers on the
    validated states whose maps folded on some held-out field. With ``score`` the validation panel draws the score
    that chose the kept weights (:func:`rfmap.training.validation.score`: the checkpoint score where recorded, else
    the mean with every folded map counted as the identity) instead of the plain mean, which one folded map can inflate
    without bound, and a star marks the kept weights at their step, the value the recipe table records; where only
    the plain mean is stored, open circles mark the states with a folded map, which ranked behind every fold-free
    one; with ``mark_folded`` as well, open circles mark them on every score. Values below 0.01 are drawn in units
    of a power of ten named on the axis. ``mark_kept`` does the same for the plain mean: the last validation (the
    kept weights validated again as the run ended) becomes a star at the kept weights' step instead of a point at
    the run's end. Returns the figure."""
    import matplotlib.pyplot as plt

    names = list(metas)
    ncols = max(1, min(ncols, len(names)))
    nrows = -(-len(names) // ncols)
    fig, axes = plt.subplots(nrows, 2 * ncols, figsize=(7.2, 2.3 * nrows + 0.2), layout="constrained",
                             squeeze=False)
    for k, name in enumerate(names):
        ax, ax_val = axes[k // ncols, 2 * (k % ncols)], axes[k // ncols, 2 * (k % ncols) + 1]
        meta, budget = metas[name], budgets[name]
        hist = meta.get("history", {})
        last = int(meta.get("steps", hist["step"][-1] if hist.get("step") else 0))
        total = int(meta.get("cumulative_steps", last))
        offset = max(0, total - last)
        xs = [s + offset for s in hist.get("step", [])]
        ax.semilogy(xs, hist.get("loss", []), color="tab:blue", lw=1.2)
        plain_log_ticks(ax.yaxis)
        ax.set_title(f"{name}: {total:,} steps,\n{_times(total / budget)} the paper's epochs as steps")
        ax.set_ylabel("loss (running mean)")
        _chain_axis(ax, xs, offset, budget)
        val = hist.get("validation", [])
        key = _val_key(val)
        if key and score:
            _score_panel(ax_val, meta, val, key, offset, budget, mark_folded)
        elif key:
            vx = [v["step"] + offset for v in val]
            shown = val[:-1] if mark_kept and len(val) > 1 else val
            ax_val.semilogy(vx[:len(shown)], [v[key] for v in shown], "o-", color="tab:orange", ms=3, lw=1)
            if mark_folded:
                _folded_marks(ax_val, vx, ([v[key] for v in shown], shown), "tab:orange")
            if mark_kept:
                vx = vx[:len(shown)] + [_kept_marker(ax_val, meta, val, key, offset)]
            plain_log_ticks(ax_val.yaxis)
            ax_val.set_ylabel(f"held-out {VAL_NAMES[key]}")
            ax_val.set_title("validation" + (" (★ kept weights)" if mark_kept else ""))
            _chain_axis(ax_val, vx, offset, budget)
        else:
            ax_val.set_axis_off()
            ax_val.text(0.5, 0.5, "no validation\nstored", transform=ax_val.transAxes, ha="center", va="center")
    for ax in list(axes.flat)[2 * len(names):]:
        ax.set_axis_off()
    return fig


def _kept_marker(ax, meta: dict, val: list[dict], key: str, offset: int) -> int:
    """A star at the kept weights (``meta["selected_step"]``, else the run's end) with the value of the last
    validation, which validated them again; returns its step on the chain's axis."""
    kept = meta.get("selected_step")
    kx = offset + (int(kept) if kept is not None else int(val[-1]["step"]))
    ax.plot([kx], [val[-1][key]], "*", color="tab:red", ms=10, zorder=3)
    return kx


def _selection_value(record: dict, key: str) -> tuple[float, str]:
    """The score that chose among a run's validated weights, from one validation record of a history, and what it
    is: the checkpoint score (``"family score (Std ratio)"``) where recorded, else the mean metric with every folded
    map counted as the identity (``penalized``), else the capped or the plain mean, as
    :func:`rfmap.training.validation.score` ranks them."""
    if "family_score" in record:
        return float(record["family_score"]), "family score (Std ratio)"
    for k in ("penalized", "capped"):
        if k in record:
            return float(record[k]), f"{VAL_NAMES[key]}, folds as identity"
    return float(record[key]), VAL_NAMES[key]


def _score_panel(ax, meta: dict, val: list[dict], key: str, offset: int, budget: int,
                 mark_folded: bool = False) -> None:
    """The validation panel of :func:`learning_curves` with ``score``: the selection score of every validation
    but the last (the kept weights validated once more as the run ended), and a star at the kept weights' step;
    open circles on the states whose maps folded on some held-out field, where the score is the plain mean or
    ``mark_folded`` asks for them."""
    values = [_selection_value(v, key) for v in val]
    ys = np.array([v for v, _ in values])
    label = values[-1][1]
    scale = 0
    if ys.max() < 1e-2:  # small values in units of a power of ten, not long strings of digits
        scale = int(np.floor(np.log10(ys.max())))
        ys = ys / 10.0 ** scale
    vx = [v["step"] + offset for v in val]
    ax.plot(vx[:-1], ys[:-1], "o-", color="tab:orange", ms=3, lw=1)
    kept = meta.get("selected_step")
    kx = offset + int(kept) if kept is not None else vx[-1]
    ax.plot([kx], [ys[-1]], "*", color="tab:red", ms=10, zorder=4)  # over an open circle at the same state
    title = "validation (★ kept weights)"
    if mark_folded or label == VAL_NAMES[key]:  # plain mean: a state with a folded map ranked behind the others
        folded = [(x, y) for x, y, v in zip(vx[:-1], ys[:-1], val) if has_folds(v)]
        if folded:
            ax.plot(*zip(*folded), "o", ms=6, mfc="white", mec="tab:orange", mew=1.2, zorder=3)
            title = "validation (★ kept, ○ folded)"
    ax.set_yscale("log")
    plain_log_ticks(ax.yaxis)
    unit = f" (×10{str(scale).translate(_SUPERSCRIPT)})" if scale else ""
    if len(label) > 24:  # two lines: the metric, then how folded maps count
        label = label.replace(", ", ",\n")
    ax.set_ylabel(f"held-out {label}{unit}")
    ax.set_title(title)
    _chain_axis(ax, vx + [kx], offset, budget)


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def race_bars(metas: dict, ax=None, *, key: str = "std_rho_map"):
    """The outcome of a race of models trained for the same wall time (``rfmap train --time-limit``), one bar per
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


def _folded_marks(ax, xs, val, color):
    """Open markers on the validated states whose maps folded on some held-out field (``folded_fields`` > 0, or
    in older histories, which do not count folded fields, ``n_flipped`` > 0)."""
    pts = [(x, y) for x, y, v in zip(xs, *val) if has_folds(v)]
    if pts:
        ax.plot(*zip(*pts), "o", ms=5, mfc="white", mec=color, mew=1.2, zorder=3)


def validation_vs_time(metas: dict, ax=None, *, key: str | None = None, logx: bool = False,
                       legend: str = "inside", mark_folded: bool = False, minutes: bool = False):
    """The mean held-out validation metric of each model against the wall time of its last run (minutes), from the
    metadata histories (``Surrogate.meta``); the minutes of the earlier runs of an ``--init`` chain, whose curves are
    not stored, are given in the legend, so that every curve starts at zero and the axis spans the data. ``key``
    defaults to the metric the histories share (``std_rho_map`` for densities, ``mean_dd`` for Beltrami maps); log y
    axis (linear when the values span less than a factor of 3); ``logx`` puts the minutes on a log axis too, so that
    short and long runs both read; ``legend="outside"`` puts the legend below the axes, ``None`` leaves it out;
    ``mark_folded`` draws open markers on the states whose maps folded on some held-out field (their plain mean
    includes the Std of a folded map, which is what makes a curve spike); ``minutes`` adds the wall time of each
    model's last run to its legend entry; returns the axes."""
    import matplotlib.pyplot as plt

    if key is None:
        keys = [_val_key(m.get("history", {}).get("validation", [])) for m in metas.values()]
        key = next((k for k in keys if k), "std_rho_map")
    if ax is None:
        _, ax = plt.subplots(figsize=(5.2, 3.4), layout="constrained")
    chained = False  # whether some curve is the last run of a chain: the axis is then that run's time
    for k, (name, meta) in enumerate(metas.items()):
        val = [v for v in meta.get("history", {}).get("validation", []) if v.get("elapsed") is not None and key in v]
        if not val:
            continue
        earlier = float(meta.get("cumulative_wall_time", meta.get("wall_time", 0.0))) - float(meta.get("wall_time", 0.0))
        chained = chained or earlier >= 30
        label = f"{name} (after {earlier / 60:,.0f} min of earlier runs)" if earlier >= 30 else name
        if minutes:
            label += f", {float(meta.get('wall_time', 0.0)) / 60:.3g} min"
        if logx:
            val = [v for v in val if v["elapsed"] > 0]
        xs, ys = [v["elapsed"] / 60 for v in val], [v[key] for v in val]
        ax.semilogy(xs, ys, "o-", color=f"C{k}", ms=3, lw=1.2, label=label)
        if mark_folded:
            _folded_marks(ax, xs, (ys, val), f"C{k}")
    ys = [y for line in ax.get_lines() for y in line.get_ydata()]
    if ys and max(ys) < 3 * min(ys):  # a narrow range reads better on a linear axis
        ax.set_yscale("linear")
    else:
        plain_log_ticks(ax.yaxis)
    if logx:
        ax.set_xscale("log")
        plain_log_ticks(ax.xaxis)
    else:
        ax.set_xlim(left=0)
    ax.set(xlabel="wall time of the last run (min)" if chained else "training wall time (min)", ylabel=f"held-out mean {VAL_NAMES.get(key, key)}")
    if legend == "outside":
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.22), ncols=1, frameon=False)
    elif legend:
        ax.legend()
    return ax


def plot_learning_rates(ax, rates: dict, *, title: str = "", stops=()):
    """Learning-rate schedules against the optimiser step on a log axis, one line per entry of ``rates`` (label ->
    the rate of every step, :func:`rfmap.training.state.learning_rates`); a rate of zero is left out.  ``stops``
    names the entries whose run a time limit stopped: a cross marks the last step of each (one legend entry,
    "time limit reached").  Returns the axes."""
    marked = False
    for k, (label, r) in enumerate(rates.items()):
        r = np.asarray(r, dtype=float)
        steps = np.arange(1, len(r) + 1)
        keep = r > 0
        ax.semilogy(steps[keep], r[keep], color=f"C{k}", lw=1.4, label=label)
        if label in stops and keep[-1]:
            ax.plot(steps[-1], r[-1], "x", color="k", ms=7, mew=1.6,
                    label=None if marked else "time limit reached")
            marked = True
    ax.set(xlabel="optimiser step", ylabel="learning rate", title=title)
    ax.set_xlim(left=0)
    ax.legend()
    return ax
