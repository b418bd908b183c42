"""A cartogram pass's map at any point: the polygon vertices a classical method carried, or the grid map's
displacement interpolated there (the maps themselves: :mod:`rfmap.cartogram.methods`).  Nothing here imports
PyTorch."""
from __future__ import annotations

import math

import numpy as np

from ..solvers.cartoflow import bilinear

__all__ = ["at_points"]


def at_points(res, points: np.ndarray) -> np.ndarray:
    """The grid map ``res`` (a :class:`rfmap.core.result.MapResult` on the ``N``-grid) at ``points`` (P, 2): its
    displacement interpolated bilinearly."""
    if not res.info.get("grid", True):  # the flow carried the points themselves
        return res.mapped_points
    n = math.isqrt(res.ref_points.shape[0])
    return points + bilinear((res.mapped_points - res.ref_points).reshape(n, n, 2), points)
