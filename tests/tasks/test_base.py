"""Tests of training tasks and batches (:mod:`rfmap.tasks`): reproducible per-sample seeding (the property that
makes data-parallel training equal to single-process training), the input encoding, unit-mass densities and the
validation of task specifications."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from rfmap.core.mesh import vertex_weights
from rfmap.core.mesh import grid_mesh, grid_points
from rfmap.tasks import TaskSpec, encode, grid_elements, kinds, sample_batch

SPECS = [TaskSpec("density", 2, "square"), TaskSpec("beltrami", 2, "fixed"), TaskSpec("density", 3, "free")]


def _n(spec):
    return 9 if spec.dim == 2 else 5


def _tensors(b):
    out = {"inputs": b.inputs, "ref": b.ref}
    if b.density is not None:
        out["density"] = b.density
    if b.mu_target is not None:
        out["mu_target"] = b.mu_target
    return out


@pytest.mark.parametrize("spec", SPECS, ids=str)
def test_sample_batch_is_reproducible(spec):
    n = _n(spec)
    a = sample_batch(spec, seed=7, step=3, indices=range(3), n=n)
    b = sample_batch(spec, seed=7, step=3, indices=range(3), n=n)
    ta, tb = _tensors(a), _tensors(b)
    assert set(ta) == set(tb)
    for k in ta:
        assert torch.equal(ta[k], tb[k]), k
    # a different step (or seed) draws different samples
    c = sample_batch(spec, seed=7, step=4, indices=range(3), n=n)
    d = sample_batch(spec, seed=8, step=3, indices=range(3), n=n)
    assert not torch.equal(a.inputs, c.inputs)
    assert not torch.equal(a.inputs, d.inputs)
    # the samples of a batch differ from each other
    assert not torch.equal(a.inputs[0], a.inputs[1])


@pytest.mark.parametrize("spec", SPECS, ids=str)
def test_split_batch_reproduces_the_full_batch(spec):
    """Rank r of K draws samples r*B .. (r+1)*B-1: concatenating the shards gives the single-process batch."""
    n = _n(spec)
    full = sample_batch(spec, seed=1, step=5, indices=range(4), n=n)
    lo = sample_batch(spec, seed=1, step=5, indices=range(0, 2), n=n)
    hi = sample_batch(spec, seed=1, step=5, indices=range(2, 4), n=n)
    tf, tl, th = _tensors(full), _tensors(lo), _tensors(hi)
    for k in tf:
        assert torch.equal(torch.cat([tl[k], th[k]]), tf[k]), k
    assert torch.equal(full.elements, lo.elements)
    # and any single sample is the same wherever it is drawn
    one = sample_batch(spec, seed=1, step=5, indices=[3], n=n)
    assert torch.equal(one.inputs[0], full.inputs[3])


@pytest.mark.parametrize("spec", SPECS, ids=str)
@pytest.mark.parametrize("jitter", [0.0, 0.2])
def test_encoded_inputs(spec, jitter):
    n, d = _n(spec), spec.dim
    B = 2
    b = sample_batch(spec, seed=0, step=0, indices=range(B), n=n, jitter=jitter)
    assert b.n == n
    assert b.inputs.shape == (B, d + spec.n_params) + (n,) * d
    assert b.inputs.dtype == torch.float32
    assert b.ref.shape == (B, n**d, d)
    assert torch.equal(b.elements, grid_elements(n, d))
    # the coordinate channels are the reference points in grid order
    coords = b.inputs[:, :d].reshape(B, d, -1).transpose(1, 2)
    assert torch.equal(coords, b.ref)
    grid = torch.as_tensor(grid_points(n, d), dtype=torch.float32)
    if jitter == 0:
        assert torch.equal(b.ref, grid.expand(B, -1, -1))
    else:
        # jittered by at most 0.2 h, walls kept
        h = 1.0 / (n - 1)
        off = (b.ref - grid).abs()
        assert 0 < float(off.max()) <= 0.2 * h + 1e-6
        on_wall = (grid == 0) | (grid == 1)
        assert torch.all(off[:, on_wall] == 0)
    params = b.inputs[:, d:].reshape(B, spec.n_params, -1)
    if spec.kind == "density":
        assert b.mu_target is None
        assert torch.allclose(params[:, 0], torch.log(b.density), atol=1e-6)
    else:
        assert b.density is None
        assert b.mu_target.shape == (B, b.elements.shape[0]) and b.mu_target.is_complex()
        assert float(b.mu_target.abs().max()) < 1
        assert float(b.mu_target.abs().max()) > 0


@pytest.mark.parametrize("spec", [SPECS[0], SPECS[2]], ids=str)
@pytest.mark.parametrize("jitter", [0.0, 0.2])
def test_density_rows_have_unit_mass(spec, jitter):
    n = _n(spec)
    b = sample_batch(spec, seed=2, step=9, indices=range(3), n=n, jitter=jitter)
    el = b.elements.numpy()
    for i in range(3):
        dens = b.density[i].double().numpy()
        assert (dens > 0).all()
        w = vertex_weights(b.ref[i].double().numpy(), el)
        assert float(w @ dens) == pytest.approx(1.0, abs=1e-5)  # float32 storage


def test_encode_validation_and_layout():
    spec = TaskSpec("beltrami", 2, "fixed")
    pts = torch.as_tensor(grid_points(5, 2), dtype=torch.float32)[None]
    mu = torch.complex(pts[..., 0] * 0.1, -pts[..., 1] * 0.2)
    x = encode(pts, mu, spec, 5)
    assert x.shape == (1, 4, 5, 5)
    # grid order: vertex (i, j) is at (i, j) / (N - 1), first array axis along x_1
    assert torch.allclose(x[0, 0, 3, 1], torch.tensor(0.75)) and torch.allclose(x[0, 1, 3, 1], torch.tensor(0.25))
    assert torch.allclose(x[0, 2], 0.1 * x[0, 0]) and torch.allclose(x[0, 3], -0.2 * x[0, 1])
    with pytest.raises(ValueError, match="grid"):
        encode(pts, mu, spec, 6)


def test_task_spec_validation():
    assert TaskSpec().n_params == 1 and TaskSpec("beltrami", 2, "fixed").n_params == 2
    assert kinds()[:2] == ("density", "beltrami")
    with pytest.raises(ValueError, match="unknown task kind"):
        TaskSpec("curvature")
    with pytest.raises(ValueError, match="dimension"):
        TaskSpec("density", 4)
    with pytest.raises(ValueError, match="Beltrami tasks are 2D, not 3D"):
        TaskSpec("beltrami", 3)
    with pytest.raises(ValueError, match="unknown boundary"):
        TaskSpec("density", 2, "round")
    with pytest.raises(Exception):  # frozen
        TaskSpec().kind = "beltrami"


def test_grid_elements_match_the_mesh():
    for n, d in [(5, 2), (4, 3)]:
        assert np.array_equal(grid_elements(n, d).numpy(), grid_mesh(n, d).elements)


@pytest.mark.parametrize("spec", [TaskSpec("density", 2, "square"), TaskSpec("density", 3, "free"),
                                  TaskSpec("density", 3, "square")], ids=str)
def test_task_loss_fast_path_equals_the_generic_path(spec):
    """task_loss on a grid batch (strided measures) gives the same loss and gradient as on the same batch with a
    copied element list (generic gather path)."""
    from dataclasses import replace

    from rfmap.tasks import LossWeights, task_loss

    n = _n(spec)
    b = sample_batch(spec, seed=3, step=1, indices=[0, 1], n=n, jitter=0.0)
    slow_b = replace(b, elements=b.elements.clone())
    g = torch.Generator().manual_seed(0)
    psi0 = 0.3 * torch.randn(2, spec.dim, *([n] * spec.dim), generator=g)
    w = LossWeights(beltrami=0.1, fold=10.0, fold_threshold=0.5)
    grads, totals = [], []
    for batch in (b, slow_b):
        psi = psi0.clone().requires_grad_(True)
        total, parts = task_loss(spec, batch, psi, w)
        total.backward()
        grads.append(psi.grad)
        totals.append(total.detach())
        assert parts["fold"] > 0
    torch.testing.assert_close(totals[0], totals[1], rtol=1e-5, atol=1e-7)
    # float32: summation order differs, so compare at 1e-5 of the gradient's scale
    torch.testing.assert_close(grads[0], grads[1], rtol=1e-4, atol=1e-5 * float(grads[1].abs().max()))


def test_the_beltrami_target_of_a_triangle_is_the_mean_of_its_three_vertices():
    """A triangle's training target (and the LBS input of ``rfmap solve --method lbs``) is the mean of the three
    vertex values of mu, the mean of its P1 interpolant: checked on distinct random vertex values, where no single
    vertex's value is the mean, and on the first triangle by hand."""
    from rfmap.tasks import get_task

    n = 5
    spec, task = TaskSpec("beltrami", 2, "fixed"), get_task("beltrami")
    rng = np.random.default_rng(7)
    mu = 0.6 * rng.uniform(size=n * n) * np.exp(2j * np.pi * rng.uniform(size=n * n))  # |mu| < 0.6, all distinct
    params = torch.as_tensor(mu)[None]
    ref = torch.as_tensor(grid_points(n, 2))[None]
    b = task.batch(spec, None, ref, params, n, None)
    el = grid_mesh(n, 2).elements
    want = (mu[el[:, 0]] + mu[el[:, 1]] + mu[el[:, 2]]) / 3
    np.testing.assert_allclose(b.mu_target[0].numpy(), want, rtol=0, atol=1e-15)
    for corner in range(3):  # the mean is none of the vertices' values
        assert np.abs(want - mu[el[:, corner]]).min() > 1e-3
    a, c, d = el[0]
    assert b.mu_target[0, 0].item() == pytest.approx((mu[a] + mu[c] + mu[d]) / 3, abs=1e-15)
    np.testing.assert_allclose(task.solver_input(mu.reshape(n, n)), want, rtol=0, atol=1e-15)
