"""Milliseconds per training step of the ``full`` presets, batch drawing included (steady state, after warm-up).

    python benchmarks/train_step.py [--json] [--device cpu|cuda|auto] [--steps 20] [--warmup 5]
                                    [--configs beltrami2d deq2d-square dem3d-cube] [--threads T] [--workers W]
                                    [--precision fp32 bf16] [--bases 8 16 32]
    python benchmarks/train_step.py --smoke     # one step of batch 1 at the ``ci`` preset's smallest side
    python benchmarks/train_step.py --train-steps 300 [--configs deq2d-square]   # trains as well in bf16?

``--precision`` times each configuration in every precision named (``TrainConfig.precision``: bf16 autocast around
the network, the losses in float32) and ``--bases`` at every U-Net width named (the network freshly initialised);
with two precisions a last column gives the speed-up of bf16 over fp32, measured in the same run.

``--train-steps K`` instead trains each configuration's ``full`` preset from scratch for K steps from one seed in
fp32 and in bf16 and prints both validation family scores (mean Std(rho~_map) / Std(rho~_orig) over the held-out
fields; the identity map scores 1) with their relative difference: whether bf16 trains as well (the tiny-scale
check of the same is ``tests/training/test_precision.py``).

Each configuration runs its ``full`` preset (threads and batch workers as the preset sets them unless overridden)
at a fixed grid side: batch 4 at N = 80 in 2D, batch 2 at N = 48 in 3D.  A step is timed from asking the loader
for its batch to the end of the optimiser step, so synthesis that is not hidden behind the network shows up.
With ``--json`` the output is one object ``{config: {"ms_per_step", "batch", "n", "device", "threads",
"workers"}}``.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from rfmap.training.config import get_config
from rfmap.core.device import check_precision, resolve_device
from rfmap.training.data import _loader
from rfmap.training.loop import _train_step
from rfmap.training.state import _build_state

SIZES = {2: (4, 80), 3: (2, 48)}
DEFAULT_THREADS = torch.get_num_threads()


def measure(name: str, device: torch.device, steps: int, warmup: int, threads: int | None,
            workers: int | None, smoke: bool = False, precision: str = "fp32", base: int | None = None) -> dict:
    torch.set_num_threads(DEFAULT_THREADS)  # a preset without a thread count gets torch's default
    cfg = get_config(name, "full")
    batch, n = (1, get_config(name, "ci").n_range[0]) if smoke else SIZES[cfg.task.dim]
    over = {"batch": batch, "n_range": (n, n), "steps": warmup + steps, "time_limit": 0.0,
            "precision": check_precision(precision, device)}
    if base is not None:
        if cfg.model.arch != "unet":
            raise ValueError(f"--bases applies to U-Net configs; {name} is {cfg.model.arch}")
        over["model"] = replace(cfg.model, base=base)
    if threads is not None:
        over["threads"] = threads
    if workers is not None:
        over["workers"] = workers
    cfg = cfg.with_overrides(**over)
    with tempfile.TemporaryDirectory() as tmp:
        st = _build_state(cfg, Path(tmp), device, resume=False, init=None, command=None)
        loader = _loader(cfg, 0, 0, cfg.steps)
        times = []
        try:
            for step in range(cfg.steps):
                t0 = time.perf_counter()
                side, pts, par, targets = loader.get(step)
                _train_step(st, side, pts, par, targets)
                if device.type == "cuda":
                    torch.cuda.synchronize()
                times.append(time.perf_counter() - t0)
        finally:
            loader.close()
    return {"ms_per_step": round(1e3 * float(np.median(times[warmup:])), 1), "batch": batch, "n": n,
            "device": str(device), "threads": torch.get_num_threads(), "workers": cfg.workers,
            "precision": cfg.precision, "base": cfg.model.base if cfg.model.arch == "unet" else None}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", action="store_true")
    p.add_argument("--device", default="cpu")
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--warmup", type=int, default=5)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--configs", nargs="+", default=["beltrami2d", "deq2d-square", "dem3d-cube"])
    p.add_argument("--precision", nargs="+", default=["fp32"], metavar="fp32|bf16",
                   help="time every configuration in each precision (bf16: autocast around the network)")
    p.add_argument("--bases", nargs="+", type=int, default=None, metavar="B",
                   help="time every U-Net configuration at each of these base widths (default: the config's)")
    p.add_argument("--train-steps", type=int, default=0, metavar="K",
                   help="compare training instead: K steps from scratch in fp32 and bf16, then the validation score")
    p.add_argument("--smoke", action="store_true",
                   help="the smallest run: one step, no warm-up, batch 1 at the ci preset's smallest side")
    args = p.parse_args(argv)
    if args.smoke:
        args.steps, args.warmup = 1, 0
    try:
        device = resolve_device(args.device)
    except ValueError as e:
        print(f"train_step: error: {e}", file=sys.stderr)
        return 2
    if args.train_steps:
        return compare_training(args.configs, args.train_steps, device, args.threads)
    out = {}
    try:
        for name in args.configs:
            for base in args.bases or [None]:
                for prec in args.precision:
                    label = name + (f" base {base}" if base else "") + (f" {prec}" if args.precision != ["fp32"]
                                                                          else "")
                    out[label] = measure(name, device, args.steps, args.warmup, args.threads, args.workers,
                                         args.smoke, prec, base)
                    if not args.json:
                        _print_row(label, out[label], out)
    except ValueError as e:
        print(f"train_step: error: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(out))
    return 0


def compare_training(names: list[str], steps: int, device: torch.device, threads: int | None) -> int:
    """``--train-steps``: each config's ``full`` preset trained ``steps`` steps from scratch in fp32 and bf16 (one
    seed, no validation during the run), then validated; one line per config with both scores."""
    from rfmap.training.loop import train, validate
    from rfmap.training.validation import score

    for name in names:
        scores, secs = {}, {}
        for prec in ("fp32", "bf16"):
            cfg = get_config(name, "full").with_overrides(
                steps=steps, time_limit=0.0, val_every=0, select_best=False, ckpt_every=10 ** 9, warmup=0,
                precision=check_precision(prec, device), **({"threads": threads} if threads else {}))
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                sur = train(cfg, tmp, device=device, progress=False)
                secs[prec] = time.perf_counter() - t0
                scores[prec] = score(validate(sur, cfg)["mean"])[1]
        gap = scores["bf16"] / scores["fp32"] - 1
        print(f"{name:14s} {steps} steps: validation family score fp32 {scores['fp32']:.4f} ({secs['fp32']:.0f} s), "
              f"bf16 {scores['bf16']:.4f} ({secs['bf16']:.0f} s); bf16 {gap:+.1%} relative", flush=True)
    return 0


def _print_row(label: str, r: dict, out: dict) -> None:
    """One line per measurement; a bf16 line also gives its speed-up over the fp32 line of the same config."""
    ratio = ""
    if r["precision"] == "bf16" and label.replace(" bf16", " fp32") in out:
        ratio = f"  bf16 speed-up {out[label.replace(' bf16', ' fp32')]['ms_per_step'] / r['ms_per_step']:.2f}x"
    print(f"{label:24s} {r['ms_per_step']:8.1f} ms/step  batch {r['batch']}, N = {r['n']}, {r['device']}, "
          f"{r['threads']} thread(s), {r['workers']} batch worker(s){ratio}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
