"""Jacobians, measures and Beltrami coefficients of piecewise-linear maps (rfmap.core.geometry)."""
import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from rfmap.core.geometry import (
    beltrami_coefficient,
    beltrami_from_jacobian,
    det,
    edge_matrices,
    element_jacobians,
    jacobian_determinants,
    signed_measures,
    wirtinger,
)
from rfmap.core.mesh import grid_mesh

MESH2 = grid_mesh(5, 2)
MESH3 = grid_mesh(3, 3)
REF2 = torch.as_tensor(MESH2.points)
REF3 = torch.as_tensor(MESH3.points)
EL2 = torch.as_tensor(MESH2.elements)
EL3 = torch.as_tensor(MESH3.elements)


def _complex(p: torch.Tensor) -> torch.Tensor:
    return torch.complex(p[..., 0], p[..., 1])


def _real(z: torch.Tensor) -> torch.Tensor:
    return torch.stack([z.real, z.imag], -1)


def _smooth_map(p: torch.Tensor, eps: float = 0.05) -> torch.Tensor:
    """A smooth orientation-preserving deformation of the unit square."""
    x, y = p[..., 0], p[..., 1]
    return torch.stack([x + eps * torch.sin(math.pi * x) * torch.sin(2 * math.pi * y),
                        y + eps * torch.sin(2 * math.pi * x) * torch.sin(math.pi * y)], -1)


# ----------------------------------------------------------------------------------------------- exact answers
def test_identity_map():
    J = element_jacobians(REF2, REF2, EL2)
    torch.testing.assert_close(J, torch.eye(2, dtype=J.dtype).expand_as(J), rtol=0, atol=1e-12)
    torch.testing.assert_close(jacobian_determinants(REF2, REF2, EL2), torch.ones(EL2.shape[0], dtype=J.dtype))
    assert beltrami_coefficient(REF2, REF2, EL2).abs().max() < 1e-12
    torch.testing.assert_close(jacobian_determinants(REF3, REF3, EL3), torch.ones(EL3.shape[0], dtype=J.dtype))


def test_conformal_affine_map_has_zero_mu():
    a, c = complex(1.0, 0.3), complex(0.2, -0.7)
    mapped = _real(a * _complex(REF2) + c)
    mu = beltrami_coefficient(REF2, mapped, EL2)
    assert mu.abs().max() < 1e-12
    torch.testing.assert_close(jacobian_determinants(REF2, mapped, EL2),
                               torch.full((EL2.shape[0],), abs(a) ** 2, dtype=torch.float64))


@pytest.mark.parametrize("a,b", [(1 + 0j, 0.5 + 0j), (1.2 - 0.4j, 0.3 + 0.2j), (0.7j, -0.1 + 0.5j), (2 + 1j, 0j)])
def test_affine_map_mu_is_b_over_a(a, b):
    z = _complex(REF2)
    mapped = _real(a * z + b * z.conj() + (0.1 - 0.2j))
    mu = beltrami_coefficient(REF2, mapped, EL2)
    torch.testing.assert_close(mu, torch.full_like(mu, b / a), rtol=0, atol=1e-12)
    # det J = |a|^2 - |b|^2 for f = a z + b conj(z)
    torch.testing.assert_close(jacobian_determinants(REF2, mapped, EL2),
                               torch.full((EL2.shape[0],), abs(a) ** 2 - abs(b) ** 2, dtype=torch.float64))


def test_affine_jacobian_3d():
    rng = np.random.default_rng(0)
    A = torch.as_tensor(rng.normal(size=(3, 3)) + 3 * np.eye(3))
    mapped = REF3 @ A.T + torch.tensor([0.3, -1.0, 2.0], dtype=torch.float64)
    J = element_jacobians(REF3, mapped, EL3)
    torch.testing.assert_close(J, A.expand_as(J))
    torch.testing.assert_close(jacobian_determinants(REF3, mapped, EL3),
                               torch.full((EL3.shape[0],), float(torch.linalg.det(A)), dtype=torch.float64))


def test_reflection_flips_every_element():
    mapped = REF2 * torch.tensor([-1.0, 1.0], dtype=torch.float64)
    d = jacobian_determinants(REF2, mapped, EL2)
    torch.testing.assert_close(d, -torch.ones_like(d))
    # f = 0.5 z + conj(z) reverses orientation: mu = 2, |mu| > 1
    z = _complex(REF2)
    mu = beltrami_coefficient(REF2, _real(0.5 * z + z.conj()), EL2)
    torch.testing.assert_close(mu, torch.full_like(mu, 2.0))


def test_signed_measures_and_edge_matrices():
    tri = torch.tensor([[0.0, 0.0], [2.0, 0.0], [0.0, 3.0]], dtype=torch.float64)
    el = torch.tensor([[0, 1, 2]])
    torch.testing.assert_close(edge_matrices(tri, el)[0], torch.tensor([[2.0, 0.0], [0.0, 3.0]], dtype=torch.float64))
    assert float(signed_measures(tri, el)) == pytest.approx(3.0)
    assert float(signed_measures(tri, torch.tensor([[0, 2, 1]]))) == pytest.approx(-3.0)
    tet = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]], dtype=torch.float64)
    assert float(signed_measures(tet, torch.tensor([[0, 1, 2, 3]]))) == pytest.approx(1.0)


def test_det_matches_linalg():
    rng = np.random.default_rng(3)
    for d in (2, 3, 4):
        A = torch.as_tensor(rng.normal(size=(7, d, d)))
        torch.testing.assert_close(det(A), torch.linalg.det(A))


def test_wirtinger_derivatives():
    # f = a z + b conj(z): f_z = a, f_zbar = b
    a, b = 0.8 + 0.3j, -0.2 + 0.1j
    J = torch.tensor([[a.real + b.real, -a.imag + b.imag], [a.imag + b.imag, a.real - b.real]], dtype=torch.float64)
    fz, fzb = wirtinger(J)
    assert complex(fz) == pytest.approx(a)
    assert complex(fzb) == pytest.approx(b)
    assert complex(beltrami_from_jacobian(J)) == pytest.approx(b / a)


def test_batched_inputs():
    batch = torch.stack([REF2, _smooth_map(REF2), 2 * REF2])
    d = jacobian_determinants(REF2, batch, EL2)
    mu = beltrami_coefficient(REF2, batch, EL2)
    assert d.shape == (3, EL2.shape[0]) and mu.shape == (3, EL2.shape[0])
    torch.testing.assert_close(d[1], jacobian_determinants(REF2, batch[1], EL2))
    torch.testing.assert_close(d[2], torch.full_like(d[2], 4.0))


def test_bad_input():
    with pytest.raises(ValueError):
        beltrami_coefficient(REF3, REF3, EL3)  # 3D points
    with pytest.raises(ValueError):
        beltrami_from_jacobian(torch.eye(3))
    with pytest.raises(ValueError):
        signed_measures(REF2, EL3)  # tetrahedra on 2D points
    with pytest.raises(ValueError):
        signed_measures(REF2, EL2.double())  # non-integer elements


# ----------------------------------------------------------------------------------------------- invariance
angles = st.floats(min_value=-math.pi, max_value=math.pi, allow_nan=False)
shifts = st.floats(min_value=-10.0, max_value=10.0, allow_nan=False)


@settings(max_examples=30, deadline=None)
@given(theta=angles, tx=shifts, ty=shifts)
def test_det_and_mu_invariant_under_rigid_motions_2d(theta, tx, ty):
    mapped = _smooth_map(REF2)
    rot = torch.tensor([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]],
                       dtype=torch.float64)
    moved = mapped @ rot.T + torch.tensor([tx, ty], dtype=torch.float64)
    d0, d1 = jacobian_determinants(REF2, mapped, EL2), jacobian_determinants(REF2, moved, EL2)
    assert float((d0 - d1).abs().max()) < 1e-9
    m0, m1 = beltrami_coefficient(REF2, mapped, EL2), beltrami_coefficient(REF2, moved, EL2)
    assert float((m0.abs() - m1.abs()).abs().max()) < 1e-9
    # post-composition with a rotation leaves mu itself unchanged
    assert float((m0 - m1).abs().max()) < 1e-9


@settings(max_examples=20, deadline=None)
@given(a=angles, b=angles, c=angles, tx=shifts, ty=shifts, tz=shifts)
def test_det_invariant_under_rigid_motions_3d(a, b, c, tx, ty, tz):
    def rz(t):
        return torch.tensor([[math.cos(t), -math.sin(t), 0], [math.sin(t), math.cos(t), 0], [0, 0, 1]],
                            dtype=torch.float64)

    def rx(t):
        return torch.tensor([[1, 0, 0], [0, math.cos(t), -math.sin(t)], [0, math.sin(t), math.cos(t)]],
                            dtype=torch.float64)

    R = rz(a) @ rx(b) @ rz(c)
    mapped = REF3 + 0.05 * torch.sin(3 * REF3.roll(1, -1))
    moved = mapped @ R.T + torch.tensor([tx, ty, tz], dtype=torch.float64)
    d0, d1 = jacobian_determinants(REF3, mapped, EL3), jacobian_determinants(REF3, moved, EL3)
    assert float((d0 - d1).abs().max()) < 1e-9


# ----------------------------------------------------------------------------------------------- gradients
def _perturbed(ref: torch.Tensor, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    p = ref + 0.03 * (torch.rand(ref.shape, generator=g, dtype=torch.float64) - 0.5)
    return p.requires_grad_(True)


SMALL2, SMALL3 = grid_mesh(3, 2), grid_mesh(2, 3)
SREF2, SREF3 = torch.as_tensor(SMALL2.points), torch.as_tensor(SMALL3.points)
SEL2, SEL3 = torch.as_tensor(SMALL2.elements), torch.as_tensor(SMALL3.elements)


@pytest.mark.parametrize("dim", [2, 3])
def test_gradcheck_signed_measures(dim):
    ref, el = (SREF2, SEL2) if dim == 2 else (SREF3, SEL3)
    assert torch.autograd.gradcheck(lambda p: signed_measures(p, el), (_perturbed(ref, 0),))


@pytest.mark.parametrize("dim", [2, 3])
def test_gradcheck_jacobian_determinants(dim):
    ref, el = (SREF2, SEL2) if dim == 2 else (SREF3, SEL3)
    assert torch.autograd.gradcheck(lambda r, p: jacobian_determinants(r, p, el),
                                    (_perturbed(ref, 1), _perturbed(ref, 2)))


@pytest.mark.parametrize("dim", [2, 3])
def test_gradcheck_element_jacobians(dim):
    ref, el = (SREF2, SEL2) if dim == 2 else (SREF3, SEL3)
    assert torch.autograd.gradcheck(lambda r, p: element_jacobians(r, p, el),
                                    (_perturbed(ref, 3), _perturbed(ref, 4)))


def test_gradcheck_beltrami_coefficient():
    def parts(r, p):
        mu = beltrami_coefficient(r, p, SEL2)
        return mu.real, mu.imag

    assert torch.autograd.gradcheck(parts, (_perturbed(SREF2, 5), _perturbed(SREF2, 6)))


@pytest.mark.parametrize("dim,n", [(2, 2), (2, 6), (3, 2), (3, 5)])
def test_grid_fast_path_matches_the_element_list(dim, n):
    """Strided grid measures and element means equal the gathered ones exactly, element by element, and so do
    their gradients (the training losses use the strided path)."""
    from rfmap.core.geometry import grid_element_mean, grid_signed_measures

    mesh = grid_mesh(n, dim)
    el = torch.as_tensor(mesh.elements)
    g = torch.Generator().manual_seed(dim * 10 + n)
    x = torch.as_tensor(mesh.points)[None].repeat(3, 1, 1) + 0.05 * torch.randn(3, n**dim, dim, generator=g,
                                                                                dtype=torch.float64)
    x1, x2 = x.clone().requires_grad_(True), x.clone().requires_grad_(True)
    fast, slow = grid_signed_measures(x1, n), signed_measures(x2, el)
    assert fast.shape == (3, math.factorial(dim) * (n - 1) ** dim)
    torch.testing.assert_close(fast, slow, rtol=0, atol=1e-15)
    w = torch.randn(fast.shape, generator=g, dtype=torch.float64)
    (fast * w).sum().backward()
    (slow * w).sum().backward()
    torch.testing.assert_close(x1.grad, x2.grad, rtol=0, atol=1e-13)
    v = torch.rand(3, n**dim, generator=g, dtype=torch.float64)
    torch.testing.assert_close(grid_element_mean(v, n, dim), v[:, el].mean(-1), rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="do not form"):
        grid_signed_measures(x[:, :-1], n)


@pytest.mark.parametrize("dim,n", [(2, 2), (2, 6), (3, 2), (3, 5)])
def test_grid_measure_coefficients_are_the_measures_of_mixed_meshes(dim, n):
    """c_S of grid_measure_coefficients is the measure of the mesh whose coordinates a in S come from the
    displacement and the others from the grid (measured on the element list), to 1e-15; and the polynomial
    sum_S c_S prod alpha_a is the measure of the grid moved by alpha * D."""
    from rfmap.core.geometry import grid_measure_coefficients

    mesh = grid_mesh(n, dim)
    ref = torch.as_tensor(mesh.points, dtype=torch.float64)
    el = torch.as_tensor(mesh.elements)
    disp = 0.2 * torch.randn(ref.shape, generator=torch.Generator().manual_seed(n + dim), dtype=torch.float64)
    coeffs = grid_measure_coefficients(ref, disp, n)
    assert [s for s, _ in coeffs] == [tuple(a for a in range(dim) if b >> a & 1) for b in range(2**dim)]
    for s, c in coeffs:
        mixed = torch.stack([disp[:, a] if a in s else ref[:, a] for a in range(dim)], -1)
        torch.testing.assert_close(c, signed_measures(mixed, el), rtol=0, atol=1e-15)
    alpha = [0.7, 1.9, 1.3][:dim]
    poly = sum(c * math.prod(alpha[a] for a in s) for s, c in coeffs)
    moved = ref + torch.as_tensor(alpha, dtype=torch.float64) * disp
    torch.testing.assert_close(poly, signed_measures(moved, el), rtol=0, atol=1e-14)
    with pytest.raises(ValueError, match="do not form"):
        grid_measure_coefficients(ref[:-1], disp[:-1], n)


@pytest.mark.parametrize("d,n", [(2, 6), (3, 5)])
def test_grid_min_measure_is_the_smallest_signed_measure(d, n):
    """The identity's smallest element measure is h^d / d! (the grid's equal simplices), and on a fold-free
    perturbation and on a map with elements turned over it is the smallest of ``signed_measures`` (to 1e-5 of
    the reference measure), whichever precision decides."""
    from rfmap.core.geometry import grid_min_measure

    mesh = grid_mesh(n, d)
    ref = 1.0 / ((n - 1) ** d * math.factorial(d))
    assert grid_min_measure(mesh.points, n) == pytest.approx(ref, rel=1e-6)
    jittered = mesh.points + 0.2 / (n - 1) * np.random.default_rng(4).uniform(-0.5, 0.5, size=mesh.points.shape)
    folded = mesh.points.copy()
    folded[(n**d) // 2, 0] += 1.3 / (n - 1)  # the middle vertex pushed past its neighbour
    for p in (jittered, folded):
        want = float(signed_measures(torch.as_tensor(p), torch.as_tensor(mesh.elements)).min())
        assert grid_min_measure(p, n) == pytest.approx(want, abs=1e-5 * ref)
    assert want < 0
