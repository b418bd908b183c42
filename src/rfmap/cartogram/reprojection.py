r"""Written regions that survive reprojection: needles removed, edges that bend split.

A region that the passes squeeze towards nothing keeps its vertices, pressed into needles: a vertex where the ring
turns back on itself, a ring part without area.  Such a polygon is valid, but by a hair: a user who reprojects the
file moves every vertex by a smooth map under which straight edges are other curves, and an edge that passed a needle
by :math:`10^{-14}` of the map's extent crosses it.  Two stages make the written polygons robust to that:

* :func:`remove_needles`: a vertex :math:`v` between its ring neighbours :math:`a` and :math:`b` is a **needle**
  when its edges meet at an angle :math:`\angle avb <` ``angle`` (:data:`NEEDLE_ANGLE`) and the needle's width
  :math:`w = |(a - v) \times (b - v)| / \max(|a - v|, |b - v|)` (the nearer neighbour's distance from the line of the
  farther edge) is under ``width`` (:data:`NEEDLE_WIDTH`) times the map's extent :math:`L` (the longer side of its
  bounding box).  A ring whose mean width :math:`2|A|/P` is under ``width`` :math:`L` has collapsed to a line: it is
  dropped, a hole or a part of a region that keeps another.  Removing :math:`v` changes the ring's area by the
  triangle :math:`avb`, at most :math:`w \max(|a-v|, |b-v|)/2`; a region whose area would change by more than
  ``max_change`` (:data:`NEEDLE_AREA`) of it, or that the removal would make invalid, has only its narrower needles
  removed, or none.
* :func:`split_bent_edges`: a region valid as written but invalid after a transform of the whole map (by default
  :func:`cylindrical_equal_area` of longitude/latitude) has every edge split at its midpoint, round after round,
  until its transformed polygon, whose straight edges then follow the transformed curves, is valid too.  The written
  polygon keeps its shape and area (the midpoints lie on its edges) and its neighbours' edges along the split ones
  are split alike, so that shared borders keep the same vertices on both sides.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["NEEDLE_ANGLE", "NEEDLE_WIDTH", "NEEDLE_AREA", "NARROWER", "SPLIT_ROUNDS", "cylindrical_equal_area",
           "needles", "remove_needles", "split_bent_edges"]

#: The angle (degrees) under which a vertex's two edges make it a needle tip (with :data:`NEEDLE_WIDTH`)
NEEDLE_ANGLE = 1.0
#: The width (a share of the map's extent) under which a sharp vertex is a needle and a ring a collapsed line: on a
#: map of the contiguous United States, 6 m
NEEDLE_WIDTH = 1e-6
#: The largest change of a region's area (a share of it) by which :func:`remove_needles` removes its needles: that
#: of a repaired speck (:data:`rfmap.cartogram.output.SPECK`), ten thousand times under the cartogram's default 1 %
NEEDLE_AREA = 1e-6
#: The shares of the needle width that :func:`remove_needles` tries in turn on a region whose needles hold more
#: than :data:`NEEDLE_AREA` of it (a squeezed region narrower than the width all along)
NARROWER = (1.0, 1e-1, 1e-2, 1e-3, 1e-4)
#: The rounds of midpoint splits (each doubles the vertices of the region's rings) that :func:`split_bent_edges` tries
SPLIT_ROUNDS = 6


def cylindrical_equal_area(lonlat: np.ndarray, lat0: float = 0.0) -> np.ndarray:
    r"""Lambert's cylindrical equal-area projection of longitude/latitude (P, 2), degrees, on the unit sphere with
    standard parallel ``lat0``: :math:`x = \lambda \cos\varphi_0`, :math:`y = \sin\varphi / \cos\varphi_0`
    (radians; Snyder 1987, §10).  The standard parallel scales :math:`x` and :math:`y` only, so a polygon's validity
    does not depend on it; that of the curve :math:`\varphi \mapsto \sin\varphi` does."""
    c = math.cos(math.radians(lat0))
    lonlat = np.asarray(lonlat, dtype=float)
    return np.column_stack([np.radians(lonlat[:, 0]) * c, np.sin(np.radians(lonlat[:, 1])) / c])


def needles(ring: np.ndarray, angle: float, width: float) -> np.ndarray:
    r"""Which vertices of a closed ring (k + 1, 2) are needle tips (boolean, (k,)): the angle between the edges to the
    previous and the next vertex is under ``angle`` degrees and the width :math:`w` (see
    :mod:`rfmap.cartogram.reprojection`) under ``width`` (the ring's units).  A vertex on an edge of zero length is
    none."""
    p = ring[:-1]
    u, v = np.roll(p, 1, axis=0) - p, np.roll(p, -1, axis=0) - p
    cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    turn = np.degrees(np.abs(np.arctan2(cross, np.einsum("ij,ij->i", u, v))))
    longer = np.maximum(np.hypot(u[:, 0], u[:, 1]), np.hypot(v[:, 0], v[:, 1]))
    short = np.minimum(np.hypot(u[:, 0], u[:, 1]), np.hypot(v[:, 0], v[:, 1]))
    return (short > 0) & (turn < angle) & (np.abs(cross) < width * longer)


def _ring_area(ring: np.ndarray) -> float:
    """The signed shoelace area of a closed ring (k + 1, 2)."""
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.dot(x[:-1], y[1:]) - np.dot(x[1:], y[:-1]))


def _strip_ring(ring: np.ndarray, angle: float, width: float, tipped: bool = True) -> tuple[np.ndarray | None, int]:
    """A closed ring with its needle tips removed, round after round (the first tip of every run of neighbouring
    tips each round, so that every removal is judged with its true neighbours), and the count removed; ``None`` for
    a ring that collapsed (fewer than three vertices left, or a mean width :math:`2|A|/P` under ``width``).  A ring
    not ``tipped`` (found without a tip at this width or a wider one) is only checked for collapse."""
    removed = 0
    while True:
        p = ring[:-1]
        if len(p) < 3 or 2 * abs(_ring_area(ring)) < width * float(np.hypot(*np.diff(ring, axis=0).T).sum()):
            return None, removed
        if not tipped:
            return ring, removed
        tip = needles(ring, angle, width)
        if not tip.any():
            return ring, removed
        if tip.all():
            return None, removed
        first = tip & ~np.roll(tip, 1)
        removed += int(first.sum())
        p = p[~first]
        ring = np.vstack([p, p[:1]])


def _strip_region(geom, angle: float, width: float, tipped: np.ndarray):
    """A (Multi)Polygon with its needles removed and collapsed rings dropped (:func:`_strip_ring`), and the count of
    points removed (those of a dropped ring included); the region itself when nothing changed or nothing would be
    left.  ``tipped`` flags the rings (in the order of ``shapely.get_rings`` of its parts) that hold a tip at this
    width or a wider one (:func:`_candidates`)."""
    import shapely

    polys, changed, flags = [], False, iter(tipped)
    for part in shapely.get_parts(geom):
        shell, n = _strip_ring(np.asarray(part.exterior.coords), angle, width, next(flags))
        changed |= shell is None or n > 0
        if shell is None:
            for _ in part.interiors:
                next(flags)
            continue
        holes = []
        for h in part.interiors:
            hole, n = _strip_ring(np.asarray(h.coords), angle, width, next(flags))
            changed |= hole is None or n > 0
            if hole is not None:
                holes.append(hole)
        polys.append(shapely.Polygon(shell, holes))
    if not changed or not polys:
        return geom, 0
    kind = shapely.get_type_id(geom)
    out = polys[0] if kind == 3 and len(polys) == 1 else shapely.MultiPolygon(polys)
    return out, int(shapely.get_num_coordinates(geom) - shapely.get_num_coordinates(out))


def _candidates(geoms: np.ndarray, angle: float, width: float) -> dict[int, np.ndarray]:
    """The regions (indices) with a needle tip or a collapsed ring, every ring screened at once, and which of each
    one's rings (in the order of ``shapely.get_rings`` of its parts) hold a tip: ``{region: flags}``."""
    import shapely

    parts, owner = shapely.get_parts(geoms, return_index=True)
    rings, of_part = shapely.get_rings(parts, return_index=True)
    xy, of_ring = shapely.get_coordinates(rings, return_index=True)
    start = np.r_[0, np.flatnonzero(np.diff(of_ring)) + 1]
    last = np.r_[start[1:], len(xy)] - 1  # each ring's closing point, a repeat of its first
    prev = np.arange(len(xy)) - 1
    prev[start] = last - 1
    nxt = np.minimum(np.arange(len(xy)) + 1, len(xy) - 1)
    u, v = xy[prev] - xy, xy[nxt] - xy
    cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    turn = np.degrees(np.abs(np.arctan2(cross, np.einsum("ij,ij->i", u, v))))
    lu, lv = np.hypot(u[:, 0], u[:, 1]), np.hypot(v[:, 0], v[:, 1])
    tip = (np.minimum(lu, lv) > 0) & (turn < angle) & (np.abs(cross) < width * np.maximum(lu, lv))
    tip[last] = False
    tipped = np.zeros(len(rings), dtype=bool)
    np.logical_or.at(tipped, of_ring, tip)
    hit = tipped | (2 * np.abs(shapely.area(shapely.polygons(rings))) < width * shapely.length(rings))
    region = np.zeros(len(geoms), dtype=bool)  # a mask, not np.unique: that loads numpy.ma (10 ms of a short run)
    region[owner[of_part[hit]]] = True
    ring_owner = owner[of_part]
    return {int(i): tipped[ring_owner == i] for i in np.flatnonzero(region)}


def remove_needles(geoms: np.ndarray, *, angle: float = NEEDLE_ANGLE, width: float = NEEDLE_WIDTH,
                   max_change: float = NEEDLE_AREA) -> tuple[np.ndarray, dict[int, int]]:
    r"""Polygons (R,) with their needles removed and their collapsed rings dropped (see
    :mod:`rfmap.cartogram.reprojection`): a needle tip's edges meet at under ``angle`` degrees and it is narrower than
    ``width`` :math:`L`, :math:`L` the longer side of the map's bounding box.  A region is changed only where its area
    changes by at most ``max_change`` of it and it stays valid (or was invalid already); where it would not, only its
    narrower needles are removed (``width`` times each of :data:`NARROWER` in turn: those that a reprojection breaks
    first).  Returns the polygons and ``{region: points removed}`` (a dropped ring's closing point included)."""
    import shapely

    lo_x, lo_y, hi_x, hi_y = shapely.total_bounds(geoms)
    w = width * max(hi_x - lo_x, hi_y - lo_y)
    out, removed = geoms.copy(), {}
    for i, tipped in _candidates(geoms, angle, w).items():
        area, valid = abs(shapely.area(geoms[i])), shapely.is_valid(geoms[i])
        for narrower in NARROWER:  # a ring without a tip at the width has none at a narrower one
            g, n = _strip_region(geoms[i], angle, w * narrower, tipped)
            if n and abs(shapely.area(g) - area) <= max_change * area and (shapely.is_valid(g) or not valid):
                out[i], removed[int(i)] = g, n
                break
    return out, removed


def _edge_key(a: np.ndarray, b: np.ndarray) -> bytes:
    """One key for the edge between two points, whichever way round it is drawn."""
    a, b = a.tobytes(), b.tobytes()
    return a + b if a <= b else b + a


def _split_ring(ring: np.ndarray, split: set | None) -> np.ndarray:
    """A closed ring with its edges (all of them, or those whose :func:`_edge_key` is in ``split``) split at their
    midpoints, :math:`(a + b)/2`: the same point whichever way round the edge is drawn."""
    a, b = ring[:-1], ring[1:]
    mid = 0.5 * (a + b)
    keep = np.ones(len(a), dtype=bool) if split is None else \
        np.array([_edge_key(p, q) in split for p, q in zip(a, b)], dtype=bool)
    out = np.empty((len(a) + int(keep.sum()) + 1, 2))
    pos = np.arange(len(a)) + np.r_[0, np.cumsum(keep)[:-1]]
    out[pos] = a
    out[pos[keep] + 1] = mid[keep]
    out[-1] = ring[-1]
    return out


def _map_rings(geom, fn):
    """A (Multi)Polygon with every ring (closed coordinates) replaced by ``fn(ring)``."""
    import shapely

    polys = [shapely.Polygon(fn(np.asarray(p.exterior.coords)), [fn(np.asarray(h.coords)) for h in p.interiors])
             for p in shapely.get_parts(geom)]
    return polys[0] if shapely.get_type_id(geom) == 3 else shapely.MultiPolygon(polys)


def _edges(geom) -> set:
    """The :func:`_edge_key` of every edge of a (Multi)Polygon."""
    import shapely

    keys = set()
    for ring in shapely.get_rings(shapely.get_parts(geom)):
        c = shapely.get_coordinates(ring)
        keys.update(_edge_key(p, q) for p, q in zip(c[:-1], c[1:]))
    return keys


def split_bent_edges(geoms: np.ndarray, transform, *, rounds: int = SPLIT_ROUNDS
                     ) -> tuple[np.ndarray, dict[int, int], list[int]]:
    r"""Regions (R,) valid as they are but invalid after ``transform`` (points (P, 2) to points (P, 2), applied to
    every vertex, as a reprojection of the file does) made valid under it by splitting their edges at the midpoints,
    up to ``rounds`` times (:data:`SPLIT_ROUNDS`): the transformed edges then follow the curves that the straight
    edges become.  Every edge of another region drawn between the same two points is split alike (a shared border
    keeps the same vertices on both sides).  A split is kept only where the region stays valid as written.

    Returns
    -------
    (ndarray, dict, list)
        The polygons, ``{region: vertices added}`` of the regions split (their neighbours included), and the
        regions valid as written that are still invalid after ``transform``.
    """
    import shapely

    valid = shapely.is_valid(geoms)
    bad = np.flatnonzero(valid & ~shapely.is_valid(shapely.transform(geoms, transform)))
    out, added = geoms.copy(), {}
    if not bad.size:
        return out, added, []
    tree = shapely.STRtree(geoms)
    for i in bad:
        near = [int(j) for j in tree.query(geoms[i], predicate="intersects") if j != i and valid[j]]
        g, trial = out[i], {}
        for _ in range(rounds):
            keys = _edges(g)
            g = _map_rings(g, lambda r: _split_ring(r, None))
            for j in near:  # the same edges of the neighbours
                h = trial.get(j, out[j])
                trial[j] = _map_rings(h, lambda r: _split_ring(r, keys))
            if not shapely.is_valid(g):
                break
            if shapely.is_valid(shapely.transform(g, transform)):
                break
        if not (shapely.is_valid(g) and shapely.is_valid(shapely.transform(g, transform))):
            continue
        for j, h in [(int(i), g), *trial.items()]:
            extra = shapely.get_num_coordinates(h) - shapely.get_num_coordinates(out[j])
            if extra and shapely.is_valid(h):
                added[j] = added.get(j, 0) + int(extra)
                out[j] = h
    left = np.flatnonzero(shapely.is_valid(out) & ~shapely.is_valid(shapely.transform(out, transform)))
    return out, added, [int(i) for i in left]
