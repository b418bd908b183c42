r"""Data-free training of a surrogate (paper Sec. 5), single-process or data-parallel.

``python -m rfmap.train --config NAME [--preset ci|full] [--out DIR] [--resume]`` (also ``rfmap train``) trains the
named configuration of :mod:`rfmap.config`.  Every step draws a fresh batch of random fields (sample ``i`` of step
``t`` is seeded by ``(seed, t, i)``) on a random grid size in ``n_range``, with Sobol-jittered vertices.

Data-parallel: ``torchrun --nproc_per_node=K -m rfmap.train --config NAME ...`` runs K processes (gloo on CPU,
NCCL on GPU); rank ``r`` draws samples ``r*B .. (r+1)*B - 1`` of each step, so K processes with batch ``B`` train
the same model as one process with batch ``K*B``.

Outputs in ``--out`` (default ``runs/NAME``): ``log.jsonl`` (one JSON object per logged step and per
validation), ``checkpoint.pt`` (model, optimiser, scheduler, step; loaded with ``weights_only=True``), and the final
``NAME.safetensors`` + ``NAME.json`` (metadata: config, steps, wall time, final metrics).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

from ._version import __version__
from .config import TrainConfig, config_names, get_config
from .nn.model import MultiResUNet
from .surrogate import Surrogate
from .tasks import sample_batch, task_loss

__all__ = ["train", "validate", "main", "VALIDATION_FIELDS"]

VALIDATION_FIELDS = {
    ("density", 2): ["sin-cos", "exp-log", "rect-peak", "ring"],
    ("density", 3): ["sin-cos-3d", "shell-3d", "octant-3d", "prism-peak-3d"],
    ("beltrami", 2): ["T1", "T2", "T3", "T4"],
}


def _dist_info() -> tuple[int, int]:
    if torch.distributed.is_available() and torch.distributed.is_initialized():
        return torch.distributed.get_rank(), torch.distributed.get_world_size()
    return 0, 1


def _scheduler(opt, cfg: TrainConfig):
    if cfg.schedule == "cosine":
        def f(step):
            if step < cfg.warmup:
                return (step + 1) / max(1, cfg.warmup)
            t = (step - cfg.warmup) / max(1, cfg.steps - cfg.warmup)
            return cfg.lr_min / cfg.lr + (1 - cfg.lr_min / cfg.lr) * 0.5 * (1 + math.cos(math.pi * min(t, 1.0)))
        return torch.optim.lr_scheduler.LambdaLR(opt, f)
    if cfg.schedule == "step":
        return torch.optim.lr_scheduler.StepLR(opt, cfg.step_size, cfg.gamma)
    if cfg.schedule == "restarts":
        return torch.optim.lr_scheduler.CosineAnnealingWarmRestarts(opt, cfg.T0, cfg.T_mult, eta_min=cfg.lr_min)
    raise ValueError(f"unknown schedule {cfg.schedule!r}; expected cosine, step or restarts")


def step_size_n(cfg: TrainConfig, step: int) -> int:
    """Training grid side of step ``step`` (uniform in ``n_range``, the same on every rank)."""
    lo, hi = cfg.n_range
    return int(np.random.default_rng([cfg.seed, step, 2**31]).integers(lo, hi + 1))


class _Prefetcher:
    """Draws the batches of the coming steps in a background thread (numpy releases the GIL in its array
    kernels), so that field synthesis overlaps with the network step."""

    def __init__(self, fn, start: int, stop: int, depth: int = 2):
        import queue
        import threading

        self.q: "queue.Queue" = queue.Queue(maxsize=depth)
        self._stop = threading.Event()

        def work():
            for step in range(start, stop):
                if self._stop.is_set():
                    return
                try:
                    item = (step, fn(step), None)
                except BaseException as e:  # surface errors in the training loop
                    item = (step, None, e)
                while not self._stop.is_set():
                    try:
                        self.q.put(item, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if item[2] is not None:
                    return

        self.thread = threading.Thread(target=work, daemon=True)
        self.thread.start()

    def get(self):
        step, batch, err = self.q.get()
        if err is not None:
            raise err
        return step, batch

    def close(self):
        self._stop.set()
        self.thread.join(timeout=5)


def validate(sur: Surrogate, n: int, fields: list[str] | None = None) -> dict:
    """Metrics of a surrogate on the paper's test fields at grid side ``n`` (mean over fields, worst flips)."""
    from .fields import BELTRAMI_MAPS, get_field

    fields = fields or VALIDATION_FIELDS[(sur.spec.kind, sur.spec.dim)]
    out: dict = {}
    vals = []
    for name in fields:
        r = sur.map(name, n)
        if sur.spec.kind == "beltrami":
            f = BELTRAMI_MAPS[name]
            m = r.metrics(exact_points=f(r.ref_points), mu_ref=r.field)
            vals.append({"mean_dd": m.mean_dd, "mean_dmu": m.mean_dmu, "n_flipped": m.n_flipped,
                         "min_jacobian": m.min_jacobian})
        else:
            m = r.metrics()
            vals.append({"std_rho_map": m.std_rho_map, "n_flipped": m.n_flipped, "min_jacobian": m.min_jacobian})
        out[name] = vals[-1]
    keys = vals[0].keys()
    summary = {}
    for k in keys:
        arr = [v[k] for v in vals]
        summary[k] = int(sum(arr)) if k == "n_flipped" else (min(arr) if k == "min_jacobian" else float(np.mean(arr)))
    out["mean"] = summary
    return out


def train(cfg: TrainConfig, out_dir=None, *, resume: bool = False, progress: bool = True,
          log_every: int = 10, command: str | None = None) -> Surrogate:
    """Train ``cfg``; returns the trained :class:`Surrogate` (also written to ``out_dir``).  ``command`` (the
    command line that started the run) is recorded in the metadata."""
    rank, world = _dist_info()
    out = Path(out_dir or Path("runs") / cfg.name)
    if rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    spec = cfg.task
    model = MultiResUNet(spec.dim, spec.n_params, cfg.model.base, cfg.model.depth, cfg.model.attention)
    ddp = None
    if world > 1:
        ddp = torch.nn.parallel.DistributedDataParallel(model)
    net = ddp or model
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay, betas=cfg.betas)
    sched = _scheduler(opt, cfg)
    start, elapsed0 = 0, 0.0
    ckpt = out / "checkpoint.pt"
    log_path = out / "log.jsonl"
    if resume and ckpt.exists():
        state = torch.load(ckpt, weights_only=True)
        if state.get("config") != json.dumps(cfg.to_dict(), sort_keys=True):
            raise ValueError(f"checkpoint {ckpt} was written by a different configuration; remove it or use "
                             "another --out")
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["opt"])
        sched.load_state_dict(state["sched"])
        start, elapsed0 = int(state["step"]), float(state["elapsed"])
    elif rank == 0 and log_path.exists():
        log_path.unlink()

    def log(rec):
        if rank == 0:
            with open(log_path, "a") as f:
                f.write(json.dumps(rec) + "\n")

    def surrogate(step, elapsed, final=None):
        meta = {"name": cfg.name, "preset": cfg.preset, "n_range": list(cfg.n_range), "config": cfg.to_dict(),
                "rfmap_version": __version__, "steps": step, "wall_time": round(elapsed, 1),
                "world_size": world, "global_batch": cfg.batch * world, "description": cfg.description}
        if command:
            meta["command"] = command
        if final is not None:
            meta["final_metrics"] = final
        s = Surrogate(model, spec, meta)
        return s

    t_start = time.perf_counter() - elapsed0
    bar = None
    if progress and rank == 0:
        from tqdm.auto import tqdm

        bar = tqdm(total=cfg.steps, initial=start, desc=f"train {cfg.name}", unit="step", dynamic_ncols=True)
    step = start
    ema = None

    def make_batch(t):
        return sample_batch(spec, seed=cfg.seed, step=t, indices=range(rank * cfg.batch, (rank + 1) * cfg.batch),
                            n=step_size_n(cfg, t), jitter=cfg.jitter, density_cfg=cfg.density_field,
                            beltrami_cfg=cfg.beltrami_field, beltrami_source=cfg.beltrami_source)

    loader = _Prefetcher(make_batch, start, cfg.steps)
    try:
        sur = _loop(cfg, spec, model, net, opt, sched, loader, bar, log, surrogate, ckpt, t_start, step, rank,
                    world, ema, log_every, out)
    finally:
        loader.close()
    return sur


def _loop(cfg, spec, model, net, opt, sched, loader, bar, log, surrogate, ckpt, t_start, step, rank, world, ema,
          log_every, out):
    while step < cfg.steps:
        _, batch = loader.get()
        n = batch.n
        model.train()
        psi = net(batch.inputs)
        loss, parts = task_loss(spec, batch, psi, cfg.loss)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        gnorm = float(torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.clip))
        opt.step()
        sched.step()
        step += 1
        lv = float(loss.detach())
        ema = lv if ema is None else 0.95 * ema + 0.05 * lv
        elapsed = time.perf_counter() - t_start
        if bar is not None:
            bar.update(1)
            bar.set_postfix(loss=f"{ema:.3g}", n=n)
        if step % log_every == 0 or step == cfg.steps:
            log({"step": step, "n": n, "loss": lv, **parts, "grad_norm": gnorm, "lr": opt.param_groups[0]["lr"],
                 "elapsed": round(elapsed, 2)})
        stop = cfg.time_limit > 0 and elapsed > cfg.time_limit
        if world > 1:
            flag = torch.tensor([float(stop)])
            torch.distributed.all_reduce(flag)
            stop = bool(flag.item() > 0)
        if rank == 0 and (step % cfg.val_every == 0 and step < cfg.steps and not stop):
            model.eval()
            v = validate(surrogate(step, elapsed), cfg.val_n)
            log({"step": step, "validation": v, "elapsed": round(elapsed, 2)})
            if bar is not None:
                bar.write(f"step {step}: validation {v['mean']}")
        if rank == 0 and (step % cfg.ckpt_every == 0 or stop or step == cfg.steps):
            torch.save({"model": model.state_dict(), "opt": opt.state_dict(), "sched": sched.state_dict(),
                        "step": step, "elapsed": elapsed, "config": json.dumps(cfg.to_dict(), sort_keys=True)},
                       ckpt)
        if stop:
            if bar is not None:
                bar.write(f"time limit of {cfg.time_limit:.0f} s reached at step {step}")
            break
    if bar is not None:
        bar.close()
    elapsed = time.perf_counter() - t_start
    model.eval()
    sur = surrogate(step, elapsed)
    if rank == 0:
        final = validate(sur, cfg.val_n)
        log({"step": step, "validation": final, "elapsed": round(elapsed, 2), "final": True})
        sur = surrogate(step, elapsed, final)
        sur.meta["history"] = history(out / "log.jsonl")
        sur.save(out / f"{cfg.name}.safetensors")
    return sur


def history(log_path, points: int = 200) -> dict:
    """A compact training history from ``log.jsonl``: up to ``points`` (step, loss) pairs of a running mean of the
    loss, and the mean validation metrics over time (stored in the weight metadata for the book's plots)."""
    steps, losses, val = [], [], []
    with open(log_path) as f:
        for line in f:
            rec = json.loads(line)
            if "validation" in rec:
                val.append({"step": rec["step"], **rec["validation"]["mean"]})
            elif "loss" in rec:
                steps.append(rec["step"])
                losses.append(rec["loss"])
    if losses:
        w = max(1, len(losses) // points)
        sm = np.convolve(losses, np.ones(w) / w, mode="valid")[::w]
        steps = steps[w - 1::w][: len(sm)]
        losses = [float(x) for x in sm]
    return {"step": steps, "loss": losses, "validation": val}


def build_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    p = parser or argparse.ArgumentParser(prog="rfmap train", description="Train a surrogate from a named config.")
    p.add_argument("--config", required=True, help=f"one of: {', '.join(config_names())}")
    p.add_argument("--preset", choices=["ci", "full"], default=None, help="default: $RFMAP_SCALE or full")
    p.add_argument("--out", default=None, help="output directory (default runs/CONFIG)")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--steps", type=int, default=None, help="override the number of steps")
    p.add_argument("--batch", type=int, default=None, help="override the per-process batch size")
    p.add_argument("--time-limit", type=float, default=None, help="override the wall-time limit (s)")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads per process")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--no-progress", action="store_true")
    return p


def run(args) -> Surrogate:
    cfg = get_config(args.config, args.preset)
    over = {k: v for k, v in {"steps": args.steps, "batch": args.batch, "time_limit": args.time_limit,
                              "threads": args.threads, "seed": args.seed}.items() if v is not None}
    cfg = cfg.with_overrides(**over)
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not torch.distributed.is_initialized():
        backend = "nccl" if torch.cuda.is_available() else "gloo"
        torch.distributed.init_process_group(backend)
    try:
        return train(cfg, args.out, resume=args.resume, progress=not args.no_progress,
                     command=_command_line(args))
    finally:
        if world > 1 and torch.distributed.is_initialized():
            torch.distributed.destroy_process_group()


def _command_line(args) -> str:
    parts = ["rfmap train", f"--config {args.config}"]
    if args.preset:
        parts.append(f"--preset {args.preset}")
    for flag, val in [("--steps", args.steps), ("--batch", args.batch), ("--time-limit", args.time_limit),
                      ("--threads", args.threads), ("--seed", args.seed)]:
        if val is not None:
            parts.append(f"{flag} {val:g}" if isinstance(val, float) else f"{flag} {val}")
    if args.resume:
        parts.append("--resume")
    return " ".join(parts)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    run(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
