"""The interface of a cartogram method: the map of the unit square for one pass of
:func:`rfmap.cartogram.resize.cartogram`, and what the passes need to know of it."""
from __future__ import annotations

from typing import ClassVar

import numpy as np

__all__ = ["CartogramMethod", "MAX_N"]

#: The default ``max_n`` of :func:`rfmap.cartogram.resize.cartogram`: the finest raster (cells per side) a slow pass
#: may ask for
MAX_N = 1024


class CartogramMethod:
    """One way to map the unit square for a cartogram pass, built from the cartogram's options
    (:class:`rfmap.cartogram.options.CartogramOptions`).

    Attributes
    ----------
    name : str
        The name :data:`rfmap.cartogram.methods.METHODS` knows it by.
    classical : bool
        A classical solver (numpy only, no network): a time series of cartograms runs only these.
    carries_vertices : bool
        The map carries the polygons' distinct vertices themselves (the classical methods), so that edges it
        stretched are split between passes; otherwise it maps the raster's grid and its displacement is interpolated.
    accelerate : bool
        Between passes every region's weight is boosted by its slow progress
        (:func:`rfmap.cartogram.metrics.boost`).
    finest : int
        The default ``max_n``: the finest raster a slow pass may ask for.
    calls : int
        Passes mapped so far (the flow blurs its first ones).
    """

    name: ClassVar[str] = ""
    classical: ClassVar[bool] = True
    carries_vertices: ClassVar[bool] = True
    accelerate: ClassVar[bool] = False
    finest: ClassVar[int] = MAX_N

    def __init__(self, options) -> None:
        self.options = options
        self.calls = 0

    def prepare(self) -> None:
        """Called once before the first pass, to load what the method needs and check the options.  Here, and
        for the classical methods, it does nothing; the neural methods load their surrogate
        (:meth:`rfmap.cartogram.methods.neural.SurrogateMethod.prepare`)."""

    def grid_map(self, density: np.ndarray, points: np.ndarray):
        """The map of the unit square for one pass of the density raster ``density`` (N+1, N+1), at the distinct
        polygon vertices ``points`` (P, 2) for a method that carries them: a
        :class:`rfmap.core.result.MapResult`."""
        self.calls += 1
        return self._map(density, points, dict(self.options.solver_kw or {}))

    def _map(self, density: np.ndarray, points: np.ndarray, solver_kw: dict):
        raise NotImplementedError
