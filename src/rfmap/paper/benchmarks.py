r"""Classical, neural and hybrid maps side by side: the benchmark fields, time to accuracy and its summary (shared by
``benchmarks/hybrid.py`` and the book's chapters).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..hybrid import UNGUARDED

__all__ = ["METHODS", "ROWS", "WARM_MODELS", "compare_methods", "benchmark_fields", "time_to_accuracy", "summarize"]

#: The methods compared by :func:`compare_methods`.
METHODS = ("diffusion", "flow", "surrogate", "surrogate+refine", "hybrid")
#: The rows of :func:`compare_methods`, in order: the hybrid's run also gives the row of its warm flow alone
#: (:data:`rfmap.hybrid.UNGUARDED`; where the flow started cold, the hybrid's own row).
ROWS = METHODS[:-1] + (UNGUARDED, "hybrid")


def compare_methods(density: np.ndarray, surrogate=None, *, boundary: str = "square",
                    methods=METHODS) -> list[dict[str, Any]]:
    r"""Std(rho~_map), folds and wall time of every method on one density of the ``N``-grid, run one after another.

    Parameters
    ----------
    density : ndarray, shape (N,)*d
        Vertex densities (preprocessed, unit mass).
    surrogate : rfmap.Surrogate, optional
        The network for ``"surrogate"``, ``"surrogate+refine"`` and ``"hybrid"`` (those are skipped without one).
    boundary : {"square", "free"}
    methods : sequence of str
        Any of :data:`METHODS`.

    Returns
    -------
    list of dict
        One row per method: ``method``, ``std_rho_map``, ``n_flipped``, ``time`` (s, the result's own ``time``) and,
        for the hybrid, ``start`` (warm or cold) and ``kept`` (the map the guard kept); the hybrid's run adds the
        row :data:`rfmap.hybrid.UNGUARDED` before its own: its warm flow's map, timed without the guard's cold flow.
    """
    from ..solvers import solve_dem

    rows = []
    for method in methods:
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; choose from {METHODS}")
        if method in ("diffusion", "flow"):
            res = solve_dem(density, method=method, boundary=boundary)
        elif surrogate is None:
            continue
        else:
            n = density.shape[0]
            res = surrogate.map(density, n, preprocess=False, refine=method == "surrogate+refine",
                                polish=method == "hybrid")
        m = res.metrics()
        row = {"method": method, "std_rho_map": m.std_rho_map, "n_flipped": m.n_flipped, "time": res.time}
        if method == "hybrid":
            p = res.info["polish"]
            row.update(start=p["start"], kept=p["kept"])
            st = p["stages"]
            alone = dict(row, method=UNGUARDED, kept=p["start"])
            if "cold" in st:  # the warm flow's map, and the time without the guard's cold flow
                alone.update(std_rho_map=st["warm"]["std_rho_map"], n_flipped=st["warm"]["n_flipped"],
                             time=res.time - st["cold"]["time"], kept="warm")
            rows.append(alone)
        rows.append(row)
    return rows


#: The shipped surrogate that warm-starts each (dimension, boundary).
WARM_MODELS = {(2, "square"): "dem2d-square", (2, "free"): "deq2d-free", (3, "square"): "dem3d-cube",
               (3, "free"): "dem3d-free"}


def benchmark_fields(dim: int, n: int, *, paper: bool = True, random: int = 0) -> list[tuple[str, np.ndarray]]:
    """Labelled densities on the ``N``-grid: the paper's test fields and ``random`` unseen random fields (the
    ``report`` stream of :func:`rfmap.validation.validation_fields`), preprocessed as the paper does."""
    from ..inputs import preprocess_density
    from ..mesh import grid_points
    from ..paper_fields import TEST_FIELDS, sample_density
    from ..validation import validation_fields

    out = [(name, sample_density(name, n)) for name in TEST_FIELDS[("density", dim)]] if paper else []
    if random:
        pts = grid_points(n, dim)
        for j, f in enumerate(validation_fields("density", dim, random, stream="report")):
            out.append((f"random-{j}", preprocess_density(np.asarray(f.field(pts)).reshape((n,) * dim))))
    return out


def time_to_accuracy(dim: int, n: int, boundary: str = "square", *, paper: bool = True, random: int = 0,
                     methods=None, surrogate=None, warmup: bool = True) -> list[dict[str, Any]]:
    """:func:`compare_methods` on every field of :func:`benchmark_fields`; rows carry ``field``, ``dim``, ``n`` and
    ``boundary`` as well.  The surrogate defaults to the shipped model of :data:`WARM_MODELS`.

    ``warmup``: first run every method once on the first field, untimed, so that no method's time includes what
    only its first call in a process pays at a new grid size (transform plans, the network's trace, first-touch
    memory).
    """
    methods = METHODS if methods is None else methods
    if surrogate is None and set(methods) - {"diffusion", "flow"}:
        from ..surrogate import Surrogate

        surrogate = Surrogate.pretrained(WARM_MODELS[(dim, boundary)])
    rows = []
    fields = benchmark_fields(dim, n, paper=paper, random=random)
    if warmup and fields:
        compare_methods(fields[0][1], surrogate, boundary=boundary, methods=methods)
    for label, dens in fields:
        for row in compare_methods(dens, surrogate, boundary=boundary, methods=methods):
            rows.append({"field": label, "dim": dim, "n": n, "boundary": boundary, **row})
    return rows


def summarize(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (dim, n, boundary, method): mean Std(rho~_map), mean time, total folds, and the ratios to the best
    classical solver of the same case (the one with the lower mean Std; time ratio < 1 means faster)."""
    keys = sorted({(r["dim"], r["n"], r["boundary"]) for r in rows})
    out = []
    for key in keys:
        case = [r for r in rows if (r["dim"], r["n"], r["boundary"]) == key]
        agg = {}
        for method in [m for m in ROWS if any(r["method"] == m for r in case)]:
            rs = [r for r in case if r["method"] == method]
            agg[method] = {"std_rho_map": float(np.mean([r["std_rho_map"] for r in rs])),
                           "time": float(np.mean([r["time"] for r in rs])),
                           "n_flipped": int(sum(r["n_flipped"] for r in rs)), "fields": len(rs)}
        classical = [m for m in ("diffusion", "flow") if m in agg]
        best = min(classical, key=lambda m: agg[m]["std_rho_map"]) if classical else None
        for method, a in agg.items():
            row = {"dim": key[0], "n": key[1], "boundary": key[2], "method": method, **a, "best_classical": best}
            if best:
                row["std_ratio"] = a["std_rho_map"] / agg[best]["std_rho_map"]
                row["time_ratio"] = a["time"] / agg[best]["time"]
            out.append(row)
    return out
