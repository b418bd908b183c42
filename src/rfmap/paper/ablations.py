r"""What weight refinement does to the paper's test cases: the network run natively with :math:`\alpha = 1` against
the same map refined (the paper's method, Sec. 4.3).

Refinement minimises an objective over the stretching vector :math:`\alpha`, starting from :math:`\alpha = 1`, and
never returns a larger objective than :math:`\alpha = 1`.  The objective is not the training loss: for every density
model, DEM and DEQ alike, it is Std(ρ̃_map) plus :math:`\lambda` times the share of flipped elements
(:func:`rfmap.tasks.objectives.density_objective`, no Beltrami term); for a Beltrami model it is the mean
:math:`|\mu(u_\alpha) - \mu_{\text{in}}|` plus the same fold term (:func:`rfmap.tasks.objectives.beltrami_objective`).
On a fold-free density map the objective is the Std(ρ̃_map) the paper's tables score; the Beltrami tables score the
mean ``|Δd|``, which refinement does not minimise and may raise: :func:`refinement_study` measures both.
"""
from __future__ import annotations

from ..finish import quiet_quality
from ..core.wording import power_of_ten
from .comparison import DIGITS, format_number
from .tables import Table

__all__ = ["refinement_study", "refinement_summary", "refinement_markdown"]


@quiet_quality()
def refinement_study(sur, fields, n: int, title: str = "") -> Table:
    r"""Per field, the network on the ``n``-grid itself (``native=True``, no repair) with :math:`\alpha = 1` and refined:
    the table's metric (the task's ``score_metric``: ``std_rho_map`` of a density model, ``mean_dd`` of a Beltrami
    model, :meth:`rfmap.tasks.base.Task.test_record`), the refinement
    objective at :math:`\alpha = 1` and at the refined :math:`\alpha`, and :math:`\alpha`.

    Parameters
    ----------
    sur : rfmap.Surrogate
    fields : sequence of str
        Built-in fields of the surrogate's kind and dimension.
    n : int
    title : str

    Returns
    -------
    Table
        Rows ``(field, "α = 1")`` and ``(field, "refined")`` with columns ``metric``, ``objective`` and ``alpha``;
        a column of which some cell prints as a power of ten prints every cell so (``9.931 × 10⁻⁴`` beside
        ``1.946 × 10⁻³``, not ``0.001946``).
    """
    task = sur.spec.task
    metric = task.score_metric
    t = Table("tab:refinement", title or f"Weight refinement on the {sur.name} test fields, N = {n}",
              ["metric", "objective", "alpha"])
    for f in fields:
        raw = sur.map(f, n, native=True, repair=False)
        ref = sur.map(f, n, native=True, repair=False, refine=True)
        for label, res in (("α = 1", raw), ("refined", ref)):
            values = task.test_record(res, f)
            objective = ref.info["refine_objective_start" if label == "α = 1" else "refine_objective"]
            t.add(f, label, {"metric": values[metric], "objective": float(objective),
                             "alpha": list(res.info["alpha"])})
    for col in ("metric", "objective"):  # one notation a column: all powers of ten where any cell is one
        if any("×" in t.cell(v[col], col) for _, _, v in t.rows):
            t.formats[col] = lambda v: power_of_ten(float(v), DIGITS)
    return t


def refinement_summary(table: Table) -> dict:
    """Counts over the fields of a :func:`refinement_study`: ``fields``, ``objective_lowered`` (refinement lowered its
    objective, or kept it: never raised), ``metric_lowered`` and ``metric_raised`` (the table's metric, its unrounded
    values compared, the rule of the Beltrami chapter too), ``raised`` (the fields whose metric rose),
    ``raised_unprinted`` (those of them whose rise is below the printed precision, so that the table prints the same
    value twice), and the ``worst`` field (largest rise of the metric, relative) with its two values as text."""
    fields = list(dict.fromkeys(c for c, _, _ in table.rows))
    out = {"fields": len(fields), "objective_lowered": 0, "metric_lowered": 0, "metric_raised": 0,
           "raised": [], "raised_unprinted": []}
    worst, rise = None, 0.0
    for f in fields:
        a, r = (table.value(f, m, "metric") for m in ("α = 1", "refined"))
        oa, o = (table.value(f, m, "objective") for m in ("α = 1", "refined"))
        out["objective_lowered"] += int(o <= oa)
        out["metric_lowered"] += int(r < a)
        out["metric_raised"] += int(r > a)
        if r > a:
            out["raised"].append(f)
            if format_number(r) == format_number(a):  # a rise the table does not print
                out["raised_unprinted"].append(f)
        if a > 0 and r / a - 1 > rise:
            worst, rise = f, r / a - 1
    out["worst"] = "none" if worst is None else (
        "{}, from {} to {}".format(worst, *_one_notation(table.value(worst, m, "metric")
                                                        for m in ("α = 1", "refined"))))
    return out


def _one_notation(values) -> list[str]:
    """Numbers by :func:`format_number`, all as powers of ten when any of them is one, so that the two ends of a
    change read in one notation (``9.931 × 10⁻⁴ to 1.026 × 10⁻³``, not ``9.931 × 10⁻⁴ to 0.001026``)."""
    values = [float(v) for v in values]
    texts = [format_number(v) for v in values]
    if any("×" in t for t in texts):
        texts = [power_of_ten(v, DIGITS) for v in values]
    return texts


def refinement_markdown(studies: dict) -> str:
    """One row per model of ``{name: refinement_study(...)}``: the fields, on how many refinement did not raise its
    objective, lowered and raised the table's metric, and the largest rise (:func:`refinement_summary`)."""
    head = ["model", "fields", "objective not raised", "metric lowered", "metric raised", "largest rise"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, table in studies.items():
        s = refinement_summary(table)
        lines.append(f"| {name} | {s['fields']} | {s['objective_lowered']} | {s['metric_lowered']} | "
                     f"{s['metric_raised']} | {s['worst']} |")
    return "\n".join(lines)
