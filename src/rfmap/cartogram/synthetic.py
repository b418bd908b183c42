r"""Synthetic hard maps for cartograms: a country cut into thousands of regions of very different sizes, and one
cut into subdivisions across the antimeridian.

Real maps that stress a cartogram are a county map (thousands of regions, from a few cells of the raster down to a
hundredth of one, the smallest holding the densest populations) and the subdivisions of a country that crosses the
antimeridian (long shared borders, regions split at 180°).  :func:`tessellate` builds such maps from any outline:
the Voronoi cells of random seeds, clipped to the outline, where the seeds are drawn partly uniformly and partly in
tight clusters ("cities"), so that cell areas span orders of magnitude; every region gets a value

.. math:: v_i = a_i \, \rho_i, \qquad \rho_i = \rho_0 \, e^{\sigma z_i} \, (\bar a / a_i)^{\gamma},

(:math:`a_i` its area in degrees², :math:`z_i` standard normal): small regions are dense, as cities are.  The cells
share their borders vertex for vertex (as a clean coverage does); coordinates are rounded to ``decimals`` as
GeoJSON files are.  :func:`synthetic_counties` cuts the contiguous United States of Natural Earth's 1:110m map
(:func:`rfmap.cartogram.regions.world_countries`) into about 3,100 such counties; :func:`synthetic_subdivisions` cuts Russia
into about 80 regions, those across 180° split there (RFC 7946) as real data draw them.

Nothing here imports PyTorch.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .regions import _listify, _shapely, world_countries

__all__ = ["TessellationOptions", "tessellate", "synthetic_counties", "synthetic_subdivisions", "country_outline"]


@dataclass(frozen=True)
class TessellationOptions:
    r"""How :func:`tessellate` cuts an outline (see :mod:`rfmap.cartogram.synthetic`).

    Attributes
    ----------
    count : int
        Seeds (regions, before the rare seed whose cell the outline cuts away).
    clusters : int
        Tight clusters of seeds ("cities").
    clustered : float
        Share of the seeds drawn in clusters.
    spread : float
        Cluster width (standard deviation) as a share of the outline's smaller side, drawn log-uniformly between
        ``spread / 30`` and ``spread``.
    sigma : float
        Spread of the densities: the standard deviation :math:`\sigma` of their log-normal noise.
    gamma : float
        The exponent :math:`\gamma` by which the density grows as a region's area shrinks (small regions are the
        dense ones, as in cities).
    decimals : int
        Coordinates rounded to this many decimals (degrees).
    wiggle : float
        Borders bent by a smooth displacement of this amplitude (degrees, with waves 15 times as long; 0: the
        Voronoi cells' straight edges), the same on both sides of every border.
    simplify : float
        Each region simplified on its own to this tolerance (degrees; 0: not at all), as files simplified feature by
        feature draw every border twice: slivers of gap and of overlap open between neighbours.
    seed : int
    """

    count: int = 3100
    clusters: int = 40
    clustered: float = 0.45
    spread: float = 0.02
    sigma: float = 1.0
    gamma: float = 0.7
    decimals: int = 5
    wiggle: float = 0.0
    simplify: float = 0.0
    seed: int = 0


def country_outline(name: str):
    """The outline (longitude/latitude, a shapely (Multi)Polygon) of a country of
    :func:`rfmap.cartogram.regions.world_countries` by its ``name``; a country split at the antimeridian comes back as one
    geometry with longitudes in :math:`[0, 360)`."""
    shapely = _shapely()
    from shapely.geometry import shape

    feats = [f for f in world_countries()["features"] if f["properties"]["name"] == name]
    if not feats:
        raise ValueError(f"no country named {name!r} in the Natural Earth map")
    g = shape(feats[0]["geometry"])
    xy = shapely.get_coordinates(g)
    if xy[:, 0].min() < -170 and xy[:, 0].max() > 170:  # across the antimeridian: the western half moved east
        g = shapely.transform(g, lambda p: np.where(p[:, :1] < 0, p + [360.0, 0.0], p))
        g = shapely.union_all(shapely.make_valid(shapely.get_parts(g)), grid_size=1e-9)
    return g


def _seeds(outline, opts: TessellationOptions, rng: np.random.Generator) -> np.ndarray:
    """``opts.count`` distinct points inside ``outline``: uniform, and a share in log-normal clusters."""
    shapely = _shapely()
    x0, y0, x1, y1 = outline.bounds
    side = min(x1 - x0, y1 - y0)
    shapely.prepare(outline)

    def inside(p):
        return p[shapely.contains_xy(outline, p[:, 0], p[:, 1])]

    n_clustered = int(opts.clustered * opts.count)
    pts = []
    centres = np.empty((0, 2))
    while len(centres) < opts.clusters:
        centres = np.concatenate([centres, inside(rng.uniform((x0, y0), (x1, y1), (4 * opts.clusters, 2)))])
    centres = centres[:opts.clusters]
    widths = side * opts.spread * np.exp(rng.uniform(np.log(1 / 30), 0.0, opts.clusters))
    weights = rng.dirichlet(np.ones(opts.clusters))
    need = n_clustered
    while need > 0:
        k = rng.choice(opts.clusters, 2 * need, p=weights)
        got = inside(centres[k] + rng.normal(size=(2 * need, 2)) * widths[k, None])[:need]
        pts.append(got)
        need -= len(got)
    need = opts.count - n_clustered
    while need > 0:
        got = inside(rng.uniform((x0, y0), (x1, y1), (2 * need, 2)))[:need]
        pts.append(got)
        need -= len(got)
    return np.unique(np.round(np.concatenate(pts), opts.decimals + 1), axis=0)


def _wiggle(geoms: np.ndarray, amplitude: float, rng: np.random.Generator) -> np.ndarray:
    """Every vertex moved by the smooth field :math:`d(x) = A \\sum_k (\\sin, \\cos)(w_k \\cdot x + \\phi_k) / 3`
    (three random waves of wavelength :math:`15 A`): shared vertices move alike, so borders stay shared."""
    shapely = _shapely()
    angle, phase = rng.uniform(0, 2 * np.pi, 3), rng.uniform(0, 2 * np.pi, (2, 3))
    w = 2 * np.pi / (15 * amplitude) * np.stack([np.cos(angle), np.sin(angle)], axis=1)  # (3, 2)

    def move(p):
        arg = p @ w.T
        return p + amplitude / 3 * np.stack([np.sin(arg + phase[0]).sum(1), np.cos(arg + phase[1]).sum(1)], axis=1)
    return shapely.transform(geoms, move)


def tessellate(outline, options: TessellationOptions | None = None, *, prefix: str = "R") -> dict:
    """An outline cut into Voronoi regions of very different sizes with a value each (see
    :mod:`rfmap.cartogram.synthetic`).

    Parameters
    ----------
    outline : shapely Polygon or MultiPolygon
        Longitude/latitude; longitudes beyond 180° are moved back by 360° after the cut, and a region across 180°
        is split there.
    options : TessellationOptions, optional
    prefix : str
        The regions' ids are ``prefix`` and a number.

    Returns
    -------
    dict
        A GeoJSON FeatureCollection; each feature has an ``id`` and the properties ``id``, ``name``, ``value`` (a
        positive number) and ``area`` (degrees², before the split).
    """
    shapely = _shapely()
    opts = options or TessellationOptions()
    rng = np.random.default_rng(opts.seed)
    seeds = _seeds(outline, opts, rng)
    cells = shapely.get_parts(shapely.voronoi_polygons(shapely.multipoints(seeds), extend_to=outline.envelope))
    if opts.wiggle > 0:
        cells = _wiggle(shapely.segmentize(cells, 2.0 * opts.wiggle), opts.wiggle, rng)
    clipped = shapely.intersection(shapely.make_valid(cells), outline)
    clipped = np.array([shapely.union_all(p[shapely.get_type_id(p) == 3]) for p in map(shapely.get_parts, clipped)],
                       dtype=object)
    if opts.simplify > 0:
        clipped = shapely.simplify(clipped, opts.simplify)
    clipped = shapely.set_precision(clipped, 10.0 ** -opts.decimals)
    keep = ~shapely.is_empty(clipped) & (shapely.area(clipped) > 0)
    regions = clipped[keep]
    area = shapely.area(regions)
    rho = np.exp(opts.sigma * rng.normal(size=area.size)) * (area.mean() / area) ** opts.gamma
    values = np.round(area * rho / (area * rho).sum() * 3e8)
    values = np.maximum(values, 1.0)
    east = shapely.box(180.0, -90.0, 540.0, 90.0)
    feats = []
    for k, (g, v, a) in enumerate(zip(regions, values, area)):
        if g.bounds[2] > 180.0:  # beyond the antimeridian: split there, the eastern part moved back by 360°
            west = shapely.difference(g, east)
            far = shapely.transform(shapely.intersection(g, east), lambda p: p - [360.0, 0.0])
            parts = [p for h in (west, far) for p in shapely.get_parts(h) if shapely.get_type_id(p) == 3]
            g = shapely.set_precision(shapely.multipolygons(parts), 10.0 ** -opts.decimals)
        rid = f"{prefix}{k:04d}"
        feats.append({"type": "Feature", "id": rid,
                      "properties": {"id": rid, "name": f"{prefix} {k}", "value": float(v), "area": float(a)},
                      "geometry": _listify(shapely.geometry.mapping(g))})
    return {"type": "FeatureCollection", "features": feats}


def synthetic_counties(count: int = 3100, *, seed: int = 0, slivers: bool = False) -> dict:
    """The contiguous United States cut into about ``count`` counties (:func:`tessellate`): areas over five orders
    of magnitude, the smallest a hundredth of a cell of a 256-cell raster and the densest.  With ``slivers`` the
    borders are bent (``wiggle`` 0.05°) and every county simplified on its own (0.02°), so that neighbours overlap
    and leave gaps along their borders, as in files simplified feature by feature."""
    shapely = _shapely()
    usa = country_outline("United States of America")
    parts = shapely.get_parts(usa)
    lower48 = parts[np.argmax(shapely.area(parts))]  # Alaska and Hawaii are separate parts
    opts = TessellationOptions(count=count, seed=seed, wiggle=0.05 if slivers else 0.0,
                               simplify=0.02 if slivers else 0.0)
    return tessellate(lower48, opts, prefix="C")


def synthetic_subdivisions(country: str = "Russia", count: int = 80, *, seed: int = 0, slivers: bool = False) -> dict:
    """A country cut into about ``count`` subdivisions (:func:`tessellate`, fewer clusters), for Russia across the
    antimeridian, its regions there split at 180°.  With ``slivers`` the borders are bent (``wiggle`` 0.1°) and every
    region simplified on its own (0.05°): neighbours overlap along long shared borders."""
    opts = TessellationOptions(count=count, clusters=6, clustered=0.35, spread=0.03, seed=seed,
                               wiggle=0.1 if slivers else 0.0, simplify=0.05 if slivers else 0.0)
    return tessellate(country_outline(country), opts, prefix="S")
