"""3D maps rendered off screen with PyVista: the volume cut open along a plane, lattice slices, and the paper's 3D
figures."""
from __future__ import annotations

import warnings

import numpy as np

from ..core.result import setup_pyvista, to_pyvista
from .figures import ColorScale, color_scale, save_figure, style
from .figures import colorbar as add_colorbar

__all__ = ["CAMERA_3D", "CUT_PLANE", "render_volume", "render_lattice", "render_slices", "volume_rows"]


#: one camera for every 3D panel (position, focal point, view-up), so that panels can be compared
CAMERA_3D = [(2.55, -1.45, 1.95), (0.5, 0.5, 0.42), (0.0, 0.0, 1.0)]


#: the cutting plane of :func:`render_volume` (``clip="plane"``): through the cube's centre, its normal towards
#: :data:`CAMERA_3D`, so that the half facing the camera is cut away and the cut face is seen head on
CUT_PLANE = ((0.5, 0.5, 0.5), (1.0, -0.6, 0.75))


def _pyvista():
    """:func:`rfmap.core.result.setup_pyvista` without the notice that importing PyVista prints in a Jupyter kernel
    without ipywidgets: PyVista imports pooch, which imports ``tqdm.auto``, which warns that it cannot draw a
    notebook progress bar.  No rendering here shows one."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="IProgress not found")
        return setup_pyvista()


def _cut(grid, clip):
    """``grid`` cut by a smooth plane (``"plane"``: :data:`CUT_PLANE`) or with the octant nearest the camera cut
    away (``True`` or ``"octant"``); tetrahedra are split along the cut, so the cut faces are flat."""
    if clip == "plane":
        origin, normal = CUT_PLANE
        return grid.clip(normal=normal, origin=origin, invert=True)
    if clip:
        return grid.clip_box([0.5, 1.1, -0.1, 0.5, 0.5, 1.1], invert=True, crinkle=False)
    return grid


#: where :func:`render_lattice` and :func:`render_slices` name the axes when seen from :data:`CAMERA_3D`: beside the
#: edges of the unit cube along x1 and x2 from the corner (1, 0, 0) nearest the camera, and x3 beside the vertical
#: edge through the origin
AXIS_LABELS = {"x1": (0.5, -0.1, 0.0), "x2": (1.1, 0.5, 0.0), "x3": (-0.04, -0.04, 0.5)}

#: the size of the axis names in the rendered image (pixels of a 420-pixel window)
AXIS_LABEL_SIZE = 24


def _label_axes(pl) -> None:
    """Write ``x1``, ``x2``, ``x3`` beside edges of the unit cube along the three axes (``AXIS_LABELS``; their
    places suit :data:`CAMERA_3D`)."""
    pl.add_point_labels(np.array(list(AXIS_LABELS.values())), list(AXIS_LABELS), font_size=AXIS_LABEL_SIZE,
                        shape=None, show_points=False, always_visible=True, text_color="black",
                        justification_horizontal="center", justification_vertical="center")


#: the width of the grid lines drawn by :func:`render_lattice` (pixels)
LATTICE_LINE_WIDTH = 2.0

#: the colour scale of :func:`render_volume` and :func:`render_lattice` (:math:`\tilde\rho` from 0 to 2.5)
RHO_SCALE = ColorScale(0.0, 2.5)


def render_volume(result, *, mapped: bool = True, scalars: str | None = "rho", clip: bool | str = True,
                  window_size=(420, 420), show_edges: bool = False, camera="iso", scale: ColorScale = RHO_SCALE, **kw):
    r"""Render a 3D result off screen and return the image (H, W, 3).

    ``scalars`` names an array of :func:`rfmap.core.result.to_pyvista` (``"rho"`` per element, ``"density"`` at the
    vertices) or ``"|u - x|"``, the length of the displacement :math:`|u(x) - x|` at the vertices.  ``clip`` cuts
    the volume open along flat faces: ``True`` (or ``"octant"``) removes the octant nearest the camera, ``"plane"``
    the half in front of :data:`CUT_PLANE`.  ``camera`` is a PyVista camera position (``'iso'`` fits the view to the
    mesh, a fixed one such as :data:`CAMERA_3D` makes several renderings comparable).  ``scale``
    (:class:`rfmap.viz.figures.ColorScale`, default ``RHO_SCALE``) colours the scalars; its fields may be given as
    keywords (``clim=(lo, hi)``, ``cmap=...``).
    """
    sc = color_scale(scale, **kw)
    clim, cmap = sc.clim, sc.cmap
    pv = _pyvista()
    grid = to_pyvista(result, mapped=mapped)
    if scalars == "|u - x|":
        grid.point_data[scalars] = np.linalg.norm(np.asarray(grid.point_data["displacement"]), axis=1)
    grid = _cut(grid, clip)
    pl = pv.Plotter(off_screen=True, window_size=list(window_size))
    pl.add_mesh(pv.Box(bounds=(0, 1, 0, 1, 0, 1)).outline(), color="gray", line_width=1)
    pl.add_mesh(grid, scalars=scalars, clim=clim, cmap=cmap, show_edges=show_edges, show_scalar_bar=False)
    pl.camera_position = camera
    pl.background_color = "white"
    img = pl.screenshot(return_img=True)
    pl.close()
    return img


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


def render_lattice(result, *, mapped: bool = True, slices=(0.2, 0.5, 0.8), lines: int = 13, window_size=(420, 420),
                   camera=CAMERA_3D, scale: ColorScale = RHO_SCALE, carried: bool = False, **kw):
    """Render the grid lines of a 3D grid result on a few horizontal slices (:math:`x_3` = ``slices`` in the
    reference cube) off screen, coloured by :math:`\\tilde\\rho` at the vertices, inside the outline of the unit
    cube; returns the image (H, W, 3).  The original lattice (``mapped=False``) is drawn flat; the mapped one shows
    where the map moves each slice, coloured by the density left on the mapped mesh, or with ``carried`` by the
    input's normalised density carried along with the vertices.  ``scale`` as in :func:`render_volume`.  Seen
    from :data:`CAMERA_3D`, the axes are named beside the cube's edges (``AXIS_LABELS``)."""
    sc = color_scale(scale, **kw)
    clim, cmap = sc.clim, sc.cmap
    pv = _pyvista()
    n = round(len(result.ref_points) ** (1 / 3))
    if n**3 != len(result.ref_points):
        raise ValueError("render_lattice needs a result on an N x N x N grid")
    pts = np.asarray(result.mapped_points if mapped else result.ref_points, dtype=np.float64).reshape(n, n, n, 3)
    rho = _vertex_rho(result, mapped and not carried).reshape(n, n, n)
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
    pl.add_mesh(mesh, scalars="rho", clim=clim, cmap=cmap, line_width=LATTICE_LINE_WIDTH,
                show_scalar_bar=False)
    if camera == CAMERA_3D:  # the labels' places suit this camera only
        _label_axes(pl)
    pl.camera_position = camera
    pl.background_color = "white"
    img = pl.screenshot(return_img=True)
    pl.close()
    return img


def render_slices(result, *, mapped: bool = True, slices=(0.2, 0.5, 0.8), window_size=(420, 420),
                  camera=CAMERA_3D, scale: ColorScale = RHO_SCALE, **kw):
    r"""Filled horizontal slices (:math:`x_3` = ``slices``) through a 3D result's mesh, every piece coloured by the
    :math:`\tilde\rho` of the tetrahedron it cuts: on the original mesh (``mapped=False``) the input's normalised
    density, on the mapped mesh the density the map leaves there, one colour where the map equalizes; inside the
    outline of the unit cube, off screen; returns the image (H, W, 3).  ``scale`` as in :func:`render_volume`;
    the axes named as in :func:`render_lattice`."""
    sc = color_scale(scale, **kw)
    pv = _pyvista()
    grid = to_pyvista(result, mapped=mapped)
    pl = pv.Plotter(off_screen=True, window_size=list(window_size))
    pl.add_mesh(pv.Box(bounds=(0, 1, 0, 1, 0, 1)).outline(), color="gray", line_width=1)
    for z in slices:
        cut = grid.slice(normal="z", origin=(0.5, 0.5, float(z)))
        if cut.n_cells:
            pl.add_mesh(cut, scalars="rho", preference="cell", clim=sc.clim, cmap=sc.cmap, show_scalar_bar=False)
    if camera == CAMERA_3D:  # the labels' places suit this camera only
        _label_axes(pl)
    pl.camera_position = camera
    pl.background_color = "white"
    img = pl.screenshot(return_img=True)
    pl.close()
    return img


def volume_rows(results: dict, labels, fig_label: str | None = None, *, clim=(0.0, 2.5), mapped_clim=(0.5, 1.5)):
    r"""The paper's 3D figures, one row per result (keyed by ``labels``): filled slices through the original mesh
    coloured by the input's :math:`\tilde\rho` and through the mapped mesh coloured by the :math:`\tilde\rho` the
    map leaves (:func:`render_slices`: one colour where the map equalizes), and the grid itself on the same three
    slices as the map moves it, coloured by the input's density carried along (:func:`render_lattice`,
    ``carried=True``); one camera (:data:`CAMERA_3D`).  The input and the moved grid share the scale ``clim``; the
    density the map leaves has a narrow scale of its own, ``mapped_clim`` (``None``: ``clim``), on which what is
    left unequalized shows; each scale has its colour bar under its columns, with arrows where values beyond it
    saturate.  Saved under
    ``fig_label`` (7.2 inches wide, readable in the book's text column; not saved when it is ``None``, the
    default); returns the figure."""
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    labels = list(labels)
    mapped_clim = clim if mapped_clim is None else mapped_clim
    titles = [r"input: $\tilde\rho$ on three slices", r"mapped: $\tilde\rho$ remaining", "the map: the grid moved"]
    with style():
        fig, axes = plt.subplots(len(labels), 3, figsize=(7.2, 2.25 * len(labels) + 0.9), layout="constrained",
                                 squeeze=False)
        for row, key in zip(axes, labels):
            r = results[key]
            imgs = [render_slices(r, mapped=False, clim=clim), render_slices(r, mapped=True, clim=mapped_clim),
                    render_lattice(r, mapped=True, carried=True, clim=clim)]
            for ax, img in zip(row, imgs):
                ax.imshow(img)
                ax.set_xticks([])
                ax.set_yticks([])
                for side in ax.spines.values():
                    side.set_visible(False)
            row[0].set_ylabel(str(key))
        for ax, t in zip(axes[0], titles):
            ax.set_title(t)
        add_colorbar(ScalarMappable(Normalize(*clim), "viridis"), fig=fig, ax=axes[:, 0].tolist(), location="bottom",
                     shrink=0.9, aspect=12, extend="max", label=r"input $\tilde\rho$ (left and right)")
        add_colorbar(ScalarMappable(Normalize(*mapped_clim), "viridis"), fig=fig, ax=axes[:, 1].tolist(),
                     location="bottom", shrink=0.9, aspect=12, extend="both",
                     label=r"$\tilde\rho$ remaining (middle)")
        if fig_label is not None:
            save_figure(fig, fig_label)
    return fig
