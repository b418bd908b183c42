"""The figures of the chapter on diffusion and density-equalizing maps: the classical density-equalizing map step by step (the paper's Fig. 3) and the
overview of the two kinds of field-driven map, drawn with the shipped surrogates (the paper's Fig. 1)."""
from __future__ import annotations

import numpy as np

from ..core.metrics import residual_parts
from .figures import color_scale, colorbar, frameless
from .meshes import TEXT_WIDTH_IN, plot_density, plot_mesh
from .studies import plain_log_ticks
from .volumes import CAMERA_3D, RHO_SCALE, render_lattice, render_slices

__all__ = ["dem_steps_figure", "overview_figure", "grid_convergence_figure", "solve_cost_figure",
           "boundaries_figure", "volume_panels_figure", "residual_parts_figure"]


def dem_steps_figure(densities: dict, meshes: dict, rho0, elements, *, n: int, lines: int = 12):
    r"""The paper's Fig. 3: the diffusing density and the mesh it carries.

    ``densities`` maps a time to the density on a regular grid (an image, the first axis x); ``meshes`` maps a time
    to the vertex positions of the ``n`` x ``n`` grid mesh at that time, its last entry the final map (one entry
    fewer than ``densities``: the last column holds the histogram).  The top row
    draws each density on one colour scale; the bottom row draws each mesh, its triangles coloured by their initial
    normalised density ``rho0`` (one value per element of ``elements``) on a second scale, with every k-th grid
    line (at most ``lines`` a direction) drawn so that a cell's growth is seen at the page's width, and beside them
    the histogram of :math:`\tilde\rho` on the original and the final mesh.  Returns the figure."""
    import matplotlib.pyplot as plt

    times, stages = list(densities), list(meshes)
    fig, axes = plt.subplots(2, len(times), figsize=(TEXT_WIDTH_IN, 5.4), layout="constrained")
    vmax = float(max(np.max(r) for r in densities.values()))
    for ax, t in zip(axes[0], times):
        im = ax.imshow(np.asarray(densities[t]).T, origin="lower", extent=(0, 1, 0, 1), vmin=0, vmax=vmax,
                       cmap="viridis")
        ax.set_title(f"$\\rho$ at t = {t:g}")
        frameless(ax)
    # under the row, so that the colour bar sits beside no column of the row below
    colorbar(im, ax=axes[0, :], location="bottom", shrink=0.6, aspect=30, label=r"density $\rho$")
    top = float(np.max(rho0))
    for i, (ax, t) in enumerate(zip(axes[1, :-1], stages)):
        last = i == len(stages) - 1
        pts = meshes[t]
        tri = plot_density(ax, pts, elements, rho0, vmin=0, vmax=top, colorbar=False,
                           title="final map" if last else f"mesh at t = {t:g}")
        plot_mesh(ax, pts, n=n, max_lines=lines, color="w", lw=0.7)
    colorbar(tri, ax=axes[1, :-1], location="bottom", shrink=0.6, aspect=30,
             label=r"initial $\tilde\rho$ of each triangle, carried by the map")
    hist = axes[1, -1]
    mapped = rho0 / _areas(meshes[stages[-1]], elements)  # the grid's triangles all have one area
    bins = np.linspace(0, 1.02 * top, 41)
    counts = [hist.hist(rho0, bins=bins, alpha=0.6, label="original")[0],
              hist.hist(mapped / mapped.mean(), bins=bins, alpha=0.8, label="mapped")[0]]
    hist.set_yscale("log")
    hist.set_xlabel(r"$\tilde\rho$")
    hist.set_ylabel("triangles")
    # ticks, label and spine on the right, outside the row of meshes, so that the columns stay even
    hist.yaxis.tick_right()
    hist.yaxis.set_label_position("right")
    hist.spines["right"].set_visible(True)
    hist.spines["left"].set_visible(False)
    hist.set_title(r"$\tilde\rho$ per triangle")
    # head room above the tallest bar on the log axis, where the legend sits without hiding a bar
    hist.set_ylim(0.7, 10 * float(max(c.max() for c in counts)))
    hist.legend(loc="upper right", framealpha=0.9, handlelength=1)
    return fig


def _areas(points, elements) -> np.ndarray:
    p = np.asarray(points)[np.asarray(elements)]
    a, b = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])


def _arrow(ax, label: str) -> None:
    ax.annotate("", xy=(1.0, 0.5), xytext=(0.0, 0.5), xycoords="axes fraction",
                arrowprops=dict(arrowstyle="-|>", lw=2, color="0.3"))
    ax.text(0.5, 0.62, label, ha="center", va="bottom", fontsize=9, transform=ax.transAxes)
    ax.text(0.5, 0.4, "$u = x + \\mathcal{B}\\odot\\psi$", ha="center", va="top", fontsize=9,
            transform=ax.transAxes)
    ax.set_axis_off()


def overview_figure(beltrami, density, *, name: str = "T4", slices=(0.25, 0.75), clim=(0.2, 1.8)):
    r"""The paper's Fig. 1: two field-driven maps made by a surrogate.

    ``beltrami`` is a 2D map from a Beltrami coefficient (its ``field`` the coefficient per triangle, ``name`` the
    name of the field in the titles); ``density`` a 3D map of the cube from a density.  The first row draws
    :math:`|\mu|` on the square and the mapped grid; the second the density on the horizontal slices
    :math:`x_3` = ``slices`` of the cube (:func:`rfmap.viz.volumes.render_slices`) and the same slices of the grid
    as the map moves them (:func:`rfmap.viz.volumes.render_lattice`, coloured by the initial density carried
    along), both seen from the one camera :data:`rfmap.viz.volumes.CAMERA_3D`, on the colour scale ``clim``.
    Returns the figure."""
    import matplotlib as mpl
    import matplotlib.pyplot as plt

    before = render_slices(density, mapped=False, slices=slices, clim=clim, camera=CAMERA_3D)
    after = render_lattice(density, mapped=True, carried=True, slices=slices, clim=clim, camera=CAMERA_3D)
    cut = " and ".join(f"{s:g}" for s in slices)
    fig = plt.figure(figsize=(TEXT_WIDTH_IN, 5.8), layout="constrained")
    grid = fig.add_gridspec(2, 3, width_ratios=[1, 0.55, 1])
    n = round(len(beltrami.ref_points) ** 0.5)
    ax = fig.add_subplot(grid[0, 0])
    plot_density(ax, beltrami.ref_points, beltrami.elements, np.abs(beltrami.field), cmap="magma", vmin=0,
                 title=f"(a) $|\\mu|$ of {name} on the square")
    ax = fig.add_subplot(grid[0, 2])
    plot_mesh(ax, beltrami.mapped_points, n=n, max_lines=24, title="the quasi-conformal map")
    ax = fig.add_subplot(grid[1, 0])
    ax.imshow(before)
    ax.set_title(f"(b) density $\\rho$ in the cube,\nslices $x_3$ = {cut}")
    ax.set_axis_off()
    ax2 = fig.add_subplot(grid[1, 2])
    ax2.imshow(after)
    ax2.set_title("the density-equalizing map: the\nsame slices moved (colour: initial $\\rho$)")
    ax2.set_axis_off()
    # the renderings' colour scale, as a bar under the row
    sc = color_scale(RHO_SCALE, clim=clim)
    bar = mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(sc.vmin, sc.vmax), cmap=sc.cmap)
    colorbar(bar, ax=[ax, ax2], location="bottom", shrink=0.5, aspect=30, label=r"density $\rho$")
    _arrow(fig.add_subplot(grid[0, 1]), "field $\\mu$\n$\\downarrow$\nsurrogate $\\mathcal{N}_\\theta$")
    _arrow(fig.add_subplot(grid[1, 1]), "field $\\rho$\n$\\downarrow$\nsurrogate $\\mathcal{N}_\\theta$")
    return fig


def grid_convergence_figure(sides, values, *, title: str = "",
                            ylabel: str = r"Std($\tilde\rho$) on the mapped mesh"):
    r"""A quantity against the grid spacing :math:`h = 1/(N-1)` of the grid sides ``sides``, on log axes, with a
    tick at every spacing of the study labelled ``1/(N-1)``.  Returns the figure.

    Parameters
    ----------
    sides : sequence of int
        The grid sides :math:`N`.
    values : sequence of float
        The quantity at each side (positive), by default Std(ρ̃) of the mapped mesh.
    title, ylabel : str
        The axes' title and the label of the quantity.
    """
    import matplotlib.pyplot as plt

    sides = np.asarray(sides)
    h = 1.0 / (sides - 1)
    fig, ax = plt.subplots(figsize=(4.4, 3.3), layout="constrained")
    ax.loglog(h, np.asarray(values), "o-")
    ax.set_xticks(h, [f"1/{n - 1}" for n in sides])
    ax.xaxis.set_minor_locator(plt.NullLocator())
    plain_log_ticks(ax.yaxis)
    # labels at 1, 2, 3, 5 and 7 times the powers of ten inside the data's range, so that the range is covered
    # where it spans less than a few decades
    lo, hi = sorted(ax.get_ylim())
    nice = [m * 10.0**e for e in range(int(np.floor(np.log10(lo))), int(np.ceil(np.log10(hi))) + 1)
            for m in (1, 2, 3, 5, 7)]
    inside = [v for v in nice if lo <= v <= hi]
    if 3 <= len(inside) <= 7:
        ax.set_yticks(inside, [f"{v:.3g}" for v in inside])
        ax.yaxis.set_minor_formatter(plt.NullFormatter())
    ax.set_xlabel("grid spacing $h$")
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    return fig


def solve_cost_figure(cost: dict, *, title: str = ""):
    """Wall time against the number of vertices, one line per dimension, on log axes with plain tick labels.

    Parameters
    ----------
    cost : dict
        Maps a dimension (2, 3) to its rows ``(N, vertices, seconds, ...)``; further entries of a row are ignored.
    title : str
        The axes' title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4.6, 3.4), layout="constrained")
    for (d, rows), marker in zip(sorted(cost.items()), ["o-", "s-", "^-"]):
        ax.loglog([r[1] for r in rows], [r[2] for r in rows], marker, label=f"{d}D")
    plain_log_ticks(ax.xaxis)
    plain_log_ticks(ax.yaxis)
    ax.set_xlabel("number of vertices")
    ax.set_ylabel("time (s)")
    if title:
        ax.set_title(title)
    ax.legend()
    return fig


def boundaries_figure(results: dict, rho0, *, n: int, vmax: float | None = None, lines: int = 40):
    r"""Mapped meshes side by side, each panel's triangles coloured by their initial :math:`\tilde\rho` ``rho0`` on
    one colour scale (its bar under the panels), with the grid lines in white and the unit square dashed, so that a
    free boundary's outline shows against the fixed one.

    Parameters
    ----------
    results : dict
        Maps a panel title to a 2D map of the ``n``-grid (:class:`rfmap.core.result.MapResult`).
    rho0 : ndarray, shape (m,)
        The value of every triangle, carried by the maps.
    n : int
        Grid side.
    vmax : float, optional
        Top of the colour scale (default: the largest value).
    lines : int
        At most this many grid lines a direction.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(TEXT_WIDTH_IN, TEXT_WIDTH_IN / 2), layout="constrained",
                             squeeze=False)
    top = float(np.max(rho0)) if vmax is None else vmax
    for ax, (title, res) in zip(axes[0], results.items()):
        im = plot_density(ax, res.mapped_points, res.elements, rho0, vmin=0, vmax=top, colorbar=False,
                          title=title)
        plot_mesh(ax, res.mapped_points, n=n, max_lines=lines, color="w", lw=0.25)
        ax.plot([0, 1, 1, 0, 0], [0, 0, 1, 1, 0], "k--", lw=0.6)
        ax.set_axis_off()
    colorbar(im, ax=axes[0, :], location="bottom", shrink=0.5,
             aspect=30, label=r"initial $\tilde\rho$ of each triangle, carried by the map")
    return fig


def volume_panels_figure(images, titles, *, clim, label: str, cmap: str = "viridis"):
    """Rendered images side by side (:func:`rfmap.viz.volumes.render_volume`, :func:`.render_lattice`) with their
    titles and one colour bar below them for the colour scale ``clim`` they were rendered on.

    Parameters
    ----------
    images : sequence of ndarray
        RGB(A) images.
    titles : sequence of str
        One title per image.
    clim : (float, float)
        The colour scale of the renders.
    label : str
        Label of the colour bar.
    cmap : str
        The colour map of the renders.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    fig, axes = plt.subplots(1, len(images), figsize=(TEXT_WIDTH_IN, 3.1), layout="constrained", squeeze=False)
    for ax, img, title in zip(axes[0], images, titles):
        ax.imshow(img)
        ax.set_title(title)
        ax.set_axis_off()
    colorbar(ScalarMappable(Normalize(*clim), cmap), ax=axes[0], location="bottom", shrink=0.6, aspect=30,
             label=label)
    return fig


def residual_parts_figure(results: dict, *, cells: int = 8, quantile: float = 0.99):
    r"""Where the residual density of density-equalizing maps sits: one row per map, three panels on the reference
    mesh (the unit square).

    The panels are the residual :math:`r_e = \tilde\rho_e - 1` of every element, its smooth part :math:`\bar r_v`
    (the reference-measure-weighted mean over the elements around each vertex,
    :func:`rfmap.core.metrics.residual_parts`), and a close-up of :math:`r_e` on a window of ``cells`` x ``cells``
    grid cells, with the element edges drawn, centred where the first map's element-scale rest
    :math:`|r_e - \bar r_e|` is largest (:math:`\bar r_e` the mean of :math:`\bar r_v` over the element's vertices);
    the same window in every row.  The residual and its close-up share one diverging colour scale, the smooth part
    has its own; both are symmetric about 0, shared by the rows, and reach the ``quantile`` of their absolute values
    (a few extreme elements do not wash the rest out).

    Parameters
    ----------
    results : dict
        Maps a row label to a fold-free 2D density-equalizing map of a grid mesh
        (:class:`rfmap.core.result.MapResult`).
    cells : int
        Side of the close-up window in grid cells.
    quantile : float
        Top of each colour scale, as a quantile of the absolute values.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    parts = {label: residual_parts(res.ref_points, res.mapped_points, res.elements, res.field)
             for label, res in results.items()}
    first = next(iter(results.values()))
    r0, s0 = parts[next(iter(parts))]
    centre = first.ref_points[first.elements[np.argmax(np.abs(r0 - s0[first.elements].mean(1)))]].mean(0)
    half = cells / (2 * (round(np.sqrt(len(first.ref_points))) - 1))
    lo = np.clip(centre - half, 0.0, 1.0 - 2 * half)
    tops = [float(np.quantile(np.abs(np.concatenate([p[k] for p in parts.values()])), quantile)) for k in (0, 1)]
    fig, axes = plt.subplots(len(results), 3, figsize=(TEXT_WIDTH_IN, 0.36 * TEXT_WIDTH_IN * len(results)),
                             layout="constrained", squeeze=False)
    titles = (r"residual $r_e$", r"smooth part $\bar r_v$", f"close-up of $r_e$ ({cells} x {cells} cells)")
    for i, (label, res) in enumerate(results.items()):
        r, smooth = parts[label]
        for k, values in enumerate((r, smooth, r)):
            ax = axes[i, k]
            im = plot_density(ax, res.ref_points, res.elements, values, colorbar=False, vmin=-tops[k % 2],
                              vmax=tops[k % 2], cmap="RdBu_r", title=titles[k] if i == 0 else None)
            if k == 2:
                ax.triplot(res.ref_points[:, 0], res.ref_points[:, 1], res.elements, color="0.4", lw=0.3)
                ax.set_xlim(lo[0], lo[0] + 2 * half)
                ax.set_ylim(lo[1], lo[1] + 2 * half)
            if k == 0:
                ax.text(-0.08, 0.5, label, transform=ax.transAxes, rotation=90, va="center", ha="right")
                ax.add_patch(plt.Rectangle(lo, 2 * half, 2 * half, fill=False, lw=0.8, color="k"))
            if i == len(results) - 1 and k < 2:
                colorbar(im, ax=axes[:, k], shrink=0.8, location="bottom")
    return fig
