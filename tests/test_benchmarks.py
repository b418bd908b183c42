"""Smoke tests of the benchmark scripts at the smallest sizes: they run and print the tables they promise.

The numbers themselves (times, ratios) are what the scripts are for and are not asserted here; what is asserted
could fail: the table's columns, one row per grid side, and no folded element after repair.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def run_script(name: str, *args: str) -> str:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, str(ROOT / "benchmarks" / name), *args], capture_output=True, text=True,
                         env=env, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def table_rows(text: str) -> list[list[str]]:
    return [[c.strip() for c in line.strip("|").split("|")] for line in text.splitlines()
            if line.startswith("| ") and not line.startswith("| N ") and not line.startswith("|---")]


def test_repair_benchmark_smoke():
    out = run_script("repair.py", "--fields", "3", "--models", "beltrami2d")
    assert "repair / classical" in out
    rows = table_rows(out)
    from rfmap import Surrogate

    lo = Surrogate.pretrained("beltrami2d").n_range[0]  # the model's smallest side, the middle, 256
    assert [r[0] for r in rows] == [str(lo), str((lo + 256) // 2), "256"]
    assert all(r[4] == "0" for r in rows)  # folded after repair


@pytest.mark.parametrize("boundary", ["square"])
def test_hybrid_benchmark_smoke(boundary):
    out = run_script("hybrid.py", "--dims", "2", "--n2", "33", "--boundaries", boundary, "--no-paper",
                     "--random", "1")
    for method in ("diffusion", "flow", "surrogate", "hybrid"):
        assert method in out
