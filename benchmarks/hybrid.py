"""Time to accuracy: Std(rho~_map) against wall time of the diffusion and flow-based solvers, the surrogate (raw,
refined) and the hybrid (surrogate polished by the flow; with its guard, and its warm flow alone), on the paper's
test fields and on unseen random fields.

Every method runs on the same field one after another in one process, so the time ratios are side by side, after
one untimed run of every method on each case's first field (``time_to_accuracy(warmup=True)``); the absolute times
depend on the machine and its load.  The table gives, per case, the mean over the fields and the
ratios to the best classical solver of that case (the one with the lower mean Std).

Usage::

    python benchmarks/hybrid.py                              # 2D N=51/128/256 and 3D N=32/48/64, both boundaries
    python benchmarks/hybrid.py --n2 51 --n3 32 --random 2   # fewer cases
    python benchmarks/hybrid.py --dims 3 --n3 48 --boundaries square --no-paper --random 4
"""
from __future__ import annotations

import argparse

from rfmap.paper.benchmarks import METHODS, summarize, time_to_accuracy
from rfmap.paper.tables import format_value


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dims", type=int, nargs="+", default=[2, 3], choices=[2, 3])
    p.add_argument("--n2", type=int, nargs="+", default=[51, 128, 256], help="2D grid sides")
    p.add_argument("--n3", type=int, nargs="+", default=[32, 48, 64], help="3D grid sides")
    p.add_argument("--boundaries", nargs="+", default=["square", "free"], choices=["square", "free"])
    p.add_argument("--no-paper", action="store_true", help="skip the paper's test fields")
    p.add_argument("--random", type=int, default=4, help="unseen random fields per case (default 4)")
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    args = p.parse_args(argv)
    rows = []
    for dim in args.dims:
        for n in (args.n2 if dim == 2 else args.n3):
            for boundary in args.boundaries:
                case = time_to_accuracy(dim, n, boundary, paper=not args.no_paper, random=args.random,
                                        methods=args.methods)
                rows += case
                for r in case:
                    print(f"# {dim}D N={n} {boundary} {r['field']:14s} {r['method']:17s} "
                          f"std={r['std_rho_map']:.4g} t={r['time']:.3f}s flips={r['n_flipped']}"
                          f"{' ' + r['start'] + ' start, kept ' + r['kept'] if 'start' in r else ''}", flush=True)
    cols = ["std_rho_map", "time", "n_flipped", "std_ratio", "time_ratio"]
    print("\n| d | N | boundary | method | fields | " + " | ".join(cols) + " |")
    print("|" + "---|" * (5 + len(cols)))
    for r in summarize(rows):
        vals = [format_value(r[c], c) if c in r else "—" for c in cols]
        vals = [v if c not in ("std_ratio", "time_ratio") or v == "—" else f"{r[c]:.3g}" for v, c in zip(vals, cols)]
        print(f"| {r['dim']} | {r['n']} | {r['boundary']} | {r['method']} | {r['fields']} | " + " | ".join(vals) + " |")


if __name__ == "__main__":
    main()
