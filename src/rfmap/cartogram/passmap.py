"""The map of the unit square for one cartogram pass, by each method of :func:`rfmap.cartogram.resize.cartogram`, and
its displacement at any point.

Nothing here imports PyTorch until a surrogate is asked for.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["DIFFUSION_SETTINGS", "FLOW_SETTINGS", "HYBRID_POLISH", "at_points", "grid_map"]

#: Settings of :func:`rfmap.solvers.solve_dem` on a cartogram's raster (which holds cell means: ``refine=1``, book:
#: Design decisions); stop at a remaining displacement of 1 % of a cell (``tol_end``, used by the cartograms' own
#: torch-free diffusion, :func:`rfmap.solvers.cartodiffusion.diffusion_square`, too).
DIFFUSION_SETTINGS = {"refine": 1, "tol_end": 1e-2}
#: Settings of ``solve_dem(method="flow")`` on a cartogram's raster: one flow per pass (``tol=0``: passes stop on
#: area errors), on the vertex grid (``refine=1``; book: Design decisions).  :func:`cartogram` itself carries the
#: vertices by the torch-free :func:`rfmap.solvers.cartoflow.flow_square`.
FLOW_SETTINGS = {"refine": 1, "tol": 0.0}
#: The hybrid's polish tolerance on Std(rho~_map) (``Surrogate.map(polish=...)``): far below any raster's variation, so
#: that every pass runs its flow, for the reason of :data:`FLOW_SETTINGS`' ``tol=0``.  The polish runs on the
#: raster's vertex grid (the network's map resampled to it), where the area errors are judged (book: Design
#: decisions).
HYBRID_POLISH = 1e-9


def at_points(res, points: np.ndarray) -> np.ndarray:
    """The grid map ``res`` (a :class:`rfmap.core.result.MapResult` on the ``N``-grid) at ``points`` (P, 2): its
    displacement interpolated bilinearly."""
    from ..solvers.cartoflow import bilinear

    if not res.info.get("grid", True):  # the flow carried the points themselves
        return res.mapped_points
    n = math.isqrt(res.ref_points.shape[0])
    return points + bilinear((res.mapped_points - res.ref_points).reshape(n, n, 2), points)


def grid_map(method: str, density: np.ndarray, surrogate, solver_kw: dict):
    """The map of the unit square for one pass: the classical diffusion or flow DEM with fixed walls, the
    surrogate's map on its working grid (repaired there, so that it is fold-free before it is interpolated at the
    polygon vertices), or the hybrid's on the raster's vertex grid."""
    kw = dict(solver_kw)
    points = kw.pop("points", None)
    if method == "flow":  # torch-free, as the diffusion
        from ..solvers.cartoflow import CartoFlowOptions, flow_square

        return flow_square(density, CartoFlowOptions(**kw), points=points)
    if method == "diffusion":
        from ..solvers.cartodiffusion import CartoDiffusionOptions, diffusion_square

        opts = CartoDiffusionOptions(**{"tol_end": DIFFUSION_SETTINGS["tol_end"], **kw})
        return diffusion_square(density, opts, points=points)
    from ..finish import quiet_quality

    # the raster's Std(rho~) counts the sea and every region's edge; the cartogram judges a pass by its area errors
    with quiet_quality():
        if method == "hybrid":  # the network's map resampled to the vertex grid and finished there by the flow
            return surrogate.map(density, density.shape[0], preprocess=False, polish=HYBRID_POLISH)
        return surrogate.map(density, surrogate.work_n(density.shape[0]), preprocess=False)

