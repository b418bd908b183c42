"""Tests of the data-free training losses (:mod:`rfmap.tasks.losses`): exact values for identity, affine and scaled maps,
the invariances the paper relies on, finiteness of values and gradients, and independence of the resolution."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from rfmap.tasks import losses as L
from rfmap.fields import preprocess_density
from rfmap.core.geometry import signed_measures
from rfmap.core.mesh import grid_mesh
from rfmap.tasks import LossWeights, TaskSpec, sample_batch, task_loss


def mesh_t(n: int, dim: int = 2):
    m = grid_mesh(n, dim)
    return torch.as_tensor(m.points)[None], torch.as_tensor(m.elements)


def density_on(ref: torch.Tensor, fn) -> torch.Tensor:
    n = round(ref.shape[1] ** 0.5)
    return torch.as_tensor(preprocess_density(fn(ref[0].numpy()).reshape(n, n)).reshape(1, -1))


def bump(x):
    return 1.0 + 0.5 * np.sin(np.pi * x[..., 0]) * np.cos(np.pi * x[..., 1])


def affine(ref: torch.Tensor, a: complex, b: complex, c: complex = 0j) -> torch.Tensor:
    """The map z -> a z + b conj(z) + c on points (..., 2)."""
    z = torch.complex(ref[..., 0], ref[..., 1])
    w = a * z + b * z.conj() + c
    return torch.stack([w.real, w.imag], -1)


def smooth_map(ref: torch.Tensor, eps: float = 0.05) -> torch.Tensor:
    x, y = ref[..., 0], ref[..., 1]
    return ref + eps * (torch.sin(math.pi * x) * torch.sin(math.pi * y))[..., None]


# ----------------------------------------------------------------------------------------------- finiteness


@pytest.mark.parametrize("kind,dim,boundary,n", [
    ("density", 2, "square", 9), ("density", 2, "free", 9), ("density", 2, "fixed", 9),
    ("beltrami", 2, "fixed", 9), ("density", 3, "square", 5), ("density", 3, "free", 5),
])
@pytest.mark.parametrize("scale", [0.05, 2.0])
def test_losses_finite_with_finite_gradients(kind, dim, boundary, n, scale):
    """Random outputs, small and large (scale 2 folds many elements), give finite losses and gradients."""
    spec = TaskSpec(kind, dim, boundary)
    batch = sample_batch(spec, seed=3, step=1, indices=range(2), n=n)
    g = torch.Generator().manual_seed(0)
    psi = (scale * torch.randn(2, dim, *([n] * dim), generator=g)).requires_grad_()
    weights = LossWeights(beltrami=0.1, fold=10.0, area=1.0)
    total, parts = task_loss(spec, batch, psi, weights)
    assert total.dim() == 0 and torch.isfinite(total)
    assert all(math.isfinite(v) and v >= 0 for v in parts.values())
    expected = {"beltrami", "fold"} if kind == "beltrami" else {"density", "fold"}
    expected |= {"mu2"} if kind == "density" and dim == 2 else set()
    expected |= {"area"} if kind == "density" and boundary == "free" else set()
    assert set(parts) == expected
    total.backward()
    assert psi.grad is not None and torch.isfinite(psi.grad).all()
    assert psi.grad.abs().sum() > 0
    if scale == 2.0:
        assert parts["fold"] > 0  # the large output did fold elements


def test_task_loss_total_is_the_weighted_sum_of_its_parts():
    spec = TaskSpec("density", 2, "free")
    batch = sample_batch(spec, seed=0, step=0, indices=[0, 1], n=9)
    psi = 0.1 * torch.randn(2, 2, 9, 9, generator=torch.Generator().manual_seed(2))
    w = LossWeights(beltrami=0.3, fold=7.0, area=2.0)
    total, parts = task_loss(spec, batch, psi, w)
    want = parts["density"] + 0.3 * parts["mu2"] + 7.0 * parts["fold"] + 2.0 * parts["area"]
    assert float(total) == pytest.approx(want, rel=1e-5)
    # the identity (psi = 0) gives exactly the density loss of the undeformed grid and nothing else
    total0, parts0 = task_loss(spec, batch, torch.zeros_like(psi), w)
    assert parts0["mu2"] < 1e-10 and parts0["fold"] == 0.0 and parts0["area"] < 1e-10
    assert float(total0) == pytest.approx(parts0["density"], abs=1e-6)


# ----------------------------------------------------------------------------------------------- density loss


def test_density_loss_zero_for_identity_on_uniform_density():
    ref, el = mesh_t(17)
    uniform = torch.ones(1, ref.shape[1], dtype=torch.float64)
    assert float(L.density_loss(ref, ref, el, uniform)) < 1e-12
    # any constant works (only the relative density matters)
    assert float(L.density_loss(ref, ref, el, 7.5 * uniform)) < 1e-12


def test_density_loss_positive_for_non_uniform_density():
    ref, el = mesh_t(17)
    rho = density_on(ref, bump)
    assert float(L.density_loss(ref, ref, el, rho)) > 1e-3
    # element densities relative to their mean: mean 1 weighted by the mapped measures
    rt, w = L.element_density(ref, ref, el, rho)
    assert float((rt * w).sum() / w.sum()) == pytest.approx(1.0, abs=1e-12)


@settings(max_examples=25, deadline=None)
@given(s=st.floats(0.5, 3.0), cx=st.floats(-2, 2), cy=st.floats(-2, 2))
def test_density_loss_invariant_to_uniform_scaling(s, cx, cy):
    """The free-boundary property: rescaling the mapped domain about any centre cannot change the loss.

    (Down to the 1% floor of the element measure; scales >= 0.5 keep every element well above it.)"""
    ref, el = mesh_t(9)
    rho = density_on(ref, bump)
    mapped = smooth_map(ref, 0.08)
    c = torch.tensor([cx, cy], dtype=torch.float64)
    scaled = c + s * (mapped - c)
    a = float(L.density_loss(ref, mapped, el, rho))
    b = float(L.density_loss(ref, scaled, el, rho))
    assert a > 1e-3
    assert b == pytest.approx(a, abs=1e-10)


def test_density_loss_is_lowered_by_equalising():
    """The density p(x) = 0.5 + x (unit mass) is equalised by u(x) = 0.5 x + x^2 / 2, the map with u' = p."""
    n = 17
    ref, el = mesh_t(n)
    x = ref[0, :, 0].numpy()
    rho = torch.as_tensor(0.5 + x)[None]
    # u(x) = integral of p from 0 to x, i.e. 0.5 x + x^2 / 2 (maps [0, 1] onto [0, 1])
    mapped = ref.clone()
    mapped[..., 0] = torch.as_tensor(0.5 * x + 0.5 * x**2)
    before = float(L.density_loss(ref, ref, el, rho))
    after = float(L.density_loss(ref, mapped, el, rho))
    assert before > 1e-3
    # exact up to the piecewise-linear quadrature: the relative element density is 1 + O(h) (h / 6 p), so the loss
    # drops from 0.5 Var(p) = 1/24 to O(h^2) (about 7e-5 at h = 1/16)
    assert after < 5e-3 * before


def test_density_tangent_agrees_above_the_floor_and_pulls_collapsed_elements_open():
    """The tangent continuation equals the clamp wherever every element keeps 1 % of its measure; on a map that
    collapses one triangle (and flips it), the clamp gives that vertex no density gradient, the tangent does, and
    the gradient points to where the triangle opens."""
    ref, el = mesh_t(9)
    rho = density_on(ref, bump)
    mapped = smooth_map(ref, 0.08)
    a = L.density_loss(ref, mapped, el, rho)
    b = L.density_loss(ref, mapped, el, rho, tangent=True)
    assert float(b) == pytest.approx(float(a), rel=1e-12)
    # push an interior vertex through the opposite edge of one of its triangles
    meas = signed_measures(ref, el)[0]
    k = 40  # an interior triangle
    i, j, m = (int(v) for v in el[k])
    bad = ref.clone()
    bad[0, i] = ref[0, j] + ref[0, m] - ref[0, i]  # reflected through the midpoint of edge j-m: area -|T|
    assert float(signed_measures(bad, el)[0, k]) < -0.5 * float(meas[k])
    grads = {}
    for tangent in (False, True):
        x = bad.clone().requires_grad_(True)
        L.density_loss(ref, x, el, rho, tangent=tangent).backward()
        # the part of the vertex's gradient that comes from the flipped triangle: total minus the others
        grads[tangent] = x.grad[0, i].clone()
    x = bad.clone().requires_grad_(True)
    area = signed_measures(x, el)[0, k]
    area.backward()
    opens = x.grad[0, i]  # moving the vertex along +opens increases the flipped triangle's area
    # descending the tangent loss moves the vertex to open the triangle (the clamp's gradient there is only what
    # the neighbouring triangles contribute)
    assert float(-(grads[True] - grads[False]) @ opens) > 0
    assert torch.isfinite(grads[True]).all()


def test_density_loss_resolution_independent():
    """Losses are quadratures of integrals over the domain, so they converge as the grid is refined.

    For a smooth density and the smooth map u = x + 0.05 sin(pi x) sin(pi y) the values at N = 33 and N = 65 differ
    by about 0.4% (O(h^2) quadrature error); we allow 2%."""
    vals = {}
    for n in (33, 65):
        ref, el = mesh_t(n)
        rho = density_on(ref, bump)
        mapped = smooth_map(ref)
        vals[n] = {"density": float(L.density_loss(ref, mapped, el, rho)),
                   "mu2": float(L.beltrami_energy(ref, mapped, el)),
                   "fold": float(L.fold_penalty(ref, mapped, el, threshold=1.0))}
    for k in vals[33]:
        assert vals[33][k] > 1e-3, k
        assert vals[65][k] == pytest.approx(vals[33][k], rel=0.02), k


# ----------------------------------------------------------------------------------------------- Beltrami


@settings(max_examples=20, deadline=None)
@given(ar=st.floats(0.5, 2.0), ai=st.floats(-1.0, 1.0), br=st.floats(-0.3, 0.3), bi=st.floats(-0.3, 0.3))
def test_beltrami_loss_zero_for_matching_target(ar, ai, br, bi):
    a, b = complex(ar, ai), complex(br, bi)
    ref, el = mesh_t(9)
    mapped = affine(ref, a, b, 0.3 - 0.1j)
    target = torch.full((1, el.shape[0]), b / a, dtype=torch.complex128)
    assert float(L.beltrami_loss(ref, mapped, el, target)) < 1e-12
    # a wrong target gives exactly |mu - target|^2 (constant mu)
    wrong = target + 0.1j
    assert float(L.beltrami_loss(ref, mapped, el, wrong)) == pytest.approx(0.01, rel=1e-9)


def test_beltrami_loss_averages_over_area():
    """Triangles of equal area: the loss is the plain mean of |mu - target|^2 over triangles."""
    ref, el = mesh_t(5)
    m = el.shape[0]
    target = torch.zeros(1, m, dtype=torch.complex128)
    target[0, : m // 2] = 0.2  # half the triangles have error 0.2 for the identity map
    assert float(L.beltrami_loss(ref, ref, el, target)) == pytest.approx(0.5 * 0.04, rel=1e-12)


@pytest.mark.parametrize("a,b", [(1, 0), (2 + 1j, 0), (0.7j, 0), (1.0, 0.3), (1 + 1j, 0.2 - 0.4j), (2.0, -0.5j)])
def test_beltrami_energy_of_affine_maps(a, b):
    ref, el = mesh_t(9)
    mapped = affine(ref, a, b, 0.5 + 0.25j)
    want = abs(b / a) ** 2
    assert float(L.beltrami_energy(ref, mapped, el)) == pytest.approx(want, abs=1e-12)


# ----------------------------------------------------------------------------------------------- penalties


def test_fold_penalty():
    ref, el = mesh_t(5)
    assert float(L.fold_penalty(ref, ref, el)) == 0.0
    # a strong anisotropic squeeze keeps orientation but pushes det J = 0.01 below the threshold 0.02
    squeezed = ref * torch.tensor([1.0, 0.01], dtype=torch.float64)
    assert float(L.fold_penalty(ref, squeezed, el)) == pytest.approx(0.01, abs=1e-12)
    # flip one interior vertex across its neighbours: the elements around it get negative Jacobians
    flipped = ref.clone()
    centre = 2 * 5 + 2
    flipped[0, centre] += torch.tensor([0.6, 0.6], dtype=torch.float64)
    det = (signed_measures(flipped, el) / signed_measures(ref, el))[0]
    assert (det < 0).any()
    pen = float(L.fold_penalty(ref, flipped, el))
    want = float((torch.relu(0.02 - det) * signed_measures(ref, el)[0]).sum())  # unit total area
    assert pen > 0 and pen == pytest.approx(want, rel=1e-12)
    # the mirror image of the whole square flips every element
    mirror = ref * torch.tensor([-1.0, 1.0], dtype=torch.float64)
    assert float(L.fold_penalty(ref, mirror, el)) == pytest.approx(1.02, rel=1e-12)


def test_area_penalty():
    ref, el = mesh_t(9)
    assert float(L.area_penalty(ref, ref, el)) < 1e-28
    # area-preserving: shear, rotation, stretch (2, 1/2), and the smooth boundary-fixing map
    theta = 0.7
    rot = torch.tensor([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]],
                       dtype=torch.float64)
    shear = torch.tensor([[1.0, 0.3], [0.0, 1.0]], dtype=torch.float64)
    for mapped in (ref @ shear.T, ref @ rot.T + 3.0, ref * torch.tensor([2.0, 0.5], dtype=torch.float64),
                   smooth_map(ref)):
        assert float(L.area_penalty(ref, mapped, el)) < 1e-24
    for s in (0.5, 1.1, 2.0):
        assert float(L.area_penalty(ref, s * ref, el)) == pytest.approx((s * s - 1) ** 2, rel=1e-12)


def test_weighted_mean():
    v = torch.tensor([[1.0, 3.0], [2.0, 2.0]])
    w = torch.tensor([[1.0, 3.0], [5.0, 1.0]])
    # per row (1 + 9) / 4 = 2.5 and 2, averaged over the batch
    assert float(L.weighted_mean(v, w)) == pytest.approx(2.25)


@pytest.mark.parametrize("tangent", [False, True])
def test_element_density_floors_a_collapsed_element_at_one_percent_of_its_measure(tangent):
    r"""An element squeezed to :math:`10^{-3}` of its reference measure (and one turned over) counts as holding 1 %
    of it: :math:`\tilde\rho_i = (p_i / a_0) / (P/A)` with :math:`a_0 = 0.01\,|T_i|`, or along the tangent
    :math:`p_i/a_0\,(2 - A_i/a_0)`; elements above the floor keep :math:`p_i/A_i`.  :math:`P/A` is the total
    population over the total mapped measure, the floored elements' true measures included."""
    ref, el = mesh_t(5)
    rho = density_on(ref, bump)
    ref_meas = signed_measures(ref, el)[0]
    mapped = ref.clone()
    k = 10  # an interior triangle: its first vertex moved onto the line of the other two, all but a thousandth
    i, j, m = (int(v) for v in el[k])
    mapped[0, i] = 0.5 * (ref[0, j] + ref[0, m]) + 1e-3 * (ref[0, i] - 0.5 * (ref[0, j] + ref[0, m]))
    meas = signed_measures(mapped, el)[0]
    assert float(meas[k]) == pytest.approx(1e-3 * float(ref_meas[k]), rel=1e-9)
    pop = rho[0, el].mean(-1) * ref_meas
    floor = 0.01 * ref_meas
    want = torch.where(meas >= floor, pop / meas, pop / floor * (2 - meas / floor) if tangent else pop / floor)
    want = want / (pop.sum() / meas.sum())
    got, w = L.element_density(ref, mapped, el, rho, tangent=tangent)
    torch.testing.assert_close(got[0], want, rtol=1e-12, atol=0)
    assert float(got[0, k]) == pytest.approx(float(pop[k] / floor[k] * (2 - 0.1 if tangent else 1)
                                                   / (pop.sum() / meas.sum())), rel=1e-12)
    torch.testing.assert_close(w[0], ref_meas)
