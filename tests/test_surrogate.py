"""Tests of :class:`rfmap.surrogate.Surrogate`: safe weight files (safetensors + JSON, never unpickled) with clear
errors for bad files, and inference from every kind of field input, at grids or arbitrary query points."""
from __future__ import annotations

import json
import os
import pickle

import numpy as np
import pytest
import torch

import rfmap.surrogate as S
from rfmap.fields import get_field
from rfmap.core.mesh import vertex_weights
from rfmap.core.mesh import element_measures, grid_points
from rfmap.nn import MultiResUNet
from rfmap.surrogate import Surrogate
from rfmap.tasks import TaskSpec

DENSITY = TaskSpec("density", 2, "square")
BELTRAMI = TaskSpec("beltrami", 2, "fixed")


def tiny(spec=DENSITY, seed=0, head_seed=None, **meta) -> Surrogate:
    torch.manual_seed(seed)
    sur = Surrogate(MultiResUNet(spec.dim, spec.n_params, base=4, depth=2), spec, {"name": "tiny", **meta})
    if head_seed is not None:
        g = torch.Generator().manual_seed(head_seed)
        with torch.no_grad():
            sur.model.head.weight.copy_(0.2 * torch.randn(sur.model.head.weight.shape, generator=g))
            sur.model.head.bias.copy_(0.02 * torch.randn(sur.model.head.bias.shape, generator=g))
    return sur


def bump(x):
    return 1.0 + 0.5 * np.sin(np.pi * x[..., 0]) * np.cos(np.pi * x[..., 1])


@pytest.fixture
def saved(tmp_path):
    sur = tiny(head_seed=3, n_range=[17, 25])
    w, j = sur.save(tmp_path / "tiny.safetensors")
    return sur, w, j


# ----------------------------------------------------------------------------------------------- files


def test_save_load_roundtrip(saved):
    sur, w, j = saved
    assert w.name == "tiny.safetensors" and j.name == "tiny.json"
    loaded = Surrogate.load(w)
    assert loaded.spec == sur.spec and loaded.n_range == (17, 25) and loaded.name == "tiny"
    for k, v in sur.model.state_dict().items():
        assert torch.equal(loaded.model.state_dict()[k], v), k
    a, b = sur.map("sin-cos", 21, repair=False), loaded.map("sin-cos", 21, repair=False)  # the networks' own maps
    assert np.abs(a.displacement).max() > 1e-3
    assert np.array_equal(a.mapped_points, b.mapped_points)
    meta = json.loads(j.read_text())
    assert meta["model"] == {"dim": 2, "n_params": 1, "base": 4, "depth": 2, "attention": True}
    assert meta["task"] == {"kind": "density", "dim": 2, "boundary": "square"}
    # the path may be given without the suffix
    assert Surrogate.load(w.with_suffix("")).name == "tiny"


def test_model_without_attention_roundtrips(tmp_path):
    sur = Surrogate(MultiResUNet(2, 1, base=4, depth=2, attention=False), DENSITY, {"name": "plain"})
    w, _ = sur.save(tmp_path / "plain.safetensors")
    loaded = Surrogate.load(w)
    assert set(loaded.model.state_dict()) == set(sur.model.state_dict())


def test_weight_file_is_safetensors_not_pickle(saved):
    _, w, _ = saved
    raw = w.read_bytes()
    header_len = int.from_bytes(raw[:8], "little")
    header = json.loads(raw[8:8 + header_len])
    assert header["__metadata__"]["format"] == "rfmap"
    assert "head.weight" in header
    assert not raw.startswith(b"\x80") and not raw.startswith(b"PK")  # neither a pickle nor a torch zip


def test_loading_never_unpickles(saved, monkeypatch):
    _, w, _ = saved

    def forbidden(*a, **k):
        raise AssertionError("unpickling during Surrogate.load")

    monkeypatch.setattr(pickle, "load", forbidden)
    monkeypatch.setattr(pickle, "loads", forbidden)
    monkeypatch.setattr(pickle, "Unpickler", forbidden)
    monkeypatch.setattr(torch, "load", forbidden)
    Surrogate.load(w)


class _Evil:
    def __reduce__(self):
        return (open, (os.environ["RFMAP_TEST_MARKER"], "w"))


def test_pickle_disguised_as_weights_is_rejected_without_running_it(saved, tmp_path, monkeypatch):
    _, w, j = saved
    marker = tmp_path / "pwned"
    monkeypatch.setenv("RFMAP_TEST_MARKER", str(marker))
    bad = tmp_path / "evil.safetensors"
    bad.write_bytes(pickle.dumps({"head.weight": _Evil()}))
    (tmp_path / "evil.json").write_text(j.read_text())
    with pytest.raises(ValueError, match="corrupt or truncated"):
        Surrogate.load(bad)
    assert not marker.exists()


@pytest.mark.parametrize("damage", ["garbage", "truncated", "empty"])
def test_corrupt_weight_file_raises_value_error(saved, tmp_path, damage):
    _, w, j = saved
    raw = w.read_bytes()
    data = {"garbage": np.random.default_rng(0).bytes(len(raw)), "truncated": raw[: len(raw) // 2],
            "empty": b""}[damage]
    bad = tmp_path / f"{damage}.safetensors"
    bad.write_bytes(data)
    (tmp_path / f"{damage}.json").write_text(j.read_text())
    with pytest.raises(ValueError, match="corrupt or truncated weight file"):
        Surrogate.load(bad)


@pytest.mark.parametrize("change,match", [({"base": 8}, "shape mismatch"), ({"depth": 3}, "do not match"),
                                          ({"n_params": 2}, "shape mismatch")])
def test_mismatched_metadata_raises_value_error(saved, change, match):
    _, w, j = saved
    meta = json.loads(j.read_text())
    meta["model"].update(change)
    j.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=match):
        Surrogate.load(w)


def test_bad_metadata(saved):
    _, w, j = saved
    meta = json.loads(j.read_text())
    j.write_text("{not json")
    with pytest.raises(ValueError, match="corrupt metadata"):
        Surrogate.load(w)
    j.write_text(json.dumps({k: v for k, v in meta.items() if k != "model"}))
    with pytest.raises(ValueError, match="lacks the model"):
        Surrogate.load(w)
    j.write_text(json.dumps({**meta, "task": {"kind": "curvature", "dim": 2, "boundary": "square"}}))
    with pytest.raises(ValueError, match="unknown task kind"):
        Surrogate.load(w)


def test_missing_files(saved, tmp_path):
    _, w, j = saved
    with pytest.raises(FileNotFoundError, match="no weight file"):
        Surrogate.load(tmp_path / "nothing.safetensors")
    j.unlink()
    with pytest.raises(FileNotFoundError, match="no metadata"):
        Surrogate.load(w)


def test_model_and_task_must_fit():
    with pytest.raises(ValueError, match="does not fit"):
        Surrogate(MultiResUNet(2, 1, base=4, depth=2), BELTRAMI)


def test_models_and_pretrained():
    names = S.models()
    assert isinstance(names, list) and names == sorted(names)
    for name in names:
        assert (S.WEIGHTS_DIR / f"{name}.safetensors").exists()
    with pytest.raises(ValueError, match="no pretrained model 'nope'"):
        Surrogate.pretrained("nope")


# ----------------------------------------------------------------------------------------------- inputs


def test_map_accepts_name_callable_array_and_scattered():
    sur = tiny(head_seed=1)
    sur_map = sur.map

    def raw(*a, **kw):  # the raw network map: this test is about the inputs, not the bijectivity repair
        return sur_map(*a, repair=False, **kw)

    sur.map = raw
    n = 17
    by_name = sur.map("sin-cos", n)
    fn = get_field("sin-cos")
    by_callable = sur.map(lambda x: fn(x), n)
    by_array = sur.map(fn(grid_points(n, 2)).reshape(n, n), n)
    # scattered samples at exactly the grid vertices (shuffled): linear interpolation reproduces the grid values
    perm = np.random.default_rng(0).permutation(n * n)
    pts = grid_points(n, 2)[perm]
    by_scattered = sur.map((pts, fn(pts)), n)
    for r in (by_name, by_callable, by_array, by_scattered):
        assert r.ref_points.shape == (n * n, 2) and r.mapped_points.shape == (n * n, 2)
        assert r.elements.shape == (2 * (n - 1) ** 2, 3) and r.field.shape == (n * n,)
        assert r.kind == "density" and r.info["work_n"] == n
        np.testing.assert_allclose(r.mapped_points, by_name.mapped_points, atol=1e-6, rtol=0)
        # the field is returned with unit mass
        w = vertex_weights(r.ref_points, r.elements)
        assert float(w @ r.field) == pytest.approx(1.0, abs=1e-9)
    assert np.abs(by_name.displacement).max() > 1e-3
    # genuinely scattered samples (1000 random points and the boundary at spacing 1/32) give nearly the same map:
    # the model sees the field up to the O(spacing^2) error of linear interpolation (measured: 2-5% of the
    # displacement for 1500-600 points)
    rng = np.random.default_rng(1)
    t = np.linspace(0, 1, 33)[:-1]
    edge = np.concatenate([np.stack([t, 0 * t], 1), np.stack([1 + 0 * t, t], 1), np.stack([1 - t, 1 + 0 * t], 1),
                           np.stack([0 * t, 1 - t], 1)])
    cloud = np.concatenate([rng.random((1000, 2)), edge])
    r = sur.map((cloud, fn(cloud)), n)
    assert np.abs(r.mapped_points - by_name.mapped_points).max() < 0.1 * np.abs(by_name.displacement).max()


def test_map_beltrami_inputs():
    sur = tiny(BELTRAMI)
    n = 17
    r = sur.map("T1", n)
    assert r.kind == "beltrami" and r.field.shape == (2 * (n - 1) ** 2,) and np.iscomplexobj(r.field)
    assert np.array_equal(r.mapped_points, r.ref_points)  # untrained: the identity
    mu = get_field("T1").mu
    r2 = sur.map(mu(grid_points(n, 2)).reshape(n, n), n)
    assert r2.field.shape == r.field.shape
    r3 = sur.map(lambda x: 0.2 * x[..., 0] + 0.1j * x[..., 1], n)
    assert float(np.abs(r3.field).max()) < 0.3


def test_wrong_kind_of_field():
    with pytest.raises(ValueError, match="density field"):
        tiny(BELTRAMI).map("sin-cos", 17)
    with pytest.raises(ValueError, match="beltrami field"):
        tiny().map("T1", 17)
    with pytest.raises(ValueError, match="3D"):
        tiny().map("sin-cos-3d", 17)
    with pytest.raises(ValueError, match="unknown field"):
        tiny().map("no-such-field", 17)
    with pytest.raises(ValueError, match="real density"):
        tiny().map(np.ones((17, 17), dtype=complex), 17)
    with pytest.raises(ValueError, match="< 1"):
        tiny(BELTRAMI).map(np.full((17, 17), 1.2 + 0j), 17)


def test_bad_field_values():
    sur = tiny()
    bad = bump(grid_points(17, 2)).reshape(17, 17)
    bad[3, 4] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        sur.map(bad, 17)
    with pytest.raises(ValueError, match="NaN"):
        sur.map(lambda x: np.where(x[..., 0] > 0.5, np.nan, 1.0), 17)
    with pytest.raises(ValueError, match="NaN"):
        tiny(BELTRAMI).map(lambda x: np.full(x.shape[0], np.nan + 0j), 17)
    with pytest.raises(ValueError, match="N\\^2 grid"):
        sur.map(np.ones((17, 16)), 17)
    with pytest.raises(ValueError, match="scattered"):
        sur.map((np.random.rand(10, 3), np.ones(10)), 17)
    with pytest.raises(ValueError, match="N must be >= 3"):
        sur.map("sin-cos", 2)
    with pytest.raises(ValueError, match="smaller than this model"):
        sur.map("sin-cos", 17, work_n=sur.model.min_size - 1)


# ----------------------------------------------------------------------------------------------- query points


def test_points_outside_the_domain():
    sur = tiny()
    for pts in (np.array([[0.5, 0.5], [1.2, 0.3], [0.1, 0.9]]), np.array([[0.5, -0.01], [0.2, 0.3], [0.7, 0.9]])):
        with pytest.raises(ValueError, match="unit square"):
            sur.map("sin-cos", 17, points=pts)
    with pytest.raises(ValueError, match="NaN"):
        sur.map("sin-cos", 17, points=np.array([[0.5, np.nan], [0.2, 0.3], [0.7, 0.9]]))
    with pytest.raises(ValueError, match="shape"):
        sur.map("sin-cos", 17, points=np.random.rand(10, 3))


@pytest.mark.parametrize("spec,n", [(DENSITY, 17), (BELTRAMI, 17), (TaskSpec("density", 3, "free"), 9)], ids=str)
def test_points_give_the_map_at_those_points(spec, n):
    rng = np.random.default_rng(0)
    d = spec.dim
    corners = np.array(np.meshgrid(*([[0.0, 1.0]] * d), indexing="ij")).reshape(d, -1).T
    pts = np.concatenate([rng.random((80, d)), corners])
    r = tiny(spec).map(get_field({"density": "sin-cos", "beltrami": "T2"}[spec.kind] + ("-3d" if d == 3 else "")),
                       n, points=pts)
    assert np.array_equal(r.ref_points, pts)
    assert np.array_equal(r.mapped_points, pts)  # untrained: u(x) = x at every query point
    # a Delaunay triangulation of the points, positively oriented, covering the unit square / cube
    assert r.elements.shape[1] == d + 1 and r.elements.max() < len(pts)
    meas = element_measures(pts, r.elements)
    assert (meas > 0).all()
    assert meas.sum() == pytest.approx(1.0, abs=1e-9)
    if spec.kind == "density":
        assert r.field.shape == (len(pts),)
    else:
        assert r.field.shape == (len(r.elements),)


def test_points_agree_with_the_grid_map():
    """Query points at grid vertices give the same map as the grid output (interpolation of psi)."""
    sur = tiny(head_seed=2)
    grid = sur.map("exp-log", 17, work_n=17, repair=False)  # the network's own maps (no repair, no shortening)
    idx = np.array([0, 5, 40, 100, 150, 288])
    pts = grid.ref_points[idx]
    extra = np.array([[0.0, 1.0], [1.0, 0.0], [1.0, 1.0], [0.3, 0.31]])
    q = sur.map("exp-log", 17, points=np.concatenate([pts, extra]), work_n=17, repair=False)
    np.testing.assert_allclose(q.mapped_points[: len(idx)], grid.mapped_points[idx], atol=1e-6, rtol=0)


def test_map_batch_equals_individual_maps():
    sur = tiny(head_seed=4)
    fields = ["sin-cos", "ring", bump]
    batch = sur.map_batch(fields, 17)
    assert len(batch) == 3
    for f, rb in zip(fields, batch):
        r1 = sur.map(f, 17)
        np.testing.assert_allclose(rb.mapped_points, r1.mapped_points, atol=1e-6, rtol=0)
        np.testing.assert_array_equal(rb.field, r1.field)
    assert not np.allclose(batch[0].mapped_points, batch[1].mapped_points)
    with pytest.raises(ValueError, match="one output size"):
        sur.map_batch([np.ones((17, 17)), np.ones((21, 21))])


def test_traced_network_gives_the_eager_maps():
    """Surrogate.trace: one TorchScript trace per input shape, sharing the parameters, so the maps are the eager
    ones bit for bit, also after the parameters change in place; moving the network drops the traces.  (The raw
    maps: this random network's maps are worse than the identity, which the delivered maps would fall back to.)"""
    sur = tiny(head_seed=6)
    eager = [sur.map(f, n, repair=False) for f, n in (("sin-cos", 17), ("ring", 21))]
    assert sur.trace() is sur
    for _ in range(2):
        traced = [sur.map(f, n, repair=False) for f, n in (("sin-cos", 17), ("ring", 21))]
        for a, b in zip(eager, traced):
            np.testing.assert_array_equal(a.mapped_points, b.mapped_points)
    assert len(sur._traces) == 2 and all(isinstance(t, torch.jit.ScriptModule) for t in sur._traces.values())
    batch = sur.map_batch(["sin-cos", "ring"], 17, repair=False)  # a batch of two is another shape
    assert len(sur._traces) == 3
    np.testing.assert_allclose(batch[0].mapped_points, eager[0].mapped_points, atol=1e-6, rtol=0)
    with torch.no_grad():
        next(sur.model.parameters()).mul_(1.5)
    traced = sur.map("sin-cos", 17, repair=False).mapped_points
    np.testing.assert_array_equal(traced, sur.trace(False).map("sin-cos", 17, repair=False).mapped_points)
    assert not np.array_equal(traced, eager[0].mapped_points)
    sur.trace().map("sin-cos", 17)
    sur.to("cpu")
    assert sur._traces == {}


def test_untraceable_network_runs_eagerly(monkeypatch):
    sur = tiny(head_seed=6)
    want = sur.map("sin-cos", 17).mapped_points

    def refuse(*a, **k):
        raise RuntimeError("cannot trace this network")

    monkeypatch.setattr(torch.jit, "trace", refuse)
    np.testing.assert_array_equal(sur.trace().map("sin-cos", 17).mapped_points, want)
    assert list(sur._traces.values()) == [sur.model]


def test_work_n_is_clipped_to_the_training_range():
    sur = tiny(n_range=[17, 25])
    assert (sur.work_n(9), sur.work_n(21), sur.work_n(65)) == (17, 21, 25)
    assert sur.map("sin-cos", 65).info["work_n"] == 25
    assert tiny().n_range == (5, 1 << 30)  # no range: native resolution


def test_alpha_scales_the_displacement():
    sur = tiny(head_seed=5)
    r1 = sur.map("sin-cos", 17, repair=False)  # the raw maps: alpha acts on the network's displacement
    r2 = sur.map("sin-cos", 17, alpha=[0.5, 2.0], repair=False)
    np.testing.assert_allclose(r2.displacement, r1.displacement * np.array([0.5, 2.0]), atol=1e-12)
    assert r2.info["alpha"] == [0.5, 2.0]


def test_3d_single_field_matches_its_row_in_a_batch():
    """A single 3D field (whose no-grad Conv3d layers take the oneDNN kernel at batch 1) gives its row of a batched
    evaluation to float32 round-off: the network acts on every sample independently."""
    sur = tiny(TaskSpec("density", 3, "square"), head_seed=1)
    rng = np.random.default_rng(0)
    g = rng.uniform(0.5, 1.5, size=(2, 9, 9, 9))
    with torch.no_grad():
        one = sur.displacement(g[:1])
        both = sur.displacement(g)
    assert one.shape == (1, 3, 9, 9, 9)
    assert float(one.abs().max()) > 1e-3
    torch.testing.assert_close(one, both[:1], rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("dim,n,boundary", [(2, 9, "square"), (3, 6, "square"), (3, 5, "free")])
def test_density_objective_grid_path_equals_the_element_path(dim, n, boundary):
    """The refinement objective on a grid mesh gives the same value through the strided measures, for several
    stretching vectors, including one that folds the map (fold penalty active)."""
    from rfmap.core.mesh import grid_mesh
    from rfmap.tasks.objectives import density_objective

    mesh = grid_mesh(n, dim)
    ref = torch.as_tensor(mesh.points)
    g = torch.Generator().manual_seed(n)
    psi = 0.3 * torch.randn(ref.shape, generator=g, dtype=torch.float64)
    dens = 1 + np.random.default_rng(n).random(len(ref))
    el = torch.as_tensor(mesh.elements)
    slow = density_objective(ref, psi, el, dens, boundary)
    fast = density_objective(ref, psi, el, dens, boundary, grid_n=n)
    for alpha in (np.ones(dim), np.full(dim, 0.3), np.linspace(0.5, 2.5, dim)):
        assert fast(alpha) == pytest.approx(slow(alpha), rel=1e-12, abs=1e-12)
    assert slow(np.full(dim, 3.0)) > slow(np.full(dim, 0.1))  # large stretch folds: the penalty shows


# ----------------------------------------------------------------------------------------------- regrid (3D)


def _folding_then_benign(sur, benign_below: int):
    """A displacement that folds on working grids of side >= ``benign_below`` (neighbouring vertices along x pushed
    through each other) and below it a constant shift towards x = 0, which enlarges the denser side of a density
    rising in x (so the map is more equal than the input)."""

    def fake(grids):
        b, n = grids.shape[0], grids.shape[1]
        psi = torch.zeros(b, 3, n, n, n)
        if n >= benign_below:
            sign = torch.tensor([(-1.0) ** i for i in range(n)])
            psi[:, 0] = 0.9 / (n - 1) * sign[:, None, None]
        else:
            psi[:, 0] = -0.05
        return psi

    sur.displacement = fake
    return sur


def rising(x):
    return 1.0 + 0.5 * x[..., 0]


def test_regrid_sides_step_down_to_the_training_range():
    sur = tiny(TaskSpec("density", 3, "square"), n_range=[32, 48])
    assert sur._regrid_sides(48) == [44, 40, 36, 32]
    assert sur._regrid_sides(46) == [42, 38, 34, 32]
    assert sur._regrid_sides(32) == []


def test_a_folded_3d_map_is_taken_from_a_coarser_working_grid():
    """The default grid (17) and the next (13) fold; the 9-grid gives a fold-free map more equal than the input,
    which is returned without a repair, exactly as an explicit work_n = 9 would give it."""
    sur = _folding_then_benign(tiny(TaskSpec("density", 3, "square"), n_range=[9, 17]), benign_below=10)
    r = sur.map(rising, 17)
    assert r.info["regrid"]["from"] == 17 and r.info["regrid"]["tried"] == [13, 9]
    assert r.info["regrid"]["work_n"] == 9 and r.info["work_n"] == 9
    assert r.info["repair"]["needed"] is False
    m = r.metrics()
    assert m.n_flipped == 0 and m.std_rho_map < m.std_rho_orig
    np.testing.assert_array_equal(r.mapped_points, sur.map(rising, 17, work_n=9).mapped_points)
    assert r.time >= r.info["regrid"]["time"]


def test_an_explicit_work_n_and_2d_maps_go_straight_to_the_repair():
    sur = _folding_then_benign(tiny(TaskSpec("density", 3, "square"), n_range=[9, 17]), benign_below=10)
    r = sur.map(rising, 17, work_n=17)
    assert "regrid" not in r.info and r.info["repair"]["needed"] and r.metrics().n_flipped == 0
    sur2 = tiny(n_range=[9, 17])

    def fold2(grids):
        b, n = grids.shape[:2]
        psi = torch.zeros(b, 2, n, n)
        psi[:, 0] = 0.9 / (n - 1) * torch.tensor([(-1.0) ** i for i in range(n)])[:, None]
        return psi

    sur2.displacement = fold2
    r2 = sur2.map(rising, 17)
    assert "regrid" not in r2.info and r2.info["repair"]["needed"] and r2.metrics().n_flipped == 0


def test_when_every_working_grid_folds_the_default_map_is_repaired():
    sur = _folding_then_benign(tiny(TaskSpec("density", 3, "square"), n_range=[9, 17]), benign_below=0)
    r = sur.map(rising, 17)
    assert r.info["regrid"]["tried"] == [13, 9] and r.info["regrid"]["work_n"] is None
    assert r.info["work_n"] == 17 and r.info["repair"]["needed"] and r.metrics().n_flipped == 0


def test_regrid_summary_lines():
    from rfmap.cli.commands import regrid_summary

    took = regrid_summary({"from": 48, "tried": [44, 40], "work_n": 40, "time": 0.25})
    assert took == "working grid: 48 folded; took 40 (tried 44, 40; 0.250 s)"
    none = regrid_summary({"from": 48, "tried": [44, 40, 36, 32], "work_n": None, "time": 0.5})
    assert none.startswith("working grid: 48 folded, and so did 44, 40, 36, 32; the 48-grid map is repaired")


def test_with_polish_a_folded_3d_map_starts_cold_without_trying_coarser_grids():
    sur = _folding_then_benign(tiny(TaskSpec("density", 3, "square"), n_range=[9, 17]), benign_below=10)
    r = sur.map(rising, 17, polish=True)
    assert "regrid" not in r.info and r.info["polish"]["start"] == "cold" and r.metrics().n_flipped == 0


# ----------------------------------------------------------------------------------------------- map quality


@pytest.mark.parametrize("n, d", [(21, 2), (9, 3)])
def test_density_quality_matches_the_metrics(n, d):
    from rfmap.core.mesh import grid_mesh
    from rfmap.core.result import MapResult

    ref = grid_points(n, d)
    rng = np.random.default_rng(0)
    dens = 0.5 + rng.random(len(ref))
    for amp in (0.02, 0.0):  # a smooth map (float32 measures), and the identity
        mapped = ref + amp * np.sin(2 * np.pi * ref[:, ::-1]) * (ref * (1 - ref)).prod(1, keepdims=True) * 16
        q = S.density_quality(mapped, dens, n)
        m = MapResult(ref_points=ref, mapped_points=mapped, elements=grid_mesh(n, d).elements, field=dens,
                      kind="density", time=0.0).metrics()
        assert q["std_rho_orig"] == pytest.approx(m.std_rho_orig, rel=1e-12)
        assert q["std_rho_map"] == pytest.approx(m.std_rho_map, rel=1e-5)
        assert q["min_jacobian"] == pytest.approx(m.min_jacobian, rel=1e-5)
        assert q["worse"] == (m.std_rho_map > m.std_rho_orig * (1 + S.QUALITY_MARGIN) + 1e-5)
    assert not q["worse"] and q["min_jacobian"] == pytest.approx(1.0, rel=1e-5)  # the identity (float32 measures)


def test_density_quality_of_thin_and_broken_maps():
    from rfmap.core.mesh import grid_mesh
    from rfmap.core.result import MapResult

    n = 11
    ref = grid_points(n, 2)
    dens = 1.0 + ref[:, 0]
    mapped = ref.copy()
    mapped[60] += 0.9999 * (ref[61] - ref[60])  # an interior vertex almost onto its neighbour: slivers
    q = S.density_quality(mapped, dens, n)
    m = MapResult(ref_points=ref, mapped_points=mapped, elements=grid_mesh(n, 2).elements, field=dens,
                  kind="density", time=0.0).metrics()
    assert q["min_jacobian"] < 1e-3  # decided in double precision: exact to round-off
    assert q["min_jacobian"] == pytest.approx(m.min_jacobian, rel=1e-9)
    assert q["std_rho_map"] == pytest.approx(m.std_rho_map, rel=1e-9) and q["worse"]
    mapped[3] = np.nan
    assert S.density_quality(mapped, dens, n)["worse"]


def test_a_map_that_undoes_equalization_warns():
    import warnings

    # a density uniform to one part in a million (a uniform one is mapped to the identity without the network):
    # any movement makes it less equal
    flat = lambda x: 1.0 + 1e-6 * x[..., 0]  # noqa: E731
    with pytest.warns(S.PoorMapWarning, match=r"less equal than it was .*shortened to .*refine=True.*polish=True"):
        r = tiny(head_seed=3).map(flat, 21)
    # delivered: shortened back to the identity, the only map that leaves a nearly uniform density so
    assert r.info["shorten"]["scale"] == 0.0 and r.info["shorten"]["std_before"] > 1e-3
    assert not r.info["quality"]["worse"] and r.info["quality"]["std_rho_map"] < 1e-5  # (float32 measures)
    np.testing.assert_allclose(r.mapped_points, r.ref_points, atol=0)
    with pytest.warns(S.PoorMapWarning, match=r"less equal than it was \(Std"):  # the raw map: as it came
        raw = tiny(head_seed=3).map(flat, 21, repair=False)
    assert raw.info["quality"]["worse"] and raw.info["quality"]["std_rho_map"] > 1e-3 and "shorten" not in raw.info
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with S.quiet_quality():
            tiny(head_seed=3).map(flat, 21)
            ident = tiny().map(bump, 21)  # the untrained network: the identity, no worse than the input
    assert not ident.info["quality"]["worse"] and ident.info["quality"]["no_gain"]
    with pytest.warns(S.PoorMapWarning, match="shortened to 0 of itself"):  # query points: judged on the grid
        cloud = tiny(head_seed=3).map(flat, points=grid_points(21, 2)[::7])
    assert "quality" not in cloud.info and cloud.info["shorten"]["scale"] == 0.0


@pytest.mark.parametrize("d", [2, 3])
def test_density_quality_flags_the_identity_on_every_grid(d):
    """The identity leaves Std(rho~) as it was, up to round-off that differs from grid to grid: within the stated
    tolerance GAIN_RTOL it brings no gain on every grid, and it is never worse."""
    for n in ([17, 33, 51, 64, 97] if d == 2 else [9, 12, 17]):
        ref = grid_points(n, d)
        dens = 1.0 + 0.8 * np.sin(2 * np.pi * ref[:, 0]) * np.cos(2 * np.pi * ref[:, 1])
        q = S.density_quality(ref, dens, n)
        assert abs(q["std_rho_map"] / q["std_rho_orig"] - 1.0) < 1e-5  # equal up to round-off
        assert q["no_gain"] and not q["worse"], n


def test_the_untrained_networks_identity_map_is_flagged_on_every_grid():
    """Surrogate.map warns for the identity map of a density on every grid side, and leaves it unshortened."""
    sur = tiny()
    for n in (17, 21, 33, 51):
        with pytest.warns(S.PoorMapWarning, match=r"does not make this density more equal"):
            r = sur.map("sin-cos", n)
        np.testing.assert_array_equal(r.mapped_points, r.ref_points)
        assert r.info["quality"]["no_gain"] and "shorten" not in r.info


def test_query_points_are_shortened_as_their_working_grid_map():
    """A density map of query points is shortened by the scale the working grid's delivered map gets, so that grid
    and points deliver one map; the judgement is made on the working grid and reported."""
    sur = tiny(head_seed=6)
    with pytest.warns(S.PoorMapWarning, match=r"shortened to"):
        grid = sur.map(bump, 21, work_n=21)
    grid_only = r"shortened to .*polish=True \(the flow-based finish, on a grid only\) can help"
    with pytest.warns(S.PoorMapWarning, match=grid_only):
        q = sur.map(bump, 21, points=grid_points(21, 2), work_n=21)
    s_grid, rep = grid.info["shorten"]["scale"], q.info["shorten"]
    assert 0.0 < s_grid < 1.0  # a genuine shortening, not one of the ends
    assert rep["scale"] == pytest.approx(s_grid, abs=1e-12)
    assert rep["decided_on"] == "working grid" and rep["work_n"] == 21 and not rep["query_mesh"]
    assert rep["quality"]["std_rho_map"] < rep["quality"]["std_rho_orig"]  # judged better than no map there
    m = q.metrics()
    assert m.n_flipped == 0 and m.std_rho_map < m.std_rho_orig
    # a scattered cloud: the same scale
    cloud = np.vstack([np.random.default_rng(1).random((300, 2)), [[0, 0], [0, 1], [1, 0], [1, 1]]])
    with pytest.warns(S.PoorMapWarning):
        c = sur.map(bump, 21, points=cloud, work_n=21)
    assert c.info["shorten"]["scale"] == pytest.approx(s_grid, abs=1e-12) and c.metrics().n_flipped == 0


def test_query_shortening_falls_back_to_the_query_mesh(monkeypatch):
    """When the working grid's scale would fold the query mesh, the scale is chosen on the query mesh itself."""
    import rfmap.finish.query as query

    monkeypatch.setattr(query, "fold_free", lambda *a, **k: False)  # pretend the working grid's scale folds
    with pytest.warns(S.PoorMapWarning):
        q = tiny(head_seed=6).map(bump, 21, points=grid_points(21, 2)[::3], work_n=21)
    rep = q.info["shorten"]
    assert rep["query_mesh"] and rep["scale"] == rep["query_report"]["scale"]
    m = q.metrics()
    assert m.n_flipped == 0 and m.std_rho_map <= m.std_rho_orig + 1e-12


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("value", [0.0, 1.0, -1.0])
def test_a_constant_density_is_the_identity_exactly(dim, value):
    """A constant density (all zeros, all equal, all -1: uniform after the paper's preprocessing) is equal already:
    a network that moves every other field (``head_seed``) returns the identity bit for bit, without a warning,
    for an array, a function, query points, ``refine``, ``polish`` and a batch; ``info`` says why."""
    import warnings

    sur = tiny(TaskSpec("density", dim, "square"), head_seed=3)
    n = 13
    grid = np.full((n,) * dim, value)
    const = lambda x: np.full(x.shape[:-1], value)  # noqa: E731
    pts = 0.02 + 0.96 * grid_points(n, dim)[::5]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        results = [sur.map(grid), sur.map(const, n), sur.map(grid, points=pts), sur.map(grid, refine=True),
                   *sur.map_batch([grid, grid], n)]
        if dim == 2:
            results.append(sur.map(grid, polish=True))
    for r in results:
        assert np.array_equal(r.mapped_points, r.ref_points) and r.mapped_points is not r.ref_points
        assert dict(r.info) == {"uniform": True} and r.kind == "density"
        assert np.ptp(r.field) <= 1e-12 * r.field[0]  # query points: a multilinear interpolant of the constant
    assert results[2].ref_points.shape == pts.shape
    with S.quiet_quality():  # the same network does move a field that is not constant
        moved = sur.map(lambda x: 1.0 + 0.5 * np.sin(np.pi * x[..., 0]), n, repair=False)
    assert np.abs(moved.mapped_points - moved.ref_points).max() > 1e-3
