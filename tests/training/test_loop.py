"""Tests of training (:mod:`rfmap.training`) at ``ci`` scale: the loss goes down, outputs and metadata are written,
resuming from a checkpoint reproduces an uninterrupted run exactly, and two data-parallel processes train the same
model as one process with twice the batch."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file

import rfmap.training as T
import rfmap.training.state as TS
from rfmap.training.config import get_config
from rfmap.nn import build_model
from rfmap.fields.paper import TEST_FIELDS
from rfmap.surrogate import Surrogate
from rfmap.tasks import sample_batch, task_loss
from rfmap.training.validation import validation_fields

CFG = get_config("deq2d-square", "ci")


def _held_out_loss(model, cfg, n=21):
    """Loss of a fixed batch of 8 samples from the training distribution that training never draws (another
    seed)."""
    batch = sample_batch(cfg.task, seed=12345, step=0, indices=range(8), n=n, jitter=0.0,
                         density_cfg=cfg.density_field)  # the training distribution, another seed
    with torch.no_grad():
        return float(task_loss(cfg.task, batch, model(batch.inputs), cfg.loss)[0])


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A 40-step ci run with a raised learning rate (the ci preset's 5e-4 barely moves in 40 steps)."""
    out = tmp_path_factory.mktemp("train")
    # the random fields without the narrow peaks and ramps of the full preset: on those, 40 steps of this
    # 4-channel network lower the held-out loss by only ~4 % (measured), too little to test against noise
    cfg = CFG.with_overrides(steps=40, lr=1e-2, val_every=1000, ckpt_every=1000, density_field=None)
    sur = T.train(cfg, out, progress=False, log_every=1)
    return cfg, out, sur


def test_training_lowers_the_loss(trained):
    """The losses logged during training are on fresh random batches (too noisy to compare over 40 steps), so the
    loss is measured on a fixed held-out batch: the untrained model is the identity map, and training must lower
    its loss by at least 5% (measured: 12% for seed 0, 27% for seed 1)."""
    cfg, out, sur = trained
    torch.manual_seed(cfg.seed)
    untrained = build_model(cfg.model.kwargs(cfg.task.dim, cfg.task.n_params)).eval()
    before = _held_out_loss(untrained, cfg)
    after = _held_out_loss(sur.model, cfg)
    assert before > 0.01
    assert after < 0.95 * before, (before, after)
    # the validation on the paper's test fields improves on the identity map, too
    final = sur.meta["final_metrics"]
    assert final["mean"]["n_flipped"] == 0
    identity = Surrogate.untrained(cfg.task, base=4, depth=2, n_range=list(cfg.n_range))
    ident = T.validate(identity, cfg)
    assert final["mean"]["std_rho_map"] < ident["mean"]["std_rho_map"]


def test_outputs_and_metadata(trained):
    cfg, out, sur = trained
    names = sorted(p.name for p in out.iterdir())
    assert names == ["checkpoint.pt", "deq2d-square.json", "deq2d-square.safetensors", "log.jsonl"]
    meta = json.loads((out / "deq2d-square.json").read_text())
    for key in ("config", "steps", "wall_time", "final_metrics", "model", "task", "n_range", "rfmap_version"):
        assert key in meta, key
    assert meta["steps"] == 40
    assert meta["wall_time"] > 0
    assert meta["config"] == cfg.to_dict()
    assert meta["config"]["lr"] == 1e-2
    assert meta["task"] == {"kind": "density", "dim": 2, "boundary": "square"}
    assert meta["n_range"] == list(cfg.n_range)
    assert meta["world_size"] == 1 and meta["global_batch"] == cfg.batch
    # validation on the held-out random fields; the paper's fields only as a report
    assert set(meta["final_metrics"]) == {f"{v.label}@{cfg.val_n}" for v in
                                          validation_fields("density", 2, cfg.val_count)} | {"mean"}
    assert set(meta["paper_fields_report"]) == set(TEST_FIELDS[("density", 2)]) | {"mean"}
    # one log record per step, losses finite and the lr follows the schedule down to lr_min
    recs = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    steps = [r for r in recs if "loss" in r]
    assert [r["step"] for r in steps] == list(range(1, 41))
    assert all(cfg.n_range[0] <= r["n"] <= cfg.n_range[1] for r in steps)
    assert steps[-1]["lr"] == pytest.approx(cfg.lr_min)
    assert [r for r in recs if "validation" in r][-1].get("final") is True
    assert "paper_fields_report" in recs[-1]  # reported after the final validation, never used to select
    # the written weights reload to the returned model
    loaded = Surrogate.load(out / "deq2d-square.safetensors")
    for k, v in sur.model.state_dict().items():
        assert torch.equal(loaded.model.state_dict()[k], v), k
    ck = torch.load(out / "checkpoint.pt", weights_only=True)
    assert ck["step"] == 40


class _Crash(Exception):
    pass


def _train_until_crash(cfg, out, command, monkeypatch, at: int = 10) -> None:
    """Train ``cfg`` into ``out`` and crash right after the checkpoint of step ``at``."""
    real_checkpoint = T.TrainState.checkpoint

    def checkpoint_then_crash(self):
        real_checkpoint(self)
        if self.step == at:
            raise _Crash

    monkeypatch.setattr(T.TrainState, "checkpoint", checkpoint_then_crash)
    with pytest.raises(_Crash):
        T.train(cfg, out, progress=False, command=command)
    monkeypatch.setattr(T.TrainState, "checkpoint", real_checkpoint)


@pytest.mark.parametrize("ema", [0.0, 0.8])
def test_resume_reproduces_an_uninterrupted_run(tmp_path, monkeypatch, ema):
    """Train 20 steps straight; separately train, crash right after the step-10 checkpoint, and resume to 20.
    The prefetcher restarts at the saved step, and optimiser, scheduler and weight-average states are restored,
    so the final weights are identical."""
    cfg = CFG.with_overrides(steps=20, ckpt_every=10, val_every=10, ema=ema)
    straight = T.train(cfg, tmp_path / "a", progress=False)

    start = f"rfmap train --config {cfg.name} --preset ci --steps 20"
    _train_until_crash(cfg, tmp_path / "b", start, monkeypatch)
    assert not (tmp_path / "b" / f"{cfg.name}.safetensors").exists()
    ck = torch.load(tmp_path / "b" / "checkpoint.pt", weights_only=True)
    assert ck["step"] == 10

    resumed = T.train(cfg, tmp_path / "b", progress=False, resume=True, command=start + " --resume")
    assert resumed.meta["steps"] == 20
    # the metadata keeps the command that repeats the run and lists the resumption
    assert resumed.meta["command"] == start
    assert resumed.meta["resumed"] == [start + " --resume"]
    sa, sb = straight.model.state_dict(), resumed.model.state_dict()
    assert set(sa) == set(sb)
    for k in sa:
        assert torch.allclose(sa[k], sb[k], atol=1e-6, rtol=0), k
    moved = max(float(v.abs().max()) for k, v in sa.items() if k.startswith("head."))
    assert moved > 1e-4  # the head started at zero: the comparison is not trivial
    # the resumed log continues at step 10 and ends with the same losses as the uninterrupted run
    la = [json.loads(x) for x in (tmp_path / "a" / "log.jsonl").read_text().splitlines()]
    lb = [json.loads(x) for x in (tmp_path / "b" / "log.jsonl").read_text().splitlines()]
    loss_a = {r["step"]: r["loss"] for r in la if "loss" in r}
    loss_b = {r["step"]: r["loss"] for r in lb if "loss" in r}
    assert loss_a == loss_b


def test_finish_ends_a_stopped_run_from_its_checkpoint(tmp_path, monkeypatch):
    """A run stopped after its step-10 checkpoint, ended with --resume --finish: no further step, the weight file
    holds the best validated (averaged) state, and the metadata records the starting and the finishing command."""
    cfg = CFG.with_overrides(steps=20, ckpt_every=10, val_every=5, ema=0.5)
    start = f"rfmap train --config {cfg.name} --preset ci --steps 20 --ema 0.5"
    _train_until_crash(cfg, tmp_path, start, monkeypatch)
    ck = torch.load(tmp_path / "checkpoint.pt", weights_only=True)
    sur = T.train(cfg, tmp_path, progress=False, resume=True, finish=True, command=start + " --resume --finish")
    assert sur.meta["steps"] == 10 and sur.meta["command"] == start
    assert sur.meta["resumed"] == [start + " --resume --finish"]
    losses = [json.loads(x) for x in (tmp_path / "log.jsonl").read_text().splitlines()]
    assert max(r["step"] for r in losses if "loss" in r) == 10  # nothing trained after the checkpoint
    final = [r for r in losses if r.get("final")][-1]
    assert sur.meta["selected_step"] == final["selected_step"]
    # the shipped weights: the best validated state, or the average at the checkpoint's step
    best = json.loads(ck["best"]["step"])
    want = ck["best_state"] if final["selected_step"] == best and best != 10 else ck["average"]["shadow"]
    for k, v in want.items():
        assert torch.allclose(sur.model.state_dict()[k], v.float(), atol=1e-6, rtol=0), k
    with pytest.raises(ValueError, match="--finish"):
        T.train(cfg, tmp_path / "none", progress=False, finish=True)


def test_started_as_rebuilds_the_starting_command_of_an_old_checkpoint():
    assert TS._started_as("rfmap train --config x --lr 0.0002 --resume", []) == "rfmap train --config x --lr 0.0002"
    parent = [{"name": "x", "sha256": "0" * 64}]
    assert TS._started_as("rfmap train --config x --resume", parent) == "rfmap train --config x --init x"
    assert TS._started_as("rfmap train --config x --init y --resume", parent) == "rfmap train --config x --init y"
    assert TS._started_as(None, parent) is None


@pytest.fixture
def fake_clock(monkeypatch):
    """``time.perf_counter`` replaced by a clock that advances one second whenever the main thread reads it (other
    threads read it without advancing it), so that a time limit stops training at a step that does not depend on
    the machine's speed or load."""
    import threading
    import time

    now = [0.0]

    def perf_counter():
        if threading.current_thread() is threading.main_thread():
            now[0] += 1.0
        return now[0]

    monkeypatch.setattr(time, "perf_counter", perf_counter)
    return now


def test_resume_after_the_time_limit_trains_nothing(tmp_path, fake_clock):
    cfg = CFG.with_overrides(steps=10**6, val_every=10**6, ckpt_every=10**6, time_limit=20.0)
    T.train(cfg, tmp_path, progress=False)
    before = torch.load(tmp_path / "checkpoint.pt", weights_only=True)
    # stopped on the (fake) clock, after a few steps: a few clock readings per step
    assert 1 <= before["step"] <= 20 and before["elapsed"] > cfg.time_limit
    again = T.train(cfg, tmp_path, progress=False, resume=True)
    assert again.meta["steps"] == before["step"]
    for k, v in before["model"].items():
        assert torch.equal(v, again.model.state_dict()[k]), k


def test_resume_rescores_the_kept_best_state_by_the_current_rule(tmp_path):
    """A checkpoint keeps its best validated state with the score of the rule it was written under; a resumed run
    recomputes that score from the stored summary, so later checkpoints are compared by one rule."""
    from rfmap.training.validation import score

    cfg = CFG.with_overrides(steps=4, val_every=2, ckpt_every=2)
    T.train(cfg, tmp_path, progress=False)
    ck = torch.load(tmp_path / "checkpoint.pt", weights_only=True)
    best = {k: json.loads(v) for k, v in ck["best"].items()}
    ck["best"]["score"] = json.dumps([7, 99.0])  # as if written under another rule
    torch.save(ck, tmp_path / "checkpoint.pt")
    st = TS._build_state(cfg, tmp_path, torch.device("cpu"), resume=True, init=None, command=None)
    assert st.best["score"] == list(score(best["summary"])) and st.best["score"][0] == 0


def test_resume_with_another_config_is_refused(tmp_path):
    cfg = CFG.with_overrides(steps=2, val_every=1000)
    T.train(cfg, tmp_path, progress=False)
    with pytest.raises(ValueError, match="different configuration"):
        T.train(cfg.with_overrides(lr=0.5), tmp_path, progress=False, resume=True)


def test_train_3d_ci_config(tmp_path):
    """The 3D ci preset trains on grids 9..13, whose coarsest U-Net level is smaller than the attention pooling."""
    cfg = get_config("dem3d-cube", "ci").with_overrides(steps=2, val_every=1000)
    sur = T.train(cfg, tmp_path, progress=False)
    assert sur.meta["final_metrics"]["mean"]["n_flipped"] == 0
    assert (tmp_path / "dem3d-cube.safetensors").exists()


def test_two_process_data_parallel_equals_single_process_with_twice_the_batch(tmp_path):
    torchrun = Path(sys.executable).with_name("torchrun")
    if not torchrun.exists():
        pytest.skip("torchrun is not installed next to the Python interpreter")
    if not torch.distributed.is_available():
        pytest.skip("torch.distributed is not available")
    common = ["--config", "deq2d-square", "--preset", "ci", "--steps", "5", "--no-progress", "--threads", "1"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    env.pop("WORLD_SIZE", None)
    proc = subprocess.run([str(torchrun), "--standalone", "--nproc_per_node=2", "-m", "rfmap.training", *common,
                           "--batch", "1", "--out", str(tmp_path / "ddp")], env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert T.main([*common, "--batch", "2", "--out", str(tmp_path / "single")]) == 0
    a = load_file(str(tmp_path / "ddp" / "deq2d-square.safetensors"))
    b = load_file(str(tmp_path / "single" / "deq2d-square.safetensors"))
    assert set(a) == set(b)
    for k in a:
        assert torch.allclose(a[k], b[k], atol=1e-5, rtol=1e-4), (k, float((a[k] - b[k]).abs().max()))
    assert float(a["head.weight"].abs().max()) > 1e-4  # trained away from the zero initialisation
    meta = json.loads((tmp_path / "ddp" / "deq2d-square.json").read_text())
    assert meta["world_size"] == 2 and meta["global_batch"] == 2 and meta["steps"] == 5
    # rank 0 alone validated and logged: one final validation record
    recs = [json.loads(x) for x in (tmp_path / "ddp" / "log.jsonl").read_text().splitlines()]
    assert sum(1 for r in recs if r.get("final")) == 1
