"""Measure the package's tuned constants again (the book's page *Design decisions*).

Each case measures one decision of ``src/rfmap/data/design.json`` at a size that runs in well under a minute on
one thread, and prints a Markdown table of the chosen value against the alternatives (the page's columns *case*,
*chosen*, *alternative*).  With ``--record`` the rows, what they were measured on, the date, the commit and the
machine are stored in the decision's entry (:func:`rfmap.paper.design.record`); ``make pages`` (or ``python
scripts/make_design_md.py``) then regenerates the page.

The held-out fields are the validation stream's (``rfmap.training.validation``), never the paper's test fields,
except where a decision is about solver speed on the paper's test densities (``rfmap.fields.TEST_FIELDS``).

Usage::

    python benchmarks/design.py --list                       # the cases and their default sizes
    python benchmarks/design.py --only WALK_FILL              # one decision
    python benchmarks/design.py --only RTOL MARGIN --n 24     # two, at another grid side
    python benchmarks/design.py --record                      # every case, stored in design.json
"""
from __future__ import annotations

import argparse
import contextlib
import functools
import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from rfmap.fields import TEST_FIELDS, sample_density
from rfmap.paper.design import DESIGN_PATH, measured_on, record


@dataclass(frozen=True)
class Case:
    """One decision's measurement: ``measure(n, repeat, threads)`` returns the table rows; ``sizes`` says what the
    default grid sides are (``--n`` replaces them) and ``data(n, repeat, threads)`` what the rows were measured on."""

    measure: Callable[..., list[dict[str, str]]]
    sizes: str
    data: Callable[..., str]


def best_time(fn: Callable[[], object], repeat: int) -> tuple[float, object]:
    """The shortest wall time of ``repeat`` calls of ``fn`` and the result of the last call."""
    best, out = math.inf, None
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


@contextlib.contextmanager
def patched(obj, name: str, value):
    """``obj.name`` set to ``value`` inside the block."""
    old = getattr(obj, name)
    setattr(obj, name, value)
    try:
        yield
    finally:
        setattr(obj, name, old)


def _row(case: str, chosen: str, alternative: str = "") -> dict[str, str]:
    return {"case": case, "chosen": chosen, "alternative": alternative}


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.1f} ms" if seconds < 1 else f"{seconds:.2f} s"


# ------------------------------------------------------------------------------------------------ flow defaults
def _flow_default(option: str, boundary: str, dim: int, chosen: float, alternative: float, n: int,
                  repeat: int) -> list[dict[str, str]]:
    """Time and Std(rho~_map) of the flow solver with the chosen value of ``option`` and the alternative, per test
    density of dimension ``dim``, and how far apart the two maps are (largest vertex distance, in grid spacings)."""
    from rfmap.solvers.flow import solve_flow

    def run(density, **kw):
        results = [solve_flow(density, boundary=boundary, num_threads=1, **kw) for _ in range(max(1, repeat))]
        return min(results, key=lambda r: r.time)

    rows = []
    for name in TEST_FIELDS["density", dim]:
        density = sample_density(name, n)
        r0, r1 = run(density, **{option: chosen}), run(density, **{option: alternative})
        apart = float(np.linalg.norm(r0.mapped_points - r1.mapped_points, axis=1).max()) * (n - 1)
        rows.append(_row(f"{name}, {dim}D N = {n}, {boundary} boundary",
                         f"{option} = {chosen}: {r0.time:.2f} s, Std(ρ̃_map) {r0.metrics().std_rho_map:.4f}",
                         f"{option} = {alternative}: {r1.time:.2f} s, Std(ρ̃_map) {r1.metrics().std_rho_map:.4f}; "
                         f"maps at most {apart:.2g} grid spacings apart"))
    return rows


def rtol(n, repeat, threads):
    """The 3D default against 0.2 and the 2D default against 0.4 (square boundary)."""
    from rfmap.solvers.flow import RTOL

    return (_flow_default("rtol", "square", 3, RTOL[3], 0.2, n or 48, repeat)
            + _flow_default("rtol", "square", 2, RTOL[2], 0.4, 4 * (n or 64), repeat))


def margin(n, repeat, threads):
    """The 3D sea width against the diffusion solver's (free boundary)."""
    from rfmap.solvers.flow import MARGIN

    return _flow_default("margin", "free", 3, MARGIN[3], 0.5, n or 48, repeat)


# ------------------------------------------------------------------------------------------------ point location
def _box_points(mapped: np.ndarray, n: int, boundary: str) -> tuple[np.ndarray, int]:
    """A flow map's vertices in the flow's box (the unit cube, or the domain in its sea) and the raster side ``M``
    of that box, as ``solve_flow`` rasterizes the residual density (refine 2)."""
    from rfmap.solvers.flow import MARGIN

    d = mapped.shape[1]
    pad = 0 if boundary == "square" else max(1, int(round(MARGIN[d] * (n - 1))))
    scale = (n - 1 + 2 * pad) / (n - 1)
    return (mapped + pad / (n - 1)) / scale, 2 * (n - 1 + 2 * pad) + 1


def walk_fill(n, repeat, threads):
    """Locating the raster nodes in a flow map by the grid walk (the mesh fills at least WALK_FILL of its box) or by
    scanning every element, and whether both give the same raster."""
    from rfmap.core.geometry import grid_signed_measures
    from rfmap.solvers import locate
    from rfmap.solvers.flow import solve_flow

    n = n or 32
    rows = []
    for boundary in ("square", "free"):
        for name in TEST_FIELDS["density", 3]:
            res = solve_flow(sample_density(name, n), boundary=boundary, num_threads=1)
            y, m = _box_points(res.mapped_points, n, boundary)
            values = res.field / res.field.mean()
            span = y.max(0) - y.min(0)
            fill = float(grid_signed_measures(torch.from_numpy(y)[None], n).sum()) / float(np.prod(span))

            def locate_all():
                return locate.rasterize_elements(y, res.elements, values, m, 1.0, at="vertices")

            t_walk, walk = best_time(locate_all, repeat)
            with patched(locate, "WALK_FILL", math.inf):
                t_scan, scan = best_time(locate_all, repeat)
            diff = float(np.abs(walk - scan).max())
            rows.append(_row(f"{name}, 3D N = {n}, {boundary} boundary, M = {m} (fills {fill:.2f} of its box)",
                             f"walk: {_ms(t_walk)}" if fill >= locate.WALK_FILL else f"scan: {_ms(t_scan)}",
                             f"scan: {_ms(t_scan)}; rasters differ by at most {diff:.1e}"))
    return rows


# ------------------------------------------------------------------------------------------------ residual density
def residual_iterations(n, repeat, threads):
    """Std(rho~_map) of one flow pass started at the identity (its density is the vertex residual of the identity
    map, by ``k`` conjugate-gradient iterations) over that of the cold flow, per 2D test density."""
    from rfmap.solvers import flow
    from rfmap.solvers.residual import RESIDUAL_ITERATIONS, vertex_residual

    n = n or 65
    counts = sorted({0, 2, 5, RESIDUAL_ITERATIONS, 2 * RESIDUAL_ITERATIONS})
    rows = []
    for name in TEST_FIELDS["density", 2]:
        density = sample_density(name, n)
        cold = flow.solve_flow(density, num_threads=1)
        ratio = {}
        for k in counts:
            with patched(flow, "vertex_residual", functools.partial(vertex_residual, iterations=k)):
                warm = flow.solve_flow(density, start=cold.ref_points, num_threads=1)
            ratio[k] = warm.metrics().std_rho_map / cold.metrics().std_rho_map
        rows.append(_row(f"{name}, 2D N = {n}: warm / cold Std(ρ̃_map)",
                         f"{RESIDUAL_ITERATIONS} iterations: {ratio[RESIDUAL_ITERATIONS]:.4f}",
                         "; ".join(f"{k}: {ratio[k]:.4f}" for k in counts if k != RESIDUAL_ITERATIONS)))
    return rows


# ------------------------------------------------------------------------------------------------ weight refinement
def scan_points(n, repeat, threads):
    """Weight refinement of the 3D networks' maps of the held-out steep ramps, with the coarse scan of SCAN_POINTS
    points, other counts, and no scan: maps still folded, mean objective J and evaluations per map."""
    from rfmap import Surrogate
    from rfmap.finish import quiet_quality
    from rfmap.finish import refine as R
    from rfmap.training.validation import validation_fields

    n = n or 48
    chosen = R.SCAN_POINTS
    variants = [("no scan", None), *((f"{k} points", k) for k in sorted({5, chosen, 17}))]

    def no_scan(f, bounds, tol, s, js):
        return s, js

    rows = []
    for model in ("dem3d-cube", "dem3d-free"):
        sur = Surrogate.pretrained(model)
        ramps = [f for f in validation_fields("density", 3) if f.label.startswith("ramp")]
        out = {}
        for label, k in variants:
            folded, J, evals = 0, [], 0
            with quiet_quality(), patched(R, "_rescan", no_scan if k is None else R._rescan), \
                    patched(R, "SCAN_POINTS", k or chosen):
                t0 = time.perf_counter()
                for f in ramps:
                    r = sur.map(f.field, n, refine=True, repair=False)
                    folded += int(r.metrics().n_flipped > 0)
                    J.append(r.info["refine_objective"])
                    evals += r.info["refine_evaluations"]
                seconds = (time.perf_counter() - t0) / len(ramps)
            out[label] = (f"{label}: {folded} folded, mean J {np.mean(J):#.3g}, {evals / len(ramps):.0f} evaluations, "
                          f"{seconds:.1f} s per map")
        key = f"{chosen} points"
        rows.append(_row(f"{model}, the {len(ramps)} held-out steep ramps, 3D N = {n}", out[key],
                         "; ".join(v for k, v in out.items() if k != key)))
    return rows


# ------------------------------------------------------------------------------------------------ precision
def element_measures(n, repeat, threads):
    """The mapped element measures of a map (what ``density_quality`` computes) in float32 and in float64: time and
    the relative difference of the Std(rho~_map) they give."""
    from rfmap.core.geometry import grid_element_mean, grid_signed_measures
    from rfmap.core.metrics import density_std
    from rfmap.solvers.flow import solve_flow

    rows = []
    for d, side in ((3, n or 48), (2, 4 * (n or 64))):
        name = TEST_FIELDS["density", d][0]
        density = sample_density(name, side)
        mapped = solve_flow(density, num_threads=1).mapped_points
        pop = grid_element_mean(torch.from_numpy(density.reshape(1, -1)), side, d)[0]

        def measures(dtype):
            x = torch.from_numpy(np.ascontiguousarray(mapped, dtype=dtype))[None]
            return grid_signed_measures(x, side)[0].double()

        t32, m32 = best_time(lambda: measures(np.float32), max(3, repeat))
        t64, m64 = best_time(lambda: measures(np.float64), max(3, repeat))
        rel = abs(density_std(pop, m32) / density_std(pop, m64) - 1.0)
        rows.append(_row(f"flow map of {name}, {d}D N = {side} ({m32.numel():,} elements)",
                         f"float32: {_ms(t32)} (Std(ρ̃_map) within {rel:.0e} of float64's)", f"float64: {_ms(t64)}"))
    return rows


def _velocity_setup(n: int, dtype, dim: int = 3):
    """The flow solver's first velocity table of a test density of dimension ``dim`` (raster refine 2,
    ``M = 2 N - 1``) in ``dtype`` and the identity grid's vertices as query points (grid_sample order)."""
    from rfmap.core.mesh import grid_points
    from rfmap.solvers.raster import p1_upsample
    from rfmap.solvers.spectral import flow_planes

    raster = p1_upsample(sample_density(TEST_FIELDS["density", dim][0], n), 2)
    table = torch.from_numpy(flow_planes(raster, 0.0, dtype))[None]
    q = torch.from_numpy(grid_points(n, dim)).flip(-1).mul(2.0).sub(1.0)
    return table, q, raster.shape[0]


def _sample(table: torch.Tensor, q: torch.Tensor, entries: int) -> torch.Tensor:
    """grid_sample of the points ``q`` (P, d) in ``table`` split into ``entries`` batch entries over the same
    (expanded) table, as the flow solver's velocity does."""
    p, d = q.shape
    rows = -(-p // entries)
    q = torch.cat([q, q.new_zeros(rows * entries - p, d)]) if rows * entries != p else q
    q = q.to(table.dtype).reshape(entries, *([1] * (d - 1)), rows, d)
    f = torch.nn.functional.grid_sample(table.expand(entries, *table.shape[1:]), q, mode="bilinear",
                                        padding_mode="border", align_corners=True)
    return f.reshape(entries, d + 1, rows).permute(0, 2, 1).reshape(entries * rows, d + 1)[:p]


def velocity_table(n, repeat, threads):
    """One velocity evaluation of the 3D flow (every vertex of the N-grid in the table of the refined raster) with
    the table in float32 and in float64, one thread."""
    n = n or 48
    t32_table, q, m = _velocity_setup(n, np.float32)
    t64_table, _, _ = _velocity_setup(n, np.float64)
    t32, f32 = best_time(lambda: _sample(t32_table, q, 1), max(3, repeat))
    t64, f64 = best_time(lambda: _sample(t64_table, q, 1), max(3, repeat))
    rel = float(((f32.double() - f64).abs().max() / f64.abs().max()))
    return [_row(f"3D N = {n}, M = {m}: one evaluation at {len(q):,} points", f"float32: {_ms(t32)}",
                 f"float64: {_ms(t64)}; largest difference {rel:.0e} of the largest value")]


def lookup_engine(n, repeat, threads):
    """One velocity lookup of the 3D and the 2D flow (every vertex of the N-grid in the table of the refined raster)
    with the map solver's engine (torch ``grid_sample``, float32 table) and with the cartogram's (numpy
    :func:`rfmap.core.mesh.multilinear`, float32 table), one thread: whether the two solvers could share one lookup
    without torch."""
    from rfmap.core.mesh import multilinear

    rows = []
    for dim, side in ((3, n or 48), (2, 4 * (n or 64) + 1)):
        table, q, m = _velocity_setup(side, np.float32, dim)
        planes = table[0].numpy()  # (d + 1, M, ...) in grid_sample's axis order
        u = ((q.double().numpy() + 1.0) / 2.0 * (m - 1))[:, ::-1].copy()  # (P, d) index units, planes' axis order
        t_torch, f = best_time(lambda: _sample(table, q, 1), max(3, repeat))
        t_np, g = best_time(lambda: multilinear(planes, u.copy()), max(3, repeat))
        rel = float(np.abs(f.double().numpy() - g).max() / np.abs(g).max())
        apart = f"largest difference {rel:.0e} of the largest value" if rel else "the same values"
        rows.append(_row(f"{dim}D N = {side}, M = {m}: one lookup at {len(q):,} points",
                         f"grid_sample, float32: {_ms(t_torch)}",
                         f"numpy multilinear, float32: {_ms(t_np)} ({t_np / t_torch:.1f} times); {apart}"))
    return rows


def cartogram_tables(n, repeat, threads):
    """A flow cartogram of the world's countries with the passes' tables in float32 (``TABLE_DTYPE``) and in
    float64: the whole call's time (best of ``repeat``), its passes and its largest area error."""
    from rfmap.cartogram.resize import cartogram
    from rfmap.cartogram.regions import world_countries
    from rfmap.solvers import cartoflow

    n, regions, out = n or 256, world_countries(), []
    for dtype in (np.float32, np.float64):
        with patched(cartoflow, "TABLE_DTYPE", dtype):
            t, c = best_time(lambda: cartogram(regions, "pop_est", n=n, method="flow"), max(3, repeat))
        m = c.metrics()
        out.append(f"{np.dtype(dtype).name}: {t:.2f} s, {c.info['iterations']} passes, largest area error "
                   f"{m.max_error:.4f}, {'valid' if m.topology_ok else 'invalid'}")
    return [_row(f"world's countries by population, flow method, N = {n}", *out)]


def batch_per_thread(n, repeat, threads):
    """One velocity evaluation of the 3D flow on ``threads`` threads, the points split into one grid_sample batch
    entry per thread over the same table or left in one entry; and on one thread, where the rule gives one entry
    (the two settings coincide), to show what the extra threads cost or gain on the machine at hand."""
    n = n or 48
    table, q, m = _velocity_setup(n, np.float32)
    old = torch.get_num_threads()
    try:
        torch.set_num_threads(threads)
        t_split, _ = best_time(lambda: _sample(table, q, threads), max(5, repeat))
        t_one, _ = best_time(lambda: _sample(table, q, 1), max(5, repeat))
        torch.set_num_threads(1)
        t_single, _ = best_time(lambda: _sample(table, q, 1), max(5, repeat))
    finally:
        torch.set_num_threads(old)
    return [_row(f"3D N = {n}, M = {m}, {threads} threads: one evaluation at {len(q):,} points",
                 f"{threads} batch entries: {_ms(t_split)}", f"one batch entry: {_ms(t_one)}"),
            _row(f"3D N = {n}, M = {m}, 1 thread: one evaluation at {len(q):,} points",
                 f"1 batch entry: {_ms(t_single)}", "the same single entry")]


# ------------------------------------------------------------------------------------------------ symmetrization
def batch_points(n, repeat, threads):
    """The 8 symmetric copies of deq2d-square's input evaluated stacked into batches of at most BATCH_POINTS grid
    points or one after another, one thread.  The settings are timed in turn, round after round, and each one's
    median counts: on a loaded machine a best-of-n taken one setting after another lets the load of the moment
    pick the winner."""
    from rfmap import Surrogate
    from rfmap.nn.symmetry import BATCH_POINTS, symmetrized_displacement

    sur = Surrogate.pretrained("deq2d-square")
    rows = []
    for side in ([n] if n else [51, 64, 96, 128, 256]):
        grids = sample_density("sin-cos", side)[None].astype(np.float32)
        grids = grids / grids.mean()
        stacked = max(1, min(8, BATCH_POINTS // side**2))
        settings = {"chosen": BATCH_POINTS}
        if stacked > 1:  # one copy per batch is the chosen rule itself
            settings["one after another"] = 1
        if stacked < 8:
            settings["all 8 in one batch"] = 8 * side**2
        for points in settings.values():  # the first call of a shape pays for tracing
            symmetrized_displacement(sur.displacement, grids, "full", batch_points=points)
        times = {k: [] for k in settings}
        for _ in range(max(5, repeat)):
            for k, points in settings.items():
                t0 = time.perf_counter()
                symmetrized_displacement(sur.displacement, grids, "full", batch_points=points)
                times[k].append(time.perf_counter() - t0)
        med = {k: float(np.median(v)) for k, v in times.items()}
        rows.append(_row(f"2D N = {side} ({stacked} cop{'y' if stacked == 1 else 'ies'} per batch)",
                         _ms(med["chosen"]), "; ".join(f"{k} {_ms(med[k])}" for k in settings if k != "chosen")))
    return rows


def default_symmetry(n, repeat, threads):
    """Mean Std(rho~_map) of the raw network maps over the held-out validation fields (in 3D the smooth, step and peak
    fields) with each set of symmetries, and (3D) how many raw maps of the steep ramps fold."""
    from rfmap import Surrogate
    from rfmap.finish import quiet_quality
    from rfmap.nn.symmetry import DEFAULT_SYMMETRY
    from rfmap.training.validation import validation_fields

    names = {"none": "plain", "permutations": "axis orders (`permutations`)", "cyclic": "cyclic orders (`cyclic`)",
             "flips": "reflections (`flips`)", "full": "all symmetries (`full`)"}
    rows = []
    for model, d, side, groups in (("deq2d-square", 2, n or 51, ("none", "permutations", "flips", "full")),
                                   ("dem3d-cube", 3, n or 32, ("none", "cyclic", "permutations", "flips"))):
        sur = Surrogate.pretrained(model)
        fields = validation_fields("density", d)
        mean, ramps_folded = {}, {}
        with quiet_quality():
            for g in groups:
                std, folded = [], 0
                for f in fields:
                    m = sur.map(f.field, side, repair=False, symmetrize=False if g == "none" else g).metrics()
                    if d == 3 and f.label.startswith("ramp"):
                        folded += int(m.n_flipped > 0)
                    else:
                        std.append(m.std_rho_map)
                mean[g], ramps_folded[g] = float(np.mean(std)), folded
        chosen = DEFAULT_SYMMETRY[d]
        which = "the 16 fields" if d == 2 else "smooth, step and peak fields"
        rows.append(_row(f"{model}, {d}D N = {side}, mean Std(ρ̃_map) of {which}",
                         f"{names[chosen]}: {mean[chosen]:.4f}",
                         "; ".join(f"{names[g]} {mean[g]:.4f}" for g in groups if g != chosen)))
        if d == 3:
            rows.append(_row(f"{model}, {d}D N = {side}, raw maps of the 4 steep ramps folded",
                             f"{names[chosen]}: {ramps_folded[chosen]}",
                             "; ".join(f"{names[g]} {ramps_folded[g]}" for g in groups if g != chosen)))
    return rows


# ------------------------------------------------------------------------------------------------ memory
#: the pipelines whose peak memory sets BYTES_PER_VERTEX: name, dimension, default grid side and the code that maps
#: one field (run in a fresh process; ``n`` is the grid side)
MEMORY_CASES = [
    ("2D Linear Beltrami Solver", 2, 512,
     "from rfmap.solvers import solve_lbs; from rfmap.fields import sample_mu, TEST_FIELDS\n"
     "run = lambda: solve_lbs(sample_mu(TEST_FIELDS['beltrami', 2][0], n), n)"),
    ("2D diffusion DEM", 2, 512,
     "from rfmap.solvers import solve_dem\nrun = lambda: solve_dem(sample_density('sin-cos', n))"),
    ("2D surrogate map (deq2d-square)", 2, 512,
     "from rfmap import Surrogate\nsur = Surrogate.pretrained('deq2d-square')\n"
     "run = lambda: sur.map(sample_density('sin-cos', n))"),
    ("3D surrogate map with refinement (dem3d-cube)", 3, 64,
     "from rfmap import Surrogate\nsur = Surrogate.pretrained('dem3d-cube')\n"
     "run = lambda: sur.map(sample_density('sin-cos-3d', n), refine=True)"),
    ("3D diffusion DEM", 3, 48,
     "from rfmap.solvers import solve_dem\nrun = lambda: solve_dem(sample_density('sin-cos-3d', n))"),
]

#: the peak resident size of the process so far (VmHWM; not ru_maxrss, which a child inherits from its parent)
_MEMORY_PROBE = """
import sys
import torch
torch.set_num_threads(1)
from rfmap.fields import sample_density

def peak():
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmHWM:"))

n = int(sys.argv[1])
{setup}
base = peak()
run()
print(peak() - base)
"""


def bytes_per_vertex(n, repeat, threads):
    """Peak resident memory of each pipeline (from sampling the field to the map) above that of its process before
    (package imported, model loaded), per grid vertex, in a fresh process each; BYTES_PER_VERTEX is meant to be
    about twice the largest."""
    from rfmap.core.mesh import BYTES_PER_VERTEX

    rows = []
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    for label, d, default, setup in MEMORY_CASES:
        side = n or default
        out = subprocess.run([sys.executable, "-c", _MEMORY_PROBE.format(setup=setup), str(side)], env=env,
                             capture_output=True, text=True, check=True)
        per_vertex = max(1, int(out.stdout.split()[-1])) / side**d
        rows.append(_row(f"{label}, N = {side}", f"{per_vertex / 1024:.2f} KiB per vertex",
                         f"{BYTES_PER_VERTEX[d] / 1024:g} KiB assumed in {d}D: "
                         f"{BYTES_PER_VERTEX[d] / per_vertex:.1f} times the peak"))
    return rows


# ------------------------------------------------------------------------------------------------ FNO size
def fno_size(n, repeat, threads):
    """Real parameter count and one forward and backward pass (batch 4, one thread) of the FNO of fno-deq2d-square
    beside the U-Net of deq2d-square."""
    from rfmap.core.mesh import grid_points
    from rfmap.nn.registry import build_model
    from rfmap.tasks.base import encode
    from rfmap.training.config import get_config

    side = n or 80
    out = {}
    for name in ("fno-deq2d-square", "deq2d-square"):
        cfg = get_config(name, "full")
        torch.manual_seed(0)
        net = build_model(cfg.model.kwargs(cfg.task.dim, cfg.task.n_params))
        params = sum(p.numel() * (2 if p.is_complex() else 1) for p in net.parameters())
        pts = torch.as_tensor(grid_points(side, 2), dtype=torch.float32).expand(4, -1, -1)
        rho = torch.as_tensor(np.stack([sample_density(f, side).reshape(-1) for f in TEST_FIELDS["density", 2]]),
                              dtype=torch.float32)
        x = encode(pts, rho, cfg.task, side)

        def step():
            net.zero_grad()
            net(x).square().mean().backward()

        step()
        out[name] = (params, best_time(step, max(3, repeat))[0])
    (p_f, t_f), (p_u, t_u) = out["fno-deq2d-square"], out["deq2d-square"]
    return [_row("real parameters", f"{p_f / 1e6:.2f} M", f"U-Net: {p_u / 1e6:.2f} M"),
            _row(f"forward and backward pass, batch 4, 2D N = {side}, one thread", _ms(t_f), f"U-Net: {_ms(t_u)}")]


# ------------------------------------------------------------------------------------------------ the cases
#: decision (its ``remeasure`` key in design.json) -> how it is measured
CASES: dict[str, Case] = {
    "RTOL": Case(rtol, "3D N = 48, 2D N = 256", lambda n, r, t: f"the paper's four 3D test densities at N = "
                 f"{n or 48} and four 2D ones at N = {4 * (n or 64)}, square boundary, best of {r} runs"),
    "MARGIN": Case(margin, "3D N = 48", lambda n, r, t: f"the paper's four 3D test densities at N = {n or 48}, free "
                   f"boundary, best of {r} runs"),
    "WALK_FILL": Case(walk_fill, "3D N = 32", lambda n, r, t: f"the flow maps of the paper's four 3D test densities "
                      f"at N = {n or 32}, square and free boundary, best of {r} runs"),
    "RESIDUAL_ITERATIONS": Case(residual_iterations, "2D N = 65", lambda n, r, t: f"the paper's four 2D test densities "
                                f"at N = {n or 65}, square boundary, one flow pass"),
    "SCAN_POINTS": Case(scan_points, "3D N = 48", lambda n, r, t: f"the 4 steep ramps of the held-out validation "
                        f"fields at N = {n or 48}, dem3d-cube and dem3d-free, refine=True, repair=False"),
    "element-measures-float32": Case(element_measures, "3D N = 48, 2D N = 256", lambda n, r, t: "the flow maps of "
                                     f"sin-cos-3d at N = {n or 48} and sin-cos at N = {4 * (n or 64)}, best of "
                                     f"{max(3, r)}"),
    "velocity-table-float32": Case(velocity_table, "3D N = 48", lambda n, r, t: f"the flow's first velocity table of "
                                   f"sin-cos-3d at N = {n or 48} (M = {2 * (n or 48) - 1}), best of {max(3, r)}"),
    "flow-lookup-engine": Case(lookup_engine, "3D N = 48, 2D N = 257", lambda n, r, t: "the flow's first velocity "
                               f"tables of sin-cos-3d at N = {n or 48} and sin-cos at N = {4 * (n or 64) + 1}, one "
                               f"thread, best of {max(3, r)}"),
    "cartogram-tables-float32": Case(cartogram_tables, "N = 256", lambda n, r, t: "the Natural Earth countries by "
                                     f"population (rfmap.cartogram.regions.world_countries), N = {n or 256}, one "
                                     f"thread, best of {max(3, r)}"),
    "grid-sample-per-thread": Case(batch_per_thread, "3D N = 48", lambda n, r, t: "the table and points of "
                                   f"the section on the velocity table's precision, {t} threads and one thread, "
                                   f"best of {max(5, r)}"),
    "BATCH_POINTS": Case(batch_points, "2D N = 51 to 256", lambda n, r, t: "deq2d-square, the 8 symmetries of "
                         f"sin-cos at {'N = 51, 64, 96, 128 and 256' if n is None else f'N = {n}'}, one thread, "
                         f"median of {max(5, r)} rounds, the settings timed in turn"),
    "DEFAULT_SYMMETRY": Case(default_symmetry, "2D N = 51, 3D N = 32", lambda n, r, t: "the 16 held-out validation "
                             f"fields: deq2d-square at N = {n or 51}, dem3d-cube at N = {n or 32}; raw maps"),
    "BYTES_PER_VERTEX": Case(bytes_per_vertex, "2D N = 512, 3D N = 48 and 64", lambda n, r, t: "the paper's first "
                             "test field of each kind at "
                             f"{'2D N = 512, 3D N = 64 (surrogate) and 48 (DEM)' if n is None else f'N = {n}'}, "
                             "one fresh process per pipeline, one thread"),
    "fno-size": Case(fno_size, "2D N = 80", lambda n, r, t: f"one forward and backward pass at batch 4 (the paper's "
                     f"four 2D test densities), N = {n or 80}, one thread, best of {max(3, r)}"),
}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=sorted(CASES), metavar="NAME",
                        help=f"measure these decisions only (of {', '.join(CASES)})")
    parser.add_argument("--n", type=int, default=None, help="grid side of every case (default: each case's own)")
    parser.add_argument("--repeat", type=int, default=3, help="runs per timing; the best counts")
    parser.add_argument("--threads", type=int, default=2, help="threads of grid-sample-per-thread")
    parser.add_argument("--list", action="store_true", help="list the cases and their default sizes")
    parser.add_argument("--record", action="store_true", help="store the rows in src/rfmap/data/design.json")
    parser.add_argument("--out", default=str(DESIGN_PATH), help="the design record to update with --record")
    args = parser.parse_args(argv)
    if args.list:
        for name, case in CASES.items():
            print(f"{name:26s} {case.sizes}")
        return
    torch.set_num_threads(1)
    for name in args.only or list(CASES):
        case = CASES[name]
        t0 = time.perf_counter()
        rows = case.measure(args.n, args.repeat, args.threads)
        seconds = time.perf_counter() - t0
        print(f"\n### {name}\n\n| case | chosen | alternative |\n|---|---|---|")
        for r in rows:
            print(f"| {r['case']} | {r['chosen']} | {r['alternative']} |")
        print(f"\n({seconds:.0f} s)")
        if args.record:
            threads = args.threads if name == "grid-sample-per-thread" else 1
            record(name, path=Path(args.out), results=rows, data=case.data(args.n, args.repeat, args.threads),
                   measured=measured_on(threads, seconds))


if __name__ == "__main__":
    main()
