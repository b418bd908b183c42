r"""Repair of 2D grid maps by μ-truncation and the Linear Beltrami Solver on the whole grid.

The Beltrami coefficient of the current map is computed per triangle (paper Eq. (1)); a flipped triangle has
:math:`|\mu| > 1`.  Every coefficient is truncated (:func:`cap_mu`): radially where the triangle keeps its
orientation, to zero where it is flipped or the coefficient is not finite,

.. math::

   \mu \leftarrow \begin{cases} \mu \, \min\Bigl(1, \dfrac{1 - \delta}{|\mu|}\Bigr), & |\mu| < 1, \\
   0, & |\mu| \ge 1 \text{ or } \mu \text{ not finite}, \end{cases} \qquad \delta = 0.1,

and the map is rebuilt from the truncated :math:`\mu` by :func:`rfmap.solvers.solve_lbs` with the model's boundary
condition: the identity on the boundary (``fixed``), or the boundary vertices held where the network put them
(``square``, whose map keeps them on their walls, and ``free``), after moving crossing boundary vertices back towards
the square until the boundary polygon is simple (:func:`untangle_boundary`).  On the square the vertices slide along
the walls only as a fallback: when a vertex has passed its neighbour along a wall, so that holding them would fold
the boundary back on itself.  Where the map was not folded and
:math:`|\mu| \le 1 - \delta` the coefficient is unchanged, and the LBS reproduces a piecewise-linear map from its
own coefficient, so the rebuilt map stays close to the input.  The discrete LBS has no bijectivity theorem (its
stiffness weights may be negative), so its output is checked and, if still folded, handed to the displacement
scaling (:mod:`rfmap.finish.repair.scale`).

References
----------
G. P. T. Choi, C. H. Rycroft, "Density-equalizing maps for simply connected open surfaces", SIAM J. Imaging Sci.
11(2), 1134–1178 (2018) (μ-truncation and LBS reconstruction to keep density-equalizing maps bijective).
"""
from __future__ import annotations

import numpy as np
import torch

from ...core.folds import map_measures
from ...core.geometry import beltrami_coefficient
from ...core.mesh import grid_mesh
from ...core.surface import boundary_crossings, boundary_loop
from ...solvers.lbs import solve_lbs

__all__ = ["DELTA", "cap_mu", "untangle_boundary", "lbs_repair"]


#: Margin of the μ-truncation: the *truncated coefficient* that the LBS is given satisfies
#: :math:`|\mu| \le 1 - \delta`.  The map rebuilt from it is only checked to be fold-free
#: (:math:`|\mu| < 1` on every triangle); its own :math:`|\mu|` may exceed :math:`1 - \delta`.
DELTA = 0.1


def cap_mu(mu: np.ndarray, delta: float = DELTA) -> tuple[np.ndarray, np.ndarray]:
    r"""Truncate a Beltrami coefficient into the disk :math:`|\mu| \le 1 - \delta`.

    Orientation-preserving triangles with :math:`1 - \delta < |\mu| < 1` are truncated radially,
    :math:`\mu \leftarrow \mu\,(1-\delta)/|\mu|`; flipped triangles (:math:`|\mu| \ge 1`, where :math:`\mu` no
    longer describes a distortion of the triangle) and non-finite values get :math:`\mu = 0`.  (Truncating a flipped
    triangle radially to :math:`1 - \delta`, or reflecting it to :math:`1/\bar\mu`, leaves most single-vertex folds
    in place after the LBS solve; :math:`\mu = 0` removes them.)

    Returns
    -------
    capped : complex ndarray, shape (m,)
        The truncated coefficient.
    mask : bool ndarray, shape (m,)
        The entries that changed.
    """
    mu = np.asarray(mu, dtype=np.complex128)
    bad = ~np.isfinite(mu)
    a = np.abs(np.where(bad, 0, mu))
    over = a > 1 - delta
    out = np.where(over, mu * ((1 - delta) / np.maximum(a, 1e-300)), mu)
    out[bad | (a >= 1)] = 0
    return out, over | bad


def untangle_boundary(ref_b: np.ndarray, mapped_b: np.ndarray, *, max_rounds: int = 30) -> np.ndarray:
    r"""Move boundary vertices towards their reference positions until the boundary polygon is simple.

    The polygon :math:`q_v = x_v + t_v (p_v - x_v)` starts at :math:`t = 1`; the endpoints of every crossing edge
    get :math:`t_v \leftarrow t_v / 2`, round after round.  If crossings remain after ``max_rounds``, a uniform
    :math:`t` is halved instead; :math:`t = 0` is the square itself, which is simple.

    Parameters
    ----------
    ref_b, mapped_b : ndarray, shape (k, 2), in boundary order (:func:`~rfmap.core.surface.boundary_loop`)
    """
    ref_b, mapped_b = np.asarray(ref_b, np.float64), np.asarray(mapped_b, np.float64)
    t = np.ones(len(ref_b))
    for _ in range(max_rounds):
        q = ref_b + t[:, None] * (mapped_b - ref_b)
        c = boundary_crossings(q)
        if len(c) == 0:
            return q
        v = np.unique(np.concatenate([c.ravel(), (c.ravel() + 1) % len(q)]))
        t[v] *= 0.5
    s = 1.0
    while s > 1e-6:
        s *= 0.5
        q = ref_b + s * t[:, None] * (mapped_b - ref_b)
        if len(boundary_crossings(q)) == 0:
            return q
    return ref_b.copy()


def lbs_repair(mapped: np.ndarray, n: int, boundary: str, delta: float = DELTA,
               passes: int = 3) -> tuple[np.ndarray, np.ndarray]:
    r"""Rebuild a 2D grid map from its truncated Beltrami coefficient with the Linear Beltrami Solver.

    Up to ``passes`` times: :math:`\mu` of the current map, :func:`cap_mu`, LBS; stops as soon as no triangle is
    flipped.

    Parameters
    ----------
    mapped : ndarray, shape (N**2, 2)
        The map on :func:`rfmap.core.mesh.grid_mesh` ``(N, 2)``.
    boundary : {"fixed", "square", "free"}
        ``fixed``: identity on the boundary; ``square`` and ``free``: Dirichlet values at the boundary positions of
        ``mapped``, untangled by :func:`untangle_boundary`.  On the square the vertices stay on their walls, as
        ``mapped`` keeps them there and the untangling only shortens displacements; if a vertex has passed its
        neighbour along a wall, the walls slide instead (:func:`rfmap.solvers.solve_lbs`, ``boundary="square"``).
        Keeping the map's own boundary needs one factorisation for both components, where sliding walls need one
        per component.

    Returns
    -------
    points : ndarray, shape (N**2, 2)
        The rebuilt map.
    capped : bool ndarray, shape (m,)
        The triangles whose :math:`\mu` was truncated.
    """
    mesh = grid_mesh(n, 2)
    ref_t, el_t = torch.as_tensor(mesh.points), torch.as_tensor(mesh.elements)
    bv = None
    if boundary in ("free", "square"):
        loop = boundary_loop(n)
        bv = mesh.points.copy()
        bv[loop] = untangle_boundary(mesh.points[loop], mapped[loop])
        if boundary == "square":
            # on the walls, every boundary edge must keep its direction (a vertex that passed its neighbour along a
            # wall folds back on a straight line, which no crossing test sees); otherwise the walls slide
            q, x = bv[loop], mesh.points[loop]
            if (((np.roll(q, -1, 0) - q) * (np.roll(x, -1, 0) - x)).sum(1) <= 0).any():
                bv = None
    capped = np.zeros(len(mesh.elements), bool)
    out = np.asarray(mapped, np.float64)
    for _ in range(passes):
        mu = beltrami_coefficient(ref_t, torch.as_tensor(out), el_t).numpy()
        mu_c, mask = cap_mu(mu, delta)
        capped |= mask
        if bv is None:
            out = solve_lbs(mu_c, n, boundary=boundary).mapped_points
        else:
            out = solve_lbs(mu_c, n, boundary="fixed", boundary_values=bv).mapped_points
        if map_measures(out, mesh.elements, n).min() > 0:
            break
    return out, capped
