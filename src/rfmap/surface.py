r"""The boundary surface of a tetrahedral mesh and its self-intersections.

A piecewise-linear map of a tetrahedral mesh of a ball with every tetrahedron positively oriented is injective when
its restriction to the boundary surface is (a locally injective map that is injective on the boundary of a ball is
a homeomorphism onto the region the boundary image encloses).  With a fixed or sliding cube boundary the boundary
image is the cube's own surface and nothing more needs checking; with a free boundary two far-apart parts of the
surface could be pushed through each other while every tetrahedron stays positive.  This module finds such
crossings:

* :func:`boundary_faces`: the triangles that belong to exactly one tetrahedron, oriented outwards.
* :func:`surface_intersections`: pairs of triangles of a triangulated surface that intersect, leaving out pairs
  that share a vertex (they meet by construction).  A uniform-grid broad phase (cell side the median
  bounding-box extent) pairs triangles whose boxes overlap; the narrow phase is the interval test of Möller (1997):
  two non-coplanar triangles intersect when each straddles the other's plane and the two intervals they cut from
  the planes' common line overlap; (nearly) coplanar pairs are projected onto the plane and tested for properly
  crossing edges or a vertex strictly inside the other triangle.  Touching counts as intersecting only beyond a
  relative tolerance ``tol`` of the surface's size, so a surface on the faces of the unit cube (the identity map)
  has no intersection.

Cost: linear in the number of triangles for a surface without wild differences in triangle size; at the 3D grid side
N = 48 (26,508 boundary triangles) well under a second.

References
----------
T. Möller, "A fast triangle-triangle intersection test", J. Graphics Tools 2(2), 25–30 (1997).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from .mesh import grid_mesh

__all__ = ["boundary_faces", "surface_intersections", "grid_boundary_faces"]


def boundary_faces(elements: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
    """Faces of a tetrahedral mesh that belong to one tetrahedron only, shape (f, 3).

    Parameters
    ----------
    elements : int ndarray, shape (m, 4)
        Tetrahedra, positively oriented.
    points : ndarray, shape (n, 3), optional
        Not needed for the faces; when given, each face is oriented with its normal pointing out of its tetrahedron
        (checked on these points).

    The face opposite vertex ``i`` of a positive tetrahedron ``(v0, v1, v2, v3)`` is oriented outwards when listed
    as the even permutation used here.
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
    """:func:`boundary_faces` of :func:`rfmap.mesh.grid_mesh` ``(N, 3)``, outward, shape (12 (N-1)^2, 3); computed
    once per ``N`` (a read-only array)."""
    m = grid_mesh(n, 3)
    out = boundary_faces(m.elements, m.points)
    out.setflags(write=False)
    return out


def _broad_phase(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``i < j`` of boxes ``[lo, hi]`` that share a cell of a uniform grid (cell side: the median box
    extent), a superset of the pairs of overlapping boxes."""
    f = len(lo)
    ext = np.median((hi - lo).max(1))
    cell = max(float(ext), 1e-12)
    c0 = np.floor(lo / cell).astype(np.int64)
    c1 = np.floor(hi / cell).astype(np.int64)
    span = c1 - c0 + 1
    counts = span.prod(1)
    # every (triangle, cell) incidence
    tri = np.repeat(np.arange(f), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    r = np.arange(len(tri)) - first
    sy, sz = span[tri, 1], span[tri, 2]
    ox, rem = np.divmod(r, sy * sz)
    oy, oz = np.divmod(rem, sz)
    cells = c0[tri] + np.stack([ox, oy, oz], 1)
    cells -= cells.min(0)
    dims = cells.max(0) + 1
    code = (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]
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
    points : ndarray, shape (n, 3)
        Vertex positions (e.g. a mapped mesh).
    faces : int ndarray, shape (f, 3)
        Triangles, e.g. :func:`boundary_faces` of the mesh.
    tol : float
        Relative tolerance: contacts shallower than ``tol`` times the surface's bounding-box diagonal do not count.

    Pairs of triangles that share a vertex are not tested (they meet by construction).  Returns an empty (0, 2)
    array for an embedded surface.
    """
    p = np.asarray(points, np.float64)
    fc = np.asarray(faces, np.int64)
    if p.ndim != 2 or p.shape[1] != 3 or fc.ndim != 2 or fc.shape[1] != 3:
        raise ValueError(f"surface_intersections needs points (n, 3) and faces (f, 3), got {p.shape}, {fc.shape}")
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
