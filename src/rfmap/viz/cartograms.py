"""Cartograms: regions drawn from their geometries, a cartogram beside its input map, panels of cartograms, and
histograms of the area errors."""
from __future__ import annotations

import numpy as np

from .figures import save_figure, style

__all__ = ["plot_regions", "cartogram_figure", "cartogram_panels", "area_error_histograms"]


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
