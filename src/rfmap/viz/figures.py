"""The book's figures: one matplotlib style, and where figures are saved under their paper labels."""
from __future__ import annotations

import os
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

__all__ = ["ColorScale", "color_scale", "STYLE", "style", "colorbar", "frameless", "COLORBAR_TICKS", "repository_root",
           "figures_dir", "save_figure", "display_font_sizes", "MIN_DISPLAY_PT", "TEXT_COLUMN_PX", "MAX_FIGURE_PX"]


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


#: the display width, in CSS pixels, that the readability check of saved figures assumes
#: (:func:`display_font_sizes`): an image wider than this is taken to be shown scaled down to it.  An assumed width,
#: not a measured one: the book's text column narrows and widens with the browser window
TEXT_COLUMN_PX = 720

#: the smallest text a reader should have to read, in points, as the figure is shown in the text column
MIN_DISPLAY_PT = 9.0

#: the widest saved image, in pixels
MAX_FIGURE_PX = 2400


@dataclass(frozen=True)
class ColorScale:
    """How values map to colours: the limits (``None``: the data's own) and the colormap."""

    vmin: float | None = None
    vmax: float | None = None
    cmap: str = "viridis"

    @property
    def clim(self) -> tuple[float | None, float | None]:
        return (self.vmin, self.vmax)


def color_scale(scale: ColorScale | None = None, **kw) -> ColorScale:
    """``scale`` (default :class:`ColorScale`) with the fields given as keywords replaced: ``vmin``, ``vmax``,
    ``cmap``, or ``clim=(vmin, vmax)``; ``TypeError`` for any other keyword."""
    if "clim" in kw:
        kw["vmin"], kw["vmax"] = kw.pop("clim")
    return replace(scale or ColorScale(), **kw)


@contextmanager
def style():
    """Context manager applying the book's matplotlib style."""
    import matplotlib.pyplot as plt

    with plt.rc_context(STYLE):
        yield


#: the most labelled ticks on a colour bar (at round steps), so that fewer, shorter labels fit at the figure's text size
COLORBAR_TICKS = 5


def colorbar(mappable, *, ax, fig=None, **kw):
    """A colour bar for ``mappable`` beside ``ax`` (an axis or a list of axes; ``kw`` as for
    ``Figure.colorbar``), with at most :data:`COLORBAR_TICKS` labelled ticks set at the figure's text size
    (``font.size`` of the book's :data:`STYLE`), never smaller: short bars otherwise crowd many small labels."""
    import matplotlib as mpl
    import numpy as np
    from matplotlib.ticker import MaxNLocator

    fig = fig or (ax if hasattr(ax, "figure") else np.ravel(ax)[0]).figure
    cb = fig.colorbar(mappable, ax=ax, **kw)
    if not isinstance(getattr(mappable, "norm", None), mpl.colors.LogNorm):
        cb.locator = MaxNLocator(COLORBAR_TICKS, steps=[1, 2, 2.5, 5, 10])
        cb.update_ticks()
    cb.ax.tick_params(labelsize=max(float(mpl.rcParams["font.size"]), float(STYLE["font.size"])))
    return cb


def frameless(ax) -> None:
    """An image-like panel (a mesh, a field on the square, a rendering) without ticks and without the frame's
    spines, which say nothing there."""
    ax.set_xticks([])
    ax.set_yticks([])
    for side in ax.spines.values():
        side.set_visible(False)


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
        here = Path(__file__).resolve().parents[3]
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


def display_font_sizes(fig, dpi: float | None = None) -> tuple[float, list[tuple[str, float]], int]:
    r"""How large the text of ``fig`` appears when its saved image is shown at most :data:`TEXT_COLUMN_PX` wide.

    A saved image ``w`` pixels wide is taken to be shown at :math:`\min(w, C)` CSS pixels, :math:`C` =
    ``TEXT_COLUMN_PX``, so text of ``s`` points at ``dpi`` appears at
    :math:`s\,\frac{\mathrm{dpi}}{96}\,\min\bigl(1, \frac{C}{w}\bigr)` points (96 CSS pixels to the inch, 72 points to
    the inch).

    Returns
    -------
    scale : float
        Displayed points per point of the figure.
    texts : list of (str, float)
        Every visible, non-empty text of the figure with its displayed size in points.
    width : int
        The saved width in pixels (the tight bounding box when ``savefig.bbox`` is ``"tight"``).
    """
    import matplotlib as mpl
    from matplotlib.text import Text

    if dpi is None:
        dpi = fig.dpi if mpl.rcParams["savefig.dpi"] == "figure" else mpl.rcParams["savefig.dpi"]
    dpi = float(dpi)
    fig.canvas.draw()  # a constrained or tight layout places (and may resize) its texts only when drawn
    renderer = fig.canvas.get_renderer()
    inches = (fig.get_tightbbox(renderer).width if mpl.rcParams["savefig.bbox"] == "tight"
              else fig.get_size_inches()[0])
    width = int(round(inches * dpi))
    scale = dpi / 96.0 * min(1.0, TEXT_COLUMN_PX / max(width, 1))
    texts = [(t.get_text(), t.get_fontsize() * scale) for t in fig.findobj(Text)
             if t.get_visible() and t.get_text().strip() and _drawn(t, renderer)]
    return scale, texts, width


def _drawn(text, renderer) -> bool:
    """Whether a text lies inside the figure (tick labels outside an axis' view are kept but never drawn)."""
    try:
        box = text.get_window_extent(renderer)
    except Exception:  # noqa: BLE001
        return False
    fig_box = text.figure.bbox
    return box.width > 0 and box.x1 >= fig_box.x0 - 1 and box.x0 <= fig_box.x1 + 1 and \
        box.y1 >= fig_box.y0 - 1 and box.y0 <= fig_box.y1 + 1


def save_figure(fig, label: str) -> Path:
    """Save ``fig`` as ``<figures_dir>/<label>.png`` where ``label`` is the paper's label (``fig:x_y`` → ``fig-x-y``).

    Meant for the book's own figures, whose layout rule it enforces; save a figure of your own with matplotlib's
    ``fig.savefig(path)``, which checks nothing.

    Raises
    ------
    ValueError
        When the figure would be unreadable in the book: wider than :data:`MAX_FIGURE_PX` pixels, or with text that
        appears smaller than :data:`MIN_DISPLAY_PT` points in the text column (:func:`display_font_sizes`).  Nothing
        is written then.
    """
    scale, texts, width = display_font_sizes(fig)
    small = sorted({(round(size, 1), text[:30]) for text, size in texts if size < MIN_DISPLAY_PT - 1e-6})
    if width > MAX_FIGURE_PX or small:
        raise ValueError(f"figure {label} is unreadable in the book: {width} px wide (at most {MAX_FIGURE_PX}); "
                         f"text shown at {scale:.2f} pt per pt" + (f", {len(small)} texts under {MIN_DISPLAY_PT:g} pt, "
                                                                  f"e.g. {small[:3]}" if small else ""))
    name = label.replace(":", "-").replace("_", "-")
    path = figures_dir() / f"{name}.png"
    fig.savefig(path)
    return path
