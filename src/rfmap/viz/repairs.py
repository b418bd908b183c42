"""The figures of the chapter on repairing folded maps: a folded 2D map beside its repair, and a bent cube whose boundary surface crosses
itself beside its repair."""
from __future__ import annotations

from ..core.mesh import element_measures
from .figures import style
from .meshes import plot_mesh, plot_slice_outline

__all__ = ["fold_repair_figure", "surface_crossing_figure"]


def fold_repair_figure(raw, repaired, n: int, *, margin: float = 0.06):
    """A folded 2D map and its repair (the chapter on repairing folded maps): (a) the raw map with its flipped triangles circled, (b) the
    repaired map, (c) both around the folds (``margin`` beyond the folds' centroids), in the book's style.
    ``raw``, ``repaired``: :class:`rfmap.core.result.MapResult` of one ``n``-grid.  Returns the figure."""
    import matplotlib.pyplot as plt

    det = element_measures(raw.mapped_points, raw.elements)
    centres = raw.mapped_points[raw.elements[det <= 0]].mean(1)
    with style():
        fig, axes = plt.subplot_mosaic("ab;cc", figsize=(7.0, 6.6), layout="constrained")
        plot_mesh(axes["a"], raw.mapped_points, n=n, title=f"(a) raw map: {len(centres)} flipped")
        axes["a"].plot(*centres.T, "o", color="crimson", ms=9, mfc="none", mew=1.5)
        plot_mesh(axes["b"], repaired.mapped_points, n=n, title="(b) repaired map")
        for ax in (axes["a"], axes["b"]):
            ax.spines[["left", "bottom"]].set_visible(False)
        lo, hi = centres.min(0) - margin, centres.max(0) + margin
        # the raw map first and faint, the repaired map over it: where the two differ, the repair is seen
        axes["c"].triplot(*raw.mapped_points.T, raw.elements, lw=0.6, ls="--", color="tab:orange", alpha=0.8,
                          label="raw map", zorder=1)
        axes["c"].triplot(*repaired.mapped_points.T, repaired.elements, lw=1.1, color="tab:blue",
                          label="repaired map", zorder=2)
        axes["c"].plot(*centres.T, "o", color="crimson", ms=6, mfc="none", label="flipped (raw map)")
        axes["c"].set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), aspect="equal",
                      title="(c) close-up around the folds")
        axes["c"].legend(loc="upper left", bbox_to_anchor=(1.02, 1), borderaxespad=0)
    return fig


def surface_crossing_figure(bent, repaired, n: int, turns: float, scale: float):
    """The middle slice of a bent cube whose boundary surface crosses itself (``bent``, mapped points of the
    ``n``-grid, bent through ``turns`` turns) beside its repair (``repaired``, the displacement kept at ``scale``),
    in the book's style (the chapter on repairing folded maps), both panels on the same axes' limits.  Returns the
    figure."""
    import matplotlib.pyplot as plt

    with style():
        fig, axes = plt.subplots(1, 2, figsize=(7.0, 3.9), layout="constrained")
        plot_slice_outline(axes[0], bent, n, title=f"(a) raw: bent through {turns:g} turns,\nthe ends overlap")
        plot_slice_outline(axes[1], repaired, n, title=f"(b) repaired: displacement\n× {scale:.3f}")
        # one scale for both panels, so that the repaired bar is seen as nearly straight beside the bent one
        x0, x1 = min(a.get_xlim()[0] for a in axes), max(a.get_xlim()[1] for a in axes)
        y0, y1 = min(a.get_ylim()[0] for a in axes), max(a.get_ylim()[1] for a in axes)
        for a in axes:
            a.set(xlim=(x0, x1), ylim=(y0, y1))
    return fig
