"""Plotting: one matplotlib style for the 2D figures, PyVista (off screen) for the 3D ones, VTK export."""
from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

import numpy as np

__all__ = ["STYLE", "style", "figures_dir", "save_figure", "plot_mesh", "plot_density", "plot_mu", "plot_map_row",
           "to_pyvista", "render_volume", "element_rho", "setup_pyvista"]

STYLE = {
    "figure.dpi": 110,
    "savefig.dpi": 140,
    "savefig.bbox": "tight",
    "font.size": 9,
    "axes.titlesize": 9,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "image.cmap": "viridis",
}


@contextmanager
def style():
    """Context manager applying the book's matplotlib style."""
    import matplotlib.pyplot as plt

    with plt.rc_context(STYLE):
        yield


def figures_dir() -> Path:
    """Where figures go: ``$RFMAP_FIGURES``, else ``book/figures`` of the source checkout, else ``./figures``."""
    env = os.environ.get("RFMAP_FIGURES")
    if env:
        p = Path(env)
    else:
        root = Path(__file__).resolve().parents[2]
        p = root / "book" / "figures" if (root / "_config.yml").exists() else Path.cwd() / "figures"
    p.mkdir(parents=True, exist_ok=True)
    return p


def save_figure(fig, label: str) -> Path:
    """Save ``fig`` as ``<figures_dir>/<label>.png`` where ``label`` is the paper's label (``fig:x_y`` → ``fig-x-y``)."""
    name = label.replace(":", "-").replace("_", "-")
    path = figures_dir() / f"{name}.png"
    fig.savefig(path)
    return path


def element_rho(result) -> np.ndarray:
    """Per-element density :math:`\\tilde\\rho` on the mapped mesh (population / mapped measure, mean 1)."""
    from .geometry import signed_measures
    from .metrics import element_population
    import torch

    ref = torch.as_tensor(result.ref_points, dtype=torch.float64)
    mapped = torch.as_tensor(result.mapped_points, dtype=torch.float64)
    el = torch.as_tensor(result.elements)
    pop = element_population(ref, el, result.field.reshape(-1))
    rho = pop / signed_measures(mapped, el)
    return (rho / rho.mean()).numpy()


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
    import torch

    from .geometry import beltrami_coefficient

    mu = beltrami_coefficient(torch.as_tensor(result.ref_points), torch.as_tensor(result.mapped_points),
                              torch.as_tensor(result.elements)).abs().numpy()
    return plot_density(ax, result.mapped_points, result.elements, mu, title=title, vmin=0, vmax=vmax,
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


def setup_pyvista():
    """Configure PyVista for off-screen rendering (EGL) and static images in notebooks; returns the module."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    pv.OFF_SCREEN = True
    try:
        pv.set_jupyter_backend("static")
    except Exception:  # noqa: BLE001 - outside Jupyter
        pass
    return pv


def to_pyvista(result, *, mapped: bool = True):
    """A ``pyvista.UnstructuredGrid`` of the (mapped) mesh with point data ``displacement`` and ``density`` and
    cell data ``rho`` (density on the mapped mesh)."""
    pv = setup_pyvista()
    import vtk  # noqa: F401

    pts = np.asarray(result.mapped_points if mapped else result.ref_points, dtype=np.float64)
    el = np.asarray(result.elements)
    d = pts.shape[1]
    if d == 2:
        pts = np.column_stack([pts, np.zeros(len(pts))])
        celltype = pv.CellType.TRIANGLE
    else:
        celltype = pv.CellType.TETRA
    cells = np.column_stack([np.full(len(el), el.shape[1]), el]).ravel()
    grid = pv.UnstructuredGrid(cells, np.full(len(el), celltype, dtype=np.uint8), pts)
    disp = result.mapped_points - result.ref_points
    grid.point_data["displacement"] = np.column_stack([disp, np.zeros(len(disp))]) if d == 2 else disp
    if result.kind == "density":
        grid.point_data["density"] = result.field.reshape(-1)
        grid.cell_data["rho"] = element_rho(result) if mapped else result.field.reshape(-1)[el].mean(1) / \
            result.field.reshape(-1)[el].mean(1).mean()
    return grid


def render_volume(result, *, mapped: bool = True, scalars: str | None = "rho", clip: bool = True,
                  window_size=(420, 420), clim=(0.0, 2.5), cmap="viridis", show_edges: bool = False):
    """Render a 3D result off screen and return the image (H, W, 3).  With ``clip`` an octant is cut away so the
    interior is visible."""
    pv = setup_pyvista()
    grid = to_pyvista(result, mapped=mapped)
    if clip:
        grid = grid.clip_box([0.5, 1.1, -0.1, 0.5, 0.5, 1.1], invert=True, crinkle=True)
    pl = pv.Plotter(off_screen=True, window_size=list(window_size))
    pl.add_mesh(grid, scalars=scalars, clim=clim, cmap=cmap, show_edges=show_edges, show_scalar_bar=False)
    pl.camera_position = "iso"
    pl.background_color = "white"
    img = pl.screenshot(return_img=True)
    pl.close()
    return img
