r"""The density that a map leaves on its image, per element and as a vertex field.

A map :math:`T` of a mesh leaves the density :math:`\tilde\rho_e = \text{population}_e / |T(e)|` on its elements
(:func:`residual_density`).  The flow-based solver flows it away in its later passes and from a warm start; it needs
it as a field on its raster, which the vertex field of :func:`vertex_residual` gives without the shift and blur of
reading element values (or their lumped vertex means, :func:`lumped_residual`) at the raster nodes.
"""
from __future__ import annotations

import numpy as np

__all__ = ["residual_density", "lumped_residual", "vertex_residual", "RESIDUAL_ITERATIONS"]


def _measures(points: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """Signed element measures times d! (numpy; enough for ratios and sign tests)."""
    P = points[elements]
    E = P[:, 1:] - P[:, :1]
    if E.shape[-1] == 2:
        return E[:, 0, 0] * E[:, 1, 1] - E[:, 0, 1] * E[:, 1, 0]
    return np.einsum("ei,ei->e", E[:, 0], np.cross(E[:, 1], E[:, 2]))


def residual_density(ref: np.ndarray, mapped: np.ndarray, elements: np.ndarray, density: np.ndarray) -> np.ndarray:
    r"""Density that a map leaves on its image: :math:`\tilde\rho_e = \text{population}_e / |T(e)|`, shape (e,).

    The population is the exact integral of the P1 vertex density over the reference element (mean vertex value
    times measure, as in :mod:`rfmap.core.metrics`); :math:`|T(e)|` is the signed measure of the mapped element.
    """
    return density[elements].mean(1) * _measures(ref, elements) / _measures(mapped, elements)


def lumped_residual(elements: np.ndarray, population: np.ndarray, measure: np.ndarray, n: int) -> np.ndarray:
    r"""The residual density lumped onto the vertices: :math:`\sum_{e \ni v} \text{population}_e \,/\,
    \sum_{e \ni v} |T(e)|`, shape (P,): the measure-weighted mean of the element residuals
    :math:`\tilde\rho_e = \text{population}_e/|T(e)|` around each vertex.

    Parameters
    ----------
    elements : ndarray, shape (e, d+1)
    population : ndarray, shape (e,)
        Mass of each element (as in :func:`residual_density`).
    measure : ndarray, shape (e,)
        Measure of each mapped element :math:`|T(e)|` (positive; any common scale as ``population``'s).
    n : int
        Number of vertices, :math:`P` (the length of the result).
    """
    mass = np.zeros(n)
    vol = np.zeros(n)
    for k in range(elements.shape[1]):
        mass += np.bincount(elements[:, k], weights=population, minlength=n)
        vol += np.bincount(elements[:, k], weights=measure, minlength=n)
    return mass / vol


#: Conjugate-gradient iterations of :func:`vertex_residual` (from the lumped residual): enough for a flow started at
#: the identity to end where the cold flow does (:doc:`Design decisions </book/design>`).
RESIDUAL_ITERATIONS = 10


def vertex_residual(elements: np.ndarray, population: np.ndarray, measure: np.ndarray, n: int, *,
                    iterations: int = RESIDUAL_ITERATIONS) -> np.ndarray:
    r"""The residual density of a map as a P1 vertex field whose element means match :math:`\tilde\rho_e`.

    The flow needs the density that a map leaves on its image, :math:`\tilde\rho_e = \text{population}_e /
    |T(e)|`, as a field on its raster.  Read element by element at the raster nodes (which sit on the faces of a
    nearly undeformed mesh, so that each takes the value of an arbitrary neighbouring element) it is shifted by up
    to half an element; lumped onto the vertices (:func:`lumped_residual`) it is blurred over one.  Both errors are
    smooth, and the flow transports them faithfully.  Instead, this returns the vertex values :math:`r` whose P1
    interpolant has, element by element, the mean :math:`\tilde\rho_e` in the weighted least-squares sense,

    .. math:: \min_r \sum_e |T(e)| \Big(\frac{1}{d+1}\sum_{v \in e} r_v - \tilde\rho_e\Big)^2 ,

    by ``iterations`` steps of Jacobi-preconditioned conjugate gradients on the normal equations, started from the
    lumped residual.  For the identity map of a P1 vertex density :math:`\rho` the element means are those of
    :math:`\rho` itself, so :math:`r = \rho` and a warm start from the identity is the cold flow.  Vertex patterns
    whose element means all vanish lie in the null space; conjugate gradients leave the lumped start's component
    there.

    Parameters
    ----------
    elements, population, measure, n
        As in :func:`lumped_residual`.
    iterations : int
        Conjugate-gradient steps (0 returns the lumped residual).

    Returns
    -------
    ndarray, shape (P,)
    """
    import scipy.sparse as sp

    x = lumped_residual(elements, population, measure, n)
    if iterations <= 0:
        return x
    e, k = elements.shape
    A = sp.csr_matrix((np.full(e * k, 1.0 / k), elements.reshape(-1), np.arange(0, e * k + 1, k)), shape=(e, n))
    At = A.T  # a CSC view: its products cost about as much as CSR ones, without the 55 ms conversion (3D N = 48)
    w = np.asarray(measure, dtype=np.float64)

    def normal(v: np.ndarray) -> np.ndarray:
        return At @ (w * (A @ v))

    diag = At @ (w / k)  # the diagonal of A^T W A: sum over the elements at v of |T(e)| / (d+1)^2
    r = At @ np.asarray(population, dtype=np.float64) - normal(x)
    z = r / diag
    p = z.copy()
    rz = float(r @ z)
    for _ in range(int(iterations)):
        if rz <= 0.0:
            break
        Ap = normal(p)
        alpha = rz / float(p @ Ap)
        x += alpha * p
        r -= alpha * Ap
        z = r / diag
        rz_next = float(r @ z)
        p = z + (rz_next / rz) * p
        rz = rz_next
    return x
