r"""Structured vertex grids on the unit square / cube and their simplicial meshes.

Conventions (shared by every part of :mod:`rfmap`):

* An ``N``-grid in dimension ``d`` has ``N**d`` vertices; vertex :math:`(i, j[, k])` sits at
  :math:`(i, j[, k]) / (N - 1)` and has flat index ``i*N + j`` (``(i*N + j)*N + k`` in 3D), i.e. C order with the
  first array axis along :math:`x_1`.  A field sampled on the grid is an array of shape ``(N,)*d`` indexed
  ``[i, j(, k)]``.
* 2D: every grid square is split into two triangles by the diagonal from :math:`(x+h, y)` to :math:`(x, y+h)`.
* 3D: every grid cube is split into six tetrahedra around its main diagonal (Kuhn / Freudenthal split).
* Every element is positively oriented on the reference grid.

The split of one grid cell is :func:`rfmap.core.geometry.grid_cell_simplices`; the mesh here and the strided grid
operators of :mod:`rfmap.core.geometry` both use it, so their element orders agree.  Beside the mesh: the vertex
quadrature weights (:func:`vertex_weights`), element centroids, multilinear interpolation of grid fields
(:func:`interpolate` in torch, :func:`multilinear` in numpy) and the Sobol-jittered vertices used in training
(:func:`jittered_points`).
"""
from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

# torch (and rfmap.core.geometry, which needs it) is imported where it is used: the mesh's checks and grids serve
# the torch-free cartogram path too

__all__ = [
    "Mesh",
    "grid_points",
    "grid_mesh",
    "grid_size",
    "square_triangles",
    "cube_tetrahedra",
    "element_measures",
    "element_centroids",
    "triangulate",
    "vertex_weights",
    "grid_vertex_weights",
    "interpolate",
    "multilinear",
    "jittered_points",
    "check_n",
    "check_dim",
    "check_grid_memory",
    "available_memory",
    "BYTES_PER_VERTEX",
]


def _geometry():
    """:mod:`rfmap.core.geometry`, imported on first use (it needs torch)."""
    from . import geometry

    return geometry


def _is_tensor(x) -> bool:
    """Whether ``x`` is a torch tensor (without importing torch: none exists before torch is loaded)."""
    torch = sys.modules.get("torch")
    return torch is not None and isinstance(x, torch.Tensor)


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


#: Bytes of memory per grid vertex that a map needs, by dimension.  It is the peak memory of the heaviest
#: single-map pipelines (peak resident size above that of the imported package), with a margin over the measured
#: peak (the book's page :doc:`Design decisions </book/design>` gives the margin per pipeline).
BYTES_PER_VERTEX = {2: 4096, 3: 4096}


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (``MemAvailable`` of ``/proc/meminfo``, else the physical
    memory), or ``None`` where neither can be read."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def check_grid_memory(n: int, dim: int, *, available: int | None = None) -> int:
    r"""Refuse an ``N``-grid whose maps cannot fit in memory: a ``ValueError`` saying so, before anything is
    allocated, when :math:`N^d` times :data:`BYTES_PER_VERTEX` exceeds the available memory.

    Parameters
    ----------
    n, dim : int
        Grid side and dimension.
    available : int, optional
        Bytes available (default :func:`available_memory`; the check is skipped when that is unknown).

    Returns
    -------
    int
        The estimated bytes a map on this grid needs.
    """
    need = int(n) ** int(dim) * BYTES_PER_VERTEX[dim]
    if need <= 2**28:  # 256 MiB: any machine that runs the package has that
        return need
    avail = available_memory() if available is None else available
    if avail is not None and need > avail:
        raise ValueError(f"N={n} is too large for this machine's memory: a map on the {n}^{dim} grid "
                         f"({n ** dim:,} vertices) needs about {need / 2**30:.1f} GiB, "
                         f"{avail / 2**30:.1f} GiB available")
    return need


def grid_points(n: int, dim: int = 2, dtype=np.float64) -> np.ndarray:
    """Vertices of the ``N``-grid on :math:`[0,1]^d`.

    Returns
    -------
    ndarray, shape (N**d, d)
        Row ``i*N + j`` holds :math:`(i, j)/(N-1)`.
    """
    n = check_n(n, 2)
    dim = check_dim(dim)
    check_grid_memory(n, dim)
    t = np.linspace(0.0, 1.0, n, dtype=dtype)
    axes = np.meshgrid(*([t] * dim), indexing="ij")
    return np.stack([a.reshape(-1) for a in axes], axis=-1)


def _grid_elements(n: int, dim: int) -> np.ndarray:
    """Elements of the ``N``-grid: every simplex type of :func:`rfmap.core.geometry.grid_cell_simplices`, over all
    cells (C order), one type after the other."""
    cells = np.stack([a.reshape(-1) for a in np.meshgrid(*([np.arange(n - 1)] * dim), indexing="ij")], axis=-1)
    stride = n ** np.arange(dim - 1, -1, -1)
    blocks = [np.stack([((cells + np.array(c)) * stride).sum(-1) for c in corners], axis=-1)
              for corners in _geometry().grid_cell_simplices(dim)]
    return np.concatenate(blocks, axis=0).astype(np.int64)


def square_triangles(n: int) -> np.ndarray:
    """Triangles of the ``N``-grid on the unit square, shape ``(2 (N-1)^2, 3)``, counter-clockwise.

    Each square with lower-left vertex :math:`(x, y)` gives
    :math:`[(x,y), (x+h,y), (x,y+h)]` and :math:`[(x+h,y), (x+h,y+h), (x,y+h)]`,
    i.e. the diagonal runs from :math:`(x+h, y)` to :math:`(x, y+h)`.
    """
    return _grid_elements(check_n(n, 2), 2)


def cube_tetrahedra(n: int) -> np.ndarray:
    """Tetrahedra of the ``N``-grid on the unit cube (Kuhn split), shape ``(6 (N-1)^3, 4)``.

    Each cube is cut into the six tetrahedra :math:`v_{000} \\to v_{000}+e_{\\sigma_1} \\to
    v_{000}+e_{\\sigma_1}+e_{\\sigma_2} \\to v_{111}` for the six permutations :math:`\\sigma`;
    vertices are ordered so that every tetrahedron has positive volume.
    """
    return _grid_elements(check_n(n, 2), 3)


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
    """The ``N``-grid mesh of the unit square (``dim=2``) or cube (``dim=3``).

    The arrays are fresh copies of cached ones (building the 3D elements at N = 48 costs about 0.1 s, a copy a few
    milliseconds), so callers may modify them."""
    n = check_n(n, 2)
    dim = check_dim(dim)
    points, elements = _grid_arrays(n, dim)
    return Mesh(n=n, dim=dim, points=points.copy(), elements=elements.copy())


@lru_cache(maxsize=4)
def _grid_arrays(n: int, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Points and elements of the ``N``-grid mesh (cached, read-only)."""
    points, elements = grid_points(n, dim), _grid_elements(n, dim)
    for a in (points, elements):
        a.setflags(write=False)
    return points, elements


def grid_size(points, elements) -> int | None:
    """``N`` when ``(points, elements)`` is exactly :func:`grid_mesh` ``(N, d)`` (same vertices, same elements in the
    same order), else ``None``: lets whole-mesh measurements use the strided grid kernels
    (:func:`rfmap.core.geometry.grid_signed_measures`), an order of magnitude cheaper than gathers on 3D meshes."""
    pts = points.detach().cpu().numpy() if _is_tensor(points) else np.asarray(points)
    el = elements.detach().cpu().numpy() if _is_tensor(elements) else np.asarray(elements)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3) or el.ndim != 2 or el.shape[1] != pts.shape[1] + 1:
        return None
    d = pts.shape[1]
    n = int(round(pts.shape[0] ** (1.0 / d)))
    if n < 2 or n**d != pts.shape[0] or el.shape[0] != math.factorial(d) * (n - 1) ** d:
        return None
    gp, ge = _grid_arrays(n, d)
    return n if np.array_equal(pts, gp) and np.array_equal(el, ge) else None


def element_measures(points, elements):
    """Signed areas (2D) or volumes (3D) of the elements.

    Accepts numpy arrays or torch tensors (returned in the same kind); see
    :func:`rfmap.core.geometry.signed_measures`.
    """
    import torch

    signed_measures = _geometry().signed_measures
    if isinstance(points, torch.Tensor):
        return signed_measures(points, torch.as_tensor(elements, device=points.device))
    return signed_measures(torch.as_tensor(np.asarray(points, dtype=np.float64)),
                           torch.as_tensor(np.asarray(elements))).numpy()


def element_centroids(points, elements) -> np.ndarray:
    """Centroids of the elements, shape (m, d): the mean of their vertices."""
    return np.asarray(points)[np.asarray(elements)].mean(1)


def triangulate(points, *, tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    r"""A simplicial mesh of scattered points of the unit square or cube: Delaunay, positively oriented.

    Elements of measure :math:`\le 10^{-14}` (slivers of the Delaunay triangulation) are dropped.

    Parameters
    ----------
    points : array, shape (P, d)
        Points in :math:`[0, 1]^d` (up to ``tol``).

    Returns
    -------
    points : ndarray, float64, shape (P, d)
    elements : ndarray, int64, shape (m, d+1)
    """
    from scipy.spatial import Delaunay

    ref = np.asarray(points, dtype=np.float64)
    if ref.ndim != 2 or ref.shape[1] not in (2, 3):
        raise ValueError(f"query points must have shape (P, 2) or (P, 3), got {ref.shape}")
    d = ref.shape[1]
    if not np.isfinite(ref).all():
        raise ValueError("query points contain NaN or infinite values")
    if ref.min() < -tol or ref.max() > 1 + tol:
        raise ValueError(f"query points must lie in the unit {'square' if d == 2 else 'cube'}; got "
                         f"coordinates in [{ref.min():.4g}, {ref.max():.4g}]")
    elements = Delaunay(ref).simplices.astype(np.int64)
    import torch

    vol = _geometry().signed_measures(torch.as_tensor(ref), torch.as_tensor(elements)).numpy()
    elements[vol < 0] = elements[vol < 0][:, [1, 0] + list(range(2, d + 1))]
    return ref, elements[np.abs(vol) > 1e-14]


def vertex_weights(points: np.ndarray, elements: np.ndarray) -> np.ndarray:
    r"""Quadrature weights :math:`w_v = \sum_{T \ni v} |T| / (d+1)`.

    :math:`\sum_v w_v p_v` is the exact integral of the piecewise-linear interpolant of the vertex values
    :math:`p_v`, i.e. the total population in the paper's convention (element population = mean vertex value times
    element measure).

    Returns
    -------
    ndarray, shape (P,)
    """
    pts = np.asarray(points, dtype=np.float64)
    el = np.asarray(elements)
    meas = element_measures(pts, el)
    w = np.zeros(pts.shape[0])
    np.add.at(w, el.reshape(-1), np.repeat(meas / el.shape[1], el.shape[1]))
    return w


@lru_cache(maxsize=32)
def grid_vertex_weights(n: int, dim: int) -> np.ndarray:
    """:func:`vertex_weights` of the ``N``-grid mesh, shape (N**d,) (cached, read-only)."""
    mesh = grid_mesh(n, dim)
    w = vertex_weights(mesh.points, mesh.elements)
    w.setflags(write=False)
    return w


def multilinear(planes: np.ndarray, u: np.ndarray) -> np.ndarray:
    r"""Multilinear (bi-/trilinear) interpolant of grid planes at points given in grid index units, in numpy.

    With :math:`u = i + f` (:math:`i` the cell's lower corner, :math:`0 \le f \le 1` per axis), plane :math:`c` at
    :math:`u` is

    .. math:: \sum_{b \in \{0, 1\}^d} p_c[i + b] \prod_{j=1}^d \bigl(b_j f_j + (1 - b_j)(1 - f_j)\bigr),

    the corners summed in C order (last axis fastest).  Coordinates are clamped to the grid; a point on the upper
    wall of an axis is interpolated in the last cell.  It is the interpolation that the classical solvers use for
    their tables (the diffusion's heat field, :class:`rfmap.solvers.heatfield.HeatField`, and the cartogram flow,
    :func:`rfmap.solvers.cartoflow.bilinear`); :func:`interpolate` is its torch form for batches of fields.

    Parameters
    ----------
    planes : ndarray, shape (C, W_1, ..., W_d), d in {2, 3}
        ``C`` fields on a grid of ``W_1 x ... x W_d`` nodes (every ``W_j >= 2``), C-contiguous; float32 planes are
        interpolated in single precision (half the memory read), any other in double.
    u : ndarray, shape (P, d), float64
        Points in index units: node :math:`(i_1, \dots, i_d)` is at :math:`u = (i_1, \dots, i_d)`.  Overwritten
        (clamped, then reduced to the offsets in the cell).

    Returns
    -------
    ndarray, shape (P, C), float32 for float32 planes, else float64
        In Fortran order (each channel contiguous), as :func:`interpolate` returns it.

    Warnings
    --------
    ``u`` is modified in place; pass ``u.copy()`` to keep the points.
    """
    shape = planes.shape[1:]
    d = len(shape)
    flat = planes.reshape(planes.shape[0], -1)
    top = np.asarray(shape) - 1
    np.clip(u, 0.0, top, out=u)
    i = np.minimum(u.astype(np.intp), top - 1)
    u -= i
    strides = [int(np.prod(shape[j + 1:], dtype=np.int64)) for j in range(d)]  # C order: (W_2, 1) in 2D
    k = i[:, 0] * strides[0]
    for j in range(1, d):
        k += i[:, j] * strides[j]
    dtype = np.float32 if planes.dtype == np.float32 else np.float64
    w_u = u if dtype == np.float64 else u.astype(dtype)  # the offsets in the planes' precision
    corners: list[tuple[int, np.ndarray | None]] = [(0, None)]  # (offset, weight), C order
    for j in range(d):
        f = w_u[:, j]
        g = 1.0 - f
        corners = [(off + b * strides[j], (f if b else g) if w is None else w * (f if b else g))
                   for off, w in corners for b in (0, 1)]
    idx = [k if off == 0 else k + off for off, _ in corners]
    # channel by channel, returned transposed (Fortran order): the solvers' reductions over the points of a velocity,
    # and of the points it moves, then run along contiguous columns; the solvers pass points computed for the call,
    # so u is overwritten rather than copied
    out = np.empty((len(flat), len(u)), dtype=dtype)
    for plane, acc in zip(flat.astype(dtype, copy=False), out):
        np.take(plane, idx[0], out=acc)
        acc *= corners[0][1]
        for at, (_, w) in zip(idx[1:], corners[1:]):
            acc += np.take(plane, at) * w
    return out.T


def interpolate(values, points, *, tol: float = 1e-9, check: bool = True):
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
    check : bool
        Validate shapes and coordinates; ``False`` skips the checks (for callers in an inner loop whose points are
        known to be finite).  Either way coordinates are clamped to :math:`[0, 1]`.

    Returns
    -------
    Tensor or ndarray (same kind as ``values``), shape (B, P, C)
    """
    import torch

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
    if check:
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


@lru_cache(maxsize=16)
def _sobol_base(count: int, dim: int) -> np.ndarray:
    from scipy.stats import qmc

    pts = qmc.Sobol(d=dim, scramble=False).random_base2(int(math.ceil(math.log2(max(count, 2)))))[:count]
    pts.setflags(write=False)
    return pts


def jittered_points(
    n: int,
    dim: int,
    rng: np.random.Generator,
    *,
    grad_magnitude: np.ndarray | None = None,
    strength: float = 0.2,
) -> np.ndarray:
    r"""Sobol-jittered vertices of the ``N``-grid (paper Sec. 5: stochastic jittered sampling).

    Vertex :math:`x_v` moves to :math:`x_v + \text{strength}\cdot h\cdot g_v\,(2 s_v - 1)` where :math:`s_v` is a
    randomly shifted (Cranley–Patterson) Sobol point in :math:`[0,1]^d` and :math:`g_v \in [0, 1]` is the local
    gradient magnitude of the field normalised by its maximum (1 everywhere when ``grad_magnitude`` is ``None``).
    Boundary vertices only slide along the boundary and corners stay fixed, so the jittered mesh still tiles
    :math:`[0,1]^d`; with ``strength <= 0.2`` no element can flip.  (A Kuhn tetrahedron can degenerate once its
    vertices move :math:`h/6` per axis, so in 3D the offsets are scaled by 3/4 to keep that guarantee.)

    Returns
    -------
    ndarray, shape (N**d, d)
    """
    n = check_n(n)
    dim = check_dim(dim)
    if not 0 <= strength <= 0.2:
        raise ValueError(f"jitter strength must lie in [0, 0.2] (fraction of the grid spacing), got {strength}")
    pts = grid_points(n, dim)
    sob = (_sobol_base(pts.shape[0], dim) + rng.random(dim)) % 1.0
    sob = sob[rng.permutation(pts.shape[0])]
    off = (2 * sob - 1) * (strength if dim == 2 else 0.75 * strength) / (n - 1)
    if grad_magnitude is not None:
        g = np.abs(np.asarray(grad_magnitude, dtype=np.float64)).reshape(-1)
        if g.shape[0] != pts.shape[0]:
            raise ValueError(f"grad_magnitude has {g.shape[0]} values for {pts.shape[0]} vertices")
        g = g / g.max() if g.max() > 0 else g
        off = off * g[:, None]
    on_wall = (pts <= 0) | (pts >= 1)
    off[on_wall] = 0.0
    return np.clip(pts + off, 0.0, 1.0)
