r"""Flow-based density-equalizing maps (Gastner, Seguy & More 2018) on the unit square and cube.

Instead of letting the density diffuse, the flow-based method prescribes its history: the density is interpolated
linearly in time between the input :math:`\rho_0` and its mean :math:`\bar\rho`,

.. math:: \rho_t(x) = (1 - t)\,\rho_0(x) + t\,\bar\rho, \qquad 0 \le t \le 1 .

The continuity equation :math:`\partial_t\rho_t + \nabla\cdot(\rho_t v) = 0` then asks for a flux
:math:`\rho_t v = -\nabla\phi` with

.. math:: \Delta\phi = \bar\rho - \rho_0, \qquad \partial_n\phi = 0 \text{ on the walls},

which does not depend on :math:`t`: one Poisson solve gives the velocity :math:`v(x, t) = -\nabla\phi(x)/\rho_t(x)`
at every time.  Every vertex is carried by :math:`\dot x = v(x, t)` from :math:`t = 0` to :math:`t = 1`; at
:math:`t = 1` the density is uniform and the vertex positions define the map.  The flow ends at a finite time
(the diffusion flow only approaches its end as :math:`t \to \infty`), which is why the method is fast.

Numerical method:

1. **Density raster.**  As in ``rfmap.solvers.diffusion``: the piecewise-linear (P1) interpolant of the vertex
   densities sampled on a grid ``refine`` times finer (``rfmap.solvers.diffusion.p1_upsample``), ``M`` points
   per side of the box.
2. **Poisson solve.**  With the cosine coefficients :math:`a_k` of the raster (type-I DCT,
   ``rfmap.solvers.diffusion.cosine_coefficients``), :math:`\phi_k = a_k / (\pi^2 |k|^2)` for
   :math:`k \ne 0`; the flux :math:`-\nabla\phi` is evaluated on the raster by inverse type-I DCTs along the cosine
   axes and a type-I DST along the differentiated axis (:func:`poisson_flux`), :math:`O(M^d \log M)`.  Its normal
   component vanishes exactly on the walls (no-flux).
3. **Velocity at a point.**  The flux and :math:`\rho_0` are interpolated multilinearly at the vertex and
   :math:`v = -\nabla\phi / ((1-t)\rho_0 + t\bar\rho)` is formed there.  The Poisson solve and this table are
   single precision (a relative error of about 1e-7, far below a step's tolerance, at half the transform time and
   a tenth of the interpolation time of double precision); the vertex positions are integrated in double.
4. **Time steps.**  Predictor–corrector (Heun) steps, :math:`x^* = x + \Delta t\, v(x, t)`,
   :math:`x' = x + \tfrac{\Delta t}{2}\,(v(x, t) + v(x^*, t + \Delta t))`.  A step is accepted when the
   predictor–corrector difference :math:`\max|x' - x^*|` is at most ``rtol`` grid spacings *and* no element of the
   mesh has turned over (all signed measures stay positive; decided in single precision unless the smallest
   measure is too close to zero for it, :data:`F32_MARGIN`); otherwise it is retried with a smaller
   :math:`\Delta t`.  The step then grows or shrinks with the usual rule for an embedded first/second-order pair.
   A density jump sharper than the mesh can make the sampled velocity squeeze one element to zero measure in finite
   time, so that no step, however short, is accepted; when the step falls below ``STALL_DT`` the pass is redone
   with the density blurred over 1, 2, then 4 vertex spacings (``STALL_BLURS``; recorded in ``info["stall_blurs"]``)
   and later passes correct the residual the blur leaves.
5. **Passes.**  Interpolation and time-stepping leave a residual.  After a pass the density that remains on the
   mapped mesh, :math:`\tilde\rho_e = \text{population}_e / |T(e)|` (population of the element over its mapped
   measure), is turned into the P1 vertex field whose element means match it (:func:`vertex_residual`) and
   rasterized by locating every raster node in the mapped mesh and interpolating linearly in its element
   (:func:`rasterize_elements`); the next pass moves the mapped vertices by the flow of that density, composing the
   maps.  Passes stop when :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` is below ``tol`` or stops improving (by
   less than ``stall``).

Boundary conditions follow ``rfmap.solvers.diffusion.solve_dem``: ``"square"`` keeps the walls (boundary
vertices slide, corners stay); ``"free"`` embeds the square in :math:`[-L, 1+L]^d` filled with a sea whose level is
balanced so that the domain keeps its measure (``_balanced_sea``), and later passes fill the sea with the domain's
mean residual density.  The flow's velocity :math:`-\nabla\phi/\rho_t` carries the density's jumps into the map,
and a steep jump from a dense coast to the sea can squeeze a coastal element to zero measure: on held-out fields
with a steep ramp against the coast (``rfmap.validation``) the pass stalls, its blurred retries (below) leave much of
the density unequalized, and the flow ends 9-24 times above the diffusion solver's Std(rho~_map) at 2D N = 256 and
4-5 times at 3D N = 48.  A stalled first pass of a free boundary is therefore first redone with a sea that starts at
the coast's own density and blends to its level (``stall_blend``); ``sea_blend`` asks for that sea from the start
(see ``solve_flow``).

The same passes finish any fold-free starting map (``start``): the first pass then flows the residual density of
the starting map.  :mod:`rfmap.hybrid` uses this to polish a neural surrogate's map.

References
----------
M. T. Gastner, V. Seguy, P. More, "Fast flow-based algorithm for creating density-equalizing map projections",
Proc. Natl. Acad. Sci. USA 115(10), E2156–E2164 (2018).
"""
from __future__ import annotations

import itertools
import math
import numbers
import time

import numpy as np
import torch
from scipy.fft import dct, dctn, dst

from ..geometry import grid_cell_simplices, grid_element_mean, grid_min_measure, grid_signed_measures
from ..mesh import grid_mesh
from ..result import MapResult
from .diffusion import DEM_BOUNDARIES, _balanced_sea, _check_grid_density, _torch_threads, cosine_coefficients, \
    fft_workers, p1_upsample

__all__ = ["STALL_BLEND", "solve_flow", "poisson_flux", "box_mean", "rasterize_elements", "residual_density",
           "lumped_residual", "vertex_residual"]


def _dct1(x: np.ndarray, axis: int) -> np.ndarray:
    r"""Unnormalised type-I DCT along ``axis`` (may overwrite ``x``): :math:`\sum_k e_k x_k \cos(\pi k j/(M-1))` at the
    nodes ``j``, with :math:`e_k = 1` at both ends and 2 inside."""
    return dct(x, type=1, axis=axis, workers=fft_workers(), overwrite_x=True)


def gaussian_blur(values: np.ndarray, sigma: float) -> np.ndarray:
    r"""Gaussian blur of width ``sigma`` (box units) with mirror walls: the cosine coefficients are multiplied by
    :math:`e^{-\pi^2|k|^2\sigma^2/2}` (the heat kernel at time :math:`\sigma^2/2`); the mean is kept.

    Parameters
    ----------
    values : ndarray, shape (M,)*d
    sigma : float

    Returns
    -------
    ndarray, shape (M,)*d
    """
    d, m = values.ndim, values.shape[0]
    y = dctn(values, type=1, workers=fft_workers())
    g = np.exp(-0.5 * (math.pi * sigma * np.arange(m)) ** 2)
    for ax in range(d):
        shape = [1] * d
        shape[ax] = m
        y = y * g.reshape(shape)
    return dctn(y, type=1, workers=fft_workers()) / (2.0 * (m - 1)) ** d


def box_mean(values: np.ndarray) -> float:
    r"""Mean over :math:`[0,1]^d` of the cosine interpolant of grid values: its zero coefficient :math:`a_0`, which
    is the trapezoidal mean (end nodes weighted half along every axis) — without the transform.

    Parameters
    ----------
    values : ndarray, shape (M,)*d

    Returns
    -------
    float
    """
    v = np.asarray(values, dtype=np.float64)
    for _ in range(v.ndim):  # reduce the leading axis each time
        v = (v.sum(0) - 0.5 * (v[0] + v[-1])) / (v.shape[0] - 1)
    return float(v)


def poisson_flux(values: np.ndarray, dtype=np.float64) -> np.ndarray:
    r"""The flux :math:`-\nabla\phi` of :math:`\Delta\phi = \bar\rho - \rho_0` with no-flux walls on :math:`[0,1]^d`.

    :math:`\rho_0` is the cosine interpolant of the grid values (coefficients :math:`a_k`); then
    :math:`\phi = \sum_{k \ne 0} \frac{a_k}{\pi^2|k|^2} \prod_i \cos(\pi k_i x_i)` and
    :math:`-\partial_i\phi = \sum_k \frac{a_k\,\pi k_i}{\pi^2 |k|^2} \sin(\pi k_i x_i) \prod_{j\ne i}\cos(\pi k_j x_j)`.

    Parameters
    ----------
    values : ndarray, shape (M,)*d
        Density at the grid nodes :math:`j/(M-1)` of :math:`[0,1]^d`.
    dtype : numpy dtype
        Precision of the transforms (``np.float32`` halves their time; the flow uses it).

    Returns
    -------
    ndarray, shape (d, M, ..., M), of ``dtype``
        The flux components on the grid; the normal component is exactly zero on the walls.
    """
    d, m = values.ndim, values.shape[0]
    b = _half_coefficients(values, dtype)
    b /= _eigenvalues(d, m, b.dtype)
    b.flat[0] = 0.0
    return _flux_synthesis(b)


def _half_coefficients(values: np.ndarray, dtype=np.float64) -> np.ndarray:
    r""":math:`b_k = \mathrm{DCT\text{-}I}(p)_k / (2(M-1))^d` (unnormalised transform) of grid values ``p``: the cosine
    coefficients :math:`a_k` of their interpolant with every interior index halved per axis (:math:`a_k = e_k b_k`,
    :math:`e_k = 1` at the ends and 2 inside).  A type-I DCT of :math:`b` along an axis is the cosine synthesis
    along it (:func:`_dct1`).  Shape (M,)*d, of ``dtype``."""
    d, m = values.ndim, values.shape[0]
    y = dctn(np.asarray(values, dtype=dtype), type=1, workers=fft_workers())
    y *= y.dtype.type(1.0 / (2.0 * (m - 1)) ** d)
    return y


def _eigenvalues(d: int, m: int, dtype=np.float64) -> np.ndarray:
    r"""The Laplacian's eigenvalues :math:`\pi^2|k|^2` of the cosine modes, shape (M,)*d, with 1 at :math:`k = 0`
    (so that it can divide)."""
    k2 = (math.pi * np.arange(m, dtype=np.float64)) ** 2
    lam = np.zeros((m,) * d, dtype=dtype)
    for ax in range(d):
        lam += k2.astype(dtype).reshape([m if j == ax else 1 for j in range(d)])
    lam.flat[0] = 1.0
    return lam


def _flux_synthesis(b: np.ndarray) -> np.ndarray:
    r"""The flux :math:`-\nabla\psi` at the grid nodes of the potential :math:`\psi = \sum_k e_k b_k \prod_i
    \cos(\pi k_i x_i)` given by its half coefficients ``b`` (:func:`_half_coefficients`; consumed), shape (d, M..).

    :math:`-\partial_i\psi = \sum_k e_k b_k\,\pi k_i \sin(\pi k_i x_i) \prod_{j\ne i}\cos(\pi k_j x_j)`: cosine
    syntheses along the other axes and, along axis ``i``, the type-I DST of the interior coefficients (only interior
    :math:`k_i` contribute; zero on both walls).  Transforms along an axis commute with factors along another, so the
    cosine syntheses are shared between the components: in 3D eight one-axis transforms, and no transposed copies.
    """
    d, m = b.ndim, b.shape[0]
    k = (math.pi * np.arange(m)).astype(b.dtype)
    out = np.empty((d,) + (m,) * d, dtype=b.dtype)

    def deriv(g: np.ndarray, i: int) -> None:  # out[i]: the sine synthesis along axis i of g * pi k_i
        inner = tuple(slice(1, m - 1) if j == i else slice(None) for j in range(d))
        wall = [slice(None)] * d
        for end in (0, m - 1):
            wall[i] = end
            out[i][tuple(wall)] = 0.0
        g = g[inner] * k[1:-1].reshape([m - 2 if j == i else 1 for j in range(d)])
        out[i][inner] = dst(g, type=1, axis=i, workers=fft_workers(), overwrite_x=True)

    if d == 2:
        deriv(_dct1(b.copy(), 1), 0)
        deriv(_dct1(b, 0), 1)
        return out
    p2 = _dct1(b.copy(), 2)  # cosine along axis 2: shared by components 0 and 1
    deriv(_dct1(p2.copy(), 1), 0)
    deriv(_dct1(p2, 0), 1)
    deriv(_dct1(_dct1(b, 0), 1), 2)
    return out


def _node_boxes(P: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest ``M``-grid node index per axis inside each element's bounding box, (e, d) each."""
    s = m - 1
    eps = 1e-9
    lo = np.clip(np.ceil(P.min(1) * s - eps).astype(np.int64), 0, s)
    hi = np.clip(np.floor(P.max(1) * s + eps).astype(np.int64), 0, s)
    return lo, hi


def _locate(points: np.ndarray, elements: np.ndarray, m: int, chunk: int, subset: np.ndarray | None = None):
    r"""Yield ``(node, element, lam)`` chunks: flat indices of the ``M``-grid nodes of :math:`[0,1]^d` inside an
    element, that element, and the node's barycentric coordinates :math:`\lambda_1..\lambda_d` in it (shape (k, d)).
    A node on a shared face appears once per element that contains it.  ``subset``: element indices to scan
    (default all)."""
    d = points.shape[1]
    s = m - 1
    P = points[elements]  # (e, d+1, d)
    lo, hi = _node_boxes(P, m)
    ext = np.maximum(hi - lo + 1, 0)
    count = ext.prod(1)
    if subset is not None:
        chosen = np.zeros(len(count), dtype=bool)
        chosen[subset] = True
        count = np.where(chosen, count, 0)
    keep = np.nonzero(count)[0]
    strides = np.array([m ** (d - 1 - a) for a in range(d)], dtype=np.int64)
    ends = np.cumsum(count[keep])
    start = 0
    while start < keep.size:  # chunks of whole elements with about `chunk` pairs each
        stop = max(start + 1, int(np.searchsorted(ends, (ends[start - 1] if start else 0) + chunk)))
        sel = keep[start:stop]
        E = np.swapaxes(P[sel, 1:] - P[sel, :1], 1, 2)  # columns are the edge vectors
        Einv = np.linalg.inv(E)
        c = count[sel]
        owner = np.repeat(np.arange(sel.size), c)
        r = np.arange(owner.size) - np.repeat(np.cumsum(c) - c, c)
        ext_o = ext[sel][owner]
        lo_o = lo[sel][owner]
        rel = np.empty((owner.size, d))
        flat = np.zeros(owner.size, dtype=np.int64)
        for ax in range(d - 1, -1, -1):  # mixed-radix digits of the local index
            node = r % ext_o[:, ax] + lo_o[:, ax]
            r //= ext_o[:, ax]
            flat += node * strides[ax]
            rel[:, ax] = node / s - P[sel, 0, ax][owner]
        lam = np.einsum("pij,pj->pi", Einv[owner], rel)
        inside = (lam >= -1e-10).all(1) & (lam.sum(1) <= 1 + 1e-10)
        yield flat[inside], sel[owner[inside]], lam[inside]
        start = stop


def _barycentric(coords: list[np.ndarray], vid: np.ndarray, y: list[np.ndarray]) -> list[np.ndarray]:
    r""":math:`\lambda_1..\lambda_d` (d arrays, (k,) each) of the points ``y`` in the simplices of vertices ``vid``
    (k, d+1), by Cramer's rule.  ``coords``: the d vertex coordinate arrays (each contiguous, (n,)); ``y``: the d
    point coordinate arrays (each (k,)).  Gathering one coordinate at a time keeps every operand contiguous (about
    4x faster than gathering (k, d+1, d) vertex blocks)."""
    d = len(coords)
    p0 = [c[vid[:, 0]] for c in coords]
    e = [[c[vid[:, i]] - q for c, q in zip(coords, p0)] for i in range(1, d + 1)]
    r = [ya - q for ya, q in zip(y, p0)]
    if d == 2:
        (ax, ay), (bx, by) = e
        det = ax * by - ay * bx
        return [(r[0] * by - r[1] * bx) / det, (ax * r[1] - ay * r[0]) / det]
    e1, e2, e3 = e

    def cross(a, b):
        return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])

    def dot(a, b):
        return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]

    c23 = cross(e2, e3)
    det = dot(e1, c23)
    return [dot(r, c23) / det, dot(r, cross(e3, e1)) / det, dot(r, cross(e1, e2)) / det]


def _kuhn_lookup() -> np.ndarray:
    """Simplex type (index into ``grid_cell_simplices(3)``) of a point of the unit cube from the three comparisons
    ``(f0 >= f1, f0 >= f2, f1 >= f2)`` of its coordinates, packed as a 3-bit code; the Kuhn tetrahedron of the
    permutation sigma holds the points with ``f[sigma_1] >= f[sigma_2] >= f[sigma_3]``."""
    lut = np.zeros(8, dtype=np.int64)
    for i, perm in enumerate(itertools.permutations(range(3))):
        rank = {ax: r for r, ax in enumerate(perm)}
        code = 4 * (rank[0] < rank[1]) + 2 * (rank[0] < rank[2]) + (rank[1] < rank[2])
        lut[code] = i
    return lut


_KUHN = _kuhn_lookup()

#: Newton steps of the grid walk of :func:`rasterize_elements` before a node is handed to the element scan
WALK_STEPS = 6
#: The walk of an ``M``-grid starts from the inverse map found on a grid about this many times coarser ...
WALK_COARSE = 4
#: ... when that grid has at least this many nodes per side
WALK_COARSE_MIN = 9
#: :func:`rasterize_elements` walks when the mesh's measure is at least this fraction of its bounding box's (the
#: nodes the walk gives up on go to the element scan, so the result is the same either way).  A free boundary's
#: mapped cube fills about 0.68 of its box (dem3d-free, N = 48): walking there instead of scanning every element
#: locates the 143^3 raster in 1.6-1.7 s instead of 2.0-2.7 s; the warm starts of the 2D and 3D free-boundary
#: hybrids (paper fields and two unseen ones, 2D N = 256, 3D N = 48) got 6 % faster, with identical maps
WALK_FILL = 0.5


def _simplex_frames(d: int) -> tuple[np.ndarray, np.ndarray]:
    """Corner offsets (S, d+1, d) of the simplex types of a grid cell and their edge matrices (S, d, d), columns
    the edges from the first corner."""
    types = np.array(grid_cell_simplices(d))
    return types, np.swapaxes(types[:, 1:] - types[:, :1], 1, 2).astype(np.float64)


def _reference_points(cell: np.ndarray, t: np.ndarray, lam: np.ndarray, s: int) -> np.ndarray:
    r"""Points :math:`x = X_0 + \sum_i \lambda_i (X_i - X_0)` (k, d) of the unit box: barycentric coordinates
    ``lam`` (k, d) in the simplex of type ``t`` (k,) of the grid cells ``cell`` (k, d) of an ``s``-cell grid."""
    types, edges = _simplex_frames(cell.shape[1])
    return (cell + types[t, 0] + np.einsum("kij,kj->ki", edges[t], lam)) / s


def _box_guess(points: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The points ``y`` (k, d) taken back to the unit box by the affine map of the mesh's bounding box."""
    low, high = points.min(0), points.max(0)
    return np.clip((y - low) / (high - low), 0.0, 1.0)


def _inverse_guess(points: np.ndarray, n: int, mc: int, steps: int, y: np.ndarray) -> np.ndarray:
    r"""Reference points :math:`x \approx u^{-1}(y)` of the nodes ``y`` (k, d) of a fold-free map ``points`` of the
    ``N``-grid mesh: the walk of :func:`_walk_grid` on the ``mc``-grid, its inverse map (the bounding-box guess
    at the nodes it did not find) interpolated multilinearly at ``y``, clipped to the unit box."""
    d = points.shape[1]
    s = n - 1
    (node, el, lam), _ = _walk_grid(points, n, mc, steps, coarse=1)
    yc = np.stack(np.meshgrid(*([np.linspace(0.0, 1.0, mc)] * d), indexing="ij"), -1).reshape(-1, d)
    xc = _box_guess(points, yc)
    t, cell = np.divmod(el, s**d)
    xc[node] = _reference_points(np.stack(np.unravel_index(cell, (s,) * d), -1), t, lam, s)
    table = torch.from_numpy(np.ascontiguousarray(xc.T.reshape(1, d, *(mc,) * d)))
    # grid_sample takes the last point coordinate along the last grid axis: reverse the axes
    q = torch.from_numpy(2.0 * y[:, ::-1] - 1.0).reshape(1, *([1] * (d - 1)), -1, d)
    x = torch.nn.functional.grid_sample(table, q, mode="bilinear", align_corners=True)
    return np.clip(x.reshape(d, -1).T.numpy(), 0.0, 1.0)


def _walk_grid(points: np.ndarray, n: int, m: int, steps: int = WALK_STEPS, coarse: int = WALK_COARSE):
    r"""Locate the ``M``-grid nodes in a fold-free map ``points`` (N**d, d) of the ``N``-grid mesh (elements in
    :func:`rfmap.mesh.grid_mesh` order) by Newton's method on the piecewise-linear map.

    A node :math:`y` starts at the reference point :math:`x` of the inverse map found by the same walk on a grid
    ``coarse`` times coarser (:func:`_inverse_guess`; at 3D N = 48 its first step finds four nodes in five, where
    the bounding-box guess leaves nearly all of them to four or five steps), or, on a coarse grid, at the point
    that the affine map of the mesh's bounding box onto the unit box gives.  The grid cell and simplex type
    holding :math:`x` give a mapped simplex, and the barycentric coordinates :math:`\lambda` of :math:`y` in it
    either lie in the simplex (found) or define the next reference point :math:`x = X_0 + \sum_i \lambda_i (X_i -
    X_0)`, the affine inverse of that simplex (a Newton step; clipped to the unit box).  Nodes outside the
    bounding box of the mapped mesh are not tried, and a node whose step leaves the unit box by more than a cell
    is given up (it is most likely outside the mesh, in a free boundary's sea).

    Returns
    -------
    (node, element, lam), left
        Flat node indices, their elements and barycentric coordinates (k, d); ``left``: the flat indices of the
        nodes inside the mesh's bounding box that were not found (given up, or not found in ``steps`` steps).
    """
    d = points.shape[1]
    s = n - 1
    types, _ = _simplex_frames(d)
    offsets = (types * n ** np.arange(d - 1, -1, -1)).sum(-1)  # (S, d+1): vertex index offsets in a cell

    def flat(ix: np.ndarray, side: int) -> np.ndarray:  # C-order flat index of integer coordinates (k, d)
        out = ix[:, 0].copy()
        for a in range(1, d):
            out *= side
            out += ix[:, a]
        return out

    lo, hi = _node_boxes(points[None], m)
    axes = [np.arange(lo[0, a], hi[0, a] + 1) for a in range(d)]
    idx = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, d)
    todo = flat(idx, m)
    y = idx / (m - 1)
    mc = (m - 1) // int(coarse) + 1
    if coarse > 1 and mc >= WALK_COARSE_MIN:  # start from the inverse map found on a coarser raster
        x = _inverse_guess(points, n, mc, steps, y)
    else:
        x = _box_guess(points, y)
    coords = [np.ascontiguousarray(points[:, a]) for a in range(d)]
    y = [np.ascontiguousarray(y[:, a]) for a in range(d)]
    found: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    gave_up: list[np.ndarray] = []
    for _ in range(int(steps)):
        if todo.size == 0:
            break
        xs = x * s
        cell = np.minimum(xs.astype(np.int64), s - 1)
        f = xs - cell
        if d == 2:
            t = (f[:, 0] + f[:, 1] > 1).astype(np.int64)
        else:
            t = _KUHN[4 * (f[:, 0] >= f[:, 1]) + 2 * (f[:, 0] >= f[:, 2]) + (f[:, 1] >= f[:, 2])]
        vid = flat(cell, n)[:, None] + offsets[t]  # (k, d+1)
        cols = _barycentric(coords, vid, y)
        inside = sum(cols) <= 1 + 1e-10
        for c in cols:
            inside &= c >= -1e-10
        if inside.any():
            found.append((todo[inside], t[inside] * s**d + flat(cell[inside], s),
                          np.stack([c[inside] for c in cols], 1)))
        out = ~inside
        t, lam = t[out], np.stack([c[out] for c in cols], 1)
        x = _reference_points(cell[out], t, lam, s)
        todo, y = todo[out], [ya[out] for ya in y]
        # a step that leaves the unit box by more than a cell points outside the mesh (a free boundary's sea)
        away = ((x < -1.0 / s) | (x > 1.0 + 1.0 / s)).any(1)
        if away.any():
            gave_up.append(todo[away])
            x, todo, y = x[~away], todo[~away], [ya[~away] for ya in y]
        np.clip(x, 0.0, 1.0, out=x)
    left = np.concatenate(gave_up + [todo])
    if not found:
        return (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, d))), left
    return tuple(np.concatenate(a) for a in zip(*found)), left


def _boxes_holding(mask: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Whether each box ``[lo, hi]`` (e, d) of ``M``-grid node indices holds a ``True`` node of ``mask`` (summed-area
    table; inclusion-exclusion over the 2^d corners)."""
    d = mask.ndim
    sat = np.pad(mask.astype(np.int64), [(1, 0)] * d)
    for a in range(d):
        sat = np.cumsum(sat, axis=a)
    total = np.zeros(len(lo), dtype=np.int64)
    for corner in itertools.product((0, 1), repeat=d):
        ix = tuple(np.where(c, hi[:, a] + 1, lo[:, a]) for a, c in enumerate(corner))
        total += (-1) ** (d - sum(corner)) * sat[ix]
    return total > 0


def rasterize_elements(points: np.ndarray, elements: np.ndarray, values: np.ndarray, m: int,
                       fill: float, *, at: str = "elements", chunk: int = 1 << 20) -> np.ndarray:
    r"""Sample a field of a simplicial mesh at the nodes of the ``M``-grid of :math:`[0,1]^d`.

    Every element's bounding box is scanned for grid nodes and each node is tested with the element's barycentric
    coordinates :math:`\lambda = E^{-1}(y - p_0)` (inside when all :math:`\lambda_i \ge 0` and
    :math:`\sum\lambda_i \le 1`, up to round-off); the work is the total node count of the bounding boxes,
    vectorized in chunks of ``chunk`` (element, node) pairs.  When the mesh is a map of the ``N``-grid mesh
    (:func:`rfmap.mesh.grid_mesh`'s elements) that fills enough of its bounding box (:data:`WALK_FILL`: the square
    and cube boundaries, and the free boundary's mapped squares and cubes) the nodes are first located by a Newton
    walk on the grid (:func:`_walk_grid`, a few vectorized steps over the nodes instead of a scan over the elements;
    0.4 s against 1.6 s at 3D N = 48, ``M`` = 95), and only the elements whose boxes hold a node it did not find are
    scanned.

    * ``at="elements"``: ``values`` is piecewise constant, one value per element; a node on a shared face takes
      the value of one of its elements (which one depends on the element order, so a raster whose nodes sit on
      the mesh's faces is biased by up to half an element).
    * ``at="vertices"``: ``values`` is piecewise linear (P1), one value per vertex, and a node takes
      :math:`\sum_i \lambda_i v_i` of its element: continuous, so a node on a shared face gets the same value from
      every element.

    Parameters
    ----------
    points : ndarray, shape (n, d)
        Vertex positions in :math:`[0,1]^d` (a fold-free mesh).
    elements : ndarray, shape (e, d+1)
    values : ndarray, shape (e,) or (n,)
        One value per element or per vertex (``at``).
    m : int
        Grid nodes per side.
    fill : float
        Value of the nodes that no element covers.
    at : {"elements", "vertices"}

    Returns
    -------
    ndarray, shape (M,)*d
    """
    if at not in ("elements", "vertices"):
        raise ValueError(f"at must be 'elements' or 'vertices', got {at!r}")
    want = elements.shape[0] if at == "elements" else points.shape[0]
    values = np.asarray(values, dtype=np.float64)
    if values.shape != (want,):
        raise ValueError(f"values at the {at} must have shape ({want},), got {values.shape}")
    d = points.shape[1]
    out = np.full((m,) * d, float(fill))
    flat_out = out.reshape(-1)
    chunks = []
    n = _grid_side(points, elements)
    subset = None
    if n is not None:  # the walk pays where the mesh fills enough of its bounding box (WALK_FILL)
        span = points.max(0) - points.min(0)
        volume = float(grid_signed_measures(torch.from_numpy(np.ascontiguousarray(points))[None], n).sum())
        fills = volume >= WALK_FILL * float(np.prod(span))
        n = n if fills else None
    if n is not None:
        hit, left = _walk_grid(points, n, m)
        chunks.append(hit)
        subset = left[:0]
        if left.size:  # scan only the elements whose boxes hold a node the walk did not find
            mask = np.zeros(m**d, dtype=bool)
            mask[left] = True
            lo, hi = _node_boxes(points[elements], m)
            subset = np.nonzero(_boxes_holding(mask.reshape((m,) * d), lo, hi))[0]
    if subset is None or subset.size:
        chunks = itertools.chain(chunks, _locate(points, elements, m, chunk, subset))
    for node, el, lam in chunks:
        if at == "elements":
            flat_out[node] = values[el]
        else:
            v = values[elements[el]]  # (k, d+1)
            flat_out[node] = (1.0 - lam.sum(1)) * v[:, 0] + np.einsum("ki,ki->k", lam, v[:, 1:])
    return out


def _grid_side(points: np.ndarray, elements: np.ndarray) -> int | None:
    """``N`` when ``elements`` are those of :func:`rfmap.mesh.grid_mesh` ``(N, d)`` over ``N**d`` points, else
    ``None`` (the vertices may be anywhere: a map of the grid mesh)."""
    d = points.shape[1]
    n = int(round(points.shape[0] ** (1.0 / d)))
    if n < 2 or n**d != points.shape[0] or elements.shape != (math.factorial(d) * (n - 1) ** d, d + 1):
        return None
    return n if np.array_equal(elements, grid_mesh(n, d).elements) else None


def lumped_residual(elements: np.ndarray, population: np.ndarray, measure: np.ndarray, n: int) -> np.ndarray:
    r"""The residual density lumped onto the vertices: :math:`\sum_{e \ni v} \text{population}_e \,/\,
    \sum_{e \ni v} |T(e)|`, shape (n,): the measure-weighted mean of the element residuals
    :math:`\tilde\rho_e = \text{population}_e/|T(e)|` around each vertex.

    Parameters
    ----------
    elements : ndarray, shape (e, d+1)
    population : ndarray, shape (e,)
        Mass of each element (as in :func:`residual_density`).
    measure : ndarray, shape (e,)
        Measure of each mapped element :math:`|T(e)|` (positive; any common scale as ``population``'s).
    n : int
        Number of vertices.
    """
    mass = np.zeros(n)
    vol = np.zeros(n)
    for k in range(elements.shape[1]):
        mass += np.bincount(elements[:, k], weights=population, minlength=n)
        vol += np.bincount(elements[:, k], weights=measure, minlength=n)
    return mass / vol


#: conjugate-gradient iterations of :func:`vertex_residual` (from the lumped residual); with 10, a flow started at
#: the identity ends within 0.1 % of the cold flow's Std(rho~_map) (measured on smooth and sharp densities, N 17-65)
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
    ndarray, shape (n,)
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
    times measure, as in :mod:`rfmap.metrics`); :math:`|T(e)|` is the signed measure of the mapped element.
    """
    return density[elements].mean(1) * _measures(ref, elements) / _measures(mapped, elements)


#: the fold check of a step (:func:`rfmap.geometry.grid_min_measure`, with the same threshold) and
#: ``rfmap.surrogate.density_quality`` decide on float32 measures unless the smallest is below this fraction of the
#: reference element measure; float64 then decides (the float32 rounding error of a grid element's measure is about
#: 1e-6 / h of the mean, so this leaves a margin of about 20 at N = 1000)
F32_MARGIN = 1e-3


def _turned_over(x: np.ndarray, n: int) -> bool:
    """Whether an element of the ``N``-grid mesh with vertices at ``x`` (N**d, d) has non-positive measure
    (:func:`rfmap.geometry.grid_min_measure`: float32 unless the minimum is too close to zero for it, and only the
    minimum is formed)."""
    return grid_min_measure(x, n) <= 0.0


class _Stalled(RuntimeError):
    """A pass cannot advance: every step, however short, turns an element over (a collapsing element)."""


#: default step tolerance per dimension (grid spacings).  3D steps cost about ten times 2D ones; measured on the
#: paper's 3D fields and two unseen ones at N = 48, 0.4 instead of 0.2 takes 15 % less time for a Std(rho~_map) at
#: most 5 % higher (mean 1 %), while in 2D at N = 256 it would raise Std(rho~_map) by 4 % on average
RTOL = {2: 0.2, 3: 0.4}

#: default sea width L of the free boundary per dimension (the box is [-L, 1 + L]^d).  The diffusion solver's 0.5
#: (the sea as wide as the domain) in 2D; in 3D the transforms of the sea box are most of the flow's time, and
#: measured at N = 48 on the paper's 3D fields and two unseen ones (one thread), 0.25 instead of 0.5 takes 35-45 %
#: less time (0.91-1.35 s -> 0.63-0.79 s) for the same Std(rho~_map) (within 2 %), the maps differing by at most
#: 1.6 grid spacings (0.07-0.43 on all but the octant), less than the flow's own distance from the diffusion map
MARGIN = {2: 0.5, 3: 0.25}

#: Sea blend (``solve_flow(stall_blend=...)``) of the first remedy for a stalled first pass of a free boundary's cold
#: start, tried before the blurred retries (``STALL_BLURS``).  The width was chosen on the validation stream
#: (``rfmap.validation``, 16 fields at 2D N = 256, the blend applied from the start): mean Std(rho~_map) over the
#: diffusion solver's 6.34 (no blend), 1.195 (0.125), 1.150 (0.25), 1.151 (0.375), 1.178 (0.5).  On the report stream
#: (``rfmap.experiments.sea_blend_study``, chapter 10) the two of eight fields that stall, steep ramps pressing a
#: dense coast against the sea, went from 15-27 times diffusion's (blurred retries) to 0.9-1.0 times.  A pass that
#: does not stall keeps the diffusion solver's sea.
STALL_BLEND = 0.25

#: a pass stalls when the step falls below this (in units of the unit time interval)
STALL_DT = 1e-9
#: blur widths (vertex grid spacings) of the retries of a stalled pass
STALL_BLURS = (1.0, 2.0, 4.0)


class _FlowPass:
    """One pass of the flow: the flux of one density raster and the time integration from t = 0 to 1."""

    def __init__(self, raster: np.ndarray, sigma: float = 0.0):
        self.dim = raster.ndim
        self.m = raster.shape[0]
        if sigma > 0:
            raster = gaussian_blur(raster, sigma)
        self.mean = box_mean(raster)  # the box mean of the cosine interpolant
        # the velocity table in single precision: torch's grid_sample is vectorised for float32 only (3D, M = 95:
        # about 3 ms per evaluation against 38 ms in float64), and a relative error of 1e-7 in the velocity is far
        # below the step's own tolerance (rtol grid spacings); the positions are integrated in float64
        flux = poisson_flux(raster, dtype=np.float32)
        # channels first, grid axes reversed: grid_sample takes the last point coordinate along the last grid axis
        self.grid = torch.from_numpy(np.concatenate([flux, raster[None].astype(np.float32)]))[None]  # (1, d+1, M..)
        self.evaluations = 0

    def velocity(self, t: float, y: np.ndarray) -> np.ndarray:
        r""":math:`v(y, t) = -\nabla\phi(y) / ((1-t)\rho_0(y) + t\bar\rho)` at points (P, d) of the box."""
        self.evaluations += 1
        q = torch.from_numpy(y).float().flip(-1).mul_(2.0).sub_(1.0)  # float32 arithmetic: the table's precision
        # grid_sample runs its batch in parallel but one batch entry on one thread: split the points into one
        # batch entry per thread over the same (expanded, not copied) table; 3D N = 48 on 2 threads: 5.3 -> 2.7 ms
        k, p = max(1, torch.get_num_threads()), len(y)
        rows = -(-p // k)
        if rows * k != p:
            q = torch.cat([q, q.new_zeros(rows * k - p, self.dim)])
        q = q.reshape(k, *([1] * (self.dim - 1)), rows, self.dim)
        f = torch.nn.functional.grid_sample(self.grid.expand(k, *self.grid.shape[1:]), q, mode="bilinear",
                                            padding_mode="border", align_corners=True)
        f = f.reshape(k, self.dim + 1, rows).permute(0, 2, 1).reshape(k * rows, self.dim + 1)[:p]
        rho = f[:, -1] * (1.0 - t) + t * self.mean
        return (f[:, :-1] / rho[:, None]).numpy().astype(np.float64)

    def run(self, y: np.ndarray, turned_over, project, *, h: float, rtol: float, max_steps: int,
            bar) -> tuple[np.ndarray, dict]:
        t, dt = 0.0, 1e-2
        accepted = rejected = folds = 0
        k1 = self.velocity(0.0, y)
        while t < 1.0:
            if accepted + rejected >= max_steps:
                raise RuntimeError(f"flow map did not reach t = 1 in {max_steps} steps (t={t:.4g}); "
                                   "increase max_steps or rtol")
            dt = min(dt, 1.0 - t)
            if dt < STALL_DT:
                raise _Stalled(f"flow step fell below {STALL_DT:g} at t = {t:.4g} (a collapsing element)")
            y_pred = project(y + dt * k1)
            k2 = self.velocity(t + dt, y_pred)
            y_new = project(y + (0.5 * dt) * (k1 + k2))
            diff = y_new - y_pred
            err = math.sqrt(float(np.einsum("ij,ij->i", diff, diff).max())) / (rtol * h)
            folded = err <= 1.0 and turned_over(y_new)
            if err <= 1.0 and not folded:
                t = 1.0 if 1.0 - (t + dt) < 1e-12 else t + dt
                y = y_new
                accepted += 1
                if t < 1.0:
                    k1 = self.velocity(t, y)
                if bar is not None:
                    bar.n = round(t, 4)
                    bar.refresh()
                dt *= min(2.0, max(0.3, 0.9 / math.sqrt(max(err, 1e-12))))
            else:
                rejected += 1
                folds += int(folded)
                dt *= 0.5 if folded else max(0.2, 0.9 / math.sqrt(err))
        return y, {"steps": accepted, "rejected": rejected, "fold_rejections": folds}


def _sea_raster(dens: np.ndarray, pad: int, refine: int, blend: float) -> tuple[np.ndarray, float, float]:
    """The free boundary's first raster with its balanced sea (``rfmap.solvers.diffusion._balanced_sea``) blended
    over ``blend``, halved while the blended sea would not be positive (down to an eighth, then 0); returns the
    raster, the sea level and the blend used.  ``RuntimeError`` if even the abrupt sea cannot be balanced."""
    floor = blend / 8
    while True:
        raster, sea = _balanced_sea(dens, pad, refine, blend)
        if blend == 0 or (sea > 0 and raster.min() > 0):
            break
        blend = blend / 2 if blend > floor else 0.0
    if not sea > 0:
        raise RuntimeError(f"could not balance the sea density (got {sea:.4g})")
    return raster, float(sea), float(blend)


def solve_flow(
    density,
    *,
    boundary: str = "square",
    progress: bool = False,
    tol: float = 1e-3,
    rtol: float | None = None,
    refine: int = 2,
    margin: float | None = None,
    sea_blend: float = 0.0,
    stall_blend: float = STALL_BLEND,
    max_passes: int = 1,
    stall: float = 0.8,
    blur: float = 0.0,
    max_steps: int = 10_000,
    start=None,
    num_threads: int | None = None,
    stall_blurs: tuple[float, ...] = STALL_BLURS,
    keep_best: bool = True,
) -> MapResult:
    r"""Flow-based density-equalizing map (Gastner, Seguy & More 2018) of the unit square or cube.

    Every vertex follows :math:`\dot x = -\nabla\phi(x) / ((1-t)\rho_0(x) + t\bar\rho)` for :math:`0 \le t \le 1`,
    :math:`\Delta\phi = \bar\rho - \rho_0` with no-flux walls, in passes until the density left on the mapped mesh
    is uniform to ``tol`` (see the module docstring for the numerical method).

    Parameters
    ----------
    density : ndarray, shape (N, N) or (N, N, N)
        Vertex densities on the ``N``-grid (strictly positive, finite; any positive scale).  ``N >= 3``.
    boundary : {"square", "free"}
        As in ``rfmap.solvers.diffusion.solve_dem``: fixed walls of the unit square/cube, or a sea of the mean
        density around it in :math:`[-L, 1+L]^d`.
    progress : bool
        Show a ``tqdm`` progress bar over the time of each pass.
    tol : float
        Stop after the pass whose :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` is at most ``tol`` (no pass at all
        when the input's is); 0 leaves the passes to ``max_passes`` and ``stall`` (a caller with its own stopping
        rule, such as the passes of ``rfmap.cartogram.cartogram``, runs exactly one pass of a density that is not
        exactly uniform).
    rtol : float, optional
        Largest predictor–corrector difference of an accepted step, in grid spacings of the raster's box; default
        :data:`RTOL` of the dimension (0.2 in 2D, 0.4 in 3D).
    refine : int
        The density raster is ``refine`` times finer than the vertex grid (``M = refine (N_box - 1) + 1``).
    margin : float, optional
        Sea width :math:`L` for ``boundary="free"``, rounded to whole grid cells (at least one); default
        :data:`MARGIN` of the dimension (0.5 in 2D, 0.25 in 3D).
    sea_blend : float
        For ``boundary="free"``: the width (domain length units) over which the sea blends from the coast's density
        to its balanced level (``rfmap.solvers.diffusion._balanced_sea``); 0 (the default) starts the sea at the
        coast, as the diffusion solver does, so that both solve the same free-boundary problem.  A blend is a
        different sea, hence a different coastline, and it is not a uniform gain.  Measured against the diffusion
        solver's Std(rho~_map) with ``sea_blend=0.25``: on held-out validation fields the mean ratio fell from 6.34
        to 1.15 at 2D N = 256 (16 fields) and from 2.98 to 0.98 at 3D N = 48 (8 fields), the steep ramps from
        9-24x to 0.8-1.4x; box steps rose from 1.06-1.18x to 1.07-1.32x; on raw densities of contrast ~170 at
        N = 33 one field went from 1.5x to 8.4x (the blend carries a nearly empty coast into the sea); and the
        coastline moved up to 16 cells further from the diffusion map's at N = 256.  The width is halved while the
        blended sea would not be positive (down to an eighth of the request, then 0); the width used is
        ``info["sea_blend"]``.
    max_passes : int
        Most passes; the passes also stop when one lowers :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` by less than
        the factor ``stall`` (the map with the lowest value is returned).
    stall : float
        See ``max_passes``; in (0, 1].
    blur : float
        Width (in vertex grid spacings) of a Gaussian blur of the first pass's density (:func:`gaussian_blur`),
        halved at every further pass, as cartogram programs do to soften sharp edges; 0 turns it off.
    max_steps : int
        Most (accepted + rejected) steps of one pass; ``RuntimeError`` if exceeded, or if a pass still stalls
        with the density blurred over the last of ``stall_blurs``.
    start : ndarray, shape (N**d, d), optional
        A fold-free map of the grid's vertices to start from (for ``"square"`` inside the unit square/cube with
        boundary vertices on their walls; for ``"free"`` inside the sea box).  The first pass then flows the density
        that this map leaves on its image.
    stall_blurs : tuple of float
        Blur widths (vertex spacings) of the retries of a stalled pass (see the module docstring); ``()`` makes a
        stall a ``RuntimeError`` at once (the hybrid then starts cold rather than blur a warm start).
    stall_blend : float
        For the first pass of a free boundary's cold start with ``sea_blend=0``: when it stalls, it is first redone
        once with the sea blended over this width (:data:`STALL_BLEND`; ``info["sea_fallback"]``, and
        ``info["sea_blend"]`` the width used), and only then, if it stalls again, with blurred densities; 0 skips
        this remedy.
    num_threads : int, optional
        Torch threads for the interpolation and the element measures (restored afterwards); as in
        ``rfmap.solvers.diffusion.solve_dem``, default 1 in 2D and torch's setting in 3D.
    keep_best : bool
        Return the map with the lowest :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` among the start and the passes
        (default), or ``False``: the map of the last pass, even where it is worse (to study what a pass does).

    Returns
    -------
    MapResult
        ``kind="density"``, ``field`` the vertex densities (N**d,), ``time`` the wall-clock seconds; ``info`` holds
        ``method="flow"``, ``passes``, ``steps`` / ``rejected`` / ``fold_rejections`` / ``evaluations`` summed over
        the passes, ``std_history`` (:math:`\mathrm{Std}(\tilde\rho_{\text{map}})` after each pass, preceded by the
        starting map's), ``eval_grid`` (``M``), ``box_grid``, ``rtol`` (the step tolerance used), ``stall_blurs``
        (the blur widths, in vertex spacings, of passes redone after a stall; usually empty) and, for ``"free"``,
        ``sea_density``.

    Raises
    ------
    ValueError
        For a bad density (as ``rfmap.solvers.diffusion.solve_dem``), an unknown ``boundary``, non-positive
        ``tol``/``rtol``/``margin``/``refine``/``max_passes``, ``stall`` outside (0, 1], or a ``start`` of the wrong
        shape, with non-finite values, outside the box, or folded.
    """
    t_start = time.perf_counter()
    if boundary not in DEM_BOUNDARIES:
        raise ValueError(f"unknown boundary {boundary!r} for the flow solver; choose one of {DEM_BOUNDARIES}")
    dens = _check_grid_density(density)
    if rtol is None:
        rtol = RTOL[dens.ndim]
    if margin is None:
        margin = MARGIN[dens.ndim]
    for name, val in (("sea_blend", sea_blend), ("stall_blend", stall_blend), ("tol", tol)):
        if isinstance(val, bool) or not isinstance(val, numbers.Real) or not math.isfinite(val) or val < 0:
            raise ValueError(f"{name} must be a finite number >= 0, got {val!r}")
    sea_blend = float(sea_blend)
    for name, val in (("rtol", rtol), ("margin", margin), ("stall", stall)):
        if isinstance(val, bool) or not isinstance(val, numbers.Real) or not math.isfinite(val) or val <= 0:
            raise ValueError(f"{name} must be a positive finite number, got {val!r}")
    if stall > 1:
        raise ValueError(f"stall must lie in (0, 1], got {stall!r}")
    for name, val in (("refine", refine), ("max_passes", max_passes)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < 1:
            raise ValueError(f"{name} must be a positive integer, got {val!r}")
    d, n = dens.ndim, dens.shape[0]
    mesh = grid_mesh(n, d)
    ref, elements = mesh.points, mesh.elements
    field = dens.reshape(-1)

    sea = None
    if boundary == "square":
        pad, scale = 0, 1.0
    else:
        pad = max(1, int(round(margin * (n - 1))))
        scale = (n - 1 + 2 * pad) / (n - 1)
    shift = pad / (n - 1)
    nb = n + 2 * pad
    m = int(refine) * (nb - 1) + 1

    if boundary == "square":
        wall_idx = np.nonzero((ref == 0.0) | (ref == 1.0))
        wall_val = ref[wall_idx]

        def project(p: np.ndarray) -> np.ndarray:
            np.clip(p, 0.0, 1.0, out=p)
            p[wall_idx] = wall_val
            return p
    else:

        def project(p: np.ndarray) -> np.ndarray:
            return np.clip(p, 0.0, 1.0, out=p)

    def measures(x: np.ndarray) -> np.ndarray:
        return grid_signed_measures(torch.from_numpy(x)[None], n)[0].numpy()

    # populations: element means of the vertex density times the (equal) reference measures, by strided views
    pop = grid_element_mean(torch.from_numpy(field)[None], n, d)[0].numpy() / (math.factorial(d) * (n - 1) ** d)

    def std_of(x: np.ndarray) -> float:
        rho = pop / measures(x)
        rho = rho / rho.mean()
        return float(rho.std(ddof=1))

    if start is None:
        mapped = ref.copy()
        if boundary == "square":
            raster = p1_upsample(dens, int(refine))
        else:
            raster, sea, sea_blend = _sea_raster(dens, pad, int(refine), sea_blend)
    else:
        mapped = np.array(start, dtype=np.float64)
        if mapped.shape != ref.shape:
            raise ValueError(f"start must have shape {ref.shape}, got {mapped.shape}")
        if not np.isfinite(mapped).all():
            raise ValueError("start contains NaN or infinite values")
        y_chk = (mapped + shift) / scale
        if y_chk.min() < -1e-9 or y_chk.max() > 1 + 1e-9:
            raise ValueError(f"start leaves the box of the {boundary!r} boundary")
        if measures(mapped).min() <= 0:
            raise ValueError("start has folded (non-positively oriented) elements")
        raster = None
    # from the identity every element keeps its (equal) reference measure: Std of the populations, no measure pass
    history = [float((pop / pop.mean()).std(ddof=1)) if start is None else std_of(mapped)]
    best, best_std = mapped, history[0]

    totals = {"steps": 0, "rejected": 0, "fold_rejections": 0, "evaluations": 0}
    stall_retries: list[float] = []
    sea_fallback = False  # whether a stalled first pass was redone with a blended sea
    fallback_tried = False
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=1.0, desc=f"flow {d}D N={n}", leave=False,
                   bar_format="{l_bar}{bar}| t={n:.4f}/1 [{elapsed}<{remaining}]")
    passes = 0
    threads = num_threads if num_threads is not None else (1 if d == 2 else None)
    try:
        with _torch_threads(threads):
            while passes < max_passes and best_std > tol:
                y = project((mapped + shift) / scale)
                if raster is None:  # the residual density of the current map, located exactly on the raster
                    meas = measures(mapped)
                    rho = pop / meas
                    fill = 1.0
                    if boundary == "free":  # the sea: the domain's mean residual density
                        fill = float((rho * meas).sum() / meas.sum())
                    vert = vertex_residual(elements, pop, meas, len(mapped))
                    raster = rasterize_elements(y, elements, vert / rho.mean(), m, fill / rho.mean(),
                                                at="vertices")
                if bar is not None:
                    bar.set_description(f"flow {d}D N={n} pass {passes + 1}")
                    bar.n = 0
                    bar.refresh()
                width = blur * 0.5 ** passes
                retry = 0
                while True:
                    fp = _FlowPass(raster, width / (n - 1) / scale)
                    try:
                        y_next, info = fp.run(y, lambda x: _turned_over(x, n), project, h=1.0 / (nb - 1),
                                              rtol=float(rtol), max_steps=int(max_steps), bar=bar)
                    except _Stalled as exc:
                        totals["evaluations"] += fp.evaluations
                        if (boundary == "free" and start is None and passes == 0 and sea_blend == 0
                                and stall_blend > 0 and not fallback_tried):
                            fallback_tried = True
                            # first remedy: the coast's jump to the sea is what collapses an element; blend it
                            raster, sea, sea_blend = _sea_raster(dens, pad, int(refine), stall_blend)
                            sea_fallback = sea_blend > 0
                            if sea_fallback:
                                continue
                        if retry == len(stall_blurs):
                            raise RuntimeError(f"flow map stalled with the density blurred over {width:g} grid "
                                               f"spacings: {exc}") from None
                        # a density jump sharper than the mesh: blur it (as cartogram programs do) and redo the pass
                        width = max(width, stall_blurs[retry])
                        stall_retries.append(width)
                        retry += 1
                        continue
                    break
                y = y_next
                for k in ("steps", "rejected", "fold_rejections"):
                    totals[k] += info[k]
                totals["evaluations"] += fp.evaluations
                passes += 1
                raster = None
                mapped = y * scale - shift
                if boundary == "square":
                    mapped = project(mapped)
                history.append(std_of(mapped))
                if history[-1] < best_std:
                    best, best_std = mapped, history[-1]
                if not history[-1] < stall * history[-2]:
                    break
    finally:
        if bar is not None:
            bar.close()
    elapsed = time.perf_counter() - t_start
    info = {"method": "flow", "boundary": boundary, "n": n, "dim": d, "passes": passes, **totals,
            "std_history": history, "warm_start": start is not None, "eval_grid": m, "box_grid": nb,
            "rtol": float(rtol), "stall_blurs": stall_retries}
    if sea is not None:
        info["sea_density"] = sea
        info["sea_blend"] = float(sea_blend)
        info["sea_fallback"] = sea_fallback
    return MapResult(ref_points=ref, mapped_points=best if keep_best else mapped, elements=elements, field=field,
                     kind="density", time=elapsed, info=info)
