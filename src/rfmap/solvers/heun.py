r"""The predictor--corrector (Heun) time integration shared by the flow-based solvers and the cartogram diffusion.

The classical density-equalizing solvers carry points by a velocity field, :math:`\dot y = v(t, y)`, and all of
them but the diffusion map of :mod:`rfmap.solvers.diffusion` step it the same way (:func:`heun_flow`): the map
solver's passes (:mod:`rfmap.solvers.flow`), the cartogram flow (:mod:`rfmap.solvers.cartoflow`) and the
cartogram diffusion (:mod:`rfmap.solvers.cartodiffusion`, until its velocity has settled).

* A step is a predictor--corrector pair (:func:`heun_step`),
  :math:`y^* = y + \Delta t\,v(t, y)`, :math:`y' = y + \tfrac{\Delta t}{2}(v(t, y) + v(t + \Delta t, y^*))`,
  accepted when :math:`\max|y' - y^*|` is within the tolerance and, where the points are a mesh's vertices, no
  element has turned over.
* The next step follows the usual rule of an embedded first/second-order pair (:func:`step_factor`).
* A flow whose step falls below :data:`STALL_DT` has stalled (:class:`Stalled`: a collapsing element); the flow
  solvers then redo the pass with the density blurred over :data:`STALL_BLURS` vertex spacings.

The module uses numpy only, so that the torch-free cartogram passes can step with it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["HeunOptions", "heun_flow", "heun_step", "step_factor", "Stalled", "STALL_DT", "STALL_BLURS"]

#: A pass stalls when the step falls below this (in units of the unit time interval).
STALL_DT = 1e-9
#: Blur widths (vertex spacings) with which the flow solvers (:mod:`rfmap.solvers.flow`,
#: :mod:`rfmap.solvers.cartoflow`) redo a stalled pass.
STALL_BLURS = (1.0, 2.0, 4.0)


class Stalled(RuntimeError):
    """A flow cannot advance: every step, however short, turns an element over (a collapsing element)."""


def heun_step(vel, t: float, dt: float, y: np.ndarray, k1: np.ndarray, project, tol: float,
              turned_over=None) -> tuple[np.ndarray, float, bool]:
    r"""One predictor--corrector (Heun) step of :math:`\dot y = v(t, y)` from ``y`` with ``k1 = v(t, y)``.

    :math:`y^* = y + \Delta t\,k_1`, :math:`y' = y + \tfrac{\Delta t}{2}(k_1 + v(t + \Delta t, y^*))`, both projected
    back onto the box by ``project``.

    Returns
    -------
    y_new : ndarray
    err : float
        The largest predictor--corrector difference :math:`\max|y' - y^*|` over ``tol``; the step is accepted when it
        is at most 1.
    folded : bool
        Whether ``turned_over(y_new)`` (a mesh element turned over; only asked of a step within the tolerance, and
        never without a ``turned_over``).
    """
    y_pred = project(y + dt * k1)
    k2 = vel(t + dt, y_pred)
    y_new = project(y + (0.5 * dt) * (k1 + k2))
    diff = y_new - y_pred
    err = math.sqrt(float(np.einsum("ij,ij->i", diff, diff).max())) / tol
    folded = turned_over is not None and err <= 1.0 and bool(turned_over(y_new))
    return y_new, err, folded


def step_factor(err: float, accepted: bool, folded: bool, floor: float = 0.3) -> float:
    """The factor of the next step after a :func:`heun_step` of error ``err``: at most twice as long after an
    accepted step, shorter after a rejected one (half after a fold, at least ``floor`` times otherwise)."""
    if accepted:
        return min(2.0, max(0.3, 0.9 / math.sqrt(max(err, 1e-12))))
    return 0.5 if folded else max(floor, 0.9 / math.sqrt(err))


@dataclass(frozen=True)
class HeunOptions:
    """How :func:`heun_flow` steps.

    Attributes
    ----------
    tol : float
        Largest predictor--corrector difference of an accepted step (``rtol`` grid spacings, in box units).
    t0 : float
        The start time (0 by default, the start of the flow-based map's unit interval).
    t_end : float
        The end time (1 by default).
    first_step : float
        The first step.
    max_steps : int
        Most (accepted + rejected) steps; ``RuntimeError`` beyond.
    floor : float
        Smallest factor by which a rejected step (not folded) shrinks the next.
    stall_dt : float
        The step below which the flow has stalled (:data:`STALL_DT`; 0: never).
    """

    tol: float
    t0: float = 0.0
    t_end: float = 1.0
    first_step: float = 1.0
    max_steps: int = 10_000
    floor: float = 0.3
    stall_dt: float = STALL_DT


def heun_flow(vel, y: np.ndarray, project, options: HeunOptions, turned_over=None, *, settled=None,
              on_step=None) -> tuple[np.ndarray, dict]:
    r"""Heun steps (:func:`heun_step`) of :math:`\dot y = v(t, y)` from :math:`t_0` to :math:`t_{end}`: the time
    integration shared by the flow-based map (from 0 to 1: the cartogram pass
    :func:`rfmap.solvers.cartoflow.flow_square` and the map solver :func:`rfmap.solvers.solve_flow`) and the
    cartogram's diffusion map (:func:`rfmap.solvers.cartodiffusion.diffusion_square`, until the velocity has
    ``settled``).

    A step is accepted when its error is at most 1 and no element turned over; the next step follows
    :func:`step_factor` (rejections shrink it by at least ``options.floor``).

    Parameters
    ----------
    vel : callable ``(t, y) -> ndarray``, shape (P, d)
    y : ndarray, shape (P, d)
        Starting points.
    project : callable
        Points back onto the box, in place.
    options : HeunOptions
        Tolerance, time span, first step, step budget, rejection floor and stall threshold.
    turned_over : callable ``(y) -> bool``, optional
        Whether the mesh at ``y`` has an element turned over (none checked without it).
    settled : callable ``(v) -> bool``, optional
        Stop before :math:`t_{end}` once the velocity at the points (P, d) says so.
    on_step : callable ``(t) -> None``, optional
        Called after every accepted step (a progress bar).

    Returns
    -------
    y : ndarray, shape (P, d)
        The points at the end.
    info : dict
        ``steps``, ``rejected``, ``fold_rejections``, ``t_end`` (the time reached).

    Raises
    ------
    Stalled
        When the step falls below ``options.stall_dt`` (a collapsing element).
    RuntimeError
        When ``options.max_steps`` run out.
    """
    o = options
    t, t_end, dt = o.t0, o.t_end, o.first_step
    accepted = rejected = folds = 0
    k1 = vel(t, y)
    while t < t_end:
        if settled is not None and settled(k1):
            break
        if accepted + rejected >= o.max_steps:
            raise RuntimeError(f"the flow did not reach t = {t_end:g} in {o.max_steps} steps (t={t:.4g}); "
                               "increase max_steps or rtol")
        dt = min(dt, t_end - t)
        if dt < o.stall_dt:
            raise Stalled(f"flow step fell below {o.stall_dt:g} at t = {t:.4g} (a collapsing element)")
        y_new, err, folded = heun_step(vel, t, dt, y, k1, project, o.tol, turned_over)
        if err <= 1.0 and not folded:
            t = t_end if t_end - (t + dt) < 1e-12 else t + dt
            y = y_new
            accepted += 1
            if t < t_end:
                k1 = vel(t, y)
            if on_step is not None:
                on_step(t)
        else:
            rejected += 1
            folds += int(folded)
        dt *= step_factor(err, err <= 1.0 and not folded, folded, o.floor)
    return y, {"steps": accepted, "rejected": rejected, "fold_rejections": folds, "t_end": t}
