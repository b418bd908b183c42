#!/usr/bin/env python3
"""Write book/design.md, the page "Design decisions", from src/rfmap/data/design.json.

Usage: python scripts/make_design_md.py [--check]

With --check nothing is written; the exit status is 1 when book/design.md differs from what would be written, or
when a value recorded in design.json is no longer the one in the code (rfmap.paper.design.stale_values).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rfmap.paper.design import stale_values, to_markdown

ROOT = Path(__file__).resolve().parent.parent
TARGET = Path("book/design.md")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only check that book/design.md is up to date")
    args = parser.parse_args(argv)
    for constant, recorded, now in stale_values():
        print(f"design.json records {constant} = {recorded}, the code has {now}: measure it again", file=sys.stderr)
    text = to_markdown()
    target = ROOT / TARGET
    if args.check:
        current = target.read_text(encoding="utf-8") if target.exists() else ""
        if current != text or stale_values():
            print(f"{TARGET} is out of date: run python scripts/make_design_md.py", file=sys.stderr)
            return 1
        print(f"{TARGET} is up to date")
        return 0
    target.write_text(text, encoding="utf-8")
    print(f"wrote {TARGET}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
