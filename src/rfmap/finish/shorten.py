r"""Shortening a map towards the identity: the most equal fold-free map on the segment from the identity to a map.

Not a repair (a fold-free map may be shortened too): a returned density map is never less equal than no map at
all (:func:`shorten_map`).
"""
from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
import torch

from ..core.geometry import grid_element_mean
from ..core.metrics import density_std
from ..core.folds import map_measures, fold_free

__all__ = ["shorten_map", "SHORTEN_SAMPLES"]


#: Uniform samples of the scale in :func:`shorten_map` before the golden-section refinement around the best
SHORTEN_SAMPLES = 10


def shorten_map(ref: np.ndarray, mapped: np.ndarray, density: np.ndarray, n: int | None = None, *, boundary: str,
                elements: np.ndarray | None = None, samples: int = SHORTEN_SAMPLES,
                rounds: int = 12) -> tuple[np.ndarray, dict[str, Any]]:
    r"""The most equal fold-free map among the shortened maps :math:`u_s = x + s\,(u - x)`, :math:`0 \le s \le 1`.

    A density map that leaves the density less equal than it was (a field unlike a surrogate's training fields, or
    a repair that had to squeeze a region) is worse than no map at all: the identity (:math:`s = 0`) leaves
    :math:`\mathrm{Std}(\tilde\rho_{\text{map}}) = \mathrm{Std}(\tilde\rho_{\text{orig}})`.  Along the segment
    from the identity to the map, the objective

    .. math::

       J(s) = \begin{cases}
          \mathrm{Std}(\tilde\rho(u_s)) & \text{if } u_s \text{ is fold-free,} \\
          +\infty & \text{otherwise,}
       \end{cases}

    (fold-free as :func:`~rfmap.core.folds.fold_free` checks it: no element folded and, on a free boundary, the
    boundary embedded) is sampled at ``samples + 1`` equally spaced
    scales (both ends included) and refined by ``rounds`` golden-section steps between the neighbours of the best
    sample.  The returned map is never less equal than either end: it is at
    least as good as the input map when that is fold-free, and as the identity in any case.  Every :math:`u_s`
    keeps the boundary condition of :math:`u` (walls stay walls; the identity and the map both satisfy it and the
    condition is linear).

    Parameters
    ----------
    ref, mapped : ndarray, shape (P, d)
        The mesh's vertices and their images: the ``N``-grid (:func:`rfmap.core.mesh.grid_points` order, ``P = N**d``)
        with ``n``, or any simplicial mesh with ``elements``.
    density : ndarray, shape (P,)
        Vertex densities (the population of an element is its mean vertex density times its measure, as in
        :mod:`rfmap.core.metrics`).
    n : int, optional
        Grid side (the fast strided measures of the grid mesh).
    boundary : {"fixed", "square", "free"}
        Selects the embedding check of :func:`~rfmap.core.folds.fold_free` (free boundaries).
    elements : int ndarray, shape (m, d+1), optional
        The elements of a general mesh (e.g. the Delaunay mesh of query points); exactly one of ``n`` and
        ``elements`` is given.

    Returns
    -------
    points : ndarray, shape (P, d)
        The map :math:`u_s` at the chosen scale.
    report : dict
        ``scale`` (the chosen :math:`s`), ``std_before`` (of the input map; ``inf`` if folded),
        ``std_identity``, ``std_after``, ``evaluations``, ``time`` (s) and ``curve``, the evaluated
        ``[s, J(s)]`` pairs in increasing ``s``.
    """
    t0 = time.perf_counter()
    ref = np.asarray(ref, np.float64)
    disp = np.asarray(mapped, np.float64) - ref
    d = ref.shape[1]
    if (n is None) == (elements is None):
        raise ValueError("shorten_map needs exactly one of n (a grid mesh) and elements (a general mesh)")
    if ref.shape != disp.shape or (n is not None and ref.shape[0] != n ** d):
        want = f"the N-grid's {n ** d} points" if n is not None else "matching points"
        raise ValueError(f"shorten_map needs {want} and their images; got {ref.shape} and {disp.shape}")
    if samples < 1 or rounds < 0:
        raise ValueError(f"samples must be at least 1 and rounds non-negative, got {samples} and {rounds}")
    dens = torch.as_tensor(np.asarray(density, dtype=np.float64)).reshape(1, -1)
    if dens.shape[1] != ref.shape[0]:
        raise ValueError(f"density has {dens.shape[1]} values for {ref.shape[0]} vertices")
    if n is not None:  # equal reference measures: the element means are the populations up to a common factor
        pop = grid_element_mean(dens, n, d)[0]
    else:
        el = np.asarray(elements)
        pop = dens[0, torch.as_tensor(el)].mean(-1) * torch.as_tensor(map_measures(ref, el, None))
    cache: dict[float, float] = {}

    def J(s: float) -> float:
        if s not in cache:
            pts = ref + s * disp
            ok = s == 0.0 or fold_free(pts, elements, grid_n=n, boundary=boundary)
            meas = torch.as_tensor(map_measures(pts, elements, n))
            cache[s] = density_std(pop, meas) if ok else math.inf
        return cache[s]

    grid = [k / samples for k in range(samples + 1)]
    vals = [J(s) for s in grid]
    k = int(np.argmin(vals))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, samples)]
    g = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = hi - g * (hi - lo), lo + g * (hi - lo)
    for _ in range(rounds):
        if J(a) <= J(b):
            hi, b = b, a
            a = hi - g * (hi - lo)
        else:
            lo, a = a, b
            b = lo + g * (hi - lo)
    best = min(cache, key=lambda s: (cache[s], -s))
    report = {"scale": float(best), "std_before": cache[1.0], "std_identity": cache[0.0], "std_after": cache[best],
              "evaluations": len(cache), "time": time.perf_counter() - t0,
              "curve": [[float(k), cache[k]] for k in sorted(cache)]}
    return (np.asarray(mapped) if best == 1.0 else ref + best * disp), report
