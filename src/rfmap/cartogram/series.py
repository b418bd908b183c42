r"""Cartograms of a time series: one cartogram per frame (a year's population, say), warm-started from the previous
frame, checked against the tolerance, and drawn as an animation.

A cold series computes every frame from the original map (:func:`rfmap.cartogram.resize.cartogram`).  A warm series
computes the first frame so, in the projection's plane (``output="projected"``), and every later frame from the
previous frame's cartogram, in that same plane (``projection="none"``), with the new values.  Between two frames
a region's share of the total changes by a few per cent, so the previous cartogram is already nearly
density-equalized for the new values: the raster of the first pass is nearly uniform and fewer passes reach the
tolerance.  Every frame of either series lies in one plane (metres of the equal-area projection for
longitude/latitude input), so frames can be compared and animated as they are.

A frame is within tolerance when the largest relative area error :math:`|A_i / T_i - 1|` over the regions holding
at least ``min_share`` of the total value is at most ``tol``; the regions below that share (islands of a few
thousand people on a world map) are reported apart (``small_error`` of :class:`SeriesFrame`).

Nothing here imports PyTorch at import time.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..core.wording import counted
from .options import CartogramOptions
from .resize import cartogram

__all__ = ["SeriesFrame", "CartogramSeries", "cartogram_series", "compare_warm_cold", "save_animation"]


@dataclass
class SeriesFrame:
    """One frame of a :class:`CartogramSeries`.

    Attributes
    ----------
    key : str
        The frame's value property (e.g. ``"pop_1952"``).
    carto : rfmap.cartogram.resize.Cartogram
        Its cartogram, in the projection's plane.
    seconds : float
        Wall-clock seconds of the frame's :func:`~rfmap.cartogram.resize.cartogram` call (parsing included).
    passes : int
        Passes run.
    max_error : float
        The largest relative area error over the regions holding at least ``min_share`` of the total.
    small_error : float
        The largest over the other regions (0 when there are none).
    small : list of str
        The regions below ``min_share`` (their ids or names).
    """

    key: str
    carto: object
    seconds: float
    passes: int
    max_error: float
    small_error: float
    small: list = field(default_factory=list)


@dataclass
class CartogramSeries:
    """Cartograms of one map by a sequence of values (:func:`cartogram_series`)."""

    frames: list
    warm: bool
    tol: float
    min_share: float

    @property
    def seconds(self) -> np.ndarray:
        """Seconds per frame, shape (F,)."""
        return np.array([f.seconds for f in self.frames])

    @property
    def passes(self) -> np.ndarray:
        """Passes per frame, shape (F,)."""
        return np.array([f.passes for f in self.frames])

    @property
    def max_errors(self) -> np.ndarray:
        """The largest area error over the regions holding at least ``min_share``, per frame, shape (F,)."""
        return np.array([f.max_error for f in self.frames])

    def within_tolerance(self) -> np.ndarray:
        """Whether each frame's :attr:`max_errors` is at most ``tol``, shape (F,)."""
        return self.max_errors <= self.tol

    def problems(self) -> list[str]:
        """One line per frame above the tolerance, and one per frame with invalid or overlapping regions."""
        out = []
        for f in self.frames:
            if not f.max_error <= self.tol:
                out.append(f"{f.key}: largest area error {f.max_error:.4f} above {self.tol:g} after "
                           f"{counted(f.passes, 'pass')}")
            m = f.carto.metrics()
            if not m.topology_ok:
                out.append(f"{f.key}: {counted(m.n_invalid, 'invalid region')}, "
                           f"{counted(m.n_overlapping, 'overlapping pair')}")
        return out


def _name(feature: dict, k: int) -> str:
    props = feature.get("properties") or {}
    return str(props.get("name") or feature.get("id") or f"#{k}")


def _frame(carto, key: str, seconds: float, min_share: float) -> SeriesFrame:
    """A :class:`SeriesFrame`: the area errors split at ``min_share`` of the total value."""
    err = carto.area_errors
    share = carto.values / carto.values.sum()
    big = share >= min_share
    small = [_name(carto.features[k], k) for k in np.flatnonzero(~big)]
    return SeriesFrame(key, carto, seconds, int(carto.info["iterations"]), float(err[big].max()),
                       float(err[~big].max()) if (~big).any() else 0.0, small)


def cartogram_series(collection, keys: Sequence[str], options: CartogramOptions | None = None, *, warm: bool = True,
                     **kw) -> CartogramSeries:
    r"""One cartogram per value property in ``keys``, each warm-started from the previous frame or cold.

    Parameters
    ----------
    collection : dict, str or path
        A GeoJSON FeatureCollection whose regions hold every property of ``keys``.
    keys : sequence of str
        The frames' value properties, in order (e.g. ``["pop_1952", "pop_1957", ...]``).
    options : CartogramOptions, optional
        The options of every frame's :func:`rfmap.cartogram.resize.cartogram` (``method``, ``n``, ``tol``,
        ``max_iterations``, ...; its fields may be given as keywords).  ``projection`` is the plane of the first
        frame (and of every cold frame); ``min_share``: regions holding less than this share of a frame's total are
        checked apart (:class:`SeriesFrame`) and left out of the passes' stopping rule; ``output`` stays
        ``"auto"``: every frame is returned in the projection's plane (the warm frames are computed there).
    warm : bool
        ``True``: frame :math:`k > 0` is the cartogram of frame :math:`k-1`'s cartogram (in the projection's
        plane) by the values of ``keys[k]``; ``False``: every frame from ``collection``.

    Returns
    -------
    CartogramSeries
    """
    o = replace(options or CartogramOptions(), **kw)
    keys = list(keys)
    if not keys:
        raise ValueError("give at least one value property")
    if o.output != CartogramOptions.output:
        raise ValueError("a series is computed in the projection's plane; output cannot be chosen")
    frames, previous = [], None
    for key in keys:
        t0 = time.perf_counter()
        if warm and previous is not None:
            src = {"type": "FeatureCollection", "features": previous.features}
            carto = cartogram(src, key, replace(o, projection="none", output="input"))
        else:
            carto = cartogram(collection, key, replace(o, output="projected"))
        frames.append(_frame(carto, key, time.perf_counter() - t0, o.min_share))
        previous = carto
    return CartogramSeries(frames, warm, float(o.tol), o.min_share)


def compare_warm_cold(collection, keys: Sequence[str], options: CartogramOptions | None = None,
                      **kw) -> tuple[CartogramSeries, CartogramSeries]:
    """The warm and the cold series of :func:`cartogram_series` with the same options: ``(warm, cold)``."""
    return (cartogram_series(collection, keys, options, warm=True, **kw),
            cartogram_series(collection, keys, options, warm=False, **kw))


def save_animation(series: CartogramSeries, path, *, titles: Sequence[str] | None = None, fps: float = 2.0,
                   colors=None, width: float = 7.8, dpi: int = 80) -> str:
    """Write the frames of ``series`` as an animated GIF (matplotlib's ``PillowWriter``) or, for ``.mp4``, a video
    (``FFMpegWriter``; needs ffmpeg); returns the path.  Every frame on one extent, regions in fixed colours
    (:func:`rfmap.viz.cartograms.neighbour_colours` of the first frame unless ``colors``), titled by ``titles``
    (default: the frame keys)."""
    import matplotlib.pyplot as plt
    from matplotlib import animation

    from ..viz.cartograms import column_style, neighbour_colours, plot_regions

    path = str(path)
    if not path.lower().endswith((".gif", ".mp4")):
        raise ValueError(f"an animation is written as .gif or .mp4, got {path!r}")
    geoms = [f.carto.projected_geometries() for f in series.frames]
    titles = list(titles) if titles is not None else [f.key for f in series.frames]
    face = colors if colors is not None else neighbour_colours(series.frames[0].carto.projected_geometries(
        mapped=False))
    b = np.array([g.bounds for gs in geoms for g in gs])
    lo, hi = b[:, :2].min(0), b[:, 2:].max(0)
    pad = 0.02 * (hi - lo)
    with plt.rc_context(column_style(width)):
        fig, ax = plt.subplots(figsize=(width, width * (hi - lo)[1] / (hi - lo)[0] + 0.5), layout="constrained")

        def draw(k):
            ax.clear()
            coll = plot_regions(ax, geoms[k], lw=0.2)
            coll.set_facecolor(face)
            ax.set(xlim=(lo[0] - pad[0], hi[0] + pad[0]), ylim=(lo[1] - pad[1], hi[1] + pad[1]))
            ax.set_aspect("equal")
            ax.axis("off")
            ax.set_title(f"{titles[k]}: largest area error {series.frames[k].max_error:.3f}")
            return [coll]

        anim = animation.FuncAnimation(fig, draw, frames=len(geoms), blit=False)
        writer = animation.PillowWriter(fps=fps) if path.lower().endswith(".gif") else \
            animation.FFMpegWriter(fps=fps)
        anim.save(path, writer=writer, dpi=dpi)
        plt.close(fig)
    return path
