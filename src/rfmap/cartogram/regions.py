r"""GeoJSON regions in the unit square: reading and checking them, their density raster, and real maps to try.

The input stage of a cartogram (:mod:`rfmap.cartogram.resize`): a FeatureCollection of Polygon / MultiPolygon features
with a value per region (:func:`read_regions`), fitted into the unit square by an equal-area projection
(:class:`rfmap.cartogram.projection.PlanarFrame`), and rasterised to the densities at the vertices of a grid of ``N``
cells per side with the sea at the mean density (:func:`density_grid`).  :func:`montreal_election` (a city) and
:func:`world_countries` (the world) are real maps to try it on.
"""
from __future__ import annotations

import json
import math
import numbers
import os

import numpy as np

from ..core.mesh import check_n
from .projection import PlanarFrame

__all__ = ["read_regions", "PlanarFrame", "density_grid", "fit_outlines", "clean_coverage", "montreal_election",
           "MONTREAL_CANDIDATES", "ZERO_FLOOR", "world_countries"]


#: The candidates of the 2013 Montreal mayoral election (vote counts per district in :func:`montreal_election`).
MONTREAL_CANDIDATES = ("Coderre", "Bergeron", "Joly")


#: A zero value is replaced by this fraction of the smallest positive density times the region's area.
ZERO_FLOOR = 0.1


def _shapely():
    try:
        import shapely
    except ImportError as e:  # pragma: no cover - shapely is a dependency
        raise ImportError("cartograms need shapely (pip install shapely)") from e
    return shapely


def _load_collection(collection) -> dict:
    """A FeatureCollection ``dict`` from a dict, a JSON string or a path."""
    if isinstance(collection, dict):
        return collection
    if isinstance(collection, (str, os.PathLike)):
        text = str(collection)
        if isinstance(collection, os.PathLike) or not text.lstrip().startswith("{"):
            try:
                with open(collection, encoding="utf-8") as fh:
                    text = fh.read()
            except OSError as e:
                raise ValueError(f"cannot read {os.fspath(collection)}: {e.strerror or e}") from e
            except UnicodeDecodeError as e:
                raise ValueError(f"cannot read {os.fspath(collection)}: not UTF-8 text ({e.reason} at byte "
                                 f"{e.start})") from e
        try:
            return json.loads(text)
        except json.JSONDecodeError as e:
            raise ValueError(f"not valid GeoJSON (JSON error: {e})") from e
    raise ValueError(f"expected a GeoJSON FeatureCollection (dict, JSON text or path), got {type(collection).__name__}")


def _geometry(geom: dict):
    """The shapely (Multi)Polygon of a GeoJSON Polygon or MultiPolygon geometry, as ``shapely.geometry.shape`` makes
    it, each ring read as one float array (shapely's constructors read a list of positions point by point, which on
    a country's subdivisions takes longer than parsing the file)."""
    shapely = _shapely()

    def polygon(rings):
        if not rings:
            return shapely.Polygon()
        shell, *holes = (np.asarray(ring, dtype=float) for ring in rings)
        return shapely.Polygon(shell, holes)

    if geom["type"] == "Polygon":
        return polygon(geom["coordinates"])
    return shapely.MultiPolygon([polygon(rings) for rings in geom["coordinates"]])


def read_regions(collection, value: str, *, floor: float = ZERO_FLOOR):
    """The polygons of a GeoJSON FeatureCollection and their values, checked.

    Parameters
    ----------
    collection : dict, str or path
        A FeatureCollection of Polygon / MultiPolygon features (a dict, JSON text, or a file name).
    value : str
        The feature property holding each region's value (a number :math:`\\ge 0`).
    floor : float
        Zero values become ``floor`` times the smallest positive density times the region's area (cartogram tools
        cannot shrink a region to nothing).

    Returns
    -------
    features : list of dict
        The input features (for their properties and ids).
    geoms : ndarray of shapely geometries, shape (R,)
    values : ndarray, float64, shape (R,)
        The values after flooring.
    floored : list of int
        Indices of the regions whose zero value was floored.

    Raises
    ------
    ValueError
        One line naming the problem: not a FeatureCollection, a feature without a Polygon / MultiPolygon geometry
        or with zero area, a missing, non-numeric, negative, NaN or infinite value, or all values zero.
    """
    shapely = _shapely()
    fc = _load_collection(collection)
    if not isinstance(fc, dict) or fc.get("type") != "FeatureCollection" or not isinstance(fc.get("features"), list):
        raise ValueError("not a GeoJSON FeatureCollection (need {'type': 'FeatureCollection', 'features': [...]})")
    features = fc["features"]
    if not features:
        raise ValueError("the FeatureCollection has no features")
    geoms, values = [], []
    for k, feat in enumerate(features):
        name = _feature_name(feat, k)
        geom = feat.get("geometry") if isinstance(feat, dict) else None
        if not isinstance(geom, dict) or geom.get("type") not in ("Polygon", "MultiPolygon"):
            got = geom.get("type") if isinstance(geom, dict) else type(geom).__name__
            raise ValueError(f"feature {name}: geometry must be a Polygon or MultiPolygon, got {got}")
        try:
            g = _geometry(geom)
        except Exception as e:  # noqa: BLE001 - shapely raises several types for malformed coordinates
            raise ValueError(f"feature {name}: malformed {geom['type']} coordinates ({e})") from e
        if g.is_empty or not np.isfinite(shapely.get_coordinates(g)).all() or g.area <= 0:
            raise ValueError(f"feature {name}: empty, non-finite or zero-area geometry")
        props = feat.get("properties") or {}
        if value not in props:
            raise ValueError(f"feature {name} has no property {value!r}")
        v = props[value]
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            raise ValueError(f"feature {name}: value {value!r} = {v!r} is not a number")
        v = float(v)
        if not math.isfinite(v):
            raise ValueError(f"feature {name}: value {value!r} is {v} (NaN or infinite)")
        if v < 0:
            raise ValueError(f"feature {name}: value {value!r} = {v:g} is negative")
        geoms.append(g)
        values.append(v)
    geoms = np.array(geoms, dtype=object)
    values = np.array(values)
    zero = np.flatnonzero(values == 0)
    if zero.size == values.size:
        raise ValueError(f"every value of {value!r} is zero")
    if zero.size:
        areas = shapely.area(geoms)
        pos = values > 0
        values[zero] = floor * float(np.min(values[pos] / areas[pos])) * areas[zero]
    return features, geoms, values, zero.tolist()


def _feature_name(feat, k: int) -> str:
    """``#k`` and, where the feature has one, its id (else its ``name`` property)."""
    fid = feat.get("id") if isinstance(feat, dict) else None
    if fid is not None:
        return f"#{k} (id {fid})"
    props = feat.get("properties") if isinstance(feat, dict) else None
    name = props.get("name") if isinstance(props, dict) else None
    return f"#{k}" + (f" ({name})" if isinstance(name, str) else "")


def density_grid(geoms: np.ndarray, values: np.ndarray, n: int, *, supersample: int = 4,
                 areas: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    r"""Vertex densities of a grid of ``n`` by ``n`` vertices of the unit square: the mean over each vertex's cell of
    :math:`\rho = v_i / a_i` inside region :math:`i` and the sea density :math:`\bar\rho = \sum v_i / \sum a_i`
    elsewhere.  ``n`` counts vertices, not cells: a cartogram of ``N`` cells per side (``n`` of
    :class:`~rfmap.cartogram.options.CartogramOptions`) passes ``N + 1``.

    The mean is taken along ``supersample`` horizontal scanlines per cell, each measured exactly: the cell's share of
    the line that lies in each region (computed for all cells of a row at once).  Where regions overlap (a border that
    two neighbours draw apart, a fold), a cell's covered shares :math:`c_i` sum to more than the share of the cell they
    cover; there the cell takes the mean density of its regions, :math:`\sum_i \rho_i c_i / \sum_i c_i`, over at most
    the whole cell (:math:`\min(1, \sum_i c_i)`) and the sea over the rest, so that every density is positive (the plain
    sum :math:`\bar\rho + \sum_i (\rho_i - \bar\rho) c_i` counts an overlap twice, and two sparse regions overlapping
    over a cell would make it negative).

    Parameters
    ----------
    geoms : ndarray of shapely geometries, shape (R,), inside the unit square
    values : ndarray, shape (R,), positive
    n : int
        Vertices per side; vertex ``(i, j)`` sits at :math:`(i, j)/(n-1)` and its cell is the square of side
        :math:`h = 1/(n-1)` around it (clipped to the unit square).
    supersample : int
        Scanlines per cell, at :math:`y = (j - 1/2 + (k + 1/2)/s) h`, :math:`k < s`.
    areas : ndarray, shape (R,), optional
        ``shapely.area(geoms)``, when the caller has measured it already.

    Returns
    -------
    density : ndarray, shape (n, n), ``density[i, j]`` at :math:`(i, j)/(n-1)`
    sea : float
        :math:`\bar\rho`.
    """
    shapely = _shapely()
    n = check_n(n)
    s = int(supersample)
    if s < 1:
        raise ValueError(f"supersample must be a positive integer, got {supersample!r}")
    areas = shapely.area(geoms) if areas is None else areas
    rho = values / areas
    sea = float(values.sum() / areas.sum())
    # excess density (above the sea) and 1 times the covered length, summed over each cell's scanlines (the density
    # times it is the excess plus the sea's times the cover)
    excess, cover = _scanline_rows(geoms, (rho - sea, np.ones_like(rho)), n, s)  # (row of cells, column)
    t = ((np.arange(n * s) + 0.5) / s - 0.5) / (n - 1)  # the scanlines' heights
    lines = np.add.reduceat(((t >= 0) & (t <= 1)).astype(float), np.arange(0, n * s, s))  # those in the square
    width = np.ones(n)
    width[[0, -1]] = 0.5  # the cells' widths within the square, in cells
    inv = 1.0 / lines  # the tables are (row of cells, column): divided by the lines, then the widths
    excess *= inv[:, None]
    cover *= inv[:, None]
    excess[:, [0, -1]] *= 2.0
    cover[:, [0, -1]] *= 2.0
    over = cover > 1.0 + OVERLAP_COVER  # overlapping regions: their mean density over the cell
    mass = excess[over] + sea * cover[over]  # sum_i rho_i c_i per cell
    excess += sea  # the density: sea + excess / size
    excess[over] = mass / cover[over]
    return excess.T, sea


#: A cell whose regions' covered shares sum to more than ``1 + OVERLAP_COVER`` holds an overlap (:func:`density_grid`);
#: below, the sum is 1 up to rounding on the borders that neighbours share
OVERLAP_COVER = 1e-9


def _scanline_rows(geoms: np.ndarray, weights: tuple, n: int, s: int) -> list[np.ndarray]:
    r"""The scanlines of :func:`density_grid`: for every array ``weight`` (R,) of ``weights``, ``out[b, c]`` is the
    sum, over the scanlines of cell row ``b`` that lie in :math:`[0, 1]` and over the regions, of their ``weight``
    times the length of the line inside the region and inside cell column ``c`` (within the square), in cell widths;
    a list of arrays of shape (N, N).

    Every ring edge crosses the scanlines :math:`y_r \in [y_0, y_1)` of its height (half-open, so that a vertex on a
    line counts once); per region and line the crossings, sorted, pair into spans (even-odd rule: holes and the
    parts of a MultiPolygon come out right).  A span :math:`[X_a, X_b)` (in cell units, clipped to the square) covers
    the cells from :math:`\lfloor X_a \rfloor` to :math:`\lfloor X_b \rfloor`: a difference array adds 1 to each,
    and two corrections take off the uncovered parts of the end cells.  :math:`O(\text{crossings} + N^2)` per
    call.
    """
    shapely = _shapely()
    m = n * s
    h = 1.0 / (n - 1)
    parts, part_of = shapely.get_parts(geoms, return_index=True)
    rings, ring_of = shapely.get_rings(parts, return_index=True)
    coords, ring_id = shapely.get_coordinates(rings, return_index=True)
    region = part_of[ring_of[ring_id]]
    same = ring_id[1:] == ring_id[:-1]  # consecutive points of one ring: an edge
    p0, p1, reg = coords[:-1][same], coords[1:][same], region[:-1][same]
    lo, hi = np.minimum(p0[:, 1], p1[:, 1]), np.maximum(p0[:, 1], p1[:, 1])

    def first_line(v):  # the smallest r with y_r >= v
        return np.clip(np.ceil(s * (v / h + 0.5) - 0.5), 0, m).astype(np.int64)

    b0, b1 = first_line(lo), first_line(hi)
    cnt = b1 - b0
    e = np.repeat(np.arange(len(cnt)), cnt)
    r = b0[e] + (np.arange(e.size) - np.repeat(np.cumsum(cnt) - cnt, cnt))  # scanline of each crossing
    ty = ((r + 0.5) / s - 0.5) * h
    a, b = p0[e], p1[e]
    x = a[:, 0] + (ty - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    key = reg[e] * m + r
    order = np.argsort(key, kind="stable")  # by region and line (runs: the lines of every edge come in order)
    key, x = key[order], x[order]
    x = _sort_within(key, x)  # then by x
    key = key[0::2]
    xa, xb, r, g = x[0::2], x[1::2], key % m, key // m  # every (region, line) holds an even number of crossings
    ty = ((r + 0.5) / s - 0.5) * h
    keep = (ty >= 0) & (ty <= 1)  # scanlines beyond the square do not count
    # cell units: cell c spans [c, c + 1), the square [1/2, N - 1/2]
    xa = np.clip(xa[keep] / h + 0.5, 0.5, n - 0.5)
    xb = np.clip(xb[keep] / h + 0.5, 0.5, n - 0.5)
    r, g = r[keep], g[keep]
    ca, cb = np.minimum(xa.astype(np.int64), n - 1), np.minimum(xb.astype(np.int64), n - 1)
    row = (r // s) * (n + 1)
    fa, fb = xa - ca, xb - cb  # the uncovered share of the first cell, the covered share of the last
    idx = np.concatenate([row + ca, row + cb, row + ca + 1, row + cb + 1])
    del x, r, xa, xb, ca, cb, row
    out = []
    for weight in weights:
        w = weight[g]
        # one difference array per weight: +w over the cells from the first to the last, less the first cell's
        # uncovered share and plus the last cell's covered share, each put at its cell and taken off at the next
        d = np.bincount(idx, np.concatenate([w * (1.0 - fa), -w * (1.0 - fb), w * fa, -w * fb]),
                        minlength=n * (n + 1)).reshape(n, n + 1)
        np.cumsum(d, axis=1, out=d)  # in place: at a 2049 raster every table is 34 MB
        out.append(d[:, :n])
    return out


def _sort_within(key: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``x`` (K,) sorted within every run of equal ``key`` (K,), a sorted array whose runs are of even length (a
    region's crossings of a scanline): the pairs ``x[2i], x[2i + 1]`` ordered by a swap (a run of two, most of
    them), then the longer runs by one sort of their entries; in place."""
    a, b = x[0::2].copy(), x[1::2]
    np.minimum(a, b, out=x[0::2])
    np.maximum(a, b, out=x[1::2])
    k = key[0::2]
    same = k[1:] == k[:-1]  # pairs of one longer run
    if same.any():
        long = np.repeat(np.r_[same, False] | np.r_[False, same], 2)
        sub = x[long]
        x[long] = sub[np.lexsort((sub, key[long]))]
    return x


def clean_coverage(regions: np.ndarray) -> np.ndarray:
    r"""The regions rebuilt as an exact coverage: every shared border drawn by the same vertices on both sides.

    Real maps draw a border twice, once per neighbour, and the two drawings need not match vertex for vertex (a
    vertex of one lies on an edge of the other, or a hair off it).  Such a map is no coverage in the sense of
    ``shapely.coverage_is_valid``, and simplifying it border by border opens slivers of overlap.  Here all the
    outlines are noded together (``shapely.union_all`` of the boundaries), cut into faces
    (``shapely.polygonize``), and every face goes to the first region that holds it; faces that no region holds
    (gaps, lakes, the sea) stay out.  Every area changes by no more than the original slivers between neighbours.

    Parameters
    ----------
    regions : ndarray of shapely geometries, shape (R,)

    Returns
    -------
    ndarray of shapely geometries, shape (R,)
        Valid polygons (multi-part where needed), without repeated points; a region that holds no face (a
        degenerate input) is returned as it was.
    """
    shapely = _shapely()
    lines = shapely.union_all(shapely.boundary(regions))
    faces = shapely.get_parts(shapely.polygonize(shapely.get_parts(lines)))
    face, region = shapely.STRtree(regions).query(shapely.point_on_surface(faces), predicate="within")
    order = np.lexsort((region, face))
    first = np.unique(face[order], return_index=True)[1]
    owner = np.full(len(faces), -1)
    owner[face[order][first]] = region[order][first]
    out = regions.copy()
    for k in np.flatnonzero(np.bincount(owner[owner >= 0], minlength=len(regions))):
        out[k] = shapely.coverage_union_all(faces[owner == k])
    return shapely.remove_repeated_points(out)


def fit_outlines(regions: np.ndarray, points: int, *, steps: int = 20) -> np.ndarray:
    r"""The region outlines with about ``points`` vertices in all: simplified when they hold more, densified when
    they hold fewer; shared borders stay shared.

    Simplification is topology-preserving over the whole coverage (``shapely.coverage_simplify``,
    Visvalingam–Whyatt: a border shared by two regions is simplified once, for both), on the regions made an exact
    coverage first (:func:`clean_coverage`), so that no two regions overlap afterwards; densification splits every
    edge evenly (``shapely.segmentize``), which keeps every area.  The tolerance or step is found by bisection on
    its logarithm, so the count ends within a few per cent of ``points`` (at most ``points`` when simplifying).

    Parameters
    ----------
    regions : ndarray of shapely geometries, shape (R,)
        A coverage: regions that meet along shared borders without overlaps.
    points : int
        The budget of vertices over all regions (ring closures counted).
    steps : int
        Bisection steps.

    Returns
    -------
    ndarray of shapely geometries, shape (R,)
    """
    shapely = _shapely()
    if isinstance(points, bool) or not isinstance(points, numbers.Integral) or points < 4 * len(regions):
        raise ValueError(f"points must be an integer of at least 4 per region ({4 * len(regions)}), got {points!r}")
    # shared borders split from either end agree only to the last bits: snap them, so the coverage's edges match
    uniq, inverse = _distinct_vertices(regions)
    regions = shapely.remove_repeated_points(shapely.set_coordinates(regions.copy(), uniq[inverse]))
    count = int(shapely.get_num_coordinates(regions).sum())
    if count == points:
        return regions
    x0, x1 = shapely.bounds(regions)[:, [0, 2]].min(), shapely.bounds(regions)[:, [1, 3]].max()
    lo, hi = math.log(1e-9 * (x1 - x0) + 1e-300), math.log(abs(x1 - x0) + 1e-300)
    if count > points:
        regions = clean_coverage(regions)

        def make(t):
            return shapely.coverage_simplify(regions, math.exp(t), simplify_boundary=True)
        fits = lambda g: shapely.get_num_coordinates(g).sum() <= points  # noqa: E731  (larger t: fewer points)
    else:
        def make(t):
            return shapely.segmentize(regions, math.exp(t))
        fits = lambda g: shapely.get_num_coordinates(g).sum() >= points  # noqa: E731  (smaller t: more points)
    best = None
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        g = make(mid)
        if fits(g):
            best = g
            lo, hi = (lo, mid) if count > points else (mid, hi)
        else:
            lo, hi = (mid, hi) if count > points else (lo, mid)
    return best if best is not None else make(hi if count > points else lo)


#: Coordinates (of the unit-square frame) closer than this are one vertex (:func:`_distinct_vertices`)
MERGE = 1e-12


def _runs(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group index (P,) of every entry of ``keys`` (complex: sorted by real, then imaginary part) among the distinct
    keys, numbered in sorted order, and the index of each group's first entry (its smallest index)."""
    order = np.argsort(keys, kind="stable")
    ks = keys[order]
    start = np.ones(len(ks), dtype=bool)
    start[1:] = ks[1:] != ks[:-1]
    groups = np.empty(len(ks), dtype=np.intp)
    groups[order] = np.cumsum(start) - 1
    return groups, order[start]


def _grid_groups(xy: np.ndarray, side: float, shift: tuple[float, float]) -> np.ndarray:
    """Group index (P,) of every point by its cell of a grid of side ``side`` shifted by ``shift`` cells."""
    k = np.floor(xy / side + np.asarray(shift))  # whole numbers, exact in double precision
    return _runs(k[:, 0] + 1j * k[:, 1])[0]


def _distinct_vertices(regions: np.ndarray, merge: float = MERGE) -> tuple[np.ndarray, np.ndarray]:
    """The distinct vertices (V, 2) of ``regions`` and the index (K,) of every coordinate among them: each is mapped
    once, so that neighbours keep identical edges.

    A border split from either end gives points that agree only to the last bits, and rounding them to a grid
    would part the rare pair that straddles a cell's edge.  Points are merged instead when they share a cell of any
    of four grids of side ``merge`` (shifted by half a cell in x, y or both): two points closer than a quarter
    cell in both coordinates always share one of them.  Merged groups are closed transitively; each keeps its
    first point.  Repeats of the very same point (most shared borders) are merged first, by one sort."""
    xy = _shapely().get_coordinates(regions)
    if len(xy) == 0:
        return xy, np.zeros(0, dtype=np.intp)
    exact, first = _runs(xy[:, 0] + 1j * xy[:, 1])
    label = first.copy()  # every distinct point's smallest index among its repeats
    near = _near_in_x(xy[first, 0], 2.0 * merge)  # the others share no grid cell with any point
    pts, sub = xy[first[near]], label[near]
    grids = [_grid_groups(pts, merge, s) for s in ((0.0, 0.0), (0.5, 0.0), (0.0, 0.5), (0.5, 0.5))]
    while sub.size:
        new = sub
        for g in grids:
            low = np.full(g.max() + 1, len(xy))
            np.minimum.at(low, g, new)
            new = low[g]
        if np.array_equal(new, sub):
            break
        sub = new
    label[near] = sub
    used = np.zeros(len(xy), dtype=bool)  # the kept points, in the order of their indices (np.unique's)
    used[label] = True
    return xy[used], (np.cumsum(used) - 1)[label[exact]]


def _near_in_x(x: np.ndarray, gap: float) -> np.ndarray:
    """Which of the sorted values ``x`` (P,) lie within ``gap`` of another (boolean, (P,))."""
    close = np.diff(x) <= gap
    return np.r_[close, False] | np.r_[False, close]


def _longest_edge(regions: np.ndarray) -> float:
    """The longest edge of any ring of ``regions`` (consecutive coordinates of one ring)."""
    return float(_longest_edges(regions).max(initial=0.0))


def _longest_edges(regions: np.ndarray) -> np.ndarray:
    """The longest edge of every region's rings (consecutive coordinates of one ring), shape (R,); 0 for a region
    without edges."""
    shapely = _shapely()
    parts, part_of = shapely.get_parts(regions, return_index=True)
    rings, ring_of = shapely.get_rings(parts, return_index=True)
    xy, idx = shapely.get_coordinates(rings, return_index=True)
    step = np.hypot(*np.diff(xy, axis=0).T)
    same = idx[1:] == idx[:-1]
    out = np.zeros(len(regions))
    np.maximum.at(out, part_of[ring_of[idx[1:][same]]], step[same])
    return out


def _segmentize(regions: np.ndarray, cell: float, long: np.ndarray) -> np.ndarray:
    """``shapely.segmentize(regions, cell)`` given the regions with an edge longer than ``cell`` (``long``, boolean
    (R,)): only those are split; the others come out as segmentize leaves them (a one-part MultiPolygon as its
    Polygon)."""
    shapely = _shapely()
    out = regions.copy()
    out[long] = shapely.segmentize(regions[long], cell)
    one = ~long & (shapely.get_type_id(regions) == 6) & (shapely.get_num_geometries(regions) == 1)
    out[one] = shapely.get_geometry(regions[one], 0)
    return out


def _listify(obj):
    """Tuples (as shapely's ``mapping`` writes coordinates) to lists, for a GeoJSON dict that equals its JSON."""
    if isinstance(obj, (list, tuple)):
        return [_listify(o) for o in obj]
    if isinstance(obj, dict):
        return {k: _listify(v) for k, v in obj.items()}
    return obj


def montreal_election() -> dict:
    """The 2013 Montreal mayoral election as a FeatureCollection: 58 districts with the votes of
    :data:`MONTREAL_CANDIDATES` and ``total`` as properties (from the data that plotly ships; needs the ``geo``
    extra: ``pip install rfmap[geo]``)."""
    try:
        import plotly.data
    except ImportError as e:
        raise ImportError("the Montreal election data come with plotly: pip install 'rfmap[geo]'") from e
    gj = plotly.data.election_geojson()
    table = plotly.data.election()
    rows = {int(r["district_id"]): r for r in table.to_dict("records")}  # district names differ in spelling
    feats = []
    for f in gj["features"]:
        r = rows[int(f["id"])]
        props = {"district": f["properties"]["district"], "winner": str(r["winner"]),
                 **{k: int(r[k]) for k in (*MONTREAL_CANDIDATES, "total")}}
        feats.append({"type": "Feature", "id": f.get("id"), "properties": props, "geometry": f["geometry"]})
    return {"type": "FeatureCollection", "features": feats}


def world_countries() -> dict:
    """The countries of the world as a FeatureCollection: 177 features with the properties ``name``, ``iso_a3``,
    ``continent`` and ``pop_est`` (estimated population), as multi-part countries and islands are drawn at the 1:110m
    scale.

    Natural Earth's 1:110m Admin 0 countries (public domain, https://www.naturalearthdata.com), from the
    ``naturalearth_lowres`` data set that geopandas 0.14.4 shipped, converted (by a script of the source repository) to
    the package's ``data/naturalearth_lowres.geojson`` (coordinates rounded to 4 decimals).  Longitude/latitude on
    WGS84; the countries that cross the antimeridian (Russia, Fiji) are split there.
    """
    from importlib import resources

    text = resources.files("rfmap").joinpath("data", "naturalearth_lowres.geojson").read_text(encoding="utf-8")
    return json.loads(text)
