"""Plotting: one matplotlib style for the 2D figures, PyVista (off screen) for the 3D ones, VTK export."""
from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .result import setup_pyvista, to_pyvista

__all__ = ["STYLE", "style", "repository_root", "figures_dir", "save_figure", "plot_mesh", "plot_density", "plot_mu",
           "plot_map_row", "to_pyvista", "render_volume", "element_rho", "setup_pyvista", "architecture_diagram",
           "population_figure", "volume_rows", "render_lattice", "plot_batch", "plot_loss_terms", "training_curves", "learning_curves", "CAMERA_3D", "LOSS_TERMS", "plot_regions", "cartogram_figure",
           "cartogram_panels", "area_error_histograms", "time_accuracy_figure", "validation_vs_time",
           "table_lines", "plot_slice_outline", "displacement_demand_figure", "vertex_error_panels", "shorten_curve"]

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


def _is_book_root(path: Path) -> bool:
    return (path / "_config.yml").is_file() and (path / "book").is_dir()


def repository_root(start: str | os.PathLike | None = None) -> Path | None:
    """The source checkout that holds the book (the directory with ``_config.yml`` and ``book/``), or ``None``.

    With ``start``, the nearest such directory at or above ``start``.  Without it, the checkout this module was
    imported from (an editable install), else the nearest one at or above the working directory (a regular install
    used inside a checkout, e.g. a notebook opened from ``notebooks/``).  The answer never depends on *which*
    directory of the checkout the caller runs in.
    """
    if start is None:
        here = Path(__file__).resolve().parents[2]
        if _is_book_root(here):
            return here
        start = Path.cwd()
    start = Path(start).resolve()
    return next((p for p in (start, *start.parents) if _is_book_root(p)), None)


def figures_dir() -> Path:
    """Where figures go: ``$RFMAP_FIGURES``, else ``book/figures`` of the checkout found by :func:`repository_root`
    (the place the book build writes to, from the repository root, from ``notebooks/`` or from anywhere else),
    else ``./figures`` outside a checkout."""
    env = os.environ.get("RFMAP_FIGURES")
    if env:
        p = Path(env)
    else:
        root = repository_root()
        p = root / "book" / "figures" if root is not None else Path.cwd() / "figures"
    p.mkdir(parents=True, exist_ok=True)
    return p


def save_figure(fig, label: str) -> Path:
    """Save ``fig`` as ``<figures_dir>/<label>.png`` where ``label`` is the paper's label (``fig:x_y`` → ``fig-x-y``)."""
    name = label.replace(":", "-").replace("_", "-")
    path = figures_dir() / f"{name}.png"
    fig.savefig(path)
    return path


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


def architecture_diagram(model, ax=None):
    """Draw the encoder–decoder structure of a :class:`rfmap.nn.MultiResUNet` from its own modules.

    Walks ``model.lift``, ``model.down``, ``model.up``, ``model.dec`` and ``model.head`` and draws one box per
    stage, labelled with the channel counts read from the stage's convolutions (``in_channels`` /
    ``out_channels``), arrows for pooling and up-sampling, and dashed arrows for the skip connections.  Boxes of
    enhanced double convolutions with spatial attention are marked "+ attn".

    Returns
    -------
    matplotlib Axes
    """
    import matplotlib.pyplot as plt

    from .nn.blocks import SpatialAttention

    levels = len(model.down)
    dx, dy, w, h = 1.45, 1.25, 1.2, 0.72
    if ax is None:
        width = 3.45 + 2 * (levels - 1) * dx + 3.1 + w
        _, ax = plt.subplots(figsize=(0.85 * width, 0.95 * ((levels - 1) * dy + 1.05)))

    def box(x, y, text, color, height=h, width=w):
        ax.add_patch(plt.Rectangle((x - width / 2, y - height / 2), width, height, facecolor=color,
                                   edgecolor="0.25", lw=0.8, zorder=2))
        ax.text(x, y, text, ha="center", va="center", fontsize=7, zorder=3)

    def arrow(p, q, text="", style="-|>", ls="-", color="0.2", offset=(0.0, 0.0), **kw):
        ax.annotate("", xy=q, xytext=p, arrowprops=dict(arrowstyle=style, lw=0.9, ls=ls, color=color,
                                                        shrinkA=0, shrinkB=0), zorder=1)
        if text:
            ax.text((p[0] + q[0]) / 2 + offset[0], (p[1] + q[1]) / 2 + offset[1], text, fontsize=6.5,
                    ha="center", va="center", color=color, **kw)

    def edc_label(block, name):
        conv = block.body[0].loc
        attn = " + attn" if isinstance(block.attn, SpatialAttention) else ""
        return f"{name}\nEDC{attn}\n{conv.in_channels}→{conv.out_channels}"

    lift = model.lift
    scales = ", ".join("1" if s == 1 else f"1/{s}" for s in lift.scales)
    c_in, c_lift = lift.lift[0].in_channels, lift.lift[0].out_channels
    x_in, x_lift, x0 = 0.0, 1.7, 3.45
    box(x_in, 0, f"input [x, p]\n{c_in} channels", "#e8e8e8")
    box(x_lift, 0, f"lift\nscales {scales}\n1×1: {c_in}→{c_lift} each\nmix 1×1: "
                   f"{lift.mix.in_channels}→{lift.mix.out_channels}", "#cfe3f5", height=1.05, width=1.5)
    arrow((x_in + w / 2, 0), (x_lift - 0.75, 0))
    arrow((x_lift + 0.75, 0), (x0 - w / 2, 0))
    enc_pos = []
    for i, block in enumerate(model.down):
        x, y = x0 + i * dx, -i * dy
        enc_pos.append((x, y))
        box(x, y, edc_label(block, "bottleneck" if i == levels - 1 else f"encoder {i}"),
            "#f3d9b1" if i == levels - 1 else "#d8ecd0")
        if i > 0:
            px, py = enc_pos[i - 1]
            arrow((px, py - h / 2), (x - w / 2, y), "avg pool 2×", offset=(-0.62, 0.05))
    prev = enc_pos[-1]
    x_dec = None
    for j, (up, dec) in enumerate(zip(model.up, model.dec)):
        i = levels - 2 - j  # level of this decoder stage
        x_dec, y = x0 + (2 * (levels - 1) - i) * dx, -i * dy
        box(x_dec, y, edc_label(dec, f"decoder {i}"), "#d8ecd0")
        arrow((prev[0] + w / 2, prev[1]), (x_dec, y - h / 2),
              f"up {up.in_channels}→{up.out_channels}\n(ConvT 2×, resize)", offset=(0.72, -0.1))
        ex, ey = enc_pos[i]
        skip_c = model.down[i].body[0].loc.out_channels
        arrow((ex + w / 2, ey), (x_dec - w / 2, y), f"skip, {skip_c} ch", ls="--", color="tab:blue",
              offset=(0.0, 0.12))
        prev = (x_dec, y)
    head = model.head
    x_head = (x_dec if x_dec is not None else x0) + 1.55
    x_out = x_head + 1.55
    box(x_head, 0, f"head\n1×1 conv\n{head.in_channels}→{head.out_channels}", "#cfe3f5")
    box(x_out, 0, f"ψ, {head.out_channels} ch\nu = x + B⊙ψ", "#e8e8e8", width=1.35)
    arrow((prev[0] + w / 2, 0), (x_head - w / 2, 0))
    arrow((x_head + w / 2, 0), (x_out - 0.675, 0))
    ax.set_xlim(x_in - w / 2 - 0.1, x_out + 0.775)
    ax.set_ylim(-(levels - 1) * dy - 0.45, 0.6)
    ax.set_axis_off()
    return ax


def render_volume(result, *, mapped: bool = True, scalars: str | None = "rho", clip: bool = True,
                  window_size=(420, 420), clim=(0.0, 2.5), cmap="viridis", show_edges: bool = False, camera="iso"):
    """Render a 3D result off screen and return the image (H, W, 3).  With ``clip`` an octant is cut away so the
    interior is visible; ``camera`` is a PyVista camera position (``'iso'`` fits the view to the mesh, a fixed
    one such as :data:`CAMERA_3D` makes several renderings comparable)."""
    pv = setup_pyvista()
    grid = to_pyvista(result, mapped=mapped)
    if clip:
        grid = grid.clip_box([0.5, 1.1, -0.1, 0.5, 0.5, 1.1], invert=True, crinkle=True)
    pl = pv.Plotter(off_screen=True, window_size=list(window_size))
    pl.add_mesh(grid, scalars=scalars, clim=clim, cmap=cmap, show_edges=show_edges, show_scalar_bar=False)
    pl.camera_position = camera
    pl.background_color = "white"
    img = pl.screenshot(return_img=True)
    pl.close()
    return img


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


def volume_rows(results: dict, labels, fig_label: str, *, clim=(0.0, 2.5)):
    """The paper's 3D figures: per result (keyed by ``labels``) the original lattice and the mapped one on three
    slices (:func:`render_lattice`) and the mapped volume cut open (:func:`render_volume`), all coloured by
    :math:`\\tilde\\rho` and seen by one camera (:data:`CAMERA_3D`); saved under ``fig_label``; returns the figure."""
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    titles = [r"original lattice, $\tilde\rho$", r"mapped lattice, $\tilde\rho$ on the mapped mesh",
              r"mapped volume, cut open"]
    with style():
        fig, axes = plt.subplots(len(labels), 3, figsize=(10.5, 3.3 * len(labels)), layout="constrained",
                                 squeeze=False)
        for row, key in zip(axes, labels):
            r = results[key]
            imgs = [render_lattice(r, mapped=False, clim=clim), render_lattice(r, mapped=True, clim=clim),
                    render_volume(r, mapped=True, scalars="rho", clim=clim, camera=CAMERA_3D)]
            for ax, img, t in zip(row, imgs, titles):
                ax.imshow(img)
                ax.set_title(f"{key}: {t}")
                ax.axis("off")
        fig.colorbar(ScalarMappable(Normalize(*clim), "viridis"), ax=axes, shrink=0.5, label=r"$\tilde\rho$")
        save_figure(fig, fig_label)
    return fig


#: one camera for every 3D panel (position, focal point, view-up), so that panels can be compared
CAMERA_3D = [(2.55, -1.45, 1.95), (0.5, 0.5, 0.42), (0.0, 0.0, 1.0)]
#: the loss terms of training (keys of :func:`rfmap.tasks.task_loss` and :func:`rfmap.losses.loss_integrands`)
LOSS_TERMS = {"density": r"density mismatch $L(\tilde\rho - 1)$", "mu2": r"Beltrami energy $|\mu|^2$",
              "beltrami": r"$\mu$ mismatch $|\mu(u) - \mu_{in}|^2$", "fold": r"fold penalty relu$(\tau - \det J)$",
              "area": "area constraint"}


def _vertex_rho(result, mapped: bool) -> np.ndarray:
    """:math:`\\tilde\\rho` at the vertices: the mean over the elements around each vertex of the density on the
    mapped mesh (``mapped``) or of the normalised input density (the original mesh)."""
    el = np.asarray(result.elements)
    if mapped:
        rho_e = result.rho()
    else:
        f = np.asarray(result.field, dtype=np.float64).reshape(-1)[el].mean(1)
        rho_e = f / f.mean()
    n_pts = len(result.ref_points)
    total = np.bincount(el.ravel(), weights=np.repeat(rho_e, el.shape[1]), minlength=n_pts)
    return total / np.maximum(np.bincount(el.ravel(), minlength=n_pts), 1)


def render_lattice(result, *, mapped: bool = True, slices=(0.2, 0.5, 0.8), lines: int = 13, clim=(0.0, 2.5),
                   cmap="viridis", window_size=(420, 420), camera=CAMERA_3D, line_width: float = 2.0):
    """Render the grid lines of a 3D grid result on a few horizontal slices (:math:`x_3` = ``slices`` in the
    reference cube) off screen, coloured by :math:`\\tilde\\rho` at the vertices, inside the outline of the unit
    cube; returns the image (H, W, 3).  The original lattice (``mapped=False``) is drawn flat; the mapped one shows
    where the map moves each slice."""
    pv = setup_pyvista()
    n = round(len(result.ref_points) ** (1 / 3))
    if n**3 != len(result.ref_points):
        raise ValueError("render_lattice needs a result on an N x N x N grid")
    pts = np.asarray(result.mapped_points if mapped else result.ref_points, dtype=np.float64).reshape(n, n, n, 3)
    rho = _vertex_rho(result, mapped).reshape(n, n, n)
    idx = sorted({int(round(s * (n - 1))) for s in slices})
    keep = sorted({int(round(t)) for t in np.linspace(0, n - 1, min(lines, n))})
    polys, scal = [], []
    for k in idx:
        layer, layer_rho = pts[:, :, k], rho[:, :, k]
        for i in keep:
            polys += [layer[i, :], layer[:, i]]
            scal += [layer_rho[i, :], layer_rho[:, i]]
    points = np.concatenate(polys)
    offsets = np.cumsum([0] + [len(p) for p in polys])
    cells = np.concatenate([np.r_[len(p), np.arange(o, o + len(p))] for p, o in zip(polys, offsets)])
    mesh = pv.PolyData(points, lines=cells)
    mesh.point_data["rho"] = np.concatenate(scal)
    pl = pv.Plotter(off_screen=True, window_size=list(window_size))
    pl.add_mesh(pv.Box(bounds=(0, 1, 0, 1, 0, 1)).outline(), color="gray", line_width=1)
    pl.add_mesh(mesh, scalars="rho", clim=clim, cmap=cmap, line_width=line_width, show_scalar_bar=False)
    pl.camera_position = camera
    pl.background_color = "white"
    img = pl.screenshot(return_img=True)
    pl.close()
    return img


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
    (:func:`rfmap.train.train`); returns the axes."""
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


def plot_regions(ax, geoms, values=None, *, title: str | None = None, cmap="viridis", vmin=None, vmax=None,
                 edgecolor="white", lw=0.4, colorbar: bool = False, label: str | None = None):
    """Draw shapely Polygons / MultiPolygons (holes included), filled by ``values`` (one per geometry) or grey."""
    import matplotlib.pyplot as plt
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path as MplPath

    patches = []
    for g in geoms:
        parts = getattr(g, "geoms", [g])
        verts, codes = [], []
        for poly in parts:
            for ring in (poly.exterior, *poly.interiors):
                xy = np.asarray(ring.coords)
                verts.append(xy)
                codes += [MplPath.MOVETO] + [MplPath.LINETO] * (len(xy) - 2) + [MplPath.CLOSEPOLY]
        patches.append(PathPatch(MplPath(np.concatenate(verts), codes)))
    coll = PatchCollection(patches, cmap=cmap, edgecolor=edgecolor, linewidth=lw)
    if values is not None:
        coll.set_array(np.asarray(values, dtype=float))
        coll.set_clim(vmin, vmax)
    else:
        coll.set_facecolor("0.7")
    ax.add_collection(coll)
    ax.autoscale_view()
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title)
    if colorbar and values is not None:
        plt.colorbar(coll, ax=ax, fraction=0.046, pad=0.03, label=label)
    return coll


def cartogram_figure(carto, *, title: str = "", label: str | None = None, path=None):
    """A cartogram (:class:`rfmap.cartogram.Cartogram`) beside its input map, both in the input's coordinates, every
    region in the colour of its input density (value per unit area over the mean), so that each can be followed from
    one map to the other.  Saved under the figure ``label`` (:func:`save_figure`) and/or to ``path``; returns the
    figure."""
    import matplotlib.pyplot as plt

    before, after = carto.input_geometries(), carto.output_geometries()
    density = carto.values / np.array([g.area for g in carto.regions])
    density /= carto.values.sum() / sum(g.area for g in carto.regions)
    m = carto.metrics()
    with style():
        fig, axes = plt.subplots(1, 2, figsize=(11, 5))
        vmax = float(density.max())
        plot_regions(axes[0], before, density, title=f"{title} input".strip(), vmin=0.0, vmax=vmax)
        plot_regions(axes[1], after, density, vmin=0.0, vmax=vmax, colorbar=True, label="input density / mean",
                     title=f"{title} cartogram ({carto.method}, N = {carto.n}): area error mean {m.mean_error:.3f}, "
                           f"max {m.max_error:.3f}".strip())
        b = np.array([g.bounds for g in (*before, *after)])
        lo, hi = b[:, :2].min(0), b[:, 2:].max(0)
        pad = 0.02 * (hi - lo)
        for ax in axes:  # one extent and the planar frame's aspect, so that sizes and shapes compare
            ax.set(xlim=(lo[0] - pad[0], hi[0] + pad[0]), ylim=(lo[1] - pad[1], hi[1] + pad[1]))
            ax.set_aspect(1.0 / carto.frame.cos_lat)
            ax.axis("off")
        fig.tight_layout()
        if label:
            save_figure(fig, label)
        if path:
            fig.savefig(path)
    return fig


def cartogram_panels(cartos: dict, keys, *, label: str | None = None, cols: int = 4):
    """Cartograms side by side, one panel per key of ``cartos`` (``{key: Cartogram}``, keys as in
    :func:`rfmap.cartogram.compare_cartograms`), regions coloured by their input density over the mean, with the
    input map first; saved under ``label``; returns the figure."""
    import matplotlib.pyplot as plt

    keys = list(keys)
    first = cartos[keys[0]]
    rows = -(-(len(keys) + 1) // cols)
    with style():
        fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.6 * rows), squeeze=False)
        panels = [(first.input_geometries(), first, "input map")]
        panels += [(cartos[k].output_geometries(), cartos[k], " / ".join(map(str, k))) for k in keys]
        for ax, (geoms, c, title) in zip(axes.flat, panels):
            area = np.array([g.area for g in c.regions])
            density = c.values / area / (c.values.sum() / area.sum())
            plot_regions(ax, geoms, density, title=title, vmin=0.0, vmax=float(np.quantile(density, 0.98)), lw=0.2)
            ax.set_aspect(1.0 / first.frame.cos_lat)
            ax.axis("off")
        for ax in axes.flat[len(panels):]:
            ax.axis("off")
        fig.tight_layout()
        if label:
            save_figure(fig, label)
    return fig


def area_error_histograms(cartos: dict, labels, values, *, label: str | None = None, bins: int = 30):
    """Histograms of the relative area errors :math:`|A_i/T_i - 1|` (log scale), one panel per value and one colour
    per method label; ``cartos`` as returned by :func:`rfmap.cartogram.compare_cartograms`; saved under ``label``;
    returns the figure."""
    import matplotlib.pyplot as plt

    values, labels = list(values), list(labels)
    errs = {k: np.maximum(c.area_errors, 1e-6) for k, c in cartos.items()}
    edges = np.logspace(-6, np.log10(max(e.max() for e in errs.values())) + 0.05, bins + 1)
    with style():
        fig, axes = plt.subplots(1, len(values), figsize=(3.6 * len(values), 3.0), squeeze=False, sharey=True)
        for ax, v in zip(axes.flat, values):
            for lab in labels:
                ax.hist(errs[v, lab], bins=edges, histtype="step", lw=1.4, label=lab)
            ax.axvline(0.01, color="0.5", ls=":", lw=0.8)
            ax.set(xscale="log", xlabel=r"$|A_i/T_i - 1|$", title=v)
        axes.flat[0].set_ylabel("regions")
        axes.flat[0].legend(loc="upper left", fontsize=7)
        fig.tight_layout()
        if label:
            save_figure(fig, label)
    return fig


def time_accuracy_figure(rows: list[dict], *, title: str | None = None):
    """Std(rho~_map) against wall time, one panel per (dimension, N, boundary), one marker per field and method
    (rows of :func:`rfmap.paper.benchmarks.time_to_accuracy`); log-log axes."""
    import matplotlib.pyplot as plt

    cases = sorted({(r["dim"], r["n"], r["boundary"]) for r in rows})
    methods = list(dict.fromkeys(r["method"] for r in rows))
    markers = dict(zip(methods, "osD^v*"))
    fig, axes = plt.subplots(1, len(cases), figsize=(4.2 * len(cases), 3.8), squeeze=False)
    for ax, case in zip(axes[0], cases):
        for k, method in enumerate(methods):
            rs = [r for r in rows if (r["dim"], r["n"], r["boundary"]) == case and r["method"] == method]
            if rs:
                ax.loglog([r["time"] for r in rs], [r["std_rho_map"] for r in rs], markers[method], color=f"C{k}",
                          label=method, alpha=0.8, mfc="none")
        ax.set_title(f"{case[0]}D, N = {case[1]}, {case[2]}")
        ax.set_xlabel("wall time (s)")
    axes[0, 0].set_ylabel(r"Std($\tilde\rho_{map}$)")
    axes[0, -1].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def displacement_demand_figure(records: list[dict], *, title: str | None = None):
    """Left: the network map's largest displacement (reach) against the classical map's (demand), one marker per
    field, with the line reach = demand; right: the fraction of the non-uniformity each map leaves,
    Std(rho~_map) / Std(rho~_orig), against the demand.  The band marks the demand of 90 % of the training draws
    (records of :func:`rfmap.paper.generalization.displacement_demand`)."""
    import matplotlib.pyplot as plt

    groups = list(dict.fromkeys(r["group"] for r in records))
    fig, (a, b) = plt.subplots(1, 2, figsize=(10.5, 4.2))
    train = [r["demand"] for r in records if r["group"] == "training"]
    if train:
        p90 = float(np.quantile(train, 0.9))
        for ax in (a, b):
            ax.axvspan(0, p90, color="0.9", zorder=0, label="90 % of training draws")
    for k, g in enumerate(groups):
        rs = [r for r in records if r["group"] == g]
        d = [r["demand"] for r in rs]
        kw = dict(color=f"C{k}", alpha=0.35 if g == "training" else 0.9, ms=4 if g == "training" else 7)
        a.plot(d, [r["reach"] for r in rs], "o", label=g, **kw)
        b.plot(d, [r["left_net"] for r in rs], "o", label=f"{g}: ours", **kw)
        if g != "training":
            b.plot(d, [r["left_classical"] for r in rs], "x", color=f"C{k}", ms=6)
    top = max(max(r["demand"] for r in records), max(r["reach"] for r in records)) * 1.05
    a.plot([0, top], [0, top], "k--", lw=1, label="reach = demand")
    a.set_xlim(0, top)
    a.set_ylim(0, top)
    a.set_xlabel("demand: classical map's largest displacement")
    a.set_ylabel("reach: network map's largest displacement")
    a.legend(fontsize=8)
    b.set_xlim(0, top)
    b.set_yscale("log")
    b.set_xlabel("demand: classical map's largest displacement")
    b.set_ylabel(r"Std($\tilde\rho_{map}$) / Std($\tilde\rho_{orig}$)  (o: ours, x: classical)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
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


def table_lines(table, column: str = "std_rho_map", ax=None, *, logx: bool = True):
    """One line per ``method`` of an :class:`rfmap.paper.tables.Table` whose cases are numbers (e.g. grid sides):
    ``column`` against the case; returns the axes."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(5.2, 3.4), layout="constrained")
    methods = list(dict.fromkeys(m for _, m, _ in table.rows))
    for k, method in enumerate(methods):
        pts = sorted((float(c), v[column]) for c, m, v in table.rows if m == method and v.get(column) is not None)
        if pts:
            ls = "--" if "native" in method else "-"
            ax.plot(*zip(*pts), ls, marker="o", ms=3, lw=1.2, color=f"C{k // 2 if len(methods) > 2 else k}",
                    label=method)
    if logx:
        ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set(xlabel="N", ylabel=column)
    ax.legend(fontsize=8)
    return ax


def shorten_curve(report: dict, ax=None, *, title: str | None = None):
    r"""Std(rho~) of the shortened maps :math:`u_s = x + s\,(u - x)` against the scale ``s``, from the report of
    :func:`rfmap.repair.shorten_map` (``info["shorten"]`` of ``Surrogate.map``): the evaluated scales (folded ones
    marked at the top), the identity's level and the chosen scale; returns the axes."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(5.2, 3.4), layout="constrained")
    s, j = np.array(report["curve"], dtype=float).T
    ok = np.isfinite(j)
    ax.plot(s[ok], j[ok], "o-", ms=3, lw=1.2, color="C0", label=r"fold-free $u_s$")
    if (~ok).any():
        top = float(j[ok].max()) if ok.any() else 1.0
        ax.plot(s[~ok], np.full((~ok).sum(), top), "x", color="C3", label=r"folded $u_s$")
    ax.axhline(report["std_identity"], color="0.4", ls=":", lw=1, label="identity (no map)")
    ax.axvline(report["scale"], color="C2", ls="--", lw=1, label=f"chosen s = {report['scale']:.3g}")
    ax.set(xlabel="scale s of the displacement", ylabel=r"Std($\tilde\rho_{map}$)", title=title)
    ax.legend(fontsize=8)
    return ax
