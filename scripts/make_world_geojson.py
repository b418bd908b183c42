#!/usr/bin/env python3
"""Write src/rfmap/data/naturalearth_lowres.geojson, the world map of :func:`rfmap.cartogram.regions.world_countries`.

Usage::

    pip download geopandas==0.14.4 --no-deps -d /tmp/gpd
    pip install pyshp            # only this script needs it
    python scripts/make_world_geojson.py /tmp/gpd/geopandas-0.14.4-py3-none-any.whl

The source is the ``naturalearth_lowres`` shapefile that the geopandas 0.14.4 wheel ships
(``geopandas/datasets/naturalearth_lowres/``): Natural Earth's 1:110m Admin 0 countries (public domain,
https://www.naturalearthdata.com), 177 countries, with Crimea drawn with Ukraine as geopandas prepared it.  The
shapefile is read from the wheel with pyshp; each country becomes one GeoJSON Feature with the properties ``name``,
``iso_a3``, ``continent`` and ``pop_est`` (an integer), its rings oriented as RFC 7946 asks (exterior
counter-clockwise) and its coordinates rounded to 4 decimals (about 10 m, far below the 1:110m scale).  A country
that rounding leaves invalid (a narrow spike of Sudan's border that closes, a speck of North Korea's coast) is
repaired with ``shapely.make_valid`` and its slivers (parts under 0.1 % of its area) dropped; the script prints how
many were.
"""
from __future__ import annotations

import argparse
import io
import json
import zipfile
from pathlib import Path

import shapely
from shapely.geometry import mapping, shape
from shapely.geometry.polygon import orient

ROOT = Path(__file__).resolve().parent.parent
TARGET = ROOT / "src" / "rfmap" / "data" / "naturalearth_lowres.geojson"
MEMBER = "geopandas/datasets/naturalearth_lowres/naturalearth_lowres"
DIGITS = 4
#: Parts of a repaired country smaller than this fraction of its area are slivers of a spike, and dropped.
SLIVER = 1e-3


def read_shapefile(wheel: Path):
    """The records and shapes of the wheel's shapefile (a pyshp ``Reader``)."""
    import shapefile  # pyshp

    with zipfile.ZipFile(wheel) as z:
        parts = {ext: io.BytesIO(z.read(f"{MEMBER}.{ext}")) for ext in ("shp", "shx", "dbf")}
        encoding = z.read(f"{MEMBER}.cpg").decode("ascii").strip()
    return shapefile.Reader(**parts, encoding=encoding)


def _rounded(obj):
    if isinstance(obj, (list, tuple)):
        if obj and isinstance(obj[0], float):
            return [round(c, DIGITS) for c in obj]
        return [_rounded(o) for o in obj]
    return obj


def convert(reader) -> tuple[dict, int]:
    """The FeatureCollection and the number of countries that rounding left invalid (repaired)."""
    features, repaired = [], 0
    for rec, shp in zip(reader.records(), reader.shapes()):
        g = shape(shp.__geo_interface__)
        g = shape({"type": g.geom_type, "coordinates": _rounded(mapping(g)["coordinates"])})
        if not g.is_valid:  # a spike or a speck that rounding closed: its slivers are dropped
            g = shapely.make_valid(g)
            repaired += 1
            polys = [p for p in shapely.get_parts(g) if p.geom_type == "Polygon"]
            polys = [p for p in polys if p.area >= SLIVER * g.area]
            g = polys[0] if len(polys) == 1 else shapely.MultiPolygon(polys)
        polys = [orient(p, 1.0) for p in shapely.get_parts(g)]
        g = polys[0] if len(polys) == 1 else shapely.MultiPolygon(polys)
        props = {"name": rec["name"], "iso_a3": rec["iso_a3"], "continent": rec["continent"],
                 "pop_est": int(round(rec["pop_est"]))}
        features.append({"type": "Feature", "properties": props,
                         "geometry": json.loads(json.dumps(mapping(g)))})
    return {"type": "FeatureCollection", "features": features}, repaired


def write(fc: dict, path: Path) -> None:
    """Compact JSON, one feature per line."""
    lines = [json.dumps(f, separators=(",", ":"), ensure_ascii=False) for f in fc["features"]]
    path.write_text('{"type":"FeatureCollection","features":[\n' + ",\n".join(lines) + "\n]}\n", encoding="utf-8")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("wheel", type=Path, help="geopandas-0.14.4-py3-none-any.whl")
    p.add_argument("--out", type=Path, default=TARGET)
    args = p.parse_args()
    fc, repaired = convert(read_shapefile(args.wheel))
    write(fc, args.out)
    print(f"wrote {args.out}: {len(fc['features'])} countries, {repaired} repaired after rounding, "
          f"{args.out.stat().st_size / 1e3:.0f} kB")


if __name__ == "__main__":
    main()
