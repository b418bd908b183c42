#!/usr/bin/env python3
"""Record how long each chapter takes to execute, for the reproduction column of book/figures.md.

Usage:
    python scripts/chapter_times.py record NB --start T0 --end T1 --scale ci|full --out FILE
        (called by ``make chapter``) print the wall time of one chapter and write it to FILE as JSON
    python scripts/chapter_times.py collect --scale ci|full (--chapters DIR | --build DIR) [--note TEXT]
        store the times in src/rfmap/data/chapter_times.json under ``scale``: from the FILEs that ``make chapter``
        wrote into DIR (default _build/chapters), or from the execution records of a book build (the Sphinx
        environment in DIR/.doctrees, default _build, as ``make book`` leaves it; only chapters that succeeded)

``collect`` then rewrites book/figures.md (scripts/make_figures_md.py), whose reproduction table shows the times.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import pickle
import platform
import sys
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "src/rfmap/data/chapter_times.json"
SCALES = ("ci", "full")


def machine() -> str:
    """A one-line description of the computer: processor and logical core count."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} logical cores"


def record(args) -> int:
    seconds = float(args.end) - float(args.start)
    entry = {"chapter": args.notebook, "scale": args.scale, "seconds": round(seconds, 1), "machine": machine(),
             "date": datetime.now(timezone.utc).strftime("%Y-%m-%d")}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(entry, indent=1) + "\n", encoding="utf-8")
    print(f"{args.notebook}: {seconds:.1f} s at RFMAP_SCALE={args.scale} ({entry['machine']})")
    return 0


def from_chapters(folder: Path, scale: str) -> tuple[dict, str]:
    times, machines = {}, set()
    for path in sorted(folder.glob("*.time.json")):
        entry = json.loads(path.read_text(encoding="utf-8"))
        if entry["scale"] == scale:
            times[entry["chapter"]] = entry["seconds"]
            machines.add(entry["machine"])
    return times, "; ".join(sorted(machines)) or machine()


def from_build(build: Path) -> dict:
    """Execution time of every notebook a book build ran successfully (myst-nb's execution records)."""
    from myst_nb.sphinx_ import NbMetadataCollector

    with open(build / ".doctrees" / "environment.pickle", "rb") as f:
        env = pickle.load(f)
    times = {}
    for docname, data in NbMetadataCollector.get_doc_data(env).items():
        run = data.get("exec_data") or {}
        if run.get("succeeded") and run.get("runtime") is not None:
            times[Path(docname).name] = round(float(run["runtime"]), 1)
    return times


def collect(args) -> int:
    if args.build:
        times, how, where = from_build(Path(args.build)), "book build (myst-nb execution records)", machine()
    else:
        times, where = from_chapters(Path(args.chapters), args.scale)
        how = "make chapter"
    if not times:
        print("no chapter times found", file=sys.stderr)
        return 1
    data = json.loads(DATA.read_text(encoding="utf-8"))
    section = data.setdefault(args.scale, {})
    section.update(how=how, machine=where, date=datetime.now(timezone.utc).strftime("%Y-%m-%d"))
    if args.note:
        section["note"] = args.note
    section.setdefault("seconds", {}).update(times)
    section["seconds"] = dict(sorted(section["seconds"].items()))
    DATA.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    print(f"stored {len(times)} chapter times at scale {args.scale} in {DATA.relative_to(ROOT)}")
    return regenerate_figures_page()


def regenerate_figures_page() -> int:
    """Rewrite book/figures.md (and the introduction's scoreboard), whose reproduction table shows the times."""
    spec = importlib.util.spec_from_file_location("make_figures_md", ROOT / "scripts" / "make_figures_md.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main([])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record", help="write the wall time of one chapter")
    rec.add_argument("notebook")
    rec.add_argument("--start", required=True)
    rec.add_argument("--end", required=True)
    rec.add_argument("--scale", choices=SCALES, required=True)
    rec.add_argument("--out", required=True)
    col = sub.add_parser("collect", help="store chapter times in src/rfmap/data/chapter_times.json")
    col.add_argument("--scale", choices=SCALES, required=True)
    src = col.add_mutually_exclusive_group()
    src.add_argument("--chapters", default=str(ROOT / "_build/chapters"))
    src.add_argument("--build")
    col.add_argument("--note")
    args = parser.parse_args(argv)
    return record(args) if args.command == "record" else collect(args)


if __name__ == "__main__":
    sys.exit(main())
