r"""Classical, neural and hybrid maps side by side: the benchmark fields, time to accuracy and its summary, as
the book's chapter "11 Fast classical maps and neural warm starts" runs them (the source repository's script
``benchmarks/hybrid.py`` runs the same functions).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.inputs import preprocess_density
from ..core.wording import counted, of_count
from ..core.mesh import grid_points
from ..fields.paper import TEST_FIELDS, sample_density
from ..finish.polish import UNGUARDED
from ..solvers import solve_dem
from ..surrogate import Surrogate
from ..training.validation import DENSITY_KINDS, validation_fields
from .comparison import format_time
from .tables import Table, format_value, headline

__all__ = ["METHODS", "ROWS", "WARM_MODELS", "STD_TOL", "FLOW_TIME", "HYBRID_TIME", "compare_methods",
           "benchmark_fields", "time_to_accuracy", "summarize", "target_checks", "targets_headline", "summary_table",
           "targets_table", "method_tables", "time_ratio_table", "CaseTable", "hybrid_findings", "refinement_fields"]

#: The methods compared by :func:`compare_methods`.
METHODS = ("diffusion", "flow", "surrogate", "surrogate+refine", "hybrid")
#: The rows of :func:`compare_methods`, in order: the hybrid's run also gives the row of its warm flow alone,
#: without the guard (:data:`rfmap.finish.polish.UNGUARDED`, ``"hybrid (no guard)"``; where the flow started cold,
#: the hybrid's own row).
ROWS = METHODS[:-1] + (UNGUARDED, "hybrid")

#: "As accurate": a final Std(ρ̃_map) at most this factor above the reference solver's.
STD_TOL = 1.1
#: The flow-based solver's target: at most this fraction of the diffusion solver's time.
FLOW_TIME = 0.2
#: The hybrid's target: at most this fraction of the best classical solver's time.
HYBRID_TIME = 0.5


def compare_methods(density: np.ndarray, surrogate=None, *, boundary: str = "square",
                    methods=METHODS) -> list[dict[str, Any]]:
    r"""Std(ρ̃_map), folds and wall time of every method on one density of the ``N``-grid, run one after another.

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
        One row per method: ``method``, ``std_rho_map``, ``n_flipped``, ``time`` (s, the result's own ``time``); for
        the surrogate's two rows ``coarser`` (the network's map folded, and a fold-free map from a coarser working
        grid was taken, :func:`rfmap.finish.stages.regrid`) and ``work_n`` (the side of the grid the returned map's
        network ran on); for the hybrid, ``start`` (warm or cold) and ``kept`` (the map the guard kept); the hybrid's run adds the
        row ``"hybrid (no guard)"`` (:data:`rfmap.finish.polish.UNGUARDED`) before its own: its warm flow's map
        alone, as the hybrid would return it without the guard (the cold flow from the identity that it also runs,
        keeping the better map), timed without that cold flow.
    """
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
        if method in ("surrogate", "surrogate+refine"):  # the network's map folded; one from a coarser grid taken
            row["coarser"] = (res.info.get("regrid") or {}).get("work_n") is not None
            row["work_n"] = int(res.info["work_n"])
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
    """Labelled densities on the ``N``-grid: the paper's test fields and a number ``random`` of unseen random fields
    (the report stream of :func:`rfmap.training.validation.validation_fields`: fields drawn from a seed of their
    own, never drawn in training or used to choose a model), preprocessed as the paper does."""
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
    """Per (dim, n, boundary, method): mean Std(ρ̃_map), mean time, total folds, and the ratios to the best
    classical solver of the same case (the one with the lower mean Std; time ratio < 1 means faster).  The cases
    keep the order in which ``rows`` first give them (the order they were run in)."""
    keys = list(dict.fromkeys((r["dim"], r["n"], r["boundary"]) for r in rows))
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


def _pick(summary, case, method):
    return next(r for r in summary if (r["dim"], r["n"], r["boundary"], r["method"]) == (*case, method))


def target_checks(summary: list[dict[str, Any]], cases) -> list[dict[str, Any]]:
    r"""The speed and accuracy targets per case, from the rows of :func:`summarize`.

    The flow-based solver meets its target when its mean time is at most :data:`FLOW_TIME` times the diffusion
    solver's and its mean :math:`\mathrm{Std}(\tilde\rho_{map})` at most :data:`STD_TOL` times the diffusion
    solver's; the hybrid when it is within :data:`HYBRID_TIME` and :data:`STD_TOL` of the best classical solver.

    Parameters
    ----------
    summary : list of dict
        Rows of :func:`summarize` (with the methods ``diffusion``, ``flow`` and ``hybrid``).
    cases : sequence of (dim, n, boundary)

    Returns
    -------
    list of dict
        One row per case: ``case`` (a label), ``dim``, ``n``, ``boundary``, ``flow_time`` and ``flow_std`` (flow
        over diffusion), ``hybrid_time`` and ``hybrid_std`` (hybrid over the best classical solver),
        ``hybrid_vs_flow`` (the hybrid's time over the flow's, which no target bounds), ``best_classical``,
        ``flow_met`` and ``hybrid_met``.
    """
    out = []
    for case in cases:
        flow, diff, hyb = (_pick(summary, tuple(case), m) for m in ("flow", "diffusion", "hybrid"))
        row = {"case": f"{case[0]}D N = {case[1]} {case[2]}", "dim": case[0], "n": case[1], "boundary": case[2],
               "flow_time": flow["time"] / diff["time"], "flow_std": flow["std_rho_map"] / diff["std_rho_map"],
               "hybrid_time": hyb["time_ratio"], "hybrid_std": hyb["std_ratio"],
               "hybrid_vs_flow": hyb["time"] / flow["time"], "best_classical": hyb["best_classical"]}
        row["flow_met"] = bool(row["flow_time"] <= FLOW_TIME and row["flow_std"] <= STD_TOL)
        row["hybrid_met"] = bool(row["hybrid_time"] <= HYBRID_TIME and row["hybrid_std"] <= STD_TOL)
        out.append(row)
    return out


def targets_headline(checks: list[dict[str, Any]]):
    """The targets at a glance: a :class:`~rfmap.paper.tables.Headline` with one row per case and criterion (the
    measured ratio, its target and whether it is met), from the rows of :func:`target_checks`."""
    criteria = (("flow_time", "flow time / diffusion", FLOW_TIME), ("flow_std", "flow Std / diffusion", STD_TOL),
                ("hybrid_time", "hybrid time / best classical", HYBRID_TIME),
                ("hybrid_std", "hybrid Std / best classical", STD_TOL))
    ours, target = {}, {}
    for c in checks:
        for key, name, limit in criteria:
            ours[f"{c['case']}: {name}"] = c[key]
            target[f"{c['case']}: {name}"] = limit
    return headline("The speed and accuracy targets", "Ratios of the means over each case's fields (target: at most)",
                    ours, target, labels={"ours": "measured", "paper": "target"})


@dataclass
class CaseTable:
    """A Markdown table with its title, shown as a cell's value (``_repr_markdown_``)."""

    title: str
    text: str

    def _repr_markdown_(self) -> str:
        return f"**{self.title}**\n\n{self.text}"


def _case_label(dim: int, n: int, boundary: str) -> str:
    return f"{dim}D, N = {n}, {boundary}"


def _refine_worse_text(worse: int, fields: int, coarser: int) -> str:
    """The sentence on the fields where weight refinement raised the Std, and on how many of them the default map
    came from a coarser working grid (the network's own map folded)."""
    text = f"Field by field, refinement raised the Std on {of_count(worse, fields, 'field')}"
    if worse == 0:
        return text + "."
    those = "that one" if worse == 1 else "both" if worse == 2 else f"all {worse}"
    if coarser == worse:
        return text + f"; on {those} the network's own map folded and the default map came from a coarser grid."
    if coarser == 0:
        return text + "; the network's own map folded on none of them."
    return text + f"; on {coarser} of them the network's own map folded and the default map came from a coarser grid."


def targets_table(checks: list[dict[str, Any]]) -> CaseTable:
    """The targets of :func:`target_checks` in one row per case: each measured ratio (three significant digits,
    trailing zeros kept) with whether it meets its target (the target in the column's head), and the hybrid's time
    over the flow solver's, which has no target."""
    cols = (("flow_time", f"flow time / diffusion (≤ {FLOW_TIME:g})", FLOW_TIME),
            ("flow_std", f"flow Std / diffusion (≤ {STD_TOL:g})", STD_TOL),
            ("hybrid_time", f"hybrid time / best classical (≤ {HYBRID_TIME:g})", HYBRID_TIME),
            ("hybrid_std", f"hybrid Std / best classical (≤ {STD_TOL:g})", STD_TOL),
            ("hybrid_vs_flow", "hybrid time / flow", None))
    lines = ["| case | " + " | ".join(c[1] for c in cols) + " |", "|---|" + "---|" * len(cols)]
    for c in checks:
        cells = []
        for key, _, limit in cols:
            text = _ratio_text(c[key])
            if limit is not None:
                text += " (met)" if c[key] <= limit else " (missed)"
            cells.append(text)
        lines.append(f"| {_case_label(c['dim'], c['n'], c['boundary'])} | " + " | ".join(cells) + " |")
    return CaseTable("The project's speed and accuracy targets (not the paper's)", "\n".join(lines))


def method_tables(summary: list[dict[str, Any]]) -> tuple[CaseTable, CaseTable]:
    """The rows of :func:`summarize` as two tables with one row per case and one column per method: the mean
    Std(ρ̃_map) over the case's fields, and the mean time."""
    cases = list(dict.fromkeys((r["dim"], r["n"], r["boundary"]) for r in summary))
    methods = [m for m in ROWS if any(r["method"] == m for r in summary)]
    by = {(r["dim"], r["n"], r["boundary"], r["method"]): r for r in summary}
    out = []
    for key, title in (("std_rho_map", "Mean Std(ρ̃_map) over each case's fields"),
                       ("time", "Mean time over each case's fields")):
        lines = ["| case | " + " | ".join(methods) + " |", "|---|" + "---|" * len(methods)]
        for case in cases:
            cells = [format_value(by[(*case, m)][key], key) if (*case, m) in by else "—" for m in methods]
            lines.append(f"| {_case_label(*case)} | " + " | ".join(cells) + " |")
        out.append(CaseTable(title, "\n".join(lines)))
    return out[0], out[1]


def time_ratio_table(rows: list[dict[str, Any]], case: tuple, methods=("surrogate", "surrogate+refine")) -> CaseTable:
    """Each field's time of ``methods`` over the flow solver's on one case ``(dim, n, boundary)`` of the rows of
    :func:`time_to_accuracy`, one row per field, with the median over the fields in the last row and, where the
    network's own map folded and the default map came from a coarser grid, a mark on the field."""
    by = {(r["field"], r["method"]): r for r in rows if (r["dim"], r["n"], r["boundary"]) == tuple(case)}
    fields = [f for f, m in by if m == "flow"]
    methods = [m for m in methods if any((f, m) in by for f in fields)]
    ratio = {(f, m): by[f, m]["time"] / by[f, "flow"]["time"] for f in fields for m in methods if (f, m) in by}
    lines = ["| field | " + " | ".join(f"{m} / flow" for m in methods) + " |", "|---|" + "---|" * len(methods)]
    for f in fields:
        mark = " (coarser grid)" if any(by.get((f, m), {}).get("coarser") for m in methods) else ""
        lines.append(f"| {f}{mark} | " + " | ".join(
            _ratio_text(ratio[f, m]) if (f, m) in ratio else "—" for m in methods) + " |")
    meds = [_ratio_text(float(np.median([v for (f, m2), v in ratio.items() if m2 == m]))) for m in methods]
    lines.append("| median | " + " | ".join(meds) + " |")
    return CaseTable(f"Time over the flow solver's, field by field, {_case_label(*case)}", "\n".join(lines))


def summary_table(summary: list[dict[str, Any]]):
    """The rows of :func:`summarize` as a :class:`~rfmap.paper.tables.Table`: one case per dimension, grid side
    and boundary, one row per method, with the mean Std(ρ̃_map), the mean time, the folds and the ratios to the
    case's best classical solver."""
    table = Table("tab:time_to_accuracy", "Time to accuracy: means over each case's fields",
                  ["std_rho_map", "time", "n_flipped", "std_ratio", "time_ratio"])
    for r in summary:
        table.add(f"{r['dim']}D N = {r['n']} {r['boundary']}", r["method"],
                  {k: r.get(k) for k in table.columns})
    return table


def _ratio_text(v: float) -> str:
    """A ratio to three significant digits, trailing zeros kept (``"1.00"``, never a bare ``"1"``)."""
    text = f"{v:#.3g}"
    if "e" in text or not np.isfinite(v):
        return f"{v:.3g}"
    return text.rstrip(".")


def _refine_effect(before: float, after: float) -> str:
    """What weight refinement does to the surrogate's Std, as the text says it."""
    a, b = _ratio_text(before), _ratio_text(after)
    if a == b:
        return f"leaves it at {a} (to three digits)"
    if after < before:
        return f"lowers it from {a} to {b}"
    return f"raises it from {a} to {b}"


#: the rows of each quoted case that the text sets against the flow solver, and the prefix of their keys
_AGAINST_FLOW = (("surrogate", "sur"), ("surrogate+refine", "ref"), ("hybrid", "hyb"), (UNGUARDED, "ng"))


def hybrid_findings(rows: list[dict[str, Any]], targets: dict) -> dict[str, Any]:
    """The numbers that the book's text quotes from a time-to-accuracy run (the chapter on fast classical maps and
    neural warm starts): counts, ratios and times, each formatted as the text prints it (ratios to three significant
    digits, times with their unit).

    Parameters
    ----------
    rows : list of dict
        Rows of :func:`time_to_accuracy`.
    targets : dict
        ``dim -> (dim, n, boundary)``: the case whose numbers the text quotes for each dimension.

    Returns
    -------
    dict
        These entries:

        * ``n_methods`` and ``method_names``: the methods run (the tables add the row
          :data:`rfmap.finish.polish.UNGUARDED`);
        * ``flow_hybrid_flips``: the folds of the flow and the hybrid, and ``flow_hybrid_flips_text``, the sentence
          on them;
        * the guard's counts: ``guard_fields`` (hybrid runs), ``guard_warm`` (warm starts, after which the guard ran
          the cold flow), ``guard_cold`` (runs that kept the cold flow's map) and ``guard_worse`` (runs that ended
          above the flow alone);
        * ``warm_vs_cold``: the warm flow's final Std over the cold flow's, mean over the warm starts;
        * ``flow_rough_field`` and ``flow_rough_ratio``: the field on which the flow ends furthest above the
          diffusion solver in the first quoted case, and that ratio;
        * per quoted dimension ``d``: ``n{d}``; ``flow_speed{d}`` and ``flow_std{d}`` (the diffusion solver's time
          over the flow's, the flow's Std over diffusion's); ``flow_wall{d}`` (the flow's mean time, with its unit)
          and ``flow_abs{d}`` (its mean Std);
        * per quoted dimension ``d`` and method tag, for the surrogate (``sur``), the surrogate with weight
          refinement (``ref``), the hybrid (``hyb``) and its warm flow without the guard (``ng``):
          ``<tag>_vs_flow{d}`` (mean time over the flow's) and ``<tag>_abs{d}`` (mean Std; absent for a method that
          was not run); also ``sur_std_vs_flow{d}`` (the surrogate's Std over the flow's);
        * ``hyb_time{d}`` and ``hyb_std{d}``: the hybrid against the best classical solver;
        * ``ref_effect{d}``: what weight refinement does to the surrogate's Std, as a phrase;
        * ``ref_worse_cases``: the cases, of those run with refinement, in which refinement raised the Std
          (``"2 of 8 cases"``); ``ref_worse_fields``: the fields on which it raised the Std, of those mapped both
          ways; ``ref_worse_coarser``: how many of those (an int) had a default map taken from a coarser working
          grid, because the network's own map folded; ``ref_worse_text``: the sentence that says both;
        * the hybrid's mean time over the flow's in every case of the time table (not only the quoted ones):
          ``hyb_flow_range`` (``"from 3.32 to 3.88"``), ``hyb_std_range`` (the hybrid's mean Std over the best
          classical solver's, over the same cases), ``hyb_slower_cases`` (the cases where the hybrid took longer,
          ``"all 8 cases"``), ``hyb_cost_text`` (the clause that says both) and ``hyb_verdict`` (``"does not pay"``
          where the hybrid took longer in every case, ``"pays"`` where in none, else ``"pays only in some cases"``).
    """
    summary = summarize(rows)
    methods = [m for m in dict.fromkeys(r["method"] for r in rows) if m != UNGUARDED]
    names = {"surrogate+refine": "surrogate with weight refinement"}
    by = {(r["dim"], r["n"], r["boundary"], r["field"], r["method"]): r for r in rows}
    hybrids = [r for r in rows if r["method"] == "hybrid"]
    warm = [r for r in hybrids if r["start"] == "warm"]
    worse = [r for r in hybrids
             if r["std_rho_map"] > by[r["dim"], r["n"], r["boundary"], r["field"], "flow"]["std_rho_map"] * (1 + 1e-9)]
    out = {"n_methods": len(methods), "method_names": ", ".join(names.get(m, m) for m in methods),
           "flow_hybrid_flips": sum(r["n_flipped"] for r in summary if r["method"] in ("flow", "hybrid", UNGUARDED)),
           "guard_fields": len(hybrids), "guard_warm": len(warm),
           "guard_cold": sum(r["kept"] == "cold" for r in warm), "guard_worse": len(worse)}
    for d, case in targets.items():
        flow, diff, hyb, sur = (_pick(summary, tuple(case), m) for m in ("flow", "diffusion", "hybrid", "surrogate"))
        out.update({f"n{d}": case[1],
                    f"flow_speed{d}": _ratio_text(diff["time"] / flow["time"]),
                    f"flow_std{d}": _ratio_text(flow["std_rho_map"] / diff["std_rho_map"]),
                    f"flow_wall{d}": format_time(flow["time"]), f"flow_abs{d}": _ratio_text(flow["std_rho_map"]),
                    f"sur_std_vs_flow{d}": _ratio_text(sur["std_rho_map"] / flow["std_rho_map"]),
                    f"hyb_time{d}": _ratio_text(hyb["time_ratio"]), f"hyb_std{d}": _ratio_text(hyb["std_ratio"])})
        for method, tag in _AGAINST_FLOW:
            r = next((r for r in summary if (r["dim"], r["n"], r["boundary"], r["method"]) == (*case, method)), None)
            if r is None:  # a method that was not run
                continue
            out[f"{tag}_vs_flow{d}"] = _ratio_text(r["time"] / flow["time"])
            out[f"{tag}_abs{d}"] = _ratio_text(r["std_rho_map"])
    ratios = [by[r["dim"], r["n"], r["boundary"], r["field"], UNGUARDED]["std_rho_map"]
              / by[r["dim"], r["n"], r["boundary"], r["field"], "flow"]["std_rho_map"] for r in warm]
    out["warm_vs_cold"] = _ratio_text(float(np.mean(ratios)) if ratios else float("nan"))
    # weight refinement against the default map, in every case where both ran
    pairs = [(_pick(summary, c, "surrogate"), _pick(summary, c, "surrogate+refine"))
             for c in dict.fromkeys((r["dim"], r["n"], r["boundary"]) for r in summary)
             if any((r["dim"], r["n"], r["boundary"], r["method"]) == (*c, "surrogate+refine") for r in summary)]
    out["ref_worse_cases"] = of_count(sum(b["std_rho_map"] > a["std_rho_map"] for a, b in pairs), len(pairs), "case")
    # field by field: where refinement raised the Std, and whether the default map there came from a coarser grid
    both, worse = _refine_pairs(rows)
    out["ref_worse_fields"] = of_count(len(worse), len(both), "field")
    out["ref_worse_coarser"] = sum(bool(a.get("coarser")) for a, _ in worse)
    out["ref_worse_text"] = _refine_worse_text(len(worse), len(both), out["ref_worse_coarser"])
    folds = out["flow_hybrid_flips"]
    out["flow_hybrid_flips_text"] = ("Neither the flow nor the hybrid folded an element in any case." if not folds else
                                     f"Over all cases the flow and the hybrid folded {counted(folds, 'element')}.")
    for d, case in targets.items():
        sur, ref = (next((r for r in summary if (r["dim"], r["n"], r["boundary"], r["method"]) == (*case, m)), None)
                    for m in ("surrogate", "surrogate+refine"))
        if sur is not None and ref is not None:
            out[f"ref_effect{d}"] = _refine_effect(sur["std_rho_map"], ref["std_rho_map"])
    out.update(_roughest_field(by, rows, tuple(targets[min(targets)])))
    out.update(_hybrid_cost(summary))
    return out


def _hybrid_cost(summary: list[dict[str, Any]]) -> dict[str, str]:
    """The hybrid's mean time over the flow's in every case of :func:`summarize` that ran both: the range, how
    many cases were slower, the clause that says both and the verdict on the warm start that follows."""
    cases = list(dict.fromkeys((r["dim"], r["n"], r["boundary"]) for r in summary))
    times = {(r["dim"], r["n"], r["boundary"], r["method"]): r["time"] for r in summary}
    ratios = [times[(*c, "hybrid")] / times[(*c, "flow")] for c in cases
              if (*c, "hybrid") in times and (*c, "flow") in times]
    if not ratios:
        return {}
    lo, hi = _ratio_text(min(ratios)), _ratio_text(max(ratios))
    span = lo if lo == hi else f"from {lo} to {hi}"
    slower = sum(v > 1 for v in ratios)
    where = "every case" if len(ratios) > 1 else "the one case"
    if slower == len(ratios):
        text, verdict = f"it took longer than the flow alone in {where} of the time table, {span} times", "does not pay"
    elif slower == 0:
        text, verdict = f"it took less time than the flow alone in {where} of the time table, {span} times", "pays"
    else:
        text, verdict = (f"it took longer than the flow alone in {of_count(slower, len(ratios), 'case')} of the"
                         f" time table; its time ranged {span} times"), "pays only in some cases"
    text += " the flow's time"
    stds = [r["std_ratio"] for r in summary if r["method"] == "hybrid" and "std_ratio" in r]
    lo_s, hi_s = _ratio_text(min(stds)), _ratio_text(max(stds))
    return {"hyb_std_range": lo_s if lo_s == hi_s else f"from {lo_s} to {hi_s}",
            "hyb_flow_range": span, "hyb_slower_cases": of_count(slower, len(ratios), "case"),
            "hyb_cost_text": text, "hyb_verdict": verdict}


def _refine_pairs(rows: list[dict[str, Any]]) -> tuple[list[tuple[dict, dict]], list[tuple[dict, dict]]]:
    """The (default map, refined map) rows of :func:`time_to_accuracy` of every field mapped both ways, and those
    of the fields on which refinement raised the Std."""
    by = {(r["dim"], r["n"], r["boundary"], r["field"], r["method"]): r for r in rows}
    both = [(r, by[r["dim"], r["n"], r["boundary"], r["field"], "surrogate+refine"]) for r in rows
            if r["method"] == "surrogate" and (r["dim"], r["n"], r["boundary"], r["field"], "surrogate+refine") in by]
    return both, [(a, b) for a, b in both if b["std_rho_map"] > a["std_rho_map"]]


def refinement_fields(rows: list[dict[str, Any]]) -> CaseTable:
    """The fields on which weight refinement raised the surrogate's Std(ρ̃_map), from the rows of
    :func:`time_to_accuracy`: one row per such field with its case, the default map's Std and the refined map's,
    and whether the default map came from a coarser working grid (the network's own map folded on the requested
    one).  The title says on how many of the fields mapped both ways, default and refined, refinement raised the
    Std ("it raised the map's Std on *k* of *m* fields mapped both ways"); without such a field the table is the line
    "No field."."""
    both, worse = _refine_pairs(rows)
    title = (f"Weight refinement, field by field: it raised the map's Std on {of_count(len(worse), len(both), 'field')}"
             " mapped both ways")
    lines = ["| case | field | default map | with refinement | default map from a coarser grid |",
             "|---|---|---|---|---|"]
    for a, b in worse:
        lines.append(f"| {_case_label(a['dim'], a['n'], a['boundary'])} | {a['field']} | "
                     f"{format_value(a['std_rho_map'], 'std_rho_map')} | "
                     f"{format_value(b['std_rho_map'], 'std_rho_map')} | {'yes' if a.get('coarser') else 'no'} |")
    return CaseTable(title, "\n".join(lines) if worse else "No field.")


def _roughest_field(by: dict, rows: list[dict[str, Any]], case: tuple) -> dict[str, Any]:
    """The field of ``case`` on which the flow's final Std is furthest above the diffusion solver's."""
    fields = sorted({r["field"] for r in rows if (r["dim"], r["n"], r["boundary"]) == case})
    over = {f: by[(*case, f, "flow")]["std_rho_map"] / by[(*case, f, "diffusion")]["std_rho_map"] for f in fields}
    rough = max(over, key=over.get)
    label = rough
    if rough.startswith("random-"):  # an unseen field of the report stream: say which kind it is

        kind = DENSITY_KINDS[int(rough.split("-")[1]) % len(DENSITY_KINDS)]
        label = f"the unseen {kind} random field {rough}"
    return {"flow_rough_field": label, "flow_rough_ratio": _ratio_text(over[rough])}
