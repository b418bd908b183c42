r"""Beyond the paper's test fields: the surrogates on unseen random fields, their angular distortion, and how far
the fields ask a map to move its points.

The unseen fields come from the *report stream* of :mod:`rfmap.training.validation`: random fields of the training
families drawn from a seed of their own, kept for reporting results and never drawn in training or used to choose a
model.
"""
from __future__ import annotations

import numpy as np

from ..core.inputs import preprocess_density
from ..core.mesh import grid_points
from ..fields.paper import PAPER_N, TEST_FIELDS, sample_density
from ..finish import quiet_quality
from ..solvers import solve_dem
from ..tasks import draw_samples
from ..training.config import get_config
from ..training.validation import validation_fields
from .reproduce import METHOD_TITLES, SYM, SYM_REF
from .tables import COLUMN_TITLES, Table, format_sig, power_of_ten

__all__ = ["generalization_table", "generalization_summary", "pivot_markdown", "columns_markdown",
           "distortion_table", "displacement_demand"]


@quiet_quality()
def generalization_table(sur, count: int = 50, n: int | None = None, refine: bool = True,
                         classical: bool = True, low_frequency: bool = False,
                         symmetrize: bool | str = False, inputs: bool = False) -> Table:
    """Surrogate against the classical solver on ``count`` seeded random fields that training never drew (the
    report stream, see the module's description), on the same ``N``-grid.

    Density models: Std(ρ̃_map) of the raw network map, of the map with weight refinement (and what
    ``Surrogate.map`` does by default about folds: coarser working grids in 3D, then the repair), and of the
    classical diffusion DEM with the model's boundary; Beltrami models: mean vertex distance (``mean_dd``) to the
    exact random map, ours against the Linear Beltrami Solver.  Rows: each kind of field and ``all``; columns: mean,
    median and worst metric, flipped elements of the map and the number of fields whose map folds (``folded``; the
    metric of a folded map is not a density spread, so read the median there), and mean time.
    ``classical=False`` leaves the classical solver's rows out (when another table already has them);
    ``low_frequency`` (Beltrami models) draws random maps of 1-4 slow modes instead (table
    ``tab:generalization-low-NAME``); ``symmetrize`` (density models) adds the network averaged over symmetries of
    the domain, with refinement and fold handling (:data:`~rfmap.paper.reproduce.SYM_REF`, or
    :data:`~rfmap.paper.reproduce.SYM` without ``refine``); ``inputs`` (density models) adds rows ``input``: the
    input's Std(ρ̃_orig), what the identity map leaves.
    """
    spec, task = sur.spec, sur.spec.task
    n = int(n or PAPER_N[spec.dim])
    fields = validation_fields(spec.kind, spec.dim, count, stream="report", low_frequency=low_frequency)
    key = task.score_metric
    rows: dict[tuple[str, str], list[tuple[float, int, float]]] = {}

    def add(kind, method, value, flips, t):
        for k in (kind, "all"):
            rows.setdefault((k, method), []).append((float(value), int(flips), float(t)))

    for vf in fields:
        kind = vf.label.rsplit("-", 1)[0]
        raw = sur.map(vf.field, n, repair=False)
        variants = [("ours", raw)]
        if refine:
            variants.append(("ours + refinement", sur.map(vf.field, n, refine=True)))
        if symmetrize:
            variants.append((SYM_REF if refine else SYM, sur.map(vf.field, n, refine=refine, symmetrize=symmetrize)))
        if classical:
            variants.append((f"classical ({task.reference_title})",
                             task.reference_of(vf.field, n, spec.dim, spec.boundary)))
        for method, r in variants:
            rec, value, _ = task.validation_record(r, vf)
            add(kind, method, value, rec["n_flipped"], r.time)
        if inputs and task.equalizes:
            add(kind, "input", raw.metrics().std_rho_orig, 0, 0.0)
    low = "low-" if low_frequency else ""
    table = Table(f"tab:generalization-{low}{sur.name}",
                  f"{sur.name}: {count} unseen {'low-frequency ' if low else ''}random fields at N = {n} "
                  f"({COLUMN_TITLES.get(key, key)})",
                  ["mean", "median", "worst", "n_flipped", "folded", "time"])
    kinds = sorted({k for k, _ in rows if k != "all"})
    kinds = kinds + ["all"] if len(kinds) > 1 else ["all"]
    methods = list(dict.fromkeys(m for _, m in rows))
    for k in kinds:
        for method in methods:
            vals = rows.get((k, method))
            if vals:
                v = np.array([x[0] for x in vals])
                table.add(k, method, {"mean": float(v.mean()), "median": float(np.median(v)),
                                      "worst": float(v.max()), "fields": len(v),
                                      "n_flipped": int(sum(x[1] for x in vals)),
                                      "folded": int(sum(x[1] > 0 for x in vals)),
                                      "time": float(np.mean([x[2] for x in vals]))})
    return table


def generalization_summary(table: Table, column: str = "mean") -> str:
    """The headline of a :func:`generalization_table` as Markdown: one row per kind of field (and ``all``), one
    column per method with its ``column`` (the mean metric by default), then the best surrogate value over the
    classical solver's (below 1: the surrogate is better)."""
    methods = list(dict.fromkeys(m for _, m, _ in table.rows))
    classical = next((m for m in methods if m.startswith("classical")), None)
    ours = [m for m in methods if m != classical]
    head = ["fields"] + [METHOD_TITLES.get(m, m) for m in ours]
    head += [METHOD_TITLES.get(classical, classical), "best ours / classical"] if classical else []
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for kind in dict.fromkeys(c for c, _, _ in table.rows):
        vals = {m: v.get(column) for c, m, v in table.rows if c == kind}
        cells = [kind] + _one_notation([vals.get(m) for m in ours + ([classical] if classical else [])])
        if classical:
            best, ref = min(vals[m] for m in ours if vals.get(m) is not None), vals.get(classical)
            cells += [f"{best / ref:.3g}×" if ref else "—"]
        lines.append("| " + " | ".join(cells) + " |")
    kinds = list(dict.fromkeys(c for c, _, _ in table.rows))
    over = "over all its fields" if kinds == ["all"] else "per kind of field"
    best = ("; *best ours / classical* is the lowest of the network's columns over the classical solver's"
            if classical else "")
    return f"**{table.title}**: the {column} of each method {over}, lower is better{best}\n\n" + "\n".join(lines)


def _one_notation(values) -> list[str]:
    """Numbers by :func:`format_sig`, all as powers of ten when any of them is one, so that a row reads in one
    notation (``1.12 × 10⁻³`` beside ``6.46 × 10⁻⁵``, not ``0.00112``)."""
    texts = [format_sig(v) for v in values]
    if any("×" in t for t in texts):
        texts = [power_of_ten(float(v), 3) if t != "—" and float(v) != 0 else t for v, t in zip(values, texts)]
    return texts


def pivot_markdown(columns: dict, column: str = "mean", title: str = "") -> str:
    """Several :func:`generalization_table` results side by side as one Markdown table: a row per kind of field
    (and ``all``) with its number of fields ``n``, a column per entry of ``columns`` (``{heading: (table,
    method)}``) holding that method's ``column`` (the mean metric by default) to three significant digits.  The
    kinds and their counts are those of the first table; every table must hold the same fields."""
    first = next(iter(columns.values()))[0]
    head = ["fields", "n"] + list(columns)
    lines = ["| " + " | ".join(h.replace("|", "\\|") for h in head) + " |", "|" + "---|" * len(head)]
    for kind in dict.fromkeys(c for c, _, _ in first.rows):
        n = next(v.get("fields") for c, _, v in first.rows if c == kind)
        cells = [kind, "—" if n is None else str(n)]
        cells += [format_sig(t.value(kind, m, column)) for t, m in columns.values()]
        lines.append("| " + " | ".join(cells) + " |")
    return (f"**{title}**\n\n" if title else "") + "\n".join(lines)


def columns_markdown(table: Table, columns: dict, *, method: str | None = None, case: str | None = None,
                     first: str = "case", title: str | None = None) -> str:
    """Chosen columns of a :class:`~rfmap.paper.tables.Table` as one Markdown table, to three significant digits:
    ``columns`` is ``{column: heading}``; one row per row of the table (only those of ``method`` when given,
    labelled by their case; only those of ``case`` when given, labelled by their method; else by case and method,
    or by case where no case repeats); ``first`` heads the label column; ``title`` (default the
    table's) is set in bold above it, ``""`` for none."""
    rows = [(c, m, v) for c, m, v in table.rows
            if (method is None or m == method) and (case is None or c == case)]
    head = [first] + list(columns.values())
    lines = ["| " + " | ".join(h.replace("|", "\\|") for h in head) + " |", "|" + "---|" * len(head)]
    for c, m, v in rows:
        if case is not None:
            label = m
        else:
            label = c if method is not None or len({c for c, _, _ in rows}) == len(rows) else f"{c}, {m}"
        lines.append("| " + " | ".join([label] + [format_sig(v.get(k)) for k in columns]) + " |")
    title = table.title if title is None else title
    return (f"**{title}**\n\n" if title else "") + "\n".join(lines)


@quiet_quality()
def distortion_table(surs: dict, count: int = 50, n: int | None = None) -> Table:
    r"""Density equalization against angular distortion of several 2D density models on the same ``count`` unseen
    random fields (the ``report`` stream of :mod:`rfmap.training.validation`), raw network maps on the ``N``-grid.

    For each model and each kind of field (and ``all``): the mean, median and worst Std(ρ̃_map), the mean over fields
    of the mean :math:`|\mu|` over triangles, the largest :math:`|\mu|`, the smallest Jacobian and the flipped
    triangles; the last column is each field's mean :math:`|\mu|` divided by that of the first model on the same
    field, averaged over the fields.  A DEQ loss (the density loss plus :math:`\lambda_{\mathrm{hr}}` times the
    Beltrami energy :math:`\int|\mu|^2`, paper Eq. (3)) should lower the mean :math:`|\mu|` against a pure DEM loss
    at about the same Std(ρ̃_map).

    Parameters
    ----------
    surs : dict
        ``{label: Surrogate}`` of 2D density models; the first is the reference of the ratio column.
    count : int
        Unseen fields (4 kinds, in turn).
    n : int, optional
        Grid side (default the paper's 51).

    Returns
    -------
    Table
        ``tab:distortion``: rows ``(kind, label)``, columns ``std_rho_map`` (the mean), ``median``, ``worst``,
        ``mean_mu``, ``max_mu``, ``min_jacobian``, ``n_flipped``, ``mu_ratio``.
    """
    if not surs:
        raise ValueError("distortion_table needs at least one model")
    for label, sur in surs.items():
        if not sur.spec.task.equalizes or sur.spec.dim != 2:
            raise ValueError(f"{label}: distortion_table compares 2D density models, got {sur.spec.kind} "
                             f"{sur.spec.dim}D")
    n = int(n or PAPER_N[2])
    fields = validation_fields("density", 2, count, stream="report")
    per: dict[tuple[str, str], list[tuple[float, float, float, int, float, float]]] = {}
    first = next(iter(surs))
    for vf in fields:
        kind = vf.label.rsplit("-", 1)[0]
        ms = {label: sur.map(vf.field, n, repair=False).metrics() for label, sur in surs.items()}
        ref = ms[first].mean_mu
        for label, m in ms.items():
            vals = (m.std_rho_map, m.mean_mu, m.max_mu, m.n_flipped, m.mean_mu / ref if ref > 0 else np.nan,
                    m.min_jacobian)
            for k in (kind, "all"):
                per.setdefault((k, label), []).append(vals)
    table = Table("tab:distortion", f"{len(fields)} unseen random densities at N = {n}: equalization and "
                  f"angular distortion of the raw maps (mean |μ| ratio: against {first} on the same field)",
                  ["std_rho_map", "median", "worst", "mean_mu", "max_mu", "min_jacobian", "n_flipped",
                   "mu_ratio"])
    kinds = sorted({k for k, _ in per if k != "all"}) + ["all"]
    for k in kinds:
        for label in surs:
            v = np.array(per[(k, label)])
            table.add(k, label, {"std_rho_map": float(v[:, 0].mean()), "median": float(np.median(v[:, 0])),
                                 "worst": float(v[:, 0].max()),
                                 "mean_mu": float(v[:, 1].mean()),
                                 "max_mu": float(v[:, 2].max()), "min_jacobian": float(v[:, 5].min()),
                                 "n_flipped": int(v[:, 3].sum()),
                                 "mu_ratio": float(v[:, 4].mean())})
    return table


@quiet_quality()
def displacement_demand(sur, count: int = 16, train_count: int = 60, n: int | None = None) -> tuple[Table, list]:
    r"""How far each field asks the map to move its points, and how far the network moves them.

    For a 2D or 3D density model: the *demand* of a field is the largest vertex displacement
    :math:`\max_i |u(x_i) - x_i|` of the classical diffusion DEM's map (the model's boundary), its *reach* that of
    the raw network map, on the same ``N``-grid.  Three groups of fields: ``train_count`` draws of the model's
    own training distribution (its ``full`` configuration, samples 0 of steps 0, 1, ..., on the grid without
    jitter), the ``count`` unseen fields of each kind of the ``report`` stream (smooth, steps, peak, ramp), and the
    paper's test fields.

    Returns
    -------
    (table, records)
        The table has one row per group and kind: the median and 90th percentile of the demand, the median reach
        over demand, the median fraction of the non-uniformity left (Std(ρ̃_map) / Std(ρ̃_orig)) by the
        network and by the classical map.  ``records`` holds one dict per field (``group``, ``label``,
        ``demand``, ``reach``, ``left_net``, ``left_classical``, ``n_flipped``) for
        :func:`rfmap.viz.studies.displacement_demand_figure`.
    """
    spec = sur.spec
    if not spec.task.equalizes:
        raise ValueError(f"displacement_demand needs a density model, got a {spec.kind} model")
    n = int(n or PAPER_N[spec.dim])
    shape = (n,) * spec.dim
    pts = grid_points(n, spec.dim)
    boundary = "free" if spec.boundary == "free" else "square"
    cfg = get_config(sur.name, "full")
    fields: list[tuple[str, str, np.ndarray]] = []
    for t in range(int(train_count)):
        _, par = draw_samples(cfg.task, seed=cfg.seed, step=t, indices=[0], n=n, jitter=0.0,
                              density_cfg=cfg.density_field)
        fields.append(("training", f"train-{t}", par[0].reshape(shape)))
    for vf in validation_fields("density", spec.dim, int(count), stream="report"):
        fields.append((vf.label.rsplit("-", 1)[0], vf.label, preprocess_density(vf.field(pts).reshape(shape))))
    for name in TEST_FIELDS["density", spec.dim]:
        fields.append(("paper", name, sample_density(name, n)))
    records = []
    for group, label, dens in fields:
        net = sur.map(dens, n, repair=False)
        cl = solve_dem(dens, boundary=boundary, progress=False)
        mn, mc = net.metrics(), cl.metrics()
        records.append({"group": group, "label": label,
                        "demand": float(np.linalg.norm(cl.mapped_points - cl.ref_points, axis=1).max()),
                        "reach": float(np.linalg.norm(net.mapped_points - net.ref_points, axis=1).max()),
                        "left_net": mn.std_rho_map / mn.std_rho_orig,
                        "left_classical": mc.std_rho_map / mc.std_rho_orig,
                        "n_flipped": int(mn.n_flipped)})
    table = Table(f"tab:displacement-demand-{sur.name}",
                  f"{sur.name}: displacement the classical map needs (demand) and the network's (reach), N = {n}",
                  ["count", "demand_median", "demand_p90", "reach_ratio", "left_net", "left_classical"])
    for group in dict.fromkeys(r["group"] for r in records):
        rs = [r for r in records if r["group"] == group]
        d = np.array([r["demand"] for r in rs])
        table.add(group, "ours" if group != "training" else "training draws",
                  {"count": len(rs), "demand_median": float(np.median(d)), "demand_p90": float(np.quantile(d, 0.9)),
                   "reach_ratio": float(np.median([r["reach"] / r["demand"] for r in rs])),
                   "left_net": float(np.median([r["left_net"] for r in rs])),
                   "left_classical": float(np.median([r["left_classical"] for r in rs]))})
    return table, records
