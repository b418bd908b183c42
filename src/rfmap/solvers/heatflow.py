r"""The flow of the diffusion method (Gastner & Newman 2004), shared by the map and the cartogram solvers.

The method, points following :math:`\dot x = v = -\nabla\rho/\rho` of the diffusing density until the flow has
settled, is stated in :mod:`rfmap.solvers.diffusion`.  One implementation here and in
:mod:`rfmap.solvers.heatfield`, for
:func:`rfmap.solvers.diffusion.solve_diffusion` (maps of the square and cube) and
:func:`rfmap.solvers.cartodiffusion.diffusion_square` (a cartogram's pass):

* the heat field, :class:`rfmap.solvers.heatfield.HeatField`: :math:`\rho`, :math:`\nabla\rho` and :math:`v`
  from the cosine series, on the raster a solver gives it and divided where it says (the maps on their refined
  raster's nodes, the cartograms at the points);
* the driver, :func:`diffuse`: velocity evaluations counted, the time integrator a strategy chosen by its options
  (:data:`INTEGRATORS`);
* the end of the flow, :class:`Settling`: the slowest mode decays at the rate :math:`\pi^2`
  (:data:`SLOWEST_RATE`), so the displacement still to come is about :math:`\max|v|/\pi^2`, and the flow stops when
  it is below a tolerance;
* a blurred start, :func:`blur_start`: the points start moving when diffusion has blurred the density over
  :math:`\sigma` vertex spacings, at :math:`t_0 = (\sigma h)^2/2` (the map's retries of a folding flow, the
  cartogram's ``blur``).

The two solvers differ in their time integrator, chosen by the options a solver hands :func:`diffuse`: the maps
take Bogacki--Shampine 3(2) steps (:func:`rfmap.solvers.bs32.bs32_flow`, error ``1e-2`` grid spacings, stopped
after repeated folds), the cartogram passes Heun pairs (:func:`rfmap.solvers.heun.heun_flow`, ``0.2`` spacings, the
cartogram flow's), each with its own first step.

The module uses numpy only.
"""
from __future__ import annotations

import math

import numpy as np

from .bs32 import BS32Options, bs32_flow
from .heun import HeunOptions, heun_flow

__all__ = ["SLOWEST_RATE", "INTEGRATORS", "Settling", "blur_start", "diffuse"]

#: The decay rate :math:`\pi^2` of the slowest cosine mode of the unit box.
SLOWEST_RATE = math.pi ** 2
#: The time integrators of :func:`diffuse`, by the type of their options.
INTEGRATORS = {BS32Options: bs32_flow, HeunOptions: heun_flow}


def blur_start(blur: float, n: int) -> float:
    r"""The time :math:`(\sigma h)^2/2` at which diffusion has blurred the density over ``blur`` (:math:`\sigma`)
    spacings of an ``n``-grid of the box (:math:`h = 1/(n-1)`)."""
    return 0.5 * (blur / (n - 1)) ** 2


class Settling:
    r"""The end of the flow: the velocity :math:`v` at the points has settled when the displacement still to come,
    about :math:`\max|v|/\pi^2`, is at most ``tol`` (box units).

    A callable ``(v) -> bool`` on velocities of shape (P, d); ``speed`` is :math:`\max|v|` of the last one asked
    (the residual velocity of a finished flow; ``inf`` before any).
    """

    def __init__(self, tol: float):
        self.threshold = tol * SLOWEST_RATE  # on max|v|
        self.speed = math.inf

    def __call__(self, v: np.ndarray) -> bool:
        self.speed = float(np.sqrt(np.einsum("ij,ij->i", v, v).max()))
        return not self.speed > self.threshold

    def remaining(self, t: float) -> float:
        """The time at which the flow is estimated to settle, from time ``t`` (the slowest mode decays as
        :math:`e^{-\\pi^2 t}`)."""
        return t + max(math.log(max(self.speed, self.threshold) / self.threshold), 0.0) / SLOWEST_RATE


def diffuse(field, y: np.ndarray, project, options, settling: Settling, turned_over=None,
            on_step=None) -> tuple[np.ndarray, dict]:
    r"""Carry points by the diffusion flow of ``field`` until it has settled.

    Parameters
    ----------
    field
        The heat field: ``field.velocity_at(t, points)`` is :math:`v = -\nabla\rho/\rho` at points (P, d).
    y : ndarray, shape (P, d)
        Starting points (in the field's box).
    project : callable
        Points back onto the box, in place.
    options : BS32Options or HeunOptions
        The integrator's options (tolerance, start time, first step, ...): the integrator is the one they belong
        to (:data:`INTEGRATORS`).
    settling : Settling
        When to stop; its ``speed`` is reported.
    turned_over : callable ``(y) -> bool``, optional
        Whether the mesh at ``y`` has an element turned over; steps that turn one over are rejected.
    on_step : callable ``(t) -> None``, optional
        Called after every accepted step.

    Returns
    -------
    y : ndarray, shape (P, d)
    info : dict
        The integrator's (``steps``, ``rejected``, ``fold_rejections``, ``t_end``, ...), ``evaluations`` (of the
        velocity) and ``residual_velocity`` (:math:`\max|v|` at the end).
    """
    evaluations = 0

    def velocity(t: float, p: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        evaluations += 1
        return field.velocity_at(t, p)

    y, info = INTEGRATORS[type(options)](velocity, y, project, options, turned_over, settled=settling,
                                         on_step=on_step)
    info.update(evaluations=evaluations, residual_velocity=settling.speed)
    return y, info
