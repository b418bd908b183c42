r"""Interactive cartograms: a self-contained HTML page (plotly) of one cartogram, or of a series with a slider.

Every region is one filled plotly trace, so that hovering over it shows its label (its id or name unless a column
gives labels), its value and its relative area error :math:`|A_i / T_i - 1|`
(:attr:`rfmap.cartogram.resize.Cartogram.area_errors`, measured in the equal-area plane).  A series (:class:`rfmap.cartogram.series.CartogramSeries`) becomes
one plotly frame per cartogram: a slider steps through them and a play button animates them; the axes hold the
extent of every frame, so that a region's size can be compared from frame to frame.  Longitude/latitude are drawn
with the aspect that is true to scale at the map's centre (:math:`1/\cos\varphi_0`), a plane's metres as they are.

The page embeds plotly.js (``include_plotlyjs=True``): it opens without a network.  plotly is imported only when a
page is made (it is in the ``geo`` extra).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .data import atomic_write

__all__ = ["HtmlOptions", "cartogram_page", "series_page", "page_figure", "figure_html", "fitted_height",
           "write_page", "PAGE_WIDTH_PX"]


@dataclass
class HtmlOptions:
    """How :func:`cartogram_page` and :func:`series_page` draw.

    Attributes
    ----------
    title : str, optional
        The page's heading (default: the value's name, or the series' first and last keys).
    labels : sequence of str, optional
        One label per region for the hover text (default: the feature's id, else its ``name`` property).
    colors : sequence of str, optional
        One CSS colour per region (default: neighbours differ, :func:`rfmap.viz.cartograms.neighbour_colours`).
    frame_ms : int
        Milliseconds per frame of the play button.
    detail : float
        The outlines are drawn simplified (``shapely.simplify``, topology kept) to this share of the map's larger
        side, their coordinates rounded to a tenth of it: a pixel of a page a thousand pixels wide by default, which
        keeps a world series of many frames a few megabytes; 0 draws every vertex as it is.  The hover's area errors
        are the cartogram's own.
    """

    title: str | None = None
    labels: Sequence | None = None
    colors: Sequence | None = None
    frame_ms: int = 800
    detail: float = 1e-3


def _plotly():
    try:
        import plotly.graph_objects as go
    except ImportError as e:  # a setup problem: said in one line by the command
        raise ImportError("the interactive page (--html) needs plotly: pip install 'rfmap[geo]'") from e
    return go


def _rings_xy(geom, step: float) -> tuple[list, list]:
    """The exterior rings of a (Multi)Polygon as one x and one y list, rings separated by ``None`` (plotly draws
    each as a closed filled shape), simplified to ``step`` and rounded to a tenth of it (``step`` 0: as they are)."""
    import shapely

    if step > 0:
        geom = shapely.simplify(geom, step, preserve_topology=True)
    xs, ys = [], []
    for part in shapely.get_parts(geom):
        if shapely.get_type_id(part) != 3 or part.is_empty:
            continue
        xy = np.asarray(part.exterior.coords)
        if step > 0:
            q = 10.0 ** np.floor(np.log10(step / 10))
            xy = np.round(xy / q) * q
        xs += xy[:, 0].tolist() + [None]
        ys += xy[:, 1].tolist() + [None]
    return xs, ys


def _label(feature: dict, k: int) -> str:
    """A region's default label: its id, else its ``name`` property, else ``#k``."""
    if feature.get("id") is not None:
        return str(feature["id"])
    name = (feature.get("properties") or {}).get("name")
    return str(name) if name is not None else f"#{k}"


def _traces(carto, labels: Sequence, colors: Sequence, step: float) -> list:
    """One filled scatter trace per region of ``carto`` (a :class:`rfmap.cartogram.resize.Cartogram`), in its output's
    coordinates (simplified to ``step``), its hover text naming the region, its value and its area error."""
    go = _plotly()
    errors = carto.area_errors
    out = []
    for k, geom in enumerate(carto.geometries):
        x, y = _rings_xy(geom, step)
        text = f"<b>{labels[k]}</b><br>value: {carto.values[k]:,.6g}<br>area error: {100 * errors[k]:.2f} %"
        out.append(go.Scatter(x=x, y=y, mode="lines", fill="toself", fillcolor=colors[k], name=str(labels[k]),
                              line={"color": "#404040", "width": 0.5}, hoveron="fills", hoverinfo="text",
                              text=text, showlegend=False))
    return out


def _extent(cartos) -> tuple[list, list]:
    """The x and y ranges holding every cartogram of ``cartos``, with 2 % to spare."""
    import shapely

    box = np.array([shapely.total_bounds(c.geometries) for c in cartos])
    lo, hi = box[:, :2].min(0), box[:, 2:].max(0)
    pad = 0.02 * (hi - lo)
    return [lo[0] - pad[0], hi[0] + pad[0]], [lo[1] - pad[1], hi[1] + pad[1]]


def page_figure(cartos: Sequence, keys: Sequence[str], options: HtmlOptions | None = None):
    """The plotly figure of :func:`cartogram_page` (one cartogram) and :func:`series_page` (several, with a slider
    and a play button): ``cartos`` are :class:`rfmap.cartogram.resize.Cartogram` of the same regions in the same
    coordinates, ``keys`` their values' names (frame names and slider labels).  Raises ValueError for labels or
    colours not one per region, or for cartograms of different regions."""
    go = _plotly()
    opts = options or HtmlOptions()
    first = cartos[0]
    count = len(first.geometries)
    if any(len(c.geometries) != count for c in cartos) or len(keys) != len(cartos):
        raise ValueError("the cartograms of a page must hold the same regions, one key each")
    labels = [_label(f, k) for k, f in enumerate(first.input_features)] if opts.labels is None else list(opts.labels)
    if opts.colors is None:
        from ..viz.cartograms import neighbour_colours

        colors = neighbour_colours(first.geometries)
    else:
        colors = ["#d9d9d9" if c is None or c == "" else str(c) for c in opts.colors]
    if len(labels) != count or len(colors) != count:
        raise ValueError(f"labels and colours must be one per region ({count}), got {len(labels)} and {len(colors)}")
    xr, yr = _extent(cartos)
    step = opts.detail * max(xr[1] - xr[0], yr[1] - yr[0])
    aspect = 1.0 / first.frame.cos_lat if first.output == "input" and first.frame.projection.geographic else 1.0
    fig = go.Figure(data=_traces(first, labels, colors, step))
    fig.update_layout(title=opts.title or (keys[0] if len(keys) == 1 else f"{keys[0]} to {keys[-1]}"),
                      plot_bgcolor="white", margin={"l": 10, "r": 10, "t": 50, "b": 10}, hovermode="closest",
                      xaxis={"range": xr, "visible": False, "autorange": False},
                      yaxis={"range": yr, "visible": False, "autorange": False, "scaleanchor": "x",
                             "scaleratio": aspect})
    if len(cartos) > 1:
        fig.frames = [go.Frame(data=_traces(c, labels, colors, step), name=str(key)) for c, key in zip(cartos, keys)]
        fig.update_layout(sliders=[_slider(keys)], updatemenus=[_play(opts.frame_ms)])
    return fig


def _slider(keys: Sequence[str]) -> dict:
    """A slider whose steps show the frames ``keys`` at once."""
    now = {"mode": "immediate", "frame": {"duration": 0, "redraw": True}, "transition": {"duration": 0}}
    return {"active": 0, "currentvalue": {"prefix": "frame: "}, "pad": {"t": 30},
            "steps": [{"label": str(k), "method": "animate", "args": [[str(k)], now]} for k in keys]}


def _play(frame_ms: int) -> dict:
    """Play and pause buttons."""
    play = {"frame": {"duration": int(frame_ms), "redraw": True}, "fromcurrent": True, "transition": {"duration": 0}}
    pause = {"mode": "immediate", "frame": {"duration": 0, "redraw": False}, "transition": {"duration": 0}}
    return {"type": "buttons", "showactive": False, "x": 0.0, "y": 0.0, "xanchor": "right", "yanchor": "top",
            "pad": {"t": 30, "r": 10},
            "buttons": [{"label": "play", "method": "animate", "args": [None, play]},
                        {"label": "pause", "method": "animate", "args": [[None], pause]}]}


#: the width, in CSS pixels, from which :func:`fitted_height` computes an interactive figure's height; the figure
#: then fills the width of the page it is on, so this width only sets its proportions (it is not the readability
#: check's :data:`rfmap.viz.figures.TEXT_COLUMN_PX`, which concerns saved images)
PAGE_WIDTH_PX = 660


def fitted_height(fig, width: int = PAGE_WIDTH_PX) -> int:
    """The height in pixels at which the plotly figure ``fig`` of :func:`page_figure`, ``width`` pixels wide, holds
    its map with no empty band above or below it: the map's extent at its aspect, the layout's margins, and room
    for the slider and buttons of a series."""
    lay = fig.layout
    dx = float(np.diff(lay.xaxis.range)[0])
    dy = float(np.diff(lay.yaxis.range)[0]) * float(lay.yaxis.scaleratio or 1.0)
    margin = lay.margin
    plot = (width - (margin.l or 0) - (margin.r or 0)) * dy / dx
    controls = 110 if lay.sliders else 0
    return int(round(min(max(plot + (margin.t or 0) + (margin.b or 0) + controls, 300), 900)))


def figure_html(fig, caption: str, *, name: str | None = None, height: int | None = None) -> str:
    """The plotly figure ``fig`` as a captioned HTML fragment for a notebook's output or a book page: a
    ``<figure>`` (with the id ``name``) that holds the figure, plotly.js embedded so that it draws without a
    network, ``height`` pixels high (an output area has no height of its own; default: :func:`fitted_height` for
    the book's text column), and a ``<figcaption>`` with ``caption`` as plain text (escaped), marked up as the
    book's captions are."""
    import html

    height = fitted_height(fig) if height is None else height
    fig.update_layout(height=height)
    body = fig.to_html(include_plotlyjs=True, full_html=False, default_height=f"{height}px")
    ident = f' id="{html.escape(name, quote=True)}"' if name else ""
    return (f'<figure class="align-default"{ident}>{body}<figcaption><p><span class="caption-text">'
            f"{html.escape(caption, quote=False)}</span></p></figcaption></figure>")


def write_page(fig, path) -> None:
    """Write the plotly figure ``fig`` as one self-contained HTML file (plotly.js embedded), atomically."""
    html = fig.to_html(include_plotlyjs=True, full_html=True, auto_play=False, config={"responsive": True})
    atomic_write(path, lambda fh: fh.write(html))


def cartogram_page(carto, path, options: HtmlOptions | None = None) -> None:
    """Write an interactive page of one cartogram (:class:`rfmap.cartogram.resize.Cartogram`) to ``path`` (.html): its
    regions in the output's coordinates, each hovered with its label, value and area error."""
    write_page(page_figure([carto], [options.title if options and options.title else "cartogram"], options), path)


def series_page(series, path, options: HtmlOptions | None = None) -> None:
    """Write an interactive page of a series of cartograms (:class:`rfmap.cartogram.series.CartogramSeries`) to
    ``path`` (.html): a frame per cartogram, a slider and a play button."""
    frames = series.frames
    write_page(page_figure([f.carto for f in frames], [f.key for f in frames], options), path)
