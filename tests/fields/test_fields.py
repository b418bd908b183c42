"""Test densities, test maps, preprocessing and random training fields (rfmap.fields)."""
import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from rfmap.fields import (
    BELTRAMI_MAPS,
    DENSITIES,
    RECT_PEAK_BOX,
    BeltramiMap,
    DensityField,
    RandomBeltrami,
    RandomBeltramiConfig,
    RandomDensity,
    RandomDensityConfig,
    RandomMap,
    check_density,
    check_mu,
    field_names,
    get_field,
    preprocess_density,
    random_beltrami,
    random_boundary_map,
    random_density,
    sample_density,
)
from rfmap.core.geometry import beltrami_coefficient, signed_measures
from rfmap.core.mesh import grid_mesh, grid_points, jittered_points, vertex_weights
from rfmap.core.metrics import compute_metrics

# Std(rho~_orig) of the test densities as published in the paper's tables (tab:population_test,
# tab:resolution_test, tab:3d_population_test): the input statistic, independent of any map.
PUBLISHED_STD_ORIG = [
    ("sin-cos", 51, 0.453812),
    ("exp-log", 51, 0.397409),
    ("ring", 51, 0.349701),
    ("multi-freq", 32, 0.391159),
    ("multi-freq", 64, 0.400335),
    ("multi-freq", 128, 0.402907),
    ("multi-freq", 256, 0.403503),
    ("sin-cos-3d", 48, 0.319948),
    ("shell-3d", 48, 0.327913),
]


def _std_orig(name: str, n: int) -> float:
    f = get_field(name)
    mesh = grid_mesh(n, f.dim)
    dens = sample_density(name, n).reshape(-1)
    return compute_metrics(mesh.points, mesh.points, mesh.elements, density=dens).std_rho_orig


# ----------------------------------------------------------------------------------------------- test densities
@pytest.mark.parametrize("name,n,published", PUBLISHED_STD_ORIG)
def test_published_input_statistic(name, n, published):
    assert _std_orig(name, n) == pytest.approx(published, abs=1e-6)


def test_registry():
    assert set(field_names("density", 2)) == {"sin-cos", "exp-log", "rect-peak", "ring", "multi-freq"}
    assert set(field_names("density", 3)) == {"sin-cos-3d", "shell-3d", "octant-3d", "prism-peak-3d",
                                              "multi-freq-3d"}
    assert set(field_names("beltrami")) == {"T1", "T2", "T3", "T4", "T1-res"}
    assert field_names("beltrami", 3) == []
    for name in field_names():
        f = get_field(name)
        assert f.name == name
        assert isinstance(f, (DensityField, BeltramiMap))
    assert all(f.dim == 2 for f in BELTRAMI_MAPS.values())


def test_density_formulas_at_points():
    p = np.array([[0.25, 0.0], [0.1, 0.7], [0.5, 0.5]])
    x, y = p[:, 0], p[:, 1]
    np.testing.assert_allclose(DENSITIES["sin-cos"](p), 2 + np.sin(2 * np.pi * x) * np.cos(2 * np.pi * y))
    np.testing.assert_allclose(DENSITIES["exp-log"](p),
                               2 + np.sin(2 * np.pi * np.exp(x)) * np.cos(np.pi * np.log(2 * y + 0.1)))
    np.testing.assert_allclose(DENSITIES["multi-freq"](p), 2 + np.sin(4 * np.pi * x) * np.cos(4 * np.pi * y)
                               + 0.3 * np.sin(6 * np.pi * x))
    r = np.hypot(x - 0.5, y - 0.5)
    np.testing.assert_allclose(DENSITIES["ring"](p), np.exp(-((r - 1) ** 2) / 0.5))
    q = np.array([[0.25, 0.5, 0.75]])
    np.testing.assert_allclose(DENSITIES["sin-cos-3d"](q), 2 + np.sin(np.pi / 2) * np.cos(np.pi) * np.sin(1.5 * np.pi))


def test_rect_peak_is_sin_cos_plus_a_box():
    (x0, x1), (y0, y1), height = RECT_PEAK_BOX
    inside = np.array([[(x0 + x1) / 2, (y0 + y1) / 2]])
    outside = np.array([[0.1, 0.9]])
    base = DENSITIES["sin-cos"]
    assert DENSITIES["rect-peak"](inside)[0] == pytest.approx(base(inside)[0] + height)
    assert DENSITIES["rect-peak"](outside)[0] == pytest.approx(base(outside)[0])


def test_shell_3d_is_nonnegative_and_vanishes_at_the_corners():
    f = DENSITIES["shell-3d"]
    assert f(np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])) == pytest.approx([0.0, 0.0], abs=1e-12)
    assert (f(grid_points(9, 3)) >= -1e-12).all()


def test_octant_3d_levels():
    f = DENSITIES["octant-3d"]
    # near the corners the smooth blend approaches the octant levels 1..8
    assert f(np.array([[0.0, 0.0, 0.0]]))[0] == pytest.approx(1.0, abs=0.1)
    assert f(np.array([[1.0, 1.0, 1.0]]))[0] == pytest.approx(8.0, abs=0.1)
    assert f(np.array([[0.5, 0.5, 0.5]]))[0] == pytest.approx(4.5, abs=1e-12)


# ----------------------------------------------------------------------------------------------- preprocessing
@pytest.mark.parametrize("dim,n", [(2, 3), (2, 17), (3, 3), (3, 6)])
def test_vertex_weights_integrate_pl_functions_exactly(dim, n):
    mesh = grid_mesh(n, dim)
    w = vertex_weights(mesh.points, mesh.elements)
    assert (w > 0).all()
    assert w.sum() == pytest.approx(1.0, abs=1e-12)
    # the integral of an affine function over the unit square / cube is its value at the centre
    for axis in range(dim):
        assert (w * mesh.points[:, axis]).sum() == pytest.approx(0.5, abs=1e-12)


@pytest.mark.parametrize("name,n", [("sin-cos", 21), ("ring", 33), ("exp-log", 8), ("sin-cos-3d", 7),
                                    ("octant-3d", 5)])
def test_preprocessing_shift_and_unit_mass(name, n):
    f = get_field(name)
    raw = f.sample(n, preprocess=False)
    p = f.sample(n)
    assert p.shape == (n,) * f.dim
    mesh = grid_mesh(n, f.dim)
    w = vertex_weights(mesh.points, mesh.elements).reshape(p.shape)
    mass_shifted = (w * (raw - raw.min() + 0.1)).sum()
    assert (w * p).sum() == pytest.approx(1.0, abs=1e-12)
    assert p.min() == pytest.approx(0.1 / mass_shifted, rel=1e-12)
    np.testing.assert_allclose(p, (raw - raw.min() + 0.1) / mass_shifted, rtol=1e-12)


def test_preprocess_density_is_shift_invariant_and_accepts_weights():
    rng = np.random.default_rng(0)
    v = rng.normal(size=(9, 9))
    np.testing.assert_allclose(preprocess_density(v), preprocess_density(v + 5.0), rtol=1e-12)
    mesh = grid_mesh(9, 2)
    w = vertex_weights(mesh.points, mesh.elements)
    np.testing.assert_allclose(preprocess_density(v.reshape(-1), weights=w), preprocess_density(v).reshape(-1),
                               rtol=1e-12)
    assert (preprocess_density(v, floor=0.5) > 0).all()


def test_population_of_a_preprocessed_density_is_one():
    from rfmap.core.metrics import element_population

    mesh = grid_mesh(13, 2)
    pop = element_population(mesh.points, mesh.elements, sample_density("exp-log", 13).reshape(-1))
    assert float(pop.sum()) == pytest.approx(1.0, abs=1e-12)


# ----------------------------------------------------------------------------------------------- test maps
@pytest.mark.parametrize("name", list(BELTRAMI_MAPS))
def test_test_maps_fix_the_boundary(name):
    f = BELTRAMI_MAPS[name]
    t = np.linspace(0, 1, 41)
    zero, one = np.zeros_like(t), np.ones_like(t)
    boundary = np.concatenate([np.stack(s, -1) for s in [(t, zero), (t, one), (zero, t), (one, t)]])
    np.testing.assert_allclose(f(boundary), boundary, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", list(BELTRAMI_MAPS))
def test_test_maps_are_quasiconformal(name):
    f = BELTRAMI_MAPS[name]
    x = grid_points(41, 2)
    mu = f.mu(x)
    assert mu.dtype == np.complex128 and mu.shape == (x.shape[0],)
    assert np.abs(mu).max() < 0.9
    assert (np.linalg.det(f.jacobian(x)) > 0).all()


def test_t1_jacobian_matches_its_formula():
    f = BELTRAMI_MAPS["T1"]
    a = b = 0.08
    rng = np.random.default_rng(0)
    x = rng.random((50, 2))
    X, Y = x[:, 0], x[:, 1]
    pi = np.pi
    J = np.empty((50, 2, 2))
    J[:, 0, 0] = 1 + a * pi * np.cos(pi * X) * np.sin(2 * pi * Y)
    J[:, 0, 1] = 2 * a * pi * np.sin(pi * X) * np.cos(2 * pi * Y)
    J[:, 1, 0] = 2 * b * pi * np.cos(2 * pi * X) * np.sin(pi * Y)
    J[:, 1, 1] = 1 + b * pi * np.sin(2 * pi * X) * np.cos(pi * Y)
    np.testing.assert_allclose(f.jacobian(x), J, rtol=0, atol=1e-12)
    fz = 0.5 * ((J[:, 0, 0] + J[:, 1, 1]) + 1j * (J[:, 1, 0] - J[:, 0, 1]))
    fzb = 0.5 * ((J[:, 0, 0] - J[:, 1, 1]) + 1j * (J[:, 1, 0] + J[:, 0, 1]))
    np.testing.assert_allclose(f.mu(x), fzb / fz, rtol=0, atol=1e-12)


def _pl_mu_error(f, n):
    mesh = grid_mesh(n, 2)
    mu_pl = beltrami_coefficient(torch.as_tensor(mesh.points), torch.as_tensor(f(mesh.points)),
                                 torch.as_tensor(mesh.elements)).numpy()
    centroids = mesh.points[mesh.elements].mean(1)
    return np.abs(mu_pl - f.mu(centroids))


@pytest.mark.parametrize("name", ["T1", "T2", "T3", "T4"])
def test_exact_mu_agrees_with_the_pl_interpolant_to_first_order(name):
    """The mu of the piecewise-linear interpolant at the centroids differs from the exact mu by O(h)."""
    f = BELTRAMI_MAPS[name]
    e_coarse, e_fine = _pl_mu_error(f, 26), _pl_mu_error(f, 51)
    assert e_fine.max() < 1.0 / 50  # max error below h
    assert 1.8 < e_coarse.mean() / e_fine.mean() < 2.2  # halving h halves the error


# ----------------------------------------------------------------------------------------------- random fields
@pytest.mark.parametrize("dim", [2, 3])
def test_random_density_is_seeded_and_shaped(dim):
    pts = np.random.default_rng(9).random((100, dim))
    for seed in range(4):
        a = random_density(np.random.default_rng(seed), dim=dim)
        b = random_density(np.random.default_rng(seed), dim=dim)
        assert isinstance(a, RandomDensity) and a.dim == dim
        va, vb = a(pts), b(pts)
        assert va.shape == (100,)
        np.testing.assert_array_equal(va, vb)
        assert np.isfinite(va).all()
    c = random_density(np.random.default_rng(100), dim=dim)
    assert not np.allclose(c(pts), random_density(np.random.default_rng(101), dim=dim)(pts))


def test_random_density_ranges_and_grid_evaluation():
    cfg = RandomDensityConfig(p_noise=0.0)
    for seed in range(5):
        d = RandomDensity(np.random.default_rng(seed), cfg)
        assert cfg.modes[0] <= d.amp.size <= cfg.modes[1]
        assert (np.abs(d.amp) <= 1).all()
        assert ((d.freq >= cfg.freq[0]) & (d.freq <= cfg.freq[1])).all()
        n = 17
        np.testing.assert_allclose(d.on_grid(n), d(grid_points(n, 2)), rtol=1e-10, atol=1e-10)
        p = preprocess_density(d.on_grid(n).reshape(n, n))
        assert p.min() > 0
    cfg3 = RandomDensityConfig.for_dim(3)
    assert cfg3.modes == (4, 40) and cfg3.freq == (0.1, 5.0)
    for seed in range(3):  # the 3D separable grid evaluation (matrix products) against the pointwise one
        d = RandomDensity(np.random.default_rng(seed), replace(cfg3, p_noise=0.0, p_peak=0.5, p_ramp=0.5))
        np.testing.assert_allclose(d.on_grid(9), d(grid_points(9, 3)), rtol=1e-10, atol=1e-10)
    with pytest.raises(ValueError):
        RandomDensity(np.random.default_rng(0))(np.zeros((4, 3)))


def test_random_beltrami_bound_boundary_and_reproducibility():
    rng = np.random.default_rng(5)
    x = rng.random((20000, 2))
    t = np.linspace(0, 1, 51)
    boundary = np.concatenate([np.stack(s, -1) for s in
                               [(t, 0 * t), (t, 0 * t + 1), (0 * t, t), (0 * t + 1, t)]])
    for seed in range(6):
        # the strictest case: the drawn sup level equals the bound k
        cfg = RandomBeltramiConfig(k=0.5, sup=(0.5, 0.5))
        b = RandomBeltrami(np.random.default_rng(seed), cfg)
        mu = b(x)
        assert mu.shape == (20000,) and np.iscomplexobj(mu)
        assert np.abs(mu).max() <= cfg.k + 1e-12
        np.testing.assert_array_equal(mu, RandomBeltrami(np.random.default_rng(seed), cfg)(x))
        assert np.abs(b(boundary)).max() == 0.0
    d = random_beltrami(np.random.default_rng(0))
    assert np.abs(d(x)).max() <= RandomBeltramiConfig().k + 1e-12
    with pytest.raises(ValueError):
        RandomBeltrami(np.random.default_rng(0), RandomBeltramiConfig(k=1.0))


def test_random_map_fixes_boundary_and_bounds_mu():
    rng = np.random.default_rng(6)
    x = rng.random((4000, 2))
    t = np.linspace(0, 1, 51)
    boundary = np.concatenate([np.stack(s, -1) for s in
                               [(t, 0 * t), (t, 0 * t + 1), (0 * t, t), (0 * t + 1, t)]])
    for seed in range(6):
        cfg = RandomBeltramiConfig(k=0.6, sup=(0.6, 0.6))
        m = RandomMap(np.random.default_rng(seed), cfg)
        np.testing.assert_allclose(m(boundary), boundary, rtol=0, atol=1e-12)
        mu = m.mu(x)
        assert mu.shape == (4000,)
        assert np.abs(mu).max() <= cfg.k
        assert (np.linalg.det(m.jacobian(x)) > 0).all()
        np.testing.assert_array_equal(m(x), RandomMap(np.random.default_rng(seed), cfg)(x))
    m = random_boundary_map(np.random.default_rng(1))
    assert np.abs(m.mu(x)).max() <= RandomBeltramiConfig().k


def test_random_map_jacobian_matches_finite_differences():
    m = random_boundary_map(np.random.default_rng(3))
    x = np.random.default_rng(4).uniform(0.05, 0.95, (30, 2))
    eps = 1e-6
    fd = np.stack([(m(x + eps * e) - m(x - eps * e)) / (2 * eps) for e in np.eye(2)], -1)
    np.testing.assert_allclose(m.jacobian(x), fd, rtol=0, atol=1e-6)


def test_random_map_separable_patches_equal_pointwise_evaluation():
    """The tensor-product evaluation (grid and clipped patches, used to fit the scale) equals the point-by-point
    one at the same points, in the same order, to double round-off."""
    m = random_boundary_map(np.random.default_rng(5))
    rng = np.random.default_rng(7)
    xs = np.clip(rng.uniform(-0.1, 1.1, (4, 1)) + np.linspace(-0.05, 0.05, 9), 0, 1)
    ys = np.clip(rng.uniform(-0.1, 1.1, (4, 1)) + np.linspace(-0.05, 0.05, 7), 0, 1)
    pts = np.stack([np.repeat(xs, 7, axis=1), np.tile(ys, (1, 9))], -1).reshape(-1, 2)
    for a, b in zip(m._parts_tensor(xs, ys), m._parts(pts)):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(m.jacobian_grid(17), m.jacobian(grid_points(17, 2)), rtol=1e-12, atol=1e-12)


def test_random_map_mu_agrees_with_its_pl_interpolant():
    m = random_boundary_map(np.random.default_rng(2), RandomBeltramiConfig(modes=(1, 5), freq=(0.1, 2.0)))
    mesh = grid_mesh(65, 2)
    mu_pl = beltrami_coefficient(torch.as_tensor(mesh.points), torch.as_tensor(m(mesh.points)),
                                 torch.as_tensor(mesh.elements)).numpy()
    mu_ex = m.mu(mesh.points[mesh.elements].mean(1))
    assert np.abs(mu_pl - mu_ex).max() < 0.05


# ----------------------------------------------------------------------------------------------- jitter
@pytest.mark.parametrize("dim,n", [(2, 24), (3, 9)])
def test_jittered_points_keep_the_mesh_valid(dim, n):
    mesh = grid_mesh(n, dim)
    ref = mesh.points
    corners = (np.isin(ref, [0.0, 1.0])).all(-1)
    for seed in range(5):
        p = jittered_points(n, dim, np.random.default_rng(seed))
        assert p.shape == ref.shape
        assert ((p >= 0) & (p <= 1)).all()
        np.testing.assert_array_equal(p[corners], ref[corners])
        # a coordinate on the boundary stays there; vertices only slide along the boundary
        on_wall = (ref == 0) | (ref == 1)
        np.testing.assert_array_equal(p[on_wall], ref[on_wall])
        assert np.abs(p - ref).max() <= 0.2 / (n - 1) + 1e-15
        assert np.abs(p - ref).max() > 0
        vol = signed_measures(torch.as_tensor(p), torch.as_tensor(mesh.elements))
        assert float(vol.min()) > 0
        assert float(vol.sum()) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_array_equal(p, jittered_points(n, dim, np.random.default_rng(seed)))


def test_jitter_follows_the_gradient_magnitude():
    n = 12
    g = np.zeros((n, n))
    g[: n // 2] = 1.0  # jitter only where x < 1/2
    p = jittered_points(n, 2, np.random.default_rng(0), grad_magnitude=g)
    moved = np.abs(p - grid_points(n, 2)).max(-1) > 0
    assert not moved[g.reshape(-1) == 0].any()
    assert moved[g.reshape(-1) > 0].any()
    np.testing.assert_array_equal(jittered_points(n, 2, np.random.default_rng(0), strength=0.0), grid_points(n, 2))
    with pytest.raises(ValueError):
        jittered_points(n, 2, np.random.default_rng(0), strength=0.3)


# ----------------------------------------------------------------------------------------------- bad input
def test_bad_input_raises_value_error():
    with pytest.raises(ValueError, match="NaN"):
        check_density([1.0, np.nan, 2.0])
    with pytest.raises(ValueError, match="NaN"):
        preprocess_density(np.array([[1.0, np.nan], [1.0, 1.0]]))
    with pytest.raises(ValueError):
        check_density([1.0, 0.0, 2.0])
    with pytest.raises(ValueError):
        check_density([1.0, -0.5])
    with pytest.raises(ValueError):
        check_density([])
    assert check_density([1.0, -0.5], positive=False).dtype == np.float64
    with pytest.raises(ValueError):
        check_mu([0.1, 1.0])
    with pytest.raises(ValueError):
        check_mu(np.array([0.5 + 0.9j]))
    with pytest.raises(ValueError):
        check_mu([np.nan])
    assert check_mu([0.1, 0.2j]).dtype == np.complex128
    for n in (2, 1, 0):
        with pytest.raises(ValueError):
            sample_density("sin-cos", n)
    with pytest.raises(ValueError, match="unknown field"):
        get_field("no-such-field")
    with pytest.raises(ValueError):
        sample_density("T1", 11)  # a test map, not a density
    with pytest.raises(ValueError):
        DENSITIES["sin-cos"](np.zeros((3, 3)))
    with pytest.raises(ValueError):
        DENSITIES["sin-cos-3d"](np.zeros((3, 2)))
    with pytest.raises(ValueError):
        BELTRAMI_MAPS["T1"](np.zeros((3, 3)))
    with pytest.raises(ValueError):
        preprocess_density(np.ones(10))  # a flat field needs weights
    with pytest.raises(ValueError):
        jittered_points(2, 2, np.random.default_rng(0))
    assert math.isfinite(_std_orig("sin-cos", 3))


def test_ramp_scale_and_width_change_only_the_ramps():
    """ramp_scale multiplies every ramp's height and ramp_width sets its width range; the random stream, and so
    every other part of the field, is the same for every setting."""
    base = RandomDensityConfig(p_ramp=1.0, p_peak=1.0, p_noise=0.0)
    a = RandomDensity(np.random.default_rng(5), base)
    b = RandomDensity(np.random.default_rng(5), replace(base, ramp_scale=3.0))
    c = RandomDensity(np.random.default_rng(5), replace(base, ramp_width=(0.2, 0.2)))
    (na, oa, wa, ha), = a.ramps
    (nb, ob, wb, hb), = b.ramps
    (_, _, wc, _), = c.ramps
    assert hb == pytest.approx(3.0 * ha, rel=1e-12) and wb == wa and ob == oa and np.array_equal(na, nb)
    assert wc == pytest.approx(0.2) and 0.01 <= wa <= 0.05
    assert a.peaks[0][2] == b.peaks[0][2] and np.array_equal(a.amp, b.amp)


def test_hard_fields_are_single_ramps_or_peaks_and_leave_other_streams_alone():
    """p_hard = 0 draws exactly the fields of before; a hard field is a single steep ramp or narrow peak over faint
    modes, evaluated alike on the grid and at points, and as unequal as the held-out ramps and peaks (Std of the
    preprocessed density up to about 1.3, against at most about 0.45 for the other training fields)."""
    n = 17
    base = RandomDensityConfig.for_dim(3, p_peak=0.15, p_ramp=0.15)
    for seed in range(4):
        a = RandomDensity(np.random.default_rng(seed), base)
        b = RandomDensity(np.random.default_rng(seed), replace(base, p_hard=0.0, hard_contrast=(2.0, 3.0)))
        np.testing.assert_array_equal(a.on_grid(n), b.on_grid(n))
        assert a.hard is None
    hard = replace(base, p_hard=1.0, p_noise=0.0)
    stds, kinds = [], set()
    for seed in range(40):
        d = RandomDensity(np.random.default_rng(seed), hard)
        kinds.add(d.hard[0])
        np.testing.assert_allclose(d.on_grid(9), d(grid_points(9, 3)), rtol=1e-10, atol=1e-10)
        v = preprocess_density(d.on_grid(n).reshape(n, n, n)).ravel()
        stds.append((v / v.mean()).std())
        if d.hard[0] == "ramp":  # raw values from about 1 to k, the faint modes at most 0.3 peak to peak
            k = d.hard[4]
            assert 1.5 <= k <= 6.0
            assert np.ptp(d.on_grid(n)) == pytest.approx(k - 1.0, abs=0.35)
    assert kinds == {"ramp", "peak"}
    assert max(stds) > 1.0 and np.median(stds) > 0.45


def test_low_frequency_share_of_random_maps():
    """``low = 0`` draws no extra random number (older training streams are kept); ``low = 1`` draws every map
    from the low-frequency ranges; the share must be a probability."""
    cfg = RandomBeltramiConfig()
    rng = np.random.default_rng(3)
    assert cfg.draw_ranges(rng) == (cfg.modes, cfg.freq)
    assert rng.random() == np.random.default_rng(3).random()
    low = RandomBeltramiConfig(low=1.0)
    for seed in range(5):
        for cls in (RandomMap, RandomBeltrami):
            m = cls(np.random.default_rng(seed), low)
            n_modes = m.freq.shape[-2]
            assert low.low_modes[0] <= n_modes <= low.low_modes[1]
            f = m.freq / (2 * math.pi) if cls is RandomMap else m.freq
            assert low.low_freq[0] <= f.min() and f.max() <= low.low_freq[1]
    half = RandomBeltramiConfig(low=0.5)
    drawn = [half.draw_ranges(np.random.default_rng(s))[0] for s in range(400)]
    assert 0.4 < np.mean([d == half.low_modes for d in drawn]) < 0.6
    for bad in (-0.1, 1.5):
        with pytest.raises(ValueError, match="low-frequency"):
            RandomBeltramiConfig(low=bad)
