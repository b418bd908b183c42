"""Cartograms on hard maps (issue: thousands of small regions, regions that overlap in the input, a country across
the antimeridian, the world in its plane): synthetic maps of :mod:`rfmap.cartogram.synthetic`."""
from __future__ import annotations

import numpy as np
import pytest
import shapely
from shapely.geometry import shape

from rfmap.cartogram.resize import cartogram, density_grid
from rfmap.cartogram.metrics import MINOR_BUDGET, judged, pass_weights
from rfmap.cartogram.synthetic import synthetic_counties, synthetic_subdivisions
from rfmap.cartogram.regions import read_regions


@pytest.fixture(scope="module")
def counties():
    return synthetic_counties()


@pytest.fixture(scope="module")
def sliver_counties():
    return synthetic_counties(slivers=True)


def _geoms(fc):
    return np.array([shape(f["geometry"]) for f in fc["features"]], dtype=object)


def test_synthetic_counties_are_thousands_of_regions_of_very_different_sizes(counties):
    g = _geoms(counties)
    area = shapely.area(g)
    values = np.array([f["properties"]["value"] for f in counties["features"]])
    assert len(g) >= 3000
    assert area.max() / area.min() > 1e4  # county-like: sizes over orders of magnitude
    assert (values > 0).all() and (values / area).max() / (values / area).min() > 1e4
    assert shapely.is_valid(g).all()
    assert shapely.coverage_is_valid(g)  # neighbours share their borders vertex for vertex


def test_overlapping_sparse_regions_keep_the_raster_positive():
    # two sparse squares drawn over each other (a border drawn twice, an enclave without its hole) beside a dense one
    geoms = np.array([shapely.box(0.1, 0.1, 0.6, 0.6), shapely.box(0.2, 0.2, 0.7, 0.7), shapely.box(0.7, 0.1, 0.9, 0.3)])
    values = np.array([1.0, 1.0, 1000.0])
    dens, sea = density_grid(geoms, values, 41)
    assert np.isfinite(dens).all() and dens.min() > 0
    rho = values / shapely.area(geoms)
    # inside the overlap the density is the two regions' mean, outside each one its own
    assert dens[16, 16] == pytest.approx(rho[:2].mean())
    assert dens[8, 8] == pytest.approx(rho[0])
    # the plain sum sea + sum_i (rho_i - sea) c_i, which the raster keeps where nothing overlaps, is negative there
    assert sea + (rho[0] - sea) + (rho[1] - sea) < 0


def test_the_raster_is_the_plain_sum_where_regions_do_not_overlap(counties):
    from rfmap.cartogram.regions import OVERLAP_COVER, _scanline_rows

    _, geoms, values, _ = read_regions(counties, "value")
    unit = shapely.transform(geoms, lambda p: (p - [-125.0, 24.0]) / 60.0 * 0.8 + 0.1)
    n, s = 129, 4
    dens, sea = density_grid(unit, values, n, supersample=s)
    rho = values / shapely.area(unit)
    excess, cover = (t.T for t in _scanline_rows(unit, (rho - sea, np.ones_like(rho)), n, s))
    t = ((np.arange(n * s) + 0.5) / s - 0.5) / (n - 1)
    lines = np.add.reduceat(((t >= 0) & (t <= 1)).astype(float), np.arange(0, n * s, s))
    width = np.full(n, 1.0)
    width[[0, -1]] = 0.5
    size = np.outer(width, lines)
    assert (cover / size).max() <= 1.0 + OVERLAP_COVER  # a coverage: nothing counted twice
    assert np.array_equal(dens, sea + excess / size)
    assert dens.min() > 0


def test_a_county_map_with_overlapping_borders_is_not_refused(sliver_counties):
    from rfmap.cartogram.metrics import overlaps

    _, geoms, values, _ = read_regions(sliver_counties, "value")
    left, right, inter = overlaps(geoms)
    assert (inter / np.minimum(shapely.area(geoms[left]), shapely.area(geoms[right])) > 0.01).sum() > 10
    c = cartogram(sliver_counties, "value", iterations=3)  # was: "density must be finite and strictly positive"
    assert len(c.mapped) == len(geoms)
    assert c.info["max_error"][-1] < 0.5 * c.info["max_error"][0]


def test_a_county_file_simplified_county_by_county_meets_the_tolerance_without_overlaps():
    """Counties each simplified on its own overlap their neighbours and open sliver gaps between them (hundreds of
    holes in their union).  The input is made a coverage with the slivers of gap closed, and overlaps that the passes
    still press together (tiny dense regions touching at a corner) are cut and followed by passes that bring the
    areas back: within the tolerance, every region valid, no overlap (before: 6 overlapping pairs, largest error
    0.0249, exit 1, on the 3,100-county map)."""
    from rfmap.cartogram.metrics import clean_input_overlaps
    from rfmap.cartogram.projection import PlanarFrame

    fc = synthetic_counties(800, seed=3, slivers=True)
    _, geoms, _, _ = read_regions(fc, "value")
    n = 128
    regions = PlanarFrame.fit(geoms, margin=0.05).project(geoms, 1.0 / n)
    holes = [sum(len(p.interiors) for p in shapely.get_parts(shapely.union_all(g)))
             for g in (regions, clean_input_overlaps(regions)[0], clean_input_overlaps(regions, 0.25 / n)[0])]
    assert holes[0] > 20 and holes[1] > 20 and holes[2] == 0, holes
    c = cartogram(fc, "value", n=n)
    m = c.metrics()
    assert c.info["input_overlaps"] > 50
    assert m.max_error <= 0.01 and m.n_invalid == 0 and m.n_overlapping == 0, (m, c.info["max_error"][-3:])
    assert not c.problems()


def test_regions_under_the_judged_share_are_raised_within_a_budget(counties):
    values = np.array([f["properties"]["value"] for f in counties["features"]])
    w = pass_weights(values, 1e-4)
    big = judged(values, 1e-4)
    assert (~big).sum() > 500  # a county map holds many small regions
    assert (w[big] == values[big]).all() and (w >= values).all()
    assert (w - values).sum() == pytest.approx(MINOR_BUDGET * values.sum(), rel=1e-9)
    # a map with few small regions raises them to the judged share itself
    few = np.array([1e6, 2e6, 10.0])
    assert pass_weights(few, 1e-4)[2] == pytest.approx(1e-4 * few.sum())


def _written(path):
    import json

    doc = json.loads(path.read_text())
    return doc, np.array([shape(f["geometry"]) for f in doc["features"]], dtype=object)


def test_county_map_cartogram_passes_reach_the_tolerance(counties, tmp_path):
    """Valid in the unit square and in the file written: scaled to metres, rounding made three counties cross
    themselves by a speck (written as invalid while the status said "ok")."""
    c = cartogram(counties, "value", output="projected")
    assert min(c.info["max_error"]) <= 0.01  # the passes (before any sliver overlap is cut)
    m = c.metrics()
    assert m.n_invalid == 0 and m.n_overlapping == 0
    assert m.mean_error < 0.005
    c.save(tmp_path / "counties.geojson")
    doc, geoms = _written(tmp_path / "counties.geojson")
    assert doc["rfmap"]["status"] == "ok" and doc["rfmap"]["coordinates"] == "projected"
    assert shapely.is_valid(geoms).all(), np.flatnonzero(~shapely.is_valid(geoms))
    # scaling moves no area: every region left alone holds its share of the total as in the unit square, and the
    # regions whose needles or specks were removed moved within those repairs' bounds (NEEDLE_AREA of their own area,
    # REPAIR_AREA of the total)
    from rfmap.cartogram.metrics import REPAIR_AREA
    from rfmap.cartogram.reprojection import NEEDLE_AREA

    share, want = shapely.area(geoms) / shapely.area(geoms).sum(), c.areas / c.areas.sum()
    alone = np.setdiff1d(np.arange(len(share)), c.info["repaired_output"].regions)
    assert np.allclose(share[alone], want[alone], rtol=1e-8, atol=0)
    assert np.all(np.abs(share - want) <= NEEDLE_AREA * want + REPAIR_AREA)
    # turned back into longitude/latitude, straight edges are other curves: six counties crossed themselves there
    from rfmap.cartogram.output import output_geometries

    lonlat, fixed = output_geometries(c.frame, c.mapped, "input")
    assert shapely.is_valid(lonlat).all() and len(fixed.regions) >= 1


def test_specks_of_rounding_are_repaired_and_what_is_written_invalid_fails(tmp_path):
    from rfmap.cartogram.output import SPECK, repair_specks

    # a square whose top edge passes a hair under one of its own vertices: a ring that crosses itself by a speck
    eps = 1e-9
    speck = shapely.Polygon([(0, 0), (1, 0), (1, 1), (0.5, 1), (0.5 + eps, 1 + eps), (0.5 + 2 * eps, 1 - eps),
                             (0, 1)])
    bowtie = shapely.Polygon([(0, 0), (1, 1), (1, 0), (0, 1)])  # two lobes of equal area: no speck to drop
    geoms = np.array([speck, bowtie, shapely.box(2, 0, 3, 1)], dtype=object)
    assert not shapely.is_valid(geoms[:2]).any()
    out, fixed = repair_specks(geoms)
    assert fixed == [0] and shapely.is_valid(out[0]) and out[2] is geoms[2]
    assert abs(shapely.area(out[0]) - 1.0) <= SPECK
    assert not shapely.is_valid(out[1])  # a real fold stays, for problems() to report
    # a cartogram whose written polygons are invalid says so, in its file too
    fc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "id": k, "properties": {"v": 1.0},
         "geometry": shapely.geometry.mapping(shapely.box(k, 0, k + 1, 1))} for k in range(3)]}
    c = cartogram(fc, "v", n=32, iterations=1)
    assert not c.problems()
    c.geometries = c.geometries.copy()
    c.geometries[1] = bowtie
    assert any("invalid region in the written coordinates" in p and "id 1" in p for p in c.problems())
    c.save(tmp_path / "bad.geojson")
    assert _written(tmp_path / "bad.geojson")[0]["rfmap"]["status"] == "failed"


# ----------------------------------------------------------------------------------------------- the world
@pytest.fixture(scope="module")
def world_file(tmp_path_factory):
    import json

    from rfmap.cartogram.regions import world_countries

    path = tmp_path_factory.mktemp("world") / "world.geojson"
    path.write_text(json.dumps(world_countries()))
    return path


def _run_cli(*args):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "rfmap.cli", "cartogram", *map(str, args)], capture_output=True,
                          text=True, timeout=900)


def test_the_world_by_default_is_written_in_its_plane_and_exits_0(world_file, tmp_path):
    """The world by population leaves the longitude/latitude domain (Russia past the edge of Equal Earth): the
    default writes it in the plane, says so in the output's "crs" and "rfmap" members, and exits 0; --lonlat forces
    longitude/latitude, where the regions are drawn at the domain's edge, and exits 1."""
    import json

    pytest.importorskip("pyproj")
    out = tmp_path / "world-out.geojson"
    proc = _run_cli(world_file, "--value", "pop_est", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "projection's plane" in proc.stdout and "Traceback" not in proc.stderr
    doc = json.loads(out.read_text())
    status = doc["rfmap"]
    assert status["status"] == "ok" and status["coordinates"] == "projected" and status["max_error"] <= 0.01
    assert any("Russia" in r for r in status["beyond_domain"])
    assert doc["crs"]["properties"]["name"] == status["projection"] and "+proj=eqearth" in status["projection"]
    xy = shapely.get_coordinates(np.array([shape(f["geometry"]) for f in doc["features"]]))
    assert np.abs(xy).max() > 1e6  # metres, not degrees
    forced = tmp_path / "world-lonlat.geojson"
    proc = _run_cli(world_file, "--value", "pop_est", "--out", forced, "--lonlat")
    assert proc.returncode == 1 and "beyond the projection's domain" in proc.stderr
    assert json.loads(forced.read_text())["rfmap"]["coordinates"] == "input"


def test_a_cartogram_within_the_domain_stays_in_longitude_latitude():
    from rfmap.cartogram.regions import world_countries

    africa = {"type": "FeatureCollection", "features": [f for f in world_countries()["features"]
                                                        if f["properties"]["continent"] == "Africa"]}
    c = cartogram(africa, "pop_est", n=64, iterations=2)
    assert c.output == "input" and c.info["beyond_domain"] == []
    assert "crs" not in c.to_geojson() and np.abs(shapely.get_coordinates(c.geometries)).max() <= 180


def test_subdivisions_across_the_antimeridian_stay_disjoint():
    """Russia cut into 80 subdivisions, those across 180° split there: the cartogram meets the tolerance with every
    region valid and no pair overlapping, in longitude/latitude too (a regression test on a clean coverage; maps
    whose input borders overlap are not covered)."""
    fc = synthetic_subdivisions()
    xy = shapely.get_coordinates(_geoms(fc))
    assert xy[:, 0].min() < -170 and xy[:, 0].max() > 170  # the map crosses the antimeridian
    c = cartogram(fc, "value", output="input")
    m = c.metrics()
    assert m.max_error <= 0.01 and m.n_invalid == 0 and m.n_overlapping == 0, m
    assert not c.problems()
    assert shapely.is_valid(c.geometries).all()  # in longitude/latitude as well


def test_subdivisions_whose_borders_overlap_come_out_disjoint():
    """Russia's subdivisions with every border bent and each region simplified on its own: dozens of neighbours
    overlap in the input, across 180° too.  The input is made a coverage first, so the cartogram holds no overlap
    (before: 31-36 overlapping pairs, exit 1), every region valid in longitude/latitude, within the tolerance."""
    from rfmap.cartogram.metrics import REPAIR_AREA, overlaps

    fc = synthetic_subdivisions(slivers=True)
    g = _geoms(fc)
    inter = overlaps(g)[2]
    assert (inter > REPAIR_AREA * shapely.area(g).sum()).sum() > 20
    c = cartogram(fc, "value", output="input")
    assert c.info["input_overlaps"] > 20
    m = c.metrics()
    assert m.n_overlapping == 0 and m.n_invalid == 0 and m.max_error <= 0.01, m
    assert not c.problems() and shapely.is_valid(c.geometries).all()


def test_no_pass_asks_a_region_for_more_than_the_pass_contrast(monkeypatch):
    """A city a few raster cells wide that must grow 2,000-fold (as St. Petersburg and Moscow do on Russia's
    map): every pass's raster stays within PASS_CONTRAST of the sea's density, so the city grows over several passes
    (before, one pass squeezed its neighbours into bands thinner than a cell whose borders crossed), and the
    cartogram still meets the tolerance, valid, without overlaps."""
    import rfmap.cartogram.resize as resize

    disc = shapely.Point(5.0, 5.0).buffer(0.12, quad_segs=16)
    feats = []
    for i in range(3):
        for j in range(3):
            box = shapely.box(i * 10 / 3, j * 10 / 3, (i + 1) * 10 / 3, (j + 1) * 10 / 3)
            if (i, j) == (1, 1):
                box = box.difference(disc)
            feats.append({"type": "Feature", "properties": {"value": box.area * (1.0 + 0.5 * ((i + 2 * j) % 3))},
                          "geometry": shapely.geometry.mapping(box)})
    feats.append({"type": "Feature", "properties": {"value": disc.area * 2000.0},
                  "geometry": shapely.geometry.mapping(disc)})
    from rfmap.cartogram.methods import FlowMethod

    seas, ratios, grid_map, raster = [], [], FlowMethod.grid_map, resize.density_grid

    def spy_raster(*args, **kw):
        dens, sea = raster(*args, **kw)
        seas.append(sea)
        return dens, sea

    def spy_map(self, density, points):
        ratios.append((density.max() / seas[-1], density.min() / seas[-1]))
        return grid_map(self, density, points)

    monkeypatch.setattr(resize, "density_grid", spy_raster)
    monkeypatch.setattr(FlowMethod, "grid_map", spy_map)
    c = cartogram({"type": "FeatureCollection", "features": feats}, "value", n=256)
    top, bottom = np.array(ratios).T
    assert len(ratios) >= 3  # the city needed more than one pass
    assert top.max() <= resize.PASS_CONTRAST * (1 + 1e-12) and bottom.min() >= (1 - 1e-12) / resize.PASS_CONTRAST
    assert top[0] == pytest.approx(resize.PASS_CONTRAST)  # the first pass was clipped
    m = c.metrics()
    assert m.max_error <= 0.01 and m.n_invalid == 0 and m.n_overlapping == 0, m
