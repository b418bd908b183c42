"""Bijectivity of the shipped surrogates on hard random fields, before and after :func:`rfmap.finish.repair.repair_map`.

    python benchmarks/repair.py [--fields K] [--fields-3d K] [--models NAME ...]

Fields come from :mod:`rfmap.fields.hard` (sharp peaks, steps, ramps, near-zero regions with p_min/p_max down to 1e-3,
mapped without the paper's shift; Beltrami coefficients with |mu| up to 0.95), spread evenly over the grid sides
from the model's smallest training side to 256 (2D) or 64 (3D).  For every model and N the table gives: fields,
fields with any folded element in the raw output and their total of folded elements, folded elements after repair
(must be 0), the mean repair time on folded fields next to the classical solver's mean time on the first
``--classical`` (default 3) of those same fields (on the first field of that N when none folds), the ratio of the two
over those fields, and on unfolded fields the check's time as a fraction of the surrogate's own time.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from rfmap.core.mesh import grid_mesh
from rfmap.finish.repair import repair_map
from rfmap.solvers import solve_dem, solve_lbs
from rfmap.fields.hard import hard_beltrami, hard_density
from rfmap.surrogate import Surrogate, quiet_quality

MODELS_2D = ["deq2d-square", "deq2d-free", "beltrami2d"]
MODELS_3D = ["dem3d-cube", "dem3d-free"]
#: folded fields per N on which the classical solver is timed as well (``--classical``)
CLASSICAL_SAMPLES = 3


def sides(sur: Surrogate) -> list[int]:
    lo = sur.n_range[0]
    top = 256 if sur.spec.dim == 2 else 64
    return sorted({lo, (lo + top) // 2, top})


def field_for(sur: Surrogate, rng, n):
    if sur.spec.kind == "density":
        return hard_density(rng, n, sur.spec.dim), {"preprocess": False}
    return hard_beltrami(rng, n), {}


def classical_time(sur: Surrogate, field, n) -> float:
    t = time.perf_counter()
    if sur.spec.kind == "beltrami":
        mesh = grid_mesh(n, 2)
        vals = field.reshape(-1)[mesh.elements].mean(1)
        solve_lbs(vals, n)
    else:
        solve_dem(field, boundary="square" if sur.spec.boundary == "square" else "free")
    return time.perf_counter() - t


def run(name: str, count: int, seed: int, samples: int = CLASSICAL_SAMPLES) -> None:
    sur = Surrogate.pretrained(name)
    ns = sides(sur)
    rng = np.random.default_rng(seed)
    rows = {n: {"fields": 0, "raw_fields": 0, "raw_elements": 0, "after": 0, "t_rep": [], "fast": [], "t_cl": []}
            for n in ns}
    first = {}
    for k in range(count):
        n = ns[k % len(ns)]
        f, kw = field_for(sur, rng, n)
        first.setdefault(n, f)
        t = time.perf_counter()
        raw = sur.map(f, n, repair=False, **kw)
        t_sur = time.perf_counter() - t
        dens = raw.field if sur.spec.kind == "density" else None
        mu = raw.field if sur.spec.kind == "beltrami" else None
        out, rep = repair_map(raw.ref_points, raw.mapped_points, raw.elements, boundary=sur.spec.boundary,
                              grid_n=n, density=dens, mu=mu)
        r = rows[n]
        r["fields"] += 1
        if rep["needed"]:
            r["raw_fields"] += 1
            r["raw_elements"] += rep["n_flipped_before"]
            r["t_rep"].append(rep["time"])
            r["after"] += int((np.asarray(rep["metrics_after"]["n_flipped"])))
            if len(r["t_cl"]) < samples:  # the classical solver on the same folded field
                r["t_cl"].append(classical_time(sur, f, n))
        else:
            r["fast"].append(rep["time"] / t_sur)
    print(f"\n### {name} ({sur.spec.kind}, {sur.spec.dim}D, {sur.spec.boundary} boundary)\n")
    print("| N | fields | raw: folded fields | raw: folded elements | folded after repair | repair (s), mean | "
          "classical (s) | repair / classical | unfolded: check / surrogate |")
    print("|---|---|---|---|---|---|---|---|---|")
    for n in ns:
        r = rows[n]
        if not r["fields"]:
            continue
        t_cl = np.mean(r["t_cl"][:len(r["t_rep"])]) if r["t_cl"] else classical_time(sur, first[n], n)
        t_rep = np.mean(r["t_rep"][:len(r["t_cl"])]) if r["t_rep"] else None
        rep = f"{np.mean(r['t_rep']):.3f}" if r["t_rep"] else "—"
        ratio = f"{t_rep / t_cl:.2f}" if t_rep is not None else "—"
        fast = f"{100 * np.mean(r['fast']):.1f} %" if r["fast"] else "—"
        print(f"| {n} | {r['fields']} | {r['raw_fields']} | {r['raw_elements']} | {r['after']} | {rep} | "
              f"{t_cl:.3f} | {ratio} | {fast} |", flush=True)


@quiet_quality()  # raw maps of hard fields are meant to be poor; the table reports them
def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--fields", type=int, default=500, help="2D fields in all, shared by the 2D models")
    p.add_argument("--fields-3d", type=int, default=100, help="3D fields in all, shared by the 3D models")
    p.add_argument("--models", nargs="*", default=MODELS_2D + MODELS_3D)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--classical", type=int, default=CLASSICAL_SAMPLES,
                   help="folded fields per N on which the classical solver is timed too (at least 1)")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    m2 = [m for m in args.models if m in MODELS_2D]
    m3 = [m for m in args.models if m not in MODELS_2D]
    for i, name in enumerate(args.models):
        group, total = (m2, args.fields) if name in m2 else (m3, args.fields_3d)
        run(name, max(1, total // len(group)), args.seed + i, max(1, args.classical))


if __name__ == "__main__":
    main()
