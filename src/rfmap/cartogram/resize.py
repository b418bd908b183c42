r"""The cartogram pipeline: GeoJSON polygons resized by a value per region, pass after pass.

A contiguous cartogram redraws every region :math:`i` of a map with an area proportional to its value :math:`v_i`
(population, votes) while keeping neighbours adjacent: it is the density-equalizing map (Gastner & Newman 2004) of
the density :math:`\rho = v_i / a_i` (value over area) of the region under each point, made in five steps:

1. **Planar frame.**  Longitude/latitude are projected to a plane where areas are the Earth's: the Lambert azimuthal
   equal-area projection centred on the map, or Equal Earth for a world map (:mod:`rfmap.cartogram.projection`; a map
   that crosses the antimeridian is centred there).  Long edges are first split along their straight lines in
   longitude/latitude, so that they bend as the projection bends them.  The map's bounding box is fitted into the unit
   square leaving a ``margin`` on every side (:class:`~rfmap.cartogram.projection.PlanarFrame`).
2. **Density raster.**  The unit square is cut into ``N`` by ``N`` cells (as cartogram programs count their grids), and
   each of the :math:`(N+1)^2` vertices gets the mean density over its own cell of that size along ``supersample``
   scanlines per cell, each measured exactly across the rings (:func:`~rfmap.cartogram.regions.density_grid`).  The sea
   has the mean density :math:`\sum_i v_i / \sum_i a_i`, as in cartogram tools: the land keeps its area, coasts move.
3. **Map.**  The default, ``"flow"``, is the flow-based method of Gastner, Seguy & More (2018) that today's
   cartogram programs run: the flux of the raster's Poisson problem (walls fixed) carries the distinct polygon
   vertices themselves from :math:`t = 0` to 1 (:func:`rfmap.solvers.cartoflow.flow_square`, numpy only: no
   PyTorch is loaded), its density blurred over :data:`~rfmap.cartogram.methods.flow.FLOW_BLUR` vertex spacings in
   the first pass and half as much in each next one.  The classical diffusion DEM of the unit square
   (``"diffusion"``, :func:`rfmap.solvers.cartodiffusion.diffusion_square`, numpy only) carries the vertices too.
   The neural methods map the grid instead and interpolate its displacement bilinearly at the vertices: a neural
   surrogate trained for 2D density equalization with the square's walls fixed (by default ``deq2d-square``, the
   paper's DEQ model, whose loss adds a Beltrami term) on its working grid, where its output is repaired to be
   fold-free, or the hybrid, which resamples the network's map to the vertex grid and finishes it there with the
   flow (``Surrogate.map(polish=...)``, :data:`~rfmap.cartogram.methods.neural.HYBRID_POLISH`).
4. **Passes.**  A map computed on a grid smears every coastline and border over a grid cell, so small dense regions come
   out a little small and sparse ones a little large.  The cartogram is therefore computed again from the mapped
   polygons, whose densities are now nearly equal, and the maps are composed, until the largest relative area error over
   the regions holding at least ``min_share`` of the total value (:data:`~rfmap.cartogram.metrics.MIN_SHARE`, 0.01 %) is
   below ``tol`` (flow-based cartogram programs stop at 1 %, the default).  The smaller regions are mapped as if they
   held that share and their errors are reported apart.  Within the passes:

   * no pass asks a region to change its area more than :data:`PASS_CONTRAST` times (its raster densities are clipped
     to that factor of the sea's): a city that must grow a hundredfold grows over several passes, and its neighbours
     are never squeezed into bands thinner than a cell, whose borders would cross;
   * a pass that gains little doubles the raster's resolution (:data:`SLOW_PASS`, up to ``max_n``): what is left are
     regions a few cells wide;
   * edges that the classical passes stretched beyond :data:`SPLIT_EDGE` cells (of at most a :data:`SPLIT_MAX_N`
     raster) are split again before the next pass;
   * a region that a pass made cross itself keeps its valid part less the lobes under :data:`LOBE` of a cell and
     :data:`LOBE_SHARE` of its area, which would pile up as parts and collapse into needles;
   * (flow) each region's weight is boosted by the share of its error that the last pass left, a secant acceleration
     of the passes (:func:`rfmap.cartogram.metrics.boost`);
   * a fold smaller than the overlap tolerance, where the input draws two edges nearly touching, is repaired
     (:func:`rfmap.cartogram.metrics.repair_folds`), and so is a sliver where neighbours under a cell apart in the
     input were pressed together (:func:`rfmap.cartogram.metrics.repair_overlaps`).

5. **Output.**  Edges longer than a grid cell are first split so that they bend with the map; every vertex is
   mapped once (shared borders stay shared); the polygons come back in the input's coordinates or the projection's
   plane (``output="projected"``) as GeoJSON with the input's properties, its ``"rfmap"`` member saying whether the
   cartogram is within tolerance and valid (:meth:`Cartogram.problems`).

Metrics (:func:`~rfmap.cartogram.metrics.cartogram_metrics`, in an equal-area plane): the relative area error
:math:`|A_i / T_i - 1|`, :math:`T_i = (v_i / \sum_j v_j) \sum_j A_j`, its mean and maximum over the judged regions, and
a topology check.

References
----------
M. T. Gastner, M. E. J. Newman, "Diffusion-based method for producing density-equalizing maps", PNAS 101, 7499
(2004); M. T. Gastner, V. Seguy, P. More, "Fast flow-based algorithm for creating density-equalizing map
projections", PNAS 115, E2156 (2018).
"""
from __future__ import annotations

import math
import numbers
import time
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from .metrics import MIN_SHARE, SLIVER_GAP, CartogramMetrics, Topology, boost, cartogram_metrics, \
    clean_input_overlaps, judged, pass_weights, repair_folds, repair_overlaps, valid_polygons
from ..core.mesh import check_grid_memory, check_n
from ..core.wording import counted
from .options import CartogramOptions
from .methods import FLOW_BLUR, FLOW_MAX_N, HYBRID_POLISH, MAX_N, METHODS, CartogramMethod, get_method
from .passmap import at_points as _at_points
from .output import OUTPUTS, choose_output, crs_member, mapped_features, output_geometries, write_geojson
from .projection import PlanarFrame
from .regions import MONTREAL_CANDIDATES, ZERO_FLOOR, _distinct_vertices, _feature_name, _listify, _longest_edges, \
    _segmentize, _shapely, density_grid, fit_outlines, montreal_election, read_regions, world_countries
from .data import atomic_write

__all__ = [
    "CARTOGRAM_METHODS", "Cartogram", "CartogramMetrics", "PlanarFrame", "read_regions", "density_grid", "cartogram",
    "cartogram_metrics", "available_methods", "compare_cartograms", "montreal_election", "world_countries",
    "MONTREAL_CANDIDATES", "HYBRID_POLISH", "ZERO_FLOOR", "OUTPUTS", "MIN_SHARE", "judged", "CartogramOptions",
]

#: Methods of :func:`cartogram`, the names of :data:`rfmap.cartogram.methods.METHODS` (``"dem"`` is accepted as another
#: name of ``"diffusion"``, as by the solvers).
CARTOGRAM_METHODS = tuple(METHODS)


# ----------------------------------------------------------------------------------------------- passes
#: A pass that leaves more than this fraction of the previous pass's largest error doubles the raster's resolution
#: (up to ``max_n``): the regions left are a few cells wide, which a finer raster resolves
SLOW_PASS = 0.7
#: A pass lowers the largest error when it takes off more than this share of it (less is rounding: splitting edges
#: alone changes the areas in their last bits)
GAIN = 1e-9
#: Between passes, edges longer than this many cells of the pass's raster are split to one cell: a straight edge
#: between mapped vertices stands for a curve, and where the flow squeezes a fjord or an inlet closed while it
#: stretches its sides, long chords cross
SPLIT_EDGE = 1.0
#: The cells of a raster finer than this many per side count as this size's for :data:`SPLIT_EDGE`: a raster
#: refined for the small regions left (a county map's) need not double every other region's vertices too
SPLIT_MAX_N = 1024
#: The lobes that a region a pass made cross itself sheds beside its largest piece go when under this share of a cell
#: of the pass's raster and :data:`LOBE_SHARE` (:func:`rfmap.cartogram.metrics.valid_polygons`): too small to resolve
LOBE = 0.1
#: The share of its own area under which a region's lobes may go (:data:`LOBE`): a region of a few cells keeps its area
LOBE_SHARE = 1e-4
#: The most passes :func:`cartogram` runs after overlap cuts moved a region beyond the tolerance (fewer once within it)
FINISH_PASSES = 12
#: A pass's raster densities are clipped to within this factor of the sea's (the mean), so that no pass asks a
#: region to grow or shrink more than this many times: a city of a few cells that must grow a hundredfold otherwise
#: squeezes its neighbours into bands thinner than a cell in one pass, and their borders cross (later passes ask
#: for the rest)
PASS_CONTRAST = 10.0
#: Boosted passes in a row that may fail to lower the largest error before the boosts stop: a secant step that
#: overshoots is corrected by the next one (the boost of a region whose error changed sign falls to none)
BOOST_PATIENCE = 3
_NO_POINTS = np.empty((0, 2))


def available_methods(surrogate=None) -> tuple[str, ...]:
    """The methods of :func:`cartogram`, :data:`CARTOGRAM_METHODS`; every :class:`rfmap.Surrogate` supports them all.

    .. deprecated:: 0.1.0
       The argument ``surrogate``: it is ignored, and passing it warns.
    """
    if surrogate is not None:
        warnings.warn("available_methods(surrogate): the argument is ignored and will be removed; call "
                      "available_methods()", DeprecationWarning, stacklevel=2)
    return CARTOGRAM_METHODS


# ----------------------------------------------------------------------------------------------- result
@dataclass
class Cartogram:
    """A computed cartogram.

    Attributes
    ----------
    input_features : list of dict
        The input's features, as read.
    geometries : ndarray of shapely geometries, shape (R,)
        The mapped regions in the ``output`` coordinates (the input's, or the projection's plane).
    features : list of dict
        The mapped features (a property, built on first use): ``geometries`` as GeoJSON with the input's
        properties and ids.
    regions : ndarray of shapely geometries, shape (R,)
        The regions before mapping, in the unit-square frame.
    mapped : ndarray of shapely geometries, shape (R,)
        The regions after mapping, in the unit-square frame.
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
        ``iterations``, ``kept`` (the pass whose polygons are returned), ``max_error`` per pass (in the frame's
        plane), per-iteration ``results`` (:class:`rfmap.core.result.MapResult`; a flow that carried the polygon vertices
        keeps its ``info`` and ``time``, not its points), ``sea`` density, ``beyond_domain``
        (the regions that left the input's domain, for ``output="auto"``).
    output : {"input", "projected"}
        The coordinates of ``features`` (:mod:`rfmap.cartogram.output`).
    tol : float
        The tolerance on the largest relative area error that :meth:`problems` checks.
    min_share : float
        The share of the total value from which a region is judged: smaller regions do not count in the area errors
        (:func:`rfmap.cartogram.metrics.judged`).  :func:`cartogram` fills it, as ``tol``, from its options
        (``min_share`` of :class:`~rfmap.cartogram.options.CartogramOptions`, default
        :data:`~rfmap.cartogram.metrics.MIN_SHARE`, 0.01 %); the class default 0, every region judged, holds only
        for a ``Cartogram`` built by hand.
    """

    input_features: list
    geometries: np.ndarray
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
    output: str = "input"
    tol: float = 0.01
    min_share: float = 0.0
    _metrics: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    _problems: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    _features: list | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def features(self) -> list:
        """The mapped features: ``geometries`` as GeoJSON with the input's properties and ids."""
        if self._features is None:
            self._features = mapped_features(self.input_features, self.geometries)
        return self._features

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
        r"""Relative area errors :math:`|A_i / T_i - 1|` in the equal-area plane (as :meth:`metrics`), shape (R,)."""
        a = _shapely().area(self.frame.equal_area(self.mapped))
        return np.abs(a / (self.values / self.values.sum() * a.sum()) - 1.0)

    def metrics(self, *, overlap_tol: float = 1e-6) -> CartogramMetrics:
        """Area errors and topology (:func:`~rfmap.cartogram.metrics.cartogram_metrics`) in the equal-area plane
        (:meth:`~rfmap.cartogram.projection.PlanarFrame.equal_area`: the frame itself unless it is equirectangular)."""
        if overlap_tol not in self._metrics:
            self._metrics[overlap_tol] = cartogram_metrics(
                self.frame.equal_area(self.mapped), self.values, overlap_tol=overlap_tol, min_share=self.min_share,
                topology=self.info.get("topology", True))
        return self._metrics[overlap_tol]

    def problems(self, *, overlap_tol: float = 1e-6) -> list[str]:
        """What keeps the cartogram from being right, one sentence each (empty when it is): a largest area error above
        ``tol`` (:meth:`metrics`), invalid regions, overlapping regions, and, for output in the input's coordinates,
        regions moved where no longitude/latitude lies (:meth:`~rfmap.cartogram.projection.PlanarFrame.beyond_domain`)
        and regions valid as written that are invalid in the cylindrical equal-area plane (a reprojection of the file
        would break them: ``info["repaired_output"].invalid_reprojected``)."""
        # saving the cartogram asks too: measured once for the same arrays of polygons (replacing one measures again)
        key = (overlap_tol, id(self.geometries), id(self.mapped), self.output)
        if key not in self._problems:
            self._problems = {key: self._find_problems(overlap_tol)}
        return list(self._problems[key])

    def _find_problems(self, overlap_tol: float) -> list[str]:
        """:meth:`problems`, measured."""
        m = self.metrics(overlap_tol=overlap_tol)
        out = []
        if not m.max_error <= self.tol:
            out.append(f"the largest area error {m.max_error:.4f} is above the tolerance {self.tol:g} after "
                       f"{counted(self.info['iterations'], 'pass')}" +
                       (": the passes stopped at the time limit" if self.info.get("timed_out") else ""))
        valid = _shapely().is_valid  # in the plane of the metrics (measured there: none, or which), and as written
        checks = [(lambda: ~valid(self.frame.equal_area(self.mapped)), "")] if m.n_invalid else []
        for check, where in (*checks, (lambda: ~valid(self.geometries), f" in the written coordinates ({self.output})")):
            bad = check()
            names = ", ".join(_feature_name(self.input_features[i], int(i)) for i in np.flatnonzero(bad)[:10])
            if bad.any():
                out.append(f"{counted(bad.sum(), 'invalid region')}{where}: {names}{', ...' if bad.sum() > 10 else ''}")
                break
        if m.n_overlapping:
            out.append(f"overlapping regions: {counted(m.n_overlapping, 'pair')} (the largest overlap "
                       f"{m.max_overlap:.2g} of the total area)")
        if self.output == "input":
            far = np.flatnonzero(self.frame.beyond_domain(self.mapped))
            if far.size:
                names = ", ".join(_feature_name(self.input_features[i], int(i)) for i in far[:10])
                out.append(f"{counted(far.size, 'region')} moved beyond the projection's domain, where no "
                           f"longitude/latitude lies (past a pole or the map's edge): {names}{', ...' if far.size > 10 else ''}; in the "
                           f"input's coordinates they are drawn at its edge (the projected output keeps them)")
        bent = list(getattr(self.info.get("repaired_output"), "invalid_reprojected", []))
        if bent:
            names = ", ".join(_feature_name(self.input_features[i], int(i)) for i in bent[:10])
            out.append(f"{counted(len(bent), 'region')} valid as written but invalid in a cylindrical equal-area "
                       f"reprojection: {names}{', ...' if len(bent) > 10 else ''}")
        return out

    def to_geojson(self) -> dict:
        """The mapped FeatureCollection (in the ``output`` coordinates), with a foreign member ``"rfmap"``:
        ``status`` (``"ok"``, or ``"failed"`` with the ``problems`` of :meth:`problems`), the largest area error
        (over the judged regions; ``minor``: the share, count and largest error of the others), the ``repaired``
        regions, the passes, the method, ``N``, the ``coordinates`` (``"input"`` or ``"projected"``), the regions
        that left the input's domain (``beyond_domain``, for which ``output="auto"`` chose the plane) and the PROJ
        definition of the ``projection``'s plane (``None`` for planar input); in the plane, the ``"crs"`` member
        names it too (:func:`rfmap.cartogram.output.crs_member`)."""
        crs = crs_member(self.frame, self.output)
        return {"type": "FeatureCollection", **({"crs": crs} if crs else {}), "features": self.features,
                "rfmap": self._status()}

    def _status(self) -> dict:
        """The ``"rfmap"`` member of :meth:`to_geojson`."""
        problems, name = self.problems(), lambda i: _feature_name(self.input_features[i], i)
        m = self.metrics()
        return {"status": "failed" if problems else "ok", "problems": problems,
                "max_error": m.max_error, "minor": {"share": self.min_share, "count": m.n_minor,
                                                    "max_error": m.max_error_minor},
                "repaired": [name(i) for i in self.info.get("repaired", [])],
                "overlaps_cut": [[name(i), name(j)] for i, j in self.info.get("overlaps_cut", [])],
                "passes": self.info.get("iterations"),
                "method": self.method, "n": self.n, "coordinates": self.output,
                "beyond_domain": [name(i) for i in self.info.get("beyond_domain", [])],
                "projection": self.frame.projection.definition}

    def save(self, path) -> None:
        """Write the mapped FeatureCollection as GeoJSON, atomically (:func:`rfmap.cartogram.data.atomic_write`)."""
        atomic_write(path, lambda fh: write_geojson(fh, self.input_features, self.geometries, self._status(),
                                                    crs_member(self.frame, self.output)))

    def input_geometries(self) -> np.ndarray:
        """The input regions in the input's coordinates."""
        return self.frame.unproject(self.regions)

    def output_geometries(self) -> np.ndarray:
        """The mapped regions in the input's coordinates."""
        return self.frame.unproject(self.mapped)

    def projected_geometries(self, *, mapped: bool = True) -> np.ndarray:
        """The mapped (or, with ``mapped=False``, the input) regions in the projection's plane."""
        return self.frame.planar(self.mapped if mapped else self.regions)


# ----------------------------------------------------------------------------------------------- pipeline
def cartogram(collection, value: str, options: CartogramOptions | None = None, **kw) -> Cartogram:
    r"""A cartogram of GeoJSON regions sized by one value each, flow-based by default (see
    :mod:`rfmap.cartogram.resize`).

    Parameters
    ----------
    collection : dict, str or path
        A GeoJSON FeatureCollection of Polygon / MultiPolygon features.
    value : str
        The property holding each region's value (numbers :math:`\ge 0`; zeros are floored, see
        :func:`~rfmap.cartogram.regions.read_regions`).
    options : CartogramOptions, optional
        How the regions are resized (:class:`rfmap.cartogram.options.CartogramOptions`: ``method``, ``n``, ``tol``,
        ``max_iterations``, ``iterations``, ``margin``, ``projection``, ``output``, ``supersample``, ``model``,
        ``surrogate``, ``floor``, ``solver_kw``, ``min_share``, ``max_n``, ``points``, ``timeout``); its fields may be
        given as keywords (``cartogram(regions, "pop", method="diffusion", n=512)``).

    Returns
    -------
    Cartogram
        ``info["max_error"]`` lists the largest relative area error after every pass, ``info["iterations"]`` the
        passes run, ``info["kept"]`` the pass whose polygons are returned (1-based), ``info["timed_out"]`` whether
        ``timeout`` stopped the passes, ``info["repaired"]`` the
        regions whose numerically tiny fold was repaired (:func:`rfmap.cartogram.metrics.repair_folds`),
        ``info["repaired_output"]`` what was changed in the regions as written
        (:class:`rfmap.cartogram.output.OutputRepairs`: specks that rounding made cross themselves, needles removed,
        edges split so that longitude/latitude output stays valid in an equal-area plane, and the regions left
        invalid there), ``info["input_overlaps"]`` the count of pairs of
        input regions that overlapped, made a coverage first (:func:`rfmap.cartogram.metrics.clean_input_overlaps`),
        ``info["overlaps_cut"]`` the pairs ``(cut, kept)`` of regions whose sliver of overlap was cut from the first
        (:func:`rfmap.cartogram.metrics.repair_overlaps`).

    Raises
    ------
    ValueError
        For bad input (one line: see :func:`~rfmap.cartogram.regions.read_regions`), an unknown method, projection or
        output, a surrogate that does not map 2D densities of the square.
    ImportError
        For longitude/latitude input centred near a pole in an equal-area projection without pyproj.
    """
    o = replace(options or CartogramOptions(), **kw)
    shapely = _shapely()
    method = get_method(o.method)(o)
    plan = _plan(o, method)
    features, geoms, values, floored = read_regions(collection, value, floor=o.floor)
    method.prepare()

    t0 = time.perf_counter()
    frame = PlanarFrame.fit(geoms, margin=o.margin, projection=o.projection)
    # edges longer than a grid cell are split, so that they bend with the projection and the map (and a border that
    # one neighbour draws with more vertices than the other still matches it)
    regions = frame.project(geoms, 1.0 / plan.n)
    if o.points is not None:  # a budget of vertices: simplified (shared borders kept) or densified to it
        regions = shapely.segmentize(fit_outlines(regions, o.points), 1.0 / plan.n)
    # overlapping input borders: a coverage (sliver gaps closed), so that the map keeps the regions apart
    regions, cleaned = clean_input_overlaps(regions, gap_width=SLIVER_GAP / plan.n)
    if o.timeout is not None:
        plan = replace(plan, deadline=t0 + o.timeout)
    mapped, info, map_time = _passes(regions, values, method, plan)
    info["input_overlaps"] = cleaned
    mapped, finish_time = _repair(mapped, values, method, info, plan)
    map_time += finish_time
    elapsed = time.perf_counter() - t0
    output, info["beyond_domain"] = choose_output(frame, mapped, o.output)
    out, info["repaired_output"] = output_geometries(frame, mapped, output)  # valid as written, too
    return Cartogram(input_features=features, geometries=out, regions=regions, mapped=mapped, values=values,
                     floored=floored, frame=frame, method=method.name, n=plan.n, time=elapsed, map_time=map_time,
                     info=info, output=output, tol=float(o.tol), min_share=float(o.min_share))


@dataclass(frozen=True)
class PassPlan:
    """How the passes of :func:`cartogram` run (:func:`_passes`): the first raster's cells per side ``n``, the
    scanlines per cell ``supersample``, at most ``passes`` passes, the tolerance ``tol`` (``None``: all the passes
    run), the judged share ``min_share``, the finest raster ``max_n``, whether stretched edges are split between
    passes (``split``), whether the weights are boosted (``accelerate``) and the ``deadline`` (``time.perf_counter``)
    after which no pass starts."""

    n: int
    supersample: int
    passes: int
    tol: float | None
    min_share: float = 0.0
    max_n: int = 0
    split: bool = True
    accelerate: bool = False
    deadline: float | None = None


def _plan(o: CartogramOptions, method: CartogramMethod) -> PassPlan:
    """The passes' plan from the options, each checked (``ValueError`` in one line)."""
    n = check_n(o.n, 2)
    check_grid_memory(n + 1, 2)
    fixed = o.iterations is not None
    passes = o.iterations if fixed else o.max_iterations
    if isinstance(passes, bool) or not isinstance(passes, (int, np.integer)) or passes < 1:
        raise ValueError(f"{'iterations' if fixed else 'max_iterations'} must be a positive integer, got {passes!r}")
    if not (isinstance(o.tol, numbers.Real) and o.tol >= 0):
        raise ValueError(f"tol must be a number >= 0, got {o.tol!r}")
    if o.timeout is not None and not (isinstance(o.timeout, numbers.Real) and not isinstance(o.timeout, bool)
                                      and 0 < o.timeout < math.inf):
        raise ValueError(f"timeout must be a positive number of seconds, got {o.timeout!r}")
    if o.output not in OUTPUTS:
        raise ValueError(f"unknown output {o.output!r}; choose one of {', '.join(OUTPUTS)}")
    return PassPlan(n=n, supersample=o.supersample, passes=int(passes), tol=None if fixed else o.tol,
                    min_share=o.min_share, max_n=o.max_n if o.max_n is not None else max(n, method.finest),
                    split=method.carries_vertices, accelerate=method.accelerate)


def _passes(regions: np.ndarray, values: np.ndarray, method: CartogramMethod,
            plan: PassPlan) -> tuple[np.ndarray, dict, float]:
    """The passes of :func:`cartogram`: each rasterises the current polygons, maps the unit square by
    ``method.grid_map(density, vertices)`` and moves every distinct vertex.  With ``plan.tol`` they stop within
    tolerance, or at a pass that no longer lowers the largest area error, and the polygons of the best pass are
    returned; without, all ``plan.passes`` run; with ``plan.split``, edges stretched beyond :data:`SPLIT_EDGE` cells
    (cells of at most a :data:`SPLIT_MAX_N` raster, unless ``n`` is finer) are split between passes, and with
    ``plan.accelerate`` every region's weight is boosted by its own slow progress
    (:func:`rfmap.cartogram.metrics.boost`) until :data:`BOOST_PATIENCE` passes in a row fail to lower the largest
    error; every raster's densities are clipped to within :data:`PASS_CONTRAST` times the sea's; past
    ``plan.deadline`` no further pass starts.  With ``plan.split``, a region that a pass made cross itself is
    replaced by its valid part (``shapely.make_valid``, less the lobes under :data:`LOBE` of a cell and
    :data:`LOBE_SHARE` of its area) before its area is measured, so that the next pass corrects a true area (a
    crossed ring's signed area misleads every later pass).
    ``n`` and ``max_n`` count cells per side; the rasters have ``n + 1`` vertices per side.  Returns ``(mapped
    polygons, info, seconds in grid_map)``."""
    n, tol, split, accelerate = plan.n, plan.tol, plan.split, plan.accelerate
    shapely = _shapely()
    current, inverse = _distinct_vertices(regions)
    stale = False  # whether regions changed since current and inverse were taken from them
    mapped = regions
    big = judged(values, plan.min_share)  # the regions the stopping rule counts
    # the others are raised towards the judged share, so that none collapses into a sliver that folds; their errors
    # are still measured against their own values
    weights = pass_weights(values, plan.min_share)
    results, history, grids, map_time = [], [], [], 0.0
    best = None  # (largest area error, polygons, pass) of the best pass so far
    log_err, gain = None, np.zeros(len(values))  # the last pass's log area errors and log weight boosts
    timed_out, misses = False, 0  # misses: passes in a row that did not lower the largest error
    area = shapely.area(mapped)  # of the current polygons, measured once each pass
    for _ in range(plan.passes):
        if results and plan.deadline is not None and time.perf_counter() >= plan.deadline:
            timed_out = True
            break
        if (tol is not None and len(history) > 1 and history[-1] > tol
                and SLOW_PASS * history[-2] < history[-1] < (1 - GAIN) * history[-2] and 2 * n <= plan.max_n):
            n *= 2  # slow progress: regions down to a few cells (slivers, islands); twice the resolution
        grids.append(n)
        cell = 1.0 / min(n, max(SPLIT_MAX_N, grids[0]))
        longest = _longest_edges(mapped) if split and results else None
        if longest is not None and longest.max(initial=0.0) > SPLIT_EDGE * cell:  # stretched edges: split again
            regions = _segmentize(mapped, cell, longest >= cell * (1.0 - 1e-9))  # as segmentize measures them
            stale = True
        if stale:  # once per pass: a repair's regions that this pass splits again are not taken first
            current, inverse = _distinct_vertices(regions)
            stale = False
        if accelerate:
            now = np.log(np.maximum(area, 1e-300) / (weights / weights.sum() * area.sum()))
            gain = boost(now, log_err, gain) if log_err is not None else gain
            log_err = now
        dens, sea = density_grid(mapped, weights * np.exp(-gain), n + 1, supersample=plan.supersample, areas=area)
        np.clip(dens, sea / PASS_CONTRAST, sea * PASS_CONTRAST, out=dens)
        res = method.grid_map(dens, current)
        current = _at_points(res, current)
        map_time += res.time
        # a flow of the polygon vertices is kept as its info and time: its points would hold hundreds of megabytes
        # over the passes of a county map
        results.append(res if res.info.get("grid", True) else replace(res, ref_points=_NO_POINTS,
                                                                       mapped_points=_NO_POINTS))
        mapped = shapely.set_coordinates(regions.copy(), current[inverse])
        bad = np.flatnonzero(~shapely.is_valid(mapped))
        if bad.size and split:  # a region the pass made cross itself: its valid part, whose area the next pass fixes
            mapped[bad] = valid_polygons(mapped[bad], min_lobe=np.minimum(LOBE / n ** 2, LOBE_SHARE * area[bad]))
            regions = mapped
            stale = True
        area = shapely.area(mapped)
        history.append(float(np.abs(area / (values / values.sum() * area.sum()) - 1.0)[big].max()))
        if best is None or history[-1] < best[0]:
            best = (history[-1], mapped, len(results))
        if tol is not None and history[-1] <= tol:
            break  # within tolerance
        if tol is not None and len(history) > 1 and not history[-1] < (1 - GAIN) * history[-2]:
            misses += 1
            if accelerate and misses < BOOST_PATIENCE:
                continue  # a boosted pass overshot: the next secant step sees it
            if accelerate:  # boosted passes keep overshooting: plain passes from here on
                accelerate, gain, misses = False, np.zeros(len(values)), 0
                continue
            break  # a pass that no longer lowers the largest error
        else:
            misses = 0
    kept = len(results)
    if tol is not None:  # the polygons of the pass with the lowest largest error
        mapped, kept = best[1], best[2]
    return mapped, {"iterations": len(results), "kept": kept, "max_error": history, "results": results,
                    "sea": sea, "grids": grids, "timed_out": timed_out}, map_time


def _largest_error(mapped: np.ndarray, values: np.ndarray, min_share: float) -> float:
    """The largest relative area error of the judged regions (:func:`rfmap.cartogram.metrics.judged`)."""
    area = _shapely().area(mapped)
    return float(np.abs(area / (values / values.sum() * area.sum()) - 1.0)[judged(values, min_share)].max())


def _repair(mapped: np.ndarray, values: np.ndarray, method: CartogramMethod, info: dict,
            plan: PassPlan) -> tuple[np.ndarray, float]:
    """Tiny folds and sliver overlaps of the passes' polygons repaired (:func:`rfmap.cartogram.metrics.repair_folds`,
    :func:`rfmap.cartogram.metrics.repair_overlaps`).  Cutting overlaps moves area; when that takes a judged region
    beyond ``plan.tol``, at most :data:`FINISH_PASSES` passes more (not boosted) start from the cut polygons (whose
    cut borders are now shared, so the map keeps them apart) and their polygons, repaired in turn, are kept when
    their largest error is lower (none past ``plan.deadline``).  Returns the polygons and the seconds spent in
    ``grid_map``; ``info`` records the repairs and the passes (``info["finish_passes"]``)."""
    tol, min_share = plan.tol, plan.min_share
    valid = _shapely().is_valid(mapped)  # measured once for both repairs (repair_folds marks the folds it fixes)
    mapped, info["repaired"] = repair_folds(mapped, valid=valid)
    topology = Topology.of(mapped, valid)
    mapped, info["overlaps_cut"] = repair_overlaps(mapped, values, topology=topology)
    info["finish_passes"] = 0
    if not info["overlaps_cut"] or tol is None or (err := _largest_error(mapped, values, min_share)) <= tol:
        info["topology"] = topology.updated(mapped, [k for pair in info["overlaps_cut"] for k in pair])  # for metrics
        return mapped, 0.0
    more, extra, seconds = _passes(mapped, values, method,
                                   replace(plan, n=info["grids"][-1], passes=FINISH_PASSES, accelerate=False))
    more, folds = repair_folds(more)
    more, cut = repair_overlaps(more, values)
    if not _largest_error(more, values, min_share) < err:
        return mapped, seconds
    info["finish_passes"] = extra["iterations"]
    info["repaired"] += folds
    info["overlaps_cut"] += cut
    for key in ("max_error", "results", "grids"):
        info[key] = info[key] + extra[key]
    info["iterations"] += extra["iterations"]
    info["kept"] = info["iterations"] - extra["iterations"] + extra["kept"]
    return more, seconds


def compare_cartograms(collection, values, runs: dict, *, n: int = 256, surrogate=None) -> dict:
    """Cartograms of one map by several values and several runs of :func:`cartogram`.

    Parameters
    ----------
    collection : dict, str or path
    values : sequence of str
        Property names.
    runs : dict
        ``{label: keyword arguments of cartogram}``, e.g. ``{"diffusion": {"method": "diffusion"},
        "surrogate, 1 pass": {"method": "surrogate", "iterations": 1}}``.  A label is only a name: the method is the
        ``method`` keyword, and a run without one uses :func:`cartogram`'s default, ``"flow"``.
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
        from ..finish import quiet_quality

        with quiet_quality():  # a uniform density: any movement at all leaves it "less equal"
            surrogate.map(np.ones((surrogate.n_range[0],) * 2), preprocess=False)
    return {(v, label): cartogram(collection, v, n=n, surrogate=surrogate, **kw)
            for v in values for label, kw in runs.items()}

