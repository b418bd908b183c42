r"""The diffusion density-equalizing map of the unit square for cartograms, in numpy alone.

The method is that of :mod:`rfmap.solvers.diffusion` (Gastner & Newman 2004) with the square's walls fixed: the
density diffuses, :math:`\partial_t\rho = \Delta\rho` with no-flux walls, and points follow
:math:`\dot x = -\nabla\rho(x, t) / \rho(x, t)` until the density is nearly uniform.  As in
:mod:`rfmap.solvers.cartoflow`, it is one pass of a cartogram (:func:`rfmap.cartogram.resize.cartogram` with
``method="diffusion"``) and carries a cartogram's distinct polygon vertices themselves, or the ``N``-grid's vertices.

The flow and its heat field are the map solver's (:func:`rfmap.solvers.heatflow.diffuse`: its driver, stopping
rule and blurred start; :class:`rfmap.solvers.heatfield.HeatField`: the exact cosine solution of the diffusion
equation, evaluated by separable products); what is the cartogram's own is how it sets them:

* The raster is the vertex grid itself (a cartogram's raster holds cell means; the maps refine theirs), its cosine
  coefficients from one type-I cosine transform by ``numpy.fft``
  (:class:`rfmap.solvers.cosine.CosineTransforms`).
* The velocity at a point divides the bilinear interpolants of :math:`\nabla\rho` and :math:`\rho`
  (``divide="points"``; the maps divide on the raster and interpolate the velocity).
* Time steps are predictor--corrector (Heun) pairs (:func:`rfmap.solvers.heun.heun_flow`, the cartogram flow's):
  a step is accepted when :math:`\max|x' - x^*|` is at most ``rtol`` grid spacings (for the grid, also when no
  triangle turned over), the next step scaled by the error.  Integration stops when the remaining displacement,
  estimated as :math:`\max|v| / \pi^2` (:class:`rfmap.solvers.heatflow.Settling`), is below ``tol_end`` grid
  spacings, or at ``t_max``.

The map solver's integrator (Bogacki--Shampine 3(2)) is not used here: a cartogram's pass takes Heun steps (see
:mod:`rfmap.solvers.heatflow`).

PyTorch is never imported here (nor ``scipy.fft``): the classical cartogram methods run without either.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .cartoflow import GridFlow, _grid_turned_over, _project, square_inputs
from .cosine import CosineTransforms
from .heatfield import HeatField
from .heatflow import Settling, blur_start, diffuse
from .heun import HeunOptions

__all__ = ["CartoDiffusionOptions", "diffusion_square"]


@dataclass(frozen=True)
class CartoDiffusionOptions:
    r"""Options of :func:`diffusion_square`.

    Attributes
    ----------
    rtol : float
        Step tolerance: the largest predictor--corrector difference, in grid spacings (the flow's, 0.2).
    tol_end : float
        Stop when the estimated remaining displacement is below this many grid spacings.
    t_max : float
        Simulated time (box units) at which to stop regardless; the slowest mode has then decayed by
        :math:`e^{-\pi^2 t_{max}}`.
    max_steps : int
        Most (accepted + rejected) steps; ``RuntimeError`` beyond.
    blur : float
        Start at :math:`t_0 = (\mathrm{blur}\,h)^2 / 2`, when diffusion has blurred the density over ``blur`` vertex
        spacings (as cartogram programs blur sharp edges); 0 (default) starts at 0.
    """

    rtol: float = 0.2
    tol_end: float = 1e-2
    t_max: float = 2.0
    max_steps: int = 10_000
    blur: float = 0.0


def diffusion_square(density: np.ndarray, options: CartoDiffusionOptions | None = None, *,
                     points: np.ndarray | None = None) -> GridFlow:
    r"""One diffusion map of the unit square with fixed walls (the module's description gives the method).

    Parameters
    ----------
    density : ndarray, shape (N, N)
        Strictly positive vertex densities, ``density[i, j]`` at :math:`(i, j)/(N-1)`.
    options : CartoDiffusionOptions, optional
    points : ndarray, shape (P, 2), optional
        Points of the unit square to carry (a cartogram's distinct polygon vertices).  Default: the ``N``-grid's
        vertices, every step checked for turned-over triangles.

    Returns
    -------
    GridFlow
        The points (or the grid's vertices) and their images; ``info`` has ``method="diffusion"``, ``steps``,
        ``rejected``, ``fold_rejections``, ``evaluations``, ``t_end`` and ``grid``.

    Raises
    ------
    ValueError
        For a density that is not a square 2D array of positive finite numbers, or points not of shape (P, 2).
    RuntimeError
        When the steps run out.
    """
    t0 = time.perf_counter()
    opts = options or CartoDiffusionOptions()
    dens, ref, grid = square_inputs(density, points)
    n = dens.shape[0]
    h = 1.0 / (n - 1)
    project = (lambda p: _project(p, n)) if grid else (lambda p: np.clip(p, 0.0, 1.0, out=p))
    stepping = HeunOptions(opts.rtol * h, t0=blur_start(opts.blur, n), t_end=opts.t_max, first_step=0.1 * h * h,
                           max_steps=opts.max_steps, stall_dt=0.0)
    field = HeatField(dens, divide="points", transforms=CosineTransforms(n))
    mapped, info = diffuse(field, np.clip(ref, 0.0, 1.0), project, stepping, Settling(opts.tol_end * h),
                           _grid_turned_over(n) if grid else None)
    info.update(method="diffusion", passes=1, n=n, grid=grid)
    return GridFlow(ref_points=ref, mapped_points=mapped, time=time.perf_counter() - t0, info=info)
