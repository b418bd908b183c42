r"""The boundary of a mesh (the surface of a tetrahedral mesh, the outline of a 2D grid) and its self-intersections.

A piecewise-linear map of a tetrahedral mesh of a ball with every tetrahedron positively oriented is injective when
its restriction to the boundary surface is (a locally injective map that is injective on the boundary of a ball is
a homeomorphism onto the region the boundary image encloses).  With a fixed or sliding cube boundary the boundary
image is the cube's own surface and nothing more needs checking; with a free boundary two far-apart parts of the
surface could be pushed through each other while every tetrahedron stays positive.  This module finds such
crossings:

* :func:`boundary_faces`: the triangles that belong to exactly one tetrahedron, oriented outwards.
* :func:`surface_intersections`: pairs of triangles of a triangulated surface that intersect, leaving out pairs
  that share a vertex (they meet there by construction): a crossing between two triangles that share a vertex is
  therefore not detected.  A uniform-grid broad phase (cell side the median
  bounding-box extent) pairs triangles whose boxes overlap; the narrow phase is the interval test of Möller (1997):
  two non-coplanar triangles intersect when each straddles the other's plane and the two intervals they cut from
  the planes' common line overlap; (nearly) coplanar pairs are projected onto the plane and tested for properly
  crossing edges or a vertex strictly inside the other triangle.  Touching counts as intersecting only beyond a
  relative tolerance ``tol`` of the surface's size, so a surface on the faces of the unit cube (the identity map)
  has no intersection.

* :func:`grid_surface_intersections`: the same for the boundary of the 3D grid mesh, with a fast path that
  certifies each face of the cube by its projection on the face's own plane (positive triangles and a simple
  outline make the projection, hence the face's image, injective) and then searches only pairs of triangles from
  different faces; it falls back to :func:`surface_intersections` when a face fails.  This is what the repair uses.
* :func:`boundary_loop` and :func:`boundary_crossings`: the boundary polygon of the 2D grid and its crossing edges,
  the 2D counterpart (a free 2D boundary must be a simple polygon).

Cost: linear in the number of triangles for a surface without wild differences in triangle size.

References
----------
Tomas Möller, "A fast triangle-triangle intersection test", J. Graphics Tools 2(2), 25–30
(1997).
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from .mesh import grid_mesh, grid_points

__all__ = ["boundary_faces", "surface_intersections", "grid_boundary_faces", "grid_surface_intersections",
           "boundary_loop", "boundary_crossings"]


def boundary_faces(elements: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
    """Faces of a tetrahedral mesh that belong to one tetrahedron only, shape (f, 3).

    The face opposite vertex ``i`` of a positive tetrahedron ``(v0, v1, v2, v3)`` is listed in the order that makes
    its normal point out of the tetrahedron: ``(v1, v2, v3)``, ``(v0, v3, v2)``, ``(v0, v1, v3)``, ``(v0, v2, v1)`` for
    ``i`` = 0, 1, 2, 3.

    Parameters
    ----------
    elements : int ndarray, shape (m, 4)
        Tetrahedra, positively oriented.
    points : ndarray, shape (P, 3), optional
        Not needed for the faces; when given, each face is oriented with its normal pointing out of its tetrahedron
        (checked on these points).
    """
    el = np.asarray(elements)
    if el.ndim != 2 or el.shape[1] != 4:
        raise ValueError(f"boundary_faces needs tetrahedra of shape (m, 4), got {el.shape}")
    # outward faces of a positively oriented tetrahedron (v0, v1, v2, v3)
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    faces = el[:, local].reshape(-1, 3)
    srt = np.sort(faces, axis=1).astype(np.int64)
    nv = int(el.max()) + 1
    key = (srt[:, 0] * nv + srt[:, 1]) * nv + srt[:, 2]  # exact for meshes of up to 2 million vertices
    if nv > 2_000_000:
        raise ValueError(f"boundary_faces supports meshes of up to 2,000,000 vertices, got {nv}")
    order = np.argsort(key, kind="stable")
    ks = key[order]
    first = np.r_[True, ks[1:] != ks[:-1]]
    last = np.r_[ks[1:] != ks[:-1], True]
    single = np.sort(order[first & last])
    out = faces[single]
    if points is not None:
        p = np.asarray(points, np.float64)
        cen = p[el].mean(1)
        owner = single // 4
        n = np.cross(p[out[:, 1]] - p[out[:, 0]], p[out[:, 2]] - p[out[:, 0]])
        flip = np.einsum("ij,ij->i", n, p[out[:, 0]] - cen[owner]) < 0
        out[flip] = out[flip][:, [0, 2, 1]]
    return out


@lru_cache(maxsize=8)
def grid_boundary_faces(n: int) -> np.ndarray:
    """:func:`boundary_faces` of :func:`rfmap.core.mesh.grid_mesh` ``(N, 3)``, outward, shape (12 (N-1)^2, 3); computed
    once per ``N`` (a read-only array)."""
    m = grid_mesh(n, 3)
    out = boundary_faces(m.elements, m.points)
    out.setflags(write=False)
    return out


def _cell_incidences(lo: np.ndarray, hi: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Every (box, cell) incidence of boxes ``[lo, hi]`` (k, 3) on a grid of cubic cells of side ``cell``:
    ``(box index, cell code)``, with codes comparable between calls of the same ``cell``."""
    c0 = np.floor(lo / cell).astype(np.int64)
    c1 = np.floor(hi / cell).astype(np.int64)
    span = c1 - c0 + 1
    counts = span.prod(1)
    box = np.repeat(np.arange(len(lo)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    r = np.arange(len(box)) - first
    sy, sz = span[box, 1], span[box, 2]
    ox, rem = np.divmod(r, sy * sz)
    oy, oz = np.divmod(rem, sz)
    cells = c0[box] + np.stack([ox, oy, oz], 1)
    # a code unique for any cell within 2^20 cells of the origin per axis
    code = ((cells[:, 0] + (1 << 20)) << 42) | ((cells[:, 1] + (1 << 20)) << 21) | (cells[:, 2] + (1 << 20))
    return box, code


def _cell_side(lo: np.ndarray, hi: np.ndarray) -> float:
    return max(float(np.median((hi - lo).max(1))), 1e-12)


def _broad_phase(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``i < j`` of boxes ``[lo, hi]`` that share a cell of a uniform grid (cell side: the median box
    extent), a superset of the pairs of overlapping boxes."""
    f = len(lo)
    tri, code = _cell_incidences(lo, hi, _cell_side(lo, hi))
    order = np.argsort(code, kind="stable")
    code, tri = code[order], tri[order]
    starts = np.flatnonzero(np.r_[True, code[1:] != code[:-1]])
    sizes = np.diff(np.r_[starts, len(code)])
    ii, jj = [], []
    for s in np.unique(sizes[sizes > 1]):  # all pairs within the cells holding s triangles, vectorised per size
        st = starts[sizes == s]
        a, b = np.triu_indices(s, 1)
        ii.append(tri[st[:, None] + a[None]].ravel())
        jj.append(tri[st[:, None] + b[None]].ravel())
    if not ii:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    i, j = np.concatenate(ii), np.concatenate(jj)
    i, j = np.minimum(i, j), np.maximum(i, j)
    pair = np.sort(i * f + j)
    pair = pair[np.r_[True, pair[1:] != pair[:-1]]]
    return pair // f, pair % f


def _cross_phase(lo_a: np.ndarray, hi_a: np.ndarray, lo_b: np.ndarray, hi_b: np.ndarray,
                 cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(i, j)`` of a box of set A and a box of set B that share a cell (only pairs across the sets)."""
    ia, ca = _cell_incidences(lo_a, hi_a, cell)
    ib, cb = _cell_incidences(lo_b, hi_b, cell)
    order = np.argsort(cb, kind="stable")
    ib, cb = ib[order], cb[order]
    left = np.searchsorted(cb, ca, side="left")
    count = np.searchsorted(cb, ca, side="right") - left
    i = np.repeat(ia, count)
    pos = np.repeat(left, count) + (np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count))
    j = ib[pos]
    nb = len(lo_b)
    pair = np.sort(i * nb + j)
    pair = pair[np.r_[True, pair[1:] != pair[:-1]]] if len(pair) else pair
    return pair // nb, pair % nb


def _boxes_overlap(lo: np.ndarray, hi: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    return np.all((lo[i] <= hi[j]) & (lo[j] <= hi[i]), axis=1)


def _coplanar_overlap(A: np.ndarray, B: np.ndarray, normal: np.ndarray, eps: float) -> np.ndarray:
    """Proper overlap of coplanar triangle pairs ``A``, ``B`` (p, 3, 3), projected along the normal's dominant axis."""
    ax = np.abs(normal).argmax(1)
    keep = np.array([[1, 2], [0, 2], [0, 1]])[ax]
    rows = np.arange(len(A))[:, None]
    a = np.stack([A[rows, v, keep] for v in range(3)], 1)  # (p, 3, 2)
    b = np.stack([B[rows, v, keep] for v in range(3)], 1)

    def orient(p, q, r):
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

    hit = np.zeros(len(A), bool)
    for e in range(3):
        p, q = a[:, e], a[:, (e + 1) % 3]
        for g in range(3):
            r, s = b[:, g], b[:, (g + 1) % 3]
            o1, o2 = orient(p, q, r), orient(p, q, s)
            o3, o4 = orient(r, s, p), orient(r, s, q)
            hit |= (o1 * o2 < -eps) & (o3 * o4 < -eps)

    def inside(tri, pt):
        sgn = np.sign(orient(tri[:, 0], tri[:, 1], tri[:, 2]))
        w = [sgn * orient(tri[:, k], tri[:, (k + 1) % 3], pt) for k in range(3)]
        return (w[0] > eps) & (w[1] > eps) & (w[2] > eps)

    for v in range(3):
        hit |= inside(a, b[:, v]) | inside(b, a[:, v])
    return hit


def _triangles_intersect(A: np.ndarray, B: np.ndarray, eps: float) -> np.ndarray:
    """Möller's interval test for triangle pairs ``A``, ``B`` of shape (p, 3, 3); ``eps``: length tolerance."""
    nA = np.cross(A[:, 1] - A[:, 0], A[:, 2] - A[:, 0])
    nB = np.cross(B[:, 1] - B[:, 0], B[:, 2] - B[:, 0])
    lA = np.linalg.norm(nA, axis=1)
    lB = np.linalg.norm(nB, axis=1)
    uA = nA / np.maximum(lA, 1e-300)[:, None]
    uB = nB / np.maximum(lB, 1e-300)[:, None]
    dB = np.einsum("pj,pvj->pv", uA, B - A[:, :1])  # signed distances of B's vertices to A's plane
    dA = np.einsum("pj,pvj->pv", uB, A - B[:, :1])
    sepB = np.all(dB > eps, 1) | np.all(dB < -eps, 1)
    sepA = np.all(dA > eps, 1) | np.all(dA < -eps, 1)
    cand = ~(sepA | sepB)
    hit = np.zeros(len(A), bool)
    if not cand.any():
        return hit
    cop = cand & (np.all(np.abs(dB) <= eps, 1) | np.all(np.abs(dA) <= eps, 1))
    if cop.any():
        hit[cop] = _coplanar_overlap(A[cop], B[cop], uA[cop], eps * eps)
    gen = np.flatnonzero(cand & ~cop)
    if len(gen):
        a, b, da, db = A[gen], B[gen], dA[gen], dB[gen]
        line = np.cross(uA[gen], uB[gen])
        line /= np.maximum(np.linalg.norm(line, axis=1), 1e-300)[:, None]
        ia = _interval(np.einsum("pj,pvj->pv", line, a), np.where(np.abs(da) <= eps, 0.0, da))
        ib = _interval(np.einsum("pj,pvj->pv", line, b), np.where(np.abs(db) <= eps, 0.0, db))
        ok = np.isfinite(ia).all(1) & np.isfinite(ib).all(1)
        overlap = np.minimum(ia[:, 1], ib[:, 1]) - np.maximum(ia[:, 0], ib[:, 0])
        hit[gen] = ok & (overlap > eps)
    return hit


def _interval(proj: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """The interval (p, 2) that a triangle cuts from the line, from its vertices' projections on the line and their
    signed distances to the other plane (a vertex on the plane counts as a point of the interval)."""
    pts = []
    for i in range(3):
        j = (i + 1) % 3
        di, dj = dist[:, i], dist[:, j]
        on = di == 0
        pts.append(np.where(on, proj[:, i], np.nan))
        cross = di * dj < 0
        t = np.where(cross, di / np.where(cross, di - dj, 1.0), np.nan)
        pts.append(np.where(cross, proj[:, i] + t * (proj[:, j] - proj[:, i]), np.nan))
    P = np.stack(pts, 1)
    with np.errstate(all="ignore"):
        lo, hi = np.nanmin(P, 1), np.nanmax(P, 1)
    return np.stack([lo, hi], 1)


def surface_intersections(points: np.ndarray, faces: np.ndarray, *, tol: float = 1e-9) -> np.ndarray:
    r"""Pairs of intersecting triangles of a triangulated surface, shape (k, 2), rows ``i < j``, sorted.

    Parameters
    ----------
    points : ndarray, shape (P, 3)
        Vertex positions (e.g. a mapped mesh).
    faces : int ndarray, shape (f, 3)
        Triangles, e.g. :func:`boundary_faces` of the mesh.
    tol : float
        Relative tolerance: contacts shallower than ``tol`` times the surface's bounding-box diagonal do not count.

    Pairs of triangles that share a vertex are not tested (they meet there by construction), so a crossing between
    two such triangles elsewhere than at their shared vertex or edge is not detected.  Returns an empty (0, 2) array
    when no other pair intersects.
    """
    p = np.asarray(points, np.float64)
    fc = np.asarray(faces, np.int64)
    if p.ndim != 2 or p.shape[1] != 3 or fc.ndim != 2 or fc.shape[1] != 3:
        raise ValueError(f"surface_intersections needs points (P, 3) and faces (f, 3), got {p.shape}, {fc.shape}")
    if not np.isfinite(p).all():
        raise ValueError("surface_intersections: the points contain NaN or infinity")
    if len(fc) < 2:
        return np.zeros((0, 2), np.int64)
    T = p[fc]
    lo, hi = T.min(1), T.max(1)
    i, j = _broad_phase(lo, hi)
    share = (fc[i][:, :, None] == fc[j][:, None, :]).any((1, 2))
    i, j = i[~share], j[~share]
    near = _boxes_overlap(lo, hi, i, j)
    i, j = i[near], j[near]
    scale = float(np.linalg.norm(p.max(0) - p.min(0)))
    hit = np.zeros(len(i), bool)
    for s in range(0, len(i), 200_000):  # bounded memory
        hit[s:s + 200_000] = _triangles_intersect(T[i[s:s + 200_000]], T[j[s:s + 200_000]], tol * scale)
    return np.stack([i[hit], j[hit]], 1)


# ------------------------------------------------------------------------------- the 2D boundary polygon
def boundary_loop(n: int) -> np.ndarray:
    """Indices of the boundary vertices of the 2D ``N``-grid, counter-clockwise from the origin, shape (4 (N-1),)."""
    i = np.arange(n)
    bottom = i[:-1] * n  # (i, 0)
    right = (n - 1) * n + i[:-1]  # (N-1, j)
    top = i[::-1][:-1] * n + n - 1  # (i, N-1), i descending
    left = i[::-1][:-1]  # (0, j), j descending
    return np.concatenate([bottom, right, top, left])


def boundary_crossings(poly: np.ndarray, edges: np.ndarray | None = None) -> np.ndarray:
    r"""Pairs of properly crossing edges of a closed polygon (edge ``k`` joins vertices ``k`` and ``k+1``).

    Candidate pairs come from a uniform bucket grid whose cell is twice the median edge extent (an edge is entered
    in every cell its bounding box meets), so the cost is about linear in the number of edges plus the total
    length of the long ones, even when a few edges are stretched far beyond the others.  Edges sharing a vertex are not
    compared; two edges cross when each one's endpoints lie strictly on opposite sides of the other (orientation
    test), or when they touch (a zero orientation with overlapping extents counts as a crossing).

    With ``edges``, only the crossings that involve one of these edges are returned: each is tested against
    every edge directly (the check after moving a few vertices, as in :func:`~rfmap.finish.repair.scale.scale_repair`).

    Parameters
    ----------
    poly : ndarray, shape (k, 2)
    edges : int ndarray, optional
        Edge indices in ``[0, k)``.

    Returns
    -------
    pairs : int ndarray, shape (c, 2)
        The crossing edges as index pairs ``(i, j)`` with ``i < j``.
    """
    P = np.asarray(poly, dtype=np.float64)
    k = P.shape[0]
    a, b = P, np.roll(P, -1, axis=0)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    if edges is not None and len(edges) * k <= 1 << 18:
        e = np.unique(np.asarray(edges, np.int64) % k)
        near = (lo[e, None] <= hi[None]).all(2) & (lo[None] <= hi[e, None]).all(2)  # (len(e), k) boxes meet
        ii, jj = np.nonzero(near)
        i, j = np.minimum(e[ii], jj), np.maximum(e[ii], jj)
        return _crossing_pairs(a, b, i, j, k)
    ext = (hi - lo).max(1)
    # the cell is twice the median edge extent: a typical edge meets at most 2 x 2 cells, and a long edge (a
    # stretched boundary) is entered in every cell its bounding box meets instead of inflating every cell
    # (and no finer than 1/(4 sqrt k) of the whole polygon's extent, so that degenerate edges cannot explode it)
    whole = float((P.max(0) - P.min(0)).max())
    cell = max(2.0 * float(np.median(ext)), whole / (4.0 * math.sqrt(k)), 1e-12)
    c0 = np.floor(lo / cell).astype(np.int64)
    c1 = np.floor(hi / cell).astype(np.int64)
    span = c1 - c0 + 1  # (k, 2) cells per axis
    count = span.prod(1)
    edge = np.repeat(np.arange(k), count)
    r = np.arange(edge.size) - np.repeat(np.cumsum(count) - count, count)
    cx = c0[edge, 0] + r % span[edge, 0]
    cy = c0[edge, 1] + r // span[edge, 0]
    keys = (cx - cx.min()) * (int(cy.max() - cy.min()) + 1) + (cy - cy.min())
    order = np.argsort(keys, kind="stable")
    ids, keys = edge[order], keys[order]
    pi, pj = [], []
    off = 1
    while off < len(keys):
        same = keys[off:] == keys[:-off]
        if not same.any():
            break
        pi.append(ids[:-off][same])
        pj.append(ids[off:][same])
        off += 1
    if not pi:
        return np.zeros((0, 2), dtype=np.int64)
    i, j = np.concatenate(pi), np.concatenate(pj)
    i, j = np.minimum(i, j), np.maximum(i, j)
    box = (lo[i] <= hi[j]).all(1) & (lo[j] <= hi[i]).all(1)
    pairs = _crossing_pairs(a, b, i[box], j[box], k)
    if edges is not None:
        pairs = pairs[np.isin(pairs, np.asarray(edges, np.int64) % k).any(1)]
    return pairs


def _crossing_pairs(a: np.ndarray, b: np.ndarray, i: np.ndarray, j: np.ndarray, k: int) -> np.ndarray:
    """The candidate pairs ``i < j`` (boxes meeting) of non-adjacent edges that cross, unique and sorted."""
    gap = j - i
    keep = (gap > 1) & (gap < k - 1)
    code = np.unique(i[keep] * k + j[keep])
    i, j = code // k, code % k

    def orient(p, q, r):
        return (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])

    o1, o2 = orient(a[i], b[i], a[j]), orient(a[i], b[i], b[j])
    o3, o4 = orient(a[j], b[j], a[i]), orient(a[j], b[j], b[i])
    cross = (o1 * o2 <= 0) & (o3 * o4 <= 0)
    return np.stack([i[cross], j[cross]], 1)


# ------------------------------------------------------------------------------- the grid cube's surface
@lru_cache(maxsize=8)
def _grid_faces(n: int) -> tuple:
    """Per face of the cube (axis ``a``, side ``s``): the indices of its triangles in :func:`grid_boundary_faces`,
    the two in-plane axes, the face's vertex loop (4 (N-1) vertex indices) and the reference orientation sign of
    each triangle projected on the face's plane."""
    ref = grid_points(n, 3)
    faces = grid_boundary_faces(n)
    loop2 = boundary_loop(n)  # (i, j) -> i*N + j on the 2D grid
    out = []
    for a in range(3):
        u, v = [b for b in range(3) if b != a]
        for side in (0.0, 1.0):
            tri = np.flatnonzero(np.all(ref[faces][:, :, a] == side, axis=1))
            ii, jj = np.divmod(loop2, n)
            idx = np.zeros((len(loop2), 3), np.int64)
            idx[:, a] = int(side) * (n - 1)
            idx[:, u], idx[:, v] = ii, jj
            loop = (idx[:, 0] * n + idx[:, 1]) * n + idx[:, 2]
            sign = np.sign(_projected_areas(ref, faces[tri], u, v))
            out.append((tri, u, v, loop, sign))
    return tuple(out)


def _projected_areas(points: np.ndarray, tri: np.ndarray, u: int, v: int) -> np.ndarray:
    p = points[tri]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return e1[:, u] * e2[:, v] - e1[:, v] * e2[:, u]


def grid_surface_intersections(points: np.ndarray, n: int, *, tol: float = 1e-9) -> np.ndarray:
    r""":func:`surface_intersections` of the boundary of the 3D ``N``-grid mesh mapped to ``points``, with a fast path.

    Each of the six faces of the cube is a grid of triangles.  If a face's image, projected on the face's own
    plane, keeps every triangle's orientation and has a simple outline, the projection is injective on the face
    (a 2D piecewise-linear map with positive triangles and a simple boundary polygon is a bijection), so the image
    of the face does not cross itself and only pairs of triangles from *different* faces remain to be tested; those
    are searched among the triangles whose boxes meet the other face's box (near the shared edges, for maps that do
    not fold the cube over).  If any face fails the test the whole surface goes through
    :func:`surface_intersections`.  The result is the same pair list (indices into :func:`grid_boundary_faces`).

    Parameters
    ----------
    points : ndarray, shape (N^3, 3)
    n : int
        Grid side ``N``.
    """
    p = np.asarray(points, np.float64)
    if p.ndim != 2 or p.shape != (n ** 3, 3):
        raise ValueError(f"grid_surface_intersections needs points of shape ({n ** 3}, 3), got {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError("grid_surface_intersections: the points contain NaN or infinity")
    faces = grid_boundary_faces(n)
    meta = _grid_faces(n)
    scale = float(np.linalg.norm(p.max(0) - p.min(0)))
    eps = tol * scale
    for tri, u, v, loop, sign in meta:
        area = _projected_areas(p, faces[tri], u, v) * sign
        if not (area > eps * eps).all() or len(boundary_crossings(p[loop][:, [u, v]])):
            return surface_intersections(p, faces, tol=tol)
    T = p[faces]
    lo = np.minimum(np.minimum(T[:, 0], T[:, 1]), T[:, 2])
    hi = np.maximum(np.maximum(T[:, 0], T[:, 1]), T[:, 2])
    cell = _cell_side(lo, hi)
    box = [(lo[tri].min(0), hi[tri].max(0)) for tri, *_ in meta]
    pairs = []
    for fa in range(6):
        for fb in range(fa + 1, 6):
            (la, ha), (lb, hb) = box[fa], box[fb]
            if not (np.all(la <= hb) and np.all(lb <= ha)):
                continue
            ta, tb = meta[fa][0], meta[fb][0]
            ta = ta[np.all((lo[ta] <= hb) & (lb <= hi[ta]), axis=1)]
            tb = tb[np.all((lo[tb] <= ha) & (la <= hi[tb]), axis=1)]
            if not len(ta) or not len(tb):
                continue
            i, j = _cross_phase(lo[ta], hi[ta], lo[tb], hi[tb], cell)
            pairs.append((ta[i], tb[j]))
    if not pairs:
        return np.zeros((0, 2), np.int64)
    i = np.concatenate([a for a, _ in pairs])
    j = np.concatenate([b for _, b in pairs])
    i, j = np.minimum(i, j), np.maximum(i, j)
    share = (faces[i][:, :, None] == faces[j][:, None, :]).any((1, 2))
    i, j = i[~share], j[~share]
    near = _boxes_overlap(lo, hi, i, j)
    i, j = i[near], j[near]
    hit = _triangles_intersect(T[i], T[j], eps)
    out = np.stack([i[hit], j[hit]], 1)
    return out[np.lexsort((out[:, 1], out[:, 0]))] if len(out) else out
