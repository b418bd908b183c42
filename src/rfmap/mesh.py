r"""Structured vertex grids on the unit square / cube and their simplicial meshes.

Conventions (shared by every part of :mod:`rfmap`):

* An ``N``-grid in dimension ``d`` has ``N**d`` vertices; vertex :math:`(i, j[, k])` sits at
  :math:`(i, j[, k]) / (N - 1)` and has flat index ``i*N + j`` (``(i*N + j)*N + k`` in 3D), i.e. C order with the
  first array axis along :math:`x_1`.  A field sampled on the grid is an array of shape ``(N,)*d`` indexed
  ``[i, j(, k)]``.
* 2D: every grid square is split into two triangles by the diagonal from :math:`(x+h, y)` to :math:`(x, y+h)`.
* 3D: every grid cube is split into six tetrahedra around its main diagonal (Kuhn / Freudenthal split).
* Every element is positively oriented on the reference grid.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import torch

__all__ = [
    "Mesh",
    "grid_points",
    "grid_mesh",
    "square_triangles",
    "cube_tetrahedra",
    "element_measures",
    "interpolate",
    "check_n",
    "check_dim",
]


def check_dim(dim: int) -> int:
    """Validate a spatial dimension (2 or 3)."""
    if dim not in (2, 3):
        raise ValueError(f"dimension must be 2 or 3, got {dim!r}")
    return int(dim)


def check_n(n: int, minimum: int = 3) -> int:
    """Validate a grid size ``N`` (vertices per side)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise ValueError(f"grid size N must be an integer, got {n!r}")
    if n < minimum:
        raise ValueError(f"grid size N must be >= {minimum}, got N={n}")
    return int(n)


def grid_points(n: int, dim: int = 2, dtype=np.float64) -> np.ndarray:
    """Vertices of the ``N``-grid on :math:`[0,1]^d`.

    Returns
    -------
    ndarray, shape (N**d, d)
        Row ``i*N + j`` holds :math:`(i, j)/(N-1)`.
    """
    n = check_n(n, 2)
    dim = check_dim(dim)
    t = np.linspace(0.0, 1.0, n, dtype=dtype)
    axes = np.meshgrid(*([t] * dim), indexing="ij")
    return np.stack([a.reshape(-1) for a in axes], axis=-1)


def square_triangles(n: int) -> np.ndarray:
    """Triangles of the ``N``-grid on the unit square, shape ``(2 (N-1)^2, 3)``, counter-clockwise.

    Each square with lower-left vertex :math:`(x, y)` gives
    :math:`[(x,y), (x+h,y), (x,y+h)]` and :math:`[(x+h,y), (x+h,y+h), (x,y+h)]`,
    i.e. the diagonal runs from :math:`(x+h, y)` to :math:`(x, y+h)`.
    """
    n = check_n(n, 2)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    v00 = (i * n + j).reshape(-1)
    v10 = ((i + 1) * n + j).reshape(-1)  # (x+h, y)
    v01 = (i * n + j + 1).reshape(-1)  # (x, y+h)
    v11 = ((i + 1) * n + j + 1).reshape(-1)
    t1 = np.stack([v00, v10, v01], axis=-1)
    t2 = np.stack([v10, v11, v01], axis=-1)
    return np.concatenate([t1, t2], axis=0).astype(np.int64)


def cube_tetrahedra(n: int) -> np.ndarray:
    """Tetrahedra of the ``N``-grid on the unit cube (Kuhn split), shape ``(6 (N-1)^3, 4)``.

    Each cube is cut into the six tetrahedra :math:`v_{000} \\to v_{000}+e_{\\sigma_1} \\to
    v_{000}+e_{\\sigma_1}+e_{\\sigma_2} \\to v_{111}` for the six permutations :math:`\\sigma`;
    vertices are ordered so that every tetrahedron has positive volume.
    """
    n = check_n(n, 2)
    i, j, k = np.meshgrid(*([np.arange(n - 1)] * 3), indexing="ij")
    base = np.stack([i.reshape(-1), j.reshape(-1), k.reshape(-1)], axis=-1)  # (c, 3)
    stride = np.array([n * n, n, 1])
    tets = []
    for perm in itertools.permutations(range(3)):
        corners = [np.zeros(3, dtype=np.int64)]
        for ax in perm:
            nxt = corners[-1].copy()
            nxt[ax] += 1
            corners.append(nxt)
        idx = [((base + c) * stride).sum(-1) for c in corners]
        # orientation of the path simplex equals the sign of the permutation
        parity = np.linalg.det(np.eye(3)[list(perm)])
        if parity < 0:
            idx[1], idx[2] = idx[2], idx[1]
        tets.append(np.stack(idx, axis=-1))
    return np.concatenate(tets, axis=0).astype(np.int64)


@dataclass(frozen=True)
class Mesh:
    """A structured simplicial mesh of :math:`[0,1]^d`.

    Attributes
    ----------
    n : int
        Vertices per side.
    dim : int
        2 (triangles) or 3 (tetrahedra).
    points : ndarray, shape (N**d, d)
    elements : ndarray of int64, shape (m, d+1)
    """

    n: int
    dim: int
    points: np.ndarray
    elements: np.ndarray

    @property
    def shape(self) -> tuple[int, ...]:
        """Grid shape ``(N,)*d`` of a vertex field."""
        return (self.n,) * self.dim

    @property
    def h(self) -> float:
        """Grid spacing :math:`1/(N-1)`."""
        return 1.0 / (self.n - 1)

    def boundary_mask(self) -> np.ndarray:
        """Boolean mask of shape ``(N**d,)``: vertices on :math:`\\partial[0,1]^d`."""
        idx = np.indices(self.shape).reshape(self.dim, -1)
        return ((idx == 0) | (idx == self.n - 1)).any(axis=0)


def grid_mesh(n: int, dim: int = 2) -> Mesh:
    """The ``N``-grid mesh of the unit square (``dim=2``) or cube (``dim=3``)."""
    n = check_n(n, 2)
    dim = check_dim(dim)
    elements = square_triangles(n) if dim == 2 else cube_tetrahedra(n)
    return Mesh(n=n, dim=dim, points=grid_points(n, dim), elements=elements)


def element_measures(points, elements):
    """Signed areas (2D) or volumes (3D) of the elements.

    Accepts numpy arrays or torch tensors (returned in the same kind); see
    :func:`rfmap.geometry.signed_measures`.
    """
    from .geometry import signed_measures

    if isinstance(points, torch.Tensor):
        return signed_measures(points, torch.as_tensor(elements, device=points.device))
    return signed_measures(torch.as_tensor(np.asarray(points, dtype=np.float64)),
                           torch.as_tensor(np.asarray(elements))).numpy()


def interpolate(values, points, *, tol: float = 1e-9):
    r"""Multilinear (bi-/trilinear) interpolation of grid fields at arbitrary query points.

    Parameters
    ----------
    values : Tensor or ndarray, shape (B, C, N, N) or (B, C, N, N, N)
        Fields sampled on the ``N``-grid (grid axes ordered :math:`x_1, x_2[, x_3]`).
        Grids with different sizes per axis are allowed.
    points : Tensor or ndarray, shape (B, P, d) or (P, d)
        Query points in :math:`[0, 1]^d` (a shared point set is broadcast over the batch).
    tol : float
        Points outside :math:`[-tol, 1+tol]^d` raise ``ValueError``.

    Returns
    -------
    Tensor or ndarray (same kind as ``values``), shape (B, P, C)
    """
    is_np = not isinstance(values, torch.Tensor)
    v = torch.as_tensor(values)
    p = torch.as_tensor(points, dtype=v.dtype, device=v.device)
    if v.dim() not in (4, 5):
        raise ValueError(f"values must have shape (B, C, *grid) with a 2D or 3D grid, got {tuple(v.shape)}")
    d = v.dim() - 2
    if p.dim() == 2:
        p = p.unsqueeze(0).expand(v.shape[0], -1, -1)
    if p.dim() != 3 or p.shape[-1] != d:
        raise ValueError(f"points must have shape (B, P, {d}) or (P, {d}), got {tuple(p.shape)}")
    if p.shape[0] != v.shape[0]:
        raise ValueError(f"batch of points ({p.shape[0]}) does not match batch of values ({v.shape[0]})")
    if not torch.isfinite(p).all():
        raise ValueError("query points contain NaN or infinite values")
    lo, hi = float(p.min()), float(p.max())
    if lo < -tol or hi > 1 + tol:
        raise ValueError(f"query points must lie in [0, 1]^{d}; got coordinates in [{lo:.4g}, {hi:.4g}]")
    # grid_sample wants the last coordinate along the last grid axis, in [-1, 1]
    g = (2.0 * p.flip(-1) - 1.0).clamp(-1, 1)
    g = g.reshape(g.shape[0], *([1] * (d - 1)), g.shape[1], d)
    out = torch.nn.functional.grid_sample(v, g, mode="bilinear", padding_mode="border", align_corners=True)
    out = out.reshape(v.shape[0], v.shape[1], -1).transpose(1, 2)
    return out.numpy() if is_np else out
