"""Train runs of one configuration that differ in one option side by side for the same wall time, and store their
validation curves (``rfmap.training.records``) for the book.

Every run starts at once with one torch thread and one batch worker, so that they share the machine alike; the
comparison is at equal wall time (a run with a teacher takes fewer steps).  Each variant is a label and the options
it adds to ``rfmap train``.

Usage::

    python benchmarks/train_study.py teacher-deq2d-square --config deq2d-square --minutes 20 \\
        --variant "data-free=--teacher none" --variant "teacher (diffusion)=--teacher diffusion"
    python benchmarks/train_study.py NAME ... --collect-only     # the runs exist: write the study file only
    python benchmarks/train_study.py NAME ... --preset ci --out study.json   # a small run, written elsewhere
"""
from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
from pathlib import Path

from rfmap.training.records import collect, study_table


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("name", help="the study's name (its file: src/rfmap/data/studies/NAME.json)")
    p.add_argument("--config", required=True)
    p.add_argument("--minutes", type=float, required=True, help="wall time of every run")
    p.add_argument("--variant", action="append", required=True, metavar="LABEL=OPTIONS",
                   help="a run: its label and the rfmap train options it adds")
    p.add_argument("--common", default="", help="options of every run (e.g. '--init dem3d-cube --seed 60')")
    p.add_argument("--runs", default="runs/studies", help="folder of the runs")
    p.add_argument("--description", default="")
    p.add_argument("--collect-only", action="store_true")
    p.add_argument("--preset", default="full", choices=["ci", "full"], help="the preset of every run")
    p.add_argument("--out", default=None, help="the study file (default: src/rfmap/data/studies/NAME.json)")
    args = p.parse_args(argv)
    variants = dict(v.split("=", 1) for v in args.variant)
    dirs, commands = {}, {}
    for i, (label, opts) in enumerate(variants.items()):
        dirs[label] = Path(args.runs) / args.name / f"run{i}"
        commands[label] = (f"rfmap train --config {args.config} --preset {args.preset} --time-limit {args.minutes * 60:g} "
                           f"--threads 1 --workers 1 {args.common} {opts} --out {dirs[label]} --no-progress")
    if not args.collect_only:
        procs = [subprocess.Popen(shlex.split(c), stdout=subprocess.DEVNULL) for c in commands.values()]
        codes = [pr.wait() for pr in procs]
        if any(codes):
            print(f"a run failed: exit codes {codes}", file=sys.stderr)
            return 1
    path = collect(args.name, dirs, description=args.description or f"{args.config}, {args.minutes:g} min each",
                   commands=commands, out=args.out)
    print(f"wrote {path}")
    print(study_table(json.loads(Path(path).read_text())).to_string(float_format=lambda v: f"{v:.4g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
