"""Time and accuracy of the classical solvers against the grid size N (Markdown tables on stdout).

* LBS on the test map T1: mu sampled at the triangle centroids, error = mean vertex distance to the exact map.
* 2D DEM (square boundary) on sin-cos, 3D DEM (cube boundary) on sin-cos-3d: Std(rho~) on the mapped mesh, smallest
  element Jacobian, flipped elements; by the diffusion method, and with ``--methods diffusion flow`` also by the
  flow-based one.
* ``--targets`` adds the acceptance table: LBS on T1-T4 at N=51, 2D DEM on four densities at N=51, 3D DEM on four
  densities at N=48, and the free boundary.

Usage::

    python benchmarks/solvers.py            # full sweep (3D up to N=64; a few minutes on 2 cores)
    python benchmarks/solvers.py --quick    # stops at N=128 (2D) and N=32 (3D)
    python benchmarks/solvers.py --smoke    # one small size (N=17 in 2D, N=9 in 3D), one run each
    python benchmarks/solvers.py --targets --threads 1
    python benchmarks/solvers.py --quick --methods diffusion flow --threads 1
"""
from __future__ import annotations

import argparse
import platform
import time

import numpy as np
import torch

from rfmap.fields import BELTRAMI_MAPS, sample_density
from rfmap.core.mesh import element_measures, grid_mesh
from rfmap.solvers import solve_dem, solve_lbs


def best_of(fn, repeat: int):
    """Run ``fn`` ``repeat`` times; return the result with the smallest ``.time``."""
    results = [fn() for _ in range(max(1, repeat))]
    return min(results, key=lambda r: r.time)


def lbs_row(name: str, n: int, repeat: int) -> str:
    mesh = grid_mesh(n, 2)
    m = BELTRAMI_MAPS[name]
    mu = m.mu(mesh.points[mesh.elements].mean(axis=1))
    res = best_of(lambda: solve_lbs(mu, n), repeat)
    met = res.metrics(exact_points=m(mesh.points))
    return f"| {name} | {n} | {res.time:.4f} | {met.mean_dd:.3e} | {met.n_flipped} |"


def dem_row(name: str, n: int, repeat: int, boundary: str = "square", threads: int | None = None,
            method: str = "diffusion") -> str:
    dens = sample_density(name, n)
    res = best_of(lambda: solve_dem(dens, method=method, boundary=boundary, num_threads=threads), repeat)
    met = res.metrics()
    area = float(element_measures(res.mapped_points, res.elements).sum())
    steps = res.info["iterations"] if method == "diffusion" else res.info["steps"]
    return (f"| {name} | {boundary} | {n} | {res.time:.3f} | {met.std_rho_orig:.4f} | {met.std_rho_map:.4f} | "
            f"{met.min_jacobian:.4f} | {met.n_flipped} | {area - 1:+.1e} | {steps} |")


LBS_HEAD = "| map | N | time [s] | mean \\|Δd\\| | flips |\n|---|---:|---:|---:|---:|"
DEM_HEAD = ("| density | boundary | N | time [s] | Std(ρ̃) orig | Std(ρ̃) map | min J | flips | area − 1 | steps |\n"
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="stop at N=128 in 2D and N=32 in 3D")
    ap.add_argument("--smoke", action="store_true", help="one small size (N=17 in 2D, N=9 in 3D), one run each")
    ap.add_argument("--targets", action="store_true", help="also print the acceptance-target table")
    ap.add_argument("--no-sweep", action="store_true", help="skip the N sweep (with --targets)")
    ap.add_argument("--repeat", type=int, default=3, help="best-of repeats for runs under one second")
    ap.add_argument("--methods", nargs="+", choices=("diffusion", "flow"), default=["diffusion"],
                    help="density-equalizing methods of the sweep (default: diffusion)")
    ap.add_argument("--threads", type=int, default=None,
                    help="torch threads for 3D DEM (default: torch's setting; 2D DEM always uses 1)")
    args = ap.parse_args(argv)

    print(f"<!-- {platform.processor() or platform.machine()}, torch threads {torch.get_num_threads()}, "
          f"numpy {np.__version__}, torch {torch.__version__}; time = best of {args.repeat} below 1 s -->\n")
    if args.smoke:
        args.repeat = 1
    n2 = [17] if args.smoke else [32, 64, 128] if args.quick else [32, 64, 128, 256]
    n3 = [9] if args.smoke else [32] if args.quick else [32, 48, 64]

    def rep(n: int, dim: int) -> int:
        return args.repeat if (dim == 2 and n <= 128) else 1

    if not args.no_sweep:
        print("### Linear Beltrami Solver, T1 (mu at centroids, Dirichlet identity boundary)\n")
        print(LBS_HEAD)
        for n in n2:
            print(lbs_row("T1", n, args.repeat), flush=True)
        for method in args.methods:
            title = method.capitalize() if method == "diffusion" else "Flow-based"
            print(f"\n### {title} density-equalizing map, 2D sin-cos, square boundary\n")
            print(DEM_HEAD)
            for n in n2:
                print(dem_row("sin-cos", n, rep(n, 2), method=method), flush=True)
            print(f"\n### {title} density-equalizing map, 3D sin-cos-3d, cube boundary\n")
            print(DEM_HEAD)
            for n in n3:
                print(dem_row("sin-cos-3d", n, 1, threads=args.threads, method=method), flush=True)

    if args.targets:
        print("\n### Targets: LBS at N=51 (target: time <= 0.05 s, mean |Δd| <= 1e-4)\n")
        print(LBS_HEAD)
        for name in ("T1", "T2", "T3", "T4"):
            print(lbs_row(name, 51, args.repeat), flush=True)
        print("\n### Targets: 2D DEM at N=51 (target: Std <= 0.035, no flip, time <= 0.5 s)\n")
        print(DEM_HEAD)
        for name in ("sin-cos", "exp-log", "rect-peak", "ring"):
            print(dem_row(name, 51, args.repeat), flush=True)
        print("\n### Targets: 3D DEM at N=48 (target: Std <= 0.08, no flip, time <= 20 s)\n")
        print(DEM_HEAD)
        for name in ("sin-cos-3d", "shell-3d", "octant-3d", "prism-peak-3d"):
            print(dem_row(name, 48, 1, threads=args.threads), flush=True)
        print("\n### Free boundary (sea margin L = 0.5)\n")
        print(DEM_HEAD)
        for name, n in (("sin-cos", 51), ("exp-log", 51), ("rect-peak", 51), ("ring", 51),
                        ("sin-cos-3d", 24), ("shell-3d", 24), ("octant-3d", 24), ("prism-peak-3d", 24)):
            print(dem_row(name, n, 1, boundary="free", threads=args.threads), flush=True)


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(f"\n<!-- total {time.perf_counter() - t0:.1f} s -->")
