r"""Point location in a mapped mesh: the element and barycentric coordinates of every node of a regular grid.

The flow-based solver samples the density that a map leaves on its image at the nodes of its raster
(:func:`rasterize_elements`).  Nodes are found either by scanning every element's bounding box (any simplicial
mesh) or, for a map of the ``N``-grid mesh that fills its bounding box, by a Newton walk on the grid that starts
from the inverse map found on a coarser grid; the nodes the walk gives up on go to the scan, so the result is the
same either way.
"""
from __future__ import annotations

import itertools
import math

import numpy as np
import torch

from ..core.geometry import grid_cell_simplices, grid_signed_measures
from ..core.mesh import grid_mesh

__all__ = ["rasterize_elements", "WALK_STEPS", "WALK_COARSE", "WALK_COARSE_MIN", "WALK_FILL"]


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
    (k, d+1), by Cramer's rule.  ``coords``: the d vertex coordinate arrays (each contiguous, (P,)); ``y``: the d
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


#: Newton steps of the grid walk of :func:`rasterize_elements` before a node is handed to the element scan.
WALK_STEPS = 6


#: The walk of an ``M``-grid starts from the inverse map found on a grid about this many times coarser, when that
#: grid has at least :data:`WALK_COARSE_MIN` nodes per side.
WALK_COARSE = 4


#: The fewest nodes per side of the coarser grid from which the walk starts (:data:`WALK_COARSE`).
WALK_COARSE_MIN = 9


#: :func:`rasterize_elements` walks when the mesh's measure is at least this fraction of its bounding box's (the
#: nodes the walk gives up on go to the element scan, so the result is the same either way): a free boundary's
#: mapped cube fills most of its box, where walking is faster than scanning (:doc:`Design decisions </book/design>`).
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
    ``N``-grid mesh: the walk of ``_walk_grid`` on the ``mc``-grid, its inverse map (the bounding-box guess
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
    :func:`rfmap.core.mesh.grid_mesh` order) by Newton's method on the piecewise-linear map.

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
    (:func:`rfmap.core.mesh.grid_mesh`'s elements) that fills enough of its bounding box (:data:`WALK_FILL`: the square
    and cube boundaries, and the free boundary's mapped squares and cubes) the nodes are first located by a Newton
    walk on the grid (a few vectorized steps over the nodes instead of a scan over the elements;
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
    points : ndarray, shape (P, d)
        Vertex positions in :math:`[0,1]^d` (a fold-free mesh).
    elements : ndarray, shape (e, d+1)
    values : ndarray, shape (e,) or (P,)
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
    """``N`` when ``elements`` are those of :func:`rfmap.core.mesh.grid_mesh` ``(N, d)`` over ``N**d`` points, else
    ``None`` (the vertices may be anywhere: a map of the grid mesh)."""
    d = points.shape[1]
    n = int(round(points.shape[0] ** (1.0 / d)))
    if n < 2 or n**d != points.shape[0] or elements.shape != (math.factorial(d) * (n - 1) ** d, d + 1):
        return None
    return n if np.array_equal(elements, grid_mesh(n, d).elements) else None
