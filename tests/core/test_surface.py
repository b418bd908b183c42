"""Boundary surfaces of tetrahedral meshes and their self-intersections (rfmap.core.surface), and the 3D free-boundary
repair that keeps the surface embedded."""
import numpy as np
import pytest

from rfmap.core.mesh import grid_mesh
from rfmap.finish.repair import fold_free, repair_map
from rfmap.fields.hard import self_crossing_map
from rfmap.paper.folding import first_folding
from rfmap.core.surface import boundary_faces, grid_boundary_faces, grid_surface_intersections, surface_intersections


@pytest.mark.parametrize("n", [2, 5, 9])
def test_boundary_faces_of_the_grid_cube(n):
    """12 (N-1)^2 triangles, each on a face of the cube, normals pointing out, area summing to 6."""
    m = grid_mesh(n, 3)
    f = boundary_faces(m.elements, m.points)
    assert f.shape == (12 * (n - 1) ** 2, 3)
    p = m.points[f]
    on_face = np.any(np.all(np.isclose(p, 0.0), 1) | np.all(np.isclose(p, 1.0), 1), 1)
    assert on_face.all()
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert np.all(np.einsum("ij,ij->i", nrm, p.mean(1) - 0.5) > 0)
    np.testing.assert_allclose(0.5 * np.linalg.norm(nrm, axis=1).sum(), 6.0, rtol=1e-12)
    assert np.array_equal(grid_boundary_faces(n), f)


def test_identity_and_smooth_maps_are_embedded():
    m = grid_mesh(12, 3)
    f = grid_boundary_faces(12)
    assert len(surface_intersections(m.points, f)) == 0
    y = m.points + 0.03 * np.sin(7 * m.points[:, [1, 2, 0]])
    assert len(surface_intersections(y, f)) == 0


def test_two_overlapping_cubes_intersect_where_expected():
    """Two cube surfaces offset by half their side cross along six segments; no triangle far from them is listed."""
    m = grid_mesh(5, 3)
    f = boundary_faces(m.elements)
    pts = np.concatenate([m.points, m.points + 0.5])
    faces = np.concatenate([f, f + len(m.points)])
    pairs = surface_intersections(pts, faces)
    assert len(pairs) > 0
    assert np.all(pairs[:, 0] < len(f)) and np.all(pairs[:, 1] >= len(f))  # each surface is embedded on its own
    # every listed triangle of the first cube touches the region x, y, z >= 0.5 - h
    a = pts[faces[pairs[:, 0]]]
    assert np.all(a.max(1) >= 0.5 - 0.25 - 1e-12)


def _segment_hits_triangle(p, q, tri, eps=1e-12):
    """Independent oracle: does the segment pq cross the triangle's interior (Möller–Trumbore)?"""
    d = q - p
    e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
    h = np.cross(d, e2)
    a = e1 @ h
    if abs(a) < eps:
        return False
    s = p - tri[0]
    u = (s @ h) / a
    qv = np.cross(s, e1)
    v = (d @ qv) / a
    t = (e2 @ qv) / a
    return u > eps and v > eps and u + v < 1 - eps and eps < t < 1 - eps


def test_random_triangles_against_an_edge_crossing_oracle():
    """For triangles in general position, two triangles intersect iff an edge of one crosses the other."""
    rng = np.random.default_rng(3)
    k = 60
    centers = rng.random((k, 3))
    pts = (centers[:, None, :] + 0.15 * rng.standard_normal((k, 3, 3))).reshape(-1, 3)
    faces = np.arange(3 * k).reshape(k, 3)
    got = {tuple(r) for r in surface_intersections(pts, faces).tolist()}
    want = set()
    for i in range(k):
        for j in range(i + 1, k):
            A, B = pts[faces[i]], pts[faces[j]]
            if any(_segment_hits_triangle(A[e], A[(e + 1) % 3], B) for e in range(3)) or \
                    any(_segment_hits_triangle(B[e], B[(e + 1) % 3], A) for e in range(3)):
                want.add((i, j))
    assert len(want) > 20
    assert got == want


def test_coplanar_overlap_is_found_and_coplanar_neighbours_are_not():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 0], [1.2, 0.2, 0], [0.2, 1.2, 0],
                    [2, 0, 0], [3, 0, 0], [2, 1, 0]], float)
    faces = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]])
    assert surface_intersections(pts, faces).tolist() == [[0, 1]]


def test_bad_input():
    with pytest.raises(ValueError, match="shape"):
        boundary_faces(np.zeros((3, 3), int))
    with pytest.raises(ValueError, match="NaN"):
        surface_intersections(np.full((3, 3), np.nan), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match=r"\(P, 3\)"):
        surface_intersections(np.zeros((3, 2)), np.array([[0, 1, 2]]))


def test_wrapped_cube_is_fold_free_but_not_embedded_and_gets_repaired():
    ref, u, el = self_crossing_map(9, 1.3)
    n = 9
    assert fold_free(u, el, grid_n=n, boundary="square")  # every tetrahedron is positive
    assert not fold_free(u, el, grid_n=n, boundary="free")  # but the surface crosses itself
    out, rep = repair_map(ref, u, el, boundary="free", grid_n=n)
    assert rep["needed"] and rep["method"].endswith("+surface")
    assert rep["surface_crossings_before"] > 0 and rep["surface_crossings_after"] == 0
    assert 0 < rep["surface_scale"] < 1
    assert fold_free(out, el, grid_n=n, boundary="free")
    # below one full turn the bent cube is embedded and left alone
    ref, u, el = self_crossing_map(9, 0.8)
    out, rep = repair_map(ref, u, el, boundary="free", grid_n=n)
    assert not rep["needed"] and out is u


def test_first_folding_returns_the_first_seed_whose_raw_map_folds():
    from rfmap import Surrogate
    from rfmap.fields.hard import hard_density

    sur = Surrogate.pretrained("deq2d-square")
    seed, field = first_folding(sur, 48, seed=0, tries=40)
    assert sur.map(field, 48, preprocess=False, repair=False).metrics().n_flipped > 0
    np.testing.assert_array_equal(field, hard_density(np.random.default_rng(seed), 48, 2))
    for s in range(seed):
        earlier = hard_density(np.random.default_rng(s), 48, 2)
        assert sur.map(earlier, 48, preprocess=False, repair=False).metrics().n_flipped == 0
    with pytest.raises(RuntimeError, match="folded on none"):
        first_folding(sur, 48, seed=seed + 1, tries=0)


def _pushed(x, axis, side_value, to, half=0.3):
    """Move the middle of one face of the cube (coordinate ``axis`` = ``side_value``) to ``to`` along that axis."""
    y = x.copy()
    others = [a for a in range(3) if a != axis]
    sel = (x[:, axis] == side_value) & np.all(np.abs(x[:, others] - 0.5) < half, axis=1)
    y[sel, axis] = to
    return y


@pytest.mark.parametrize("case", ["identity", "smooth", "noisy", "top-through-bottom", "side-through-side",
                                  "bent"])
def test_grid_fast_path_finds_exactly_the_generic_pairs(case):
    """The per-face fast path (faces certified by their projection, then only pairs across faces) returns the
    same pairs as the generic search, both where it applies (a face pushed through the opposite one keeps its
    projection) and where it falls back (the bent cube)."""
    n = 12
    x = grid_mesh(n, 3).points
    rng = np.random.default_rng(0)
    y = {"identity": x, "smooth": x + 0.05 * np.sin(5 * x[:, [1, 2, 0]] + 1),
         "noisy": x + 0.02 * rng.standard_normal(x.shape),
         "top-through-bottom": _pushed(x, 2, 1.0, -0.2), "side-through-side": _pushed(x, 0, 1.0, -0.3),
         "bent": None}[case]
    if y is None:
        y = self_crossing_map(n, 1.3)[1]
    want = surface_intersections(y, grid_boundary_faces(n))
    got = grid_surface_intersections(y, n)
    np.testing.assert_array_equal(got, want)
    assert (len(want) > 0) == (case in ("top-through-bottom", "side-through-side", "bent"))


def test_grid_fast_path_bad_input():
    with pytest.raises(ValueError, match="shape"):
        grid_surface_intersections(np.zeros((10, 3)), 3)
    with pytest.raises(ValueError, match="NaN"):
        grid_surface_intersections(np.full((27, 3), np.nan), 3)


def test_cli_repair_line_reports_surface_crossings():
    from rfmap.cli.commands import repair_summary

    ref, u, el = self_crossing_map(9, 1.3)
    line = repair_summary(repair_map(ref, u, el, boundary="free", grid_n=9)[1])
    assert "+surface" in line and "crossing boundary triangle pairs" in line and line.count("\n") == 0
    assert line.split("crossing boundary triangle pairs ")[1].split(",")[0].endswith("-> 0")
