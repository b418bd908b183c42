"""A new kind of map is one new :class:`rfmap.tasks.Task` and a config entry: defined here, in the test file, it
trains at CI scale and maps a field through ``Surrogate.map`` and ``rfmap map`` without any change to the package.

The toy kind, ``shift``: the input is a scalar field :math:`s` on the unit square, and the map must move every point
along :math:`x_1` by :math:`s(x)\\,b(x)`, with the bump :math:`b = 16\\,x_1(1-x_1)\\,x_2(1-x_2)` that vanishes on the
boundary (so the identity boundary condition holds).  Its loss is the mean squared distance to that map, its
validation score the mean vertex distance to it.
"""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from rfmap.training.config import CONFIGS, get_config
from rfmap.core.mesh import grid_points, interpolate
from rfmap.tasks import Batch, Task, TaskSpec, ValidationField, get_task, grid_elements, kinds, register_task
from rfmap.tasks.base import _TASKS
from rfmap.tasks.heldout import held_out_rng

N = 9


def bump(x: np.ndarray) -> np.ndarray:
    return 16 * x[..., 0] * (1 - x[..., 0]) * x[..., 1] * (1 - x[..., 1])


def shifted(x: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The exact map of the toy task: ``x + (s b, 0)``."""
    out = np.array(x, dtype=np.float64)
    out[..., 0] += s * bump(x)
    return out


def smooth_field(rng: np.random.Generator):
    """A random smooth field of amplitude at most 0.1."""
    a, f, p = rng.uniform(-0.1, 0.1), rng.uniform(0.5, 2.0, 2), rng.uniform(0, 2 * np.pi, 2)
    return lambda x: a * np.sin(2 * np.pi * f[0] * x[..., 0] + p[0]) * np.cos(2 * np.pi * f[1] * x[..., 1] + p[1])


class ShiftTask(Task):
    """The toy kind: match a prescribed displacement along :math:`x_1`."""

    kind = "shift"
    title = "shift"
    dims = (2,)
    score_metric = "mean_dd"
    metric_names = ("mean_dd", "n_flipped", "min_jacobian")
    loss_terms = ("shift",)

    def n_params(self, dim):
        return 1

    def channels(self, params):
        return params.unsqueeze(-1)

    def check_field(self, grid, preprocess=True):
        grid = np.asarray(grid)
        if np.iscomplexobj(grid) or not np.isfinite(grid).all():
            raise ValueError("a shift field must be real and finite")
        return grid.astype(np.float64)

    def field_on_mesh(self, grid, fn, ref, elements, grid_n):
        if fn is not None:
            return np.asarray(fn(ref), dtype=np.float64)
        return interpolate(torch.as_tensor(grid)[None, None], torch.as_tensor(ref))[0, :, 0].numpy()

    def draw(self, rng, spec, n, options, teach):
        pts = grid_points(n, 2)
        return pts, smooth_field(rng)(pts), None

    def batch(self, spec, inputs, ref, params, n, targets):
        target = torch.as_tensor(shifted(ref.numpy(), params.numpy()), dtype=torch.float32)
        return Batch(inputs, ref, grid_elements(n, 2), n, extra={"exact": target})

    def loss(self, mb, weights):
        parts = {"shift": ((mb.mapped - mb.batch.extra["exact"]) ** 2).sum(-1).mean()}
        return parts["shift"], parts

    def validation_fields(self, dim, count, stream, low_frequency=False):
        out = []
        for j in range(count):
            s = smooth_field(held_out_rng(j, stream))
            out.append(ValidationField(f"shift-{j}", s, exact=lambda x, s=s: shifted(x, s(x))))
        return out

    def validation_record(self, result, vf):
        exact = vf.exact(result.ref_points)
        m = result.metrics(exact_points=exact)
        rec = {"mean_dd": m.mean_dd, "n_flipped": m.n_flipped, "min_jacobian": m.min_jacobian}
        return rec, m.mean_dd, float(np.linalg.norm(result.ref_points - exact, axis=1).mean())


@pytest.fixture
def shift_kind(monkeypatch):
    """The toy kind registered and a CI config ``shift2d`` for it, both removed again after the test."""
    monkeypatch.setitem(_TASKS, "shift", ShiftTask())
    base = get_config("deq2d-square", "ci")
    cfg = replace(base, name="shift2d", task=TaskSpec("shift", 2, "fixed"), steps=10, n_range=(N, N + 2), batch=2,
                  val_every=5, val_n=N, val_count=2, ckpt_every=100, workers=0, threads=1, time_limit=0.0, warmup=0,
                  lr=3e-3, select_best=False, description="toy kind of the task-extension test")
    monkeypatch.setitem(CONFIGS, "shift2d", {"ci": cfg})
    return cfg


def test_the_built_in_kinds_are_tasks():
    assert kinds()[:2] == ("density", "beltrami")
    assert TaskSpec("beltrami", 2, "fixed").task is get_task("beltrami")
    with pytest.raises(ValueError, match="unknown task kind 'shift'"):
        TaskSpec("shift", 2, "fixed")


def test_a_new_kind_trains_and_maps(shift_kind, tmp_path):
    from rfmap.cli.commands import main
    from rfmap.core.result import load_result
    from rfmap.training import train

    assert "shift" in kinds() and get_config("shift2d", "ci") is shift_kind
    sur = train(shift_kind, tmp_path / "run", progress=False)
    assert sur.spec == TaskSpec("shift", 2, "fixed") and sur.meta["steps"] == shift_kind.steps
    # the task's own loss term was trained on, and its validation record and score chose the weights
    steps = [json.loads(line) for line in (tmp_path / "run" / "log.jsonl").read_text().splitlines()]
    losses = [r for r in steps if "loss" in r]
    assert losses and all(r["loss"] == pytest.approx(r["shift"] + 10 * r["fold"]) for r in losses)
    assert set(sur.meta["final_metrics"]["shift-0@9"]) == set(ShiftTask.metric_names)
    assert sur.meta["paper_fields_report"] == {}  # the toy kind has no test fields of the paper

    rng = np.random.default_rng(3)
    s = smooth_field(rng)
    grid = s(grid_points(N, 2)).reshape(N, N)
    res = sur.map(grid, N)
    assert res.kind == "shift" and res.mapped_points.shape == (N * N, 2)
    np.testing.assert_allclose(res.field, grid.reshape(-1))  # the field on the output grid, as the task lays it
    assert np.isfinite(res.mapped_points).all() and res.metrics().n_flipped == 0
    assert np.abs(res.displacement).max() > 0  # the trained network moved the points
    assert "repair" in res.info and "quality" not in res.info  # repaired if folded, never judged as a density

    field_file, out = tmp_path / "s.npy", tmp_path / "mapped.npz"
    np.save(field_file, grid)
    assert main(["map", "--model", str(tmp_path / "run" / "shift2d.safetensors"), "--field-file", str(field_file),
                 "--out", str(out)]) == 0
    again = load_result(out)
    assert again.kind == "shift"
    np.testing.assert_allclose(again.mapped_points, res.mapped_points)

    with pytest.raises(ValueError, match="real and finite"):
        sur.map(np.full((N, N), np.nan), N)
