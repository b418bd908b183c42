"""The flow-based cartogram method (Gastner, Seguy & More 2018): the flux of the raster's Poisson problem carries the
polygons' vertices (:func:`rfmap.solvers.cartoflow.flow_square`, numpy only)."""
from __future__ import annotations

import numpy as np

from ...solvers import cartoflow
from .base import CartogramMethod

__all__ = ["FlowMethod", "FLOW_MAX_N", "FLOW_BLUR"]

#: The default ``max_n`` of the flow method, whose passes cost little more on a finer raster (they carry the
#: polygons' vertices, whose count ``SPLIT_MAX_N`` of :mod:`rfmap.cartogram.resize` bounds): a county map's smallest judged
#: regions, a few tens of cells at 1024, converge at 2048
FLOW_MAX_N = 2048
#: Blur (vertex spacings) of the flow's first pass, halved at every further pass (and none below a quarter): a
#: coast's jump of density, sampled by the grid, otherwise bends the outline between nearby vertices into folds
FLOW_BLUR = 1.0


class FlowMethod(CartogramMethod):
    """``"flow"`` (the default): the polygons' vertices carried by the flow, its density blurred over
    :data:`FLOW_BLUR` vertex spacings in the first pass and half as much in each next one; weights boosted between
    passes; rasters up to :data:`FLOW_MAX_N`."""

    name = "flow"
    accelerate = True
    finest = FLOW_MAX_N

    def _map(self, density: np.ndarray, points: np.ndarray, solver_kw: dict):
        blur = FLOW_BLUR * 0.5 ** (self.calls - 1)
        kw = {"blur": blur if blur >= 0.25 else 0.0, **solver_kw}
        return cartoflow.flow_square(density, cartoflow.CartoFlowOptions(**kw), points=points)
