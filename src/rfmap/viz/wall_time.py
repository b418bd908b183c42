"""The validation metric of several trained models against the wall time of their last runs, one small panel per
model, grouped."""
from __future__ import annotations

from .studies import decade_ticks
from .training import validation_vs_time

__all__ = ["validation_time_figure"]


def validation_time_figure(groups: dict, *, width: float = 7.2, ncols: int = 2):
    """The mean held-out validation metric against the wall time of the last run
    (:func:`rfmap.viz.training.validation_vs_time`, log axes, folded states marked), one small panel per model,
    ``ncols`` to a row: each entry of ``groups`` (``{title: {name: meta}}``) starts a new row, and each panel is
    titled with the group's title and the model's name, and with the minutes of the earlier runs of its chain where
    there were some. The time axes are shared and labelled at the powers of ten; one legend below the panels says
    what the filled and the open markers mean. Returns the figure."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    cells = []  # (group title, name, meta), a group starting a new row
    for title, metas in groups.items():
        cells += [(title, name, meta) for name, meta in metas.items()]
        cells += [None] * (-len(cells) % ncols)
    nrows = len(cells) // ncols
    fig, axes = plt.subplots(nrows, ncols, figsize=(width, 2.35 * nrows + 0.5), layout="constrained",
                             squeeze=False, sharex=True)
    for ax, cell in zip(axes.flat, cells):
        if cell is None:
            ax.set_axis_off()
            continue
        title, name, meta = cell
        validation_vs_time({name: meta}, ax, logx=True, legend=None, mark_folded=True)
        decade_ticks(ax.xaxis)
        label = ax.get_lines()[0].get_label() if ax.get_lines() else name
        ax.set_title(f"{title}: {label}".replace(" (after ", "\n(after "), fontsize="medium")
        ax.set_xlabel("")
        ax.tick_params(labelbottom=True)
    for ax in axes[:, 1:].flat:
        ax.set_ylabel("")
    for ax in axes.flat:
        if ax.axison:
            ax.set_xlabel("wall time of the last run (min)")
    handles = [Line2D([], [], ls="-", marker="o", ms=3, color="0.3", label="validated state"),
               Line2D([], [], ls="none", marker="o", ms=5, mfc="white", mec="0.3", mew=1.2,
                      label="validated state whose map folded on some held-out field")]
    fig.legend(handles=handles, loc="outside lower center", ncols=2, frameon=False)
    return fig
