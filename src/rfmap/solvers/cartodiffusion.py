r"""The diffusion density-equalizing map of the unit square for cartograms, in numpy alone.

The method is that of :mod:`rfmap.solvers.diffusion` (Gastner & Newman 2004) with the square's walls fixed: the
density diffuses, :math:`\partial_t\rho = \Delta\rho` with no-flux walls, and points follow
:math:`\dot x = -\nabla\rho(x, t) / \rho(x, t)` until the density is nearly uniform.  As in
:mod:`rfmap.solvers.cartoflow`, it is one pass of a cartogram (:func:`rfmap.cartogram.resize.cartogram` with
``method="diffusion"``) and carries a cartogram's distinct polygon vertices themselves, or the ``N``-grid's vertices.

The flow itself is the map solver's (:func:`rfmap.solvers.heatflow.diffuse`: its driver, stopping rule and
blurred start); what is the cartogram's own is its heat field and its integrator:

* The density's cosine coefficients :math:`c_k` come from one type-I cosine transform of the vertex values
  (:func:`rfmap.solvers.spectral.half_coefficients` on the ``numpy.fft`` transforms of
  :class:`rfmap.solvers.cosine.CosineTransforms`); at time :math:`t` they are :math:`c_k e^{-\pi^2|k|^2 t}`, and
  :math:`\rho`, :math:`-\partial_x\rho`, :math:`-\partial_y\rho` on the vertex grid are their cosine and sine
  syntheses (five transforms along one axis each; :func:`rfmap.solvers.spectral.flux_synthesis`, the flow's).
* The velocity at a point divides the bilinear interpolants of those three planes
  (:func:`rfmap.solvers.cartoflow.bilinear`).
* Time steps are predictor--corrector (Heun) pairs (:func:`rfmap.solvers.heun.heun_flow`, the cartogram flow's):
  a step is accepted when :math:`\max|x' - x^*|` is at most ``rtol`` grid spacings (for the grid, also when no
  triangle turned over), the next step scaled by the error.  Integration stops when the remaining displacement,
  estimated as :math:`\max|v| / \pi^2` (:class:`rfmap.solvers.heatflow.Settling`), is below ``tol_end`` grid
  spacings, or at ``t_max``.

The map solver's field (dense torch products on a refined raster) and integrator (Bogacki--Shampine 3(2)) are not
used here: this module must not import PyTorch, and each path keeps its results bit for bit (see
:mod:`rfmap.solvers.heatflow`).

PyTorch is never imported here (nor ``scipy.fft``): the classical cartogram methods run without either.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .cartoflow import GridFlow, _bilinear_planes, _grid_turned_over, _project, square_inputs
from .cosine import CosineTransforms
from .heatflow import Settling, blur_start, diffuse
from .heun import HeunOptions
from .spectral import damp, flux_synthesis, half_coefficients, heat_factor

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


class _Heat:
    r""":math:`\rho(\cdot, t)` and its flux :math:`-\nabla\rho` on the vertex grid, from the half cosine coefficients
    of :math:`\rho_0` (:func:`rfmap.solvers.spectral.half_coefficients`): the cartogram's heat field of
    :func:`rfmap.solvers.heatflow.diffuse`."""

    def __init__(self, dens: np.ndarray):
        self.n = dens.shape[0]
        self.ct = CosineTransforms(self.n)  # its buffers serve every evaluation
        self.coef = half_coefficients(dens, transforms=self.ct)  # synthesis: the same transforms

    def planes(self, t: float) -> np.ndarray:
        r"""(3, N*N): :math:`-\partial_x\rho`, :math:`-\partial_y\rho`, :math:`\rho` at time ``t``: the decayed
        coefficients (:func:`rfmap.solvers.spectral.heat_factor`) synthesised as a flux and its potential
        (:func:`rfmap.solvers.spectral.flux_synthesis`)."""
        b = damp(self.coef, heat_factor(self.n, t))
        return flux_synthesis(b, self.ct, value=True).reshape(3, -1)

    def velocity_at(self, t: float, pts: np.ndarray) -> np.ndarray:
        r""":math:`-\nabla\rho/\rho` at points (P, 2): the three planes interpolated, then divided."""
        f = _bilinear_planes(self.planes(t), self.n, pts)
        return f[:, :2] / f[:, 2:]


def diffusion_square(density: np.ndarray, options: CartoDiffusionOptions | None = None, *,
                     points: np.ndarray | None = None) -> GridFlow:
    r"""One diffusion map of the unit square with fixed walls (see the module docstring).

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
    mapped, info = diffuse(_Heat(dens), np.clip(ref, 0.0, 1.0), project, stepping, Settling(opts.tol_end * h),
                           _grid_turned_over(n) if grid else None)
    info.update(method="diffusion", passes=1, n=n, grid=grid)
    return GridFlow(ref_points=ref, mapped_points=mapped, time=time.perf_counter() - t0, info=info)
