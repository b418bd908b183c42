"""Milliseconds per training step of the ``full`` presets, batch drawing included (steady state, after warm-up).

    python benchmarks/train_step.py [--json] [--device cpu|cuda|auto] [--steps 20] [--warmup 5]
                                    [--configs beltrami2d deq2d-square dem3d-cube] [--threads T] [--workers W]
    python benchmarks/train_step.py --smoke     # one step of batch 1 at the ``ci`` preset's smallest side

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
from pathlib import Path

import numpy as np
import torch

from rfmap.training.config import get_config
from rfmap.core.device import resolve_device
from rfmap.training.data import _loader
from rfmap.training.loop import _train_step
from rfmap.training.state import _build_state

SIZES = {2: (4, 80), 3: (2, 48)}
DEFAULT_THREADS = torch.get_num_threads()


def measure(name: str, device: torch.device, steps: int, warmup: int, threads: int | None,
            workers: int | None, smoke: bool = False) -> dict:
    torch.set_num_threads(DEFAULT_THREADS)  # a preset without a thread count gets torch's default
    cfg = get_config(name, "full")
    batch, n = (1, get_config(name, "ci").n_range[0]) if smoke else SIZES[cfg.task.dim]
    over = {"batch": batch, "n_range": (n, n), "steps": warmup + steps, "time_limit": 0.0}
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
            "device": str(device), "threads": torch.get_num_threads(), "workers": cfg.workers}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", action="store_true")
    p.add_argument("--device", default="cpu")
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--warmup", type=int, default=5)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--configs", nargs="+", default=["beltrami2d", "deq2d-square", "dem3d-cube"])
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
    out = {}
    for name in args.configs:
        out[name] = measure(name, device, args.steps, args.warmup, args.threads, args.workers, args.smoke)
        if not args.json:
            r = out[name]
            print(f"{name:14s} {r['ms_per_step']:8.1f} ms/step  batch {r['batch']}, N = {r['n']}, {r['device']}, "
                  f"{r['threads']} thread(s), {r['workers']} batch worker(s)", flush=True)
    if args.json:
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
