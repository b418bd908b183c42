"""Test-time symmetrization: the transforms are symmetries of the grid, an equivariant operator is left unchanged,
and any operator becomes equivariant under the full group."""
import numpy as np
import pytest
import torch

from rfmap.nn.symmetry import (DEFAULT_SYMMETRY, SYMMETRY_GROUPS, Symmetry, resolve_symmetry, restore_displacement,
                            symmetries, symmetrized_displacement, transform_grid)


def gradient_field(grids: np.ndarray) -> torch.Tensor:
    """-grad(rho) by central differences: an exactly equivariant 'displacement' (B, N..) -> (B, d, N..)."""
    g = np.asarray(grids, dtype=np.float64)
    d = g.ndim - 1
    parts = np.gradient(g, axis=tuple(range(1, d + 1)))
    return -torch.as_tensor(np.stack(parts if d > 1 else [parts], 1))


def lopsided(grids: np.ndarray) -> torch.Tensor:
    """Not equivariant: the gradient plus a constant drift and a weight that grows along the first axis."""
    psi = gradient_field(grids)
    n = psi.shape[-1]
    ramp = torch.linspace(0, 1, n, dtype=psi.dtype).view(n, *([1] * (psi.dim() - 3)))
    return psi * (1 + ramp) + 0.01


@pytest.mark.parametrize("dim", [2, 3])
def test_group_sizes_and_identity_first(dim):
    import math
    sizes = {"flips": 2**dim, "permutations": math.factorial(dim), "cyclic": dim,
             "full": 2**dim * math.factorial(dim)}
    for group in SYMMETRY_GROUPS:
        syms = symmetries(dim, group)
        assert len(syms) == len(set(syms)) == sizes[group]
        assert syms[0] == Symmetry((), tuple(range(dim)))
    assert resolve_symmetry(True, dim) == DEFAULT_SYMMETRY[dim]
    assert resolve_symmetry(False, dim) is None and resolve_symmetry("cyclic", dim) == "cyclic"
    for bad in ("rotations", 3, 1.0):
        with pytest.raises(ValueError, match="symmetrize"):
            resolve_symmetry(bad, dim)
    with pytest.raises(ValueError, match="2D and 3D"):
        symmetries(4, "full")


@pytest.mark.parametrize("dim, n", [(2, 9), (3, 7)])
def test_restore_inverts_the_transform_of_an_equivariant_operator(dim, n):
    """For an equivariant operator, the restored displacement of every transformed field is the displacement of
    the field itself (to float64 round-off), and the symmetrized operator equals the operator."""
    rng = np.random.default_rng(0)
    grids = rng.random((2,) + (n,) * dim)
    ref = gradient_field(grids)
    for s in symmetries(dim, "full"):
        back = restore_displacement(gradient_field(transform_grid(grids, s)), s)
        torch.testing.assert_close(back, ref, rtol=0, atol=1e-12)
    for group in SYMMETRY_GROUPS:
        torch.testing.assert_close(symmetrized_displacement(gradient_field, grids, group), ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize("dim, n", [(2, 9), (3, 7)])
def test_full_symmetrization_makes_any_operator_equivariant(dim, n):
    rng = np.random.default_rng(1)
    grids = rng.random((1,) + (n,) * dim)
    plain = lopsided(grids)
    sym = symmetrized_displacement(lopsided, grids, "full")
    assert not torch.allclose(plain, sym, atol=1e-3)  # the operator is not equivariant to begin with
    for s in symmetries(dim, "full")[1:]:
        # symmetrize(rho o g), restored, equals symmetrize(rho): the symmetrized operator commutes with g
        moved = restore_displacement(symmetrized_displacement(lopsided, transform_grid(grids, s), "full"), s)
        torch.testing.assert_close(moved, sym, rtol=0, atol=1e-12)


@pytest.mark.parametrize("dim, n", [(2, 9), (3, 7)])
def test_batched_copies_match_one_at_a_time(dim, n):
    """Stacking the copies into batches changes how often the operator runs (ceil(|S| / copies per batch)), not the
    result (float64 round-off); a batch of one point per call is the sequential evaluation."""
    grids = np.random.default_rng(4).random((2,) + (n,) * dim)
    calls = []

    def counted(g):
        calls.append(g.shape[0])
        return lopsided(g)

    one = symmetrized_displacement(counted, grids, "full", batch_points=1)
    assert calls == [2] * len(symmetries(dim, "full"))
    for copies in (3, 1000):
        calls.clear()
        out = symmetrized_displacement(counted, grids, "full", batch_points=copies * grids.size)
        size = len(symmetries(dim, "full"))
        assert len(calls) == -(-size // min(copies, size)) and sum(calls) == 2 * size
        torch.testing.assert_close(out, one, rtol=0, atol=1e-12)


def _random_surrogate(dim, boundary="square"):
    from rfmap.surrogate import Surrogate
    from rfmap.tasks import TaskSpec

    sur = Surrogate.untrained(TaskSpec("density", dim, boundary), base=4, depth=2, name="sym-test",
                              n_range=[9, 17])
    gen = torch.Generator().manual_seed(3)
    with torch.no_grad():  # a network that moves points (the untrained head is zero) and is not equivariant
        for p in sur.model.parameters():
            p.add_(0.05 * torch.randn(p.shape, generator=gen))
    return sur


@pytest.mark.parametrize("dim, n, boundary", [(2, 13, "square"), (2, 13, "free"), (3, 9, "square")])
def test_symmetrized_surrogate_map_is_equivariant(dim, n, boundary):
    """With the full group, the map of a transformed density is the transformed map (float32 round-off); the plain
    network map is not; the network runs once per symmetry (info records the group)."""
    sur = _random_surrogate(dim, boundary)
    rng = np.random.default_rng(2)
    rho = 1.0 + rng.random((n,) * dim)
    x = torch.as_tensor(sur.map(rho, repair=False).ref_points)

    def disp(field, sym):
        r = sur.map(field, repair=False, symmetrize=sym)
        d = torch.as_tensor(r.mapped_points) - x
        return r, d.T.reshape(1, dim, *(n,) * dim)

    r, d_sym = disp(rho, "full")
    assert r.info["symmetrize"] == "full" and r.info["work_n"] == n
    _, d_plain = disp(rho, False)
    assert float((d_plain - d_sym).abs().max()) > 1e-3
    for s in symmetries(dim, "full")[1:]:
        moved = transform_grid(rho[None], s)[0]
        torch.testing.assert_close(restore_displacement(disp(moved, "full")[1], s), d_sym, rtol=0, atol=3e-5)
        if s == symmetries(dim, "full")[1]:
            assert float((restore_displacement(disp(moved, False)[1], s) - d_plain).abs().max()) > 1e-3
    batch = sur.map_batch([rho, rho[::-1].copy()], symmetrize="full", repair=False)
    np.testing.assert_allclose(batch[0].mapped_points, r.mapped_points, atol=1e-6)


def test_symmetrize_rejects_unknown_groups():
    with pytest.raises(ValueError, match="symmetrize must be"):
        _random_surrogate(2).map(np.ones((13, 13)), symmetrize="rotations")


def test_cli_symmetrize(tmp_path, capsys):
    from rfmap.cli.commands import main

    out = tmp_path / "m.npz"
    assert main(["map", "--model", "deq2d-square", "--field", "ring", "--n", "17", "--symmetrize", "flips",
                 "--out", str(out)]) == 0
    assert "mean over 4 symmetries (flips)" in capsys.readouterr().out and out.exists()
    bad = tmp_path / "b.npz"
    with pytest.raises(SystemExit) as e:
        main(["map", "--model", "deq2d-square", "--field", "ring", "--symmetrize", "rot", "--out", str(bad)])
    assert e.value.code == 2 and not bad.exists()


def test_beltrami_coefficient_transforms_as_the_conjugated_map():
    """For an exact random map f and each symmetry g of the square (g x = A x + b), the coefficient of
    g o f o g^-1, computed from its Jacobian A J_f(g^-1 x) A^-1, equals transform_grid of f's coefficient
    (to 1e-12)."""
    from rfmap.core.geometry import beltrami_from_jacobian
    from rfmap.core.mesh import grid_points
    from rfmap.fields.random import RandomBeltramiConfig, RandomMap

    n = 11
    f = RandomMap(np.random.default_rng(4), RandomBeltramiConfig(sup=(0.5, 0.5), modes=(3, 3)))
    x = grid_points(n, 2)
    mu = f.mu(x).reshape(1, n, n)
    for s in symmetries(2, "full"):
        # the affine map g of the array transform: transform_grid(h)[idx] = h[g^-1 applied to idx]
        # g^-1(x), the old coordinates of a new point x: undo the permutation, then the reflections
        y = x[:, np.argsort(s.perm)]
        y = np.where(np.isin(np.arange(2), s.flips), 1 - y, y)
        A = np.eye(2)[list(s.perm)]  # new axis k reads old axis perm[k]
        refl = np.diag([-1.0 if k in s.flips else 1.0 for k in range(2)])
        G = np.linalg.inv(A @ refl)  # dy/dx, the linear part of g^-1
        Jy = f.jacobian(y)
        J = np.linalg.inv(G) @ Jy @ G  # Jacobian of g o f o g^-1 at x
        expected = beltrami_from_jacobian(torch.as_tensor(J)).numpy().reshape(1, n, n)
        np.testing.assert_allclose(transform_grid(mu, s), expected, atol=1e-12)


@pytest.mark.parametrize("dim, n", [(2, 13), (3, 9)])
def test_surrogate_batched_symmetrization_matches_sequential(dim, n):
    """The network's batched copies agree with one evaluation per symmetry to float32 round-off."""
    sur = _random_surrogate(dim)
    grids = (1.0 + np.random.default_rng(5).random((1,) + (n,) * dim)).astype(np.float32)
    batched = sur.displacement(grids, symmetrize="full")
    seq = symmetrized_displacement(sur.displacement, grids, "full", batch_points=1)
    assert batched.abs().max() > 1e-3
    torch.testing.assert_close(batched, seq, rtol=0, atol=1e-5)
