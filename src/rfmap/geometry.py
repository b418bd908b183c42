r"""Differentiable geometry of piecewise-linear maps (torch, batched).

A piecewise-linear map sends every vertex of a simplicial mesh (reference positions ``ref``) to a new position
(``mapped``).  On each element the map is affine, :math:`f(x) = J x + c`, with

.. math:: J = E_{\text{mapped}} E_{\text{ref}}^{-1}, \qquad E = [v_1 - v_0, \dots, v_d - v_0] \in \mathbb{R}^{d\times d}.

All functions accept a leading batch shape ``...`` on the point arrays and are differentiable (``gradcheck``-tested
in float64).
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

__all__ = [
    "edge_matrices",
    "signed_measures",
    "element_jacobians",
    "jacobian_determinants",
    "beltrami_from_jacobian",
    "beltrami_coefficient",
    "wirtinger",
    "det",
]


def _as_index(elements, device) -> Tensor:
    e = torch.as_tensor(elements, device=device)
    if e.dim() != 2 or e.dtype not in (torch.int32, torch.int64):
        raise ValueError(f"elements must be an integer array of shape (m, d+1), got {tuple(e.shape)} {e.dtype}")
    return e.long()


def edge_matrices(points: Tensor, elements) -> Tensor:
    r"""Edge matrices :math:`E = [v_1 - v_0, \dots, v_d - v_0]` (edges as columns).

    Parameters
    ----------
    points : Tensor, shape (..., n, d)
    elements : LongTensor, shape (m, d+1)

    Returns
    -------
    Tensor, shape (..., m, d, d)
    """
    e = _as_index(elements, points.device)
    d = points.shape[-1]
    if e.shape[-1] != d + 1:
        raise ValueError(f"elements of a {d}D mesh need {d + 1} vertices, got {e.shape[-1]}")
    v = points[..., e, :]  # (..., m, d+1, d)
    return (v[..., 1:, :] - v[..., :1, :]).transpose(-1, -2)


def signed_measures(points: Tensor, elements) -> Tensor:
    r"""Signed element measures :math:`\det E / d!` (area in 2D, volume in 3D).

    Parameters
    ----------
    points : Tensor, shape (..., n, d)
    elements : LongTensor, shape (m, d+1)

    Returns
    -------
    Tensor, shape (..., m)
    """
    d = points.shape[-1]
    return det(edge_matrices(points, elements)) / math.factorial(d)


def det(A: Tensor) -> Tensor:
    """Determinant of (..., 2, 2) or (..., 3, 3) matrices by the explicit formula (fast for many small matrices)."""
    if A.shape[-2:] == (2, 2):
        return A[..., 0, 0] * A[..., 1, 1] - A[..., 0, 1] * A[..., 1, 0]
    if A.shape[-2:] == (3, 3):
        a, b, c = A[..., 0, 0], A[..., 0, 1], A[..., 0, 2]
        d_, e, f = A[..., 1, 0], A[..., 1, 1], A[..., 1, 2]
        g, h, i = A[..., 2, 0], A[..., 2, 1], A[..., 2, 2]
        return a * (e * i - f * h) - b * (d_ * i - f * g) + c * (d_ * h - e * g)
    return torch.linalg.det(A)


def element_jacobians(ref: Tensor, mapped: Tensor, elements) -> Tensor:
    r"""Per-element Jacobian matrices :math:`J = E_{\text{mapped}} E_{\text{ref}}^{-1}`.

    Parameters
    ----------
    ref : Tensor, shape (..., n, d)
        Reference vertex positions (broadcast against ``mapped``).
    mapped : Tensor, shape (..., n, d)
    elements : LongTensor, shape (m, d+1)

    Returns
    -------
    Tensor, shape (..., m, d, d); ``J[..., a, b]`` is :math:`\partial f_a / \partial x_b`.
    """
    e_ref = edge_matrices(ref, elements)
    e_map = edge_matrices(mapped, elements)
    return e_map @ torch.linalg.inv(e_ref)


def jacobian_determinants(ref: Tensor, mapped: Tensor, elements) -> Tensor:
    r"""Per-element Jacobian determinants :math:`\det J = |T_{\text{mapped}}| / |T_{\text{ref}}|` (signed).

    Returns
    -------
    Tensor, shape (..., m); an element is flipped when its determinant is :math:`\le 0`.
    """
    return signed_measures(mapped, elements) / signed_measures(ref, elements)


def wirtinger(J: Tensor) -> tuple[Tensor, Tensor]:
    r"""Wirtinger derivatives of a planar map from its Jacobian (paper Sec. 3.1).

    With :math:`f = u + i v`, :math:`f_z = \tfrac12(f_x - i f_y)` and :math:`f_{\bar z} = \tfrac12(f_x + i f_y)`.

    Parameters
    ----------
    J : Tensor, shape (..., 2, 2)

    Returns
    -------
    (f_z, f_zbar) : complex Tensors, shape (...)
    """
    ux, uy = J[..., 0, 0], J[..., 0, 1]
    vx, vy = J[..., 1, 0], J[..., 1, 1]
    fz = torch.complex(0.5 * (ux + vy), 0.5 * (vx - uy))
    fzb = torch.complex(0.5 * (ux - vy), 0.5 * (vx + uy))
    return fz, fzb


def beltrami_from_jacobian(J: Tensor) -> Tensor:
    r"""Beltrami coefficient :math:`\mu = f_{\bar z} / f_z` from a Jacobian (paper Eq. (1)).

    Parameters
    ----------
    J : Tensor, shape (..., 2, 2)

    Returns
    -------
    Tensor, complex, shape (...)
    """
    if J.shape[-2:] != (2, 2):
        raise ValueError(f"the Beltrami coefficient is defined for planar maps; got Jacobians {tuple(J.shape)}")
    fz, fzb = wirtinger(J)
    return fzb / fz


def beltrami_coefficient(ref: Tensor, mapped: Tensor, elements) -> Tensor:
    r"""Per-triangle Beltrami coefficient :math:`\mu = f_{\bar z} / f_z` of a piecewise-linear map (paper Eq. (1)).

    The affine map :math:`f = a z + b \bar z` has :math:`\mu = b / a`; :math:`|\mu| < 1` iff the triangle keeps its
    orientation.

    Parameters
    ----------
    ref, mapped : Tensor, shape (..., n, 2)
    elements : LongTensor, shape (m, 3)

    Returns
    -------
    Tensor, complex, shape (..., m)
    """
    if mapped.shape[-1] != 2:
        raise ValueError(f"the Beltrami coefficient needs 2D points, got dimension {mapped.shape[-1]}")
    return beltrami_from_jacobian(element_jacobians(ref, mapped, elements))
