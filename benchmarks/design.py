"""Measure the flow solver's 3D defaults again: the step tolerance ``RTOL[3]`` and the sea width ``MARGIN[3]``.

Each setting runs on the paper's four 3D test densities (``rfmap.fields.TEST_FIELDS``) at one grid size, one
thread, the best of ``--repeat`` runs; a Markdown table gives the time and Std(rho~_map) of the chosen value and the
alternative, per field.  With ``--record`` the rows are stored in ``src/rfmap/data/design.json``
(:func:`rfmap.paper.design.record`); rerun ``python scripts/make_design_md.py`` to update the book's page *Design
decisions*.

Usage::

    python benchmarks/design.py                 # N = 48, as the recorded measurements (a few minutes on 2 cores)
    python benchmarks/design.py --n 24 --repeat 1
    python benchmarks/design.py --record
"""
from __future__ import annotations

import argparse
import platform
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import torch

from rfmap.fields import TEST_FIELDS, sample_density
from rfmap.paper.design import DESIGN_PATH, record
from rfmap.solvers.flow import MARGIN, RTOL, solve_flow

#: decision -> (boundary, option, chosen value, alternative)
CASES = {"RTOL": ("square", "rtol", RTOL[3], 0.2), "MARGIN": ("free", "margin", MARGIN[3], 0.5)}


def run(density: np.ndarray, boundary: str, repeat: int, **option) -> tuple[float, float]:
    """Best time of ``repeat`` runs of the flow solver and the Std(rho~_map) of its map."""
    results = [solve_flow(density, boundary=boundary, num_threads=1, **option) for _ in range(max(1, repeat))]
    best = min(results, key=lambda r: r.time)
    return best.time, best.metrics().std_rho_map


def measure(decision: str, n: int, repeat: int) -> list[dict[str, str]]:
    """One row per field: time and Std(rho~_map) of the chosen value and of the alternative."""
    boundary, option, chosen, alternative = CASES[decision]
    rows = []
    for name in TEST_FIELDS["density", 3]:
        density = sample_density(name, n)
        t0, s0 = run(density, boundary, repeat, **{option: chosen})
        t1, s1 = run(density, boundary, repeat, **{option: alternative})
        rows.append({"case": f"{name}, 3D N = {n}, {boundary} boundary",
                     "chosen": f"{option} = {chosen}: {t0:.2f} s, Std(ρ̃_map) {s0:.4f}",
                     "alternative": f"{option} = {alternative}: {t1:.2f} s, Std(ρ̃_map) {s1:.4f}"})
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=48)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--only", choices=sorted(CASES), help="measure one decision")
    parser.add_argument("--record", action="store_true", help="store the rows in src/rfmap/data/design.json")
    parser.add_argument("--out", default=str(DESIGN_PATH), help="the design record to update with --record")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    machine = f"{platform.processor() or platform.machine()}, one thread"
    for decision in [args.only] if args.only else sorted(CASES):
        rows = measure(decision, args.n, args.repeat)
        print(f"\n### {decision}\n\n| case | chosen | alternative |\n|---|---|---|")
        for r in rows:
            print(f"| {r['case']} | {r['chosen']} | {r['alternative']} |")
        if args.record:
            record(decision, path=Path(args.out), results=rows, benchmark="benchmarks/design.py",
                   data=f"the paper's four 3D test densities at N = {args.n}, best of {args.repeat} runs ({machine})",
                   date=datetime.now(timezone.utc).strftime("%Y-%m-%d"))


if __name__ == "__main__":
    main()
