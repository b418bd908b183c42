"""Function-preserving growth of a U-Net (rfmap.nn.grow), the size curriculum and native mapping."""
from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
import torch

from rfmap import Surrogate
from rfmap.training.config import get_config
from rfmap.nn.grow import check_growth, copy_map, grow_unet
from rfmap.nn.model import MultiResUNet
from rfmap.training.data import step_batch, step_size_n

#: the grown network's output equals its parent's to this absolute tolerance (float32 round-off)
TOL = 1e-5


def _random_parent(dim: int, n_params: int, base: int, depth: int, seed: int = 0) -> MultiResUNet:
    """A U-Net with every weight random (a trained network's head is not zero), in eval mode."""
    torch.manual_seed(seed)
    net = MultiResUNet(dim, n_params, base, depth)
    with torch.no_grad():
        for p in net.parameters():
            p.normal_(0.0, 0.2)
    return net.eval()


@pytest.mark.parametrize("dim,n_params,base,depth,new,side", [
    (2, 1, 8, 3, 16, 33), (2, 2, 16, 3, 32, 27), (3, 1, 8, 2, 16, 13), (3, 1, 4, 2, 8, 9), (2, 1, 8, 2, 32, 21)])
def test_grown_network_maps_every_field_as_its_parent(dim, n_params, base, depth, new, side):
    parent = _random_parent(dim, n_params, base, depth)
    child = grow_unet(parent, new).eval()
    assert child.base == new and child.depth == depth and child.dim == dim
    assert sum(p.numel() for p in child.parameters()) > 2 * sum(p.numel() for p in parent.parameters())
    x = torch.randn(3, parent.in_channels, *([side] * dim))
    with torch.no_grad():
        a, b = parent(x), child(x)
    assert a.std() > 1e-3  # a non-trivial function
    # to 1e-5 of the output's scale (random weights give outputs far from a displacement's O(0.1))
    assert (a - b).abs().max() <= TOL * max(1.0, float(a.abs().max()))


@pytest.mark.parametrize("name,new", [("dem3d-cube", 16), ("deq2d-square", 32), ("beltrami2d", 32)])
def test_grown_shipped_model_maps_test_fields_as_its_parent(name, new):
    parent = Surrogate.pretrained(name)
    child = Surrogate(grow_unet(parent.model, new), parent.spec, parent.meta)
    field, n = ("sin-cos-3d", 20) if parent.spec.dim == 3 else (("T1", 33) if name == "beltrami2d" else ("ring", 33))
    a = parent.map(field, n, repair=False).mapped_points
    b = child.map(field, n, repair=False).mapped_points
    assert np.abs(a - b).max() < TOL


def test_copies_diverge_under_training():
    """The random split of each reading layer breaks the symmetry between a channel's copies."""
    parent = _random_parent(2, 1, 4, 2)
    child = grow_unet(parent, 8)
    src = copy_map(4, 8)
    first = child.lift.lift[0].weight.detach().clone()
    assert torch.equal(first[0], first[int(np.flatnonzero(src == src[0])[1])])  # copies start equal
    opt = torch.optim.SGD(child.parameters(), lr=0.1)
    x = torch.randn(2, 3, 17, 17)
    child.train()
    opt.zero_grad()
    child(x).square().mean().backward()
    opt.step()
    w = child.lift.lift[0].weight.detach()
    twin = int(np.flatnonzero(src == src[0])[1])
    d0, d1 = w[0] - first[0], w[twin] - first[twin]
    assert d0.abs().max() > 0 and (d0 - d1).abs().max() > 0.05 * d0.abs().max()


def test_copy_map_keeps_groups_whole():
    src = copy_map(16, 32)  # 8 groups of 2 -> 8 groups of 4
    assert np.bincount(src).tolist() == [2] * 16
    for g in range(8):  # every new group copies exactly one parent group
        assert set(src[4 * g:4 * g + 4] // 2) == {g}


@pytest.mark.parametrize("base,match", [(8, "larger"), (4, "larger"), (12, "multiple")])
def test_growth_refuses_what_it_cannot_preserve(base, match):
    with pytest.raises(ValueError, match=match):
        check_growth(MultiResUNet(2, 1, 8, 2), base)


def test_log_sampling_covers_the_range_per_octave():
    cfg = replace(get_config("deq2d-square", "ci"), n_range=(32, 256), n_sampling="log")
    ns = np.array([step_size_n(cfg, t) for t in range(3000)])
    assert ns.min() == 32 and ns.max() == 256
    octaves = [np.mean((ns >= lo) & (ns < 2 * lo)) for lo in (32, 64, 128)]
    assert all(abs(o - 1 / 3) < 0.04 for o in octaves)  # log-uniform: each octave a third of the steps
    uniform = replace(cfg, n_sampling="uniform")
    assert np.mean([step_size_n(uniform, t) < 64 for t in range(3000)]) < 0.2


def test_mixed_sampling_keeps_the_small_sides_frequent():
    cfg = replace(get_config("deq2d-square", "ci"), n_range=(32, 256), n_sampling="mixed")
    ns = np.array([step_size_n(cfg, t) for t in range(4000)])
    assert ns.min() == 32 and ns.max() == 256
    small = np.mean(ns <= 96)  # half uniform on [32, 96], half log-uniform (of which ln(97/32)/ln(257/32))
    expected = 0.5 + 0.5 * np.log(97 / 32) / np.log(257 / 32)
    assert abs(small - expected) < 0.03
    assert abs(np.mean(ns > 128) - 0.5 / 3) < 0.03  # only the log half reaches the top octave


def test_batch_points_keep_the_cost_per_step():
    cfg = replace(get_config("dem3d-cube", "ci"), batch=8, batch_points=2 * 48**3)
    assert [step_batch(cfg, n) for n in (24, 48, 64)] == [8, 2, 1]
    assert step_batch(replace(cfg, batch_points=0), 64) == 8
    with pytest.raises(ValueError, match="n_sampling"):
        replace(cfg, n_sampling="cubic")


def _train(*args: str, tmp_path, preset: str = "ci") -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rfmap.cli", "train", "--preset", preset, "--no-progress", *args],
                          capture_output=True, text=True, cwd=tmp_path, env={**__import__("os").environ,
                                                                              "OMP_NUM_THREADS": "1"})


@pytest.mark.parametrize("args,match", [
    (["--config", "dem3d-cube", "--init", "deq2d-square", "--grow", "32"], "trained for"),  # other task/dimension
    (["--config", "deq2d-square", "--init", "deq2d-square", "--grow", "8"], "larger"),      # smaller target
    (["--config", "deq2d-square", "--init", "deq2d-square", "--grow", "24"], "multiple"),
    (["--config", "deq2d-square", "--grow", "32"], "--init"),
    (["--config", "deq2d-square", "--val-count", "0"], "--val-count"),
])
def test_grow_on_an_incompatible_parent_is_one_line_and_exit_2(tmp_path, args, match):
    out = tmp_path / "out"
    r = _train(*args, "--out", str(out), tmp_path=tmp_path, preset="full")  # the shipped parents' architecture
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and match in lines[0], r.stderr
    assert not out.exists()


def test_grow_trains_from_the_parent_and_records_it(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    r = _train("--config", "dem3d-cube", "--out", str(a), tmp_path=tmp_path)
    assert r.returncode == 0, r.stderr
    r = _train("--config", "dem3d-cube", "--out", str(b), "--init", str(a / "dem3d-cube.safetensors"),
               "--grow", "8", "--n-range", "9", "13", "--n-sampling", "log", "--batch-points", "2000",
               "--val-native", "--val-count", "5", tmp_path=tmp_path)
    assert r.returncode == 0, r.stderr
    meta = json.loads((b / "dem3d-cube.json").read_text())
    assert meta["config"]["val_count"] == 5 and "--val-count 5" in meta["command"]
    assert sum(1 for k in meta["final_metrics"] if "@" in k) == 5 * len(meta["config"]["val_sizes"] or [1])
    assert meta["model"]["base"] == 8 and meta["config"]["grow"] and meta["config"]["n_sampling"] == "log"
    grown = meta["lineage"][-1]["grown"]
    assert grown["from"]["base"] == 4 and grown["to"]["base"] == 8
    assert "--grow 8" in meta["command"] and "--val-native" in meta["command"]
    assert meta["final_metrics"]["mean"]["native"] is True


def test_native_runs_the_network_on_the_requested_grid():
    sur = Surrogate.pretrained("deq2d-square")
    lo, hi = sur.n_range
    n = hi + 9
    delivered = sur.map("ring", n, repair=False)
    native = sur.map("ring", n, repair=False, native=True)
    assert delivered.info["work_n"] == hi and native.info["work_n"] == n
    assert not np.allclose(delivered.mapped_points, native.mapped_points)
    same = sur.map("ring", n, repair=False, work_n=n)
    assert np.array_equal(same.mapped_points, native.mapped_points)
    with pytest.raises(ValueError, match="native"):
        sur.map("ring", n, native=True, work_n=hi)


def test_cli_map_native(tmp_path):
    out = tmp_path / "m.npz"
    r = subprocess.run([sys.executable, "-m", "rfmap.cli", "map", "--model", "deq2d-square", "--field", "ring",
                        "--n", "41", "--native", "--no-repair", "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    from rfmap.core.result import load_result

    sur = Surrogate.pretrained("deq2d-square")
    native = sur.map("ring", 41, native=True, repair=False).mapped_points
    assert np.allclose(load_result(out).mapped_points, native, atol=1e-12)
    assert not np.allclose(sur.map("ring", 41, repair=False).mapped_points, native)  # 41 is below the range
