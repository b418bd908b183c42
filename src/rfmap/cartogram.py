r"""Cartograms of real regions: GeoJSON polygons resized by a value per region (diffusion and flow-based cartograms).

A contiguous cartogram redraws every region :math:`i` of a map with an area proportional to its value :math:`v_i`
(population, votes) while keeping neighbours adjacent.  The diffusion cartogram of Gastner & Newman (2004) is the
density-equalizing map of the density :math:`\rho = v_i / a_i` (value over area) of the region under each point:

1. **Planar frame.**  Longitude/latitude are projected by the equirectangular projection centred on the map,
   :math:`(x, y) = (\lambda \cos\varphi_0, \varphi)` (areas then agree with the sphere's to
   :math:`O(\Delta\varphi^2)` across a city or a country), and the map's bounding box is fitted into the unit square
   leaving a ``margin`` on every side (:class:`PlanarFrame`).
2. **Density raster.**  Each vertex of the ``N``-grid gets the mean density over its grid cell, measured by
   ``supersample``:sup:`2` point-in-polygon tests per cell (``shapely.contains_xy``).  Outside every region lies
   the sea at the mean density :math:`\sum_i v_i / \sum_i a_i`, as cartogram tools do, so that the land keeps its
   total area and the coast may move.
3. **Map.**  The classical diffusion DEM of the unit square (:func:`rfmap.solvers.solve_dem` with
   ``boundary="square"``: the square's walls are the edge of the sea and stay put), the flow-based DEM of Gastner,
   Seguy & More (2018) that today's cartogram programs run (``solve_dem(method="flow")``, one flow per pass), or a
   neural surrogate of the same task (``deq2d-square``) on its working grid, where its output is repaired to be
   fold-free.  The hybrid resamples the network's map to the ``N``-grid and finishes it there with the flow
   (``Surrogate.map(polish=...)``, :data:`HYBRID_POLISH`).  The grid map's
   displacement is interpolated bilinearly at the distinct polygon vertices (:func:`rfmap.mesh.interpolate`).
4. **Passes.**  A diffusion on an ``N``-grid smears every coastline and border over a grid cell, so small dense
   regions come out a little small and sparse ones a little large.  The cartogram is therefore computed again from
   the mapped polygons, whose densities are now nearly equal, and the maps are composed, until the largest relative
   area error is below ``tol`` (flow-based cartogram programs stop at 1 %, the default).
5. **Output.**  Edges longer than a grid cell are first split (``shapely.segmentize``) so that they bend with the
   map; every vertex is mapped, shared borders stay shared, and the polygons are returned in the input's
   coordinates (the inverse of the planar frame) as a GeoJSON FeatureCollection with the input's properties.

Metrics of the cartogram literature (:func:`cartogram_metrics`): the relative area error
:math:`|A_i / T_i - 1|` with the target :math:`T_i = (v_i / \sum_j v_j) \sum_j A_j`, its mean and maximum over
the regions, and a topology check: every mapped polygon is valid and no two regions overlap by more than
``overlap_tol`` of the total area.

References
----------
M. T. Gastner, M. E. J. Newman, "Diffusion-based method for producing density-equalizing maps",
Proc. Natl. Acad. Sci. USA 101(20), 7499–7504 (2004).

M. T. Gastner, V. Seguy, P. More, "Fast flow-based algorithm for creating density-equalizing map projections",
Proc. Natl. Acad. Sci. USA 115(10), E2156–E2164 (2018).
"""
from __future__ import annotations

import json
import math
import numbers
import os
import time
from dataclasses import dataclass, field

import numpy as np
import torch

from .mesh import check_grid_memory, check_n, grid_points, interpolate

__all__ = [
    "CARTOGRAM_METHODS",
    "Cartogram",
    "CartogramMetrics",
    "PlanarFrame",
    "read_regions",
    "density_grid",
    "cartogram",
    "cartogram_metrics",
    "available_methods",
    "compare_cartograms",
    "cartogram_table",
    "montreal_election",
    "MONTREAL_CANDIDATES",
    "DEM_SETTINGS",
    "FLOW_SETTINGS",
    "HYBRID_POLISH",
    "ZERO_FLOOR",
]

#: Methods of :func:`cartogram`.
CARTOGRAM_METHODS = ("dem", "flow", "surrogate", "hybrid")

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


# ----------------------------------------------------------------------------------------------- input
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
        try:
            return json.loads(text)
        except json.JSONDecodeError as e:
            raise ValueError(f"not valid GeoJSON (JSON error: {e})") from e
    raise ValueError(f"expected a GeoJSON FeatureCollection (dict, JSON text or path), got {type(collection).__name__}")


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
    from shapely.geometry import shape

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
            g = shape(geom)
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
    """``#k`` and, where the feature has one, its id."""
    fid = feat.get("id") if isinstance(feat, dict) else None
    return f"#{k}" + (f" (id {fid})" if fid is not None else "")


# ----------------------------------------------------------------------------------------------- frame
@dataclass(frozen=True)
class PlanarFrame:
    r"""The input coordinates to the unit square and back: :math:`u = s\,(P(x) - c) + (\tfrac12, \tfrac12)`.

    ``P`` is the equirectangular projection :math:`(\lambda\cos\varphi_0, \varphi)` for longitude/latitude input
    (``cos_lat`` :math:`= \cos\varphi_0`), the identity for planar input (``cos_lat = 1``); ``c`` is the centre of
    the projected bounding box and ``s`` fits its longer side into :math:`1 - 2\,\mathrm{margin}`.
    """

    cos_lat: float
    center: tuple[float, float]
    scale: float

    @classmethod
    def fit(cls, coords: np.ndarray, *, margin: float, projection: str = "auto") -> "PlanarFrame":
        """The frame of points ``coords`` (P, 2); ``projection`` is ``"auto"`` (equirectangular when every point
        is a longitude/latitude pair), ``"equirectangular"`` or ``"none"``."""
        if projection not in ("auto", "equirectangular", "none"):
            raise ValueError(f"unknown projection {projection!r}; choose auto, equirectangular or none")
        if not 0 <= margin < 0.5:
            raise ValueError(f"margin must be in [0, 0.5), got {margin!r}")
        lonlat = bool((np.abs(coords[:, 0]) <= 180).all() and (np.abs(coords[:, 1]) <= 90).all())
        geographic = projection == "equirectangular" or (projection == "auto" and lonlat)
        cos_lat = math.cos(math.radians(0.5 * (coords[:, 1].min() + coords[:, 1].max()))) if geographic else 1.0
        p = coords * np.array([cos_lat, 1.0])
        lo, hi = p.min(0), p.max(0)
        side = float((hi - lo).max())
        if side <= 0:
            raise ValueError("the regions have no extent")
        return cls(cos_lat, tuple(0.5 * (lo + hi)), (1.0 - 2.0 * margin) / side)

    def forward(self, coords: np.ndarray) -> np.ndarray:
        """Input coordinates (P, 2) to the unit square."""
        return (coords * np.array([self.cos_lat, 1.0]) - np.array(self.center)) * self.scale + 0.5

    def inverse(self, u: np.ndarray) -> np.ndarray:
        """Unit-square points (P, 2) to input coordinates."""
        return ((u - 0.5) / self.scale + np.array(self.center)) / np.array([self.cos_lat, 1.0])


def _transform(geoms: np.ndarray, fn) -> np.ndarray:
    """Apply ``fn`` (P, 2) -> (P, 2) to every vertex of every geometry at once."""
    shapely = _shapely()
    return shapely.transform(geoms, fn)


# ----------------------------------------------------------------------------------------------- raster
def density_grid(geoms: np.ndarray, values: np.ndarray, n: int, *, supersample: int = 4) -> tuple[np.ndarray, float]:
    r"""Vertex densities of the ``N``-grid of the unit square: the mean over each vertex's cell of
    :math:`\rho = v_i / a_i` inside region :math:`i` and the sea density :math:`\bar\rho = \sum v_i / \sum a_i`
    elsewhere.

    Parameters
    ----------
    geoms : ndarray of shapely geometries, shape (R,), inside the unit square
    values : ndarray, shape (R,), positive
    n : int
        Grid side ``N``; vertex ``(i, j)`` sits at :math:`(i, j)/(N-1)` and its cell is the square of side
        :math:`h = 1/(N-1)` around it (clipped to the unit square).
    supersample : int
        Point-in-polygon samples per cell side (``supersample``\ :sup:`2` per cell).

    Returns
    -------
    density : ndarray, shape (N, N), ``density[i, j]`` at :math:`(i, j)/(N-1)`
    sea : float
        :math:`\bar\rho`.
    """
    shapely = _shapely()
    n = check_n(n)
    s = int(supersample)
    areas = shapely.area(geoms)
    rho = values / areas
    sea = float(values.sum() / areas.sum())
    h = 1.0 / (n - 1)
    # sample k of vertex i along an axis sits at (i - 1/2 + (k + 1/2)/s) h; fine index f = i*s + k
    m = n * s
    t = (np.arange(m) // s - 0.5 + (np.arange(m) % s + 0.5) / s) * h
    inside = (t >= 0) & (t <= 1)  # samples of boundary cells beyond the square do not count
    excess = np.zeros((m, m))  # density above the sea at every sample
    for g, r in zip(geoms, rho):
        x0, y0, x1, y1 = g.bounds
        i0, i1 = np.searchsorted(t, [x0, x1])
        j0, j1 = np.searchsorted(t, [y0, y1])
        if i1 <= i0 or j1 <= j0:
            continue
        xx, yy = np.meshgrid(t[i0:i1], t[j0:j1], indexing="ij")
        hit = shapely.contains_xy(g, xx, yy)
        excess[i0:i1, j0:j1] += hit * (r - sea)
    excess *= inside[:, None] & inside[None, :]
    count = np.add.reduceat(np.add.reduceat((inside[:, None] & inside[None, :]).astype(float), np.arange(0, m, s), 0),
                            np.arange(0, m, s), 1)
    total = np.add.reduceat(np.add.reduceat(excess, np.arange(0, m, s), 0), np.arange(0, m, s), 1)
    return sea + total / count, sea


# ----------------------------------------------------------------------------------------------- maps
#: Settings of :func:`rfmap.solvers.solve_dem` for cartograms: the raster already holds cell means, so the velocity
#: is evaluated on the vertex grid itself (``refine=1``: three times faster than ``refine=2`` and no less accurate
#: here), and the flow stops when the remaining displacement is below 1 % of a cell.
DEM_SETTINGS = {"refine": 1, "tol_end": 1e-2}
#: Settings of the flow-based solver (``solve_dem(method="flow")``) for cartograms: one flow per pass, whatever the
#: density's remaining variation (``tol=0``: the cartogram's passes stop on the area errors, while the solver's own
#: tolerance on Std(rho~) would skip a pass once the raster is nearly uniform and leave a district at 1-3 % error),
#: on the vertex grid (``refine=1``).  Montreal's four cartograms at N = 256 (2013 election, total and each
#: candidate's votes): largest area error 0.003-0.009 in 4-6 passes and 0.38-0.87 s, against 0.0048-0.0069 in 4-7
#: passes and 0.40-1.12 s with ``refine=2``; the diffusion DEM reaches 0.0024-0.0077 in 4-6 passes and 1.0-1.5 s.
FLOW_SETTINGS = {"refine": 1, "tol": 0.0}
#: The hybrid's polish tolerance on Std(rho~_map) (``Surrogate.map(polish=...)``): far below any raster's variation, so
#: that every pass runs its flow, for the reason of :data:`FLOW_SETTINGS`' ``tol=0``.  The polish runs on the
#: raster's ``N``-grid (the network's map resampled to it): on the network's working grid (96 for ``deq2d-square``)
#: with the solver's default tolerance, Montreal's total votes at N = 256 stopped at a largest error of 0.027 after 9
#: passes (Bergeron's votes: 0.063 after 10); on the ``N``-grid, 0.0049-0.0069 in 4-7 passes and 0.67-1.32 s.
HYBRID_POLISH = 1e-9


def _at_points(res, points: np.ndarray) -> np.ndarray:
    """The grid map ``res`` (a :class:`rfmap.result.MapResult` on the ``N``-grid) at ``points`` (P, 2): its
    displacement interpolated bilinearly."""
    n = math.isqrt(res.ref_points.shape[0])
    disp = (res.mapped_points - res.ref_points).T.reshape(1, 2, n, n)
    return points + interpolate(torch.as_tensor(disp), torch.as_tensor(points))[0].numpy()


def _grid_map(method: str, density: np.ndarray, surrogate, solver_kw: dict):
    """The map of the unit square for one pass: the classical diffusion or flow DEM with fixed walls, the
    surrogate's map on its working grid (repaired there, so that it is fold-free before it is interpolated at the
    polygon vertices), or the hybrid's on the raster's ``N``-grid."""
    if method in ("dem", "flow"):
        from .solvers import solve_dem

        if method == "flow":
            return solve_dem(density, method="flow", boundary="square", **{**FLOW_SETTINGS, **solver_kw})
        return solve_dem(density, boundary="square", **{**DEM_SETTINGS, **solver_kw})
    from .surrogate import quiet_quality

    # the raster's Std(rho~) counts the sea and every region's edge; the cartogram judges a pass by its area errors
    with quiet_quality():
        if method == "hybrid":  # the network's map resampled to the N-grid and finished there by the flow
            return surrogate.map(density, density.shape[0], preprocess=False, polish=HYBRID_POLISH)
        return surrogate.map(density, surrogate.work_n(density.shape[0]), preprocess=False)


def _supports_polish(surrogate) -> bool:
    import inspect

    return "polish" in inspect.signature(surrogate.map).parameters


def available_methods(surrogate) -> tuple[str, ...]:
    """The methods of :func:`cartogram` that ``surrogate`` (an :class:`rfmap.Surrogate`) supports: ``"hybrid"``
    needs ``Surrogate.map(polish=...)``."""
    return CARTOGRAM_METHODS if _supports_polish(surrogate) else tuple(m for m in CARTOGRAM_METHODS if m != "hybrid")


# ----------------------------------------------------------------------------------------------- result
@dataclass
class CartogramMetrics:
    """Area errors and topology of a cartogram (see :func:`cartogram_metrics`)."""

    mean_error: float
    max_error: float
    n_invalid: int
    max_overlap: float
    n_overlapping: int
    overlap_tol: float

    @property
    def topology_ok(self) -> bool:
        """Every polygon valid and no pair of regions overlapping by more than ``overlap_tol``."""
        return self.n_invalid == 0 and self.n_overlapping == 0

    def __str__(self) -> str:
        topo = "valid, no overlaps" if self.topology_ok else \
            f"{self.n_invalid} invalid, {self.n_overlapping} overlapping pairs (max {self.max_overlap:.2g})"
        return f"area error mean {self.mean_error:.4f}, max {self.max_error:.4f}; {topo}"


@dataclass
class Cartogram:
    """A computed cartogram.

    Attributes
    ----------
    features : list of dict
        The mapped features, in the input's coordinates, with the input's properties and ids.
    regions, mapped : ndarray of shapely geometries, shape (R,)
        The regions before and after mapping, in the unit-square frame.
    values : ndarray, shape (R,)
        The values mapped to (zero values floored).
    floored : list of int
        Regions whose zero value was floored.
    frame : PlanarFrame
    method : str
    n : int
        Grid side of the density raster.
    time : float
        Seconds from the parsed input to the mapped polygons (rasterisation, maps, vertex mapping).
    map_time : float
        Seconds in the map computations themselves (solver or surrogate) over all iterations.
    info : dict
        ``iterations``, ``kept`` (the pass whose polygons are returned), ``max_error`` per pass, per-iteration
        ``results`` (:class:`rfmap.result.MapResult`), ``sea`` density.
    """

    features: list
    regions: np.ndarray
    mapped: np.ndarray
    values: np.ndarray
    floored: list
    frame: PlanarFrame
    method: str
    n: int
    time: float
    map_time: float
    info: dict = field(default_factory=dict)

    @property
    def areas(self) -> np.ndarray:
        """Mapped area of every region (unit-square frame), shape (R,)."""
        return _shapely().area(self.mapped)

    @property
    def target_areas(self) -> np.ndarray:
        r""":math:`T_i = (v_i / \sum_j v_j) \sum_j A_j`, shape (R,)."""
        a = self.areas
        return self.values / self.values.sum() * a.sum()

    @property
    def area_errors(self) -> np.ndarray:
        r"""Relative area errors :math:`|A_i / T_i - 1|`, shape (R,)."""
        return np.abs(self.areas / self.target_areas - 1.0)

    def metrics(self, *, overlap_tol: float = 1e-6) -> CartogramMetrics:
        """Area errors and topology (:func:`cartogram_metrics`)."""
        return cartogram_metrics(self.mapped, self.values, overlap_tol=overlap_tol)

    def to_geojson(self) -> dict:
        """The mapped FeatureCollection (input coordinates)."""
        return {"type": "FeatureCollection", "features": self.features}

    def save(self, path) -> None:
        """Write the mapped FeatureCollection as GeoJSON, atomically."""
        path = os.fspath(path)
        tmp = f"{path}.part"
        try:
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(self.to_geojson(), fh)
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.remove(tmp)
            raise

    def input_geometries(self) -> np.ndarray:
        """The input regions in the input's coordinates."""
        return _transform(self.regions, self.frame.inverse)

    def output_geometries(self) -> np.ndarray:
        """The mapped regions in the input's coordinates."""
        return _transform(self.mapped, self.frame.inverse)


def cartogram_metrics(mapped: np.ndarray, values: np.ndarray, *, overlap_tol: float = 1e-6,
                      topology: bool = True) -> CartogramMetrics:
    r"""Relative area errors and topology of mapped regions.

    The area error of region :math:`i` is :math:`|A_i / T_i - 1|` with :math:`T_i = (v_i/\sum_j v_j)\sum_j A_j`;
    a polygon is invalid when shapely says so (self-intersection, a hole outside its shell, ...); two regions
    overlap when the area of their intersection exceeds ``overlap_tol`` times the total area.

    Parameters
    ----------
    mapped : ndarray of shapely geometries, shape (R,)
    values : ndarray, shape (R,), positive
    overlap_tol : float
    topology : bool
        ``False`` skips the validity and overlap checks (their counts are then reported as zero).

    Returns
    -------
    CartogramMetrics
    """
    shapely = _shapely()
    a = shapely.area(mapped)
    err = np.abs(a / (values / values.sum() * a.sum()) - 1.0)
    if not topology:
        return CartogramMetrics(float(err.mean()), float(err.max()), 0, 0.0, 0, overlap_tol)
    valid = shapely.is_valid(mapped)
    total = float(a.sum())
    tree = shapely.STRtree(mapped)
    left, right = tree.query(mapped, predicate="intersects")
    keep = left < right
    left, right = left[keep], right[keep]
    ok = valid[left] & valid[right]
    g = np.asarray(mapped)
    inter = np.zeros(left.size)
    inter[ok] = shapely.area(shapely.intersection(g[left[ok]], g[right[ok]]))
    inter[~ok] = np.inf  # an invalid polygon's overlaps are not measurable; it is already counted as invalid
    rel = inter / total
    over = rel > overlap_tol
    measured = rel[np.isfinite(rel)]
    return CartogramMetrics(mean_error=float(err.mean()), max_error=float(err.max()),
                            n_invalid=int((~valid).sum()), max_overlap=float(measured.max()) if measured.size else 0.0,
                            n_overlapping=int((over & ok).sum()), overlap_tol=overlap_tol)


# ----------------------------------------------------------------------------------------------- pipeline
def cartogram(collection, value: str, *, method: str = "dem", n: int = 256, tol: float = 0.01,
              max_iterations: int = 10, iterations: int | None = None, margin: float = 0.1,
              projection: str = "auto", supersample: int = 4, model: str | None = None, surrogate=None,
              floor: float = ZERO_FLOOR, solver_kw: dict | None = None) -> Cartogram:
    r"""Diffusion cartogram of GeoJSON regions sized by one value each (see the module docstring).

    Parameters
    ----------
    collection : dict, str or path
        A GeoJSON FeatureCollection of Polygon / MultiPolygon features.
    value : str
        The property holding each region's value (numbers :math:`\ge 0`; zeros are floored, see
        :func:`read_regions`).
    method : {"dem", "flow", "surrogate", "hybrid"}
        ``"dem"``: the classical diffusion DEM; ``"flow"``: the classical flow-based DEM (:data:`FLOW_SETTINGS`);
        ``"surrogate"``: a pretrained neural surrogate; ``"hybrid"``: the surrogate's map finished by the classical
        flow on the ``N``-grid (``Surrogate.map(polish=HYBRID_POLISH)``).
    n : int
        Side ``N`` of the density raster and of the classical solver's grid.
    tol, max_iterations : float, int
        Passes are repeated, each from the previous pass's polygons, until the largest relative area error is at
        most ``tol`` (the usual stopping rule of cartogram tools), a pass no longer lowers it, or ``max_iterations``
        passes are done; the polygons of the pass with the lowest largest error are returned.
    iterations : int, optional
        A fixed number of passes instead (``tol`` and ``max_iterations`` are then ignored).
    margin : float
        Sea around the map: the map's bounding box is fitted into :math:`[\mathrm{margin}, 1-\mathrm{margin}]^2`.
    projection : {"auto", "equirectangular", "none"}
        See :class:`PlanarFrame`.
    supersample : int
        Point-in-polygon samples per grid cell side (:func:`density_grid`).
    model : str, optional
        Shipped surrogate for ``"surrogate"`` / ``"hybrid"`` (default ``"deq2d-square"``); ``surrogate`` passes a
        loaded :class:`rfmap.Surrogate` instead.  It must map 2D densities with the square's walls fixed, as the
        sea's edge is the unit square.
    floor : float
        Zero-value floor (:func:`read_regions`).
    solver_kw : dict, optional
        Keyword arguments of :func:`rfmap.solvers.solve_dem` over :data:`DEM_SETTINGS` (``"dem"``) or
        :data:`FLOW_SETTINGS` (``"flow"``).

    Returns
    -------
    Cartogram
        ``info["max_error"]`` lists the largest relative area error after every pass, ``info["iterations"]`` the
        passes run and ``info["kept"]`` the pass whose polygons are returned (1-based).

    Raises
    ------
    ValueError
        For bad input (one line: see :func:`read_regions`), an unknown method, a surrogate that does not map 2D
        densities of the square, or ``"hybrid"`` with a surrogate whose ``map`` has no ``polish`` option.
    """
    shapely = _shapely()
    from shapely.geometry import mapping as to_geojson

    if method not in CARTOGRAM_METHODS:
        raise ValueError(f"unknown cartogram method {method!r}; choose one of {', '.join(CARTOGRAM_METHODS)}")
    n = check_n(n)
    check_grid_memory(n, 2)
    fixed = iterations is not None
    passes = iterations if fixed else max_iterations
    if isinstance(passes, bool) or not isinstance(passes, (int, np.integer)) or passes < 1:
        raise ValueError(f"{'iterations' if fixed else 'max_iterations'} must be a positive integer, got {passes!r}")
    if not (isinstance(tol, numbers.Real) and tol >= 0):
        raise ValueError(f"tol must be a number >= 0, got {tol!r}")
    features, geoms, values, floored = read_regions(collection, value, floor=floor)
    if method not in ("dem", "flow"):
        if surrogate is None:
            from .surrogate import Surrogate

            surrogate = Surrogate.pretrained(model or "deq2d-square")
        spec = surrogate.spec
        if (spec.kind, spec.dim, spec.boundary) != ("density", 2, "square"):
            raise ValueError(f"a cartogram needs a 2D density model of the square (e.g. deq2d-square); "
                             f"{surrogate.name!r} maps {spec.dim}D {spec.kind} fields with a {spec.boundary} boundary")
        if method == "hybrid" and not _supports_polish(surrogate):
            raise ValueError("method 'hybrid' needs Surrogate.map(polish=...), which this version of rfmap lacks")

    t0 = time.perf_counter()
    frame = PlanarFrame.fit(shapely.get_coordinates(geoms), margin=margin, projection=projection)
    # edges longer than a grid cell are split, so that they bend with the map (and a border that one neighbour
    # draws with more vertices than the other still matches it)
    regions = shapely.segmentize(_transform(geoms, frame.forward), 1.0 / (n - 1))
    # shared borders: every distinct vertex is mapped once, so that neighbours keep identical edges
    # (to 1e-12 of the frame: a split border's points, computed from either end, differ in the last bits)
    uniq, inverse = np.unique(np.round(shapely.get_coordinates(regions), 12), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    current, mapped = uniq, regions
    results, history, map_time = [], [], 0.0
    best = None  # (largest area error, polygons, pass) of the best pass so far
    for _ in range(int(passes)):
        dens, sea = density_grid(mapped, values, n, supersample=supersample)
        res = _grid_map(method, dens, surrogate, solver_kw or {})
        current = _at_points(res, current)
        map_time += res.time
        results.append(res)
        mapped = shapely.set_coordinates(regions.copy(), current[inverse])
        history.append(cartogram_metrics(mapped, values, topology=False).max_error)
        if best is None or history[-1] < best[0]:
            best = (history[-1], mapped, len(results))
        if not fixed and (history[-1] <= tol or len(history) > 1 and not history[-1] < history[-2]):
            break  # within tolerance, or a pass that no longer lowers the largest error
    kept = len(results)
    if not fixed:  # the polygons of the pass with the lowest largest error
        mapped, kept = best[1], best[2]
    elapsed = time.perf_counter() - t0

    out = []
    for feat, g in zip(features, _transform(mapped, frame.inverse)):
        f = {k: v for k, v in feat.items() if k not in ("geometry", "bbox")}
        f.update(type="Feature", geometry=_listify(to_geojson(g)), properties=dict(feat.get("properties") or {}))
        out.append(f)
    return Cartogram(features=out, regions=regions, mapped=mapped, values=values, floored=floored, frame=frame,
                     method=method, n=n, time=elapsed, map_time=map_time,
                     info={"iterations": len(results), "kept": kept, "max_error": history, "results": results,
                           "sea": sea})


def compare_cartograms(collection, values, runs: dict, *, n: int = 256, surrogate=None) -> dict:
    """Cartograms of one map by several values and several runs of :func:`cartogram`.

    Parameters
    ----------
    collection : dict, str or path
    values : sequence of str
        Property names.
    runs : dict
        ``{label: keyword arguments of cartogram}``, e.g. ``{"dem": {}, "surrogate, 1 pass": {"method":
        "surrogate", "iterations": 1}}``.
    n : int
    surrogate : rfmap.Surrogate, optional
        Shared by the surrogate runs (loaded once).

    Returns
    -------
    dict
        ``{(value, label): Cartogram}``.

    Notes
    -----
    A given ``surrogate`` first maps a uniform density once, untimed: the first call pays PyTorch's one-time set-up,
    which would otherwise be charged to whichever run comes first.
    """
    if surrogate is not None:
        from .surrogate import quiet_quality

        with quiet_quality():  # a uniform density: any movement at all leaves it "less equal"
            surrogate.map(np.ones((surrogate.n_range[0],) * 2), preprocess=False)
    return {(v, label): cartogram(collection, v, n=n, surrogate=surrogate, **kw)
            for v in values for label, kw in runs.items()}


def cartogram_table(cartos: dict) -> str:
    """A Markdown table of :func:`compare_cartograms`' results: area errors, topology, passes and seconds."""
    lines = ["| value | method | N | passes | mean error | max error | topology | time (s) | map time (s) |",
             "|---|---|---:|---:|---:|---:|---|---:|---:|"]
    for (v, label), c in cartos.items():
        m = c.metrics()
        topo = "valid" if m.topology_ok else f"{m.n_invalid} invalid, {m.n_overlapping} overlaps"
        lines.append(f"| {v} | {label} | {c.n} | {c.info['iterations']} | {m.mean_error:.4f} | {m.max_error:.4f} | "
                     f"{topo} | {c.time:.2f} | {c.map_time:.2f} |")
    return "\n".join(lines)


def _listify(obj):
    """Tuples (as shapely's ``mapping`` writes coordinates) to lists, for a GeoJSON dict that equals its JSON."""
    if isinstance(obj, (list, tuple)):
        return [_listify(o) for o in obj]
    if isinstance(obj, dict):
        return {k: _listify(v) for k, v in obj.items()}
    return obj


# ----------------------------------------------------------------------------------------------- data
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
