"""The validation metric of several trained models against the wall time of their last runs, one stacked panel
per group of models."""
from __future__ import annotations

from .studies import decade_ticks
from .training import validation_vs_time

__all__ = ["validation_time_figure"]


def validation_time_figure(groups: dict, *, width: float = 7.2):
    """The mean held-out validation metric against the wall time of the last run
    (:func:`rfmap.viz.training.validation_vs_time`, log axes, folded states marked), one panel per entry of
    ``groups`` (``{title: {name: meta}}``), stacked, each with its legend to the right of the axes and its minutes
    labelled at the powers of ten. Returns the figure."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(groups), 1, figsize=(width, 2.9 * len(groups)), layout="constrained",
                             squeeze=False)
    for ax, (title, metas) in zip(axes[:, 0], groups.items()):
        validation_vs_time(metas, ax, logx=True, legend=None, mark_folded=True)
        decade_ticks(ax.xaxis)
        ax.set_title(title)
        handles, labels = ax.get_legend_handles_labels()
        labels = [lab.replace(" (after ", "\n(after ") for lab in labels]  # narrow: the note on a line of its own
        ax.legend(handles, labels, loc="center left", bbox_to_anchor=(1.02, 0.5), frameon=False)
    return fig
