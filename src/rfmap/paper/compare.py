r"""Two surrogates of one task side by side: the paper's multi-resolution U-Net against a Fourier neural operator.

Every function takes ``surs``, a mapping from a display name to a :class:`rfmap.Surrogate` of the same task, and
returns an :class:`rfmap.paper.tables.Table` whose ``method`` column names the model (and the variant).  The metric
is :math:`\operatorname{Std}(\tilde\rho_{map})` (``std_rho_map``, lower is better); ``n_flipped`` counts flipped
triangles of the *raw* network map (``repair=False``) and ``flips_repaired`` those of the map a user gets (with the
default bijectivity repair), which must be 0.

The two architectures meet the grid differently.  The U-Net's receptive field is counted in grid cells, so the
surrogate normally runs it on a fixed *working grid* near its training sizes and resamples (``work``); the FNO's
spectral weights act on frequencies and can be run on the requested grid itself (``native``).
:func:`resolution_table` measures both ways for both models.
"""
from __future__ import annotations

import time

import numpy as np

from ..core.mesh import jittered_points
from ..fields import sample_density
from ..fields.paper import PAPER_N, TEST_FIELDS
from ..finish import quiet_quality
from ..solvers import solve_dem
from ..training.validation import has_folds, score_parts
from .generalization import generalization_table
from .comparison import format_time
from .tables import Table, format_sig

__all__ = ["NETWORK_NAMES", "parameter_count", "model_table", "validated_states", "learning_summary", "kept_state",
           "shipped_raw_folds", "budget_folds", "kept_rules", "learning_verdict", "paper_fields_table", "resolution_table",
           "points_table", "generalization_tables", "inference_table", "speed_against_flow", "speed_table", "wins",
           "folded_cell", "side_by_side", "MarkdownText"]


#: The printed name of each network architecture (``arch`` of a model's settings) in :func:`model_table`, where a
#: model's own name does not already say it.
NETWORK_NAMES = {"unet": "U-Net", "fno": "FNO"}


def parameter_count(model) -> int:
    """Real parameters of a network (a complex weight counts twice)."""
    return int(sum(p.numel() * (2 if p.is_complex() else 1) for p in model.parameters()))


def _check(surs: dict) -> tuple:
    if not surs:
        raise ValueError("give at least one surrogate to compare")
    specs = {s.spec for s in surs.values()}
    if len(specs) != 1:
        raise ValueError(f"the surrogates solve different tasks: {sorted(map(str, specs))}")
    spec = specs.pop()
    if not spec.task.equalizes or spec.dim != 2:
        raise ValueError(f"the comparison covers 2D density models; got {spec}")
    return spec


def model_table(surs: dict) -> Table:
    """Each model's training configuration (its ``name``), parameters, the step whose weights were kept, wall time
    in minutes (cumulative over ``--init`` chains), and three held-out validation numbers of its kept weights, from
    its metadata.

    ``held-out mean`` is the plain mean Std(ρ̃_map) over the held-out fields (a folded map's own Std included);
    ``held-out, folds as identity`` the same mean with a folded map counted as the identity (the ``penalized``
    entry where recorded, else the plain mean); ``checkpoint score`` is the score that chose the kept weights
    (:func:`rfmap.training.validation.score`: the mean over field families of Std(ρ̃_map) / Std(ρ̃_orig)), ``None``
    where the model's training record has none and the weights were chosen by the held-out mean.  The Markdown
    prints parameters and the kept step with thousands separators and the other numbers to three significant digits,
    as the chapter's prose.  The configuration is followed by the network's name (:data:`NETWORK_NAMES`) where the
    model's own name is not already that name.
    """
    _check(surs)
    sig, whole = (lambda v: f"{v:#.3g}".rstrip(".")), (lambda v: f"{v:,}")  # 0.220 and 594, as the prose
    plain, ident = "held-out mean", "held-out, folds as identity"
    t = Table("tab:models", "The models",
              ["parameters", "kept step", "training (min)", plain, ident, "checkpoint score"],
              heads=("model", "configuration"),
              formats={"parameters": whole, "kept step": whole, "training (min)": sig, plain: sig, ident: sig,
                       "checkpoint score": sig})
    for name, s in surs.items():
        meta = s.meta
        mean = (meta.get("final_metrics") or {}).get("mean") or {}
        # a folded map counted as the identity where recorded, else the plain mean (then no held-out map folded)
        val = mean.get("penalized", mean.get("std_rho_map"))
        kept = meta.get("selected_step")
        arch = s.model.kwargs().get("arch", "unet")
        net = NETWORK_NAMES.get(arch, arch)
        t.add(name, str(meta.get("name", name)) + ("" if name == net else f" ({net})"),
              {"parameters": parameter_count(s.model),
               "kept step": None if kept is None else int(kept),
               "training (min)": float(meta.get("cumulative_wall_time", meta.get("wall_time", 0.0))) / 60.0,
               plain: None if "std_rho_map" not in mean else float(mean["std_rho_map"]),
               ident: None if val is None else float(val),
               "checkpoint score": None if "family_score" not in mean else float(mean["family_score"])})
    return t


def validated_states(meta: dict) -> list[dict]:
    """The distinct validated states of a model's training record, in order.

    The record ends with the kept state evaluated again at the last step.  Where the last state's own validation
    was logged too, the step repeats and the first entry is kept; in older records, which did not log it, the last
    entry repeats the kept step's numbers exactly and is left out (it is not a measurement of the last state).

    Parameters
    ----------
    meta : dict
        A surrogate's metadata (``history["validation"]``, one summary per validation, and ``selected_step``).

    Returns
    -------
    list of dict
        One validation summary per validated step.
    """
    seen, hist = set(), []
    for v in (meta.get("history") or {}).get("validation", []):
        if v["step"] not in seen:
            seen.add(v["step"])
            hist.append(v)
    kept = meta.get("selected_step")
    if len(hist) > 1 and kept is not None and hist[-1]["step"] != kept:
        twin = next((v for v in hist if v["step"] == kept), None)
        same = ("std_rho_map", "min_jacobian")
        if twin is not None and all(twin.get(k) == hist[-1].get(k) for k in same):
            hist.pop()
    return hist


def shipped_raw_folds(meta: dict) -> tuple[int, int]:
    """On how many held-out validation fields the raw map of a model's shipped weights folds.

    Reads the validation of the shipped state that the metadata keeps (``final_metrics``), one entry per held-out
    field (each field at each of its grid sides).  A field counts where the network's raw map, before refinement or
    repair, has a flipped element: its ``raw_folded`` flag where the run validated the repaired map, else its own
    ``n_flipped`` (the run validated the raw map).

    Parameters
    ----------
    meta : dict
        A surrogate's metadata.

    Returns
    -------
    tuple of int
        ``(folded, fields)``: the fields whose raw map folds and the held-out fields validated; ``(0, 0)`` where
        the metadata keeps no final validation.
    """
    final = meta.get("final_metrics") or {}
    fields = [v for k, v in final.items() if k != "mean"]
    folded = sum(bool(v["raw_folded"]) if "raw_folded" in v else (v.get("n_flipped") or 0) > 0 for v in fields)
    return folded, len(fields)


def budget_folds(metas: dict, paper_steps: dict):
    """Each shipped model's steps against the paper's and the folds of its raw maps, from its training record.

    Parameters
    ----------
    metas : dict
        Model name to a surrogate's metadata (``Surrogate.meta``).
    paper_steps : dict
        Model name to the paper's epochs for its task.

    Returns
    -------
    pandas.DataFrame
        One row per model: the steps spent over its whole chain of runs, the step of the chain at which the shipped
        state was validated, the paper's epochs, the validated states of the last run (:func:`validated_states`)
        whose raw map folds on some validation field (``"3 of 32"``; a record that validated the repaired map counts
        its ``raw_folded_fields``) and the fields on which the shipped raw map folds (:func:`shipped_raw_folds`).
    """
    import pandas as pd

    rows = []
    for name, meta in metas.items():
        spent = int(meta.get("cumulative_steps", meta.get("steps", 0)))
        last = int(meta.get("steps", spent))  # the steps of the chain's last run
        states = validated_states(meta)
        folded = sum(has_folds(v, raw=True) for v in states)
        rows.append({"model": name, "steps spent": spent,
                     "shipped at step": spent - last + int(meta.get("selected_step", last)),
                     "paper's epochs": int(paper_steps[name]),
                     "validated states whose raw map folds": f"{folded} of {len(states)}",
                     "validation fields on which the shipped raw map folds": "{} of {}".format(
                         *shipped_raw_folds(meta))})
    return pd.DataFrame(rows).set_index("model")


def learning_summary(meta: dict, last: int = 3) -> dict:
    """What a model's validation record says about its learning curve.

    Parameters
    ----------
    meta : dict
        A surrogate's metadata; its validated states are those of :func:`validated_states`.
    last : int
        How many of the last validations are set against the earlier ones.

    Returns
    -------
    dict
        ``states`` (distinct validated steps), ``folded`` (of them, those whose map folded on some field),
        ``fold_free_steps`` (the steps of the others), ``best`` and ``best_step`` (the lowest plain held-out mean
        Std(ρ̃_map) and its step), ``last_best`` (the lowest over the last ``last``), ``earlier_best`` (over the
        others), ``improving`` (whether ``last_best`` is below ``earlier_best``), ``last_range`` ((min, max) over
        the last ``last``), ``last_steps`` (their steps) and ``kept_step``.
    """
    hist = validated_states(meta)
    means = np.array([float(v["std_rho_map"]) for v in hist])
    folds = [has_folds(v) for v in hist]
    i = int(np.argmin(means))
    tail, head = means[-last:], means[:-last]
    earlier = float(head.min()) if len(head) else float("inf")
    return {"states": len(hist), "folded": int(sum(folds)),
            "fold_free_steps": [int(v["step"]) for v, f in zip(hist, folds) if not f],
            "best": float(means[i]), "best_step": int(hist[i]["step"]),
            "last_best": float(tail.min()), "earlier_best": earlier, "improving": bool(tail.min() < earlier),
            "last_range": (float(tail.min()), float(tail.max())),
            "last_steps": [int(v["step"]) for v in hist[-last:]], "kept_step": meta.get("selected_step")}


def kept_state(meta: dict) -> dict:
    """How a model's kept weights were chosen, how they do on the held-out fields, and what the fold-free rule keeps.

    Three rules have chosen the kept state among the validated ones (:func:`validated_states`), read from the
    kept state's validation summary as :func:`rfmap.training.validation.score_parts` ranks it: the *checkpoint
    score* (:func:`rfmap.training.validation.score`, where the record has it); in older records, the *earlier
    rule*, the held-out mean Std(ρ̃_map) with a folded map counted as the identity (where the record has that
    mean); and in the oldest, the *first runs' rule*, the lowest plain held-out mean Std(ρ̃_map) among the states
    whose maps fold on no held-out field.

    Parameters
    ----------
    meta : dict
        A surrogate's metadata: ``history``, ``selected_step`` and ``final_metrics`` (the kept state's validation,
        field by field, keys such as ``"ramp-3@128"``).

    Returns
    -------
    dict
        ``step`` (the kept step), ``rule`` (``"checkpoint score"``, ``"earlier rule"`` or ``"fold-free mean"``, the
        first runs' rule),
        ``mean`` (the kept
        state's plain held-out mean), ``folds`` (a list of ``(field, N, flipped triangles)``, one per held-out
        field on which the kept map folds), ``fold_free_step`` and ``fold_free_mean`` (the state the first runs'
        rule keeps, ``None`` if every state folds) and ``fold_free_score`` (its checkpoint score, or
        ``None``), ``score`` (the kept state's checkpoint score, or ``None``).
    """
    final = meta.get("final_metrics") or {}
    mean = final.get("mean") or {}
    folds = []
    for key, m in final.items():
        if "@" in key and (m.get("n_flipped") or 0) > 0:
            field, n = key.rsplit("@", 1)
            folds.append((field, int(n), int(m["n_flipped"])))
    free = [v for v in validated_states(meta) if not has_folds(v)]
    best = min(free, key=lambda v: float(v["std_rho_map"])) if free else None
    entry = score_parts(mean)[2] if mean else "mean"
    rule = ("checkpoint score" if entry == "family_score" else
            "earlier rule" if entry == "penalized" or "penalized" in mean else "fold-free mean")
    return {"step": meta.get("selected_step"), "rule": rule,
            "mean": None if "std_rho_map" not in mean else float(mean["std_rho_map"]),
            "folds": sorted(folds),
            "fold_free_step": None if best is None else int(best["step"]),
            "fold_free_mean": None if best is None else float(best["std_rho_map"]),
            "fold_free_score": None if best is None or "family_score" not in best else float(best["family_score"]),
            "score": None if "family_score" not in mean else float(mean["family_score"])}


def _row(res, raw) -> dict:
    m, mr = res.metrics(), raw.metrics()
    return {"std_rho_map": m.std_rho_map, "raw_std": mr.std_rho_map, "n_flipped": mr.n_flipped,
            "flips_repaired": m.n_flipped, "time": res.time, "std_rho_orig": m.std_rho_orig}


@quiet_quality()
def paper_fields_table(surs: dict, n: int | None = None, fields=None, refine: bool = True) -> Table:
    """The paper's four 2D population tests at ``N``: raw and refined Std, raw and repaired flips, per model, and
    the input's Std (``std_rho_orig``)."""
    _check(surs)
    n = int(n or PAPER_N[2])
    fields = list(fields or TEST_FIELDS["density", 2])
    t = Table("tab:fno-paper-fields", f"The paper's 2D tests (N = {n})",
              ["raw_std", "std_rho_map", "n_flipped", "flips_repaired", "time", "std_rho_orig"])
    for f in fields:
        for name, s in surs.items():
            raw = s.map(f, n, repair=False)
            t.add(f, name, _row(s.map(f, n), raw))
            if refine:
                t.add(f, f"{name} + refinement", _row(s.map(f, n, refine=True), raw))
    return t


@quiet_quality()
def resolution_table(surs: dict, ns=(32, 51, 64, 128, 256), field: str = "multi-freq") -> Table:
    """One field across grid sides: each model on its default working grid (``work``) and on the requested grid
    itself (``native``, ``work_n = N``)."""
    _check(surs)
    t = Table("tab:fno-resolution", f"{field} across resolutions",
              ["raw_std", "std_rho_map", "n_flipped", "flips_repaired", "time"])
    for n in ns:
        for name, s in surs.items():
            for how, work in (("work", None), ("native", int(n))):
                if work is not None and work < s.model.min_size:
                    continue
                raw = s.map(field, n, work_n=work, repair=False)
                row = _row(s.map(field, n, work_n=work), raw)
                row["work_n"] = int(raw.info.get("work_n", work or n))
                t.add(str(n), f"{name} ({how})", row)
    t.columns.insert(0, "work_n")
    return t


@quiet_quality()
def points_table(surs: dict, field: str = "sin-cos", n: int = 51, seed: int = 0) -> Table:
    """The map at query points instead of the grid: ``n**2`` points jittered off the grid (Sobol jitter of
    strength 0.2) and as many points scattered uniformly (plus the square's corners); the metrics are taken on the
    Delaunay triangulation of the points."""
    _check(surs)
    rng = np.random.default_rng(seed)
    jit = jittered_points(n, 2, rng, strength=0.2)
    sc = np.concatenate([rng.random((n * n - 4, 2)), [[0, 0], [1, 0], [0, 1], [1, 1]]])
    t = Table("tab:fno-points", f"{field} at {n * n} query points", ["raw_std", "std_rho_map", "n_flipped",
                                                                      "flips_repaired", "time"])
    for label, pts in (("jittered", jit), ("scattered", sc)):
        for name, s in surs.items():
            raw = s.map(field, points=pts, repair=False)
            t.add(label, name, _row(s.map(field, points=pts), raw))
    return t


def generalization_tables(surs: dict, count: int = 50, n: int | None = None) -> Table:
    """:func:`rfmap.paper.generalization.generalization_table` of every model on the same unseen random fields, merged
    (the classical solver's rows and the inputs' Std(ρ̃_orig), method ``input``, once)."""
    _check(surs)
    merged = None
    for name, s in surs.items():  # the classical solver once: every model sees the same fields and boundary
        g = generalization_table(s, count=count, n=n, refine=True, classical=merged is None, inputs=merged is None)
        if merged is None:
            merged = Table("tab:fno-generalization", g.title.split(":", 1)[1].strip(), g.columns)
        for case, method, vals in g.rows:
            if method.startswith("classical") or method == "input":
                if not any(c == case and m == method for c, m, _ in merged.rows):
                    merged.add(case, method, vals)
            else:
                merged.add(case, method.replace("ours", name), vals)
    order = list(dict.fromkeys(c for c, _, _ in merged.rows if c != "all")) + ["all"]
    merged.rows.sort(key=lambda r: order.index(r[0]))  # stable: within a kind, the insertion order
    return merged


@quiet_quality()
def inference_table(surs: dict, ns=(51, 128, 256), field: str = "multi-freq", repeats: int = 5) -> Table:
    """Median time of one raw network map (encoding, network, resampling; no refinement, no repair) per model and
    grid side, on the default working grid and natively."""
    _check(surs)
    t = Table("tab:fno-inference", f"Inference time of one raw map ({field})", ["work_n", "time"])
    for n in ns:
        for name, s in surs.items():
            for how, work in (("work", None), ("native", int(n))):
                s.map(field, n, work_n=work, repair=False)  # warm-up
                ts = []
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    r = s.map(field, n, work_n=work, repair=False)
                    ts.append(time.perf_counter() - t0)
                t.add(str(n), f"{name} ({how})", {"work_n": int(r.info.get("work_n", n)),
                                                   "time": float(np.median(ts))})
    return t


def speed_against_flow(surs: dict, n: int = 51, field: str = "multi-freq", repeats: int = 9) -> dict:
    """Median wall time of one raw map per model (encoding, network, resampling; no refinement, no repair) and of
    the flow solver (:func:`rfmap.solvers.solve_dem` with ``method="flow"``, the fastest classical solver) on the
    same field and grid, each after an untimed first run, with the Std(ρ̃_map) each leaves:
    ``{name: {"time": s, "std_rho_map": v}}``, the models first, then ``"flow solver"``."""
    _check(surs)
    if repeats < 1:
        raise ValueError(f"repeats must be at least 1, got {repeats}")
    rho = sample_density(field, int(n))
    runs = {name: (lambda s=s: s.map(field, n, repair=False)) for name, s in surs.items()}
    runs["flow solver"] = lambda: solve_dem(rho, method="flow")
    out = {}
    with quiet_quality():  # the result reports each map's Std itself
        for name, run in runs.items():
            r = run()  # untimed first run
            ts = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                run()
                ts.append(time.perf_counter() - t0)
            out[name] = {"time": float(np.median(ts)), "std_rho_map": float(r.metrics().std_rho_map)}
    return out


def speed_table(speed: dict) -> "MarkdownText":
    """The result of :func:`speed_against_flow` as a Markdown table (one row per model and the flow solver: the
    median time with its unit and the Std(ρ̃_map) the map leaves), shown as a table when it is a cell's value.
    Given ``{N: result}`` for several grid sides, one row per side instead, with a time and a Std column per
    method."""
    first = next(iter(speed.values()))
    if "time" in first:
        lines = ["| method | time of one map | Std ρ̃ map |", "|---|---|---|"]
        lines += [f"| {name} | {format_time(v['time'])} | {format_sig(v['std_rho_map'])} |"
                  for name, v in speed.items()]
        return MarkdownText("\n".join(lines))
    head = ["N"] + [f"{m}, {what}" for m in first for what in ("time", "Std")]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join([str(n)] + [cell for v in runs.values() for cell in
                                            (format_time(v["time"]), format_sig(v["std_rho_map"]))]) + " |"
              for n, runs in speed.items()]
    return MarkdownText("\n".join(lines))


def wins(table: Table, column: str = "std_rho_map", *, lower: bool = True) -> dict[str, int]:
    """How many cases of ``table`` each method wins on ``column`` (ties go to both); methods are the table's
    distinct ``method`` labels, compared case by case."""
    cases: dict[str, dict[str, float]] = {}
    for case, method, vals in table.rows:
        v = vals.get(column)
        if v is not None:
            cases.setdefault(case, {})[method] = float(v)
    count: dict[str, int] = {}
    for vals in cases.values():
        best = min(vals.values()) if lower else max(vals.values())
        for m, v in vals.items():
            count[m] = count.get(m, 0) + int(v == best)
    return count


def folded_cell(value, flips: int = 0, folded: int | None = None) -> str:
    """One cell of a headline table.  Std of a folded map (negative areas) is not a density spread, so a single
    folded map reads ``folded (n flips)``; a value over several fields (read the median) says how many of them
    folded: ``0.152 (3 folded, 109 flips)``."""
    if value is None:
        return "—"
    if flips and folded is None:
        return f"folded ({flips:,} flips)"
    if flips and folded:
        return f"{format_sig(value)} ({folded} folded, {flips:,} flips)"
    return format_sig(value)


class MarkdownText(str):
    """Markdown text that a notebook shows rendered when it is a cell's value (``_repr_markdown_``); otherwise a
    plain ``str``."""

    def _repr_markdown_(self) -> str:
        return str(self)


def side_by_side(table: Table, columns: dict, case_title: str) -> MarkdownText:
    """One row per case of a comparison table, one column per (method, column) pair, as Markdown that a notebook
    shows as a table when it is the cell's value.

    ``columns`` maps a header to ``(method, column)``.  A raw map that folds (``n_flipped`` > 0 in a row of
    :func:`paper_fields_table`, :func:`resolution_table` or :func:`points_table`) reads ``folded (n flips)``
    in its ``raw_std`` column; a row over several fields (:func:`generalization_tables`, with a ``folded``
    count) keeps its value and says how many of its maps folded (:func:`folded_cell`); times carry their unit."""
    cases = list(dict.fromkeys(c for c, _, _ in table.rows))
    vals = {(c, m): v for c, m, v in table.rows}

    def cell(case, method, column):
        v = vals.get((case, method))
        if v is None or v.get(column) is None:
            return "—"
        if column == "time":
            return format_time(v[column])
        flips = int(v.get("n_flipped") or 0)
        if "folded" in v:
            return folded_cell(v[column], flips, int(v["folded"]))
        return folded_cell(v[column], flips if column == "raw_std" else 0)

    head = [case_title, *columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join([c] + [cell(c, m, col) for m, col in columns.values()]) + " |" for c in cases]
    return MarkdownText("\n".join(lines))


def kept_rules(kept: dict) -> str:
    """Sentences saying how each model's kept step was chosen, where its kept map folds, and what the fold-free
    rule keeps instead (the text of the section on the models in the book's chapter "12 U-Net or Fourier neural
    operator?").

    Parameters
    ----------
    kept : dict
        Display name -> :func:`kept_state` of that model.

    Returns
    -------
    str
        For a model chosen by the checkpoint score: its kept step, the held-out fields on which that state's map
        folds, its plain mean, and the step the first runs' rule would have kept (with both states' plain means
        and checkpoint scores) where it differs; for a model chosen by the earlier rule or the first runs' rule: its
        kept step and plain mean.
    """
    out, cross = [], []
    for name, k in kept.items():
        if k["rule"] == "fold-free mean":
            out.append(f"The {name}'s training record has no checkpoint score (a dash in the table), so its"
                       " weights were chosen by the lowest plain held-out mean among the states whose"
                       f" maps fold on no held-out field: step {k['step']:,} ({k['mean']:#.3g}).")
            continue
        if k["rule"] == "earlier rule":
            out.append(f"The {name}'s training record has no checkpoint score (a dash in the table), so its"
                       " weights were chosen by the held-out mean with a folded map counted as the identity:"
                       f" step {k['step']:,}, plain held-out mean {k['mean']:#.3g}.")
            continue
        folds = k["folds"]
        if folds:
            where = "; ".join(f"{f} at N = {n}, {t:,} flipped triangle{'s' * (t != 1)}" for f, n, t in folds)
            many = "one held-out field" if len(folds) == 1 else f"{len(folds)} held-out fields"
            state = f"whose map folds on {many} ({where})"
        else:
            state = "whose maps fold on no held-out field"
        out.append(f"The {name}'s weights were chosen by the checkpoint score: step {k['step']:,}, {state}; its"
                   f" plain held-out mean is {k['mean']:#.3g}.")
        if k["fold_free_step"] is None:
            cross.append(f"Every validated state of the {name} folds on some held-out field.")
        elif k["fold_free_step"] != k["step"]:
            other = [n for n, v in kept.items() if v["rule"] == "fold-free mean"]
            rule = f"The {other[0]}'s rule" if other else "Keeping the fold-free state with the lowest plain mean"
            lower = "lower" if k["fold_free_mean"] < k["mean"] else "higher"
            worse = ("worse" if k["fold_free_score"] > k["score"] else "better")
            cross.append(f"{rule} would have kept the {name}'s step {k['fold_free_step']:,} instead, which folds on"
                       f" no held-out field and has the {lower} plain mean {k['fold_free_mean']:#.3g} but a {worse}"
                       f" checkpoint score ({k['fold_free_score']:#.3g} against {k['score']:#.3g}).")
    rules = {k["rule"] for k in kept.values()}
    head = ("The kept steps were chosen by different rules." if len(rules) > 1 else
            f"Every kept step was chosen by the {next(iter(rules), 'fold-free mean')}.")
    return " ".join([head] + out + cross)


def learning_verdict(learn: dict, surs: dict) -> str:
    """Whether each model's validation curve still fell at the end of its run, from its validation record.

    Parameters
    ----------
    learn : dict
        Display name -> :func:`learning_summary` of that model (``last=3``).
    surs : dict
        Display name -> the :class:`rfmap.Surrogate`, for its number of training steps.

    Returns
    -------
    str
        One sentence for the models that reached no lower plain mean later in their run (their lowest came before
        their last three validations: that mean and its step, and the range of the last three), one for each model
        whose lowest mean came among the last three (it may still have been improving), and a note where a record
        holds no validation of its last step. The sentences speak of one run per model, whose curve is noisy: they
        say where its lowest value came, not whether more steps would have lowered it.
    """
    notes = []
    for name, v in learn.items():
        total = int(surs[name].meta.get("cumulative_steps", surs[name].meta.get("steps", 0)))
        if v["last_steps"] and v["last_steps"][-1] < total:
            notes.append(f"The {name}'s record holds no validation of its last step, {total:,}, so its curve ends at"
                         f" step {v['last_steps'][-1]:,}.")
    done = [n for n, v in learn.items() if not v["improving"]]
    out = []
    if done:
        one = len(done) == 1
        if len(done) == len(learn) > 1:
            subject = "In this one run per network, neither reached a lower plain mean after its lowest"
        else:
            subject = ("The " + _steps_text(done, " and the ") + " reached no lower plain mean after "
                       + ("its" if one else "their") + " lowest in " + ("its run" if one else "their runs"))
        best = []
        for k, n in enumerate(done):
            val, step = f"{learn[n]['best']:#.3g}", f"{learn[n]['best_step']:,}"
            whose = "its" if one else f"the {n}'s"
            best.append(f"{whose} lowest plain mean, {val}, came at step {step}" if k == 0
                        else f"the {n}'s, {val}, at step {step}")
        ranges = [f"{learn[n]['last_range'][0]:#.3g} to {learn[n]['last_range'][1]:#.3g}" for n in done]
        out.append(f"{subject}: " + _steps_text(best)
                   + (", before its" if one else ", each before its") + " last three validations, which range from "
                   + _steps_text(ranges, " and from ") + ".")
    for n in learn:
        if n not in done:
            v = learn[n]
            out.append(f"The {n} may still have been improving: its lowest plain mean, {v['best']:#.3g}, came at"
                       f" step {v['best_step']:,}, among its last three validations.")
    return " ".join(out + notes)


def _steps_text(items: list, last: str = " and ") -> str:
    """Items joined as prose: ``a``, ``a and b``, ``a, b and c``."""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + last + items[-1]
