r"""The paper's tables as four-way comparisons, with one criterion.

Every row of a paper table is a *case* (a test field, or a grid side) and every scored column a *metric* where
lower is better.  For each case this module puts four values side by side:

``paper``
    the published value, from the paper's tables shipped inside the package (:func:`rfmap.paper.tables.paper_table`);
``native`` (the paper's method)
    the network run on the requested grid itself, then the paper's weight refinement (Sec. 4.3), nothing else:
    ``Surrogate.map(field, n, native=True, refine=True, repair=False)``;
``delivered``
    ``Surrogate.map(field, n, refine=True, symmetrize=True)``: the network on its working grid, averaged over the
    symmetries of the square or cube, refined, and repaired where it folds;
``classical``
    the project's fastest classical solver on the same mesh: the flow solver (``solve_dem(..., method="flow")``) or
    the Linear Beltrami Solver.

A case *meets* the paper when :math:`v_{\text{native}} \le v_{\text{paper}}`.  Times are the fastest of a few
runs after a warm-up; the paper's are read as network inference on the one NVIDIA RTX A6000 GPU its settings list.
"""
from __future__ import annotations

import csv
import io
import time
from decimal import Decimal
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .. import solvers
from ..finish import quiet_quality
from ..fields.paper import DENSITIES, PAPER_N, TEST_FIELDS, get_field, sample_mu
from ..core.result import MapResult
from .reproduce import beltrami_values, density_values, exact_beltrami_result
from ..core.wording import of_count
from .tables import _csv_cell, one_notation, paper_table, power_of_ten, printed_digits
from .verdicts import (close_calls, is_comparable, median_ratio, met_text, nc_phrase, qualified_verdict, ratio_text,
                       std_ratio)

__all__ = ["Case", "Comparison", "METHODS", "METRIC_TITLES", "format_number", "format_time", "score_row",
           "timed", "compare_density", "compare_beltrami", "compare_models", "population_comparison",
           "resolution_comparison", "beltrami_comparison", "beltrami_resolution_comparison", "PAPER_METHOD",
           "DELIVERED", "SHOWN", "native_side_by_side"]

#: The four columns of a comparison, in order.
METHODS = ("paper", "native", "delivered", "classical")

#: Keywords of :meth:`rfmap.Surrogate.map` for the paper's method: the network on the requested grid, refined.
PAPER_METHOD = {"native": True, "refine": True, "repair": False}
#: Keywords of :meth:`rfmap.Surrogate.map` for the delivered map.
DELIVERED = {"refine": True, "symmetrize": True}

#: How a metric or quantity of the tables is named in the book, key (``"std_rho_map"``) -> title (``"Std(ρ̃_map)"``);
#: ``mean |Δμ| vs PL`` is the error in μ against the μ of the exact map's piecewise-linear interpolant.
METRIC_TITLES = {"std_rho_map": "Std(ρ̃_map)", "std_rho_orig": "Std(ρ̃_orig)", "mean_mu": "mean |μ|",
                 "max_mu": "max |μ|", "mean_dd": "mean |Δd|", "mean_dmu": "mean |Δμ|", "mean_dmu_pl": "mean |Δμ| vs PL",
                 "min_jacobian": "min det J", "n_flipped": "flips", "time": "time", "network_time": "network time",
                 "work_n": "network grid", "alpha": "α", "mu_ratio": "mean |μ|, DEQ / DEM"}

#: Quantities the paper prints, lower being better, that the verdict does not score (shown beside the scored ones).
SHOWN = ("max_mu",)

#: significant digits of every number of the comparison tables and the scoreboard
DIGITS = 4


def format_number(v, digits: int = DIGITS, *, printed: bool = False) -> str:
    """One number format for every table of the comparisons and the scoreboard: ``digits`` significant digits in
    positional notation (``0.08254``, ``1234``), below 10⁻³ as a power of ten (``3.810 × 10⁻⁵``, never
    e-notation or a run of zeros), integers exactly, ``None`` or NaN as an em dash.  With ``printed`` (a published
    value) no more digits than the value was printed with: the paper's 0.000006 stays ``6 × 10⁻⁶``.

    Examples
    --------
    >>> format_number(0.0825411), format_number(3.8104e-05)
    ('0.08254', '3.810 × 10⁻⁵')
    >>> format_number(7), format_number(6e-06, printed=True)
    ('7', '6 × 10⁻⁶')
    """
    if v is None:
        return "—"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    v = float(v)
    if not np.isfinite(v):
        return "—"
    if printed:
        digits = min(digits, printed_digits(v))
    if v != 0 and abs(float(f"{v:.{digits - 1}e}")) < 1e-3:
        return power_of_ten(v, digits)
    return format(Decimal(f"{v:.{digits - 1}e}"), "f")


def format_time(seconds) -> str:
    """A time with its unit and three significant digits, trailing zeros kept so that times in one table read
    alike: ``12.3 ms``, ``84.0 ms``, ``2.43 s``; from 100 s whole seconds (``1,234 s``); ``None`` as an em dash."""
    if seconds is None:
        return "—"
    s = float(seconds)
    ms = float(f"{s * 1e3:.3g}")
    if ms < 1000:
        return f"{ms:#.3g}".rstrip(".") + " ms"
    if s < 99.95:
        return f"{float(f'{s:.3g}'):#.3g}".rstrip(".") + " s"
    return f"{s:,.0f} s"


def _met(native, paper) -> bool | None:
    return None if native is None or paper is None else bool(native <= paper)


def score_row(paper, native, delivered, classical, *, published: bool = True) -> dict[str, str]:
    """The four values of one cell of the introduction's scoreboard and its verdict, as formatted text: each number by
    :func:`format_number` (``paper`` with no more digits than it was printed with, unless it is not a
    ``published`` value but, say, a mean of them), ``met`` ``yes`` / ``no`` (``—`` without a paper value)."""
    met = _met(native, paper)
    return {"paper": format_number(paper, printed=published), "native": format_number(native),
            "delivered": format_number(delivered), "classical": format_number(classical),
            "met": "—" if met is None else ("yes" if met else "no")}


def timed(run: Callable[[], MapResult], warm: Callable[[], object] | None = None, repeats: int = 3,
          slow: float = 1.0) -> MapResult:
    """The fastest of ``repeats`` runs of ``run`` (by the result's ``time``) after one untimed ``warm`` call
    (default: ``run``); one run where the first took over ``slow`` seconds (repeats would change no quoted digit)."""
    (warm or run)()
    t0 = time.perf_counter()
    first = run()
    if time.perf_counter() - t0 > slow:
        return first
    return min([first] + [run() for _ in range(repeats - 1)], key=lambda r: r.time)


@dataclass(frozen=True)
class Case:
    """One row of a paper table: ``name`` as the paper labels it (a field, or a grid side as text), the ``field`` to
    map and the grid side ``n`` actually run (:meth:`title` says where it differs from the paper's)."""

    name: str
    field: str
    n: int

    def title(self, prefix: str = "") -> str:
        """The row's label; a case run on another grid than the paper's says so."""
        run_at = f" (run at {self.n})" if self.name.isdigit() and int(self.name) != self.n else ""
        return f"{prefix}{self.name}{run_at}"


@dataclass
class Comparison:
    """A paper table as a four-way comparison (see :mod:`rfmap.paper.comparison`).

    Attributes
    ----------
    label : str
        The label of the paper's table (``tab:...``) that the comparison reproduces.
    title : str
        The title printed above the comparison's table.
    metrics : list of str
        The scored metrics (lower is better), keys of :data:`METRIC_TITLES`.
    cases : list of Case
    classical : str
        The classical solver's name for column heads.
    values : dict
        ``{(case name, method): {quantity: value}}`` for every method of :data:`METHODS`.
    maps : dict
        ``{case name: {"native" | "delivered" | "classical" | "exact": MapResult}}``, for the figures.
    case_prefix : str
        Prefix of the row labels (``"N = "`` for grid sides).
    """

    label: str
    title: str
    metrics: list[str]
    cases: list[Case]
    classical: str
    values: dict = field(default_factory=dict)
    maps: dict = field(default_factory=dict)
    case_prefix: str = ""

    def value(self, case: str, method: str, quantity: str):
        """One value; ``None`` where it was not measured (the paper's of a quantity it does not report)."""
        return self.values.get((str(case), method), {}).get(quantity)

    def met(self, case: str, metric: str) -> bool | None:
        """Whether the paper's method is at most the paper's value (``None`` without a paper value, or where the
        case's input is not the paper's: :meth:`comparable`)."""
        if not self.comparable(case):
            return None
        return _met(self.value(case, "native", metric), self.value(case, "paper", metric))

    def comparable(self, case: str) -> bool:
        """Whether the case's input is the paper's (:func:`rfmap.paper.verdicts.is_comparable`: its Std(ρ̃_orig)
        on the paper's grid, a grid side named by the case or the table's, agrees with the paper's)."""
        c = next(c for c in self.cases if c.name == str(case))
        paper_std = self.value(c.name, "paper", "std_rho_orig")
        if paper_std is None:
            return True
        n = int(c.name) if c.name.isdigit() else PAPER_N[get_field(c.field).dim]
        return is_comparable(c.field, n, paper_std)

    def _nc_ratios(self) -> list[tuple[str, float, float]]:
        """Per case whose input is not the paper's: its name, its Std ratio by the paper's method and the paper's."""
        ratios = [[c.name] + [std_ratio(self.value(c.name, m, "std_rho_map"), self.value(c.name, m, "std_rho_orig"))
                              for m in ("native", "paper")] for c in self.cases if not self.comparable(c.name)]
        return [(c, a, b) for c, a, b in ratios if a is not None and b is not None and "std_rho_map" in self.metrics]

    def verdict_word(self, short: bool = False) -> str:
        """The verdict, its tally of (case, metric) pairs and the clause on the n/c cases with the size of the gap
        (:func:`.qualified_verdict`): ``'reproduced on the comparable cases (3 of 3); the n/c case's Std ratio is 1.6
        times the paper's'``, and with ``short`` (the scoreboards' cell) ``'reproduced (3 of 3 comparable)'``."""
        flags, nc = [self.met(c.name, m) for c in self.cases for m in self.metrics], self._nc_ratios()
        return qualified_verdict(flags, [a > b for _, a, b in nc], short=short, factors=[a / b for _, a, b in nc])

    def _case_met(self, case: str, metric: str) -> str:
        """A met cell of a chapter's table: ``yes``/``no``/``—``, or ``n/c`` for an input not the paper's."""
        if not self.comparable(case):
            return "n/c"
        return {None: "—", True: "yes", False: "no"}[self.met(case, metric)]

    def nc_note(self) -> str:
        """The note under a table with inputs not the paper's (``""`` if none): *n/c* and each one's Std ratios."""
        parts = "; ".join(f"{c}, paper's method {a:.3g} and paper {b:.3g}" for c, a, b in self._nc_ratios())
        ratio = f"; compared instead by the Std ratio, Std(ρ̃_map) / Std(ρ̃_orig), lower is better: {parts}"
        nc = not all(self.comparable(c.name) for c in self.cases)
        return f"*n/c*: not comparable, the input is not the paper's{ratio if parts else ''}." if nc else ""

    def count(self, metric: str, test: Callable[[str], bool | None] | None = None) -> tuple[int, int]:
        """``(k, m)``: the cases where ``test(case)`` holds (default: :meth:`met`) among the ``m`` it decides."""
        test = test or (lambda c: self.met(c, metric))
        verdicts = [test(c.name) for c in self.cases]
        return sum(bool(v) for v in verdicts), sum(v is not None for v in verdicts)

    def classical_better(self, metric: str) -> tuple[int, int]:
        """``(k, m)``: the cases where the classical solver's value is below the paper's method's."""
        def test(c):
            a, b = self.value(c, "classical", metric), self.value(c, "native", metric)
            return None if a is None or b is None else a < b
        return self.count(metric, test)

    def mean(self, method: str, metric: str, comparable: bool = False) -> float | None:
        """The mean of a method's values of ``metric`` over the cases (``None`` if any is missing); with ``comparable``,
        over the cases whose input is the paper's only (:meth:`comparable`), as the scoreboard counts them."""
        cases = [c for c in self.cases if not comparable or self.comparable(c.name)]
        vals = [self.value(c.name, method, metric) for c in cases]
        return None if not vals or any(v is None for v in vals) else float(np.mean(vals))

    def speed(self, method: str = "native") -> dict[str, float]:
        """Per case the classical solver's time over ``method``'s (above 1: ``method`` is faster)."""
        return {c.name: self.value(c.name, "classical", "time")/self.value(c.name, method, "time") for c in self.cases}

    def total(self, method: str, quantity: str = "n_flipped"):
        """The sum over the cases of a method's ``quantity`` (default: its flipped elements)."""
        return sum(self.value(c.name, method, quantity) for c in self.cases)

    def median_time(self, method: str, quantity: str = "time") -> float | None:
        """The median over the cases of a method's ``time`` (or ``network_time``), in seconds."""
        vals = [self.value(c.name, method, quantity) for c in self.cases]
        return None if any(v is None for v in vals) else float(np.median(vals))

    def native_lesson(self, metric: str = "std_rho_map", tol: float = 1.1) -> str:
        """A sentence on the cases where the paper's method runs the network on another grid than the delivered map
        (outside the training range): whether there its ``metric`` is more than ``tol`` times the delivered map's."""
        outside = [c.name for c in self.cases
                   if self.value(c.name, "native", "work_n") != self.value(c.name, "delivered", "work_n")]
        if not outside:
            return "The paper's method and the delivered map run the network on the same grid at every side."
        worse = [c for c in outside
                 if self.value(c, "native", metric) > tol * self.value(c, "delivered", metric)]
        if worse:
            return (f"Outside the training range (N = {', '.join(worse)}) the network run natively, as the paper "
                    f"runs it, leaves {METRIC_TITLES[metric]} more than {tol:g} times that of the delivered map, which "
                    "runs it on the working grid and interpolates: the one network accepts every grid, but it is "
                    "accurate only near the grids it was trained on.")
        return (f"Outside the training range (N = {', '.join(outside)}) the network run natively, as the paper "
                f"runs it, leaves {METRIC_TITLES[metric]} within {tol:g} times that of the delivered map, which "
                "runs it on the working grid and interpolates.")

    def score_values(self) -> dict[str, str]:
        """Scoreboard numbers as text: per metric ``{metric}_{col}`` (mean over the comparable cases, :data:`METHODS`),
        ``{metric}_{col}_ratio`` (:func:`.median_ratio` to the paper), ``{metric}_met``, ``{metric}_classical_better``
        (``"3 of 4"``), per case ``{metric}_{case}_{col}`` and ``{metric}_{case}_met`` (:func:`.met_text`, ``n/c``:
        input not the paper's); ``verdict`` (short), ``nc`` (n/c Std ratios), ``close`` (:func:`.close_calls`)."""
        out, texts = {}, {}  # numbers, put in one notation per metric; texts (ratios, met cells) as they are
        comparable = [c.name for c in self.cases if self.comparable(c.name)]
        for metric in self.metrics + self.shown():
            row = score_row(*(self.mean(m, metric, comparable=True) for m in METHODS), published=False)
            out.update({f"{metric}_{k}": v for k, v in row.items() if k != "met"})
            texts[f"{metric}_met"] = of_count(*self.count(metric))
            for m in METHODS[1:]:
                pairs = [(self.value(c, m, metric), self.value(c, "paper", metric)) for c in comparable]
                texts[f"{metric}_{m}_ratio"] = ratio_text(median_ratio(pairs))
            if metric in self.shown():
                continue
            texts[f"{metric}_classical_better"] = of_count(*self.classical_better(metric))
            for c in self.cases:
                row = score_row(*(self.value(c.name, m, metric) for m in METHODS))
                out.update({f"{metric}_{c.name}_{k}": v for k, v in row.items() if k != "met"})
                ours, paper = (self.value(c.name, m, metric) for m in ("native", "paper"))
                texts[f"{metric}_{c.name}_met"] = met_text(ours, paper) if c.name in comparable else "n/c"
        # the flow solver does not aim at a small mean |μ|: its value there says nothing of what the mesh allows
        texts["verdict"], texts["close"] = self.verdict_word(short=True), close_calls(
            (f"N = {c}" if c.isdigit() else c, METRIC_TITLES[m], self.value(c, "native", m), self.value(c, "paper", m),
             None if m == "mean_mu" else self.value(c, "classical", m)) for c in comparable for m in self.metrics)
        nc = self._nc_ratios()
        texts["nc"] = "; ".join((f"{c}: " if len(nc) > 1 else "") + nc_phrase(a, b) for c, a, b in nc) or "—"
        out = one_notation(out, self.metrics + self.shown()) | texts
        return {k: v.replace(" × ", "\u00a0×\u00a0").replace(" %", "\u00a0%") for k, v in out.items()}  # never split

    def shown(self) -> list[str]:
        """The quantities of :data:`SHOWN` that the paper's table prints: the scoreboard shows them beside the scored
        metrics (means and ``"k of m"`` cases at most the paper's), outside the verdict."""
        try:
            columns = paper_table(self.label)["columns"]
        except ValueError:  # a figure: no printed table
            return []
        return [q for q in SHOWN if q in columns and q not in self.metrics]

    def methods(self) -> list[str]:
        """The columns that hold values, in order: those of :data:`METHODS`, and ``"raw"`` (the network's map
        without refinement, where it was measured) before the paper's method."""
        return [m for m in ("paper", "raw") + METHODS[1:] if any((c.name, m) in self.values for c in self.cases)]

    def heads(self) -> list[str]:
        names = {"paper": "paper", "raw": "raw network", "native": "paper's method", "delivered": "delivered"}
        return [names.get(m, self.classical) for m in self.methods()]

    def _cell(self, case: str, method: str, q: str) -> str:
        v, flips = self.value(case, method, q), self.value(case, method, "n_flipped")
        if q == "std_rho_map" and method == "raw" and flips:  # a folded map's Std is no spread (compare.folded_cell)
            return f"folded ({int(flips):,} flips)"
        if q in ("time", "network_time"):
            return format_time(v)
        if isinstance(v, (list, tuple)):
            return ", ".join(f"{float(a):.3g}" for a in v)
        return format_number(v, printed=method == "paper")

    def _markdown(self, quantities: list[str], met: bool) -> str:
        """The rows of ``quantities``; the columns that hold one of them, ``met`` only with a scored metric."""
        heads = dict(zip(self.methods(), self.heads()))
        shown = [m for m in heads if any(self.value(c.name, m, q) is not None for c in self.cases for q in quantities)]
        met = met and bool(set(quantities) & set(self.metrics))
        head = ["N" if self.case_prefix else "case", "quantity"] + [heads[m] for m in shown] + (["met"] if met else [])
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for c in self.cases:
            for i, q in enumerate(quantities):
                cells = [c.title() if i == 0 else "", METRIC_TITLES[q].replace("|", "\\|")]
                cells += [self._cell(c.name, m, q) for m in shown]
                if met:
                    cells.append(self._case_met(c.name, q) if q in self.metrics else "")
                lines.append("| " + " | ".join(cells) + " |")
        return "\n".join(lines)

    def to_markdown(self, quantities: list[str] | None = None) -> str:
        """The paper's shape: a block of rows per case (the scored metrics and the time, or ``quantities``), a column
        per method that holds one of them and the verdict of each scored metric; numbers by :func:`format_number`.
        The note on cases that are not comparable (:meth:`nc_note`) follows only a table that shows a scored metric,
        where the *n/c* marks stand; a raw map that folds reads ``folded (n flips)`` as its Std(ρ̃_map)."""
        quantities = quantities or self.metrics + ["time"]
        table = self._markdown(quantities, met="paper" in self.methods())
        scored = bool(set(quantities) & set(self.metrics))
        note = self.nc_note() if "paper" in self.methods() and scored else ""
        return f"{table}\n\n{note}" if note else table

    def verdict(self) -> str:
        """One sentence per metric: how many cases meet the paper (criterion named), and how many the classical
        solver maps more accurately than the paper's method."""
        return " ".join(f"{METRIC_TITLES[q]}: the paper's method is at most the paper's value on "
                        f"{of_count(*self.count(q), 'case')}; the {self.classical} does better than the paper's "
                        f"method on {of_count(*self.classical_better(q))}." for q in self.metrics)

    def full_quantities(self, leave_out=()) -> list[str]:
        """Every quantity measured, in the tables' order, but those of ``leave_out``."""
        present = {q for v in self.values.values() for q in v} - set(leave_out)
        return [q for q in ["std_rho_orig", "std_rho_map", "mean_dd", "mean_dmu", "mean_dmu_pl", "mean_mu", "max_mu",
                            "min_jacobian", "n_flipped", "work_n", "alpha", "time", "network_time"] if q in present]

    def full_markdown(self) -> str:
        """Every quantity measured (``full_quantities()``) in the shape of :meth:`to_markdown`, without verdicts:
        as narrow as the text column however many quantities there are."""
        return self._markdown(self.full_quantities(), met=False)

    def to_csv(self) -> str:
        """Every value, one row per case and method; times in seconds, numbers by :func:`format_number`."""
        qs = self.full_quantities()
        buf = io.StringIO()
        w = csv.writer(buf)
        w.writerow(["case", "n", "method"] + qs)
        for c in self.cases:
            for m in self.methods():
                vals = self.values.get((c.name, m))
                if vals:
                    w.writerow([c.name, c.n, m] + [_csv_cell(vals.get(q)) for q in qs])
        return buf.getvalue()

    def save(self, out_dir) -> list[Path]:
        """Write ``<label>.md`` (the title, the paper-shaped table and the full one) and ``<label>.csv``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        stem = self.label.replace(":", "-").replace("_", "-")
        md, cs = out / f"{stem}.md", out / f"{stem}.csv"
        md.write_text(f"{self.title}\n\n{self.to_markdown()}\n\n{self.full_markdown()}\n", encoding="utf-8")
        cs.write_text(self.to_csv(), encoding="utf-8")
        return [md, cs]

    def _repr_markdown_(self) -> str:
        return f"**{self.title}**\n\n{self.to_markdown()}"


# ------------------------------------------------------------------------------------------------- the runners
def _network_values(res: MapResult, values: dict) -> dict:
    return {**values, **{k: res.info.get(k) for k in ("network_time", "work_n", "alpha")}}


def _surrogate_maps(sur, field_, n: int) -> tuple[MapResult, MapResult]:
    """The paper's method and the delivered map of one field, timed (:func:`timed`)."""
    native = timed(lambda: sur.map(field_, n, **PAPER_METHOD),
                   warm=lambda: sur.map(field_, n, native=True, repair=False))
    delivered = timed(lambda: sur.map(field_, n, **DELIVERED), warm=lambda: sur.map(field_, n, repair=False))
    return native, delivered


@quiet_quality()
def compare_density(sur, cases: list[Case], label: str, title: str, *, case_prefix: str = "") -> Comparison:
    """A density table (``tab:population_test``, ``_fb``, ``tab:resolution_test`` and the 3D ones) as a
    :class:`Comparison`: per case the paper's method, the delivered map and the flow-based solver with the
    surrogate's boundary, and the paper's row.  Scored: Std(ρ̃_map), and in 2D mean ``|μ|``.

    Parameters
    ----------
    sur : rfmap.Surrogate
        A density surrogate.
    cases : list of Case
    label, title : str
    case_prefix : str
    """
    with_mu, boundary = sur.spec.dim == 2, ("free" if sur.spec.boundary == "free" else "square")
    cmp = Comparison(label, title, ["std_rho_map"] + (["mean_mu"] if with_mu else []), list(cases),
                     "flow solver", case_prefix=case_prefix)
    paper = paper_table(label)["rows"]
    for c in cases:
        native, delivered = _surrogate_maps(sur, c.field, c.n)
        dens = DENSITIES[c.field].sample(c.n)
        flow = timed(lambda: solvers.solve_dem(dens, method="flow", boundary=boundary))
        cmp.values[(c.name, "native")] = _network_values(native, density_values(native, with_mu))
        cmp.values[(c.name, "delivered")] = _network_values(delivered, density_values(delivered, with_mu))
        cmp.values[(c.name, "classical")] = density_values(flow, with_mu)
        if c.name in paper:
            cmp.values[(c.name, "paper")] = dict(paper[c.name])
        cmp.maps[c.name] = {"native": native, "delivered": delivered, "classical": flow}
    return cmp


def compare_beltrami(sur, cases: list[Case], label: str, title: str, *, case_prefix: str = "") -> Comparison:
    """A Beltrami table (``tab:reconstruction_results_mu``, ``_res``) as a :class:`Comparison`: per case the
    paper's method, the delivered map, the Linear Beltrami Solver and the paper's row.  Scored: mean ``|Δd|`` and mean
    ``|Δμ|`` (against the analytic coefficient at the triangle centroids)."""
    cmp = Comparison(label, title, ["mean_dd", "mean_dmu"], list(cases), "LBS", case_prefix=case_prefix)
    paper = paper_table(label)["rows"]
    for c in cases:
        native, delivered = _surrogate_maps(sur, c.field, c.n)
        mu = sample_mu(c.field, c.n)
        lbs = timed(lambda: solvers.solve_lbs(mu, c.n))
        for method, res in (("native", native), ("delivered", delivered)):
            cmp.values[(c.name, method)] = _network_values(res, beltrami_values(res, c.field))
        cmp.values[(c.name, "classical")] = beltrami_values(lbs, c.field)
        if c.name in paper:
            cmp.values[(c.name, "paper")] = dict(paper[c.name])
        cmp.maps[c.name] = {"native": native, "delivered": delivered, "classical": lbs,
                            "exact": exact_beltrami_result(c.field, c.n)}
    return cmp


@quiet_quality()
def compare_models(models: dict, field, n: int, label: str, title: str, *, raw: bool = False) -> Comparison:
    """One density mapped by several density surrogates with one boundary, the cases named by the keys of
    ``models`` (the paper's Fig. 10: the DEM and the DEQ model), each by the paper's method and delivered, beside
    the flow solver's map of the same density (the same in every case). Scored: Std(ρ̃_map), mean ``|μ|``; no paper row.

    Parameters
    ----------
    models : dict of str to rfmap.Surrogate
    field : str or callable
        A built-in density or a callable on points (P, 2), as :meth:`rfmap.Surrogate.map` takes it.
    n : int
    label, title : str
    raw : bool
        Also map each density by the network alone on the requested grid, without refinement or repair (the
        ``"raw"`` column, untimed).
    """
    name = field if isinstance(field, str) else getattr(field, "__name__", "field")
    cmp = Comparison(label, title, ["std_rho_map", "mean_mu"], [Case(k, name, n) for k in models], "flow solver")
    flow = None
    for key, sur in models.items():
        native, delivered = _surrogate_maps(sur, field, n)
        if flow is None:
            dens = np.asarray(native.field).reshape((n,) * sur.spec.dim)
            boundary = "free" if sur.spec.boundary == "free" else "square"
            flow = timed(lambda: solvers.solve_dem(dens, method="flow", boundary=boundary))
        cmp.values[(key, "native")] = _network_values(native, density_values(native, True))
        cmp.values[(key, "delivered")] = _network_values(delivered, density_values(delivered, True))
        cmp.values[(key, "classical")] = density_values(flow, True)
        cmp.maps[key] = {"native": native, "delivered": delivered, "classical": flow}
        if raw:
            bare = sur.map(field, n, native=True, refine=False, repair=False)
            cmp.values[(key, "raw")] = {**_network_values(bare, density_values(bare, True)), "time": None,
                                        "network_time": None}
            cmp.maps[key]["raw"] = bare
    return cmp


# ----------------------------------------------------------------------------------------- the paper's tables
def _label(dim: int, boundary: str, kind: str) -> str:
    stem = {"population": "population_test", "resolution": "resolution_test"}[kind]
    return ("tab:" if dim == 2 else "tab:3d_") + stem + ("_fb" if boundary == "free" else "")


def population_comparison(sur, n: int | None = None, fields=None) -> Comparison:
    """Tables 4, 5, 7 and 8 of the paper (by the surrogate's dimension and boundary) on the ``n``-grid (default
    the paper's: 51 in 2D, 48 in 3D)."""
    d, b = sur.spec.dim, sur.spec.boundary
    n = n or PAPER_N[d]
    fields = list(fields or TEST_FIELDS["density", d])
    where = "free boundary" if b == "free" else ("square boundary" if d == 2 else "cube boundary")
    return compare_density(sur, [Case(f, f, n) for f in fields], _label(d, b, "population"),
                           f"{d}D population tests, {where}, N = {n}, model {sur.name}")


def resolution_comparison(sur, ns: dict | None = None) -> Comparison:
    """Tables 6 and 9 of the paper: the multi-frequency density at the paper's grid sides; ``ns`` maps each
    paper side to the side run (default: the paper's own)."""
    d = sur.spec.dim
    paper_ns = (32, 64, 128, 256) if d == 2 else (32, 40, 56, 64)
    ns = ns or {k: k for k in paper_ns}
    if set(ns) != set(paper_ns):
        raise ValueError(f"ns must map the paper's sides {paper_ns} to the sides run, got {sorted(ns)}")
    name = "multi-freq" if d == 2 else "multi-freq-3d"
    return compare_density(sur, [Case(str(k), name, int(ns[k])) for k in paper_ns], _label(d, "square", "resolution"),
                           f"{d}D resolution test, multi-frequency density, model {sur.name}", case_prefix="N = ")


def beltrami_comparison(sur, n: int = PAPER_N[2]) -> Comparison:
    """Table 2 of the paper: the test maps T1–T4 on the ``n``-grid."""
    return compare_beltrami(sur, [Case(t, t, n) for t in TEST_FIELDS["beltrami", 2]], "tab:reconstruction_results_mu",
                            f"Reconstruction from Beltrami coefficients, N = {n}, model {sur.name}")


def beltrami_resolution_comparison(sur, ns: dict | None = None) -> Comparison:
    """Table 3 of the paper: T1 with a = 0.06, b = 0.04 at the paper's grid sides (``ns`` as in
    :func:`resolution_comparison`)."""
    paper_ns = (48, 64, 80, 96)
    ns = ns or {k: k for k in paper_ns}
    if set(ns) != set(paper_ns):
        raise ValueError(f"ns must map the paper's sides {paper_ns} to the sides run, got {sorted(ns)}")
    return compare_beltrami(sur, [Case(str(k), "T1-res", int(ns[k])) for k in paper_ns],
                            "tab:reconstruction_results_res",
                            f"Reconstruction of T1 (a = 0.06, b = 0.04) per grid side, model {sur.name}",
                            case_prefix="N = ")


def native_side_by_side(tables: dict[str, Comparison], metric: str = "std_rho_map") -> str:
    """The paper's method of several models side by side, one row per case of the same paper table (Markdown):
    the paper's value, each model's native value (``{model: comparison}``, in order) with whether it meets the
    paper (*n/c* where the case's input is not the paper's), and the classical solver of the first comparison.
    ``metric`` may be any quantity the paper's method measured in every comparison; whether a value meets the paper
    is marked for the scored metrics only.

    Raises
    ------
    ValueError
        When ``tables`` is empty or the comparisons differ in their cases or metrics.
    """
    if not tables:
        raise ValueError("native_side_by_side needs at least one comparison")
    first = next(iter(tables.values()))
    for name, t in tables.items():
        if [c.name for c in t.cases] != [c.name for c in first.cases] or \
                any(t.value(c.name, "native", metric) is None for c in t.cases):
            raise ValueError(f"comparison {name!r} differs from the first in its cases or lacks {metric!r}")
    title = METRIC_TITLES[metric].replace("|", "\\|\u2060")  # a word joiner: never "paper mean |" / "μ|"
    head = [first.case_prefix.strip(" =") or "case", f"paper {title}"]
    head += [f"{name}, paper's method" for name in tables] + [first.classical]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for c in first.cases:
        cells = [c.name, format_number(first.value(c.name, "paper", metric))]
        for t in tables.values():
            met = t.met(c.name, metric) if metric in t.metrics else None
            if met is not None:
                mark = " (met)" if met else " (missed)"
            else:  # a scored metric on an input that is not the paper's
                mark = " (n/c)" if metric in t.metrics and not t.comparable(c.name) else ""
            cells.append(format_number(t.value(c.name, "native", metric)) + mark)
        cells.append(format_number(first.value(c.name, "classical", metric)))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
