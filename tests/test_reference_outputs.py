"""Outputs on the paper's test fields against stored reference arrays (``tests/data/reference_outputs.npz``).

The arrays were written by ``scripts/make_reference_outputs.py`` from :func:`reference_outputs`; a restructuring of
the package must reproduce them, and the script changes only the keys it is told to (``--only``).

* Fields, the diffusion and Beltrami solvers and metrics must agree to double-precision round-off (relative 1e-10):
  on one machine they are bit for bit the same, but numpy and LAPACK pick kernels by CPU (AVX-512 versions of sin,
  exp and the BLAS sums round differently in the last bit, measured up to 1e-14 relative), and any real change to a
  field, solver or metric moves them by far more.  The diffusion cartogram is double precision too.
* Outputs that pass through single precision are compared to within 1e-5 of their scale: network evaluations (the
  convolution arithmetic may be reordered by engine speed-ups, a different kernel or fused layer summing in another
  order), and the flow solver, whose Poisson solve and velocity table are float32 (``rfmap.solvers.flow``).  A real
  change moves them by far more: another step tolerance of the flow moved its maps by 3e-3, network outputs
  perturbed by a relative 1e-6 moved every surrogate output here by less than 7e-6.
* The surrogates are the tiny networks frozen in ``tests/data/tiny-*.safetensors`` (the ``ci`` presets' U-Net, base 4
  and depth 2, trained a few hundred steps from a fixed seed and never retrained), not the shipped weights: a retrain
  of a shipped model changes nothing here, and ``tests/test_accuracy.py`` bounds the shipped models instead.  They
  cover the raw network map, refinement, grid arrays and query points, the default path (fold repair and the
  shortening of a map that is no more equal than the input), an overshooting map (:data:`OVERSHOOT`) that needs
  both, the flow-based polish (cold and warm start) and the symmetrized network.

Sizes are small (2D N = 17, 3D N = 9) so that the whole comparison takes seconds.
"""
from __future__ import annotations

from fnmatch import fnmatch
from pathlib import Path

import numpy as np
import pytest

DATA_DIR = Path(__file__).resolve().parent / "data"
DATA = DATA_DIR / "reference_outputs.npz"

N2, N3 = 17, 9
DENSITIES_2D = ["sin-cos", "exp-log", "rect-peak", "ring", "multi-freq"]
DENSITIES_3D = ["sin-cos-3d", "shell-3d", "octant-3d", "prism-peak-3d", "multi-freq-3d"]
BELTRAMI = ["T1", "T2", "T3", "T4", "T1-res"]
METRIC_KEYS = ["std_rho_orig", "std_rho_map", "min_jacobian", "n_flipped", "max_mu", "mean_mu", "mean_dd",
               "mean_dmu"]
#: (field, boundary) of the classical density solvers' references (diffusion and flow alike)
DENSITY_CASES = ([(name, "square") for name in DENSITIES_2D] + [(name, "free") for name in DENSITIES_2D[:4]]
                 + [(name, "square") for name in DENSITIES_3D[:2]] + [(DENSITIES_3D[2], "free")])
#: The surrogates' raw maps (no fold repair, which post-processes the map and is tested in test_repair.py).
RAW = {"repair": False}
#: The frozen tiny networks of ``tests/data`` (written once by ``scripts/make_reference_outputs.py --make-models``)
#: and the fields each one maps.
SURROGATES = {"tiny-beltrami2d": ["T1", "T3"], "tiny-deq2d-square": ["sin-cos", "ring", "exp-log"],
              "tiny-deq2d-free": ["rect-peak"], "tiny-dem3d-cube": ["sin-cos-3d"],
              "tiny-dem3d-free": ["octant-3d", "sin-cos-3d"]}
#: A network map good enough for the polish to start warm (Std(rho~_map) 0.48 of the input's, below
#: ``rfmap.finish.polish.POOR``); polished without the guard, which would keep the cold flow's map here.
WARM_POLISH = ("tiny-dem3d-free", "sin-cos-3d")
#: The stretching factor of the overshooting maps, by task: three (density) or eight (Beltrami) times the network's
#: displacement folds them, so the default path repairs them and (density) shortens them.
OVERSHOOT = {"density": 3.0, "beltrami": 8.0}
#: Two squares of side 1000 (planar metres) with values 3 and 5, and the 2 x 2 block of tests/cartogram/test_resize.py with
#: values 1, 1, 1, 5: the cartogram's input, mapped in two passes at N = 24.
CARTOGRAM_N, CARTOGRAM_PASSES = 24, 2

#: How each group of keys (the part before the first "/") is compared: "round-off" (double precision, relative
#: 1e-10) or "float32" (1e-5 of the array's scale); keys holding triangulations ("elements") are compared exactly.
ROUND_OFF = ("field", "field-raw", "mu", "map", "weights", "jitter", "lbs", "lbs-metrics", "lbs-square",
             "dem-square", "dem-square-metrics", "dem-free", "dem-free-metrics", "sur-field", "sur-array-field",
             "sur-points-field", "cartogram-diffusion")
FLOAT32 = ("flow-square", "flow-square-metrics", "flow-free", "flow-free-metrics", "sur", "sur-refine",
           "sur-alpha", "sur-metrics", "sur-array", "sur-points", "sur-default", "sur-default-info",
           "sur-overshoot", "sur-overshoot-info", "sur-polish", "sur-polish-warm", "sur-polish-info",
           "sur-symmetrize", "cartogram-flow")


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


def group(key: str) -> str:
    """The group of a key: its part before the first ``/`` (``"dem-square/ring"`` -> ``"dem-square"``)."""
    return key.split("/", 1)[0]


def comparison(key: str) -> str:
    """``"exact"``, ``"round-off"`` or ``"float32"``: how the stored array of ``key`` is compared."""
    if "elements" in key:  # triangulations of the query points are integer data
        return "exact"
    g = group(key)
    if g in ROUND_OFF:
        return "round-off"
    if g in FLOAT32:
        return "float32"
    raise KeyError(f"no comparison rule for {key!r}")


def float32_equal(a: np.ndarray, b: np.ndarray, atol: float = 1e-5) -> bool:
    """Same shape, same NaNs, and every entry within ``atol`` times the larger of 1 and ``b``'s largest magnitude."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape != b.shape or not np.array_equal(np.isnan(a), np.isnan(b)):
        return False
    ok = ~np.isnan(b)
    scale = max(1.0, float(np.abs(b[ok]).max(initial=0.0)))
    return bool(np.all(np.abs(a[ok] - b[ok]) <= atol * scale))


def matches(key: str, now: np.ndarray, ref: np.ndarray) -> bool:
    """Whether ``now`` reproduces the stored ``ref`` of ``key`` (:func:`comparison`)."""
    rule = comparison(key)
    if rule == "exact":
        return bool(np.shape(now) == np.shape(ref) and np.array_equal(now, ref))
    if rule == "round-off":
        return _round_off_equal(now, ref)
    return float32_equal(now, ref)


def _centroids(n: int) -> np.ndarray:
    from rfmap.core.mesh import grid_mesh

    mesh = grid_mesh(n, 2)
    return mesh.points[mesh.elements].mean(1)


def field_outputs() -> dict[str, np.ndarray]:
    """Test densities (preprocessed and raw), exact Beltrami coefficients and maps, weights and jitter."""
    import rfmap.fields as F
    from rfmap.core.mesh import grid_mesh, grid_points, jittered_points, vertex_weights

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
        out[f"weights/{dim}d"] = vertex_weights(mesh.points, mesh.elements)
        grad = np.linalg.norm(mesh.points - 0.5, axis=1)
        out[f"jitter/{dim}d"] = jittered_points(n, dim, np.random.default_rng(7), grad_magnitude=grad)
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
    for name, boundary in DENSITY_CASES:
        n = N2 if name in DENSITIES_2D else N3
        res = solve_dem(F.sample_density(name, n), boundary=boundary)
        out[f"dem-{boundary}/{name}"] = res.mapped_points
        out[f"dem-{boundary}-metrics/{name}"] = _metric_vector(res.metrics())
    return out


def flow_outputs() -> dict[str, np.ndarray]:
    """Mapped vertices and metrics of the flow-based solver, square and free boundary, 2D and 3D."""
    import rfmap.fields as F
    from rfmap.solvers import solve_flow

    out = {}
    for name, boundary in DENSITY_CASES:
        n = N2 if name in DENSITIES_2D else N3
        res = solve_flow(F.sample_density(name, n), boundary=boundary)
        out[f"flow-{boundary}/{name}"] = res.mapped_points
        out[f"flow-{boundary}-metrics/{name}"] = _metric_vector(res.metrics())
    return out


def tiny_surrogate(name: str):
    """A frozen tiny network of ``tests/data`` (see :data:`SURROGATES`)."""
    from rfmap import Surrogate

    path = DATA_DIR / f"{name}.safetensors"
    if not path.exists():
        pytest.fail(f"missing {path}; write it with scripts/make_reference_outputs.py --make-models")
    return Surrogate.load(path)


def _pipeline_info(res) -> np.ndarray:
    """What the default path did: repair needed, elements folded before the repair, the shortening's scale (NaN when
    the map was not shortened)."""
    rep = res.info.get("repair") or {}
    short = res.info.get("shorten")
    return np.array([float(bool(rep.get("needed"))), float(rep.get("n_flipped_before", 0)),
                     np.nan if short is None else float(short["scale"])])


def _polish_info(res) -> np.ndarray:
    """How the polish went: started warm (1) or cold (0), kept the warm flow's map (1) or the cold one's (0), and
    Std(rho~_map) of the result."""
    p = res.info["polish"]
    return np.array([float(p["start"] == "warm"), float(p.get("kept", p["start"]) == "warm"),
                     res.metrics().std_rho_map])


def surrogate_outputs() -> dict[str, np.ndarray]:
    """Maps of the frozen tiny networks: named fields raw, refined, by the default path (repair and shortening), an
    overshooting map, polished and symmetrized; a grid array; scattered query points."""
    import rfmap.fields as F
    from rfmap.surrogate import quiet_quality

    out = {}
    rng = np.random.default_rng(3)
    for model, names in SURROGATES.items():
        sur = tiny_surrogate(model)
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
        with quiet_quality():  # the shortened maps warn; that is tested in test_surrogate.py
            res = sur.map(name, n)
            out[f"sur-default/{model}/{name}"] = res.mapped_points
            out[f"sur-default-info/{model}/{name}"] = _pipeline_info(res)
            res = sur.map(name, n, alpha=[OVERSHOOT[sur.spec.kind]] * sur.spec.dim)
            out[f"sur-overshoot/{model}/{name}"] = res.mapped_points
            out[f"sur-overshoot-info/{model}/{name}"] = _pipeline_info(res)
        if sur.spec.kind == "density":
            res = sur.map(name, n, polish=True)
            out[f"sur-polish/{model}/{name}"] = res.mapped_points
            out[f"sur-polish-info/{model}/{name}"] = _polish_info(res)
        if (model, names[-1]) == WARM_POLISH:
            res = sur.map(names[-1], n, polish=True, guard=False)
            out[f"sur-polish-warm/{model}/{names[-1]}"] = res.mapped_points
            out[f"sur-polish-info/{model}/{names[-1]}-warm"] = _polish_info(res)
        res = sur.map(name, n, symmetrize=True, **RAW)
        out[f"sur-symmetrize/{model}/{name}"] = res.mapped_points
        if sur.spec.kind == "density":
            arr = F.DENSITIES[name].sample(n + 2, preprocess=False)
        else:
            from rfmap.core.mesh import grid_points

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


def _collection(values) -> dict:
    """Squares of side 1000 side by side (two values) or in a 2 x 2 block (four), ids a, b, ..."""
    side = 1000.0
    corners = [(0, 0), (side, 0)] if len(values) == 2 else [(0, 0), (side, 0), (0, side), (side, side)]
    return {"type": "FeatureCollection", "features": [
        {"type": "Feature", "id": k, "properties": {"pop": v},
         "geometry": {"type": "Polygon", "coordinates": [[[x, y], [x + side, y], [x + side, y + side],
                                                          [x, y + side], [x, y]]]}}
        for k, v, (x, y) in zip("abcd", values, corners)]}


def cartogram_outputs() -> dict[str, np.ndarray]:
    """Vertices (unit-square frame) and areas of small cartograms by the diffusion and the flow-based method."""
    import shapely

    from rfmap.cartogram.resize import cartogram

    out = {}
    for label, values in (("two", [3, 5]), ("block", [1, 1, 1, 5])):
        for method in ("diffusion", "flow"):
            c = cartogram(_collection(values), "pop", method=method, n=CARTOGRAM_N, iterations=CARTOGRAM_PASSES)
            out[f"cartogram-{method}/{label}"] = shapely.get_coordinates(c.mapped)
            out[f"cartogram-{method}/{label}-areas"] = np.asarray(c.areas, dtype=np.float64)
    return out


def reference_outputs() -> dict[str, np.ndarray]:
    """Every stored output, by key ``group/name``."""
    return {**field_outputs(), **solver_outputs(), **flow_outputs(), **surrogate_outputs(), **cartogram_outputs()}


@pytest.fixture(scope="module")
def reference():
    if not DATA.exists():
        pytest.fail(f"missing {DATA}; write it with scripts/make_reference_outputs.py")
    with np.load(DATA) as z:
        return {k: z[k] for k in z.files}


def _check(reference, now: dict[str, np.ndarray], what: str) -> None:
    """Every produced key has its stored array and reproduces it; the stored keys of the same groups are exactly the
    produced ones (none left over from an output that is no longer made)."""
    groups = {group(k) for k in now}
    missing = set(now) - set(reference)
    assert not missing, f"no reference for {sorted(missing)}"
    stale = {k for k in reference if group(k) in groups} - set(now)
    assert not stale, f"stored {what} that are no longer produced: {sorted(stale)}"
    bad = [k for k in now if not matches(k, now[k], reference[k])]
    assert not bad, f"{what} differ from the reference: {bad}"


def test_every_stored_key_has_a_comparison_rule(reference):
    for k in reference:
        comparison(k)


def test_fields_bit_identical(reference):
    _check(reference, field_outputs(), "fields")


def test_solvers_and_metrics_bit_identical(reference):
    _check(reference, solver_outputs(), "solver outputs or metrics")


def test_flow_solver_matches(reference):
    _check(reference, flow_outputs(), "flow solver outputs")


def test_surrogates_match(reference):
    _check(reference, surrogate_outputs(), "surrogate outputs")


def test_cartograms_match(reference):
    _check(reference, cartogram_outputs(), "cartograms")


def test_the_references_exercise_repair_shortening_and_both_polish_starts(reference):
    """The frozen references cover what they claim: the overshooting maps folded and were repaired, the density
    maps then shortened by a scale strictly between 0 and 1 (not to the identity), and the polish started both cold
    and warm."""
    over = {k: v for k, v in reference.items() if group(k) == "sur-overshoot-info"}
    assert len(over) == len(SURROGATES)
    for k, (repaired, folded, scale) in over.items():
        assert repaired == 1 and folded > 0, (k, repaired, folded)
        assert ("beltrami" in k and np.isnan(scale)) or 0.05 < scale < 0.95, (k, scale)
    polish = np.array([v for k, v in reference.items() if group(k) == "sur-polish-info"])
    assert set(polish[:, 0]) == {0.0, 1.0} and 1.0 in polish[:, 1]


def test_unnamed_keys_are_kept_by_the_writer(tmp_path):
    """``scripts/make_reference_outputs.py --only`` writes the named keys (patterns) and keeps every other stored
    array bit for bit, however much it now differs."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_reference_outputs",
                                                  DATA_DIR.parents[1] / "scripts" / "make_reference_outputs.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    path = tmp_path / "ref.npz"
    np.savez_compressed(path, **{"field/a": np.zeros(3), "field/b": np.ones(2), "sur/m/x": np.arange(4.0),
                                 "sur/m/gone": np.zeros(1)})
    now = {"field/a": np.full(3, 7.0), "field/b": np.ones(2), "sur/m/x": np.arange(4.0) + 1e-3,
           "sur/m/new": np.ones(5)}
    written = mod.update(path, now, only=["sur/m/*"])
    assert sorted(written) == ["sur/m/gone", "sur/m/new", "sur/m/x"]
    with np.load(path) as z:
        assert sorted(z.files) == ["field/a", "field/b", "sur/m/new", "sur/m/x"]
        np.testing.assert_array_equal(z["field/a"], np.zeros(3))  # not named: kept although it differs
        np.testing.assert_array_equal(z["sur/m/x"], np.arange(4.0) + 1e-3)
    with pytest.raises(ValueError, match="matches no key"):
        mod.update(path, now, only=["nothing/*"])
    assert all(fnmatch(k, "sur/m/*") for k in written)
