"""2D maps on their meshes: grid lines, element and vertex values, and the paper's population and reconstruction
panels."""
from __future__ import annotations

import numpy as np

from .figures import save_figure, style

__all__ = ["element_rho", "plot_mesh", "plot_slice_outline", "plot_density", "plot_mu", "plot_map_row",
           "plot_beltrami_row", "vertex_error_panels", "population_figure"]


def element_rho(result) -> np.ndarray:
    """Per-element density :math:`\\tilde\\rho` on the mapped mesh (population / mapped measure, mean 1); the
    same as :meth:`rfmap.result.MapResult.rho`."""
    return result.rho()


def _grid_lines(ax, pts, n, step, **kw):
    P = pts.reshape(n, n, 2)
    idx = list(range(0, n, step))
    if idx[-1] != n - 1:
        idx.append(n - 1)
    for i in idx:
        ax.plot(P[i, :, 0], P[i, :, 1], **kw)
        ax.plot(P[:, i, 0], P[:, i, 1], **kw)


def plot_mesh(ax, points, elements=None, *, n: int | None = None, max_lines: int = 40, title: str | None = None,
              color="0.2", lw=0.5):
    """Draw a (mapped) 2D grid mesh: grid lines when ``n`` is given (at most ``max_lines`` per direction), else
    the triangle edges."""
    points = np.asarray(points)
    if n is not None and n * n == points.shape[0]:
        _grid_lines(ax, points, n, max(1, (n - 1) // max_lines), color=color, lw=lw)
    else:
        ax.triplot(points[:, 0], points[:, 1], elements, color=color, lw=lw * 0.6)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title)


def plot_slice_outline(ax, points, n: int, k: int | None = None, *, title: str | None = None, max_lines: int = 20,
                       color="0.2", lw=0.5):
    """Draw the image of the slice ``z = k / (N - 1)`` of a map of the 3D ``N``-grid, projected on the xy-plane:
    its grid lines (at most ``max_lines`` per direction) and, thicker, its outline.  ``k`` defaults to the middle.

    ``points``: mapped vertices (N^3, 3) in the grid's order (:func:`rfmap.mesh.grid_points`).
    """
    P = np.asarray(points).reshape(n, n, n, 3)[:, :, (n - 1) // 2 if k is None else int(k), :2]
    _grid_lines(ax, P.reshape(-1, 2), n, max(1, (n - 1) // max_lines), color=color, lw=lw)
    loop = np.concatenate([P[:, 0], P[-1, 1:], P[-2::-1, -1], P[0, -2::-1]])
    ax.plot(loop[:, 0], loop[:, 1], color="C3", lw=2 * lw + 0.5)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title)


def plot_density(ax, points, elements, values, *, title=None, vmin=None, vmax=None, cmap="viridis", colorbar=True):
    """Per-element (length m) or per-vertex (length n) values on a 2D mesh."""
    import matplotlib.pyplot as plt

    values = np.asarray(values)
    if values.shape[0] == len(elements):
        im = ax.tripcolor(points[:, 0], points[:, 1], elements, facecolors=values, vmin=vmin, vmax=vmax, cmap=cmap)
    else:
        im = ax.tripcolor(points[:, 0], points[:, 1], elements, values, shading="gouraud", vmin=vmin, vmax=vmax,
                          cmap=cmap)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title)
    if colorbar:
        plt.colorbar(im, ax=ax, fraction=0.046, pad=0.03)
    return im


def plot_mu(ax, result, *, title=r"$|\mu|$ on the mapped mesh", vmax=None):
    """:math:`|\\mu|` per triangle of a 2D map, drawn on the mapped mesh."""
    return plot_density(ax, result.mapped_points, result.elements, np.abs(result.mu()), title=title, vmin=0, vmax=vmax,
                        cmap="magma")


def plot_map_row(axes, result, *, n: int | None = None, rho_range=(0.0, 2.5), label: str = ""):
    """The five panels of the paper's 2D population figures: original mesh, mapped mesh, density on the original
    and on the mapped mesh, and :math:`|\\mu|` on the mapped mesh."""
    pop_orig = result.field.reshape(-1)
    el = result.elements
    plot_mesh(axes[0], result.ref_points, el, n=n, title=f"{label} original" if label else "original")
    plot_mesh(axes[1], result.mapped_points, el, n=n, title="mapped")
    rho0 = pop_orig[el].mean(1)
    plot_density(axes[2], result.ref_points, el, rho0 / rho0.mean(), title=r"$\tilde\rho$ original",
                 vmin=rho_range[0], vmax=rho_range[1])
    plot_density(axes[3], result.mapped_points, el, element_rho(result), title=r"$\tilde\rho$ mapped",
                 vmin=rho_range[0], vmax=rho_range[1])
    if result.dim == 2:
        plot_mu(axes[4], result)


def plot_beltrami_row(axes, exact, lbs, ours, *, n: int, label: str = "", bins: int = 40):
    """The six panels of the paper's reconstruction figures: the domain coloured by :math:`|\\mu|`, the exact
    map, the Linear Beltrami Solver's map, the surrogate's map, and histograms of
    :math:`|\\mu_{\\text{truth}} - \\mu_{\\text{pred}}|` for LBS and for the surrogate (``mu_truth`` is the exact
    coefficient at the triangle centroids, stored in ``exact.field``)."""
    mu_t = exact.field
    plot_density(axes[0], exact.ref_points, exact.elements, np.abs(mu_t), title=f"{label} $|\\mu|$", cmap="magma",
                 vmin=0)
    plot_mesh(axes[1], exact.mapped_points, n=n, title="exact map")
    plot_mesh(axes[2], lbs.mapped_points, n=n, title="LBS")
    plot_mesh(axes[3], ours.mapped_points, n=n, title="surrogate")
    errs = [np.abs(mu_t - lbs.mu()), np.abs(mu_t - ours.mu())]
    hi = max(float(e.max()) for e in errs) or 1.0
    for ax, e, name in zip(axes[4:6], errs, ["LBS", "surrogate"]):
        ax.hist(e, bins=bins, range=(0, hi), color="tab:blue" if name == "LBS" else "tab:orange")
        ax.set_title(f"$|\\mu_{{truth}}-\\mu_{{pred}}|$ {name}")
        ax.set_yscale("log")


def vertex_error_panels(results: dict, exact, *, n: int, title: str = ""):
    r"""One panel per 2D map of ``results`` (``{name: MapResult}`` on the ``n``-grid): the vertex error
    :math:`|u(x) - u_{\text{exact}}(x)|` as an image over the unit square, on a shared colour scale, with its mean
    in the panel title.

    Parameters
    ----------
    results : dict of str to MapResult
        Maps of the same ``n``-grid (``ref_points`` of shape (n^2, 2)).
    exact : MapResult
        The exact map on the same grid.

    Returns
    -------
    matplotlib Figure
    """
    import matplotlib.pyplot as plt

    errs = {}
    for name, r in results.items():
        if r.ref_points.shape != (n * n, 2) or exact.mapped_points.shape != (n * n, 2):
            raise ValueError(f"vertex_error_panels needs 2D maps of the {n}-grid, got {r.ref_points.shape}")
        errs[name] = np.linalg.norm(r.mapped_points - exact.mapped_points, axis=1).reshape(n, n)
    hi = max(float(e.max()) for e in errs.values()) or 1.0
    fig, axes = plt.subplots(1, len(errs), figsize=(3.3 * len(errs), 3.0), squeeze=False)
    for ax, (name, e) in zip(axes[0], errs.items()):
        im = ax.imshow(e.T, origin="lower", extent=(0, 1, 0, 1), vmin=0, vmax=hi, cmap="magma")
        ax.set_title(f"{title} {name}: mean {e.mean():.2e}".strip())
        ax.set_aspect("equal")
    fig.colorbar(im, ax=axes[0].tolist(), shrink=0.85, label="vertex error")
    return fig


def population_figure(maps: dict, fields, label: str, *, n: int, method: str = "ours+refine"):
    """The paper's 2D population figure: one :func:`plot_map_row` per field of the maps of
    :func:`rfmap.paper.reproduce.population_table`, saved under the paper's ``label``; returns the figure."""
    import matplotlib.pyplot as plt

    with style():
        fig, axes = plt.subplots(len(fields), 5, figsize=(14, 2.8 * len(fields)))
        for row, f in zip(axes, fields):
            plot_map_row(row, maps[f][method], n=n, label=f)
        fig.tight_layout()
        save_figure(fig, label)
    return fig
