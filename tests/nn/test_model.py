"""Tests of the multi-resolution U-Net (:mod:`rfmap.nn`): shapes at any resolution, the identity at
initialisation, the boundary masks, input validation and the resolution behaviour of inference.

All models are tiny (``base=4``, ``depth=2``) so that the tests run in seconds on a CPU.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from rfmap.core.mesh import grid_mesh, grid_points
from rfmap.nn import BOUNDARIES, MultiResUNet, apply_displacement, boundary_mask
from rfmap.surrogate import Surrogate
from rfmap.tasks import TaskSpec


def tiny(dim: int = 2, n_params: int = 1, seed: int = 0) -> MultiResUNet:
    torch.manual_seed(seed)
    return MultiResUNet(dim, n_params, base=4, depth=2).eval()


def perturb_head(model: MultiResUNet, seed: int = 1, scale: float = 0.5) -> MultiResUNet:
    """Give the (zero-initialised) head random weights, so the model outputs a non-trivial displacement."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        model.head.weight.copy_(scale * torch.randn(model.head.weight.shape, generator=g))
        model.head.bias.copy_(0.1 * scale * torch.randn(model.head.bias.shape, generator=g))
    return model


def smooth_density(x: np.ndarray) -> np.ndarray:
    return 1.0 + 0.5 * np.sin(np.pi * x[..., 0]) * np.cos(np.pi * x[..., 1])


# ----------------------------------------------------------------------------------------------- shapes


@pytest.mark.parametrize("n", [17, 33, 51, 64, 97])
def test_output_size_equals_input_size_2d(n):
    model = tiny(2)
    with torch.no_grad():
        out = model(torch.rand(1, 3, n, n))
    assert out.shape == (1, 2, n, n)


@pytest.mark.parametrize("n", [9, 17, 24, 33])
def test_output_size_equals_input_size_3d(n):
    model = tiny(3)
    with torch.no_grad():
        out = model(torch.rand(1, 4, n, n, n))
    assert out.shape == (1, 3, n, n, n)


def test_non_square_grid_and_batch():
    model = tiny(2, n_params=2)
    with torch.no_grad():
        out = model(torch.rand(3, 4, 17, 22))
    assert out.shape == (3, 2, 17, 22)


def test_one_implementation_for_both_dimensions():
    m2, m3 = tiny(2), tiny(3)
    assert type(m2) is type(m3) is MultiResUNet
    assert isinstance(m2.head, torch.nn.Conv2d) and isinstance(m3.head, torch.nn.Conv3d)
    # the same module tree: every 2D parameter has a 3D counterpart with one more kernel axis
    p2, p3 = dict(m2.named_parameters()), dict(m3.named_parameters())
    assert set(p2) == set(p3)
    for k in p2:
        if p2[k].dim() == 4:  # conv weight (out, in, k, k)
            assert p3[k].dim() == 5 and p3[k].shape[2:] == (p2[k].shape[2],) * 3, k


def test_kwargs_rebuild_the_same_architecture():
    for attention in (True, False):
        m = MultiResUNet(2, 1, base=4, depth=2, attention=attention)
        rebuilt = MultiResUNet(**m.kwargs())
        assert set(rebuilt.state_dict()) == set(m.state_dict())


# ----------------------------------------------------------------------------------------------- identity at init


@pytest.mark.parametrize("dim,n", [(2, 17), (2, 24), (3, 9)])
def test_untrained_model_outputs_exactly_zero(dim, n):
    model = tiny(dim)
    x = torch.randn(2, dim + 1, *([n] * dim))
    with torch.no_grad():
        out = model(x)
    assert torch.count_nonzero(out) == 0


@pytest.mark.parametrize("boundary", BOUNDARIES)
@pytest.mark.parametrize("dim", [2, 3])
def test_untrained_map_is_identity_for_every_boundary(dim, boundary):
    n = 17 if dim == 2 else 9
    model = tiny(dim)
    pts = torch.as_tensor(grid_points(n, dim), dtype=torch.float32)
    x = torch.cat([pts.T.reshape(dim, *([n] * dim)), torch.zeros(1, *([n] * dim))])[None]
    with torch.no_grad():
        psi = model(x)[0].reshape(dim, -1).T
    mapped = apply_displacement(pts, psi, boundary)
    assert torch.equal(mapped, pts)


# ----------------------------------------------------------------------------------------------- boundary masks


@pytest.mark.parametrize("dim", [2, 3])
def test_square_mask_keeps_boundary_vertices_on_their_walls(dim):
    n = 9
    pts = torch.as_tensor(grid_points(n, dim))
    psi = torch.randn(pts.shape, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    mask = boundary_mask(pts, "square")
    mapped = apply_displacement(pts, psi, "square")
    for i in range(dim):
        for wall in (0.0, 1.0):
            on = pts[:, i] == wall
            assert on.any()
            # the component normal to the wall vanishes, so the vertex stays on the wall exactly
            assert torch.all(mask[on, i] == 0)
            assert torch.all(mapped[on, i] == wall)
    # the tangential components do move (the mask is not zero everywhere on the boundary)
    edge = (pts[:, 0] == 0) & (pts[:, 1] > 0) & (pts[:, 1] < 1)
    assert torch.all(mask[edge, 1] > 0)
    # mask = 4 x (1 - x) per component, 1 at the centre
    centre = torch.full((1, dim), 0.5, dtype=torch.float64)
    assert torch.allclose(boundary_mask(centre, "square"), torch.ones(1, dim, dtype=torch.float64))


@pytest.mark.parametrize("dim", [2, 3])
def test_fixed_mask_is_zero_on_the_whole_boundary(dim):
    mesh = grid_mesh(9, dim)
    pts = torch.as_tensor(mesh.points)
    on = torch.as_tensor(mesh.boundary_mask())
    mask = boundary_mask(pts, "fixed")
    assert torch.all(mask[on] == 0)
    assert torch.all(mask[~on] > 0)
    # the same factor for every component
    assert torch.all(mask == mask[:, :1])
    psi = torch.randn(pts.shape, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    mapped = apply_displacement(pts, psi, "fixed")
    assert torch.equal(mapped[on], pts[on])


def test_free_mask_is_ones():
    pts = torch.rand(50, 2, dtype=torch.float64)
    assert torch.equal(boundary_mask(pts, "free"), torch.ones_like(pts))
    psi = torch.randn(50, 2, dtype=torch.float64)
    assert torch.allclose(apply_displacement(pts, psi, "free"), pts + psi, atol=0, rtol=0)


def test_alpha_scales_the_displacement():
    pts = torch.rand(20, 2, dtype=torch.float64)
    psi = torch.randn(20, 2, dtype=torch.float64)
    alpha = torch.tensor([0.5, 2.0], dtype=torch.float64)
    got = apply_displacement(pts, psi, "square", alpha)
    want = pts + boundary_mask(pts, "square") * psi * alpha
    assert torch.allclose(got, want, atol=1e-15, rtol=0)


def test_unknown_boundary_raises():
    with pytest.raises(ValueError, match="unknown boundary"):
        boundary_mask(torch.rand(4, 2), "round")
    with pytest.raises(ValueError, match="unknown boundary"):
        apply_displacement(torch.rand(4, 2), torch.rand(4, 2), "periodic")


# ----------------------------------------------------------------------------------------------- validation


@pytest.mark.parametrize("n", [5, 9, 12])
def test_small_3d_grids_down_to_min_size(n):
    """3D grids whose coarsest level is smaller than the attention pooling kernel (4) work like in 2D."""
    model = tiny(3)
    with torch.no_grad():
        assert model(torch.rand(1, 4, n, n, n)).shape == (1, 3, n, n, n)
        assert tiny(2)(torch.rand(1, 3, n, n)).shape == (1, 2, n, n)


def test_bad_input_raises_value_error():
    model = tiny(2)
    with pytest.raises(ValueError, match="channels"):
        model(torch.rand(1, 4, 17, 17))  # 2 coordinates + 1 parameter expected
    with pytest.raises(ValueError, match="expects input of shape"):
        model(torch.rand(1, 3, 17, 17, 17))  # a 3D grid for a 2D model
    with pytest.raises(ValueError, match="expects input of shape"):
        model(torch.rand(3, 17, 17))  # no batch axis
    assert model.min_size == 5
    with pytest.raises(ValueError, match="too small"):
        model(torch.rand(1, 3, model.min_size - 1, 17))
    with torch.no_grad():
        assert model(torch.rand(1, 3, model.min_size, model.min_size)).shape == (1, 2, 5, 5)
    with pytest.raises(ValueError, match="dim must be 2 or 3"):
        MultiResUNet(dim=4)


# ----------------------------------------------------------------------------------------------- resolution


def _on_17_grid(disp: np.ndarray, n: int) -> np.ndarray:
    """Restrict a displacement on the n-grid to the vertices of the 17-grid (n = 16 k + 1)."""
    k = (n - 1) // 16
    assert 16 * k + 1 == n
    return disp.reshape(n, n, -1)[::k, ::k].reshape(-1, disp.shape[-1])


def test_map_at_fixed_work_grid_is_consistent_across_output_resolutions():
    """With the working grid fixed (work_n = 33), the outputs at n = 17, 33, 65 are one map: the network runs on the
    same input and its displacement is interpolated, which is exact at the vertices the grids share."""
    torch.manual_seed(0)
    sur = Surrogate(perturb_head(MultiResUNet(2, 1, base=4, depth=2)), TaskSpec("density", 2, "square"))
    field = smooth_density(grid_points(33, 2)).reshape(33, 33)  # the input, sampled once on a 33-grid
    res = {n: sur.map(field, n, work_n=33, repair=False) for n in (17, 33, 65)}  # the raw network map
    base = _on_17_grid(res[17].displacement, 17)
    assert np.abs(base).max() > 0.05  # a genuinely non-trivial map
    for n in (33, 65):
        assert res[n].info["work_n"] == 33
        np.testing.assert_allclose(_on_17_grid(res[n].displacement, n), base, atol=1e-5, rtol=0)
    # between shared vertices the network output psi at n = 65 is the bilinear interpolant of the one at n = 33
    # (free boundary, so that the displacement is psi itself and not B(x) psi)
    free = Surrogate(sur.model, TaskSpec("density", 2, "free"))
    d33 = free.map(field, 33, work_n=33, repair=False).displacement.reshape(33, 33, 2)
    d65 = free.map(field, 65, work_n=33, repair=False).displacement.reshape(65, 65, 2)
    np.testing.assert_allclose(d65[::2, ::2], d33, atol=1e-6, rtol=0)
    np.testing.assert_allclose(d65[1::2, ::2], 0.5 * (d33[:-1] + d33[1:]), atol=1e-5, rtol=0)
    np.testing.assert_allclose(d65[1::2, 1::2], 0.25 * (d33[:-1, :-1] + d33[1:, :-1] + d33[:-1, 1:] + d33[1:, 1:]),
                               atol=1e-5, rtol=0)


def test_native_resolutions_agree_loosely():
    """The network evaluated natively at two similar resolutions (33 and 35), compared on the 17-grid (raw maps:
    delivered ones of this random network would fall back towards the identity, ``rfmap.finish.repair.shorten_map``).

    Tolerance reasoning: convolutions act on grid indices, so a feature at a physical point depends on the grid
    spacing h, and zero padding creates boundary layers a few cells wide whose physical width scales with h.
    Nothing but training ties the outputs at different resolutions together: for the untrained network with a
    random head, the relative L2 difference measured over head seeds 0-3 was 0.25-0.56 (correlation 0.78-0.96)
    between 33 and 35, and about 1 (correlation < 0.6) between 33 and 65.  This is why ``Surrogate.map``
    evaluates the network on a working grid inside the training range and interpolates (test above).  The bound
    here (relative difference < 0.75, correlation > 0.6) only guards against gross inconsistencies such as
    swapped axes or misplaced interpolation.
    """
    torch.manual_seed(0)
    sur = Surrogate(perturb_head(MultiResUNet(2, 1, base=4, depth=2), seed=1), TaskSpec("density", 2, "square"))
    da = sur.map(smooth_density, 17, work_n=33, repair=False).displacement.ravel()
    db = sur.map(smooth_density, 17, work_n=35, repair=False).displacement.ravel()
    rel = np.linalg.norm(da - db) / np.linalg.norm(da)
    corr = np.corrcoef(da, db)[0, 1]
    assert rel < 0.75, rel
    assert corr > 0.6, corr
    # a transposed displacement (axes swapped) would not pass the same bound
    dt = sur.map(smooth_density, 17, work_n=35, repair=False).displacement.reshape(17, 17, 2)
    dt = dt.transpose(1, 0, 2)[..., ::-1]
    assert np.linalg.norm(da - dt.ravel()) / np.linalg.norm(da) > rel


@pytest.mark.parametrize("cin,cout,k,dil", [(8, 8, 3, 1), (8, 8, 3, 2), (8, 1, 1, 1), (3, 8, 1, 1)])
def test_conv3d_inference_path_matches_torch(cin, cout, k, dil):
    """The oneDNN inference path of blocks.Conv3d gives nn.Conv3d's output (batch 1, the shapes PyTorch would send
    to its slow kernel), keeps nn.Conv3d's state dict, and with gradients enabled is nn.Conv3d itself."""
    from rfmap.nn.blocks import Conv3d

    torch.manual_seed(0)
    ours = Conv3d(cin, cout, k, padding=dil * (k // 2), dilation=dil)
    ref = torch.nn.Conv3d(cin, cout, k, padding=dil * (k // 2), dilation=dil)
    ref.load_state_dict(ours.state_dict())
    assert list(ours.state_dict()) == list(ref.state_dict())
    x = torch.randn(1, cin, 12, 11, 10)
    with torch.no_grad():
        torch.testing.assert_close(ours(x), ref(x), rtol=1e-5, atol=1e-5)
    y = ours(x.requires_grad_())
    y.square().sum().backward()
    assert x.grad is not None and ours.weight.grad is not None
    torch.testing.assert_close(y, ref(x), rtol=0, atol=0)


@pytest.mark.parametrize("cin,cout,k,dil,batch,bias", [(8, 8, 3, 2, 1, True), (8, 1, 1, 1, 1, True),
                                                       (3, 8, 1, 1, 2, False), (16, 8, 3, 1, 1, True)])
def test_conv2d_inference_path_matches_torch(cin, cout, k, dil, batch, bias):
    """blocks.Conv2d's inference paths (1x1 as a matrix product, dilated through oneDNN) give nn.Conv2d's output,
    keep its state dict, and with gradients enabled the layer is nn.Conv2d itself (bit for bit)."""
    from rfmap.nn.blocks import Conv2d

    torch.manual_seed(0)
    ours = Conv2d(cin, cout, k, padding=dil * (k // 2), dilation=dil, bias=bias)
    ref = torch.nn.Conv2d(cin, cout, k, padding=dil * (k // 2), dilation=dil, bias=bias)
    ref.load_state_dict(ours.state_dict())
    assert list(ours.state_dict()) == list(ref.state_dict())
    x = torch.randn(batch, cin, 13, 11)
    with torch.no_grad():
        torch.testing.assert_close(ours(x), ref(x), rtol=1e-5, atol=1e-5)
        # a non-contiguous input takes the standard path
        xt = x.transpose(2, 3)
        torch.testing.assert_close(ours(xt), ref(xt), rtol=1e-5, atol=1e-5)
    y = ours(x.requires_grad_())
    y.square().sum().backward()
    assert x.grad is not None and ours.weight.grad is not None
    torch.testing.assert_close(y, ref(x), rtol=0, atol=0)
