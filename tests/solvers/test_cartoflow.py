"""The lean flow-based cartogram path: torch-free imports, the numpy transforms and rasteriser, the stopping rule over
the regions holding >= 0.01 % of the total value, outline budgets, accuracy on real maps and the command's exit codes.
"""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

shapely = pytest.importorskip("shapely")

from rfmap.cartogram.resize import MIN_SHARE, cartogram, cartogram_metrics  # noqa: E402
from rfmap.cartogram.regions import density_grid, fit_outlines, world_countries  # noqa: E402
from rfmap.solvers.cartoflow import bilinear, flow_square  # noqa: E402


def squares(values, *, side: float = 1000.0) -> dict:
    """A row-major grid of planar squares (side metres), one per value, as a FeatureCollection."""
    k = int(np.ceil(np.sqrt(len(values))))
    feats = []
    for i, v in enumerate(values):
        x, y = (i % k) * side, (i // k) * side
        ring = [[x, y], [x + side, y], [x + side, y + side], [x, y + side], [x, y]]
        feats.append({"type": "Feature", "id": f"r{i}", "properties": {"pop": v},
                      "geometry": {"type": "Polygon", "coordinates": [ring]}})
    return {"type": "FeatureCollection", "features": feats}


def continent(name: str) -> dict:
    feats = [f for f in world_countries()["features"] if f["properties"]["continent"] == name]
    return {"type": "FeatureCollection", "features": feats}


#: an Asia-Pacific set around the antimeridian: Russia and Fiji are split there
ASIA_PACIFIC = ("Russia", "Fiji", "New Zealand", "Australia", "Papua New Guinea", "Indonesia", "Japan", "Philippines",
                "China", "Mongolia", "South Korea", "North Korea", "Taiwan", "Vanuatu", "Solomon Is.", "New Caledonia")


# ----------------------------------------------------------------------------------------------- imports
def test_classical_cartogram_path_never_imports_torch(tmp_path):
    """Importing the package, its command line and the cartogram modules, building the parser, and running a flow
    and a diffusion cartogram through the command line load no PyTorch; the neural names still import on access."""
    src, out = tmp_path / "in.geojson", tmp_path / "out.geojson"
    src.write_text(json.dumps(squares([1, 1, 1, 5])))
    code = f"""
import sys
import rfmap, rfmap.cli, rfmap.cartogram.resize, rfmap.cartogram.regions, rfmap.cartogram.projection, rfmap.solvers, rfmap.solvers.cartoflow
rfmap.cli.build_parser()
assert 'torch' not in sys.modules, 'import'
for method in ('flow', 'diffusion'):
    rc = rfmap.cli.main(['cartogram', {str(src)!r}, '--value', 'pop', '--method', method, '--n', '32',
                         '--out', {str(out)!r}])
    assert rc == 0, (method, rc)
    assert 'torch' not in sys.modules, method
assert 'scipy.fft' not in sys.modules, 'scipy.fft'
from rfmap import Surrogate
assert 'torch' in sys.modules and Surrogate.__name__ == 'Surrogate'
print('ok')
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0 and res.stdout.strip().endswith("ok"), res.stderr[-2000:]


def test_solvers_registry_is_lazy_but_complete():
    import rfmap.solvers as S

    assert set(S.SOLVERS) == {"lbs", "diffusion", "flow"} and S.get_solver("dem") is S.solve_diffusion
    with pytest.raises(AttributeError):
        S.no_such_solver  # noqa: B018


# ----------------------------------------------------------------------------------------------- numerics
def test_numpy_and_scipy_transforms_give_one_poisson_flux_and_blur():
    """The cosine method of :mod:`rfmap.solvers.spectral` on the cartograms' ``numpy.fft`` transforms and on the
    maps' ``scipy.fft`` ones: the same flux, blurred planes and heat synthesis to round-off."""
    from rfmap.solvers.cosine import CosineTransforms
    from rfmap.solvers.spectral import flow_planes, gaussian_blur, poisson_flux

    rng = np.random.default_rng(3)
    dens = np.exp(rng.normal(size=(33, 33)))
    ours, ref = poisson_flux(dens, transforms=CosineTransforms(33)), poisson_flux(dens)
    assert np.abs(ours - ref).max() <= 1e-12 * np.abs(ref).max()
    assert np.all(ours[0, [0, -1]] == 0) and np.all(ours[1, :, [0, -1]] == 0)  # no flux through the walls
    planes = flow_planes(dens, 0.05, transforms=CosineTransforms(33))
    assert np.abs(planes[2] - gaussian_blur(dens, 0.05)).max() <= 1e-12 * dens.max()
    assert np.abs(planes[:2] - flow_planes(dens, 0.05)[:2]).max() <= 1e-12 * np.abs(ref).max()
    assert np.array_equal(flow_planes(dens, transforms=CosineTransforms(33))[2], dens)



def test_cosine_transforms_match_their_sums_along_both_axes():
    """DCT-I and DST-I of :class:`rfmap.solvers.cosine.CosineTransforms` against their defining sums (to 1e-12 of
    the largest term), along each axis, twice in a row (the buffers are reused), whole tables, in blocks of rows
    (4 rows and 1) and by ``scipy.fft`` (as a 2049-vertex table runs), and shapes refused."""
    from rfmap.solvers.cosine import CosineTransforms

    m = 9
    j = np.arange(m)
    c = 2.0 * np.cos(np.pi * np.outer(j, j) / (m - 1))
    c[:, 0] /= 2
    c[:, -1] /= 2  # y_k = x_0 + (-1)^k x_{M-1} + 2 sum_j x_j cos(pi j k / (M-1)): C[k, j]
    i = np.arange(m - 2)
    s = 2.0 * np.sin(np.pi * np.outer(i + 1, i + 1) / (m - 1))  # K = M - 2, K + 1 = M - 1
    rng = np.random.default_rng(5)
    for ct in (CosineTransforms(m), CosineTransforms(m, block=4), CosineTransforms(m, block=1),
               CosineTransforms(m, use_scipy=True)):
        for _ in range(2):
            x, z = rng.normal(size=(m, m)), rng.normal(size=(m, m - 2))
            tol = 1e-12 * 2 * m * max(np.abs(x).max(), np.abs(z).max())
            assert np.abs(ct.dct(x, 1) - x @ c.T).max() < tol
            assert np.abs(ct.dct(x, 0) - c @ x).max() < tol
            assert np.abs(ct.dst(z, 1) - z @ s.T).max() < tol
            assert np.abs(ct.dst(z.T, 0) - s @ z.T).max() < tol
            into = np.empty((m - 2, m))
            assert ct.dst(z.T, 0, out=into) is into and np.abs(into - s @ z.T).max() < tol
            into = np.empty((m, m))
            assert ct.dct(x, 0, out=into) is into and np.abs(into - c @ x).max() < tol
            for axis, want in ((0, c @ x), (1, x @ c.T)):  # in place
                into = x.copy()
                assert ct.dct(into, axis, out=into) is into and np.abs(into - want).max() < tol
    assert CosineTransforms(513).block == 1024 and CosineTransforms(513)._scipy is None  # numpy.fft, whole tables
    with pytest.raises(ValueError, match="shape"):
        ct.dst(x, 1)
    with pytest.raises(ValueError, match="shape"):
        ct.dct(np.ones((m, m + 1)), 0)
    with pytest.raises(ValueError, match="out must have shape"):
        ct.dct(x, 1, out=np.empty((m, m - 1)))


@pytest.mark.parametrize("use_scipy", [False, True])
def test_single_precision_transforms_match_their_sums_to_float32_rounding(use_scipy):
    """``CosineTransforms(dtype=np.float32)`` (the cartogram flow's tables) returns float32 tables within float32
    rounding of the double-precision sums (1e-6 of the largest term times the side), along each axis, by
    ``numpy.fft`` and by scipy's pocketfft; a float64 ``out`` is refused and other precisions are."""
    from rfmap.solvers.cosine import CosineTransforms

    m = 65
    j = np.arange(m)
    c = 2.0 * np.cos(np.pi * np.outer(j, j) / (m - 1))
    c[:, 0] /= 2
    c[:, -1] /= 2
    i = np.arange(m - 2)
    s = 2.0 * np.sin(np.pi * np.outer(i + 1, i + 1) / (m - 1))
    rng = np.random.default_rng(6)
    ct = CosineTransforms(m, use_scipy=use_scipy, dtype=np.float32)
    x, z = rng.normal(size=(m, m)), rng.normal(size=(m, m - 2))
    tol = 1e-6 * 2 * m * max(np.abs(x).max(), np.abs(z).max())
    # the table of both axes' transforms sums 2M times as many terms: its tolerance is 2M times as large
    for got, want, bound in ((ct.dct(x, 1), x @ c.T, tol), (ct.dct(x, 0), c @ x, tol), (ct.dst(z, 1), z @ s.T, tol),
                             (ct.dst(z.T, 0), s @ z.T, tol), (ct.dctn(x), c @ x @ c.T, 2 * m * tol)):
        assert got.dtype == np.float32
        assert np.abs(got - want).max() < bound
    with pytest.raises(ValueError, match="out must be float32"):
        ct.dct(x, 1, out=np.empty((m, m)))
    with pytest.raises(ValueError, match="dtype must be float32 or float64"):
        CosineTransforms(m, dtype=np.float16)
    with pytest.raises(ValueError, match="at least 3"):
        CosineTransforms(2)
    with pytest.raises(ValueError, match="block"):
        CosineTransforms(m, block=0)


def test_bilinear_is_exact_on_bilinear_fields():
    n = 9
    t = np.linspace(0, 1, n)
    x, y = np.meshgrid(t, t, indexing="ij")
    table = np.stack([2 * x - y + 0.5, x * y], axis=-1)
    pts = np.random.default_rng(0).uniform(size=(200, 2))
    want = np.stack([2 * pts[:, 0] - pts[:, 1] + 0.5, pts[:, 0] * pts[:, 1]], axis=-1)
    assert np.abs(bilinear(table, pts) - want).max() < 1e-12


def test_flow_square_equalizes_and_keeps_the_grid_unfolded():
    """A bump of density spreads: the grid map stays fold-free, walls on their walls, and the flow moves the points
    it is given exactly as it moves the grid's vertices."""
    n = 33
    t = np.linspace(0, 1, n)
    x, y = np.meshgrid(t, t, indexing="ij")
    dens = 1 + 3 * np.exp(-((x - 0.4) ** 2 + (y - 0.6) ** 2) / 0.02)
    res = flow_square(dens)
    g = res.mapped_points.reshape(n, n, 2)
    assert np.all(g[0, :, 0] == 0) and np.all(g[-1, :, 0] == 1) and np.all(g[:, 0, 1] == 0)
    from rfmap.solvers.cartoflow import min_triangle_area

    assert min_triangle_area(g) > 0 and res.info["steps"] > 0
    moved = np.linalg.norm(res.mapped_points - res.ref_points, axis=1).reshape(n, n)
    assert moved[12, 19] < 0.02 and moved.max() > 0.02  # the bump's centre barely moves, its flanks do
    uniform = flow_square(np.full((n, n), 2.0))
    assert np.abs(uniform.mapped_points - uniform.ref_points).max() < 1e-12


def test_heat_planes_are_exact_on_cosine_modes_and_the_diffusion_map_equalizes():
    r"""The diffusing density and its gradient on the vertex grid, from the cartogram's numpy transforms, are exact
    for a sum of cosine modes (:math:`e^{-\pi^2|k|^2 t}` decay, to 1e-12); a diffusion map of a two-level density
    keeps the grid unfolded and leaves the mapped density far more uniform than the input."""
    from rfmap.core.geometry import grid_min_measure
    from rfmap.solvers.cartodiffusion import diffusion_square
    from rfmap.solvers.cosine import CosineTransforms
    from rfmap.solvers.heatfield import HeatField

    n, t = 33, 0.01
    s = np.linspace(0.0, 1.0, n)
    x, y = np.meshgrid(s, s, indexing="ij")
    heat = HeatField(2 + np.cos(np.pi * x) + 0.5 * np.cos(2 * np.pi * y), "points", CosineTransforms(n))
    e1, e2 = np.exp(-np.pi ** 2 * t), np.exp(-4 * np.pi ** 2 * t)
    rho, gx, gy = heat.fields(t)
    assert np.abs(rho - (2 + e1 * np.cos(np.pi * x) + 0.5 * e2 * np.cos(2 * np.pi * y))).max() < 1e-12
    assert np.abs(gx + np.pi * e1 * np.sin(np.pi * x)).max() < 1e-12
    assert np.abs(gy + np.pi * e2 * np.sin(2 * np.pi * y)).max() < 1e-12
    dens = np.where(np.hypot(x - 0.4, y - 0.6) < 0.25, 4.0, 1.0)
    res = diffusion_square(dens)
    assert res.info["method"] == "diffusion" and res.info["grid"]
    assert grid_min_measure(res.mapped_points, n) > 0
    # the mapped area of the dense disc, against its share of the mass (an area-weighted check on cells)
    cells = (dens[:-1, :-1] + dens[1:, 1:] + dens[1:, :-1] + dens[:-1, 1:]) / 4
    mapped = res.mapped_points.reshape(n, n, 2)
    d1, d2 = mapped[1:, 1:] - mapped[:-1, :-1], mapped[:-1, 1:] - mapped[1:, :-1]
    area = 0.5 * np.abs(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])
    rel = (cells / cells.sum()) / area
    before = (cells / cells.sum()) / (1.0 / (n - 1) ** 2)
    assert rel.std() < 0.25 * before.std()


def test_scanline_raster_matches_the_exact_lengths_on_its_lines():
    """density_grid measures each scanline exactly: against shapely's intersections of every cell's piece of every
    line with every region (holes, multipolygons, the boundary cells' halves), to 1e-12."""
    outer = shapely.Polygon([(0.1, 0.1), (0.7, 0.15), (0.6, 0.8), (0.15, 0.6)],
                            [[(0.3, 0.3), (0.4, 0.3), (0.35, 0.45)]])
    multi = shapely.MultiPolygon([shapely.box(0.72, 0.2, 0.9, 0.5), shapely.Polygon([(0.7, 0.6), (0.95, 0.9),
                                                                                      (0.65, 0.92)])])
    edge = shapely.box(0.0, 0.0, 0.05, 1.0)  # along the square's wall: half cells
    geoms, values, n, s = np.array([outer, multi, edge], dtype=object), np.array([3.0, 7.0, 0.5]), 21, 4
    dens, sea = density_grid(geoms, values, n, supersample=s)
    h = 1 / (n - 1)
    ys = ((np.arange(n * s) + 0.5) / s - 0.5) * h
    x0 = np.clip((np.arange(n) - 0.5) * h, 0, 1)
    x1 = np.clip((np.arange(n) + 0.5) * h, 0, 1)
    want = np.zeros((n, n))
    for b in range(n):
        lines = [y for y in ys[b * s:(b + 1) * s] if 0 <= y <= 1]
        acc = np.zeros(n)
        for y in lines:
            seg = shapely.linestrings([[[a, y], [c, y]] for a, c in zip(x0, x1)])
            inside = shapely.length(shapely.intersection(seg[None, :], geoms[:, None]))  # (R, N)
            acc += ((values / shapely.area(geoms) - sea)[:, None] * inside).sum(0)
        want[:, b] = sea + acc / ((x1 - x0) * len(lines))
    assert np.abs(dens - want).max() < 1e-12 * want.max()
    assert sea == pytest.approx(values.sum() / shapely.area(geoms).sum())
    again, sea2 = density_grid(geoms, values, n, supersample=s, areas=shapely.area(geoms))  # areas measured already
    assert np.array_equal(again, dens) and sea2 == sea


# ----------------------------------------------------------------------------------------------- stopping rule
def test_stopping_rule_judges_regions_above_the_share_and_reports_the_rest():
    """A region of 1e-6 of the total cannot reach 1 % on a coarse grid; it is left out of the stopping rule and of
    the largest error, and reported apart (its error against its own value)."""
    values = [1.0, 2.0, 3.0, 1.0, 1e-5, 2.0, 1.0, 1.0, 1.0]
    c = cartogram(squares(values), "pop", n=48)
    m = c.metrics()
    major = np.asarray(values) >= MIN_SHARE * sum(values)
    assert major.sum() == 8 and m.n_minor == 1
    err = c.area_errors
    assert m.max_error == pytest.approx(err[major].max(), rel=1e-9) and m.max_error <= 0.01
    assert m.max_error_minor == pytest.approx(err[~major].max(), rel=1e-9) and m.max_error_minor > 0.01
    assert c.info["max_error"][-1] == pytest.approx(m.max_error, rel=1e-6) and m.topology_ok and not c.problems()
    assert "under the judged share" in str(m)
    every = cartogram(squares(values), "pop", n=48, min_share=0.0, max_iterations=3)
    assert every.metrics().n_minor == 0 and every.info["max_error"][-1] > 0.01  # judged over all: not met
    assert cartogram_metrics(c.mapped, c.values).max_error == pytest.approx(err.max(), rel=1e-9)


# ----------------------------------------------------------------------------------------------- outlines
def test_fit_outlines_densifies_and_simplifies_to_a_budget_keeping_areas():
    from rfmap.cartogram.projection import PlanarFrame
    from rfmap.cartogram.regions import read_regions

    _, geoms, values, _ = read_regions(continent("South America"), "pop_est")
    regions = PlanarFrame.fit(geoms, margin=0.1).project(geoms, 1 / 127)
    count = int(shapely.get_num_coordinates(regions).sum())
    dense = fit_outlines(regions, 2 * count)
    assert abs(shapely.get_num_coordinates(dense).sum() / (2 * count) - 1) < 0.05
    assert np.abs(shapely.area(dense) / shapely.area(regions) - 1).max() < 1e-9  # splitting edges keeps areas
    lean = fit_outlines(regions, count // 2)
    big = values >= MIN_SHARE * values.sum()
    assert shapely.get_num_coordinates(lean).sum() <= count // 2
    assert np.abs(shapely.area(lean) / shapely.area(regions) - 1)[big].max() < 0.02
    assert shapely.is_valid(lean).all()
    with pytest.raises(ValueError, match="points"):
        fit_outlines(regions, 3)


@pytest.mark.parametrize("fc,value,points", [("South America", "pop_est", 3000), ("montreal", "total", 2000)])
def test_cartogram_with_a_point_budget(fc, value, points):
    """A simplified map (Montreal's districts draw their shared borders with vertices that do not match) stays a
    coverage: within 1 %, every region valid and no two overlapping."""
    from rfmap.cartogram.regions import montreal_election

    c = cartogram(montreal_election() if fc == "montreal" else continent(fc), value, n=128, points=points)
    m = c.metrics()
    assert m.max_error <= 0.01 and m.topology_ok, m


def test_clean_coverage_makes_shared_borders_match():
    """Two unit squares whose shared border one draws with a midpoint and the other without (a T-junction), and a
    third overlapping the second by a sliver: the result is a valid coverage, areas kept but for the sliver, and the
    second's border with the first now has the midpoint."""
    from rfmap.cartogram.regions import clean_coverage

    a = shapely.Polygon([(0, 0), (1, 0), (1, 0.5), (1, 1), (0, 1)])
    b = shapely.Polygon([(1, 0), (2, 0), (2, 1), (1, 1)])
    c = shapely.Polygon([(1.999, 0), (3, 0), (3, 1), (1.999, 1)])
    regions = np.array([a, b, c], dtype=object)
    assert not shapely.coverage_is_valid(regions)
    out = clean_coverage(regions)
    assert shapely.coverage_is_valid(out) and shapely.is_valid(out).all()
    # the sliver (0.001 of the third's 1.001) went to the first region holding it, the second
    assert np.allclose(shapely.area(out), [1.0, 1.0, 1.0])
    assert np.isclose(shapely.area(shapely.union_all(out)), 3.0)
    assert (1.0, 0.5) in set(map(tuple, shapely.get_coordinates(out[1])))


def test_distinct_vertices_merges_pairs_that_straddle_a_rounding_edge():
    """Points 4e-16 apart on either side of a rounding edge of 12 digits (which rounding would part) are one vertex;
    points 1e-9 apart stay two."""
    from rfmap.cartogram.regions import _distinct_vertices

    x0 = 0.5e-12 + 123456789012 * 1e-12  # half way between two 12-digit numbers
    lo, hi = x0 - 2e-16, x0 + 2e-16
    assert np.round(lo, 12) != np.round(hi, 12)  # the pair rounding would part
    ring = [(lo, 0.5), (0.9, 0.1), (0.9, 0.9), (hi, 0.5 + 1e-17), (0.2, 0.9), (x0 + 1e-9, 0.5)]
    pts = shapely.MultiPoint(ring)
    uniq, inverse = _distinct_vertices(np.array([pts], dtype=object))
    assert len(uniq) == 5 and inverse[0] == inverse[3] and inverse[0] != inverse[5]


def test_distinct_vertices_keep_first_points_in_order_and_merge_chains():
    """Repeats and near points (a chain 0.6e-12 apart, merged transitively) become the vertex of their first
    occurrence; the vertices come in the order of their first occurrences."""
    from rfmap.cartogram.regions import _distinct_vertices

    pts = np.array([(0.3, 0.2), (0.1, 0.1), (0.3, 0.2), (0.5, 0.5), (0.5 + 0.6e-12, 0.5), (0.5 + 1.2e-12, 0.5),
                    (0.1, 0.4), (0.1, 0.1)])
    uniq, inverse = _distinct_vertices(np.array([shapely.MultiPoint(pts)], dtype=object))
    assert np.array_equal(uniq, pts[[0, 1, 3, 6]])
    assert inverse.tolist() == [0, 1, 0, 2, 2, 2, 3, 1]


def test_near_in_x_and_sort_within_runs():
    from rfmap.cartogram.regions import _near_in_x, _sort_within

    assert _near_in_x(np.array([0.0, 1.0, 1.0 + 1e-12, 2.0, 3.0, 3.0]), 2e-12).tolist() == \
        [False, True, True, False, True, True]
    key = np.array([1, 1, 2, 2, 2, 2, 5, 5, 7, 7, 7, 7, 7, 7])
    x = np.array([0.9, 0.1, 0.4, 0.3, 0.8, 0.2, 0.5, 0.6, 6.0, 1.0, 5.0, 2.0, 4.0, 3.0])
    want = x[np.lexsort((x, key))]
    assert np.array_equal(_sort_within(key, x.copy()), want)


# ----------------------------------------------------------------------------------------------- real maps
@pytest.mark.parametrize("name,n", [("South America", 128), ("asia-pacific", 128)])
def test_flow_cartogram_of_real_maps_within_one_percent(name, n):
    """Real maps at small N: the largest area error over the regions holding >= 0.01 % of the population is within
    the 1 % tolerance, measured in the equal-area plane, every region valid and no overlaps; the Asia-Pacific set
    crosses the antimeridian."""
    if name == "asia-pacific":
        fc = {"type": "FeatureCollection",
              "features": [f for f in world_countries()["features"] if f["properties"]["name"] in ASIA_PACIFIC]}
    else:
        fc = continent(name)
    c = cartogram(fc, "pop_est", n=n)
    m = c.metrics()
    assert m.max_error <= 0.01 and m.topology_ok, (m, c.info["max_error"])
    assert not c.problems() and c.method == "flow"


@pytest.mark.parametrize("method", ["flow", "diffusion"])
def test_world_cartogram_splits_stretched_edges(method):
    """The world by population at N = 96: Greenland shrinks a hundredfold while the map squeezes its fjords closed
    and stretches their sides; the edges stretched beyond :data:`rfmap.cartogram.resize.SPLIT_EDGE` cells are split again
    between passes (both classical methods), so that no chord crosses its neighbour: every region valid, no
    overlaps, within 1 %."""
    c = cartogram(world_countries(), "pop_est", n=96, method=method)
    m = c.metrics()
    assert m.max_error <= 0.01 and m.topology_ok, (m, c.info["max_error"])
    # the splits happened: more vertices than the input's (edges of at most a cell of the first raster)
    assert shapely.get_num_coordinates(c.mapped).sum() > 1.2 * shapely.get_num_coordinates(c.regions).sum()


def test_boost_aims_each_pass_at_the_whole_error():
    from rfmap.cartogram.metrics import BOOST_CAP, BOOST_GAIN, boost

    last = np.array([0.2, 0.2, -0.1, 0.05, 0.0])
    now = np.array([0.1, 0.0, -0.09, 0.06, 0.0])  # half removed, all removed, a tenth removed, grown, none
    b = boost(now, last, np.zeros(5))
    # shares 0.5, 1 and 0.1 -> BOOST_GAIN, -0.2 -> BOOST_GAIN: b = now * (1/share - 1), within the cap
    share = np.array([0.5, 1.0, BOOST_GAIN, BOOST_GAIN, 1.0])
    assert np.allclose(b, np.clip(now * (1 / share - 1), -BOOST_CAP, BOOST_CAP), atol=1e-15)
    assert b[0] == pytest.approx(0.1) and b[1] == 0 and b[4] == 0
    assert b[2] == pytest.approx(max(-0.09 * (1 / BOOST_GAIN - 1), -BOOST_CAP))
    # the last boost counts as aimed-at error: with b = 0.1 on an error of 0.2, going to 0.1 is a share of 1/3
    want = min(0.1 * (1 / max(1 / 3, BOOST_GAIN) - 1), BOOST_CAP)
    assert boost(np.array([0.1]), np.array([0.2]), np.array([0.1]))[0] == pytest.approx(want)
    assert np.abs(boost(np.array([5.0, -5.0]), np.array([6.0, -6.0]), np.zeros(2))).max() == BOOST_CAP


def test_longest_edge_of_rings():
    from rfmap.cartogram.regions import _longest_edge

    square = shapely.Polygon([(0, 0), (3, 0), (3, 2), (0, 2)], holes=[[(1, 1), (1.5, 1), (1.5, 1.5)]])
    parts = np.array([square, shapely.MultiPolygon([shapely.box(5, 5, 5.5, 9)])], dtype=object)
    assert _longest_edge(parts) == pytest.approx(4.0, abs=1e-12)  # not the 2 of the jump between the two geometries
    assert _longest_edge(parts[:1]) == pytest.approx(3.0, abs=1e-12)


def test_longest_edges_per_region():
    from rfmap.cartogram.regions import _longest_edges

    square = shapely.Polygon([(0, 0), (3, 0), (3, 2), (0, 2)], holes=[[(1, 1), (1.5, 1), (1.5, 1.5)]])
    parts = np.array([square, shapely.MultiPolygon([shapely.box(5, 5, 5.5, 9), shapely.box(7, 0, 12, 0.1)]),
                      shapely.Polygon()], dtype=object)
    assert np.allclose(_longest_edges(parts), [3.0, 5.0, 0.0], atol=1e-12)  # 0 for a region without edges


def test_segmentize_splits_only_the_long_regions_as_segmentize_does():
    from rfmap.cartogram.regions import _longest_edges
    from rfmap.cartogram.regions import _segmentize

    geoms = np.array([shapely.box(0, 0, 1, 1), shapely.MultiPolygon([shapely.box(2, 0, 2.1, 0.1)]),
                      shapely.MultiPolygon([shapely.box(3, 0, 3.1, 0.1), shapely.box(4, 0, 4.5, 0.1)]),
                      shapely.box(5, 0, 5.3, 0.2)], dtype=object)
    for cell in (0.05, 0.25, 0.3, 2.0):  # 0.3: an edge exactly a cell long, which segmentize leaves whole
        want = shapely.segmentize(geoms, cell)
        got = _segmentize(geoms, cell, _longest_edges(geoms) >= cell * (1.0 - 1e-9))
        assert all(shapely.equals_exact(a, b, 0.0) for a, b in zip(want, got))
        assert np.array_equal(shapely.get_type_id(want), shapely.get_type_id(got))  # a one-part MultiPolygon: Polygon


# ----------------------------------------------------------------------------------------------- command line
def test_flow_cartogram_command_exit_codes(tmp_path, capsys):
    from rfmap.cli import main

    src, out = tmp_path / "in.geojson", tmp_path / "out.geojson"
    src.write_text(json.dumps(squares([1, 2, 3, 4, 1e-5])))
    assert main(["cartogram", str(src), "--value", "pop", "--method", "flow", "--n", "48", "--out", str(out)]) == 0
    status = json.loads(out.read_text())["rfmap"]
    assert status["status"] == "ok" and status["max_error"] <= 0.01
    assert "under the judged share" in capsys.readouterr().out
    rc = main(["cartogram", str(src), "--value", "pop", "--method", "flow", "--n", "16", "--max-passes", "1",
               "--tol", "1e-6", "--out", str(out)])
    assert rc == 1 and json.loads(out.read_text())["rfmap"]["status"] == "failed"
    assert main(["cartogram", str(src), "--value", "nope", "--method", "flow", "--out", str(tmp_path / "x.json")]) == 2
    assert not (tmp_path / "x.json").exists()


def test_repair_overlaps_cuts_slivers_from_the_region_above_its_target():
    """Two unit squares overlapping by a sliver of 1e-6 of the total area: the sliver is cut from the one further
    above its target area, after which the two share a border and keep their other areas; an overlap larger than
    REPAIR_OVERLAP stays unless it is a sliver (thin) within REPAIR_SLIVER."""
    from rfmap.cartogram.metrics import REPAIR_OVERLAP, REPAIR_SLIVER, repair_overlaps

    a = shapely.box(0.0, 0.0, 1.0, 1.0)
    b = shapely.box(1.0 - 2e-6, 0.0, 2.0, 1.0)
    out, cut = repair_overlaps(np.array([a, b], dtype=object), np.array([1.0, 2.0]))
    assert cut == [(0, 1)]  # a holds half b's value with about b's area: further above its target
    assert shapely.area(shapely.intersection(out[0], out[1])) == 0.0
    assert shapely.area(out[0]) == pytest.approx(1.0 - 2e-6, rel=1e-12) and shapely.area(out[1]) == shapely.area(b)
    # a strip holding 2 REPAIR_OVERLAP of the total is thin: cut; one holding 4 REPAIR_SLIVER is not
    for width, cuts in ((4 * REPAIR_OVERLAP, 1), (8 * REPAIR_SLIVER, 0)):
        wide = shapely.box(1.0 - width, 0.0, 2.0, 1.0)
        out, cut = repair_overlaps(np.array([a, wide], dtype=object), np.array([1.0, 2.0]))
        assert len(cut) == cuts and (shapely.area(shapely.intersection(out[0], out[1])) > 0) == (cuts == 0)
    # a square overlap (not thin) holding 2 REPAIR_OVERLAP of the total stays
    side = (4 * REPAIR_OVERLAP) ** 0.5
    corner = shapely.box(1.0 - side, 1.0 - side, 2.0 - side, 2.0 - side)
    out, cut = repair_overlaps(np.array([a, corner], dtype=object), np.array([1.0, 2.0]))
    assert cut == [] and shapely.area(shapely.intersection(out[0], out[1])) > 0
    # unless one of the two is under the judged share (drawn at a raised size, not at its value)
    out, cut = repair_overlaps(np.array([a, corner], dtype=object), np.array([1.0, 1e-6]))
    assert len(cut) == 1 and shapely.area(shapely.intersection(out[0], out[1])) == 0.0


def test_timeout_stops_the_passes_and_the_command_says_so(tmp_path, capsys):
    """A time limit already spent lets the first pass run and no other: the best pass is returned, flagged
    ``timed_out``, and, above the tolerance, named as a problem; the command writes the map flagged and exits 1.
    Without a limit the same map reaches the tolerance; a limit that is not a positive number is bad input."""
    from rfmap.cli import main

    fc = squares([1, 50, 2, 400, 3, 7, 1, 90, 5])
    free = cartogram(fc, "pop", n=48)
    assert free.info["iterations"] > 1 and not free.info["timed_out"] and not free.problems()
    c = cartogram(fc, "pop", n=48, timeout=1e-9)
    assert c.info["iterations"] == 1 and c.info["timed_out"]
    assert any("time limit" in p for p in c.problems()), c.problems()
    for bad in (0, -1.0, float("nan"), float("inf"), True, "1"):
        with pytest.raises(ValueError, match="timeout"):
            cartogram(fc, "pop", n=48, timeout=bad)
    src, out = tmp_path / "in.geojson", tmp_path / "out.geojson"
    src.write_text(json.dumps(fc))
    rc = main(["cartogram", str(src), "--value", "pop", "--n", "48", "--timeout", "1e-9", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 1 and "time limit" in err and json.loads(out.read_text())["rfmap"]["status"] == "failed"
    rc = main(["cartogram", str(src), "--value", "pop", "--timeout", "0", "--out", str(tmp_path / "x.geojson")])
    assert rc == 2 and "timeout" in capsys.readouterr().err and not (tmp_path / "x.geojson").exists()


@pytest.mark.parametrize("bad", [{"rtol": 0.0}, {"blur": -1.0}, {"first_step": 0.0}, {"first_step": 1.5},
                                 {"max_steps": 0}, {"rtol": float("nan")}])
def test_flow_options_refuse_what_cannot_run(bad):
    from rfmap.solvers.cartoflow import CartoFlowOptions

    with pytest.raises(ValueError, match="CartoFlowOptions need"):
        CartoFlowOptions(**bad)


def test_a_later_pass_takes_few_steps_from_a_whole_first_step():
    """The first step spans the whole flow and the step control shortens it: a nearly uniform density (a late
    cartogram pass) is carried in a few steps, to the same points as from a short first step within the step
    tolerance."""
    from rfmap.solvers.cartoflow import CartoFlowOptions

    n = 65
    t = np.linspace(0, 1, n)
    x, y = np.meshgrid(t, t, indexing="ij")
    dens = 1.0 + 0.02 * np.cos(np.pi * x) * np.cos(2 * np.pi * y)
    pts = np.random.default_rng(1).uniform(0.05, 0.95, size=(300, 2))
    whole = flow_square(dens, points=pts)
    short = flow_square(dens, CartoFlowOptions(first_step=1e-2), points=pts)
    assert whole.info["evaluations"] <= 4 < short.info["evaluations"]
    assert np.abs(whole.mapped_points - short.mapped_points).max() < 0.2 / (n - 1)


def test_edges_are_split_to_cells_of_at_most_the_split_raster(monkeypatch):
    """Passes on rasters finer than :data:`rfmap.cartogram.resize.SPLIT_MAX_N` split stretched edges to that raster's
    cells, not theirs: the world at N = 96 refined up to 384 keeps fewer vertices with the split raster at 96 than
    with none, and both come within 1 %, valid and without overlaps."""
    import rfmap.cartogram.resize as resize

    counts = {}
    for cap in (96, 4096):
        monkeypatch.setattr(resize, "SPLIT_MAX_N", cap)
        c = cartogram(world_countries(), "pop_est", n=96, method="flow", max_n=384)
        m = c.metrics()
        assert m.max_error <= 0.01 and m.topology_ok, (cap, m, c.info["grids"])
        assert max(c.info["grids"]) > 96  # refined beyond the split raster
        counts[cap] = shapely.get_num_coordinates(c.mapped).sum()
    assert counts[96] < 0.9 * counts[4096], counts


def test_map_and_cartogram_passes_share_one_velocity():
    r"""The map solver's pass (float32 ``grid_sample``) and the cartogram pass (float32 tables by ``numpy.fft``,
    read by :func:`rfmap.core.mesh.multilinear`) evaluate one :class:`rfmap.solvers.spectral.FlowVelocity` of the
    same tables: on a density of a few cosine modes they agree to the float32 tables' precision at random points and
    times, and at :math:`t = 1` the velocity is the float64 flux over the box mean :math:`\bar\rho`, the formula's
    denominator, to that precision too."""
    from rfmap.solvers import cartoflow, flow, spectral
    n = 33
    x = np.linspace(0.0, 1.0, n)
    dens = 2.0 + np.cos(np.pi * x)[:, None] * np.cos(2 * np.pi * x)[None, :] + 0.5 * np.cos(3 * np.pi * x)[:, None]
    cart = cartoflow._velocity(dens)
    mapped = flow._FlowPass(dens).velocity
    assert isinstance(cart, spectral.FlowVelocity) and isinstance(mapped, spectral.FlowVelocity)
    pts = np.random.default_rng(0).random((200, 2))
    for t in (0.0, 0.3, 1.0):
        a, b = cart(t, pts), mapped(t, pts)
        assert a.dtype == b.dtype == np.float64
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-6 * np.abs(a).max())
    flux = spectral.flow_planes(dens)[:2]
    nodes = np.stack(np.meshgrid(x, x, indexing="ij"), -1).reshape(-1, 2)
    want = np.moveaxis(flux, 0, -1).reshape(-1, 2) / spectral.box_mean(dens)
    np.testing.assert_allclose(cart(1.0, nodes), want, rtol=0, atol=1e-6 * np.abs(want).max())
    assert cart.evaluations == 4 and mapped.evaluations == 3


def test_large_table_transforms_skip_the_scipy_fft_import_and_give_its_numbers():
    """A table transformed by scipy's pocketfft (a side of ``SCIPY_SIDE`` or more) does so without importing
    ``scipy.fft`` (:func:`rfmap.solvers.cosine.type1_transforms`: half a second of a cartogram command), and
    its
    DCT-I and DST-I along both axes equal ``scipy.fft``'s bit for bit."""
    code = """
import sys
import numpy as np
from rfmap.solvers.cosine import CosineTransforms
ct = CosineTransforms(17, use_scipy=True)
x = np.random.default_rng(3).normal(size=(17, 17))
got = [ct.dct(x, 0), ct.dct(x, 1), ct.dst(x[1:-1], 0), ct.dst(x[:, 1:-1], 1)]
assert 'scipy.fft' not in sys.modules, 'scipy.fft'
import scipy.fft
want = [scipy.fft.dct(x, type=1, axis=0), scipy.fft.dct(x, type=1, axis=1),
        scipy.fft.dst(x[1:-1], type=1, axis=0), scipy.fft.dst(x[:, 1:-1], type=1, axis=1)]
assert all(np.array_equal(g, w) for g, w in zip(got, want)), 'numbers'
"""
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
