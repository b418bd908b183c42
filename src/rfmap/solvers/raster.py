r"""The density raster of the solvers' box: the checked input, its P1 interpolant on a finer grid, and the free
boundary's balanced sea.

Both classical density-equalizing solvers start from the piecewise-linear (P1) interpolant of the vertex densities
on the simplicial mesh of :func:`rfmap.core.mesh.grid_mesh` (the density whose element integrals :mod:`rfmap.core.metrics`
uses), sampled ``refine`` times finer (:func:`p1_upsample`); a free boundary embeds the domain in a box filled with
a sea whose level keeps the domain's measure (:func:`balanced_sea`).
"""
from __future__ import annotations

import itertools

import numpy as np

from ..core.inputs import check_density, is_uniform
from ..core.mesh import check_n
from ..core.wording import counted
from .spectral import contract, interval_weights

__all__ = ["DEM_BOUNDARIES", "check_grid_density", "p1_upsample", "balanced_sea"]


#: Boundary conditions understood by the density solvers (:func:`rfmap.solvers.solve_dem`, either method).
DEM_BOUNDARIES = ("square", "free")


def check_grid_density(density) -> np.ndarray:
    """The density as a float64 (N,)*d grid (``ValueError`` unless finite, of ``d`` in {2, 3}, ``N >= 3``, and
    strictly positive); a constant grid of any value, zero or negative included, is read as the uniform density
    (ones where it is not positive), as the paper's preprocessing would make it
    (:func:`rfmap.core.inputs.is_uniform`)."""
    arr = np.asarray(density)
    if arr.ndim not in (2, 3):
        raise ValueError(f"density must be a grid field of shape (N, N) or (N, N, N); got {counted(arr.ndim, 'dimension')}, "
                         f"shape {arr.shape}")
    if len(set(arr.shape)) != 1:
        raise ValueError(f"density must have the same number of vertices per side, got shape {arr.shape}")
    check_n(arr.shape[0], 3)
    v = check_density(arr, positive=False)
    if is_uniform(v) and v.flat[0] <= 0:
        return np.ones_like(v)
    return check_density(v)


def p1_upsample(values: np.ndarray, refine: int) -> np.ndarray:
    r"""Sample the piecewise-linear interpolant of grid vertex values on a ``refine`` times finer grid.

    The interpolant is linear on every element of :func:`rfmap.core.mesh.grid_mesh` (P1), i.e. exactly the density whose
    element integrals :mod:`rfmap.core.metrics` uses (mean vertex value times measure).  In 2D the square with local
    coordinates :math:`(s, t)` is split by :math:`s + t = 1`; in 3D the Kuhn split gives the barycentric weights
    :math:`(1-c_1, c_1-c_2, c_2-c_3, c_3)` of the sorted local coordinates :math:`c_1 \ge c_2 \ge c_3` along the
    path :math:`v_{000} \to v_{000}+e_{\sigma_1} \to \dots \to v_{111}`.

    Parameters
    ----------
    values : ndarray, shape (N,)*d
    refine : int
        Refinement factor ``r``; the fine grid has ``M = r (N-1) + 1`` points per side.

    Returns
    -------
    ndarray, shape (M,)*d
        Equals ``values`` on the coarse nodes (``fine[::r, ::r] == values``).
    """
    if refine == 1:
        return values.copy()
    d, n = values.ndim, values.shape[0]
    r = int(refine)
    m = r * (n - 1) + 1
    # pad one layer so that offset 0 of the (virtual) cell n-1 gives the last fine layer
    padded = np.pad(values, [(0, 1)] * d, mode="edge")
    fine = np.empty((r * n,) * d)
    corners = list(itertools.product((0, 1), repeat=d))
    for offset in itertools.product(range(r), repeat=d):
        weights = _p1_corner_weights(np.array(offset) / r)
        acc = np.zeros((n,) * d)
        for corner, w in zip(corners, weights):
            if w != 0.0:
                acc += w * padded[tuple(slice(c, c + n) for c in corner)]
        fine[tuple(slice(o, None, r) for o in offset)] = acc
    return fine[(slice(0, m),) * d]


def _p1_corner_weights(loc: np.ndarray) -> list[float]:
    """Weights of the 2**d cell corners (in ``itertools.product((0, 1), repeat=d)`` order) of the P1 interpolant
    at local coordinates ``loc`` in the cell, for the element splits of :func:`rfmap.core.mesh.grid_mesh`."""
    d = loc.size
    w = {}
    if d == 2:
        s_, t_ = float(loc[0]), float(loc[1])
        if s_ + t_ <= 1.0:  # triangle (x, y), (x+h, y), (x, y+h)
            w = {(0, 0): 1.0 - s_ - t_, (1, 0): s_, (0, 1): t_}
        else:  # triangle (x+h, y), (x+h, y+h), (x, y+h)
            w = {(1, 1): s_ + t_ - 1.0, (0, 1): 1.0 - s_, (1, 0): 1.0 - t_}
    else:  # Kuhn simplex along the axes sorted by decreasing local coordinate
        order = np.argsort(-loc, kind="stable")
        c = loc[order]
        bary = [1.0 - c[0], c[0] - c[1], c[1] - c[2], c[2]]
        vertex = [0] * d
        w[tuple(vertex)] = bary[0]
        for k in range(d):
            vertex[order[k]] = 1
            w[tuple(vertex)] = w.get(tuple(vertex), 0.0) + bary[k + 1]
    return [w.get(c, 0.0) for c in itertools.product((0, 1), repeat=d)]


def balanced_sea(dens: np.ndarray, pad: int, refine: int, blend: float = 0.0) -> tuple[np.ndarray, float]:
    r"""Fine-grid initial density of the free-boundary box and its sea level :math:`s`.

    At :math:`t\to\infty` the density is uniform, equal to the box mean :math:`a_0`, and the mapped domain has area
    :math:`m_{\Omega} / a_0` where :math:`m_\Omega` is the mass of the initial (cosine-interpolated) density on the
    unit square/cube.  With the P1 density :math:`p = p_A + s\,p_B` (``p_A``: the domain's values with a zero sea,
    ``p_B``: the P1 interpolant of the sea indicator), both are affine in :math:`s`, and
    :math:`m_\Omega(s) = a_0(s)\,|\Omega|` is solved exactly.  A plain mean-density sea is off by :math:`O(h)`
    because the cells just outside the coast carry part of the coastal density.

    With ``blend`` :math:`= L > 0` the sea does not jump to :math:`s` at the coast: at a distance :math:`r` from the
    domain it holds :math:`w\,p_{\text{edge}} + (1 - w)\,s`, with :math:`p_{\text{edge}}` the density of the
    nearest coast vertex and :math:`w = \operatorname{smoothstep}(1 - r/L)`; ``p_A`` is then :math:`w\,p_{\text{edge}}`
    (1 inside the domain) and ``p_B`` the interpolant of :math:`1 - w`, and :math:`s` is balanced as before.

    Parameters
    ----------
    dens : ndarray, shape (N,)*d
        Vertex densities of the domain.
    pad : int
        Sea width in vertex spacings on every side (``N_box = N + 2 pad``).
    refine : int
        Raster refinement (``M = refine (N_box - 1) + 1``).
    blend : float
        :math:`L` in the domain's length units (0: the sea starts at the coast).

    Returns
    -------
    fine : ndarray, shape (M,)*d
        P1-upsampled initial density on the box, ``M = refine (N_box - 1) + 1``.
    sea : float
    """
    d, n = dens.ndim, dens.shape[0]
    nb = n + 2 * pad
    inner = (slice(pad, pad + n),) * d
    if blend > 0:
        outside = np.maximum(pad - np.arange(nb), np.arange(nb) - (pad + n - 1)).clip(0) / (n - 1)
        r2 = np.zeros((nb,) * d)
        for ax in range(d):
            r2 += (outside**2).reshape([nb if j == ax else 1 for j in range(d)])
        w = np.clip(1.0 - np.sqrt(r2) / blend, 0.0, 1.0)
        w = w * w * (3.0 - 2.0 * w)  # smoothstep: w and its slope are continuous at r = 0 and r = L
        vals, ind = np.pad(dens, pad, mode="edge") * w, 1.0 - w
    else:
        vals = np.zeros((nb,) * d)
        vals[inner] = dens
        ind = np.ones((nb,) * d)
        ind[inner] = 0.0
    fine_a, fine_b = p1_upsample(vals, refine), p1_upsample(ind, refine)
    m = fine_a.shape[0]
    lo, hi = pad / (nb - 1), (pad + n - 1) / (nb - 1)
    w_in = interval_weights(m, lo, hi)
    w_all = interval_weights(m, 0.0, 1.0)  # the trapezoid weights
    vol = (hi - lo) ** d
    f_a = contract(fine_a, w_in) - vol * contract(fine_a, w_all)
    f_b = contract(fine_b, w_in) - vol * contract(fine_b, w_all)
    sea = -f_a / f_b
    fine_a += sea * fine_b
    return fine_a, float(sea)
