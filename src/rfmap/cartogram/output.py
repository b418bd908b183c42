r"""The output of a cartogram: the coordinates it is written in, and its GeoJSON.

A cartogram of longitude/latitude regions is computed in an equal-area plane (:mod:`rfmap.cartogram.projection`).  Written
back in longitude/latitude (``output="input"``), a region that the passes moved where no longitude/latitude lies
(past a pole's line, beyond the far side of the Lambert disc: Russia on a world map by population) can only be drawn
at the domain's edge.  By default (``output="auto"``) such a cartogram is written in its equal-area plane instead,
and says so: the GeoJSON's ``"crs"`` member (GeoJSON 2008's named CRS, which RFC 7946 dropped but GDAL still reads)
holds the plane's PROJ definition, and the ``"rfmap"`` member its ``coordinates`` and the regions that left the
domain (:func:`choose_output`).

The polygons are checked valid in the unit square, where the passes run.  Scaled to metres, coordinates are rounded
again, and a vertex a few units of the last place from an edge can cross it; turned back into degrees, the straight
edges between the same vertices are other curves on the Earth, and an edge that passed a vertex by a hair may cross
it.  Either way a ring crosses itself by a speck.  :func:`output_geometries` checks the polygons in the coordinates
that are written and repairs such specks (:func:`repair_specks`); what it cannot repair stays invalid, for
:meth:`rfmap.cartogram.resize.Cartogram.problems` to report.

A file is also reprojected by its users.  Before writing, :func:`output_geometries` removes the needles of regions
that the passes squeezed (:func:`rfmap.cartogram.reprojection.remove_needles`), and, for longitude/latitude output,
checks every region in the cylindrical equal-area plane of the whole map and splits the edges of those that are
invalid there only (:func:`rfmap.cartogram.reprojection.split_bent_edges`); :class:`OutputRepairs` says what was done.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from .metrics import REPAIR_AREA
from .reprojection import cylindrical_equal_area, remove_needles, split_bent_edges

__all__ = ["OUTPUTS", "SPECK", "OutputRepairs", "choose_output", "crs_member", "mapped_features", "output_geometries",
           "repair_specks", "write_geojson"]

#: The coordinates of :func:`rfmap.cartogram.resize.cartogram`'s output: ``"auto"`` (the input's, unless a region left
#: their domain, then the projection's plane), the input's, or the projection's plane.
OUTPUTS = ("auto", "input", "projected")
#: The largest change of a region's area (a share of it) by which :func:`repair_specks` makes it valid, and the
#: share of its area under which a polygon part of the repair is dropped as a speck
SPECK = 1e-6


def choose_output(frame, mapped: np.ndarray, output: str) -> tuple[str, list[int]]:
    """The coordinates to write mapped regions (unit square, (R,)) in, and the regions beyond the projection's domain
    (:meth:`rfmap.cartogram.projection.PlanarFrame.beyond_domain`; checked for ``"auto"`` only): ``"auto"`` becomes
    ``"projected"`` when there are any, else ``"input"``."""
    if output != "auto":
        return output, []
    far = np.flatnonzero(frame.beyond_domain(mapped)).tolist() if frame.projection.geographic else []
    return ("projected" if far else "input"), far


@dataclass
class OutputRepairs:
    """What :func:`output_geometries` changed in the regions as written (indices of regions)."""

    #: regions that crossed themselves by a speck in the written coordinates, the speck dropped (:func:`repair_specks`)
    specks: list = field(default_factory=list)
    #: ``{region: points removed}``: needles and collapsed rings
    #: (:func:`rfmap.cartogram.reprojection.remove_needles`)
    needles: dict = field(default_factory=dict)
    #: ``{region: vertices added}``: edges split so that the region stays valid in the cylindrical equal-area plane
    #: (:func:`rfmap.cartogram.reprojection.split_bent_edges`), the neighbours along them included
    split: dict = field(default_factory=dict)
    #: regions valid as written that are invalid in that plane even so
    invalid_reprojected: list = field(default_factory=list)

    @property
    def regions(self) -> list[int]:
        """Every region changed, sorted."""
        return sorted({*self.specks, *self.needles, *self.split})


def output_geometries(frame, mapped: np.ndarray, output: str) -> tuple[np.ndarray, OutputRepairs]:
    """The unit-square polygons ``mapped`` (R,) in the coordinates written (``"input"``: the projection inverted,
    ``"projected"``: its plane), their needles removed
    (:func:`rfmap.cartogram.reprojection.remove_needles`), the regions that rounding there made invalid repaired
    (:func:`repair_specks`) and, in longitude/latitude, the regions invalid in the cylindrical equal-area plane
    (:func:`rfmap.cartogram.reprojection.cylindrical_equal_area`, standard parallel the map's centre) made valid
    there (:func:`rfmap.cartogram.reprojection.split_bent_edges`).  Returns the polygons and what was repaired."""
    out = frame.unproject(mapped) if output == "input" else frame.planar(mapped)
    out, needles = remove_needles(out)
    out, specks = repair_specks(out, total_change=REPAIR_AREA)
    repairs = OutputRepairs(specks=specks, needles=needles)
    if output == "input" and frame.projection.geographic:
        lat0 = frame.projection.lat0
        out, repairs.split, repairs.invalid_reprojected = split_bent_edges(
            out, lambda xy: cylindrical_equal_area(xy, lat0))
    return out, repairs


def repair_specks(geoms: np.ndarray, *, max_change: float = SPECK,
                  total_change: float = 0.0) -> tuple[np.ndarray, list[int]]:
    r"""Invalid polygons (R,) made valid where the fix moves at most ``max_change`` of their area, or
    ``total_change`` of the total area (:data:`rfmap.cartogram.metrics.REPAIR_AREA` for :func:`output_geometries`:
    the metrics' tolerance on overlaps): each is replaced by the polygon parts of ``shapely.make_valid`` that hold
    more than ``max_change`` of its area (the speck where a ring crossed itself is dropped).  Returns the polygons and
    the indices of those replaced; the others are left as they were."""
    import shapely

    bad = np.flatnonzero(~shapely.is_valid(geoms))
    out, fixed = geoms.copy(), []
    budget = total_change * float(np.abs(shapely.area(geoms)).sum()) if bad.size else 0.0
    for i in bad:
        parts = shapely.get_parts(shapely.make_valid(geoms[i]))
        parts = parts[np.isin(shapely.get_type_id(parts), (3, 6))]
        parts = shapely.get_parts(parts)
        area = abs(shapely.area(geoms[i]))
        keep = parts[shapely.area(parts) > max_change * area]
        if not keep.size:
            continue
        g = keep[0] if keep.size == 1 else shapely.multipolygons(keep)
        if shapely.is_valid(g) and abs(shapely.area(g) - area) <= max(max_change * area, budget):
            out[i] = g
            fixed.append(int(i))
    return out, fixed


def crs_member(frame, output: str) -> dict | None:
    """The GeoJSON 2008 ``"crs"`` member of a cartogram written in the projection's plane (its PROJ definition as
    a named CRS), ``None`` for longitude/latitude (RFC 7946's default) or planar input."""
    definition = frame.projection.definition
    if output != "projected" or definition is None:
        return None
    return {"type": "name", "properties": {"name": definition}}


def mapped_features(features: list, mapped: np.ndarray) -> list:
    """The input features with the mapped polygons (in the output's coordinates) as their geometries."""
    from shapely.geometry import mapping as to_geojson

    from .regions import _listify

    out = []
    for feat, g in zip(features, mapped):
        f = {k: v for k, v in feat.items() if k not in ("geometry", "bbox")}
        f.update(type="Feature", geometry=_listify(to_geojson(g)), properties=dict(feat.get("properties") or {}))
        out.append(f)
    return out


def write_geojson(fh, features: list, geometries: np.ndarray, status: dict, crs: dict | None) -> None:
    """A FeatureCollection as JSON text: the ``features``' ids and properties with ``geometries`` written by GEOS
    (``shapely.to_geojson``: the same shortest round-trip numbers, several times faster than ``json``), the ``crs``
    member when given, and the ``"rfmap"`` member ``status``."""
    import shapely

    fh.write('{"type": "FeatureCollection", ' + (f'"crs": {json.dumps(crs)}, ' if crs else "") + '"features": [')
    for k, (feat, geom) in enumerate(zip(features, shapely.to_geojson(geometries))):
        head = {key: v for key, v in feat.items() if key not in ("geometry", "bbox")}
        head.update(type="Feature", properties=dict(feat.get("properties") or {}))
        fh.write(("" if k == 0 else ", ") + json.dumps(head)[:-1] + ', "geometry": ' + geom + "}")
    fh.write('], "rfmap": ' + json.dumps(status) + "}")
