r"""The output of a cartogram: the coordinates it is written in, and its GeoJSON.

A cartogram of longitude/latitude regions is computed in an equal-area plane (:mod:`rfmap.projection`).  Written
back in longitude/latitude (``output="input"``), a region that the passes moved where no longitude/latitude lies
(past a pole's line, beyond the far side of the Lambert disc: Russia on a world map by population) can only be drawn
at the domain's edge.  By default (``output="auto"``) such a cartogram is written in its equal-area plane instead,
and says so: the GeoJSON's ``"crs"`` member (GeoJSON 2008's named CRS, which RFC 7946 dropped but GDAL still reads)
holds the plane's PROJ definition, and the ``"rfmap"`` member its ``coordinates`` and the regions that left the
domain (:func:`choose_output`).
"""
from __future__ import annotations

import json

import numpy as np

__all__ = ["OUTPUTS", "choose_output", "crs_member", "mapped_features", "write_geojson"]

#: The coordinates of :func:`rfmap.cartogram.cartogram`'s output: ``"auto"`` (the input's, unless a region left
#: their domain, then the projection's plane), the input's, or the projection's plane.
OUTPUTS = ("auto", "input", "projected")


def choose_output(frame, mapped: np.ndarray, output: str) -> tuple[str, list[int]]:
    """The coordinates to write mapped regions (unit square, (R,)) in, and the regions beyond the projection's domain
    (:meth:`rfmap.projection.PlanarFrame.beyond_domain`; checked for ``"auto"`` only): ``"auto"`` becomes
    ``"projected"`` when there are any, else ``"input"``."""
    if output != "auto":
        return output, []
    far = np.flatnonzero(frame.beyond_domain(mapped)).tolist() if frame.projection.geographic else []
    return ("projected" if far else "input"), far


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
