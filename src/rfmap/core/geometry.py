r"""Differentiable geometry of piecewise-linear maps (torch, batched).

A piecewise-linear map sends every vertex of a simplicial mesh (reference positions ``ref``) to a new position
(``mapped``).  On each element the map is affine, :math:`f(x) = J x + c`, with

.. math:: J = E_{\text{mapped}} E_{\text{ref}}^{-1}, \qquad E = [v_1 - v_0, \dots, v_d - v_0] \in \mathbb{R}^{d\times d}.

All functions accept a leading batch shape ``...`` on the point arrays and are differentiable (``gradcheck``-tested
in float64).
"""
from __future__ import annotations

import itertools
import math

import numpy as np
import torch
from torch import Tensor

__all__ = [
    "edge_matrices",
    "signed_measures",
    "grid_cell_simplices",
    "grid_simplices",
    "grid_measure_coefficients",
    "grid_signed_measures",
    "grid_min_measure",
    "grid_element_mean",
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
    points : Tensor, shape (..., P, d)
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
    points : Tensor, shape (..., P, d)
    elements : LongTensor, shape (m, d+1)

    Returns
    -------
    Tensor, shape (..., m)
    """
    d = points.shape[-1]
    return det(edge_matrices(points, elements)) / math.factorial(d)


def grid_cell_simplices(dim: int) -> list[list[tuple[int, ...]]]:
    r"""The split of one grid cell into simplices: corner offsets (0 or 1 per axis) of each simplex.

    2D: the square is cut along the diagonal from :math:`(1, 0)` to :math:`(0, 1)` into two triangles.  3D: the
    cube is cut into the six Kuhn tetrahedra :math:`0 \to e_{\sigma_1} \to e_{\sigma_1} + e_{\sigma_2} \to
    (1, 1, 1)`, one per permutation :math:`\sigma` (in ``itertools.permutations`` order), with the two middle
    corners swapped for odd permutations so that every simplex is positively oriented.  This is the one definition
    of the split: :func:`rfmap.core.mesh.grid_mesh` builds its elements from it, in this order.
    """
    if dim == 2:
        return [[(0, 0), (1, 0), (0, 1)], [(1, 0), (1, 1), (0, 1)]]
    out = []
    for perm in itertools.permutations(range(3)):
        corners = [[0, 0, 0]]
        for ax in perm:
            nxt = list(corners[-1])
            nxt[ax] += 1
            corners.append(nxt)
        if _parity(perm) < 0:
            corners[1], corners[2] = corners[2], corners[1]
        out.append([tuple(c) for c in corners])
    return out


def grid_simplices(values: Tensor, n: int, dim: int) -> list[list[Tensor]]:
    r"""Vertex values of every simplex of the ``N``-grid mesh, gathered by slicing instead of indexing.

    The simplices of :func:`rfmap.core.mesh.grid_mesh` come in ``d!`` types per grid cell (2 triangles, 6 Kuhn
    tetrahedra); for each type this returns its ``d + 1`` corners as strided views of the grid, which is much
    cheaper than a gather (and its scatter-add backward) on the millions of indices of a 3D mesh.

    Parameters
    ----------
    values : Tensor, shape (B, N**d, C)
        Per-vertex values in grid order (e.g. vertex positions, C = d).

    Returns
    -------
    list over simplex types of lists of ``d + 1`` Tensors of shape (B, N-1, ..., N-1, C).
    """
    B, P, C = values.shape
    if P != n**dim:
        raise ValueError(f"{P} values do not form an N={n} grid in {dim}D")
    g = values.reshape(B, *([n] * dim), C)

    def corner(off):
        return g[(slice(None),) + tuple(slice(o, n - 1 + o) for o in off)]

    return [[corner(off) for off in simplex] for simplex in grid_cell_simplices(dim)]


def grid_signed_measures(points: Tensor, n: int) -> Tensor:
    r"""Signed measures of the elements of the ``N``-grid mesh at vertex positions ``points``.

    Equal to ``signed_measures(points, grid_mesh(n, d).elements)`` (same element order, up to rounding), computed
    from strided views of the coordinates moved to a leading axis, so that every product runs over contiguous
    rows: in 3D the triple product :math:`a \cdot (b \times c)` is written out component by component (faster,
    forward and backward, than ``linalg.cross`` on the trailing axis).
    Used by the training losses and weight refinement.

    Shapes: points (B, N**d, d) -> (B, d! (N-1)**d).
    """
    B, P, d = points.shape
    if P != n**d:
        raise ValueError(f"{P} points do not form an N={n} grid in {d}D")
    g = points.reshape(B, *([n] * d), d).movedim(-1, 1).contiguous()  # (B, d, N, ..., N)

    def corner(off):
        return g[(slice(None), slice(None)) + tuple(slice(o, n - 1 + o) for o in off)]

    out = []
    for simplex in grid_cell_simplices(d):
        c0, *rest = [corner(off) for off in simplex]
        e = [c - c0 for c in rest]
        if d == 2:
            a, b = e
            m = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
        else:
            a, b, c = e
            m = (a[:, 0] * (b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1])
                 + a[:, 1] * (b[:, 2] * c[:, 0] - b[:, 0] * c[:, 2])
                 + a[:, 2] * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0]))
        out.append(m.reshape(B, -1))
    return torch.cat(out, -1) / math.factorial(d)


def grid_measure_coefficients(ref: Tensor, disp: Tensor, n: int) -> list[tuple[tuple[int, ...], Tensor]]:
    r"""The element measures of the ``N``-grid mesh at :math:`x + \alpha \odot D` as a polynomial in
    :math:`\alpha`: :math:`|T(\alpha)| = \sum_{S \subseteq \{0..d-1\}} c_S \prod_{a \in S} \alpha_a`.

    :math:`d!\,c_S` is the determinant of the edge matrix whose row :math:`a` (coordinate :math:`a` of the
    :math:`d` edges from the simplex's first corner) comes from :math:`D` for :math:`a \in S` and from the reference
    grid otherwise (the determinant is linear in each row).  On the grid the reference rows are the same numbers for
    every cell of a simplex type, so each :math:`c_S` is expanded (Leibniz) with those numbers as scalars: terms with
    a zero drop out and the others are fused multiply-adds, which costs a fraction of :math:`2^d` calls of
    :func:`grid_signed_measures` and gives the same values up to rounding.

    Parameters
    ----------
    ref : Tensor, shape (N**d, d)
        The vertices of :func:`grid_mesh(N, d) <rfmap.core.mesh.grid_mesh>` (a uniform grid, in grid order).
    disp : Tensor, shape (N**d, d)
        The displacement :math:`D` at the vertices.

    Returns
    -------
    list of (S, c_S)
        One pair per subset :math:`S`, in binary order: ``S`` a sorted tuple of axes, ``c_S`` a tensor of shape
        (m,) over the elements, in the order of :func:`grid_signed_measures`.
    """
    P, d = disp.shape
    if P != n**d or ref.shape != disp.shape:
        raise ValueError(f"{P} displacements (and {ref.shape[0]} points) do not form an N={n} grid in {d}D")
    step = (ref.reshape(*([n] * d), d)[(1,) * d] - ref[0]).tolist()  # grid spacing per axis
    g = disp.reshape(*([n] * d), d).movedim(-1, 0).contiguous()  # (d, N, ..., N)

    def corner(off):
        return g[(slice(None),) + tuple(slice(o, n - 1 + o) for o in off)]

    subsets = [tuple(a for a in range(d) if bits >> a & 1) for bits in range(2**d)]
    parts: dict[tuple, list[Tensor]] = {s: [] for s in subsets}
    perms = [(p, _parity(p)) for p in itertools.permutations(range(d))]
    for simplex in grid_cell_simplices(d):
        c0, *rest = [corner(off) for off in simplex]
        edge_d = [[c[a] - c0[a] for c in rest] for a in range(d)]  # edge_d[a][k]: coordinate a of edge k
        edge_r = [[step[a] * (off[a] - simplex[0][a]) for off in simplex[1:]] for a in range(d)]
        for s in subsets:
            rows = [edge_d[a] if a in s else edge_r[a] for a in range(d)]
            parts[s].append(_leibniz(rows, perms, c0[0].shape).reshape(-1))
    return [(s, torch.cat(parts[s]) / math.factorial(d)) for s in subsets]


def _parity(perm: tuple[int, ...]) -> int:
    """+1 or -1: the sign of a permutation."""
    sign = 1
    for i in range(len(perm)):
        for j in range(i + 1, len(perm)):
            sign = -sign if perm[i] > perm[j] else sign
    return sign


def _leibniz(rows: list[list], perms: list[tuple[tuple[int, ...], int]], shape) -> Tensor:
    r"""The determinant :math:`\sum_\sigma \mathrm{sgn}\,\sigma \prod_a M_{a \sigma(a)}` of a matrix whose entries
    are floats (the same for every cell) or tensors of ``shape``: products with a zero float are skipped, the
    floats of a term become its coefficient."""
    total = None
    for perm, sign in perms:
        coef, factors = float(sign), []
        for a, k in enumerate(perm):
            v = rows[a][k]
            if isinstance(v, Tensor):
                factors.append(v)
            else:
                coef *= v
        if coef == 0.0:
            continue
        if total is None:
            total = torch.zeros(shape, dtype=factors[0].dtype if factors else torch.float64)
        if not factors:
            total += coef
        elif len(factors) == 1:
            total.add_(factors[0], alpha=coef)
        else:
            head = factors[0] if len(factors) == 2 else factors[0] * factors[1]
            total.addcmul_(head, factors[-1], value=coef)
    return torch.zeros(shape, dtype=torch.float64) if total is None else total


def grid_element_mean(values: Tensor, n: int, dim: int) -> Tensor:
    """Mean of per-vertex ``values`` (B, N**d) over the vertices of each grid-mesh element: (B, m)."""
    B = values.shape[0]
    out = []
    for corners in grid_simplices(values.unsqueeze(-1), n, dim):
        out.append((sum(corners) / len(corners)).reshape(B, -1))
    return torch.cat(out, -1)


def det(A: Tensor) -> Tensor:
    """Determinant of (..., 2, 2) or (..., 3, 3) matrices by the explicit formula (fast for many small matrices).

    The 3x3 case is the triple product of the columns, :math:`c_0 \\cdot (c_1 \\times c_2)`; unbinding the
    columns (rather than indexing nine entries) keeps the backward pass to a few full-size buffers.
    """
    if A.shape[-2:] == (2, 2):
        c0, c1 = A.unbind(-1)
        return c0[..., 0] * c1[..., 1] - c0[..., 1] * c1[..., 0]
    if A.shape[-2:] == (3, 3):
        c0, c1, c2 = A.unbind(-1)
        return (c0 * torch.linalg.cross(c1, c2, dim=-1)).sum(-1)
    return torch.linalg.det(A)


def element_jacobians(ref: Tensor, mapped: Tensor, elements) -> Tensor:
    r"""Per-element Jacobian matrices :math:`J = E_{\text{mapped}} E_{\text{ref}}^{-1}`.

    Parameters
    ----------
    ref : Tensor, shape (..., P, d)
        Reference vertex positions (broadcast against ``mapped``).
    mapped : Tensor, shape (..., P, d)
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
    ref, mapped : Tensor, shape (..., P, 2)
    elements : LongTensor, shape (m, 3)

    Returns
    -------
    Tensor, complex, shape (..., m)
    """
    if mapped.shape[-1] != 2:
        raise ValueError(f"the Beltrami coefficient needs 2D points, got dimension {mapped.shape[-1]}")
    return beltrami_from_jacobian(element_jacobians(ref, mapped, elements))


def _grid_min_det(points: torch.Tensor, n: int) -> float:
    r"""Smallest :math:`\det E` over the grid-mesh elements (explicit formula on strided views, no gather)."""
    d = points.shape[-1]
    out = np.inf
    for corners in grid_simplices(points[None], n, d):
        e = [(c - corners[0]).unbind(-1) for c in corners[1:]]
        if d == 2:
            det = e[0][0] * e[1][1] - e[0][1] * e[1][0]
        else:
            (ax, ay, az), (bx, by, bz), (cx, cy, cz) = e
            det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
        out = min(out, float(det.min()))
    return out


def grid_min_measure(points: np.ndarray, n: int) -> float:
    r"""Smallest signed element measure of a map of the ``N``-grid mesh, cheaply.

    A float32 pass decides whenever the minimum exceeds :math:`10^{-3}` of the reference measure (float32 rounding
    of :math:`\det E` is far below that); otherwise the minimum is recomputed in float64.
    """
    d = points.shape[1]
    ref = (1.0 / (n - 1)) ** d
    m = _grid_min_det(torch.as_tensor(points, dtype=torch.float32), n)
    if not m > 1e-3 * ref:
        m = _grid_min_det(torch.as_tensor(np.asarray(points, np.float64)), n)
    return m / (2 if d == 2 else 6)
