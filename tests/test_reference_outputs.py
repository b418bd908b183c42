"""Outputs on the paper's test fields against stored reference arrays (``tests/data/reference_outputs.npz``).

The arrays were written by ``scripts/make_reference_outputs.py`` from :func:`reference_outputs`; a restructuring of
the package must reproduce them.  Fields, classical solvers and metrics must agree to double-precision round-off
(relative 1e-10): on one machine they are bit for bit the same, but numpy and LAPACK pick kernels by CPU (AVX-512
versions of sin, exp and the BLAS sums round differently in the last bit, measured up to 1e-14 relative), and any
real change to a field, solver or metric moves them by far more.  The surrogates'
outputs (network evaluations of the shipped weights) are compared to within 1e-5: the network's convolution
arithmetic may be reordered by engine speed-ups (a different kernel or fused layer sums in a different order), which
changes float32 round-off but not the model.

Sizes are small (2D N = 17, 3D N = 9) so that the whole comparison takes seconds.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).resolve().parent / "data" / "reference_outputs.npz"

N2, N3 = 17, 9
DENSITIES_2D = ["sin-cos", "exp-log", "rect-peak", "ring", "multi-freq"]
DENSITIES_3D = ["sin-cos-3d", "shell-3d", "octant-3d", "prism-peak-3d", "multi-freq-3d"]
BELTRAMI = ["T1", "T2", "T3", "T4", "T1-res"]
METRIC_KEYS = ["std_rho_orig", "std_rho_map", "min_jacobian", "n_flipped", "max_mu", "mean_mu", "mean_dd",
               "mean_dmu"]
#: The surrogates' raw maps (no fold repair, which post-processes the map and is tested in test_repair.py).
RAW = {"repair": False}
SURROGATES = {"beltrami2d": ["T1", "T3"], "deq2d-square": ["sin-cos", "ring"], "deq2d-free": ["rect-peak"],
              "dem2d-square": ["exp-log"], "dem3d-cube": ["sin-cos-3d"], "dem3d-free": ["octant-3d"]}


def _metric_vector(m) -> np.ndarray:
    return np.array([np.nan if getattr(m, k) is None else float(getattr(m, k)) for k in METRIC_KEYS])


def _round_off_equal(a: np.ndarray, b: np.ndarray, rtol: float = 1e-10) -> bool:
    """Same shape, same NaNs, and every entry within ``rtol`` of itself (plus 1e-3 ``rtol`` of the array's largest
    magnitude, for entries that are round-off themselves)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or not np.array_equal(np.isnan(a), np.isnan(b)):
        return False
    ok = ~np.isnan(b)
    scale = float(np.abs(b[ok]).max(initial=0.0))
    return bool(np.all(np.abs(a[ok] - b[ok]) <= rtol * np.abs(b[ok]) + 1e-3 * rtol * scale))


def _centroids(n: int) -> np.ndarray:
    from rfmap.mesh import grid_mesh

    mesh = grid_mesh(n, 2)
    return mesh.points[mesh.elements].mean(1)


def field_outputs() -> dict[str, np.ndarray]:
    """Test densities (preprocessed and raw), exact Beltrami coefficients and maps, weights and jitter."""
    import rfmap.fields as F
    from rfmap.mesh import grid_mesh, grid_points

    out = {}
    for name in DENSITIES_2D + DENSITIES_3D:
        n = N2 if name in DENSITIES_2D else N3
        out[f"field/{name}"] = F.sample_density(name, n)
        out[f"field-raw/{name}"] = F.DENSITIES[name].sample(n, preprocess=False)
    for name in BELTRAMI:
        out[f"mu/{name}"] = F.BELTRAMI_MAPS[name].mu(_centroids(N2))
        out[f"map/{name}"] = F.BELTRAMI_MAPS[name](grid_points(N2, 2))
    for dim, n in ((2, N2), (3, N3)):
        mesh = grid_mesh(n, dim)
        out[f"weights/{dim}d"] = F.vertex_weights(mesh.points, mesh.elements)
        grad = np.linalg.norm(mesh.points - 0.5, axis=1)
        out[f"jitter/{dim}d"] = F.jittered_points(n, dim, np.random.default_rng(7), grad_magnitude=grad)
    return out


def solver_outputs() -> dict[str, np.ndarray]:
    """Mapped vertices and metrics of the classical solvers."""
    import rfmap.fields as F
    from rfmap.solvers import solve_dem, solve_lbs

    out = {}
    for name in ["T1", "T2", "T3", "T4"]:
        res = solve_lbs(F.BELTRAMI_MAPS[name].mu(_centroids(N2)), N2)
        out[f"lbs/{name}"] = res.mapped_points
        out[f"lbs-metrics/{name}"] = _metric_vector(res.metrics(exact_points=F.BELTRAMI_MAPS[name](res.ref_points),
                                                                mu_ref=F.BELTRAMI_MAPS[name].mu(_centroids(N2))))
    res = solve_lbs(F.BELTRAMI_MAPS["T2"].mu, N2, boundary="square")
    out["lbs-square/T2"] = res.mapped_points
    cases = [(name, "square") for name in DENSITIES_2D] + [(name, "free") for name in DENSITIES_2D[:4]]
    cases += [(name, "square") for name in DENSITIES_3D[:2]] + [(DENSITIES_3D[2], "free")]
    for name, boundary in cases:
        n = N2 if name in DENSITIES_2D else N3
        res = solve_dem(F.sample_density(name, n), boundary=boundary)
        out[f"dem-{boundary}/{name}"] = res.mapped_points
        out[f"dem-{boundary}-metrics/{name}"] = _metric_vector(res.metrics())
    return out


def surrogate_outputs() -> dict[str, np.ndarray]:
    """Maps of the shipped models: named fields with and without refinement, a grid array, scattered query
    points."""
    import rfmap.fields as F
    from rfmap import Surrogate

    out = {}
    rng = np.random.default_rng(3)
    for model, names in SURROGATES.items():
        sur = Surrogate.pretrained(model)
        n = N2 if sur.spec.dim == 2 else N3
        for name in names:
            plain = sur.map(name, n, **RAW)
            refined = sur.map(name, n, refine=True, **RAW)
            out[f"sur/{model}/{name}"] = plain.mapped_points
            out[f"sur-field/{model}/{name}"] = plain.field
            out[f"sur-refine/{model}/{name}"] = refined.mapped_points
            out[f"sur-alpha/{model}/{name}"] = np.array(refined.info["alpha"])
            out[f"sur-metrics/{model}/{name}"] = _metric_vector(plain.metrics())
        name = names[0]
        if sur.spec.kind == "density":
            arr = F.DENSITIES[name].sample(n + 2, preprocess=False)
        else:
            from rfmap.mesh import grid_points

            arr = F.BELTRAMI_MAPS[name].mu(grid_points(n + 2, 2)).reshape(n + 2, n + 2)
        res = sur.map(arr, n, **RAW)
        out[f"sur-array/{model}/{name}"] = res.mapped_points
        out[f"sur-array-field/{model}/{name}"] = res.field
        pts = np.concatenate([rng.random((40, sur.spec.dim)), np.eye(sur.spec.dim)])
        res = sur.map(name, points=pts, refine=True, **RAW)
        out[f"sur-points/{model}/{name}"] = res.mapped_points
        out[f"sur-points-elements/{model}/{name}"] = res.elements
        out[f"sur-points-field/{model}/{name}"] = res.field
    return out


def reference_outputs() -> dict[str, np.ndarray]:
    """Every stored output, by key ``group/name``."""
    return {**field_outputs(), **solver_outputs(), **surrogate_outputs()}


@pytest.fixture(scope="module")
def reference():
    if not DATA.exists():
        pytest.fail(f"missing {DATA}; write it with scripts/make_reference_outputs.py")
    with np.load(DATA) as z:
        return {k: z[k] for k in z.files}


def test_fields_bit_identical(reference):
    now = field_outputs()
    missing = set(now) - set(reference)
    assert not missing, f"no reference for {sorted(missing)}"
    bad = [k for k in now if not _round_off_equal(now[k], reference[k])]
    assert not bad, f"fields differ from the reference: {bad}"


def test_solvers_and_metrics_bit_identical(reference):
    now = solver_outputs()
    missing = set(now) - set(reference)
    assert not missing, f"no reference for {sorted(missing)}"
    bad = [k for k in now if not _round_off_equal(now[k], reference[k])]
    assert not bad, f"solver outputs or metrics differ from the reference: {bad}"


def test_surrogates_match(reference):
    now = surrogate_outputs()
    missing = set(now) - set(reference)
    assert not missing, f"no reference for {sorted(missing)}"
    for k, v in now.items():
        if "elements" in k:  # triangulations of the query points are integer data: exact
            np.testing.assert_array_equal(v, reference[k], err_msg=k)
        elif "sur-field" in k or "points-field" in k or "array-field" in k:  # input fields: no network involved
            assert _round_off_equal(v, reference[k]), k
        else:
            # network outputs: the convolution arithmetic may be reordered by engine speed-ups (another kernel
            # or fused layer), so float32 round-off may change; solver and field outputs above agree to double round-off
            np.testing.assert_allclose(v, reference[k], rtol=0, atol=1e-5, err_msg=k, equal_nan=True)
