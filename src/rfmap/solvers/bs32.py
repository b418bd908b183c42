r"""The embedded Bogacki--Shampine 3(2) time integration of the diffusion map solver.

:func:`bs32_flow` carries points by :math:`\dot y = v(t, y)` with the Bogacki--Shampine pair (the last stage
of a step is the first of the next, so a step takes three velocity evaluations), the local error of a step estimated by
the difference of its third- and second-order solutions.  It has the signature of
:func:`rfmap.solvers.heun.heun_flow`, so that the diffusion flow (:func:`rfmap.solvers.heatflow.diffuse`) takes
either as its integrator: this one for the maps of :mod:`rfmap.solvers.diffusion`, the Heun pairs for the
cartogram passes of :mod:`rfmap.solvers.cartodiffusion`.

* A step is accepted when its error is at most ``tol`` and, where the points are a mesh's vertices, no element has
  turned over; a step that folds is retried with half the step, and after ``fold_stop`` such rejections the
  integration stops at its last accepted (fold-free) state.
* The next step is :math:`0.9\,\mathrm{err}^{-1/3}` times the last, between 0.2 and 5 times.

numpy only.

References
----------
P\. Bogacki, L. F. Shampine, "A 3(2) pair of Runge--Kutta formulas", Appl. Math. Lett. 2(4), 321--325 (1989).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["BS32Options", "bs32_flow"]

#: the tableau: stage times, weights of the third-order solution, and the third- minus the embedded second-order
#: solution's weights (the last for the FSAL stage)
_C = (0.5, 0.75)
_B = (2.0 / 9.0, 1.0 / 3.0, 4.0 / 9.0)
_E = (-5.0 / 72.0, 1.0 / 12.0, 1.0 / 9.0, -1.0 / 8.0)


@dataclass(frozen=True)
class BS32Options:
    """How :func:`bs32_flow` steps.

    Attributes
    ----------
    tol : float
        Largest local error estimate of an accepted step (box units; the largest over the points of its Euclidean
        norm).
    first_step : float
        The first step.
    t0 : float
        The start time (0 by default).
    t_end : float
        The end time; by default none (infinity): the flow runs until it has ``settled``.
    max_steps : int
        Most (accepted + rejected) steps; ``RuntimeError`` beyond.
    fold_stop : int, optional
        Fold rejections after which the integration stops at its last fold-free state (never without it).
    """

    tol: float
    first_step: float
    t0: float = 0.0
    t_end: float = math.inf
    max_steps: int = 10_000
    fold_stop: int | None = None


def _max_norm(v: np.ndarray) -> float:
    return float(np.sqrt(np.einsum("ij,ij->i", v, v).max()))


def bs32_flow(vel, y: np.ndarray, project, options: BS32Options, turned_over=None, *, settled=None,
              on_step=None) -> tuple[np.ndarray, dict]:
    r"""Bogacki--Shampine 3(2) steps of :math:`\dot y = v(t, y)` from :math:`t_0` until the velocity has
    ``settled`` (or :math:`t_{end}`).

    Parameters
    ----------
    vel : callable ``(t, y) -> ndarray``, shape (P, d)
    y : ndarray, shape (P, d)
        Starting points.
    project : callable
        Points back onto the box, in place.
    options : BS32Options
    turned_over : callable ``(y) -> bool``, optional
        Whether the mesh at ``y`` has an element turned over (none checked without it).
    settled : callable ``(v) -> bool``, optional
        Stop once the velocity at the points (P, d) says so; asked at the start and after every accepted step,
        before ``on_step``.
    on_step : callable ``(t) -> None``, optional
        Called after every accepted step (a progress bar).

    Returns
    -------
    y : ndarray, shape (P, d)
    info : dict
        ``steps``, ``rejected``, ``fold_rejections``, ``t_end`` (the time reached) and ``fold_stop`` (the time at
        which ``options.fold_stop`` fold rejections stopped the flow, else ``None``).

    Raises
    ------
    RuntimeError
        When ``options.max_steps`` run out.
    """
    o = options
    t, dt = o.t0, o.first_step
    accepted = rejected = folds = 0
    fold_stop = None
    k1 = vel(t, y)
    done = settled is not None and settled(k1)
    while not done and t < o.t_end:
        if accepted + rejected >= o.max_steps:
            raise RuntimeError(f"the flow did not settle in {o.max_steps} steps (t={t:.4g}); increase max_steps or "
                               "rtol")
        dt = min(dt, o.t_end - t)
        k2 = vel(t + _C[0] * dt, project(y + (_C[0] * dt) * k1))
        k3 = vel(t + _C[1] * dt, project(y + (_C[1] * dt) * k2))
        y_new = project(y + dt * (_B[0] * k1 + _B[1] * k2 + _B[2] * k3))
        k4 = vel(t + dt, y_new)  # FSAL: the first stage of the next step
        err = _max_norm(dt * (_E[0] * k1 + _E[1] * k2 + _E[2] * k3 + _E[3] * k4)) / o.tol
        if err <= 1.0 and turned_over is not None and turned_over(y_new):
            rejected += 1
            folds += 1
            if o.fold_stop is not None and folds >= o.fold_stop:  # it folds however short the step: stop here
                fold_stop = t
                break
            dt *= 0.5
            continue
        if err <= 1.0:
            t += dt
            y, k1 = y_new, k4
            accepted += 1
            done = settled is not None and settled(k1)
            if on_step is not None:
                on_step(t)
        else:
            rejected += 1
        dt *= min(5.0, max(0.2, 0.9 * max(err, 1e-12) ** (-1.0 / 3.0)))
    return y, {"steps": accepted, "rejected": rejected, "fold_rejections": folds, "t_end": t, "fold_stop": fold_stop}
