r"""The options of a cartogram (:func:`rfmap.cartogram.resize.cartogram`), listed once: the API takes them as an
object or as keywords, and ``rfmap cartogram`` builds them from its arguments."""
from __future__ import annotations

from dataclasses import dataclass

from .metrics import MIN_SHARE
from .regions import ZERO_FLOOR

__all__ = ["CartogramOptions"]


@dataclass(frozen=True)
class CartogramOptions:
    r"""How :func:`rfmap.cartogram.resize.cartogram` resizes regions; a call names only the fields that differ.

    Most calls need at most four: ``method`` (the classical flow by default), ``n`` (the raster's resolution),
    ``projection`` and ``output`` (the plane of the computation and the coordinates of the result).  The others
    tune the stopping rule, the raster and the outlines.

    Attributes
    ----------
    method : {"diffusion", "flow", "surrogate", "hybrid"}
        ``"flow"`` (default): the classical flow-based method, which carries the polygons' vertices themselves
        (:func:`rfmap.solvers.cartoflow.flow_square`; numpy only, no PyTorch); ``"diffusion"`` (also
        ``"dem"``): the classical diffusion DEM, carrying the vertices too
        (:func:`rfmap.solvers.cartodiffusion.diffusion_square`, numpy only); ``"surrogate"``: a pretrained neural
        surrogate; ``"hybrid"``: the surrogate's map finished by the classical flow on the raster's vertex grid
        (``Surrogate.map(polish=HYBRID_POLISH)``).
    n : int
        Cells per side ``N`` of the density raster, as the ``-n`` option of cartogram-cpp (the C++ program of the
        flow-based method of Gastner, Seguy & More 2018, github.com/mgastner/cartogram-cpp) counts them; the maps
        run on its :math:`(N+1)^2` vertices (FFT lengths :math:`2N`: a power of two is fastest).  It counts cells,
        not vertices: the ``n`` of :meth:`rfmap.Surrogate.map` and of ``rfmap map --n``, and that of
        :func:`~rfmap.cartogram.regions.density_grid`, count vertices, so ``n = 64`` here is a side of 65 there.
    tol : float
        The stopping tolerance of the passes, see ``max_iterations``.
    max_iterations : int
        Passes are repeated, each from the previous pass's polygons, until the largest relative area error is at
        most ``tol`` (the usual stopping rule of cartogram tools), a pass no longer lowers it, or ``max_iterations``
        passes are done; the polygons of the pass with the lowest largest error are returned.
    iterations : int, optional
        A fixed number of passes instead (``tol`` and ``max_iterations`` are then ignored).
    margin : float
        Sea around the map: the map's bounding box is fitted into :math:`[\mathrm{margin}, 1-\mathrm{margin}]^2`.
    projection : {"auto", "equal-area", "equirectangular", "none"}
        The plane the cartogram is computed in (:class:`~rfmap.cartogram.projection.PlanarFrame`): ``"auto"`` is
        ``"equal-area"`` for longitude/latitude input (Lambert azimuthal equal-area centred on the map, Equal Earth
        for a map wider than 180° of longitude) and ``"none"`` (the coordinates as they are) for planar input.
    output : {"auto", "input", "projected"}
        The coordinates of the returned features: the input's (the projection inverted), or the projection's plane
        (metres for the equal-area projections; its PROJ definition is in
        :meth:`~rfmap.cartogram.resize.Cartogram.to_geojson`); ``"auto"`` (default) is the input's unless a region left
        their domain (past a pole, beyond the far side of the Lambert disc), then the plane
        (:func:`rfmap.cartogram.output.choose_output`).
    supersample : int
        Scanlines per grid cell (:func:`~rfmap.cartogram.regions.density_grid`).
    model : str, optional
        Shipped surrogate for ``"surrogate"`` / ``"hybrid"`` (default ``"deq2d-square"``); ``surrogate`` passes a
        loaded :class:`rfmap.Surrogate` instead.  It must map 2D densities with the square's walls fixed, as the
        sea's edge is the unit square.
    floor : float
        Zero-value floor (:func:`~rfmap.cartogram.regions.read_regions`).
    solver_kw : dict, optional
        Fields of :class:`rfmap.solvers.cartoflow.CartoFlowOptions` (``"flow"``) or
        :class:`rfmap.solvers.cartodiffusion.CartoDiffusionOptions` (``"diffusion"``).
    min_share : float
        The smallest share of the total value whose regions are judged (default
        :data:`~rfmap.cartogram.metrics.MIN_SHARE`, 0.01 %).  The stopping rule, the tolerance and
        :meth:`~rfmap.cartogram.resize.Cartogram.metrics` count only the judged regions, so islands of a few people
        on a world map do not hold the passes back; ``info["max_error"]`` is over the judged regions, and the others'
        largest error is reported apart (``CartogramMetrics.max_error_minor``).  The passes raise the others' values
        towards this share, so that none (an uninhabited Antarctica) collapses into a sliver that folds.
    max_n : int, optional
        The finest raster side that the passes may refine to; set ``max_n = n`` to keep the raster fixed.  A pass
        that lowers the largest error but leaves more than :data:`~rfmap.cartogram.resize.SLOW_PASS` of it (regions
        down to a few cells: slivers, small islands) doubles the raster's side, :math:`N \to 2N`, up to ``max_n``.
        Default: the larger of ``n`` and :data:`~rfmap.cartogram.methods.base.MAX_N` (for the flow,
        :data:`~rfmap.cartogram.methods.flow.FLOW_MAX_N`); ``info["grids"]`` lists each pass's ``N``.
    points : int, optional
        About how many vertices the outlines keep: they are simplified (shared borders kept,
        :func:`rfmap.cartogram.regions.fit_outlines`) or densified to about that many.  Simplifying removes detail
        finer than the grid and speeds up maps drawn with far more vertices than the grid resolves; it changes the
        input's areas slightly.  The budget sets the outlines' detail, not the count of points the flow carries: as
        for any input, the outlines are then split to edges of at most a grid cell, and edges that the classical
        methods stretch beyond :data:`~rfmap.cartogram.resize.SPLIT_EDGE` cells are split again between passes, so
        that straight edges between distant vertices do not cross.
    timeout : float, optional
        Seconds (counted from the parsed input) after which no further pass starts; the best pass so far is
        returned, with ``info["timed_out"]`` set and, when it is not within ``tol``, a problem that says so
        (:meth:`~rfmap.cartogram.resize.Cartogram.problems`).  The first pass always runs.
    surrogate : rfmap.Surrogate, optional
        A loaded surrogate for ``"surrogate"`` / ``"hybrid"`` instead of the shipped ``model``.
    """

    method: str = "flow"
    n: int = 256
    tol: float = 0.01
    max_iterations: int = 60
    iterations: int | None = None
    margin: float = 0.1
    projection: str = "auto"
    output: str = "auto"
    supersample: int = 4
    model: str | None = None
    surrogate: object = None
    floor: float = ZERO_FLOOR
    solver_kw: dict | None = None
    min_share: float = MIN_SHARE
    max_n: int | None = None
    points: int | None = None
    timeout: float | None = None
