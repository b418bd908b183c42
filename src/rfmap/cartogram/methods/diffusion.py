"""The diffusion cartogram method (Gastner & Newman 2004): the polygons' vertices carried by the diffusion DEM of the
unit square with fixed walls (:func:`rfmap.solvers.cartodiffusion.diffusion_square`, numpy only)."""
from __future__ import annotations

import numpy as np

from ...solvers import cartodiffusion
from .base import CartogramMethod

__all__ = ["DiffusionMethod", "DIFFUSION_SETTINGS"]

#: Settings of :func:`rfmap.solvers.solve_dem` on a cartogram's raster (which holds cell means: ``refine=1``,
#: :doc:`Design decisions </book/design>`); stop at a remaining displacement of 1 % of a cell (``tol_end``, used by the
#: cartograms' own torch-free diffusion, :func:`rfmap.solvers.cartodiffusion.diffusion_square`, too).
DIFFUSION_SETTINGS = {"refine": 1, "tol_end": 1e-2}


class DiffusionMethod(CartogramMethod):
    """``"diffusion"`` (also ``"dem"``): the classical diffusion DEM, carrying the vertices."""

    name = "diffusion"

    def _map(self, density: np.ndarray, points: np.ndarray, solver_kw: dict):
        opts = cartodiffusion.CartoDiffusionOptions(**{"tol_end": DIFFUSION_SETTINGS["tol_end"], **solver_kw})
        return cartodiffusion.diffusion_square(density, opts, points=points)
