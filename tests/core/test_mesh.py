"""Structured grids, their simplicial meshes and multilinear interpolation (rfmap.core.mesh)."""
import numpy as np
import pytest
import torch

from rfmap.core.mesh import (
    Mesh,
    check_dim,
    check_n,
    cube_tetrahedra,
    element_measures,
    grid_mesh,
    grid_points,
    grid_vertex_weights,
    interpolate,
    multilinear,
    vertex_weights,
    square_triangles,
)

TOL = 1e-12


# ----------------------------------------------------------------------------------------------- grid points
@pytest.mark.parametrize("n", [2, 3, 7])
def test_grid_points_ordering_2d(n):
    p = grid_points(n, 2)
    assert p.shape == (n * n, 2)
    for i in range(n):
        for j in range(n):
            np.testing.assert_allclose(p[i * n + j], np.array([i, j]) / (n - 1), rtol=0, atol=TOL)


@pytest.mark.parametrize("n", [2, 4])
def test_grid_points_ordering_3d(n):
    p = grid_points(n, 3)
    assert p.shape == (n**3, 3)
    for i in range(n):
        for j in range(n):
            for k in range(n):
                np.testing.assert_allclose(p[(i * n + j) * n + k], np.array([i, j, k]) / (n - 1), rtol=0, atol=TOL)


def test_grid_points_match_field_layout():
    """A field of shape (N, N) indexed [i, j] flattens to the vertex order of grid_points."""
    n = 5
    p = grid_points(n, 2)
    field = np.add.outer(10 * np.arange(n), np.arange(n))  # value 10 i + j at vertex (i, j)
    np.testing.assert_allclose(field.reshape(-1), 10 * p[:, 0] * (n - 1) + p[:, 1] * (n - 1), atol=1e-9)


# ----------------------------------------------------------------------------------------------- elements
@pytest.mark.parametrize("n", [2, 3, 6])
def test_triangle_count_and_indices(n):
    t = square_triangles(n)
    assert t.shape == (2 * (n - 1) ** 2, 3)
    assert t.dtype == np.int64
    assert t.min() == 0 and t.max() == n * n - 1
    # every vertex is used
    assert np.unique(t).size == n * n


@pytest.mark.parametrize("n", [2, 3, 5])
def test_tetra_count_and_indices(n):
    t = cube_tetrahedra(n)
    assert t.shape == (6 * (n - 1) ** 3, 4)
    assert t.dtype == np.int64
    assert t.min() == 0 and t.max() == n**3 - 1
    assert np.unique(t).size == n**3


@pytest.mark.parametrize("dim,n", [(2, 2), (2, 9), (3, 2), (3, 5)])
def test_reference_elements_positive_and_tile_the_domain(dim, n):
    m = grid_mesh(n, dim)
    meas = element_measures(m.points, m.elements)
    h = 1.0 / (n - 1)
    expected = h**dim / (2 if dim == 2 else 6)
    assert (meas > 0).all()
    np.testing.assert_allclose(meas, expected, rtol=1e-12)
    assert abs(meas.sum() - 1.0) < 1e-12


def test_element_measures_torch_and_numpy_agree():
    m = grid_mesh(4, 2)
    pts = torch.as_tensor(m.points)
    a = element_measures(pts, m.elements)
    assert isinstance(a, torch.Tensor)
    np.testing.assert_allclose(a.numpy(), element_measures(m.points, m.elements), atol=TOL)


def test_2d_diagonal_runs_from_lower_right_to_upper_left():
    """Every grid square is cut by the diagonal (x+h, y) -- (x, y+h), never by (x, y) -- (x+h, y+h)."""
    n = 4
    m = grid_mesh(n, 2)
    h = m.h
    edges = set()
    for tri in m.elements:
        for a in range(3):
            for b in range(a + 1, 3):
                edges.add(frozenset((int(tri[a]), int(tri[b]))))
    for i in range(n - 1):
        for j in range(n - 1):
            v00, v10, v01, v11 = i * n + j, (i + 1) * n + j, i * n + j + 1, (i + 1) * n + j + 1
            assert frozenset((v10, v01)) in edges
            assert frozenset((v00, v11)) not in edges
    # the first square's triangles, explicitly
    p = m.points
    t1, t2 = m.elements[0], m.elements[(n - 1) ** 2]
    np.testing.assert_allclose(p[t1], [[0, 0], [h, 0], [0, h]], atol=TOL)
    np.testing.assert_allclose(p[t2], [[h, 0], [h, h], [0, h]], atol=TOL)


def test_3d_kuhn_split_shares_main_diagonal():
    m = grid_mesh(2, 3)
    # every tetrahedron of the single cube contains the corners (0,0,0) and (1,1,1)
    for tet in m.elements:
        assert 0 in tet and 7 in tet
    assert len({tuple(sorted(t)) for t in m.elements}) == 6


def test_mesh_properties():
    m = grid_mesh(5, 3)
    assert isinstance(m, Mesh)
    assert m.shape == (5, 5, 5)
    assert m.h == pytest.approx(0.25)
    bm = m.boundary_mask()
    assert bm.shape == (125,)
    assert bm.sum() == 125 - 27
    on_boundary = ((m.points == 0) | (m.points == 1)).any(-1)
    np.testing.assert_array_equal(bm, on_boundary)


@pytest.mark.parametrize("dim", [2, 3])
def test_grid_mesh_is_cached_but_returns_writable_copies(dim):
    a, b = grid_mesh(6, dim), grid_mesh(6, dim)
    np.testing.assert_array_equal(a.elements, b.elements)
    assert a.elements is not b.elements and a.points is not b.points
    a.points[0] = 0.5  # the caller owns its arrays: changing them leaves the cache alone
    a.elements[0] = 0
    c = grid_mesh(6, dim)
    np.testing.assert_array_equal(c.points, grid_points(6, dim))
    np.testing.assert_array_equal(c.elements[0], b.elements[0])


@pytest.mark.parametrize("dim", [2, 3])
def test_cached_grid_vertex_weights_equal_the_generic_ones(dim):
    m = grid_mesh(7, dim)
    np.testing.assert_allclose(grid_vertex_weights(7, dim), vertex_weights(m.points, m.elements), rtol=0, atol=1e-15)
    assert grid_vertex_weights(7, dim).sum() == pytest.approx(1.0, abs=1e-13)


# ----------------------------------------------------------------------------------------------- validation
def test_check_n_and_dim():
    assert check_n(3) == 3
    assert check_n(np.int64(7)) == 7
    for bad in (2, 0, -1, 2.5, "5", True):
        with pytest.raises(ValueError):
            check_n(bad)
    assert check_dim(2) == 2 and check_dim(3) == 3
    for bad in (1, 4, 0):
        with pytest.raises(ValueError):
            check_dim(bad)
    with pytest.raises(ValueError):
        grid_mesh(1, 2)
    with pytest.raises(ValueError):
        grid_points(5, 4)


# ----------------------------------------------------------------------------------------------- interpolation
def _bilinear(x, c):
    return c[0] + c[1] * x[..., 0] + c[2] * x[..., 1] + c[3] * x[..., 0] * x[..., 1]


def _trilinear(x, c):
    X, Y, Z = x[..., 0], x[..., 1], x[..., 2]
    return (c[0] + c[1] * X + c[2] * Y + c[3] * Z + c[4] * X * Y + c[5] * Y * Z + c[6] * X * Z
            + c[7] * X * Y * Z)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_interpolation_reproduces_multilinear_functions(dim, backend):
    rng = np.random.default_rng(1)
    n, batch, channels, npts = (9 if dim == 2 else 5), 3, 2, 200
    grid = grid_points(n, dim)
    coef = rng.normal(size=(batch, channels, 8))
    fn = _bilinear if dim == 2 else _trilinear
    values = np.stack([np.stack([fn(grid, coef[b, c]).reshape((n,) * dim) for c in range(channels)])
                       for b in range(batch)])
    pts = rng.random((batch, npts, dim))
    pts[:, :2 ** dim] = grid_points(2, dim)  # include the corners
    expected = np.stack([np.stack([fn(pts[b], coef[b, c]) for c in range(channels)], -1) for b in range(batch)])
    if backend == "torch":
        out = interpolate(torch.as_tensor(values), torch.as_tensor(pts))
        assert isinstance(out, torch.Tensor)
        out = out.numpy()
    else:
        out = interpolate(values, pts)
        assert isinstance(out, np.ndarray)
    assert out.shape == (batch, npts, channels)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12)


def test_interpolation_shared_points_and_grid_nodes():
    rng = np.random.default_rng(2)
    n = 6
    values = rng.normal(size=(2, 1, n, n))
    out = interpolate(values, grid_points(n, 2))  # (P, 2) broadcast over the batch
    np.testing.assert_allclose(out[..., 0], values.reshape(2, -1), atol=1e-12)


def test_interpolation_anisotropic_grid():
    """Grids with different sizes per axis: the x1 axis is the first grid axis."""
    xs, ys = np.linspace(0, 1, 4), np.linspace(0, 1, 7)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    values = (1 + 2 * X - 3 * Y)[None, None]
    pts = np.array([[0.3, 0.9], [0.75, 0.1]])
    np.testing.assert_allclose(interpolate(values, pts)[0, :, 0], 1 + 2 * pts[:, 0] - 3 * pts[:, 1], atol=1e-12)


def test_interpolation_is_differentiable_in_values():
    values = torch.rand(1, 1, 5, 5, dtype=torch.float64, requires_grad=True)
    pts = torch.rand(1, 10, 2, dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda v: interpolate(v, pts), (values,))


@pytest.mark.parametrize("bad", [[[1.1, 0.5]], [[-0.01, 0.5]], [[0.5, 2.0]], [[np.nan, 0.5]]])
def test_interpolation_rejects_points_outside_the_domain(bad):
    values = np.zeros((1, 1, 4, 4))
    with pytest.raises(ValueError):
        interpolate(values, np.array(bad))


def test_interpolation_rejects_bad_shapes():
    with pytest.raises(ValueError):
        interpolate(np.zeros((1, 1, 4, 4)), np.full((5, 3), 0.5))  # 3D points on a 2D grid
    with pytest.raises(ValueError):
        interpolate(np.zeros((1, 4, 4)), np.full((5, 2), 0.5))  # no channel axis
    with pytest.raises(ValueError):
        interpolate(np.zeros((2, 1, 4, 4)), np.full((3, 5, 2), 0.5))  # batch mismatch


def test_grid_too_large_for_memory_is_refused_before_allocation():
    """A grid whose maps cannot fit in the available memory is a ValueError naming N and the memory, raised before
    anything is allocated (N = 10**6 in 2D would need about 4 TB)."""
    from rfmap.core.mesh import BYTES_PER_VERTEX, check_grid_memory

    with pytest.raises(ValueError, match=r"N=1000000 is too large for this machine's memory"):
        grid_points(10**6, 2)
    with pytest.raises(ValueError, match="too large"):
        grid_mesh(10**5, 3)
    # the rule itself: refused exactly when N^d bytes-per-vertex exceed what is available
    need = 1000**2 * BYTES_PER_VERTEX[2]
    assert check_grid_memory(1000, 2, available=need) == need
    with pytest.raises(ValueError, match="GiB available"):
        check_grid_memory(1000, 2, available=need - 1)
    assert check_grid_memory(32, 3, available=0) == 32**3 * BYTES_PER_VERTEX[3]  # small grids are never refused


@pytest.mark.parametrize("dim", [2, 3])
def test_multilinear_of_float32_planes_reproduces_multilinear_functions_in_single_precision(dim):
    """:func:`rfmap.core.mesh.multilinear` of float32 planes (the cartogram flow's tables) returns float32 values of a
    multilinear function within float32 rounding (1e-6 of its largest value), and of float64 planes float64 values
    to 1e-12."""
    rng = np.random.default_rng(3)
    n = 9 if dim == 2 else 5
    grid = grid_points(n, dim)
    fn = _bilinear if dim == 2 else _trilinear
    coef = rng.normal(size=(2, 8))
    planes = np.stack([fn(grid, c).reshape((n,) * dim) for c in coef])
    pts = rng.random((300, dim))
    expected = np.stack([fn(pts, c) for c in coef], -1)
    single = multilinear(planes.astype(np.float32), pts * (n - 1))
    double = multilinear(planes, pts * (n - 1))
    assert single.dtype == np.float32 and double.dtype == np.float64
    np.testing.assert_allclose(single, expected, rtol=0, atol=1e-6 * np.abs(expected).max())
    np.testing.assert_allclose(double, expected, rtol=0, atol=1e-12)
