"""Inference and training-step times of the surrogates against N, next to the classical solver on the same field.

    python benchmarks/inference.py [--model NAME ...] [--threads T] [--quick | --smoke]

Prints Markdown tables. The surrogate's time (the result's own ``time``) covers encoding, the network, building the
map on the output grid and the fold check (and repair, where needed); the classical time is one solve of the same
field on the same grid; both are medians over the repeats (one classical solve in 3D); ``ratio`` = classical /
surrogate.
``traced`` is the same map with the network evaluated through its TorchScript trace (``Surrogate.trace``: the same
operations and parameters without Python's per-module overhead; tracing a shape, about 0.2 s, happens once in the
warm-up call and is not in the median), what a user mapping many fields of one size gets.
``symmetrized`` is the traced map averaged over the domain's symmetries (``symmetrize=True``: 8 network
evaluations in 2D, 3 in 3D; ``rfmap.nn.symmetry``).
Models that are not shipped are replaced by an untrained network of the ``full`` preset's size (same cost).
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from rfmap.training.config import get_config
from rfmap.fields import BELTRAMI_MAPS, DENSITIES
from rfmap.core.mesh import grid_mesh
from rfmap.solvers import solve_dem, solve_lbs
from rfmap.surrogate import Surrogate, models
from rfmap.tasks import sample_batch, task_loss


def surrogate(name: str) -> Surrogate:
    if name in models():
        return Surrogate.pretrained(name)
    cfg = get_config(name, "full")
    sur = Surrogate.untrained(cfg.task, base=cfg.model.base, depth=cfg.model.depth, name=name + " (untrained)",
                              n_range=list(cfg.n_range))
    return sur


def median_of(fn, repeats: int):
    """The results of ``repeats`` calls of ``fn`` after one warm-up call, and the median of their own ``time``."""
    fn()
    results = [fn() for _ in range(repeats)]
    return results, float(np.median([r.time for r in results]))


def inference_rows(name: str, ns, repeats: int):
    sur = surrogate(name)
    kind, dim = sur.spec.kind, sur.spec.dim
    field = "T1" if kind == "beltrami" else ("multi-freq" if dim == 2 else "multi-freq-3d")
    print(f"\n### {sur.name}: {kind}, {dim}D, field {field} (medians of {repeats} runs)\n")
    print("| N | working grid | surrogate (s) | network only (s) | traced (s) | symmetrized (s) | classical (s) "
          "| ratio | ratio traced | ratio symmetrized |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in ns:
        rs, t_sur = median_of(lambda: sur.trace(False).map(field, n), repeats)
        t_net = float(np.median([r.info["network_time"] for r in rs]))
        # the traced network (Surrogate.trace): the warm-up call of median_of traces this shape
        _, t_tr = median_of(lambda: sur.trace().map(field, n), repeats)
        _, t_sym = median_of(lambda: sur.trace().map(field, n, symmetrize=True), repeats)
        if kind == "beltrami":
            mesh = grid_mesh(n, 2)
            mu = BELTRAMI_MAPS[field].mu(mesh.points[mesh.elements].mean(1))
            _, t_cl = median_of(lambda: solve_lbs(mu, n), repeats)
        else:
            dens = DENSITIES[field].sample(n)
            _, t_cl = median_of(lambda: solve_dem(dens, boundary="square"), 1 if dim == 3 else repeats)
        print(f"| {n} | {rs[0].info['work_n']} | {t_sur:.4f} | {t_net:.4f} | {t_tr:.4f} | {t_sym:.4f} | {t_cl:.4f} | "
              f"{t_cl / t_sur:.1f} | {t_cl / t_tr:.1f} | {t_cl / t_sym:.1f} |")


def train_step_rows(names, repeats: int, smoke: bool = False):
    print("\n### one training step of the `full` presets\n")
    print("| config | batch | N | data (s) | step (s) |")
    print("|---|---|---|---|---|")
    for name in names:
        cfg = get_config(name, "full")
        from rfmap.nn import MultiResUNet

        model = MultiResUNet(cfg.task.dim, cfg.task.n_params, cfg.model.base, cfg.model.depth)
        opt = torch.optim.AdamW(model.parameters(), lr=1e-4)
        n = get_config(name, "ci").n_range[0] if smoke else int(np.mean(cfg.n_range))
        batch = 1 if smoke else cfg.batch
        tds, tss = [], []
        for i in range(repeats + 1):
            t0 = time.perf_counter()
            b = sample_batch(cfg.task, seed=0, step=i, indices=range(batch), n=n, jitter=cfg.jitter)
            t1 = time.perf_counter()
            loss, _ = task_loss(cfg.task, b, model(b.inputs), cfg.loss)
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.clip)
            opt.step()
            t2 = time.perf_counter()
            if i:
                tds.append(t1 - t0)
                tss.append(t2 - t1)
        print(f"| {name} | {batch} | {n} | {min(tds):.3f} | {min(tss):.3f} |")


def main():
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--model", nargs="*", default=["beltrami2d", "deq2d-square", "dem3d-cube"])
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--quick", action="store_true", help="fewer sizes and repeats")
    p.add_argument("--smoke", action="store_true", help="the smallest run: one size (the ci preset's smallest), "
                   "one repeat, batch 1")
    a = p.parse_args()
    if a.threads:
        torch.set_num_threads(a.threads)
    print(f"torch threads: {torch.get_num_threads()}")
    reps = 1 if a.smoke else 3 if a.quick else 7
    for name in a.model:
        dim = get_config(name, "full").task.dim
        ns = ((32, 51, 64, 128, 256) if not a.quick else (51, 128)) if dim == 2 else \
            ((32, 48, 64) if not a.quick else (32, 48))
        inference_rows(name, (get_config(name, "ci").n_range[0],) if a.smoke else ns, reps)
    train_step_rows(a.model, reps, a.smoke)


if __name__ == "__main__":
    main()
