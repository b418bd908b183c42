"""The figures of the chapter on repairing folded maps: a folded 2D map beside its repair, and a bent cube whose boundary surface crosses
itself beside its repair."""
from __future__ import annotations

import numpy as np

from ..core.mesh import element_measures
from .figures import style
from .meshes import plot_mesh, plot_slice_outline

__all__ = ["fold_repair_figure", "surface_crossing_figure"]


def fold_repair_figure(raw, repaired, n: int, *, margin: float = 0.03):
    """A folded 2D map and its repair (the chapter on repairing folded maps), in the book's style.

    Panels: (a) the raw map with its flipped triangles circled, (b) the repaired map, and close-ups around the folds
    (``margin`` beyond the flipped triangles' centroids), on the same limits: (c) the raw map with its flipped
    triangles filled and circled (a flipped triangle is often too thin to see), (d) the repaired map with the
    triangles whose vertices the repair moved filled.

    Parameters
    ----------
    raw, repaired : rfmap.core.result.MapResult
        The raw map and its repair on one ``n``-grid (same ``elements``, (T, 3)).
    n : int
        Grid side.
    margin : float
        Close-up margin, in the unit square's units.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    det = element_measures(raw.mapped_points, raw.elements)
    flipped = raw.elements[det <= 0]
    centres = raw.mapped_points[flipped].mean(1)
    moved_v = np.linalg.norm(repaired.mapped_points - raw.mapped_points, axis=1) > 1e-9
    moved = repaired.elements[moved_v[repaired.elements].any(1)]
    with style():
        fig, axes = plt.subplot_mosaic("ab;cd", figsize=(7.0, 6.0), layout="constrained")
        plot_mesh(axes["a"], raw.mapped_points, n=n, title=f"(a) raw map: {len(centres)} flipped")
        axes["a"].plot(*centres.T, "o", color="crimson", ms=9, mfc="none", mew=1.5)
        plot_mesh(axes["b"], repaired.mapped_points, n=n, title="(b) repaired map")
        lo, hi = centres.min(0) - margin, centres.max(0) + margin
        close = (("c", raw, flipped, "crimson", "(c) raw map, close-up:\nflipped triangles circled"),
                 ("d", repaired, moved, "tab:orange", "(d) repaired map, close-up:\ntriangles it moved filled"))
        for key, res, fill, colour, title in close:
            ax = axes[key]
            ax.add_collection(PolyCollection(res.mapped_points[fill], facecolor=colour, alpha=0.45, lw=0))
            ax.triplot(*res.mapped_points.T, res.elements, lw=0.5, color="tab:blue")
            if key == "c":
                ax.plot(*centres.T, "o", color="crimson", ms=14, mfc="none", mew=1.5)
            ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), aspect="equal", title=title)
        for ax in axes.values():
            ax.spines[["left", "bottom"]].set_visible(False)
    return fig


def surface_crossing_figure(bent, repaired, n: int, turns: float, scale: float):
    """The middle slice of a bent cube whose boundary surface crosses itself (``bent``, mapped points of the
    ``n``-grid, bent through ``turns`` turns) beside its repair (``repaired``, the displacement kept at ``scale``),
    in the book's style (the chapter on repairing folded maps), both panels on the same axes' limits, each with the
    undeformed slice (the unit square) faintly dashed.  Returns the figure."""
    import matplotlib.pyplot as plt

    with style():
        fig, axes = plt.subplots(1, 2, figsize=(7.0, 3.9), layout="constrained")
        plot_slice_outline(axes[0], bent, n, title=f"(a) raw: bent through {turns:g} turns,\nthe ends overlap")
        plot_slice_outline(axes[1], repaired, n, title=f"(b) repaired: displacement\n× {scale:.3f}")
        for a in axes:  # the slice before the map, the unit square, faintly dashed in both panels
            a.plot([0, 1, 1, 0, 0], [0, 0, 1, 1, 0], ls="--", lw=0.8, color="0.6", zorder=0)
        # one scale for both panels, so that the repaired bar is seen as nearly straight beside the bent one
        x0, x1 = min(a.get_xlim()[0] for a in axes), max(a.get_xlim()[1] for a in axes)
        y0, y1 = min(a.get_ylim()[0] for a in axes), max(a.get_ylim()[1] for a in axes)
        for a in axes:
            a.set(xlim=(x0, x1), ylim=(y0, y1))
    return fig
