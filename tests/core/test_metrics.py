"""Map quality metrics in the paper's conventions (rfmap.core.metrics) and the MapResult container (rfmap.core.result)."""
import json
import math

import numpy as np
import pytest
import torch

from rfmap.fields import BELTRAMI_MAPS, sample_density
from rfmap.core.geometry import signed_measures
from rfmap.core.mesh import grid_mesh
from rfmap.core.metrics import MapMetrics, compute_metrics, density_std, element_population
from rfmap.core.result import MapResult, load_result

MESH = grid_mesh(11, 2)


def _smooth(p, eps=0.04):
    x, y = p[:, 0], p[:, 1]
    return np.stack([x + eps * np.sin(np.pi * x) * np.sin(2 * np.pi * y),
                     y + eps * np.sin(2 * np.pi * x) * np.sin(np.pi * y)], -1)


def test_identity_map_metrics():
    dens = sample_density("sin-cos", 11).reshape(-1)
    m = compute_metrics(MESH.points, MESH.points, MESH.elements, density=dens, time=0.5)
    assert m.std_rho_orig == pytest.approx(m.std_rho_map, abs=1e-14)
    assert m.min_jacobian == pytest.approx(1.0, abs=1e-14)
    assert m.n_flipped == 0
    assert m.max_mu == pytest.approx(0.0, abs=1e-14) and m.mean_mu == pytest.approx(0.0, abs=1e-14)
    assert m.time == 0.5
    assert m.mean_dd is None and m.mean_dmu is None


def test_uniform_density_has_zero_std():
    dens = np.ones(MESH.points.shape[0])
    m = compute_metrics(MESH.points, MESH.points, MESH.elements, density=dens)
    assert m.std_rho_orig == pytest.approx(0.0, abs=1e-12)


def test_std_rho_by_hand():
    """rho = population / measure, normalised by its mean, std with ddof = 1."""
    dens = sample_density("ring", 11).reshape(-1)
    mapped = _smooth(MESH.points)
    def areas(p):
        e = p[MESH.elements]
        u, v = e[:, 1] - e[:, 0], e[:, 2] - e[:, 0]
        return (u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]) / 2

    ref_area, map_area = areas(MESH.points), areas(mapped)
    pop = dens[MESH.elements].mean(1) * ref_area
    m = compute_metrics(MESH.points, mapped, MESH.elements, density=dens)
    for area, value in [(ref_area, m.std_rho_orig), (map_area, m.std_rho_map)]:
        rho = pop / area
        assert value == pytest.approx(np.std(rho / rho.mean(), ddof=1), rel=1e-12)
    assert m.min_jacobian == pytest.approx((map_area / ref_area).min(), rel=1e-12)


def test_uniform_scaling_changes_jacobian_not_density_spread():
    dens = sample_density("exp-log", 11).reshape(-1)
    m = compute_metrics(MESH.points, 3.0 * MESH.points, MESH.elements, density=dens)
    assert m.min_jacobian == pytest.approx(9.0)
    assert m.std_rho_map == pytest.approx(m.std_rho_orig, rel=1e-12)
    assert m.max_mu == pytest.approx(0.0, abs=1e-12)


def test_flipped_elements_are_counted():
    mapped = MESH.points.copy()
    centre = 5 * 11 + 5  # vertex (0.5, 0.5)
    mapped[centre] += [0.15, 0.15]  # pushed beyond its neighbours' diagonal
    m = compute_metrics(MESH.points, mapped, MESH.elements)
    dets = signed_measures(torch.as_tensor(mapped), torch.as_tensor(MESH.elements)) / (0.5 * 0.1**2)
    assert m.n_flipped == int((dets <= 0).sum()) > 0
    assert m.min_jacobian <= 0
    assert m.max_mu >= 1.0  # a flipped triangle has |mu| >= 1


def test_mean_dd_and_mean_dmu():
    mapped = MESH.points + np.array([0.03, -0.04])
    m = compute_metrics(MESH.points, mapped, MESH.elements, exact_points=MESH.points,
                        mu_ref=np.full(MESH.elements.shape[0], 0.1 + 0.0j))
    assert m.mean_dd == pytest.approx(0.05, rel=1e-12)
    assert m.mean_dmu == pytest.approx(0.1, rel=1e-12)


def test_given_mu_is_used():
    mu = np.full(MESH.elements.shape[0], 0.3j)
    mu[0] = 0.6
    m = compute_metrics(MESH.points, MESH.points, MESH.elements, mu=mu)
    assert m.max_mu == pytest.approx(0.6)
    assert m.mean_mu == pytest.approx((0.6 + 0.3 * (mu.size - 1)) / mu.size)


def test_exact_test_map_metrics():
    f = BELTRAMI_MAPS["T1"]
    mapped = f(MESH.points)
    m = compute_metrics(MESH.points, mapped, MESH.elements, exact_points=mapped)
    assert m.mean_dd == 0.0
    assert m.n_flipped == 0 and 0 < m.max_mu < 1


def test_3d_metrics_have_no_mu():
    mesh = grid_mesh(4, 3)
    dens = sample_density("sin-cos-3d", 4).reshape(-1)
    m = compute_metrics(mesh.points, 2 * mesh.points, mesh.elements, density=dens)
    assert m.max_mu is None and m.mean_mu is None
    assert m.min_jacobian == pytest.approx(8.0)
    assert m.std_rho_map == pytest.approx(m.std_rho_orig, rel=1e-12)


def test_element_population_and_density_std():
    dens = sample_density("sin-cos", 11).reshape(-1)
    pop = element_population(MESH.points, MESH.elements, dens)
    assert pop.shape == (MESH.elements.shape[0],)
    assert float(pop.sum()) == pytest.approx(1.0, abs=1e-12)
    meas = signed_measures(torch.as_tensor(MESH.points), torch.as_tensor(MESH.elements))
    assert density_std(meas * 7.0, meas) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("flip", [False, True], ids=["positive", "some-negative"])
def test_density_std_is_the_sample_std_of_the_normalised_density(flip):
    """Std(rho / mean(rho)) with ddof = 1, against numpy's two-pass std, to 1e-12 relative; a buffer gives the
    same value; measures of either sign (folded elements) included."""
    rng = np.random.default_rng(5)
    pop = torch.as_tensor(rng.uniform(0.5, 2.0, 10_000))
    meas = torch.as_tensor(rng.uniform(0.8, 1.2, 10_000))
    if flip:
        meas[::7] *= -0.01
    rho = (pop / meas).numpy()
    want = float(np.std(rho / rho.mean(), ddof=1))
    assert density_std(pop, meas) == pytest.approx(want, rel=1e-12)
    assert density_std(pop, meas, out=torch.empty_like(pop)) == pytest.approx(want, rel=1e-12)


def test_bad_input():
    with pytest.raises(ValueError):
        compute_metrics(MESH.points, MESH.points[:-1], MESH.elements)
    with pytest.raises(ValueError):
        compute_metrics(MESH.points, MESH.points, MESH.elements, density=np.ones(5))


def test_map_metrics_container():
    m = MapMetrics(std_rho_orig=0.5, n_flipped=2, time=1.25)
    assert m.to_dict() == {"std_rho_orig": 0.5, "n_flipped": 2, "time": 1.25}
    assert set(m.to_dict(drop_none=False)) == set(MapMetrics.columns())
    assert json.loads(m.to_json()) == m.to_dict()
    assert m.row() == "| 0.5 | 2 | 1.25 |"
    assert m.row(["std_rho_orig", "max_mu"]) == "| 0.5 | — |"
    assert "n_flipped=2" in str(m)
    # a map collapsing everything to a point: every element is degenerate, mu is undefined (NaN), no exception
    collapsed = compute_metrics(MESH.points, np.zeros_like(MESH.points), MESH.elements)
    assert collapsed.min_jacobian == 0.0 and collapsed.n_flipped == MESH.elements.shape[0]
    assert math.isnan(collapsed.max_mu) and math.isnan(collapsed.mean_mu)


def test_map_result_roundtrip(tmp_path):
    dens = sample_density("sin-cos", 11)
    mapped = _smooth(MESH.points)
    r = MapResult(MESH.points, mapped, MESH.elements, dens.reshape(-1), kind="density", time=0.25)
    assert r.dim == 2
    np.testing.assert_allclose(r.displacement, mapped - MESH.points)
    path = tmp_path / "sub" / "map.npz"
    r.save(path)
    back = load_result(path)
    np.testing.assert_array_equal(back.mapped_points, mapped)
    np.testing.assert_array_equal(back.elements, MESH.elements)
    assert back.kind == "density" and back.time == 0.25
    assert back.metrics().to_dict() == pytest.approx(r.metrics().to_dict())
    assert sorted(f.name for f in (tmp_path / "sub").iterdir()) == ["map.npz"]  # no temporary file left
    mu = np.zeros(MESH.elements.shape[0], dtype=complex)
    rb = MapResult(MESH.points, mapped, MESH.elements, mu, kind="beltrami")
    assert rb.metrics(mu_ref=mu).std_rho_orig is None


def test_load_result_rejects_bad_files(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file")
    with pytest.raises(ValueError):
        load_result(bad)
    partial = tmp_path / "partial.npz"
    np.savez(partial, ref_points=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="missing"):
        load_result(partial)
    with pytest.raises(ValueError):
        load_result(tmp_path / "does-not-exist.npz")
    whole = tmp_path / "whole.npz"
    MapResult(MESH.points, MESH.points, MESH.elements, np.ones(len(MESH.points))).save(whole)
    raw = whole.read_bytes()
    for cut in (len(raw) // 2, len(raw) - 30):  # truncated archives: a bad zip or a damaged member
        damaged = tmp_path / f"cut{cut}.npz"
        damaged.write_bytes(raw[:cut])
        with pytest.raises(ValueError, match="cannot read"):
            load_result(damaged)


@pytest.mark.parametrize("dim,n", [(2, 13), (3, 7)])
def test_grid_fast_path_equals_the_general_path(dim, n):
    """On the grid mesh the measures come from strided kernels; permuting the elements (not a grid mesh any more)
    takes the gather path. Every metric is order-free, so both must agree to 1e-12, also for a folding map."""
    from rfmap.core.mesh import grid_size

    mesh = grid_mesh(n, dim)
    rng = np.random.default_rng(dim)
    mapped = mesh.points + 0.08 * rng.standard_normal(mesh.points.shape)  # folds some elements
    dens = rng.uniform(0.5, 2.0, len(mesh.points))
    perm = rng.permutation(len(mesh.elements))
    assert grid_size(mesh.points, mesh.elements) == n
    assert grid_size(mesh.points, mesh.elements[perm]) is None
    assert grid_size(mesh.points[::-1], mesh.elements) is None
    fast = compute_metrics(mesh.points, mapped, mesh.elements, density=dens).to_dict()
    slow = compute_metrics(mesh.points, mapped, mesh.elements[perm], density=dens).to_dict()
    assert fast["n_flipped"] > 0
    for k, v in fast.items():
        if isinstance(v, float) and math.isfinite(v):
            assert v == pytest.approx(slow[k], rel=1e-12, abs=1e-15), k
        else:
            assert v == slow[k] or (v != v and slow[k] != slow[k]), k


# ----------------------------------------------------------------------------------------------- residual scales
def test_residual_scales_split_a_smooth_residual_from_element_noise():
    from rfmap.core.metrics import residual_scales
    from rfmap.core.mesh import grid_mesh

    m = grid_mesh(41, 2)
    x = m.points
    uniform = np.ones(len(x))
    exact = residual_scales(x, x, m.elements, uniform)
    assert exact["std"] < 1e-12 and exact["smooth"] < 1e-12
    # identity map of a smooth density: the residual is the density itself, smooth at the cell scale
    smooth = 1.0 + 0.3 * np.sin(np.pi * x[:, 0]) * np.cos(np.pi * x[:, 1])
    s = residual_scales(x, x, m.elements, smooth)
    assert s["std"] == pytest.approx(compute_metrics(x, x, m.elements, density=smooth).std_rho_map, rel=1e-12)
    assert s["element_fraction"] < 0.02
    # vertices jittered by a tenth of a cell under a uniform density: the residual alternates between elements
    rng = np.random.default_rng(0)
    inner = ~m.boundary_mask()
    y = x.copy()
    y[inner] += 0.1 / 40 * rng.uniform(-1, 1, size=(inner.sum(), 2))
    s = residual_scales(x, y, m.elements, uniform)
    assert s["std"] > 0.05 and s["element_fraction"] > 0.7
    with pytest.raises(ValueError, match="folded"):
        residual_scales(x, np.stack([1 - x[:, 0], x[:, 1]], 1), m.elements, uniform)  # a mirror image


def _wall_fields(d: int, n: int):
    """A gradient g (no flux through the walls) and a divergence-free r, both vanishing normally on the walls, at
    the vertices of the n-grid, and their exact L2 norms squared over the unit square/cube."""
    from rfmap.core.mesh import grid_points

    x = grid_points(n, d)
    pi, s, c = np.pi, np.sin, np.cos
    if d == 2:
        g = np.stack([-pi * s(pi * x[:, 0]) * c(2 * pi * x[:, 1]) - 0.9 * pi * s(3 * pi * x[:, 0]),
                      -2 * pi * c(pi * x[:, 0]) * s(2 * pi * x[:, 1])], 1)  # grad(cos(pi x)cos(2pi y) + .3cos(3pi x))
        r = np.stack([pi * s(pi * x[:, 0]) * c(pi * x[:, 1]), -pi * c(pi * x[:, 0]) * s(pi * x[:, 1])], 1)
        return x, g, r, pi**2 * (0.25 + 0.405 + 1.0), pi**2 * 0.5
    z = c(pi * x[:, 2])  # g = grad(cos(pi x) cos(2 pi y) cos(pi z))
    g = np.stack([-pi * s(pi * x[:, 0]) * c(2 * pi * x[:, 1]) * z, -2 * pi * c(pi * x[:, 0]) * s(2 * pi * x[:, 1]) * z,
                  -pi * c(pi * x[:, 0]) * c(2 * pi * x[:, 1]) * s(pi * x[:, 2])], 1)
    r = np.stack([pi * s(pi * x[:, 0]) * c(pi * x[:, 1]) * z, -pi * c(pi * x[:, 0]) * s(pi * x[:, 1]) * z, 0 * z], 1)
    return x, g, r, pi**2 * (1 + 4 + 1) / 8, pi**2 * (1 + 1) / 8


@pytest.mark.parametrize("d,n", [(2, 33), (3, 17)])
def test_rotational_share_of_exact_fields(d, n):
    """0 for a gradient (to round-off), 1 for a divergence-free field, 0 for the identity, the exact L2 ratio
    ||r|| / ||g + r|| for a sum (the two parts are orthogonal), and independent of the displacement's size."""
    from rfmap.core.metrics import rotational_share

    x, g, r, g2, r2 = _wall_fields(d, n)
    assert rotational_share(x, x + 0.01 * g) < 1e-12
    assert rotational_share(x, x + 0.01 * r) == pytest.approx(1.0, abs=1e-12)
    assert rotational_share(x, x) == 0.0
    mixed = rotational_share(x, x + 0.01 * (g + r))
    assert mixed == pytest.approx(np.sqrt(r2 / (g2 + r2)), rel=1e-10)
    assert rotational_share(x, x + 0.002 * (g + r)) == pytest.approx(mixed, rel=1e-12)


def test_rotational_share_keeps_nodal_gradients_of_the_highest_cosine():
    """The gradient of cos(pi (N-1) x) cos(pi y) has the nodal samples (0, -pi cos(pi (N-1) x) sin(pi y)): kept
    whole, as a gradient."""
    from rfmap.core.mesh import grid_points
    from rfmap.core.metrics import rotational_share

    n = 17
    x = grid_points(n, 2)
    g = np.stack([np.zeros(len(x)), -np.pi * np.cos(np.pi * (n - 1) * x[:, 0]) * np.sin(np.pi * x[:, 1])], 1)
    assert rotational_share(x, x + 1e-3 * g) < 1e-12


def test_rotational_share_refuses_bad_maps():
    from rfmap.core.mesh import grid_points
    from rfmap.core.metrics import rotational_share

    x = grid_points(9, 2)
    with pytest.raises(ValueError, match="walls"):
        rotational_share(x, x + 0.01)  # a shift moves the boundary vertices off their walls
    with pytest.raises(ValueError, match="grid_points"):
        rotational_share(x[::-1], x[::-1])
    with pytest.raises(ValueError, match="shape"):
        rotational_share(x, x[:-1])
    bad = x.copy()
    bad[40, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        rotational_share(x, bad)


@pytest.mark.parametrize("dim,n", [(2, 7), (3, 5)])
def test_element_population_on_the_grid_path_equals_the_element_list(dim, n):
    """``grid_n`` takes the vertex means from strided views: the same populations to 1e-15."""
    from rfmap.core.mesh import grid_mesh

    mesh = grid_mesh(n, dim)
    dens = np.random.default_rng(n).uniform(0.5, 2.0, n**dim)
    a = element_population(mesh.points, mesh.elements, dens)
    b = element_population(mesh.points, mesh.elements, dens, grid_n=n)
    torch.testing.assert_close(a, b, rtol=0, atol=1e-15)


def test_residual_scales_weights_each_vertex_mean_by_the_reference_measures():
    r"""Two triangles of areas 1/2 and 5/2 sharing the edge BC, identity map, density 1 at A, B, C and 4 at D:
    element densities 1 and 2 (mean 3/2), residuals r = -1/3 and 1/3.  The smooth part at B and C is the
    measure-weighted mean (1/2 (-1/3) + 5/2 (1/3)) / 3 = 2/9 (a plain mean of the two elements would give 0), at A
    and D the one element's residual; ``smooth`` is their standard deviation (ddof 0), ``std`` that of r (ddof 1)."""
    from rfmap.core.metrics import residual_scales

    pts = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [3.0, 3.0]])  # A, B, C, D
    el = np.array([[0, 1, 2], [1, 3, 2]])
    s = residual_scales(pts, pts, el, np.array([1.0, 1.0, 1.0, 4.0]))
    smooth = np.array([-1 / 3, 2 / 9, 2 / 9, 1 / 3])
    std = math.sqrt(2 / 9)  # of (-1/3, 1/3), ddof 1
    assert s["std"] == pytest.approx(std, rel=1e-12)
    assert s["smooth"] == pytest.approx(smooth.std(), rel=1e-12)
    assert s["element_fraction"] == pytest.approx(1 - smooth.std() ** 2 / std**2, rel=1e-12)


def test_residual_parts_are_the_residual_and_its_vertex_means():
    """``residual_parts`` returns r_e = rho~_e - 1 (mean 0 up to rounding) and, at each vertex, the
    reference-measure-weighted mean of r over the elements around it; ``residual_scales`` is their statistics."""
    from rfmap.core.metrics import residual_parts, residual_scales
    from rfmap.core.mesh import grid_mesh

    m = grid_mesh(9, 2)
    x = m.points
    rng = np.random.default_rng(1)
    inner = ~m.boundary_mask()
    y = x.copy()
    y[inner] += 0.1 / 8 * rng.uniform(-1, 1, size=(inner.sum(), 2))
    dens = 1.0 + 0.5 * x[:, 0]
    r, smooth = residual_parts(x, y, m.elements, dens)
    assert r.shape == (len(m.elements),) and smooth.shape == (len(x),)
    rho = compute_metrics(x, y, m.elements, density=dens)
    assert r.std(ddof=1) == pytest.approx(rho.std_rho_map, rel=1e-12)
    v = 40  # an interior vertex: the uniform grid's reference measures are all equal, so a plain mean
    around = np.flatnonzero((m.elements == v).any(1))
    assert smooth[v] == pytest.approx(r[around].mean(), rel=1e-12)
    s = residual_scales(x, y, m.elements, dens)
    assert s["smooth"] == pytest.approx(smooth.std(), rel=1e-12)


def test_block_std_pools_cells_of_the_grid():
    """With one cell per block the blocks are the grid's squares; a map of the (2N - 1)-grid pooled in blocks of
    2 x 2 cells is measured on the squares of the N-grid: for a density that is linear in x and the identity map,
    the block densities are the densities of the N-grid's squares."""
    from rfmap.core.metrics import block_std

    def identity(n):
        m = grid_mesh(n, 2)
        dens = 1.0 + m.points[:, 0]
        return MapResult(m.points, m.points.copy(), m.elements, dens, kind="density")

    coarse, fine = identity(5), identity(9)
    assert block_std(fine, 2) == pytest.approx(block_std(coarse, 1), rel=1e-12)
    # the squares' densities: 1 + the x of their centres, constant in y
    rho = 1.0 + (np.arange(4) + 0.5) / 4
    rho = np.repeat(rho, 4)
    assert block_std(coarse, 1) == pytest.approx(rho.std(ddof=1) / rho.mean(), rel=1e-12)
    with pytest.raises(ValueError):
        block_std(coarse, 3)
