"""The diffusion cartogram method (Gastner & Newman 2004): the polygons' vertices carried by the diffusion DEM of the
unit square with fixed walls (:func:`rfmap.solvers.cartodiffusion.diffusion_square`, numpy only)."""
from __future__ import annotations

import numpy as np

from .base import CartogramMethod

__all__ = ["DiffusionMethod"]


class DiffusionMethod(CartogramMethod):
    """``"diffusion"`` (also ``"dem"``): the classical diffusion DEM, carrying the vertices; it stops at a remaining
    displacement of 1 % of a vertex spacing (the default ``tol_end`` of
    :class:`rfmap.solvers.cartodiffusion.CartoDiffusionOptions`)."""

    name = "diffusion"

    def _map(self, density: np.ndarray, points: np.ndarray, solver_kw: dict):
        from ...solvers import cartodiffusion  # loaded by the method's first pass: a flow cartogram never needs it

        opts = cartodiffusion.CartoDiffusionOptions(**solver_kw)
        return cartodiffusion.diffusion_square(density, opts, points=points)
