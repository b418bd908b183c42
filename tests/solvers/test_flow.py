"""Tests of the flow-based density-equalizing map (rfmap.solvers.flow) and of the neural warm start (rfmap.finish.polish).

Exact answers: the Poisson flux against direct cosine sums, uniform density -> identity, exact rasterization of a
mesh; agreement with the diffusion solver (its fixed point); no folded element on the hard fields of rfmap.fields.hard;
input validation.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from rfmap.fields import sample_density
from rfmap.core.mesh import grid_mesh
from rfmap.solvers import SOLVERS, get_solver, solve_dem, solve_flow
from rfmap.solvers.diffusion import cosine_coefficients
from rfmap.solvers.flow import F32_MARGIN, _turned_over, lumped_residual, rasterize_elements, vertex_residual
from rfmap.solvers.spectral import gaussian_blur, poisson_flux
from rfmap.solvers.residual import _measures
from rfmap.fields.hard import hard_density


def wall_checks(res) -> None:
    ref, out = res.ref_points, res.mapped_points
    on_wall = (ref == 0.0) | (ref == 1.0)
    assert np.array_equal(out[on_wall], ref[on_wall])
    assert out.min() >= 0.0 and out.max() <= 1.0


def test_registry_and_dispatch():
    assert get_solver("flow") is solve_flow and "flow" in SOLVERS
    with pytest.raises(ValueError, match="unknown density-equalizing method"):
        solve_dem(np.ones((5, 5)), method="fast")


@pytest.mark.parametrize("d,m", [(2, 9), (3, 6)])
def test_poisson_flux_matches_cosine_sums(d, m):
    """-grad(phi) with Laplace(phi) = mean - rho, evaluated by direct sums over the cosine modes."""
    rng = np.random.default_rng(1)
    v = 1.0 + rng.random((m,) * d)
    a = cosine_coefficients(v)
    x = np.linspace(0, 1, m)
    k = np.arange(m)
    C, S = np.cos(math.pi * np.outer(x, k)), -math.pi * k * np.sin(math.pi * np.outer(x, k))
    K2 = sum(np.meshgrid(*([(math.pi * k) ** 2] * d), indexing="ij"))
    K2.flat[0] = 1.0
    phi = a / K2
    phi.flat[0] = 0.0
    for i in range(d):
        mats = [S if j == i else C for j in range(d)]
        direct = phi
        for ax, M in enumerate(mats):  # contract mode axis ax with the table
            direct = np.moveaxis(np.tensordot(M, direct, axes=([1], [ax])), 0, ax)
        np.testing.assert_allclose(poisson_flux(v)[i], -direct, atol=1e-13)
    walls = poisson_flux(v)[0]
    assert np.abs(walls[0]).max() == 0 and np.abs(walls[-1]).max() == 0  # no flux through the walls
    # the flow's single-precision solve: float32 throughout, equal to the double one to float32 round-off
    f32 = poisson_flux(v, dtype=np.float32)
    assert f32.dtype == np.float32 and cosine_coefficients(v.astype(np.float32)).dtype == np.float32
    np.testing.assert_allclose(f32, poisson_flux(v), atol=2e-6 * np.abs(poisson_flux(v)).max())
    assert np.abs(f32[0][0]).max() == 0 and np.abs(f32[0][-1]).max() == 0


def test_gaussian_blur_keeps_mean_and_constants():
    v = np.random.default_rng(2).random((17, 17))
    b = gaussian_blur(v, 0.05)
    assert abs(cosine_coefficients(b)[0, 0] - cosine_coefficients(v)[0, 0]) < 1e-14
    assert b.std() < v.std()
    np.testing.assert_allclose(gaussian_blur(np.full((9, 9, 9), 3.0), 0.1), 3.0, atol=1e-13)


@pytest.mark.parametrize("d", [2, 3])
def test_rasterize_identity_mesh(d):
    """Every node of a 2x finer grid lies in an element of the grid mesh; values are the element's."""
    mesh = grid_mesh(5, d)
    vals = np.arange(len(mesh.elements), dtype=float)
    out = rasterize_elements(mesh.points, mesh.elements, vals, 9, fill=-1.0)
    assert (out >= 0).all()
    # an interior node at a cell centre (odd indices) lies inside one of the cell's elements
    cen = mesh.points[mesh.elements].mean(1)
    node = np.full(d, 1) / 8
    inside = [e for e in range(len(cen)) if np.all(np.abs(cen[e] - node) < 1 / 4)]
    assert out[(1,) * d] in vals[inside]


def _bent_mesh(n: int, d: int):
    """A fold-free, curved map of the N-grid mesh inside the unit square/cube (x_i -> x_i + 0.08 sin(pi x_i) x_j)."""
    mesh = grid_mesh(n, d)
    x = mesh.points
    y = x.copy()
    for i in range(d):
        y[:, i] = x[:, i] + 0.08 * np.sin(np.pi * x[:, i]) * x[:, (i + 1) % d]
    assert (_measures(y, mesh.elements) > 0).all()
    return mesh, y


@pytest.mark.parametrize("d", [2, 3])
def test_rasterize_vertex_values_is_exact_for_affine_fields(d):
    """P1 rasterization of vertex values a.y + b on a curved mesh gives a.y + b at every covered raster node (to
    round-off), and the nodes outside the image get the fill."""
    mesh, y = _bent_mesh(7 if d == 2 else 5, d)
    y = 0.1 + 0.8 * y  # leave a frame of uncovered nodes
    a = np.array([0.7, -1.3, 2.1][:d])
    out = rasterize_elements(y, mesh.elements, y @ a + 0.4, 21, fill=-9.0, at="vertices")
    nodes = np.stack(np.meshgrid(*[np.linspace(0, 1, 21)] * d, indexing="ij"), -1)
    covered = out != -9.0
    assert covered.mean() > 0.3 and not covered[(0,) * d]
    np.testing.assert_allclose(out[covered], nodes[covered] @ a + 0.4, atol=1e-12)


@pytest.mark.parametrize("d,shrink,refine", [(2, 1.0, 3), (2, 0.6, 3), (3, 1.0, 3), (3, 0.6, 3), (2, 1.0, 5),
                                             (3, 1.0, 8)])
def test_rasterize_grid_walk_matches_the_element_scan(d, shrink, refine):
    """On a map of the grid mesh the Newton walk (with the element scan for the nodes it leaves) gives the same
    raster as scanning every element; with the image shrunk into the box (a free boundary's sea) the uncovered
    nodes keep the fill.  The finer rasters (41 nodes per side) start the walk from a coarse walk's inverse."""
    from rfmap.solvers.locate import WALK_COARSE, WALK_COARSE_MIN, _grid_side, _locate, _walk_grid

    n = 9 if d == 2 else 6
    mesh, y = _bent_mesh(n, d)
    y = 0.5 + shrink * (y - 0.5)
    m = refine * (n - 1) + 1
    assert ((m - 1) // WALK_COARSE + 1 >= WALK_COARSE_MIN) == (refine > 3)
    vals = np.random.default_rng(3).random(len(y))
    assert _grid_side(y, mesh.elements) == n and _grid_side(y, mesh.elements[::-1]) is None
    fast = rasterize_elements(y, mesh.elements, vals, m, fill=-1.0, at="vertices")
    slow = np.full(m**d, -1.0)
    for node, el, lam in _locate(y, mesh.elements, m, 1 << 20):
        v = vals[mesh.elements[el]]
        slow[node] = (1 - lam.sum(1)) * v[:, 0] + np.einsum("ki,ki->k", lam, v[:, 1:])
    np.testing.assert_allclose(fast.reshape(-1), slow, atol=1e-12)
    (node, _, _), left = _walk_grid(y, n, m)
    assert node.size > 0.5 * (slow != -1).sum()
    assert (slow == -1).any() == (shrink < 1)


@pytest.mark.parametrize("d,n", [(2, 33), (3, 17)])
def test_coarse_walk_inverse_is_a_good_start(d, n):
    """The walk's starting points from a 4x coarser raster (``_inverse_guess``) lie within 0.05 grid cells of the
    exact preimages of the raster nodes under a smooth map (the bounding-box guess: more than a cell off), and the
    walk from them finds the same nodes as from the bounding-box guess."""
    from rfmap.solvers.locate import WALK_STEPS, _inverse_guess, _walk_grid

    mesh, y = _bent_mesh(n, d)
    m = 2 * (n - 1) + 1
    nodes = np.stack(np.meshgrid(*[np.linspace(0, 1, m)] * d, indexing="ij"), -1).reshape(-1, d)

    def bend(x):  # the smooth map that _bent_mesh interpolates
        return np.stack([x[:, i] + 0.08 * np.sin(np.pi * x[:, i]) * x[:, (i + 1) % d] for i in range(d)], 1)

    guess = _inverse_guess(y, n, (m - 1) // 4 + 1, WALK_STEPS, nodes)
    box = np.clip((nodes - y.min(0)) / (y.max(0) - y.min(0)), 0.0, 1.0)
    err = [np.abs(bend(x) - nodes).max() * (n - 1) for x in (guess, box)]
    assert err[0] < 0.05 and err[1] > 1.0, err
    found = [np.sort(_walk_grid(y, n, m, coarse=c)[0][0]) for c in (4, 1)]
    np.testing.assert_array_equal(*found)


def test_rasterize_bad_arguments():
    mesh = grid_mesh(5, 2)
    with pytest.raises(ValueError, match="at must be"):
        rasterize_elements(mesh.points, mesh.elements, np.ones(len(mesh.elements)), 9, 0.0, at="faces")
    with pytest.raises(ValueError, match="vertices must have shape"):
        rasterize_elements(mesh.points, mesh.elements, np.ones(len(mesh.elements)), 9, 0.0, at="vertices")


@pytest.mark.parametrize("name,n,d", [("sin-cos", 33, 2), ("sin-cos-3d", 13, 3)])
def test_vertex_residual_recovers_a_vertex_density(name, n, d):
    """From the element means of a P1 density (the identity map) the least-squares vertex residual gives the vertex
    density back to within 1 % (the lumped residual, a one-element blur, is off by far more); a uniform residual
    on a curved map stays uniform."""
    mesh = grid_mesh(n, d)
    dens = sample_density(name, n).reshape(-1)
    meas = _measures(mesh.points, mesh.elements)
    pop = dens[mesh.elements].mean(1) * meas
    rel = np.abs(vertex_residual(mesh.elements, pop, meas, len(dens)) / dens - 1).max()
    lumped = np.abs(lumped_residual(mesh.elements, pop, meas, len(dens)) / dens - 1).max()
    assert rel < 0.01 and lumped > 5 * rel, (rel, lumped)
    _, y = _bent_mesh(n, d)
    my = _measures(y, mesh.elements)
    np.testing.assert_allclose(vertex_residual(mesh.elements, 2.5 * my, my, len(dens)), 2.5, rtol=1e-12)


@pytest.mark.parametrize("name,n,boundary", [("sin-cos", 33, "square"), ("exp-log", 33, "square"),
                                             ("exp-log", 33, "free"), ("sin-cos-3d", 13, "square")])
def test_warm_start_from_the_identity_is_the_cold_flow(name, n, boundary):
    """The warm-start route (the residual of the starting map, rasterized) started at the identity reproduces the
    cold flow's Std(rho~_map) to 0.5 % on the square (reading the element residual at the raster nodes was 1.4x
    worse).  With a free boundary the warm route fills the sea with the domain's mean residual instead of the cold
    flow's balanced sea level (off by O(h) at the coast): within 10 % there."""
    dens = sample_density(name, n)
    cold = solve_flow(dens, boundary=boundary)
    warm = solve_flow(dens, boundary=boundary, start=grid_mesh(n, dens.ndim).points, stall_blurs=())
    rel = 5e-3 if boundary == "square" else 0.1
    assert warm.metrics().std_rho_map == pytest.approx(cold.metrics().std_rho_map, rel=rel)
    assert warm.metrics().n_flipped == 0


@pytest.mark.parametrize("d,boundary", [(2, "square"), (2, "free"), (3, "square"), (3, "free")])
def test_uniform_density_is_identity(d, boundary):
    n = 9 if d == 2 else 6
    res = solve_flow(np.full((n,) * d, 2.5), boundary=boundary)
    np.testing.assert_allclose(res.mapped_points, res.ref_points, atol=1e-12)
    assert res.info["passes"] == 0  # nothing to equalize


@pytest.mark.parametrize("name,n,boundary", [("sin-cos", 51, "square"), ("exp-log", 51, "free"),
                                             ("ring", 33, "square"), ("sin-cos-3d", 17, "square"),
                                             ("sin-cos-3d", 17, "free")])
def test_same_fixed_point_as_diffusion(name, n, boundary):
    """Both methods reach the same final Std(rho~_map) (within 10 %) and, on smooth fields, nearly the same map."""
    dens = sample_density(name, n)
    flow = solve_dem(dens, method="flow", boundary=boundary)
    diff = solve_dem(dens, boundary=boundary)
    s_flow, s_diff = flow.metrics().std_rho_map, diff.metrics().std_rho_map
    assert s_flow <= 1.1 * s_diff + 1e-3, (s_flow, s_diff)
    assert flow.metrics().n_flipped == 0
    assert np.abs(flow.mapped_points - diff.mapped_points).max() < 1.0 / (n - 1)  # within one grid cell
    if boundary == "square":
        wall_checks(flow)
    assert flow.info["method"] == "flow" and flow.time > 0


@pytest.mark.parametrize("d,n,seed", [(2, 33, 0), (2, 33, 1), (2, 33, 2), (3, 13, 0)])
def test_no_fold_on_hard_fields(d, n, seed):
    dens = hard_density(np.random.default_rng(seed), n, d)
    for boundary in ("square", "free"):
        res = solve_flow(dens, boundary=boundary)
        m = res.metrics()
        assert m.n_flipped == 0 and m.std_rho_map < 0.5 * m.std_rho_orig


def test_blended_sea_is_balanced_and_continuous_at_the_coast():
    """The blended sea keeps the balance of the abrupt one (the domain's mass is the box mean times its measure:
    the same affine equation, solved exactly), starts at the coast's own density and reaches its level at the blend
    width; blend 0 is the abrupt sea."""
    from rfmap.solvers.raster import balanced_sea as _balanced_sea
    from rfmap.solvers.spectral import contract as _contract, interval_weights as _interval_weights

    rng = np.random.default_rng(3)
    dens = 0.5 + rng.random((17, 17))
    pad, refine = 8, 2
    fine, sea = _balanced_sea(dens, pad, refine, 0.25)
    m, nb = fine.shape[0], 17 + 2 * pad
    lo, hi = pad / (nb - 1), (pad + 16) / (nb - 1)
    inside = _contract(fine, _interval_weights(m, lo, hi))
    assert inside == pytest.approx((hi - lo) ** 2 * _contract(fine, _interval_weights(m, 0.0, 1.0)), rel=1e-12)
    c = refine * pad  # the coast's first raster row: the sea's first row outside it holds the coast's density
    np.testing.assert_allclose(fine[c - 1, c:-c], fine[c, c:-c], rtol=0.2)
    far = refine * (pad - 4)  # 4 cells = 0.25 of the unit square outside the coast: the level
    np.testing.assert_allclose(fine[:far + 1, c:-c], sea, rtol=1e-12)
    a0, s0 = _balanced_sea(dens, pad, refine)
    a1, s1 = _balanced_sea(dens, pad, refine, 0.0)
    assert s0 == s1 and np.array_equal(a0, a1)


def test_sea_blend_tames_a_dense_coast():
    """A steep held-out ramp against the free boundary's coast: the abrupt sea with blurred retries leaves the flow's
    map about 6 times above the diffusion map's Std(rho~_map) at N = 65; a blended sea brings it within 2 times,
    fold-free, and records its width, and so does the default, whose stalled first pass is redone with it."""
    from rfmap.core.inputs import preprocess_density
    from rfmap.training.validation import validation_fields

    vf = next(f for f in validation_fields("density", 2, 16) if f.label == "ramp-3")
    dens = preprocess_density(vf.field(grid_mesh(65, 2).points).reshape(65, 65))
    diffusion = solve_dem(dens, boundary="free").metrics().std_rho_map
    abrupt = solve_flow(dens, boundary="free", stall_blend=0.0)
    blended = solve_flow(dens, boundary="free", sea_blend=0.25)
    default = solve_flow(dens, boundary="free")  # the abrupt sea stalls here: redone with the blended sea
    assert abrupt.info["sea_blend"] == 0.0 and blended.info["sea_blend"] == 0.25
    assert default.info["sea_fallback"] and not blended.info["sea_fallback"]
    assert abrupt.metrics().std_rho_map > 4 * diffusion
    for res in (blended, default):
        assert res.metrics().std_rho_map < 2 * diffusion and res.metrics().n_flipped == 0
    with pytest.raises(ValueError, match="sea_blend"):
        solve_flow(dens, boundary="free", sea_blend=-0.1)
    with pytest.raises(ValueError, match="stall_blend"):
        solve_flow(dens, boundary="free", stall_blend=float("nan"))


def test_sea_blend_study_rows():
    """One row per report field with its kind; the ramp against the coast stalls with the diffusion solver's sea,
    the default flow redoes it with a blended sea and ends far lower; no folds."""
    from rfmap.paper.flow_studies import sea_blend_study

    rows = sea_blend_study(2, 33, count=4)
    assert [r["kind"] for r in rows] == ["smooth", "steps", "peak", "ramp"]
    ramp = rows[3]
    assert ramp["stalled"] and ramp["fallback"]
    assert ramp["ratio_abrupt"] > 2 * ramp["ratio_default"] and ramp["shift"] > 1.0
    for r in rows:  # where the abrupt sea does not stall, the default flow is that flow
        assert r["fallback"] == r["stalled"]
        if not r["stalled"]:
            assert r["ratio_default"] == pytest.approx(r["ratio_abrupt"], rel=1e-12)
        assert r["n_flipped"] == 0 and r["std_diffusion"] > 0 and r["time_default"] > 0


def test_stalled_pass_is_redone_with_a_blended_sea_then_blurred():
    """A ramp sharper than the mesh against the free boundary's coast (an unseen field, N = 51) squeezes one element
    to zero measure at t ~ 0.09, so no step is accepted.  The first remedy redoes the pass with a blended sea
    (``info["sea_fallback"]``), which does not stall here and ends far more equal than the second remedy, the pass
    redone with a blurred density (``stall_blend=0``: recorded in ``stall_blurs``); a square boundary does not stall;
    with neither remedy the stall is an error at once."""
    from rfmap.paper.benchmarks import benchmark_fields

    dens = dict(benchmark_fields(2, 51, paper=False, random=4))["random-3"]
    blurred = solve_flow(dens, boundary="free", stall_blend=0.0)
    assert blurred.info["stall_blurs"], "the unblurred pass no longer stalls on this field: pick another"
    assert not blurred.info["sea_fallback"] and blurred.info["sea_blend"] == 0.0
    mb = blurred.metrics()
    assert mb.n_flipped == 0 and mb.std_rho_map < 0.2 * mb.std_rho_orig
    assert blurred.info["steps"] + blurred.info["rejected"] < 2000
    res = solve_flow(dens, boundary="free")
    assert res.info["sea_fallback"] and res.info["sea_blend"] > 0 and not res.info["stall_blurs"]
    m = res.metrics()
    assert m.n_flipped == 0 and m.std_rho_map < 0.5 * mb.std_rho_map
    assert not solve_flow(dens, boundary="square").info["stall_blurs"]
    with pytest.raises(RuntimeError, match="stalled"):  # no retries: the stall is an error at once
        solve_flow(dens, boundary="free", stall_blurs=(), stall_blend=0.0)


def test_warm_start_continues_a_map():
    """Starting from a partial map (half the flow's displacement) finishes it; a folded start is rejected."""
    dens = sample_density("sin-cos", 33)
    cold = solve_flow(dens)
    half = cold.ref_points + 0.5 * (cold.mapped_points - cold.ref_points)
    warm = solve_flow(dens, start=half)
    assert warm.info["warm_start"] and warm.info["std_history"][0] > 2 * warm.metrics().std_rho_map
    assert warm.metrics().std_rho_map < 1.5 * cold.metrics().std_rho_map
    assert warm.metrics().n_flipped == 0
    folded = half.copy()
    folded[[34, 35]] = folded[[35, 34]]
    with pytest.raises(ValueError, match="folded"):
        solve_flow(dens, start=folded)


def test_keep_best_false_returns_the_last_pass():
    """A second pass from the flow's own map cannot remove the element-scale residual (it does not lower the Std);
    ``keep_best=False`` returns that pass's map all the same, and the default keeps the better start."""
    dens = sample_density("sin-cos", 33)
    cold = solve_flow(dens)
    last = solve_flow(dens, start=cold.mapped_points, keep_best=False)
    best = solve_flow(dens, start=cold.mapped_points)
    h = last.info["std_history"]
    assert len(h) == 2 and last.metrics().std_rho_map == pytest.approx(h[-1], rel=1e-9)
    assert best.metrics().std_rho_map == pytest.approx(min(h), rel=1e-9)
    assert last.metrics().n_flipped == 0


def test_residual_floor_rows():
    from rfmap.paper.flow_studies import residual_floor

    rows = residual_floor(ns=(17, 33))
    assert [(r["n"], r["method"]) for r in rows] == [(n, m) for n in (17, 33)
                                                     for m in ("diffusion", "flow", "flow + second pass")]
    for r in rows:
        assert r["n_flipped"] == 0 and 0.0 <= r["element_fraction"] <= 1.0 and r["smooth"] < r["std"]
    # the classical floor shrinks with the grid spacing
    by = {(r["n"], r["method"]): r["std"] for r in rows}
    assert by[33, "diffusion"] < 0.75 * by[17, "diffusion"] and by[33, "flow"] < 0.75 * by[17, "flow"]


def test_flow_convergence_rows():
    """One row per field and flow setting, labelled; the flow's map is fold-free and near diffusion's Std under
    every setting; a tighter step tolerance takes more steps; the diffusion run is shared by a field's rows."""
    from rfmap.paper.flow_studies import CONVERGENCE_SETTINGS as FLOW_SETTINGS, flow_convergence

    rows = flow_convergence(2, 17, "square", random=1)
    labels = ["default", "rtol=0.02", "rtol=0.005", "refine=4"]
    fields = list(dict.fromkeys(r["field"] for r in rows))
    assert len(FLOW_SETTINGS) == 4 and len(rows) == 4 * len(fields) and "random-0" in fields
    assert [r["setting"] for r in rows] == labels * len(fields)
    by = {(r["field"], r["setting"]): r for r in rows}
    for f in fields:
        assert len({by[f, s]["std_diffusion"] for s in labels}) == 1
        assert by[f, "rtol=0.005"]["steps"] > by[f, "default"]["steps"]
    for r in rows:
        assert r["n_flipped"] == 0 and 0.5 < r["std_ratio"] < 2.0 and r["time_ratio"] > 0
        assert 0.0 <= r["rotation_diffusion"] < 1.0 and 0.0 <= r["rotation"] < 1.0
    # the flow's velocity -grad(phi)/rho_t is not a gradient; diffusion's -grad(log rho_t) is
    assert all(by[f, "default"]["rotation"] > by[f, "default"]["rotation_diffusion"] for f in fields)
    free = flow_convergence(2, 17, "free", random=0, settings=({},))
    assert all(r["rotation"] is None and r["rotation_diffusion"] is None for r in free)


def test_warm_start_residuals_rows():
    """Five maps per N; the two flows from the identity start from the same map and differ only by the route of the
    density to the raster, and end at the same Std; all flows are far below the input's variation; a Beltrami model
    is refused."""
    from rfmap import Surrogate
    from rfmap.paper.flow_studies import warm_start_residuals
    from rfmap.fields.paper import sample_density

    rows = warm_start_residuals(Surrogate.pretrained("deq2d-square"), "sin-cos", (17, 33))
    methods = ("cold flow", "flow from the identity, warm-start route", "network", "flow from the network", "polish")
    assert [(r["n"], r["method"]) for r in rows] == [(n, m) for n in (17, 33) for m in methods]
    by = {(r["n"], r["method"]): r for r in rows}
    for n in (17, 33):
        dens = sample_density("sin-cos", n)
        orig = float((dens / dens.mean()).std())
        for m in ("cold flow", "flow from the identity, warm-start route", "flow from the network", "polish"):
            assert by[n, m]["std"] < 0.3 * orig
        assert by[n, "flow from the network"]["std"] < by[n, "network"]["std"]
        ident, cold = by[n, "flow from the identity, warm-start route"]["std"], by[n, "cold flow"]["std"]
        assert ident == pytest.approx(cold, rel=5e-3)
    with pytest.raises(ValueError, match="density surrogate"):
        warm_start_residuals(Surrogate.pretrained("beltrami2d"), "sin-cos", (17,))


@pytest.mark.parametrize("bad,kw,match", [
    (np.ones(5), {}, "grid field"),
    (np.ones((4, 5)), {}, "same number"),
    (np.ones((2, 2)), {}, None),
    (np.linspace(-1.0, 1.0, 25).reshape(5, 5), {}, "strictly positive"),  # (a constant is the identity's)
    (np.full((5, 5), np.nan), {}, None),
    (np.ones((5, 5)), {"boundary": "fixed"}, "unknown boundary"),
    (np.ones((5, 5)), {"tol": -1e-3}, "tol"),
    (np.ones((5, 5)), {"tol": float("inf")}, "tol"),
    (np.ones((5, 5)), {"rtol": -1.0}, "rtol"),
    (np.ones((5, 5)), {"refine": 0}, "refine"),
    (np.ones((5, 5)), {"stall": 2.0}, "stall"),
    (np.ones((5, 5)), {"max_passes": 0}, "max_passes"),
    (np.ones((5, 5)), {"start": np.zeros((3, 2))}, "start must have shape"),
])
def test_bad_input(bad, kw, match):
    with pytest.raises(ValueError, match=match):
        solve_flow(bad, **kw)


def test_tol_zero_runs_a_pass_below_the_default_tolerance():
    """A density whose Std is below the default tol is returned unmapped by default; with tol=0 one pass runs and
    lowers it; an exactly uniform density has nothing to map either way."""
    x = np.linspace(0.0, 1.0, 33)
    dens = 1.0 + 1e-3 * np.cos(np.pi * x)[:, None] * np.cos(np.pi * x)[None, :]
    default = solve_flow(dens)
    assert default.info["passes"] == 0 and np.array_equal(default.mapped_points, default.ref_points)
    once = solve_flow(dens, tol=0.0)
    assert once.info["passes"] == 1
    assert once.metrics().std_rho_map < 0.2 * default.metrics().std_rho_map and once.metrics().n_flipped == 0
    assert solve_flow(np.ones((9, 9)), tol=0.0).info["passes"] == 0


# --------------------------------------------------------------------------------------------------- hybrid
def test_polish_warm_start_finishes_the_network_map():
    from rfmap.surrogate import Surrogate

    sur = Surrogate.pretrained("dem2d-square")
    raw = sur.map("sin-cos", 51)
    res = sur.map("sin-cos", 51, polish=True)
    p = res.info["polish"]
    assert p["start"] == "warm" and p["reason"] is None
    st = p["stages"]
    assert st["surrogate"]["std_rho_map"] == pytest.approx(raw.metrics().std_rho_map)
    m = res.metrics()
    assert m.n_flipped == 0 and m.std_rho_map == pytest.approx(st["polish"]["std_rho_map"])
    assert m.std_rho_map < 0.5 * st["surrogate"]["std_rho_map"]
    assert res.time == pytest.approx(st["surrogate"]["time"] + p["time"])
    # the guard ran the cold flow too and kept the better of the two maps (rfmap.finish.polish.GUARD)
    assert p["guard"] and set(st) == {"surrogate", "warm", "cold", "polish"}
    best = min(("warm", "cold"), key=lambda k: st[k]["std_rho_map"])
    assert p["kept"] == best and st["polish"]["std_rho_map"] == st[best]["std_rho_map"]
    assert m.std_rho_map <= solve_flow(sample_density("sin-cos", 51)).metrics().std_rho_map * (1 + 1e-12)
    assert p["time"] >= st["warm"]["time"] + st["cold"]["time"]
    wall_checks(res)


def test_compare_methods_rows_and_summary():
    """The hybrid's run gives two rows, the guarded hybrid and its warm flow alone (timed without the cold flow);
    the guarded hybrid is never worse than the flow, and the summary's ratios are against the best classical row."""
    from rfmap.paper.benchmarks import summarize
    from rfmap.finish.polish import UNGUARDED
    from rfmap.paper.benchmarks import compare_methods
    from rfmap.surrogate import Surrogate

    dens = sample_density("sin-cos", 33)
    rows = compare_methods(dens, Surrogate.pretrained("dem2d-square"), methods=("flow", "hybrid"))
    assert [r["method"] for r in rows] == ["flow", UNGUARDED, "hybrid"]
    flow, alone, hyb = rows
    assert hyb["start"] == "warm" and hyb["std_rho_map"] == min(alone["std_rho_map"], flow["std_rho_map"])
    assert hyb["kept"] == ("warm" if alone["std_rho_map"] <= flow["std_rho_map"] else "cold")
    assert 0 < alone["time"] < hyb["time"] and hyb["n_flipped"] == alone["n_flipped"] == 0
    summary = summarize([dict(r, dim=2, n=33, boundary="square", field="sin-cos") for r in rows])
    assert [r["method"] for r in summary] == ["flow", UNGUARDED, "hybrid"]
    assert all(r["best_classical"] == "flow" for r in summary)
    assert summary[2]["std_ratio"] <= 1.0 and summary[2]["time_ratio"] == pytest.approx(hyb["time"] / flow["time"])


def test_polish_guard_keeps_the_cold_map_when_the_warm_flow_ends_worse(monkeypatch):
    """Where the warm flow ends above the cold flow (here made so by returning the warm flow's starting map
    unchanged), the guard returns the cold flow's map, identical to ``solve_flow``'s, and says so; without the
    guard the warm flow's map is returned."""
    import rfmap.solvers.flow as flow
    from rfmap.surrogate import Surrogate

    real = flow.solve_flow

    def lazy_warm(density, *, start=None, **kw):
        res = real(density, start=start, **kw)
        if start is not None:  # a warm flow that did nothing
            res = flow.MapResult(ref_points=res.ref_points, mapped_points=np.array(start), elements=res.elements,
                                 field=res.field, kind="density", time=res.time, info=res.info)
        return res

    monkeypatch.setattr(flow, "solve_flow", lazy_warm)
    sur = Surrogate.pretrained("dem2d-square")
    res = sur.map("sin-cos", 33, polish=True)
    p = res.info["polish"]
    assert p["start"] == "warm" and p["kept"] == "cold"
    assert p["stages"]["warm"]["std_rho_map"] > p["stages"]["cold"]["std_rho_map"]
    np.testing.assert_array_equal(res.mapped_points, real(sample_density("sin-cos", 33)).mapped_points)
    unguarded = sur.map("sin-cos", 33, polish=True, guard=False)
    q = unguarded.info["polish"]
    assert q["kept"] == "warm" and not q["guard"] and "cold" not in q["stages"]
    assert unguarded.metrics().std_rho_map > res.metrics().std_rho_map


def test_polish_starts_from_the_smoothed_network_map():
    """The warm flow starts from the smoothed displacement's map (fold-free here) and ends within 5 % of the cold
    flow's Std(rho~_map) at N = 51 (the network's element-scale ripples, which no flow removes, are gone); the
    report's surrogate stage is still the raw network map."""
    from rfmap.surrogate import Surrogate

    sur = Surrogate.pretrained("deq2d-square")
    dens = sample_density("sin-cos", 51)
    res = sur.map("sin-cos", 51, polish=True, guard=False)
    p = res.info["polish"]
    assert p["start"] == "warm" and p["smoothed"] and p["smooth_passes"] == 2 and p["kept"] == "warm"
    assert p["stages"]["surrogate"]["std_rho_map"] == pytest.approx(sur.map("sin-cos", 51).metrics().std_rho_map)
    cold = solve_flow(dens).metrics().std_rho_map
    assert res.metrics().std_rho_map < 1.05 * cold and res.metrics().n_flipped == 0
    wall_checks(res)


@pytest.mark.parametrize("d,n", [(2, 9), (3, 6)])
def test_polish_summary_equals_compute_metrics(d, n):
    """The polish report's metrics (grid kernels, no Beltrami coefficient) are those of compute_metrics, on a
    curved map and on a folded one."""
    from rfmap.finish.polish import _Summary
    from rfmap.core.metrics import compute_metrics

    mesh, y = _bent_mesh(n, d)
    dens = np.random.default_rng(1).uniform(0.5, 2.0, len(y))
    folded = y.copy()
    folded[len(y) // 2, 0] += 1.5 / (n - 1)  # past its neighbour: folds the elements around it
    summary = _Summary(mesh.points, dens, n)
    for pts in (y, folded):
        got = summary(pts, 0.5)
        want = compute_metrics(mesh.points, pts, mesh.elements, density=dens)
        assert got["time"] == 0.5 and got["n_flipped"] == want.n_flipped
        for k in ("std_rho_map", "std_rho_orig", "min_jacobian"):
            assert got[k] == pytest.approx(getattr(want, k), rel=1e-12), k
    assert summary(folded, 0.0)["n_flipped"] > 0 == summary(y, 0.0)["n_flipped"]


def test_polish_of_a_free_boundary_map_smooths_with_linear_edges():
    """A free-boundary polish starts warm from the displacement smoothed with linear edges and ends fold-free, with
    less than a third of the network's Std(rho~_map) and within 1.5x of the cold flow's (ring, N = 51)."""
    from rfmap.surrogate import Surrogate

    sur = Surrogate.pretrained("deq2d-free")
    res = sur.map("ring", 51, polish=True, guard=False)
    p = res.info["polish"]
    assert p["start"] == "warm" and p["smoothed"] and (p["smooth_edges"], p["smooth_passes"]) == ("linear", 2)
    cold = solve_flow(sample_density("ring", 51), boundary="free").metrics().std_rho_map
    m = res.metrics()
    assert m.n_flipped == 0 and m.std_rho_map < p["stages"]["surrogate"]["std_rho_map"] / 3
    assert m.std_rho_map < 1.5 * cold and np.isfinite(res.mapped_points).all()


def test_smooth_passes_per_dimension_and_above_the_working_grid():
    from rfmap.finish.polish import SMOOTH_PASSES, SMOOTH_PASSES_FINER, smooth_passes

    assert smooth_passes(2, 51, 51) == SMOOTH_PASSES[2, "square"] and smooth_passes(3, 48, 48) == 8
    assert smooth_passes(3, 32, 32, "free") == SMOOTH_PASSES[3, "free"] == 2
    assert smooth_passes(2, 256, 96) == smooth_passes(3, 64, 48) == SMOOTH_PASSES_FINER["square"] == 8
    assert smooth_passes(2, 128, 96, "free") == SMOOTH_PASSES_FINER["free"] == 4
    with pytest.raises(ValueError, match="boundary 'fixed'"):
        smooth_passes(2, 51, 51, "fixed")


@pytest.mark.parametrize("d,edges", [(2, "replicate"), (3, "linear")])
def test_smooth_grid_displacement_is_the_grid_filter_at_the_vertices(d, edges):
    """Smoothing a displacement given at the grid's vertices (P, d) is the filter of the same field on the grid:
    the grid mode of one axis is removed in the interior, a constant is kept, and a wrong vertex count is refused."""
    import torch

    from rfmap.finish.polish import smooth_displacement, smooth_grid_displacement
    from rfmap.core.mesh import grid_points

    n = 9
    pts = torch.as_tensor(grid_points(n, d))
    alt = torch.cos(np.pi * (n - 1) * pts[:, :1])  # +-1 between neighbouring vertices along the first axis
    psi_q = torch.cat([alt, torch.full((n**d, d - 1), 0.3, dtype=pts.dtype)], 1) * 1e-3
    out = smooth_grid_displacement(psi_q, n, 2, edges)
    assert out.shape == psi_q.shape
    grid = psi_q.T.reshape(1, d, *(n,) * d)
    np.testing.assert_allclose(out.numpy(), smooth_displacement(grid, 2, edges)[0].reshape(d, -1).T.numpy())
    inner = ((pts > 0.2) & (pts < 0.8)).all(1)
    assert out[inner, 0].abs().max() < 1e-12 and torch.allclose(out[:, 1:], psi_q[:, 1:])
    with pytest.raises(ValueError, match="vertices"):
        smooth_grid_displacement(psi_q[:-1], n)


def test_polish_above_the_working_grid_smooths_on_the_output_grid():
    """Above the working grid the start is smoothed on the working grid and again on the output grid
    (rfmap.finish.polish.OUTPUT_PASSES); the warm flow ends fold-free and within 10 % of the cold flow (sin-cos, N = 121
    from a 96-grid)."""
    from rfmap.finish.polish import OUTPUT_PASSES, SMOOTH_PASSES_FINER
    from rfmap.surrogate import Surrogate

    sur = Surrogate.pretrained("deq2d-square")
    assert sur.work_n(121) < 121
    res = sur.map("sin-cos", 121, polish=True, guard=False)
    p = res.info["polish"]
    assert p["start"] == "warm" and p["smoothed"]
    assert (p["smooth_passes"], p["output_passes"]) == (SMOOTH_PASSES_FINER["square"], OUTPUT_PASSES) == (8, 2)
    cold = solve_flow(sample_density("sin-cos", 121)).metrics().std_rho_map
    assert res.metrics().n_flipped == 0 and res.metrics().std_rho_map < 1.1 * cold
    assert sur.map("sin-cos", 51, polish=True, guard=False).info["polish"]["output_passes"] == 0


@pytest.mark.parametrize("d", [2, 3])
def test_smooth_displacement_keeps_constants_and_removes_the_grid_mode(d):
    """The binomial filter keeps constant and (away from the edges) linear displacements, sends the grid-scale
    alternation to zero in the interior, and keeps the shape."""
    import torch

    from rfmap.finish.polish import smooth_displacement

    n = 12
    axes = torch.meshgrid(*[torch.arange(n, dtype=torch.float64)] * d, indexing="ij")
    const = torch.full((1, d) + (n,) * d, 0.3, dtype=torch.float64)
    torch.testing.assert_close(smooth_displacement(const), const)
    lin = torch.stack([0.01 * axes[0]] * d)[None]
    inner = (slice(None), slice(None)) + (slice(2, n - 2),) * d
    torch.testing.assert_close(smooth_displacement(lin)[inner], lin[inner])
    alt = torch.stack([(-1.0) ** sum(axes)] * d)[None]
    out = smooth_displacement(alt, passes=1)
    assert out.shape == alt.shape and out[inner].abs().max() < 1e-12
    # linear edges keep a linear displacement up to the edge; replicated ones bend it there
    torch.testing.assert_close(smooth_displacement(lin, 3, edges="linear"), lin)
    assert (smooth_displacement(lin, 3) - lin).abs().max() > 1e-3
    with pytest.raises(ValueError, match="edges must be"):
        smooth_displacement(lin, edges="reflect")


def test_polish_cold_start_when_the_network_map_is_poor():
    from rfmap.surrogate import Surrogate
    from rfmap.tasks import TaskSpec

    sur = Surrogate.untrained(TaskSpec(kind="density", dim=2, boundary="square"))
    with torch_zero(sur):
        res = sur.map("ring", 33, polish=True)
    assert res.info["polish"]["start"] == "cold" and "poor" in res.info["polish"]["reason"]
    assert res.metrics().n_flipped == 0


def test_polish_of_a_folded_network_map_skips_the_repair_and_starts_cold():
    """A folded network map is not repaired before the polish (which starts cold from the identity anyway); without
    polish the same map is repaired."""
    import torch

    from rfmap.cli.commands import repair_summary
    from rfmap.surrogate import Surrogate
    from rfmap.tasks import TaskSpec

    sur = Surrogate.untrained(TaskSpec(kind="density", dim=2, boundary="square"))
    with torch.no_grad():  # psi = (3, 0) everywhere: u_x = x + 12 x (1 - x) turns back for x > 0.54
        for p in sur.model.parameters():
            p.zero_()
        sur.model.head.bias.copy_(torch.tensor([3.0, 0.0]))
    raw = sur.map("sin-cos", 33, repair=False)
    assert raw.metrics().n_flipped > 0
    res = sur.map("sin-cos", 33, polish=True)
    rep, pol = res.info["repair"], res.info["polish"]
    assert rep["skipped"] and rep["n_flipped_before"] == raw.metrics().n_flipped
    assert pol["start"] == "cold" and "folded" in pol["reason"]
    assert res.metrics().n_flipped == 0
    assert "skipped" in repair_summary(rep)
    plain = sur.map("sin-cos", 33)
    assert not plain.info["repair"].get("skipped") and plain.metrics().n_flipped == 0


def torch_zero(sur):
    """Context: the network outputs zero displacement (the identity map, which removes no density variation)."""
    import contextlib

    import torch

    @contextlib.contextmanager
    def ctx():
        with torch.no_grad():
            for p in sur.model.parameters():
                p.zero_()
        yield
    return ctx()


@pytest.mark.parametrize("polish", [0, -1.0, "yes", float("nan")])
def test_polish_bad_tolerance(polish):
    from rfmap.surrogate import Surrogate

    with pytest.raises(ValueError, match="polish"):
        Surrogate.pretrained("dem2d-square").map("sin-cos", 33, polish=polish)


def test_polish_needs_grid_density_maps():
    from rfmap.surrogate import Surrogate

    with pytest.raises(ValueError, match="polish"):
        Surrogate.pretrained("dem2d-square").map("sin-cos", 33, points=np.random.default_rng(0).random((50, 2)),
                                                 polish=True)


def test_box_mean_is_the_zero_cosine_coefficient_and_rtol_defaults_per_dimension():
    """box_mean (trapezoidal mean) equals the cosine interpolant's a_0 without the transform; the step tolerance
    defaults to RTOL of the density's dimension and is recorded."""
    from rfmap.solvers.diffusion import cosine_coefficients
    from rfmap.solvers.flow import RTOL
    from rfmap.solvers.spectral import box_mean

    rng = np.random.default_rng(0)
    for shape in [(9,), (8, 8), (7, 7, 7)]:
        v = rng.uniform(0.5, 2.0, size=shape)
        assert abs(box_mean(v) - float(cosine_coefficients(v).flat[0])) < 1e-13
    d2 = 1.0 + 0.5 * np.outer(np.linspace(0, 1, 9), np.ones(9))
    assert solve_flow(d2).info["rtol"] == RTOL[2] == 0.2
    assert solve_flow(d2, rtol=0.1).info["rtol"] == 0.1
    d3 = 1.0 + 0.5 * np.linspace(0, 1, 7)[:, None, None] * np.ones((7, 7, 7))
    assert solve_flow(d3).info["rtol"] == RTOL[3] == 0.4


@pytest.mark.parametrize("d,n", [(2, 9), (3, 6)])
def test_fold_check_in_single_precision_agrees_with_double(d, n):
    """The step's fold check: float32 decides clear cases, float64 the ones within F32_MARGIN of zero."""
    import torch

    from rfmap.core.geometry import grid_signed_measures

    ref = grid_mesh(n, d).points
    h = 1.0 / (n - 1)
    rng = np.random.default_rng(0)
    assert not _turned_over(ref + 0.1 * h * rng.standard_normal(ref.shape), n)
    # move one interior vertex to within 1e-12 h of its left neighbour, onto it, and 1e-12 h past it: the
    # elements between them get measures of about 1e-12 of the mean, which float32 cannot resolve
    centre = int(np.argmin(((ref - 0.5) ** 2).sum(1)))
    for shift, folded in ((1e-12, False), (0.0, True), (-1e-12, True)):
        x = ref.copy()
        x[centre, 0] = ref[centre, 0] - h + shift * h
        m64 = grid_signed_measures(torch.from_numpy(x)[None], n)[0].numpy()
        assert abs(m64.min()) < F32_MARGIN * m64.mean()  # inside the margin: decided in double precision
        assert _turned_over(x, n) == (m64.min() <= 0.0) == folded


@pytest.mark.parametrize("d,n", [(2, 9), (3, 7)])
def test_velocity_is_the_same_on_any_number_of_threads(d, n):
    """The points are split into one grid_sample batch entry per thread (padded to a multiple): same values."""
    import torch

    from rfmap.solvers.diffusion import p1_upsample
    from rfmap.solvers.flow import _FlowPass

    rng = np.random.default_rng(3)
    fp = _FlowPass(p1_upsample(1.0 + rng.random((n,) * d), 2))
    y = rng.random((n ** d, d))  # 81 or 343 points: not a multiple of 2 or 4 threads
    before = torch.get_num_threads()
    try:
        out = {}
        for k in (1, 2, 4):
            torch.set_num_threads(k)
            out[k] = fp.velocity(0.3, y)
    finally:
        torch.set_num_threads(before)
    assert out[1].shape == (n ** d, d)
    np.testing.assert_array_equal(out[2], out[1])
    np.testing.assert_array_equal(out[4], out[1])


def test_time_to_accuracy_warms_every_method_up_once(monkeypatch):
    """With ``warmup`` every method runs once more, on the first field, and that run leaves no row."""
    import rfmap.paper.benchmarks as hybrid
    from rfmap.paper.benchmarks import time_to_accuracy

    calls = []
    real = hybrid.compare_methods

    def counting(density, surrogate=None, **kw):
        calls.append(density.copy())
        return real(density, surrogate, **kw)

    monkeypatch.setattr(hybrid, "compare_methods", counting)
    for warmup, runs in ((False, 2), (True, 3)):
        calls.clear()
        rows = time_to_accuracy(2, 17, paper=False, random=2, methods=("flow",), warmup=warmup)
        assert [r["field"] for r in rows] == ["random-0", "random-1"] and len(calls) == runs
        if warmup:
            np.testing.assert_array_equal(calls[0], calls[1])  # the warm-up ran on the first field


@pytest.mark.parametrize("k,sigma", [(1, 0.05), (3, 0.1), (6, 0.04)])
def test_gaussian_blur_damps_each_cosine_mode_by_the_gaussians_transform(k, sigma):
    r"""A Gaussian of standard deviation :math:`\sigma` (mirror walls) multiplies the mode :math:`\cos(\pi k x)` by
    its Fourier transform at :math:`\omega = \pi k`, :math:`e^{-\pi^2 k^2 \sigma^2 / 2}` (the heat kernel at time
    :math:`\sigma^2/2`), and leaves the mean alone: exact on the grid's cosine modes, in 2D and 3D; a kernel at
    time :math:`\sigma^2` would damp it to the square of that factor."""
    x = np.linspace(0.0, 1.0, 33)
    factor = math.exp(-0.5 * (math.pi * k * sigma) ** 2)
    mode = np.cos(math.pi * k * x)[:, None] * np.cos(math.pi * 2 * x)[None, :]  # (k, 2)
    want = factor * math.exp(-0.5 * (math.pi * 2 * sigma) ** 2) * mode
    np.testing.assert_allclose(gaussian_blur(1.5 + mode, sigma), 1.5 + want, rtol=0, atol=1e-12)
    cube = np.cos(math.pi * k * x)[None, None, :] + np.zeros((33, 33, 33))
    np.testing.assert_allclose(gaussian_blur(cube, sigma), factor * cube, rtol=0, atol=1e-12)


def test_a_warm_free_boundary_fills_its_sea_with_the_domains_total_density():
    r"""From a warm start with a free boundary the residual raster's sea holds the mapped domain's density taken
    together, total population over total mapped measure :math:`\sum_e p_e / \sum_e |T(e)|`, relative to the
    mean element density :math:`\operatorname{mean}_e(p_e/|T(e)|)`: checked at the box's corner (deep in the sea)
    on a map whose elements have unequal measures, where the plain mean of the element densities differs by 3 %."""
    import torch

    from rfmap.core.geometry import signed_measures
    from rfmap.core.metrics import element_population
    from rfmap.solvers.flow import FlowOptions, _Box, _Equality, _Run

    n = 9
    dens = sample_density("exp-log", n)
    mesh = grid_mesh(n, 2)
    x, y = mesh.points[:, 0], mesh.points[:, 1]
    mapped = np.stack([x + 0.08 * np.sin(np.pi * x) * (1 + y), y + 0.05 * np.sin(np.pi * y)], 1)
    opts = FlowOptions(boundary="free").checked(2)
    box, eq = _Box(mesh.points, n, opts), _Equality(dens.reshape(-1), n, 2)
    run = _Run(dens, mesh.elements, opts, box, warm=True)
    raster = run.residual_raster(mapped, box.project((mapped + box.shift) / box.scale), eq)
    pop = element_population(mesh.points, mesh.elements, dens.reshape(-1)).numpy()
    meas = signed_measures(torch.as_tensor(mapped), torch.as_tensor(mesh.elements)).numpy()
    rho = pop / meas
    assert abs(rho.mean() / (pop.sum() / meas.sum()) - 1) > 0.02  # the two means differ here
    assert raster[0, 0] == pytest.approx(pop.sum() / meas.sum() / rho.mean(), rel=1e-10)


@pytest.mark.parametrize("m", [9, 33])
def test_a_flow_pass_ends_at_the_mean_its_poisson_solve_leaves_out(m):
    r"""A pass's density runs from :math:`\rho_0` to :math:`\bar\rho = a_0`, the zero cosine coefficient of the raster
    (its trapezoidal mean), the mode that the Poisson solve :math:`\Delta\phi = \bar\rho - \rho_0` leaves out; so at
    :math:`t = 1` the velocity is the flux over :math:`a_0` everywhere.  The plain mean of the raster's nodes differs
    from :math:`a_0` by the half-weighted walls (here about 1 %)."""
    from rfmap.core.mesh import interpolate
    from rfmap.solvers.flow import _FlowPass

    s = np.linspace(0.0, 1.0, m)
    raster = 2.0 + np.cos(np.pi * s)[:, None] + 0.5 * s[None, :] ** 2
    a0 = cosine_coefficients(raster)[0, 0]
    fp = _FlowPass(raster)
    assert fp.velocity.mean == pytest.approx(a0, rel=1e-14)
    assert abs(raster.mean() / a0 - 1) > 1e-3
    pts = np.random.default_rng(6).uniform(0.0, 1.0, size=(50, 2))
    flux = interpolate(poisson_flux(raster)[None], pts)[0]  # -grad phi, sampled bilinearly (the pass: in float32)
    np.testing.assert_allclose(fp.velocity(1.0, pts), flux / a0, rtol=0, atol=1e-5 * np.abs(flux / a0).max())
