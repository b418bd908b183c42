"""Every benchmark script runs at its smallest size and prints the table it promises.

The numbers themselves (times, ratios) are what the scripts are for and are not asserted here; what is asserted
could fail: the script's exit status, the table's columns, one row per grid side, and no folded element after repair.
A script added to ``benchmarks/`` without an entry in :data:`SMOKE` fails :func:`test_every_benchmark_has_a_smoke_run`,
so a refactor cannot break a benchmark silently.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"

#: the smallest run of every benchmark script: its arguments (``{tmp}`` is a temporary folder) and a text its output
#: must hold
SMOKE = {
    "cartogram.py": (["--maps", "montreal", "--n", "64", "--repeat", "1", "--methods", "flow", "--workdir", "{tmp}"],
                     "| montreal | 64 | rfmap flow |"),
    "design.py": (["--n", "9", "--repeat", "1", "--only", "RTOL"], "3D N = 9"),
    "hybrid.py": (["--dims", "2", "--n2", "33", "--boundaries", "square", "--no-paper", "--random", "1"], "hybrid"),
    "inference.py": (["--smoke", "--threads", "1"], "### one training step of the `full` presets"),
    "paper_inputs.py": (["--field", "rect-peak", "--step", "0.25", "--values", "2", "--top", "1"],
                        "| sin-cos, vertex, shift | add |"),
    "repair.py": (["--fields", "3", "--models", "beltrami2d"], "repair / classical"),
    "solvers.py": (["--smoke"], "### Diffusion density-equalizing map, 3D sin-cos-3d, cube boundary"),
    "train_step.py": (["--smoke", "--threads", "1", "--workers", "0", "--json"], '"ms_per_step"'),
    "train_study.py": (["smoke", "--config", "deq2d-square", "--preset", "ci", "--minutes", "0.02", "--variant",
                        "a=--seed 1", "--variant", "b=--seed 2", "--runs", "{tmp}/runs", "--out",
                        "{tmp}/study.json"], "wrote "),
}


def run_script(name: str, *args: str) -> str:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "RFMAP_SCALE": "ci",
           "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    out = subprocess.run([sys.executable, str(BENCHMARKS / name), *args], capture_output=True, text=True,
                         env=env, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def table_rows(text: str) -> list[list[str]]:
    return [[c.strip() for c in line.strip("|").split("|")] for line in text.splitlines()
            if line.startswith("| ") and not line.startswith("| N ") and not line.startswith("|---")]


def test_every_benchmark_has_a_smoke_run():
    assert sorted(p.name for p in BENCHMARKS.glob("*.py")) == sorted(SMOKE)


@pytest.mark.parametrize("name", sorted(set(SMOKE) - {"repair.py", "hybrid.py"}))
def test_benchmark_smoke(name, tmp_path):
    args, expected = SMOKE[name]
    out = run_script(name, *(a.replace("{tmp}", str(tmp_path)) for a in args))
    assert expected in out, out[-2000:]
    if name == "train_step.py":
        rows = json.loads(out)
        assert sorted(rows) == ["beltrami2d", "dem3d-cube", "deq2d-square"]
        assert all(r["batch"] == 1 and r["ms_per_step"] > 0 for r in rows.values())
    if name == "cartogram.py":  # the command's exit status and the topology of its output
        (row,) = [r for r in table_rows(out) if r[0] == "montreal"]
        assert row[6] == "0" and row[-1] == "valid", row
    if name == "train_study.py":
        runs = json.loads((tmp_path / "study.json").read_text())["runs"]
        assert sorted(runs) == ["a", "b"]


def test_repair_benchmark_smoke():
    out = run_script("repair.py", *SMOKE["repair.py"][0])
    assert SMOKE["repair.py"][1] in out
    rows = table_rows(out)
    from rfmap import Surrogate

    lo = Surrogate.pretrained("beltrami2d").n_range[0]  # the model's smallest side, the middle, 256
    assert [r[0] for r in rows] == [str(lo), str((lo + 256) // 2), "256"]
    assert all(r[4] == "0" for r in rows)  # folded after repair


def test_hybrid_benchmark_smoke():
    out = run_script("hybrid.py", *SMOKE["hybrid.py"][0])
    for method in ("diffusion", "flow", "surrogate", "hybrid"):
        assert method in out


def test_the_cartogram_benchmark_reads_real_maps_of_cartogram_cpps_sample_data(tmp_path):
    """``--sample-data``: each real map's GeoJSON joined to its population CSV (Windows-1252, as the US county table
    comes) by the id column; a folder that is missing is named."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_cartogram", BENCHMARKS / "cartogram.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    square = {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]]}
    for name, (sub, key, value) in mod.REAL.items():
        folder = tmp_path / sub
        folder.mkdir()
        feats = [{"type": "Feature", "properties": {key: k, "other": 1}, "geometry": square} for k in ("Doña", "B")]
        (folder / f"{sub}.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": feats}),
                                               encoding="utf-8")
        (folder / "population.csv").write_bytes(f"{key},{value},Color\nDoña,5,\nB,7,\n".encode("cp1252"))
    maps = mod.real_maps(str(tmp_path))
    assert sorted(maps) == sorted(mod.REAL)
    feats, key, value = maps["us-counties"]
    assert value == "pop" and [f["properties"] for f in feats] == [{key: "Doña", "pop": 5.0}, {key: "B", "pop": 7.0}]
    with pytest.raises(SystemExit, match="needs one .geojson"):
        mod.real_maps(str(tmp_path / "nowhere"))
