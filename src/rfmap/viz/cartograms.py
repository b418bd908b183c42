"""Cartograms: regions drawn from their geometries, a cartogram beside its input map, panels of cartograms, and
histograms of the area errors."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..core.wording import format_sig
from .figures import save_figure
from .figures import colorbar as add_colorbar

__all__ = ["RegionStyle", "FigureOptions", "plot_regions", "cartogram_figure", "cartogram_panels", "area_error_histograms", "column_style",
           "neighbour_colours", "region_colours", "area_legend", "format_amount", "series_grid", "TEXT_COLUMN_IN",
           "QUALITATIVE"]


@dataclass(frozen=True)
class RegionStyle:
    """How :func:`plot_regions` fills and outlines regions: colormap and limits of the values, edge colour and width."""

    cmap: str = "viridis"
    vmin: float | None = None
    vmax: float | None = None
    edgecolor: str = "white"
    lw: float = 0.4


def _error_title(carto, m) -> str:
    """The cartogram panel's title: its largest area error, and where regions under the judged share of the total
    are left out of it, over which regions it is taken and how many smaller ones it leaves out (too small for the
    raster to size: the page that draws them says how far off they are)."""
    head = f"cartogram: max area error {format_sig(m.max_error, 2)}"
    if m.n_minor:
        some = "one region" if m.n_minor == 1 else f"{m.n_minor} regions"
        head += (f"\nover the regions holding at least {100 * carto.min_share:.2g} % of the total"
                 f" ({some} too small for the raster left out)")
    return head


def plot_regions(ax, geoms, values=None, *, title: str | None = None, colorbar: bool = False, label: str | None = None,
                 style: RegionStyle | None = None, **kw):
    """Draw shapely Polygons / MultiPolygons (holes included), filled by ``values`` (one per geometry) or grey, as
    ``style`` says (:class:`RegionStyle`; its fields may be given as keywords: ``lw=0.2``, ``vmin=0``, ...)."""
    st = replace(style or RegionStyle(), **kw)
    cmap, vmin, vmax, edgecolor, lw = st.cmap, st.vmin, st.vmax, st.edgecolor, st.lw
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
        add_colorbar(coll, ax=ax, fraction=0.046, pad=0.03, label=label)
    return coll


#: Width (inches) up to which a figure's text keeps at least its own size when shown (the readability check's
#: assumed display width, :data:`rfmap.viz.figures.TEXT_COLUMN_PX`, at 96 CSS pixels to the inch); a wider figure
#: is shrunk, so its text is set larger (:func:`column_style`) to stay at least 9 pt when shown.
TEXT_COLUMN_IN = 720 / 96
#: The qualitative palette of regions coloured so that neighbours differ (matplotlib's Set2, then Pastel1).
QUALITATIVE = ("#66c2a5", "#fc8d62", "#8da0cb", "#e78ac3", "#a6d854", "#ffd92f", "#e5c494", "#b3b3b3",
               "#fbb4ae", "#b3cde3", "#ccebc5", "#decbe4")


def column_style(width: float, *, svg_text: bool = False) -> dict:
    r"""The book's style (:data:`~rfmap.viz.figures.STYLE`) for a figure ``width`` inches wide: text of
    :math:`9\,\max(1, w / w_c)` pt with :math:`w_c` = :data:`TEXT_COLUMN_IN`, so that it is at least 9 pt once the
    figure is fitted to the text column; ``svg_text`` keeps text as text in SVG output."""
    from .figures import STYLE

    size = 9.0 * max(1.0, width / TEXT_COLUMN_IN)
    out = {**STYLE, "font.size": size, "axes.titlesize": size, "legend.fontsize": size}
    if svg_text:
        out["svg.fonttype"] = "none"
    return out


def neighbour_colours(geoms, palette=QUALITATIVE) -> list:
    """One colour of ``palette`` per region such that regions that touch differ (greedy, largest region first)."""
    import shapely

    geoms = np.asarray(geoms, dtype=object)
    tree = shapely.STRtree(geoms)
    left, right = tree.query(shapely.buffer(geoms, 0.0), predicate="intersects")
    nbrs = [set() for _ in geoms]
    for i, j in zip(left, right):
        if i != j:
            nbrs[i].add(int(j))
            nbrs[j].add(int(i))
    colour = [-1] * len(geoms)
    for i in np.argsort(-shapely.area(geoms), kind="stable"):
        used = {colour[j] for j in nbrs[i]}
        colour[i] = next(c for c in range(len(palette) + len(used) + 1) if c not in used)
    return [palette[c % len(palette)] for c in colour]


def region_colours(column) -> tuple[list, dict]:
    """Face colours from a colour column (one entry per region): matplotlib colours as they are, otherwise one
    colour of :data:`QUALITATIVE` per category (missing entries grey).  Returns the colours and ``{category:
    colour}`` for a legend (empty for colours given as such)."""
    from matplotlib.colors import is_color_like

    entries = [None if c is None or c == "" else str(c) for c in column]
    if all(c is None or is_color_like(c) for c in entries):
        return [c or "0.85" for c in entries], {}
    cats = sorted({c for c in entries if c is not None})
    key = {c: QUALITATIVE[k % len(QUALITATIVE)] for k, c in enumerate(cats)}
    return [key.get(c, "0.85") for c in entries], key


def _nice_amount(x: float) -> float:
    """The largest 1, 2 or 5 times a power of ten that is at most ``x``."""
    p = 10.0 ** math.floor(math.log10(x))
    return max(m * p for m in (1.0, 2.0, 5.0) if m * p <= x * (1 + 1e-12))


def format_amount(x: float) -> str:
    """``5e6`` -> ``"5 million"``, ``2e9`` -> ``"2 billion"``, ``2000`` -> ``"2,000"``."""
    for scale, word in ((1e12, "trillion"), (1e9, "billion"), (1e6, "million")):
        if x >= scale:
            return f"{x / scale:g} {word}"
    return f"{x:,.0f}" if x >= 1 else f"{x:g}"


def area_legend(ax, total_value: float, total_area: float, *, unit: str = "", frac: float = 0.1) -> str:
    r"""A square in the lower left of ``ax`` whose area stands for a round amount of the value: at the cartogram's
    scale :math:`\sum_i v_i / \sum_i A_i` per unit area, the amount (1, 2 or 5 times a power of ten) whose square is
    at most ``frac`` of the axes' width on a side.  Returns the legend's text (``"= 50 million unit"``)."""
    from matplotlib.patches import Rectangle

    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    side_max = frac * (x1 - x0)
    amount = _nice_amount(side_max**2 * total_value / total_area)
    side = math.sqrt(amount * total_area / total_value)
    px, py = x0 + 0.02 * (x1 - x0), y0 + 0.03 * (y1 - y0)
    ax.add_patch(Rectangle((px, py), side, side, facecolor="0.35", edgecolor="none"))
    text = f"= {format_amount(amount)} {unit}".rstrip()
    ax.annotate(text, (px + side, py + 0.5 * side), xytext=(4, 0), textcoords="offset points", va="center")
    return text


def _draw_labels(ax, geoms, labels, min_share: float) -> None:
    """Each label at its region's representative point, for regions holding at least ``min_share`` of the area."""
    import shapely

    a = shapely.area(geoms)
    pts = shapely.point_on_surface(geoms)
    for g, p, lab, share in zip(geoms, pts, labels, a / a.sum()):
        if lab not in (None, "") and share >= min_share:
            ax.text(p.x, p.y, str(lab), ha="center", va="center", clip_on=True)


@dataclass(frozen=True)
class FigureOptions:
    """What :func:`cartogram_figure` draws (each field documented there)."""

    colors: object = None
    labels: object = None
    legend: bool = True
    unit: str = ""
    title: str = ""
    width: float = TEXT_COLUMN_IN
    label_share: float = 5e-3


def cartogram_figure(carto, options: FigureOptions | None = None, *, label: str | None = None, path=None, **kw):
    """A map and its cartogram (:class:`rfmap.cartogram.resize.Cartogram`) side by side, both in the plane of the
    cartogram (the equal-area projection for longitude/latitude input), on one scale; ``options``
    (:class:`FigureOptions`, its fields also as keywords) say what is drawn.

    Parameters
    ----------
    carto : Cartogram
    colors : None, "density" or sequence, optional
        ``None``: a qualitative palette in which neighbours differ (:func:`neighbour_colours`); ``"density"``: the
        input density over the mean (value per unit area), with a colour bar; a sequence (one entry per region):
        colours or categories (:func:`region_colours`; categories get a legend).
    labels : sequence, optional
        A text per region, drawn on both maps where a region holds at least ``label_share`` of the area.
    legend : bool
        An area legend on the cartogram (:func:`area_legend`): a square whose area stands for a stated amount of
        the value, in ``unit``.
    title : str
        The value's name, for the titles.
    label, path : optional
        Save under the figure label (:func:`.save_figure`) and/or to ``path`` (``.png``, ``.svg``, ``.pdf``; text
        stays text in SVG).
    width : float
        Inches (text is scaled by :func:`column_style`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    o = replace(options or FigureOptions(), **kw)
    colors, labels, legend, unit, title = o.colors, o.labels, o.legend, o.unit, o.title
    width, label_share = o.width, o.label_share
    before, after = carto.projected_geometries(mapped=False), carto.projected_geometries()
    key = {}
    if isinstance(colors, str) and colors == "density":
        area = np.array([g.area for g in carto.regions])
        face = carto.values / area / (carto.values.sum() / area.sum())
    elif colors is None:
        face = neighbour_colours(before)
    else:
        face, key = region_colours(colors)
    m = carto.metrics()
    svg = path is not None and str(path).lower().endswith(".svg")
    b = np.array([g.bounds for g in (*before, *after)])
    lo, hi = b[:, :2].min(0), b[:, 2:].max(0)
    aspect = (hi - lo)[1] / (hi - lo)[0]
    stacked = aspect < 0.7  # a wide map (the world): one above the other
    shape = ((2, 1), (width, 2 * width * aspect * 1.2 + 0.8)) if stacked else ((1, 2), (width, 0.5 * width))
    with plt.rc_context(column_style(width, svg_text=svg)):
        fig, axes = plt.subplots(*shape[0], figsize=shape[1], layout="constrained")
        for ax, geoms, head in ((axes[0], before, "input map"), (axes[1], after, _error_title(carto, m))):
            if isinstance(face, np.ndarray):
                coll = plot_regions(ax, geoms, face, vmin=0.0, vmax=float(np.quantile(face, 0.98)), lw=0.3)
            else:
                coll = plot_regions(ax, geoms, lw=0.3, edgecolor="white")
                coll.set_facecolor(face)
            ax.set_title(f"{head} ({title})" if ax is axes[0] and title else head)
        pad = 0.02 * (hi - lo)
        for ax, geoms in zip(axes, (before, after)):
            ax.set(xlim=(lo[0] - pad[0], hi[0] + pad[0]), ylim=(lo[1] - (0.2 if legend else 0.02) * (hi - lo)[1],
                                                         hi[1] + pad[1]))
            ax.set_aspect("equal")
            ax.axis("off")
            if labels is not None:
                _draw_labels(ax, geoms, labels, label_share)
        if legend:
            area_legend(axes[1], float(carto.values.sum()), float(sum(g.area for g in after)), unit=unit or title)
        if isinstance(face, np.ndarray):
            add_colorbar(coll, fig=fig, ax=axes, fraction=0.03, pad=0.01, label="input density / mean")
        if key:
            from matplotlib.patches import Patch

            if any(c is None or c == "" for c in colors):
                key = {**key, "no data": "0.85"}
            fig.legend([Patch(color=c) for c in key.values()], list(key), loc="outside lower center",
                       ncols=min(len(key), 4), frameon=False)
        if label:
            save_figure(fig, label)
        if path:
            fig.savefig(path)
    return fig


def cartogram_panels(cartos: dict, keys, *, label: str | None = None, cols: int = 3, width: float = TEXT_COLUMN_IN):
    """Cartograms in a grid of ``cols`` columns, one panel per key of ``cartos`` (``{key: Cartogram}``, keys as in
    :func:`rfmap.cartogram.resize.compare_cartograms`), with the input map first, all in the cartogram's plane.

    Every panel colours each region by its input density over the mean (the value of its own key; the input map by the
    value of the first key, named in its title), on one scale from 0 to the largest of the panels' 98th percentiles,
    shown by one colour bar. ``width`` inches (text by :func:`column_style`); saved under ``label``; returns the
    figure.
    """
    import matplotlib.pyplot as plt

    keys = list(keys)
    first = cartos[keys[0]]
    rows = -(-(len(keys) + 1) // cols)
    side = width / cols
    panels = [(first.projected_geometries(mapped=False), first, f"input map ({keys[0][0]})")]
    panels += [(cartos[k].projected_geometries(), cartos[k], " / ".join(map(str, k))) for k in keys]
    densities = []
    for _, c, _ in panels:
        area = np.array([g.area for g in c.regions])
        densities.append(c.values / area / (c.values.sum() / area.sum()))
    vmax = max(float(np.quantile(d, 0.98)) for d in densities)
    with plt.rc_context(column_style(width)):
        fig, axes = plt.subplots(rows, cols, figsize=(width, 1.1 * side * rows + 0.5), squeeze=False,
                                 layout="constrained")
        for ax, (geoms, _, title), density in zip(axes.flat, panels, densities):
            coll = plot_regions(ax, geoms, density, title=title, vmin=0.0, vmax=vmax, lw=0.2)
            ax.axis("off")
        for ax in axes.flat[len(panels):]:
            ax.axis("off")
        cb = add_colorbar(coll, fig=fig, ax=axes, location="bottom", shrink=0.5, aspect=40, pad=0.02,
                          extend="max", label="input density / mean (value per unit area over the map's mean)")
        cb.ax.xaxis.set_label_position("bottom")
        if label:
            save_figure(fig, label)
    return fig


def area_error_histograms(cartos: dict, labels, values, *, label: str | None = None, bins: int = 30,
                          cols: int = 2, width: float = TEXT_COLUMN_IN):
    """Histograms of the relative area errors :math:`|A_i/T_i - 1|` (log scale), one panel per value in a grid of
    ``cols`` columns and one colour per method label; ``cartos`` as returned by
    :func:`rfmap.cartogram.resize.compare_cartograms`; saved under ``label``; returns the figure."""
    import matplotlib.pyplot as plt

    values, labels = list(values), list(labels)
    errs = {k: np.maximum(c.area_errors, 1e-6) for k, c in cartos.items()}
    edges = np.logspace(-6, np.log10(max(e.max() for e in errs.values())) + 0.05, bins + 1)
    rows = -(-len(values) // cols)
    with plt.rc_context(column_style(width)):
        fig, axes = plt.subplots(rows, cols, figsize=(width, 2.4 * rows + 0.6), squeeze=False, sharex=True,
                                 sharey=True, layout="constrained")
        for ax, v in zip(axes.flat, values):
            for lab in labels:
                ax.hist(errs[v, lab], bins=edges, histtype="step", lw=1.4, label=lab)
            ax.axvline(0.01, color="0.5", ls=":", lw=0.8)
            ax.set(xscale="log", title=v)
        for ax in axes[-1]:
            ax.set_xlabel(r"$|A_i/T_i - 1|$")
        for ax in axes[:, 0]:
            ax.set_ylabel("regions")
        for ax in axes.flat[len(values):]:
            ax.axis("off")
        handles, names = axes.flat[0].get_legend_handles_labels()
        fig.legend(handles, names, loc="outside lower center", ncols=min(len(labels), 3), frameon=False)
        if label:
            save_figure(fig, label)
    return fig


def series_grid(series, indices, *, titles=None, colors=None, key: dict | None = None, label: str | None = None,
                cols: int = 2, width: float = TEXT_COLUMN_IN):
    """Frames of a :class:`rfmap.cartogram.series.CartogramSeries` in a grid of ``cols`` columns, all on one extent
    and scale, regions in fixed colours (``colors``, one per region, else :func:`neighbour_colours` of the input
    map), titled by ``titles`` (default: the frames' keys) with each frame's largest area error; ``key``
    (``{category: colour}``, as :func:`region_colours` returns it) adds a legend below the frames, with "no data"
    for the grey of regions without a category; saved under ``label``; returns the figure."""
    import matplotlib.pyplot as plt

    frames = [series.frames[i] for i in indices]
    titles = list(titles) if titles is not None else [f.key for f in frames]
    geoms = [f.carto.projected_geometries() for f in frames]
    face = colors if colors is not None else neighbour_colours(series.frames[0].carto.projected_geometries(
        mapped=False))
    b = np.array([g.bounds for gs in geoms for g in gs])
    lo, hi = b[:, :2].min(0), b[:, 2:].max(0)
    rows = -(-len(frames) // cols)
    aspect = (hi - lo)[1] / (hi - lo)[0]
    with plt.rc_context(column_style(width)):
        fig, axes = plt.subplots(rows, cols, figsize=(width, rows * (width / cols * aspect + 0.35)), squeeze=False,
                                 layout="constrained")
        for ax, g, t, f in zip(axes.flat, geoms, titles, frames):
            coll = plot_regions(ax, g, lw=0.15)
            coll.set_facecolor(face)
            ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]))
            ax.set_aspect("equal")
            ax.set_title(f"{t}: max error {f.max_error:.3f}")
            ax.axis("off")
        for ax in axes.flat[len(frames):]:
            ax.axis("off")
        if key:
            from matplotlib.patches import Patch

            if colors is not None and "0.85" in list(colors):
                key = {**key, "no data": "0.85"}
            fig.legend([Patch(color=c) for c in key.values()], list(key), loc="outside lower center",
                       ncols=min(len(key), 4), frameon=False)
        if label:
            save_figure(fig, label)
    return fig
