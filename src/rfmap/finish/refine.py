r"""Weight refinement (paper Sec. 4.3): a stretching vector :math:`\alpha \in \mathbb{R}^d` applied to the output.

The refined map is :math:`u_\alpha = x + \mathcal{B}(x) \odot (\alpha \odot \psi(x))`, which keeps the boundary
condition for every :math:`\alpha`.  Here :math:`\psi` is the network's displacement (the paper's :math:`\psi` of
Sec. 4.2, which its Sec. 4.3 writes :math:`\phi`; this book keeps :math:`\phi` for the potential of the flow-based
solver), :math:`\mathcal{B}` the boundary mask and :math:`\odot` the product component by component.
:math:`\alpha^* = \arg\min_\alpha \mathcal{J}(u_\alpha)` with
:math:`\mathcal{J} = \mathcal{L}_{\text{geom}} + \lambda \mathcal{P}` is found by derivative-free alternating
golden-section searches, first of a common (isotropic) stretch, then over the components; the result never has a
larger :math:`\mathcal{J}` than :math:`\alpha = (1, \dots, 1)`.  Folded maps can make :math:`\mathcal{J}` jagged, so
the isotropic search is checked by a coarse geometric scan of :data:`SCAN_POINTS` stretches: where a scanned point
beats the search's result, the search is repeated around it (and the per-component searches are then checked the same
way).  The paper allows alternating one-dimensional or golden-section searches; the isotropic search first and the
scan that checks it are this package's choices.  Each task builds its :math:`\mathcal{J}`
(``Task.refine_objective``, from :mod:`rfmap.tasks.objectives`, whose :data:`~rfmap.tasks.objectives.FLIP_WEIGHT`
is :math:`\lambda`); :class:`RefineConfig` holds the search interval and the tolerance, :data:`REFINE` those that
:meth:`rfmap.Surrogate.map` uses and :func:`refine_alpha`'s defaults.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

__all__ = ["golden_section", "refine_alpha", "RefineResult", "RefineConfig", "REFINE", "SCAN_POINTS"]


@dataclass(frozen=True)
class RefineConfig:
    r"""Settings of weight refinement.

    Attributes
    ----------
    bounds : (float, float)
        Search interval of every component of :math:`\alpha`.
    tol : float
        Interval length at which each golden-section search stops.
    """

    bounds: tuple[float, float] = (0.1, 3.0)
    tol: float = 1e-2


#: The refinement settings of :meth:`rfmap.Surrogate.map`, and the defaults of :func:`refine_alpha`.
REFINE = RefineConfig()

_INV_PHI = (math.sqrt(5) - 1) / 2


def golden_section(f: Callable[[float], float], a: float, b: float, *, tol: float = 1e-3,
                   max_iter: int = 60) -> tuple[float, float]:
    """Minimise a scalar function on ``[a, b]`` by golden-section search; returns ``(x, f(x))`` of the best
    point evaluated (so it also behaves sensibly on non-unimodal functions)."""
    if not a < b:
        raise ValueError(f"golden_section needs a < b, got [{a}, {b}]")
    c, d = b - _INV_PHI * (b - a), a + _INV_PHI * (b - a)
    fc, fd = f(c), f(d)
    best = min((fc, c), (fd, d))
    for _ in range(max_iter):
        if b - a < tol:
            break
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - _INV_PHI * (b - a)
            fc = f(c)
            best = min(best, (fc, c))
        else:
            a, c, fc = c, d, fd
            d = a + _INV_PHI * (b - a)
            fd = f(d)
            best = min(best, (fd, d))
    return best[1], best[0]


@dataclass
class RefineResult:
    """Outcome of :func:`refine_alpha`: the stretching vector, its objective, the objective at
    :math:`\\alpha = 1`, and the number of evaluations."""

    alpha: np.ndarray
    objective: float
    objective_start: float
    evaluations: int = 0
    history: list = field(default_factory=list)


def refine_alpha(objective: Callable[[np.ndarray], float], dim: int, *, bounds: tuple[float, float] = REFINE.bounds,
                 sweeps: int = 2, tol: float = REFINE.tol) -> RefineResult:
    r"""Alternating golden-section search for :math:`\alpha^* = \arg\min \mathcal{J}(\alpha)` over
    :math:`\alpha \in [\text{lo}, \text{hi}]^d`.

    Parameters
    ----------
    objective : callable
        :math:`\mathcal{J}(\alpha)` for ``alpha`` of shape (d,); may return ``inf`` for inadmissible maps.
    dim : int
    bounds : (float, float)
        Search interval of every component (default ``REFINE.bounds``).
    sweeps : int
        Passes over the components.
    tol : float
        Interval length at which each golden-section search stops (default ``REFINE.tol``).
    """
    count = 0

    def J(a):
        nonlocal count
        count += 1
        v = float(objective(np.asarray(a, dtype=np.float64)))
        return v if math.isfinite(v) else math.inf

    alpha = np.ones(dim)
    j0 = J(alpha)
    best, history = j0, [(alpha.copy(), j0)]
    # first a common (isotropic) stretch, then alternating per-component searches
    s, js = golden_section(lambda t: J(np.full(dim, t)), *bounds, tol=tol)
    s_scan, js_scan = _rescan(lambda t: J(np.full(dim, t)), bounds, tol, s, js)
    jagged = js_scan < js  # the scan found what the search missed: guard the per-component searches too
    s, js = s_scan, js_scan
    if js < best:
        alpha, best = np.full(dim, s), js
        history.append((alpha.copy(), best))
    for _ in range(sweeps):
        for i in range(dim):
            def along(t, i=i):
                a = alpha.copy()
                a[i] = t
                return J(a)

            t, jt = golden_section(along, *bounds, tol=tol)
            if jagged:
                t, jt = _rescan(along, bounds, tol, t, jt)
            if jt < best:
                alpha[i], best = t, jt
                history.append((alpha.copy(), best))
    return RefineResult(alpha=alpha, objective=best, objective_start=j0, evaluations=count, history=history)


#: Points of the coarse geometric scan of the isotropic stretch that guards the golden-section search
#: (:doc:`Design decisions </book/design>`).
SCAN_POINTS = 9


def _rescan(f: Callable[[float], float], bounds: tuple[float, float], tol: float, s: float,
            js: float) -> tuple[float, float]:
    r"""Guard a golden-section result ``(s, js)`` against a non-unimodal objective: scan ``f`` at
    :data:`SCAN_POINTS` geometrically spaced points of ``bounds`` and, where one beats ``js``, search again between
    its neighbours.  (Folded maps make :math:`\mathcal{J}` jagged: when the map at :math:`\alpha = 1` overshoots
    and folds, both first probes can land among folded maps and the search then never reaches the fold-free
    minimum below 1.)  Returns ``(s, js)`` unchanged when no scanned point is better."""
    ts = np.geomspace(bounds[0], bounds[1], SCAN_POINTS)
    vals = [f(float(t)) for t in ts]
    k = int(np.argmin(vals))
    if not vals[k] < js:
        return s, js
    t, jt = golden_section(f, float(ts[max(k - 1, 0)]), float(ts[min(k + 1, len(ts) - 1)]), tol=tol)
    return (t, jt) if jt < vals[k] else (float(ts[k]), vals[k])
