"""Whole-command time, peak memory and accuracy of ``rfmap cartogram`` side by side with a reference program.

Runs ``rfmap cartogram`` (flow and diffusion methods) and, with ``--reference PATH`` to the ``cartogram`` binary of
cartogram-cpp (Gastner, Seguy & More's flow-based method), that program on the same real maps at N = 256 and 512
with the same 1 % tolerance: Montreal's 2013 election (total votes, :func:`rfmap.cartogram.regions.montreal_election`), the
Natural Earth world map by population (:func:`rfmap.cartogram.regions.world_countries`) and three continental subsets (Africa,
South America, and an Asia-Pacific set with Russia and Fiji that crosses the antimeridian), and two synthetic hard
maps (:mod:`rfmap.cartogram.synthetic`): the contiguous United States cut into 3,100 counties of very different
sizes (``counties``; ``counties-slivers``: its borders bent and each county simplified on its own, as a county file
simplified feature by feature draws them) and Russia cut into 80 subdivisions across the antimeridian (``russia``;
``russia-slivers``: the same bending and simplification), so that neighbours overlap in the input and sliver gaps
open between them.  Both programs read the
same GeoJSON (consecutive repeated points removed, which the reference refuses) and CSV files, written to a work
folder.

rfmap's modules are byte-compiled first (``compileall``), as pip leaves an installed package, so that no timed command
compiles them (an editable install run with ``PYTHONDONTWRITEBYTECODE`` set would).  Every command is run
``--repeat`` times as a child process; the table gives the median wall time and the median peak
resident memory (``/usr/bin/time``'s maximum resident set size), the exit status, and the largest
and mean relative area error :math:`|A_i/T_i - 1|` measured by :func:`rfmap.cartogram.resize.cartogram_metrics` over the
regions holding at least :data:`rfmap.cartogram.resize.MIN_SHARE` of the total value (the others' largest error apart), in
each program's equal-area plane (rfmap writes its projected plane, ``--projected``; the reference writes its own
equal-area plane), with validity and overlaps.  The ratio column is the median time over the reference's.

Usage::

    python benchmarks/cartogram.py --reference /path/to/cartogram-cpp/cartogram
    python benchmarks/cartogram.py --maps montreal africa --n 256 --repeat 1 --methods flow
    python benchmarks/cartogram.py --reference CARTOGRAM --sample-data cartogram-cpp/sample_data \\
        --maps us-counties russia-subjects world-countries --n 256 --repeat 1 --methods flow

``--sample-data`` adds three real maps from cartogram-cpp's ``sample_data`` folder (its public repository): the
3,108 counties of the contiguous United States (US Census Bureau), Russia's 83 federal subjects across the
antimeridian, and 198 countries of the world, each by population.
"""
from __future__ import annotations

import argparse
import compileall
import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

#: GNU time, for the peak resident size (``%M``, as ``/usr/bin/time -v`` reports it)
TIME = "/usr/bin/time"
MAPS = ("montreal", "world", "africa", "south-america", "asia-pacific", "counties", "counties-slivers", "russia",
        "russia-slivers")
#: the Asia-Pacific subset: Russia and Fiji are split at the antimeridian, so the map crosses it
ASIA_PACIFIC = ("Russia", "Fiji", "New Zealand", "Australia", "Papua New Guinea", "Indonesia", "Japan", "Philippines",
                "China", "Mongolia", "South Korea", "North Korea", "Taiwan", "Vanuatu", "Solomon Is.", "New Caledonia")


#: real maps of cartogram-cpp's ``sample_data`` folder (``--sample-data``): ``{name: (folder, id column, value
#: column)}``, the GeoJSON and the CSV (Windows-1252 or UTF-8) of each folder joined by the id
REAL = {
    "us-counties": ("contiguous_usa_by_county_since_2001", "AFFGEOID", "Population (people)"),
    "russia-subjects": ("russia_by_federal_subject_since_2008", "NAME_1", "Population (people)"),
    "world-countries": ("world_by_country_since_2022", "ISO_CODE", "Population (people)"),
}
WORLDS = ("world", "world-countries")


def real_maps(sample_data: str) -> dict:
    """The maps of :data:`REAL` from a ``sample_data`` folder: ``{name: (features with "pop", id property,
    "pop")}``; a folder or file that is missing is an error naming it."""
    import glob
    import warnings

    from rfmap.cartogram.data import read_csv_table

    out = {}
    for name, (sub, key, value) in REAL.items():
        folder = os.path.join(sample_data, sub)
        gj = glob.glob(os.path.join(folder, "*.geojson"))
        tables = glob.glob(os.path.join(folder, "*population*.csv"))
        if len(gj) != 1 or not tables:
            raise SystemExit(f"--sample-data: {folder} needs one .geojson and a population CSV")
        with open(gj[0], encoding="utf-8") as fh:
            feats = json.load(fh)["features"]
        with warnings.catch_warnings():  # a Windows-1252 table (the US counties') is read as such
            warnings.simplefilter("ignore", UnicodeWarning)
            table = read_csv_table(min(tables, key=len), key, [value])
        pop = {k: float(row[value]) for k, row in table.items()}
        for f in feats:
            f["properties"] = {key: f["properties"][key], "pop": pop[f["properties"][key]]}
        out[name] = (feats, key, "pop")
    return out


def write_inputs(folder: str, sample_data: str | None = None) -> dict:
    """GeoJSON + CSV of every map in ``folder``: ``{name: (geojson, csv, id property, value property)}``; with
    ``sample_data``, the real maps of :data:`REAL` too."""
    import shapely
    from shapely.geometry import mapping, shape

    from rfmap.cartogram.synthetic import synthetic_counties, synthetic_subdivisions
    from rfmap.cartogram.regions import _listify, montreal_election, world_countries

    world = world_countries()["features"]
    chosen = {
        "montreal": (montreal_election()["features"], "district", "total"),
        "world": (world, "name", "pop_est"),
        "africa": ([f for f in world if f["properties"]["continent"] == "Africa"], "name", "pop_est"),
        "south-america": ([f for f in world if f["properties"]["continent"] == "South America"], "name", "pop_est"),
        "asia-pacific": ([f for f in world if f["properties"]["name"] in ASIA_PACIFIC], "name", "pop_est"),
        "counties": (synthetic_counties()["features"], "id", "value"),
        "counties-slivers": (synthetic_counties(slivers=True)["features"], "id", "value"),
        "russia": (synthetic_subdivisions()["features"], "id", "value"),
        "russia-slivers": (synthetic_subdivisions(slivers=True)["features"], "id", "value"),
        **(real_maps(sample_data) if sample_data else {}),
    }
    out = {}
    for name, (feats, key, value) in chosen.items():
        clean = [{"type": "Feature", "properties": f["properties"],
                  "geometry": _listify(mapping(shapely.remove_repeated_points(shape(f["geometry"]))))}
                 for f in feats]
        gj, table = os.path.join(folder, f"{name}.geojson"), os.path.join(folder, f"{name}.csv")
        with open(gj, "w", encoding="utf-8") as fh:
            json.dump({"type": "FeatureCollection", "features": clean}, fh)
        with open(table, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow([key, value])
            w.writerows([f["properties"][key], f["properties"][value]] for f in clean)
        out[name] = (gj, table, key, value)
    return out


def timed(cmd: list[str], cwd: str) -> tuple[float, float, int]:
    """Run ``cmd`` under ``/usr/bin/time`` (a small parent, so that the peak resident size is the command's own and
    not this Python's, which a forked child inherits); return (wall seconds, peak resident MB, exit status)."""
    report = os.path.join(cwd, "time.txt")
    t0 = time.perf_counter()
    code = subprocess.call([TIME, "-f", "%M", "-o", report, *cmd], cwd=cwd, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    with open(report, encoding="utf-8") as fh:
        kb = float(fh.read().strip().splitlines()[-1])
    return wall, kb / 1024.0, code


def area_errors(path: str, key: str, value: str, values: dict) -> str:
    """``max / mean (minor max) / topology`` of an output GeoJSON in its own (equal-area) plane."""
    import shapely
    from shapely.geometry import shape

    from rfmap.cartogram.resize import MIN_SHARE, cartogram_metrics

    if not os.path.isfile(path):
        return "no output | | |"
    with open(path, encoding="utf-8") as fh:
        feats = json.load(fh)["features"]
    geoms = np.array([shape(f["geometry"]) if f["geometry"] else shapely.Polygon() for f in feats], dtype=object)
    v = np.array([float(values[str(f["properties"][key])]) for f in feats])
    m = cartogram_metrics(geoms, v, min_share=MIN_SHARE)
    topo = "valid" if m.topology_ok else f"{m.n_invalid} invalid, {m.n_overlapping} overlaps"
    minor = f"{m.max_error_minor:.3g} ({m.n_minor})" if m.n_minor else "-"
    return f"{m.max_error:.4f} | {m.mean_error:.4f} | {minor} | {topo}"


def commands(args, name: str, files: tuple, n: int, folder: str) -> dict:
    """The commands to compare for one map and grid: ``{label: (argv, output path)}``."""
    gj, table, key, value = files
    rfmap = [sys.executable, "-m", "rfmap.cli", "cartogram"]
    out = {}
    for method in args.methods:
        path = os.path.join(folder, f"{name}-{method}-{n}.geojson")
        out[f"rfmap {method}"] = ([*rfmap, gj, "--value", value, "--method", method, "--n", str(n), "--projected",
                                   "--max-passes", str(args.max_passes), "--out", path], path)
    if args.reference:
        ref = [os.path.abspath(args.reference), gj, table, "--id", key, "--area", value, "-n", str(n)]
        if name in WORLDS:
            ref.append("--world")
        stem = os.path.splitext(os.path.basename(gj))[0]
        out["cartogram-cpp"] = (ref, os.path.join(folder, f"{stem}_cartogram.geojson"))
    return out


def bench_map(args, name: str, files: tuple, n: int, folder: str) -> list[str]:
    """The table rows of one map at one grid size."""
    gj, table, key, value = files
    with open(table, encoding="utf-8") as fh:
        values = {row[key]: row[value] for row in csv.DictReader(fh)}
    rows, ref_time = [], None
    runs = commands(args, name, files, n, folder)
    for label, (cmd, path) in reversed(list(runs.items())):  # the reference first: its time is the ratio's base
        stats = []
        for _ in range(args.repeat):
            if os.path.exists(path):
                os.remove(path)
            stats.append(timed(cmd, folder))
        wall = statistics.median(s[0] for s in stats)
        rss = statistics.median(s[1] for s in stats)
        codes = sorted({s[2] for s in stats})
        if label == "cartogram-cpp":
            ref_time = wall
        ratio = f"{wall / ref_time:.2f}" if ref_time else "-"
        errors = area_errors(path, key, value, values)
        rows.append(f"| {name} | {n} | {label} | {wall:.2f} | {ratio} | {rss:.0f} | "
                    f"{','.join(map(str, codes))} | {errors} |")
        print(rows[-1], flush=True)
    return rows


HEAD = ("| map | N | program | wall [s] | × reference | peak RSS [MB] | exit | max error | mean error | "
        "minor max (count) | topology |\n|---|---:|---|---:|---:|---:|---|---:|---:|---:|---|")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reference", default=None, help="path to cartogram-cpp's cartogram binary")
    ap.add_argument("--maps", nargs="+", choices=MAPS + tuple(REAL), default=None,
                    help="maps to run (default: every synthetic and Natural Earth map, and with --sample-data the "
                         "real ones)")
    ap.add_argument("--sample-data", default=None, metavar="DIR",
                    help="cartogram-cpp's sample_data folder (its public repository): adds the real maps "
                         f"{', '.join(REAL)}")
    ap.add_argument("--n", type=int, nargs="+", default=[256, 512])
    ap.add_argument("--methods", nargs="+", choices=("flow", "diffusion"), default=["flow", "diffusion"])
    ap.add_argument("--repeat", type=int, default=3, help="runs per command (median)")
    ap.add_argument("--max-passes", type=int, default=60, help="rfmap's --max-passes")
    ap.add_argument("--workdir", default=None, help="folder for the inputs and outputs (default: a temporary one)")
    args = ap.parse_args(argv)
    # rfmap's modules byte-compiled, as pip leaves an installed package: an editable install run with
    # PYTHONDONTWRITEBYTECODE would otherwise compile them in every timed command
    import rfmap

    compileall.compile_dir(os.path.dirname(rfmap.__file__), quiet=1)
    folder = args.workdir or tempfile.mkdtemp(prefix="rfmap-cartogram-bench-")
    os.makedirs(folder, exist_ok=True)
    files = write_inputs(folder, args.sample_data)
    maps = args.maps or [*MAPS, *(REAL if args.sample_data else ())]
    if any(m in REAL for m in maps) and not args.sample_data:
        ap.error("the real maps need --sample-data DIR")
    load = os.getloadavg()
    print(f"machine: {os.cpu_count()} cores, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} at the start; "
          f"median of {args.repeat} whole commands (rfmap's modules byte-compiled first, as pip installs them); "
          "tolerance 1 %; errors over regions >= 0.01 % of the total\n")
    print(HEAD, flush=True)
    for name in maps:
        for n in args.n:
            bench_map(args, name, files[name], n, folder)
    load = os.getloadavg()
    print(f"\nload average at the end: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; outputs in {folder}")


if __name__ == "__main__":
    main()
