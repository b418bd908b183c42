r"""One verdict word per paper table or figure, and whether a test input is the paper's.

A case of a density table is *comparable* with the paper when its input is the paper's: the test density on the
paper's grid has the paper's :math:`\mathrm{Std}(\tilde\rho_{\text{orig}})` to within :data:`COMPARABLE_RTOL`
(relative).  A case whose input differs (rect-peak, whose box the paper does not define, or prism-peak-3d, whose
printed formula gives another input) is marked
*n/c* (not comparable) and is not scored against the paper's value; it is compared instead by its *Std ratio*
(:func:`std_ratio`), the share of the input's spread the map leaves,
:math:`\mathrm{Std}(\tilde\rho_{\text{map}}) / \mathrm{Std}(\tilde\rho_{\text{orig}})`, and it is *worse by Std
ratio* where :term:`the paper's method` leaves a larger share of its input's spread than the paper's map leaves of the
paper's input.

The verdict of an item (:func:`verdict`) counts, over its comparable cases and its scored metrics, the pairs where
the paper's method is at most the paper's value:

``reproduced``
    every pair;
``partly``
    some, not all;
``not reproduced``
    none;
``not comparable``
    cases, but none whose input is the paper's;
``not scored``
    nothing to score: the paper prints no number for the item (Fig. 10).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..core.mesh import grid_mesh
from ..core.metrics import compute_metrics
from ..core.wording import of_count
from ..fields.paper import get_field, sample_density

__all__ = ["COMPARABLE_RTOL", "VERDICTS", "VERDICT_RULE", "SCORED_METRICS", "input_std", "is_comparable", "std_ratio",
           "verdict", "qualified_verdict", "nc_clause", "nc_phrase", "ratio_text", "met_text", "median_ratio",
           "every_or_count", "classical_lead", "times_lower", "NEAR_MISS", "close_calls", "FIG10_METHODS",
           "fig10_checks", "fig10_text"]

#: The relative agreement of the input's Std(ρ̃_orig) with the paper's for a case to count as the paper's input
#: (the paper prints six digits).  The inputs rebuilt from formulas that the paper gives completely agree with its
#: values to 3 × 10⁻⁴ or better; rect-peak (whose box the paper does not define) and prism-peak-3d (whose printed
#: formula gives another input) miss them by 19 % and 7 % and are not comparable (:func:`is_comparable`).
COMPARABLE_RTOL = 1e-3
#: A miss by at most this share of the paper's value is named as a near miss (:func:`close_calls`); the verdict still
#: counts it as a miss.
NEAR_MISS = 5e-3
#: The verdict words, best first.
VERDICTS = ("reproduced", "partly", "not reproduced", "not comparable", "not scored")
#: The rule of :func:`verdict`, as the scoreboards state it once.
#:
#: :meta hide-value:
VERDICT_RULE = (
    "*reproduced*: the paper's method meets the paper in every scored metric of every case whose input is the "
    "paper's; *partly*: in some of them; *not reproduced*: in none; *not comparable*: no case has the paper's "
    "input; *not scored*: the paper prints no number for the item, so nothing is scored. "
    "A case's input is the paper's when its Std(ρ̃_orig) on the paper's grid agrees with the paper's to "
    f"within {COMPARABLE_RTOL * 100:g} %; a case whose input differs is marked *not comparable* (*n/c*) and "
    "compared instead by Std(ρ̃_map) / Std(ρ̃_orig), the share of the input's spread the map leaves.")
#: Why the verdict scores the metrics it does, as the scoreboards state it once.
#:
#: :meta hide-value:
SCORED_METRICS = (
    "The verdict scores the mean measures that the paper's tables report and its losses target: the mean errors "
    "|Δμ| (which the Beltrami loss drives down directly) and |Δd| (through it) of a Beltrami reconstruction, the "
    "density's remaining spread Std(ρ̃_map) and, for DEQ maps, the mean distortion mean |μ|. The extremes the "
    "paper prints beside them, max |μ| and min det J, are set by a single element each; "
    "max |μ| is shown next to the scored metrics, outside the verdict, and folds are counted in the chapters.")


@lru_cache(maxsize=64)
def input_std(field: str, n: int) -> float:
    r""":math:`\mathrm{Std}(\tilde\rho_{\text{orig}})` of the test density ``field`` on the grid mesh of side ``n``
    (the identity map's ``std_rho_orig``, :class:`rfmap.core.metrics.MapMetrics`, as every table computes it)."""
    mesh = grid_mesh(n, get_field(field).dim)
    m = compute_metrics(mesh.points, mesh.points, mesh.elements, density=sample_density(field, n).reshape(-1))
    return float(m.std_rho_orig)


def is_comparable(field: str, n: int, paper_std_orig: float | None) -> bool:
    """Whether the input ``field`` on the paper's grid side ``n`` is the paper's (see :mod:`rfmap.paper.verdicts`);
    ``True`` where the paper prints no Std(ρ̃_orig) (the Beltrami tables: their inputs are closed-form maps)."""
    if paper_std_orig is None:
        return True
    return abs(input_std(field, n) - paper_std_orig) <= COMPARABLE_RTOL * abs(paper_std_orig)


def std_ratio(std_map: float | None, std_orig: float | None) -> float | None:
    """Std(ρ̃_map) / Std(ρ̃_orig), ``None`` where either is missing."""
    if std_map is None or not std_orig:
        return None
    return float(std_map) / float(std_orig)


def verdict(met: list[bool | None]) -> str:
    """The verdict word of an item from the met flags of its (case, metric) pairs, each ``True``, ``False`` or
    ``None`` (a case whose input is not the paper's); see :mod:`rfmap.paper.verdicts`.  No pair at all (the paper
    prints no number for the item) is *not scored*; pairs that are all ``None`` are *not comparable*.

    Examples
    --------
    >>> verdict([True, True]), verdict([True, False]), verdict([False])
    ('reproduced', 'partly', 'not reproduced')
    >>> verdict([None]), verdict([])
    ('not comparable', 'not scored')
    """
    flags = [m for m in met if m is not None]
    if not flags:
        return "not comparable" if met else "not scored"
    k = sum(flags)
    return "reproduced" if k == len(flags) else ("partly" if k else "not reproduced")


def qualified_verdict(met: list[bool | None], nc_worse: list[bool] | None = None, *, short: bool = False,
                      factors: list[float] | None = None) -> str:
    """The verdict of :func:`verdict` followed by its tally and, where the item has cases whose input is not the
    paper's (n/c), a clause on those cases.

    The tally ``(k of n)`` counts (case, metric) pairs, not cases: ``n`` is the number of comparable pairs that have a
    paper value, ``k`` those where :term:`the paper's method` is at most the paper's value; it is written so even where
    ``k`` is ``0`` or ``n``.  With n/c cases the word is scoped to the comparable cases and followed by
    :func:`nc_clause`: whether each n/c case's Std ratio (:func:`std_ratio`, the share of the input's spread the map
    leaves) by the paper's method is above the paper's (``nc_worse``, one flag per n/c case, ``True`` where it is);
    with ``short`` the word and its tally named as that of the comparable cases, without the n/c clause, which the
    scoreboards' footnotes give (the scoreboards' cell; an item whose cases are all n/c keeps the clause).
    ``factors``, one per n/c case, are the paper's method's Std ratio over the paper's: the clause then says by how
    much a worse case misses.

    Examples
    --------
    >>> qualified_verdict([True, False])
    'partly (1 of 2)'
    >>> word, nc = qualified_verdict([True, True, True], [True]).split("; ")
    >>> word  # three comparable (case, metric) pairs, all met
    'reproduced on the comparable cases (3 of 3)'
    >>> nc
    'the n/c case is worse by Std ratio'
    >>> qualified_verdict([True] * 3, [True], short=True, factors=[1.61])
    'reproduced (3 of 3 comparable)'
    >>> print(qualified_verdict([None], [True], short=True, factors=[1.61]))
    not comparable; the n/c case’s Std ratio is 1.6 times the paper’s
    """
    flags = [m for m in met if m is not None]
    count = f" ({sum(flags)} of {len(flags)})" if flags else ""
    if not nc_worse:
        return verdict(met) + count
    if short:  # the scoreboards' cell: the count named as that of the comparable cases; the n/c cases in a footnote
        if flags:
            return f"{verdict(met)}{count[:-1]} comparable)"
        return f"{verdict(met)}; {nc_clause(nc_worse, factors)}"
    scope = " on the comparable cases" if flags else ""
    return f"{verdict(met)}{scope}{count}; {nc_clause(nc_worse, factors)}"


def nc_clause(nc_worse: list[bool], factors: list[float] | None = None) -> str:
    """How many of the n/c cases are *worse by Std ratio* (both defined in :mod:`rfmap.paper.verdicts`), from one
    flag per n/c case (``""`` for none); with ``factors`` (per n/c case, the paper's method's Std ratio over the
    paper's), by how much, to two digits.

    Examples
    --------
    >>> nc_clause([False])
    'the n/c case is not worse by Std ratio'
    >>> nc_clause([True, False])
    '1 of the 2 n/c cases is worse by Std ratio'
    >>> nc_clause([True, True, False])
    '2 of the 3 n/c cases are worse by Std ratio'
    >>> print(nc_clause([True], [1.93]))
    the n/c case’s Std ratio is 1.9 times the paper’s
    >>> print(nc_clause([False], [0.65]))
    the n/c case’s Std ratio is 0.65 times the paper’s
    >>> print(nc_clause([True, False], [1.61, 0.9]))
    1 of the 2 n/c cases is worse by Std ratio, 1.6 times the paper’s
    """
    if not nc_worse:
        return ""
    if len(nc_worse) == 1 and factors:  # one n/c case: its ratio to the paper's, better or worse
        return f"the n/c case’s Std ratio is {float(f'{factors[0]:.2g}'):g} times the paper’s"
    worst = max((f for f, w in zip(factors or [], nc_worse) if w), default=None)
    size = f"{float(f'{worst:.2g}'):g} times the paper’s" if worst is not None else ""
    if len(nc_worse) == 1:
        if size:
            return f"the n/c case’s Std ratio is {size}"
        return f"the n/c case is {'worse' if nc_worse[0] else 'not worse'} by Std ratio"
    k = sum(nc_worse)
    up_to = ("up to " if k > 1 else "") + size
    return (f"{k} of the {len(nc_worse)} n/c cases {'is' if k == 1 else 'are'} worse by Std ratio"
            + (f", {up_to}" if size else ""))


def nc_phrase(ours: float, paper: float) -> str:
    """One n/c case's Std ratio by the paper's method beside the paper's, as a phrase for running text after
    *leaves*: each as the share of the input's spread the map leaves, in per cent to three digits, and their
    quotient to two digits in the same form whichever is lower (lower is better).

    Examples
    --------
    >>> print(nc_phrase(0.125, 0.194))
    12.5 % of its input’s spread against the paper’s 19.4 % (0.64 times as much)
    >>> print(nc_phrase(0.442, 0.274))
    44.2 % of its input’s spread against the paper’s 27.4 % (1.6 times as much)
    """
    return (f"{100 * ours:.3g} % of its input’s spread against the paper’s {100 * paper:.3g} % "
            f"({float(f'{ours / paper:.2g}'):g} times as much)")


def ratio_text(r: float | None) -> str:
    """A ratio as the scoreboards print it, three significant digits and a times sign: ``0.452×``, ``1.001×``
    (more where three would print a ratio other than 1 as ``1.00×``); ``None`` as an em dash.

    Examples
    --------
    >>> ratio_text(0.45213), ratio_text(1.00127), ratio_text(None)
    ('0.452×', '1.001×', '—')
    """
    if r is None or not np.isfinite(r):
        return "—"
    for digits in range(3, 7):  # enough digits that a ratio other than 1 does not print as 1
        text = f"{r:#.{digits}g}"
        if (float(text) > 1) == (r > 1) and (float(text) < 1) == (r < 1):
            break
    return text.rstrip(".") + "×"


def met_text(ours: float | None, paper: float | None) -> str:
    """The *Met* cell of a scoreboard case: ``yes`` where ``ours`` is at most ``paper``, else ``no`` with the ratio
    ours / paper, so that a near miss reads as one (``no (1.001×)``); ``—`` without a value.

    Examples
    --------
    >>> met_text(0.07, 0.08), met_text(0.07902, 0.07892), met_text(None, 0.08)
    ('yes', 'no (1.001×)', '—')
    """
    if ours is None or paper is None:
        return "—"
    return "yes" if ours <= paper else f"no ({ratio_text(ours / paper)})"


def median_ratio(pairs) -> float | None:
    """The median over ``(ours, paper)`` pairs of ours / paper (``None`` if a value is missing or none is given):
    below 1 where ours is below the paper's in more than half the cases, which a ratio of means is not.

    Examples
    --------
    >>> median_ratio([(0.125, 0.275), (0.0775, 0.0737), (0.0921, 0.0638)])  # doctest: +ELLIPSIS
    1.05...
    """
    pairs = list(pairs)
    if not pairs or any(a is None or not b for a, b in pairs):
        return None
    return float(np.median([a / b for a, b in pairs]))


def every_or_count(k: int, m: int, noun: str) -> str:
    """``every density`` where ``k == m``, else :func:`rfmap.core.wording.of_count` (``3 of 4 densities``).

    Examples
    --------
    >>> every_or_count(8, 8, "density"), every_or_count(7, 8, "grid side")
    ('every density', '7 of 8 grid sides')
    """
    return f"every {noun}" if m and k == m else of_count(k, m, noun)


def classical_lead(counts, noun: str = "case") -> str:
    """Over several tables, on how many cases the classical solver is ahead of the paper's method, from the
    ``(k, m)`` of each (:meth:`rfmap.paper.comparison.Comparison.classical_better`), by :func:`every_or_count`.

    Examples
    --------
    >>> classical_lead([(4, 4), (4, 4)], "density")
    'every density'
    >>> classical_lead([(3, 4), (4, 4)])
    '7 of 8 cases'
    """
    counts = list(counts)
    return every_or_count(sum(k for k, _ in counts), sum(m for _, m in counts), noun)


def times_lower(ratios) -> str:
    """How many times a classical solver's values are below the paper's method's, from the ratios ours / classical
    of the cases, to two digits: ``20 to 350 times lower than``; ``not in every case lower than`` where a ratio is
    at most 1.

    Examples
    --------
    >>> times_lower([19.7, 51.2, 346.0]), times_lower([0.8, 150.0])
    ('20 to 350 times lower than', 'not in every case lower than')
    """
    ratios = list(ratios)
    if min(ratios) <= 1:
        return "not in every case lower than"
    return f"{float(f'{min(ratios):.2g}'):g} to {float(f'{max(ratios):.2g}'):g} times lower than"


def _pair(case: str, title: str) -> str:
    """A (case, metric) pair as a noun phrase: ``the mean |Δμ| of T2``, ``the Std at N = 128``."""
    return f"the {title} {'at' if case.startswith('N = ') else 'of'} {case}"


def close_calls(rows) -> str:
    """The misses that say less than they seem, in sentences: those within :data:`NEAR_MISS` of the paper's value,
    and those where even the classical solver is above the paper's value (a value the discretisation on this mesh
    does not reach; pass ``None`` as the classical value of a metric the classical solver does not aim at, such as
    the flow solver's mean :math:`|\\mu|`); ``—`` where there are none (the chapters test for it).  Misses of one
    case are named together.  The verdict is unchanged: a miss is a miss.

    Parameters
    ----------
    rows : iterable of tuple
        ``(case, metric title, paper's method, paper, classical)`` for every comparable (case, metric) pair.

    Examples
    --------
    >>> rows = [("N = 128", "Std", 0.07902, 0.07892, 0.0094),
    ...         ("T2", "mean |Δμ|", 0.00877, 0.00629, 0.00635)]
    >>> print(close_calls(rows))  # doctest: +NORMALIZE_WHITESPACE
    The miss on the Std at N = 128 is within 0.5 % of the paper's value.
    On the mean |Δμ| of T2 even the classical solver is above the paper's value.
    >>> print(close_calls([("N = 128", "Std", 0.0790, 0.0789, 0.009),
    ...                    ("N = 128", "|μ|", 0.1981, 0.1974, None)]))
    At N = 128 both misses, on the Std and the |μ|, are within 0.5 % of the paper's values.
    >>> print(close_calls([("T1", "mean |Δμ|", 0.009, 0.017, 0.005)]))
    —
    """
    near, shared = {}, []
    for case, title, ours, paper, classical in rows:
        if ours is None or paper is None or ours <= paper:
            continue
        if ours <= paper * (1 + NEAR_MISS):
            near.setdefault(case, []).append(title)
        if classical is not None and classical > paper:
            shared.append(_pair(case, title))
    within = f"within {NEAR_MISS * 100:g} % of the paper's value"
    if not near and not shared:
        return "—"
    parts = []
    if len(near) == 1 and len(titles := next(iter(near.values()))) > 1:
        case = next(iter(near))
        both = "both misses" if len(titles) == 2 else f"all {len(titles)} misses"
        names = _and_join([f"the {t}" for t in titles])
        parts.append(f"{'At' if case.startswith('N = ') else 'On'} {case} {both}, on {names}, are {within}s.")
    elif near:
        pairs = [_pair(c, t) for c, ts in near.items() for t in ts]
        parts.append(f"The miss{'es' * (len(pairs) > 1)} on {_and_join(pairs)} {'are' if len(pairs) > 1 else 'is'} "
                     f"{within + 's' if len(pairs) > 1 else within}.")
    if shared:
        parts.append(f"On {_and_join(shared)} even the classical solver is above the paper's value.")
    return " ".join(parts)


def _and_join(items: list[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


#: The three kinds of map that the comparison of the paper's Fig. 10 asks its questions of, by their key in a
#: comparison's values (``"native"`` is the paper's method), with their names in the text.
FIG10_METHODS = {"raw": "raw network", "native": "the paper's method", "delivered": "delivered"}


def fig10_checks(table, method: str) -> dict[str, tuple[str, float, float]]:
    """The two questions of the paper's Fig. 10 for one method's maps of a two-model comparison
    (:func:`rfmap.paper.comparison.compare_models`), whose first case is the model without the Beltrami term (DEM,
    :math:`\\lambda_{\\mathrm{hr}} = 0`) and whose second is the model with it: does the second map fold fewer
    triangles than the first (``"fewer folded triangles"``), and is its mean ``|μ|`` lower (``"lower mean |mu|"``)?

    Returns, per question, the answer (``"yes"``, ``"no"``, or ``"tie"`` where the two values are equal), the second
    map's value and the first map's.
    """
    dem_map, deq_map = (table.values[(c.name, method)] for c in table.cases)

    def answer(a, b):
        return "tie" if a == b else "yes" if a < b else "no"

    return {check: (answer(deq_map[q], dem_map[q]), deq_map[q], dem_map[q])
            for check, q in (("fewer folded triangles", "n_flipped"), ("lower mean |mu|", "mean_mu"))}


def fig10_text(table) -> str:
    """:func:`fig10_checks` for the raw network's, the paper's method's and the delivered maps of a two-model
    comparison, as lines of text: per method, each question's answer with the two values."""
    without, with_term = (c.name for c in table.cases)
    lines = []
    for method, label in FIG10_METHODS.items():
        lines.append(f"{with_term} map against {without} map, {label}:")
        lines += [f"  {check}: {word} ({a:.3g} against {b:.3g})"
                  for check, (word, a, b) in fig10_checks(table, method).items()]
    return "\n".join(lines)
