"""The diffusion's heat field (rfmap.solvers.heatfield) and the numpy multilinear interpolation it shares with the
cartogram flow (rfmap.core.mesh.multilinear), against exact answers."""
import math

import numpy as np
import pytest
import torch

from rfmap.core.mesh import interpolate, multilinear
from rfmap.solvers.cosine import CosineTransforms
from rfmap.solvers.heatfield import HeatField, _openblas_threads, blas_threads


def _modes(m: int, d: int, t: float):
    r"""Grid values of :math:`\rho_0 = 2 + \cos\pi x_1 + \frac12 \cos 2\pi x_d` on an ``m``-raster, and the exact
    :math:`\rho(x, t)` and :math:`\nabla\rho(x, t)` as functions of points (P, d)."""
    axes = np.meshgrid(*([np.linspace(0.0, 1.0, m)] * d), indexing="ij")
    e1, e2 = math.exp(-math.pi**2 * t), math.exp(-4 * math.pi**2 * t)

    def rho(x):
        return 2 + e1 * np.cos(math.pi * x[:, 0]) + 0.5 * e2 * np.cos(2 * math.pi * x[:, -1])

    def grad(x):
        g = np.zeros_like(x)
        g[:, 0] = -math.pi * e1 * np.sin(math.pi * x[:, 0])
        g[:, -1] += -math.pi * e2 * np.sin(2 * math.pi * x[:, -1])
        return g

    return 2 + np.cos(math.pi * axes[0]) + 0.5 * np.cos(2 * math.pi * axes[-1]), rho, grad


@pytest.mark.parametrize("d,m", [(2, 17), (3, 9)])
def test_fields_are_exact_on_cosine_modes(d, m):
    """rho and grad rho on the raster decay each mode by exp(-pi^2 |k|^2 t), to 1e-12, whichever transform gave the
    coefficients (the maps' scipy.fft, the cartograms' numpy.fft)."""
    t = 0.01
    values, rho, grad = _modes(m, d, t)
    nodes = np.stack(np.meshgrid(*([np.linspace(0.0, 1.0, m)] * d), indexing="ij"), -1).reshape(-1, d)
    fields = [HeatField(values)] + ([HeatField(values, "points", CosineTransforms(m))] if d == 2 else [])
    for field in fields:
        f = field.fields(t).reshape(d + 1, -1)
        assert np.abs(f[0] - rho(nodes)).max() < 1e-12
        assert np.abs(f[1:].T - grad(nodes)).max() < 1e-12


@pytest.mark.parametrize("d,m", [(2, 33), (3, 17)])
def test_velocity_divides_where_it_is_told(d, m):
    r"""At the raster's nodes both divisions give :math:`-\nabla\rho/\rho` exactly (to 1e-12); between them they
    interpolate different things, each to :math:`O(h^2)` of the exact velocity, and a window of the raster (the
    points' bounding box) gives what the whole raster gives."""
    t = 0.002
    values, rho, grad = _modes(m, d, t)
    grid, points = HeatField(values, "grid"), HeatField(values, "points")
    h = 1.0 / (m - 1)
    nodes = np.random.default_rng(0).integers(0, m, (50, d)) * h
    exact = -grad(nodes) / rho(nodes)[:, None]
    for field in (grid, points):
        assert np.abs(field.velocity_at(t, nodes) - exact).max() < 1e-12
    inside = np.random.default_rng(1).uniform(0.3, 0.6, (200, d))
    exact = -grad(inside) / rho(inside)[:, None]
    v_grid, v_points = grid.velocity_at(t, inside), points.velocity_at(t, inside)
    assert np.abs(v_grid - exact).max() < 10 * h**2 and np.abs(v_points - exact).max() < 10 * h**2
    assert np.abs(v_grid - v_points).max() > 1e-8  # two different interpolants
    whole = multilinear(grid.velocity(t), inside * (m - 1))
    assert np.abs(v_grid - whole).max() < 1e-14


def test_an_unknown_division_is_refused():
    with pytest.raises(ValueError, match="unknown divide"):
        HeatField(np.ones((5, 5)), divide="nodes")


@pytest.mark.parametrize("d", [2, 3])
def test_multilinear_is_exact_on_multilinear_functions_and_matches_torch(d):
    """A product of affine functions of each coordinate is reproduced exactly (to round-off) on a grid with
    different sides per axis, points outside are clamped to it, and the values agree with the torch form
    (rfmap.core.mesh.interpolate) to 1e-14 of their scale."""
    rng = np.random.default_rng(2)
    shape = (7, 5, 6)[:d]
    coef = rng.normal(size=(2, d, 2))  # two channels, per axis a + b x

    def f(x):  # x in index units
        return np.stack([np.prod([c[j, 0] + c[j, 1] * x[..., j] for j in range(d)], axis=0) for c in coef], -1)

    nodes = np.stack(np.meshgrid(*[np.arange(s, dtype=float) for s in shape], indexing="ij"), -1)
    planes = np.ascontiguousarray(np.moveaxis(f(nodes), -1, 0))
    u = rng.uniform(0, 1, (300, d)) * (np.array(shape) - 1)
    got = multilinear(planes, u.copy())
    scale = np.abs(planes).max()
    assert got.shape == (300, 2) and np.abs(got - f(u)).max() < 1e-13 * scale
    outside = u + np.where(rng.random((300, d)) < 0.5, -10.0, 10.0)
    assert np.array_equal(multilinear(planes, outside.copy()),
                          multilinear(planes, np.clip(outside, 0, np.array(shape) - 1)))
    torch_form = interpolate(torch.from_numpy(planes)[None], u / (np.array(shape) - 1), check=False)[0].numpy()
    assert np.abs(got - torch_form).max() < 1e-14 * scale


@pytest.mark.skipif(not _openblas_threads(), reason="numpy's BLAS is not an OpenBLAS found in this process")
def test_blas_threads_sets_and_restores_the_thread_count():
    _, get = _openblas_threads()[0]
    before = get()
    with blas_threads(1):
        assert get() == 1
        assert np.allclose(np.ones((64, 64)) @ np.ones((64, 64)), 64.0)
    assert get() == before
    with blas_threads(None):
        assert get() == before
