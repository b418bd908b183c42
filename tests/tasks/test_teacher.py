"""Tests of the classical teacher (:mod:`rfmap.tasks.teacher`), the per-family validation score, training snapshots,
``rfmap validate`` (:mod:`rfmap.training.selection`) and the accelerator script ``scripts/device_train.sh`` at CI scale."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from rfmap.cli.commands import main
from rfmap.training.config import get_config
from rfmap.core.device import bf16_supported
from rfmap.core.geometry import signed_measures
from rfmap.core.mesh import grid_mesh, grid_points
from rfmap.tasks import draw_samples, make_batch, task_loss
from rfmap.tasks.teacher import TeacherConfig, teacher_loss, teacher_map, teacher_targets
from rfmap.training.validation import family, score

ROOT = Path(__file__).resolve().parents[2]


def _one_d(n: int) -> tuple[np.ndarray, np.ndarray]:
    """A raw density varying in x only, and the exact equal-mass map x -> F(x) of its preprocessed values."""
    x = np.linspace(0, 1, n)
    g = 1.5 + np.sin(2 * np.pi * x) + 0.5 * x
    raw = np.repeat(g[:, None], n, axis=1)
    from rfmap.fields import preprocess_density

    p = preprocess_density(raw)[:, 0]
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]))])
    return raw, cum / cum[-1]


@pytest.mark.parametrize("method", ["flow", "diffusion"])
def test_teacher_map_is_the_exact_map_of_a_one_dimensional_density(method):
    """Both teachers give x -> F(x), y untouched, within 1 % of a grid spacing at N = 33 (diffusion measured
    1.9e-4 = 0.6 % h)."""
    n = 33
    raw, cum = _one_d(n)
    mapped = teacher_map(raw, "square", method)
    X, Y = mapped[:, 0].reshape(n, n), mapped[:, 1].reshape(n, n)
    h = 1 / (n - 1)
    assert np.abs(Y - np.linspace(0, 1, n)[None, :]).max() < 0.01 * h
    assert np.abs(X - cum[:, None]).max() < 0.05 * h


def test_teacher_targets_interpolate_the_grid_map():
    """At the grid's vertices the targets are the grid map; an affine displacement is carried exactly to any
    (jittered) point."""
    n = 9
    grid = grid_points(n, 2)
    A = np.array([[0.1, 0.05], [-0.02, 0.08]])
    mapped = grid + grid @ A.T
    np.testing.assert_allclose(teacher_targets(grid, n, mapped), mapped, atol=1e-12)
    rng = np.random.default_rng(0)
    pts = np.clip(grid + rng.uniform(-0.3, 0.3, grid.shape) / (n - 1), 0, 1)
    np.testing.assert_allclose(teacher_targets(pts, n, mapped), pts + pts @ A.T, atol=1e-12)


def test_free_boundary_target_keeps_the_domain_measure():
    n = 13
    raw = 1.0 + np.exp(-((grid_points(n, 2) - 0.4) ** 2).sum(-1) / 0.02).reshape(n, n)
    mapped = teacher_map(raw, "free", "flow")
    area = float(signed_measures(torch.as_tensor(mapped), torch.as_tensor(grid_mesh(n, 2).elements)).sum())
    assert area == pytest.approx(1.0, abs=1e-9)
    assert np.abs(mapped - grid_points(n, 2)).max() > 0.02  # it moved


def test_teacher_loss_is_relative_and_masked():
    """0 at the target, 1 for the identity where the target moves by more than a grid spacing, samples without a
    target ignored."""
    n = 5
    ref = torch.as_tensor(grid_points(n, 2), dtype=torch.float32)[None].repeat(2, 1, 1)
    target = ref + 0.5
    mask = torch.tensor([True, False])
    assert float(teacher_loss(target, target, ref, mask, n)) == 0.0
    assert float(teacher_loss(ref, target, ref, mask, n)) == pytest.approx(1.0)
    bad_second = torch.stack([target[0], ref[1] + 9.0])
    assert float(teacher_loss(bad_second, target, ref, mask, n)) == 0.0
    # a target that hardly moves: the floor of one grid spacing per vertex bounds the term
    tiny = ref + 1e-6
    one_h = ref + torch.tensor([0.25, 0.0])  # one grid spacing (h = 1/4) per vertex
    assert float(teacher_loss(one_h, tiny, ref, torch.tensor([True, True]), n)) == pytest.approx(1.0, rel=1e-3)


def test_teacher_config_rejects_bad_values():
    assert TeacherConfig("dem").method == "diffusion"
    for kw in ({"method": "lbs"}, {"method": "flow", "share": 0.0}, {"method": "flow", "share": 1.5},
               {"method": "flow", "weight": -1.0}, {"method": "flow", "weight": float("nan")}):
        with pytest.raises(ValueError):
            TeacherConfig(**kw)
    cfg = get_config("beltrami2d", "ci")
    with pytest.raises(ValueError, match="density configs only"):
        cfg.with_overrides(teacher=TeacherConfig("flow"))


def test_draw_samples_with_a_teacher():
    """The first round(share * B) samples carry the teacher's map, the rest NaN; the fields are those drawn
    without a teacher; the batch's teacher term is 0 at the targets."""
    cfg = get_config("deq2d-square", "ci")
    kw = dict(seed=3, step=5, indices=range(4), n=17, jitter=0.2, density_cfg=cfg.density_field)
    pts, par = draw_samples(cfg.task, **kw)
    pts2, par2, tgt = draw_samples(cfg.task, teacher=TeacherConfig("diffusion", share=0.5), **kw)
    np.testing.assert_array_equal(pts, pts2)
    np.testing.assert_array_equal(par, par2)
    assert np.isfinite(tgt[:2]).all() and np.isnan(tgt[2:]).all()
    batch = make_batch(cfg.task, pts, par, 17, tgt)
    assert batch.extra["target_mask"].tolist() == [True, True, False, False]
    from rfmap.nn.model import boundary_mask

    mask = boundary_mask(batch.ref, "square")  # u = x + B(x) psi: psi = (target - x) / B away from the walls
    disp = torch.where(mask > 0, (batch.extra["target"] - batch.ref) / mask.clamp(min=1e-12), 0.0)
    psi = disp.transpose(1, 2).reshape(4, 2, 17, 17)
    _, parts = task_loss(cfg.task, batch, psi, cfg.loss, teacher_weight=1.0)
    assert parts["teacher"] < 1e-8


def test_training_with_a_teacher_records_it(tmp_path):
    cfg = get_config("dem3d-cube", "ci").with_overrides(teacher=TeacherConfig("flow", share=1.0), snapshot_every=5)
    from rfmap.training import train

    sur = train(cfg, tmp_path, progress=False)
    logs = [json.loads(x) for x in (tmp_path / "log.jsonl").read_text().splitlines()]
    assert any("teacher" in r for r in logs if "loss" in r)
    assert sur.meta["config"]["teacher"] == {"method": "flow", "share": 1.0, "weight": 0.1}
    snaps = sorted((tmp_path / "snapshots").glob("*.safetensors"))
    assert [p.name for p in snaps] == ["dem3d-cube-step0000005.safetensors", "dem3d-cube-step0000010.safetensors"]
    assert not list((tmp_path / "snapshots").glob("*.json"))  # self-contained files


def test_family_score_weighs_every_family_alike():
    assert family("ramp-3") == "ramp" and family("low-map-2") == "low-map"
    ramps_good = {"std_rho_map": 0.1, "penalized": 0.1, "families": {"smooth": 0.9, "ramp": 0.1},
                  "family_score": 0.5}
    smooth_good = {"std_rho_map": 0.3, "penalized": 0.3, "families": {"smooth": 0.2, "ramp": 0.6},
                   "family_score": 0.4}
    assert score(smooth_good) < score(ramps_good)
    assert score(ramps_good) < score({"std_rho_map": 0.01, "penalized": 0.01})  # old summaries rank after


def test_validate_cli_scores_and_ships_snapshots(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", "--config", "deq2d-square", "--preset", "ci", "--steps", "6", "--snapshot-every", "3",
                 "--no-validate", "--teacher", "diffusion", "--out", str(out), "--no-progress"]) == 0
    capsys.readouterr()
    assert not any("validation" in x for x in (out / "log.jsonl").read_text().splitlines())
    assert main(["validate", str(out / "snapshots"), "--ship", str(tmp_path / "ship"), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "score" in text and "shipped" in text
    meta = json.loads((tmp_path / "ship" / "deq2d-square.json").read_text())
    assert meta["selected_from"].startswith("deq2d-square-step") and len(meta["candidates"]) == 2
    assert "family_score" in meta["final_metrics"]["mean"]
    assert "--teacher diffusion" in meta["command"] and "--no-validate" in meta["command"]


@pytest.mark.parametrize("args, match", [
    (["train", "--config", "deq2d-square", "--preset", "ci", "--teacher", "lbs"], "unknown teacher"),
    (["train", "--config", "beltrami2d", "--preset", "ci", "--teacher", "flow"], "density configs only"),
    (["train", "--config", "deq2d-square", "--preset", "ci", "--teacher-share", "2"], "share"),
    (["validate", "nowhere"], "no such file"),
])
def test_bad_teacher_and_validate_input(tmp_path, capsys, args, match):
    out = tmp_path / "o"
    rc = main(args + (["--out", str(out)] if args[0] == "train" else []))
    err = capsys.readouterr().err
    assert rc == 2 and match in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def _script(tmp_path, *args, **env):
    bf16 = bf16_supported(torch.device("cpu"))
    e = {**os.environ, "OUT": str(tmp_path / "out"), "DEVICE": "cpu", "PRESET": "ci", "PYTHON": sys.executable,
         "THREADS": "1", "WORKERS": "0", "PRECISION": "bf16" if bf16 else "fp32", **env}
    return subprocess.run(["bash", str(ROOT / "scripts" / "device_train.sh"), *args], env=e, capture_output=True,
                          text=True, timeout=600)


def test_device_script_at_ci_scale(tmp_path):
    """The accelerator path end to end on the CPU: snapshots and logs in OUT within the 8 files that come back,
    then rfmap validate ships the best with its lineage."""
    p = _script(tmp_path, "0.3", "dem3d-cube", SNAPSHOT_EVERY="2", KEEP="2",
                TRAIN_ARGS="--teacher flow --base 4 --depth 2 --steps 6")
    assert p.returncode == 0, p.stderr[-2000:]
    files = sorted((tmp_path / "out").rglob("*"))
    files = [f for f in files if f.is_file()]
    assert len(files) <= 8 and all(f.stat().st_size < 16 * 2**20 for f in files)
    snaps = [f for f in files if f.suffix == ".safetensors"]
    assert len(snaps) == 2 and (tmp_path / "out" / "dem3d-cube" / "log.jsonl").exists()
    assert main(["validate", *map(str, snaps), "--ship", str(tmp_path / "ship"), "--no-progress"]) == 0
    meta = json.loads((tmp_path / "ship" / "dem3d-cube.json").read_text())
    assert meta["config"]["teacher"]["method"] == "flow" and meta["device"] == "cpu"


@pytest.mark.parametrize("args", [("5", "no-such-config"), ("abc", "dem3d-cube"), ("9", "dem3d-cube")])
def test_device_script_rejects_bad_input(tmp_path, args):
    p = _script(tmp_path, *args)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1 and "error" in p.stderr
    assert not (tmp_path / "out").exists()


#: what the accelerator machine's image holds besides the standard library (the device tool's notes)
DEVICE_IMAGE = ("torch", "numpy", "scipy", "safetensors", "tqdm", "matplotlib")


def _device_image_python(tmp_path) -> str:
    """A python command that sees only the standard library, rfmap (through the script's PYTHONPATH) and the files
    of the distributions of :data:`DEVICE_IMAGE` with their requirements, as on the bare accelerator machine: the
    interpreter runs without its site-packages (``-S``) on a folder of links to those distributions' files."""
    import importlib.metadata as md
    import re

    dists: dict[str, md.Distribution] = {}

    def close(name):
        key = name.lower().replace("_", "-")
        if key in dists:
            return
        try:
            d = md.distribution(name)
        except md.PackageNotFoundError:
            return
        dists[key] = d
        for r in d.requires or []:
            if "extra ==" not in r:
                close(re.split(r"[ ;<>=!~\[(]", r.strip())[0])

    for name in DEVICE_IMAGE:
        close(name)
    site = tmp_path / "device-image"
    site.mkdir()
    for d in dists.values():
        for f in d.files or []:
            top = f.parts[0]
            if top not in ("..", "bin") and not (site / top).exists():
                src = Path(d.locate_file(top))
                if src.exists():
                    (site / top).symlink_to(src)
    wrapper = tmp_path / "python-image"
    wrapper.write_text(f'#!/bin/sh\nPYTHONPATH="$PYTHONPATH:{site}" exec {sys.executable} -S "$@"\n')
    wrapper.chmod(0o755)
    return str(wrapper)


def test_device_script_in_the_device_image_with_a_run_shorter_than_one_log_line(tmp_path):
    """The script on what the bare accelerator machine has (an import of anything else fails), with a run that
    stops after its first step, before any loss record: it still ends cleanly with its snapshot."""
    py = _device_image_python(tmp_path)
    probe = subprocess.run([py, "-c", "import torch, scipy, safetensors, tqdm, matplotlib\nimport shapely"],
                           capture_output=True, text=True)
    assert probe.returncode != 0 and "No module named 'shapely'" in probe.stderr, probe.stderr  # the image's set
    p = _script(tmp_path, "0.2", "dem3d-cube", PYTHON=py, SNAPSHOT_EVERY="2", KEEP="1",
                PRECISION="fp32", TRAIN_ARGS="--base 4 --depth 2 --time-limit 0.001")
    assert p.returncode == 0, p.stderr[-2000:]
    assert "training failed" not in p.stdout and "Traceback" not in p.stderr, p.stdout + p.stderr[-2000:]
    snaps = list((tmp_path / "out" / "dem3d-cube").glob("*.safetensors"))
    assert len(snaps) == 1


def test_device_script_refuses_an_unknown_precision(tmp_path):
    p = _script(tmp_path, "1", "dem3d-cube", PRECISION="fp16")
    assert p.returncode == 2 and "unknown precision" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
