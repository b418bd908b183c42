"""The training engine (:mod:`rfmap.training`, :mod:`rfmap.training.validation`, :mod:`rfmap.core.device`): reproducibility, batch
workers, warm restarts with lineage, the held-out validation and checkpoint choice, devices, the paper presets, and
bad input on the command line (one line, exit 2, nothing written)."""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import torch

import rfmap.training as T
import rfmap.training.state as TS
from rfmap.cli.commands import main as cli_main
from rfmap.training.config import CONFIGS, get_config
from rfmap.core.device import resolve_device
from rfmap.fields.random import RandomMap, RandomBeltramiConfig
from rfmap.surrogate import WEIGHTS_DIR, Surrogate
from rfmap.core.mesh import grid_points
from rfmap.tasks import draw_samples
from rfmap.training.validation import VALIDATION_SEED, evaluate, score, validation_fields

CFG = get_config("deq2d-square", "ci").with_overrides(threads=1)


def _weights(sur):
    return {k: v.clone() for k, v in sur.model.state_dict().items()}


def test_same_seed_and_threads_give_bit_identical_weights(tmp_path):
    cfg = CFG.with_overrides(steps=6, val_every=3)
    a = _weights(T.train(cfg, tmp_path / "a", progress=False))
    b = _weights(T.train(cfg, tmp_path / "b", progress=False))
    assert all(torch.equal(a[k], b[k]) for k in a)
    c = _weights(T.train(cfg.with_overrides(seed=1), tmp_path / "c", progress=False))
    assert any(not torch.equal(a[k], c[k]) for k in a)  # the seed matters: the comparison is not trivial


def test_3d_training_runs_channels_last_with_the_same_arithmetic(tmp_path):
    """3D networks train in the channels_last_3d format (faster oneDNN kernels): the loss and gradients equal those
    of the contiguous format to float32 round-off, runs stay bit-reproducible, and the shipped file loads."""
    from rfmap.nn.registry import build_model
    from rfmap.tasks import make_batch, task_loss

    cfg = get_config("dem3d-cube", "ci").with_overrides(threads=1)
    assert T.memory_format(3) == torch.channels_last_3d and T.memory_format(2) == torch.contiguous_format
    torch.manual_seed(0)
    a = build_model(cfg.model.kwargs(3, 1))
    torch.nn.init.normal_(a.head.weight, std=0.01)  # a non-trivial output (the head starts at zero)
    b = build_model(cfg.model.kwargs(3, 1))
    b.load_state_dict(a.state_dict())
    b = b.to(memory_format=torch.channels_last_3d)
    n, pts, par, _ = T.draw_step(cfg, 0)
    batch = make_batch(cfg.task, pts, par, n)
    la, _ = task_loss(cfg.task, batch, a(batch.inputs), cfg.loss)
    lb, _ = task_loss(cfg.task, batch, b(batch.inputs.contiguous(memory_format=torch.channels_last_3d)), cfg.loss)
    la.backward()
    lb.backward()
    assert torch.allclose(la, lb, rtol=1e-4)
    for pa, pb in zip(a.parameters(), b.parameters()):
        assert torch.allclose(pa.grad, pb.grad, rtol=1e-3, atol=1e-5 * float(pa.grad.abs().max()) + 1e-9)
    run = cfg.with_overrides(steps=3, val_every=1000)
    wa = _weights(T.train(run, tmp_path / "a", progress=False))
    wb = _weights(T.train(run, tmp_path / "b", progress=False))
    assert all(torch.equal(wa[k], wb[k]) for k in wa)
    loaded = Surrogate.load(tmp_path / "a" / "dem3d-cube.safetensors")
    assert all(torch.equal(loaded.model.state_dict()[k], wa[k]) for k in wa)


def test_worker_processes_draw_the_same_batches(tmp_path):
    """Batches drawn by two worker processes equal those of the in-process thread, so the weights are identical."""
    cfg = CFG.with_overrides(steps=6, val_every=1000)
    a = _weights(T.train(cfg, tmp_path / "thread", progress=False))
    b = _weights(T.train(cfg.with_overrides(workers=2), tmp_path / "procs", progress=False))
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_batch_workers_exit_when_the_training_process_is_killed(tmp_path):
    """A training run killed outright (SIGKILL: no clean close) leaves no batch worker behind: each worker notices
    that its parent is gone and exits without flushing the batches nobody will read."""
    import signal
    import subprocess
    import sys
    import time

    psutil = pytest.importorskip("psutil")
    out = tmp_path / "run"
    # batches of 64 fields: larger than a pipe buffer, so a batch left in a worker's queue cannot be flushed
    cmd = [sys.executable, "-m", "rfmap.training", "--config", "deq2d-square", "--preset", "ci", "--steps", "100000",
           "--batch", "64", "--workers", "2", "--threads", "1", "--out", str(out), "--no-progress"]
    # without the test session's thread pins (conftest), as a user's shell would start it
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                            "MKL_NUM_THREADS")}
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    trainer = psutil.Process(proc.pid)
    nicer = min(trainer.nice() + 10, 19)  # the workers yield the cores: ten steps nicer, capped at 19
    workers, drawing = [], []

    def started() -> bool:
        """Both batch workers are in their drawing loop (each lowers its priority first thing there)."""
        nonlocal workers, drawing
        try:
            workers = trainer.children(recursive=True)  # known early, for the clean-up below
            drawing = [w for w in workers if "spawn_main" in " ".join(w.cmdline())]
            return len(drawing) >= 2 and all(w.nice() >= nicer for w in drawing)
        except psutil.Error:  # a process listed a moment ago is gone or not yet readable: look again
            return False

    try:
        # wait for a state of the run, not for a time: training has logged its first steps (so the workers have
        # queued batches) and both workers are drawing, however long a loaded machine takes to get there (the guard
        # only keeps a run that never gets there from hanging the suite)
        guard = time.monotonic() + 1800
        while not ((out / "log.jsonl").exists() and started()):
            assert proc.poll() is None, "the training run exited before its batch workers started"
            assert time.monotonic() < guard, f"after 30 minutes {len(drawing)} batch worker(s) were drawing"
            time.sleep(0.5)
        assert len(drawing) == 2
        # and run one BLAS thread each (busy-waiting OpenBLAS threads slowed the 3D step by 15 %)
        assert all(w.environ().get("OPENBLAS_NUM_THREADS") == "1" for w in drawing)
        assert psutil.Process(proc.pid).environ().get("OPENBLAS_NUM_THREADS") != "1"
    finally:  # the workers are killed in any case, so that a failed test leaves none behind
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        # a worker notices at its next queue attempt, after the batch it is drawing at its low priority; on a busy
        # machine that can take minutes, so the wait is long (it ends as soon as they are gone)
        gone, alive = psutil.wait_procs(workers, timeout=600)
        for w in alive:
            w.kill()
    assert not alive, f"{len(alive)} batch worker(s) outlived the killed training process"


def test_single_blas_thread_env_sets_and_restores_the_variables(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "7")
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    with T.single_blas_thread_env():
        assert all(os.environ[k] == "1" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"))
    assert os.environ["OMP_NUM_THREADS"] == "7" and "OPENBLAS_NUM_THREADS" not in os.environ


def test_draw_step_is_a_pure_function_of_step_and_rank():
    n1, p1, q1, _ = T.draw_step(CFG, 7, rank=0)
    n2, p2, q2, _ = T.draw_step(CFG, 7, rank=0)
    assert n1 == n2 and np.array_equal(p1, p2) and np.array_equal(q1, q2)
    _, p3, _, _ = T.draw_step(CFG, 7, rank=1)
    assert not np.array_equal(p1, p3)


def test_init_warm_restart_records_the_lineage(tmp_path):
    parent = T.train(CFG.with_overrides(steps=4, val_every=1000), tmp_path / "p", progress=False)
    ppath = tmp_path / "p" / "deq2d-square.safetensors"
    child = T.train(CFG.with_overrides(steps=3, val_every=1000), tmp_path / "c", progress=False, init=str(ppath))
    lin = child.meta["lineage"]
    assert len(lin) == 1 and lin[0]["sha256"] == TS.sha256(ppath) and lin[0]["steps"] == 4
    assert child.meta["cumulative_steps"] == 7
    assert child.meta["cumulative_wall_time"] >= child.meta["wall_time"]
    # a second generation keeps the whole chain
    cpath = tmp_path / "c" / "deq2d-square.safetensors"
    grand = T.train(CFG.with_overrides(steps=2, val_every=1000), tmp_path / "g", progress=False, init=str(cpath))
    assert [r["cumulative_steps"] for r in grand.meta["lineage"]] == [4, 7]
    assert grand.meta["cumulative_steps"] == 9
    # the run starts from the parent's weights (a fresh start would begin at the zero-initialised head)
    assert float(parent.model.head.weight.detach().abs().max()) > 0
    start = TS._build_state(CFG, tmp_path / "s", torch.device("cpu"), False, str(ppath), None)
    assert all(torch.equal(start.model.state_dict()[k], v) for k, v in parent.model.state_dict().items())
    # a parent that was resumed (or ended with --resume --finish) passes its resumptions on to the chain
    assert "resumed" not in lin[0]
    parent.meta["resumed"] = ["rfmap train --config deq2d-square --preset ci --resume --finish"]
    parent.save(tmp_path / "r" / "deq2d-square.safetensors")
    _, record = T.load_init(str(tmp_path / "r" / "deq2d-square.safetensors"), CFG)
    assert record["resumed"] == parent.meta["resumed"]


def test_init_of_another_task_or_architecture_is_refused(tmp_path):
    other = T.train(get_config("beltrami2d", "ci").with_overrides(steps=2, val_every=1000), tmp_path / "b",
                    progress=False)
    with pytest.raises(ValueError, match="trained for"):
        T.load_init(str(tmp_path / "b" / "beltrami2d.safetensors"), CFG)
    with pytest.raises(ValueError, match="architecture"):
        T.load_init("deq2d-square", CFG)  # the shipped model is the full-size network, the ci config a tiny one
    with pytest.raises(ValueError, match="neither a shipped model"):
        T.load_init(str(tmp_path / "missing.safetensors"), CFG)
    assert other.meta["steps"] == 2


def test_validation_set_is_fixed_and_never_drawn_in_training():
    a = validation_fields("density", 2, 8)
    b = validation_fields("density", 2, 8)
    x = np.random.default_rng(0).random((50, 2))
    assert [v.label for v in a] == ["smooth-0", "steps-1", "peak-2", "ramp-3", "smooth-4", "steps-5", "peak-6",
                                    "ramp-7"]
    for u, v in zip(a, b):
        assert np.array_equal(u.field(x), v.field(x))
    # training streams are seeded by three words (seed, step, index), validation by two (VALIDATION_SEED, j):
    # even the training sample with the same leading words differs from validation field 0
    bel = validation_fields("beltrami", 2, 4)
    m = bel[0].exact
    rm = RandomMap(np.random.default_rng([VALIDATION_SEED, 0, 0]), RandomBeltramiConfig())
    assert not np.allclose(m(grid_points(9, 2)), rm(grid_points(9, 2)))
    # the low-frequency maps of the reports are other maps, of 1-4 slow modes
    low = validation_fields("beltrami", 2, 4, stream="report", low_frequency=True)
    assert [v.label for v in low] == ["low-map-0", "low-map-1", "low-map-2", "low-map-3"]
    assert all(v.exact.freq.shape[-2] <= 4 for v in low)
    assert not np.allclose(low[0].exact(grid_points(9, 2)), validation_fields("beltrami", 2, 4, stream="report")[0]
                           .exact(grid_points(9, 2)))
    with pytest.raises(ValueError, match="Beltrami"):
        validation_fields("density", 2, 4, low_frequency=True)
    pts, dens = draw_samples(CFG.task, seed=VALIDATION_SEED, step=0, indices=[0], n=17, jitter=0.0)
    val = a[0].field(pts[0])
    assert not np.allclose(dens[0] / dens[0].mean(), val / val.mean())


def test_checkpoint_choice_ships_the_best_validated_state(tmp_path):
    cfg = CFG.with_overrides(steps=12, val_every=3, lr=3e-2)
    sur = T.train(cfg, tmp_path, progress=False)
    recs = [json.loads(x) for x in (tmp_path / "log.jsonl").read_text().splitlines()]
    vals = [r for r in recs if "validation" in r and not r.get("final") and not r.get("last")]
    final = [r for r in recs if r.get("final")][0]
    assert len(vals) == 3
    best = min(score(r["validation"]["mean"]) for r in vals)
    assert score(final["validation"]["mean"]) <= best
    assert sur.meta["selected_step"] in [r["step"] for r in vals] + [12]
    # the paper's fields are a report next to it, not the selection criterion
    assert set(sur.meta["paper_fields_report"]) >= {"sin-cos", "mean"}


def test_evaluate_scores_the_exact_map_of_a_beltrami_field():
    from rfmap.surrogate import Surrogate

    sur = Surrogate.untrained(get_config("beltrami2d", "ci").task, base=4, depth=2, n_range=[17, 25])
    v = evaluate(sur, (17,), count=2)
    assert set(v) == {"map-0@17", "map-1@17", "mean"}
    assert v["mean"]["mean_dd"] > 0  # the identity is not the random map
    assert score({"mean_dd": 0.1, "n_flipped": 1}) > score({"mean_dd": 0.5, "n_flipped": 0})  # old summaries
    assert v["mean"]["penalized"] == pytest.approx(v["mean"]["mean_dd"]) or v["mean"]["folded_fields"]


def test_score_counts_a_folded_map_as_the_identity(monkeypatch):
    """One folded map with a huge Std(rho~_map) must not decide the checkpoint: the capped mean takes the field's
    Std(rho~_orig) for a folded map where that is lower, and the score (the penalized mean) takes it always, so a
    fold costs a model exactly what it gained on that field, and a model that hardly moves cannot win by folding
    nothing."""
    from types import SimpleNamespace

    import rfmap.training.validation as V
    from rfmap.surrogate import Surrogate

    sur = Surrogate.untrained(get_config("deq2d-square", "ci").task, base=4, depth=2, n_range=[17, 25])
    # (Std map, Std orig, flips): a folded map far worse than no map, a folded map better than no map, two clean ones
    fake = {0: (50.0, 0.4, 3), 1: (0.2, 0.5, 2), 2: (0.1, 0.3, 0), 3: (0.3, 0.6, 0)}
    calls = iter(range(4))

    def raw_map(s, field, n, repair=False, native=False):
        std_map, std_orig, flips = fake[next(calls)]
        return SimpleNamespace(metrics=lambda: SimpleNamespace(std_rho_map=std_map, std_rho_orig=std_orig,
                                                               n_flipped=flips, min_jacobian=-0.1 if flips else 0.2))

    monkeypatch.setattr(V, "_held_out_map", raw_map)
    m = V.evaluate(sur, (17,), count=4)["mean"]
    assert m["folded_fields"] == 2 and m["n_flipped"] == 5
    np.testing.assert_allclose(m["std_rho_map"], (50.0 + 0.2 + 0.1 + 0.3) / 4)
    np.testing.assert_allclose(m["capped"], (0.4 + 0.2 + 0.1 + 0.3) / 4)
    np.testing.assert_allclose(m["penalized"], (0.4 + 0.5 + 0.1 + 0.3) / 4)
    # the score: the mean over families of Std(map)/Std(orig), a folded map counted as 1 (one field per family)
    assert score(m) == (0, m["family_score"])
    np.testing.assert_allclose(m["family_score"], (1.0 + 1.0 + 0.1 / 0.3 + 0.3 / 0.6) / 4)
    # a fold-free model that hardly moves (penalized 0.5) ranks below a much better one with one folded map
    good_but_folded = {"std_rho_map": 9.0, "n_flipped": 4, "folded_fields": 1, "capped": 0.15, "penalized": 0.2}
    hardly_moves = {"std_rho_map": 0.5, "n_flipped": 0, "folded_fields": 0, "capped": 0.5, "penalized": 0.5}
    assert score(good_but_folded) < score(hardly_moves)
    # summaries written before the penalized mean existed: fold-free ones by their mean, folded ones after all others
    old_clean, old_folded = {"std_rho_map": 0.3, "n_flipped": 0}, {"std_rho_map": 0.1, "n_flipped": 1,
                                                                    "folded_fields": 1, "capped": 0.1}
    assert score(old_clean) == (1, 0.3) and score(hardly_moves) < score(old_folded)
    # a diverged network (non-finite points, hence a NaN Std and no flipped element counted) is no map either
    fake.update({0: (float("nan"), 0.4, 0)})
    calls = iter(range(4))
    m = V.evaluate(sur, (17,), count=4)["mean"]
    assert m["folded_fields"] == 2 and np.isfinite(m["penalized"])
    np.testing.assert_allclose(m["penalized"], (0.4 + 0.5 + 0.1 + 0.3) / 4)


def test_evaluate_with_repair_scores_the_maps_a_user_gets():
    """``evaluate(..., repair=True)`` (``TrainConfig.val_repair``): the shipped 3D model folds some held-out ramps
    at N = 48; the delivered maps (regridded or repaired) are fold-free, and the records say which raw maps folded,
    as many as the raw evaluation counts."""
    sur = Surrogate.load(Path(WEIGHTS_DIR) / "dem3d-free.safetensors")
    raw = evaluate(sur, (48,), count=4)
    delivered = evaluate(sur, (48,), count=4, repair=True)
    assert delivered["mean"]["path"] == "repaired" and "path" not in raw["mean"]
    assert delivered["mean"]["folded_fields"] == 0 and delivered["mean"]["n_flipped"] == 0
    assert delivered["mean"]["raw_folded_fields"] == raw["mean"]["folded_fields"]
    for key, rec in raw.items():
        if key != "mean":
            assert delivered[key]["raw_folded"] == (rec["n_flipped"] > 0)
            if not rec["n_flipped"]:  # an unfolded map is delivered as the network made it
                assert delivered[key]["std_rho_map"] == pytest.approx(rec["std_rho_map"], rel=1e-6)
    # the score: each delivered map at most as bad as the identity (a failed repair is worth no map)
    orig = {key: sur.map(f.field, 48, repair=False).metrics().std_rho_orig
            for key, f in zip([k for k in raw if k != "mean"], validation_fields("density", 3, 4))}
    expect = np.mean([min(delivered[k]["std_rho_map"], orig[k]) for k in orig])
    assert delivered["mean"]["penalized"] == pytest.approx(expect)


def test_a_warm_restart_validates_its_parent_and_ships_it_when_nothing_beats_it(tmp_path):
    """With ``init`` the parent is validated at step 0 and competes with every checkpoint: a child trained at an
    absurd learning rate ships the parent's weights (selected step 0)."""
    # a parent better than the identity on the validation fields (the ci fields without peaks and ramps)
    T.train(CFG.with_overrides(steps=40, val_every=1000, lr=1e-2, density_field=None), tmp_path / "p", progress=False)
    ppath = tmp_path / "p" / "deq2d-square.safetensors"
    parent = Surrogate.load(ppath)
    child = T.train(CFG.with_overrides(steps=4, val_every=2, lr=5.0, warmup=0), tmp_path / "c", progress=False,
                    init=str(ppath))
    recs = [json.loads(x) for x in (tmp_path / "c" / "log.jsonl").read_text().splitlines()]
    first = [r for r in recs if "validation" in r][0]
    assert first["step"] == 0
    assert score(first["validation"]["mean"]) == score(evaluate(parent, CFG.val_ns, CFG.val_count)["mean"])
    assert child.meta["selected_step"] == 0
    for k, v in parent.model.state_dict().items():
        assert torch.equal(child.model.state_dict()[k], v)


def test_resolve_device():
    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    with pytest.raises(ValueError, match="unknown device"):
        resolve_device("tpu")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="no CUDA device"):
            resolve_device("cuda")


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine")
def test_training_on_cuda_and_checkpoint_back_to_cpu(tmp_path):  # pragma: no cover - needs a GPU
    sur = T.train(CFG.with_overrides(steps=3, val_every=1000), tmp_path, progress=False, device="cuda")
    assert sur.meta["device"].startswith("cuda")
    ck = torch.load(tmp_path / "checkpoint.pt", weights_only=True, map_location="cpu")
    assert ck["step"] == 3


def test_paper_presets_carry_the_papers_hyperparameters():
    for name in CONFIGS:
        cfg = get_config(name, "paper")
        assert cfg.preset == "paper" and cfg.clip == 1.0 and cfg.time_limit == 0 and "Paper preset" in cfg.description
    d = get_config("deq2d-square", "paper")
    assert (d.steps, d.lr, d.weight_decay, d.schedule, d.step_size, d.gamma, d.n_range, d.loss.beltrami) == \
        (12000, 1e-5, 1e-5, "step", 200, 0.5, (64, 96), 0.1)
    assert get_config("dem2d-square", "paper").loss.beltrami == 0.0
    c = get_config("dem3d-cube", "paper")
    assert (c.steps, c.lr, c.betas, c.weight_decay, c.schedule, c.T0, c.T_mult, c.lr_min, c.n_range) == \
        (4000, 2e-4, (0.9, 0.995), 5e-5, "restarts", 600, 2, 2e-6, (32, 48))
    b = get_config("beltrami2d", "paper")
    assert (b.steps, b.schedule, b.n_range) == (250000, "step", (64, 96))


@pytest.mark.parametrize("extra, message", [
    (["--device", "tpu"], "unknown device"),
    (["--init", "beltrami2d"], "trained for"),
    (["--init", "nowhere/x.safetensors"], "neither a shipped model"),
    (["--steps", "0"], "at least 1"),
    (["--lr=-1e-4"], "--lr must be a positive number"),
    (["--lr", "nan"], "--lr must be a positive number"),
    (["--ema", "1"], "--ema must lie in [0, 1)"),
    (["--finish"], "--finish ends a run from its checkpoint"),
    (["--ema=-0.5"], "--ema must lie in [0, 1)"),
] + ([] if torch.cuda.is_available() else [(["--device", "cuda"], "no CUDA device")]))
def test_train_cli_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, extra, message):
    out = tmp_path / "run"
    code = cli_main(["train", "--config", "deq2d-square", "--preset", "ci", "--out", str(out), "--no-progress",
                     *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and message in err[0]
    assert not out.exists()


def test_map_cli_refuses_an_unavailable_device(tmp_path, capsys):
    out = tmp_path / "m.npz"
    code = cli_main(["map", "--model", "deq2d-square", "--field", "sin-cos", "--n", "17", "--out", str(out),
                     "--device", "tpu"])
    assert code == 2 and "unknown device" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("device, message", [("tpu", "unknown device")]
                         + ([] if torch.cuda.is_available() else [("cuda", "no CUDA device")]))
def test_reproduce_cli_refuses_an_unavailable_device_before_any_work(tmp_path, capsys, device, message):
    out = tmp_path / "tables"
    code = cli_main(["reproduce", "beltrami", "--out", str(out), "--device", device])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0]
    assert not out.exists()


def test_reproduce_runs_the_networks_on_the_requested_device(tmp_path, monkeypatch):
    """The experiment loads its models onto the device it is given (checked on the CPU, with the table builders
    replaced by a probe so that nothing heavy runs)."""
    import rfmap.paper.reproduce as E

    seen = []

    class Probe:
        def save(self, out):
            return []

    monkeypatch.setattr(E, "beltrami_table", lambda sur, **kw: (seen.append(sur.device) or Probe(), None))
    monkeypatch.setattr(E, "beltrami_resolution_table", lambda sur, **kw: (Probe(), None))
    E.reproduce("beltrami", tmp_path, device=torch.device("cpu"))
    assert seen == [torch.device("cpu")]


def test_train_cli_lr_override_is_used_and_recorded(tmp_path):
    from rfmap.surrogate import Surrogate

    out = tmp_path / "run"
    code = cli_main(["train", "--config", "deq2d-square", "--preset", "ci", "--out", str(out), "--no-progress",
                     "--steps", "2", "--lr", "3e-4"])
    assert code == 0
    sur = Surrogate.load(out / "deq2d-square.safetensors")
    assert sur.meta["config"]["lr"] == 3e-4 and "--lr 0.0003" in sur.meta["command"]
    first = json.loads((out / "log.jsonl").read_text().splitlines()[0])
    assert 0 < first["lr"] <= 3e-4


def test_weight_average_follows_its_recursion_and_is_what_ships(tmp_path):
    """WeightAverage against the recursion written out by hand, then a run with --ema: the shipped weights are the
    average (not the weights as trained), the command and config record it, and a resumed run restores it."""
    from rfmap.surrogate import Surrogate
    from rfmap.training import WeightAverage

    lin = torch.nn.Linear(3, 2)
    avg = WeightAverage(lin, 0.9)
    expect = [p.detach().clone() for p in lin.parameters()]
    for t in range(1, 31):
        with torch.no_grad():
            for p in lin.parameters():
                p.add_(torch.randn_like(p))
        avg.update()
        beta = min(0.9, (1 + t) / (10 + t))
        expect = [e + (1 - beta) * (p.detach() - e) for e, p in zip(expect, lin.parameters())]
    state = avg.averaged_state(lin)
    for (name, _), e in zip(lin.named_parameters(), expect):
        assert torch.allclose(state[name], e, atol=1e-6, rtol=0)
    assert not torch.allclose(state["weight"], lin.weight)  # the average is not the last iterate
    with pytest.raises(ValueError, match="decay"):
        WeightAverage(lin, 1.0)

    out = tmp_path / "run"
    code = cli_main(["train", "--config", "deq2d-square", "--preset", "ci", "--out", str(out), "--no-progress",
                     "--steps", "12", "--lr", "1e-2", "--ema", "0.5"])
    assert code == 0
    sur = Surrogate.load(out / "deq2d-square.safetensors")
    assert sur.meta["config"]["ema"] == 0.5 and "--ema 0.5" in sur.meta["command"]
    ck = torch.load(out / "checkpoint.pt", weights_only=True)
    assert ck["average"]["updates"] == 12
    # with the last state shipped, the file holds the checkpoint's average, not its trained weights
    cfg = get_config("deq2d-square", "ci").with_overrides(steps=12, lr=1e-2, ema=0.5, select_best=False)
    last = T.train(cfg, tmp_path / "last", progress=False)
    ck = torch.load(tmp_path / "last" / "checkpoint.pt", weights_only=True)
    shipped = last.model.state_dict()
    for name, t in ck["average"]["shadow"].items():
        assert torch.allclose(shipped[name], t.float(), atol=1e-6, rtol=0), name
    assert any(not torch.allclose(shipped[k], ck["model"][k].float()) for k in ck["average"]["shadow"])


def test_family_score_weighs_every_family_the_same_however_many_fields_it_has(monkeypatch):
    """Six validation fields fall into four families, two with two fields (smooth-0 and smooth-4, steps-1 and
    steps-5) and two with one: the family score is the mean of the four family means of Std(map)/Std(orig), not
    the mean over the six fields (which would weigh smooth and steps twice)."""
    from types import SimpleNamespace

    import rfmap.training.validation as V

    sur = Surrogate.untrained(get_config("deq2d-square", "ci").task, base=4, depth=2, n_range=[17, 25])
    ratios = iter([0.1, 0.5, 0.2, 0.9, 0.3, 0.7])  # smooth-0, steps-1, peak-2, ramp-3, smooth-4, steps-5

    def raw_map(s, field, n, repair=False, native=False):
        r = next(ratios)
        return SimpleNamespace(metrics=lambda: SimpleNamespace(std_rho_map=r, std_rho_orig=1.0, n_flipped=0,
                                                               min_jacobian=0.5))

    monkeypatch.setattr(V, "_held_out_map", raw_map)
    m = V.evaluate(sur, (17,), count=6)["mean"]
    assert m["families"] == pytest.approx({"smooth": 0.2, "steps": 0.6, "peak": 0.2, "ramp": 0.9}, rel=1e-12)
    assert m["family_score"] == pytest.approx((0.2 + 0.6 + 0.2 + 0.9) / 4, rel=1e-12)  # 0.475; per field: 0.45
