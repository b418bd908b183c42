r"""Training records: the budget behind a shipped model, and studies of runs of one configuration that differ in one
option, trained side by side for the same wall time, and their validation curves.

A study's runs start at once (one thread each, so that they share the machine alike; the source repository's
``benchmarks/train_study.py``), and their validation histories (:func:`collect`) ship in the package's
``data/studies/NAME.json``; the book reads
them with :func:`load_study` and draws them with :func:`plot_study`.  The score is the validation stream's
(:func:`rfmap.training.validation.score`: per field family, :math:`\mathrm{Std}(\tilde\rho_{\text{map}})`
relative to :math:`\mathrm{Std}(\tilde\rho_{\text{orig}})`, averaged over the families), never the paper's test
fields.
"""
from __future__ import annotations

import json
import shlex
from pathlib import Path

import numpy as np

from ..core.inputs import preprocess_density
from ..core.mesh import grid_points
from ..core.result import MapResult
from ..core.wording import format_sig
from ..finish import quiet_quality
from ..tasks.teacher import teacher_map
from .validation import validation_fields

__all__ = ["STUDIES_DIR", "collect", "load_study", "study_names", "study_table", "plot_study", "study_values",
           "training_budget", "budget_table", "shrinking_batches", "budget_markdown", "teacher_of", "to_markdown",
           "example_field",
           "example_text", "map_gap"]

STUDIES_DIR = Path(__file__).resolve().parent.parent / "data" / "studies"


def _curve(log_path: Path) -> dict:
    steps, elapsed, score, families, folded = [], [], [], [], []
    last_step, last_elapsed = 0, 0.0
    for line in Path(log_path).read_text().splitlines():
        rec = json.loads(line)
        # the final record scores the shipped state: a point of the curve only when that is the last step's
        if "validation" in rec and (not rec.get("final") or rec.get("selected_step") == rec["step"]):
            m = rec["validation"]["mean"]
            if "family_score" not in m:
                continue
            steps.append(int(rec["step"]))
            elapsed.append(float(rec.get("elapsed", 0.0)))
            score.append(float(m["family_score"]))
            families.append({k: float(v) for k, v in m["families"].items()})
            folded.append(int(m.get("folded_fields", 0)))
        elif "loss" in rec:
            last_step, last_elapsed = int(rec["step"]), float(rec.get("elapsed", 0.0))
    return {"step": steps, "elapsed": elapsed, "score": score, "families": families, "folded_fields": folded,
            "total_steps": max([last_step, *steps]), "total_time": max([last_elapsed, *elapsed])}


def collect(name: str, runs: dict[str, Path], *, description: str, commands: dict[str, str],
            out: Path | None = None) -> Path:
    """Write the study ``name``: for every label of ``runs`` (label → run folder holding ``log.jsonl``) its
    validation curve, its command and totals, to ``out`` (default ``STUDIES_DIR/NAME.json``)."""
    data = {"name": name, "description": description,
            "runs": {label: {"command": commands.get(label, ""), **_curve(Path(d) / "log.jsonl")}
                     for label, d in runs.items()}}
    path = Path(out or STUDIES_DIR / f"{name}.json")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1) + "\n")
    return path


def study_names() -> list[str]:
    """The stored studies."""
    return sorted(p.stem for p in STUDIES_DIR.glob("*.json"))


def load_study(name: str) -> dict:
    """A stored study by name; ``ValueError`` naming the known ones otherwise."""
    path = STUDIES_DIR / f"{name}.json"
    if not path.exists():
        raise ValueError(f"unknown study {name!r}; stored: {', '.join(study_names()) or 'none'}")
    return json.loads(path.read_text())


def study_table(study: dict, part: str = "all"):
    """One row per run: steps and minutes trained, the score at step 0 (where validated), the best score of the
    run's own states (after step 0) and its step, the last score, and the families at the best (a
    :class:`pandas.DataFrame`). ``part="runs"`` keeps the columns up to the last score, ``part="families"`` the
    score of each family and the folded fields at the best state: two narrower tables for a page."""
    import pandas as pd

    if part not in ("all", "runs", "families"):
        raise ValueError(f"part must be 'all', 'runs' or 'families', got {part!r}")

    rows = []
    for label, r in study["runs"].items():
        if not r["score"]:
            continue
        own = [i for i, st in enumerate(r["step"]) if st > 0] or list(range(len(r["score"])))
        i = min(own, key=r["score"].__getitem__)
        start = {"score at step 0": r["score"][0]} if r["step"][0] == 0 else {}
        rows.append({"run": label, "steps": r["total_steps"], "minutes": r["total_time"] / 60.0, **start,
                     "best score": r["score"][i], "at step": r["step"][i], "last score": r["score"][-1],
                     **{f"{k} (best)": v for k, v in r["families"][i].items()},
                     "folded (best)": r["folded_fields"][i]})
    table = pd.DataFrame(rows).set_index("run")
    cut = list(table.columns).index("last score") + 1
    return {"all": table, "runs": table.iloc[:, :cut], "families": table.iloc[:, cut:]}[part]


def study_values(study: dict) -> dict:
    """The numbers a page quotes from a study: per run (its position ``i`` in the study) ``run{i}_best`` (the best
    score of the run's own states, after step 0), ``run{i}_last``, ``run{i}_steps`` and ``run{i}_minutes``,
    ``run{i}_label``, ``run{i}_best_at_end`` (whether the run's best score is that of its last validation, i.e. it
    was still improving when it stopped); ``start`` (the score at step 0, where validated: the weights a continued
    run started from); ``winner`` (the label of the run with the lowest best score), ``loser``, ``margin`` (the
    loser's best score over the winner's), ``still_improving`` (every run's best at its end) and ``minutes``. With
    two runs, also the scores at equal steps: ``short_label`` (the run that took fewer steps), ``short_step`` and
    ``short_score`` (its last validation) and ``long_at_short`` (the other run's score at that step, interpolated
    linearly between its validations)."""
    out: dict = {}
    best = {}
    for i, (label, r) in enumerate(study["runs"].items()):
        # a run's own states: not the weights it started from (validated at step 0 when it continues others)
        own = [v for st, v in zip(r["step"], r["score"]) if st > 0] or r["score"]
        out.update({f"run{i}_label": label, f"run{i}_best": min(own), f"run{i}_last": r["score"][-1],
                    f"run{i}_steps": r["total_steps"], f"run{i}_minutes": r["total_time"] / 60.0,
                    f"run{i}_best_at_end": r["score"][-1] <= min(own)})
        if r["step"] and r["step"][0] == 0:
            out["start"] = r["score"][0]
        best[label] = min(own)
    order = sorted(best, key=best.get)
    out.update(winner=order[0], loser=order[-1], margin=best[order[-1]] / best[order[0]],
               minutes=max(r["total_time"] for r in study["runs"].values()) / 60.0,
               still_improving=all(out[f"run{i}_best_at_end"] for i in range(len(best))))
    if len(study["runs"]) == 2:  # per step: the shorter run's last validation against the other at that step
        short, long = sorted(study["runs"].items(), key=lambda kv: kv[1]["step"][-1])
        step = short[1]["step"][-1]
        out.update(short_label=short[0], short_step=step, short_score=short[1]["score"][-1],
                   long_at_short=float(np.interp(step, long[1]["step"], long[1]["score"])))
    return out


def plot_study(study: dict, ax=None, *, x: str = "elapsed"):
    """Validation score against wall time (``x='elapsed'``, minutes) or steps (``x='step'``), one line per run."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(5.5, 3.4), layout="constrained")
    for label, r in study["runs"].items():
        xs = [t / 60.0 for t in r["elapsed"]] if x == "elapsed" else r["step"]
        ax.plot(xs, r["score"], marker="o", ms=3, label=label)
    ax.set_xlabel("wall time (min)" if x == "elapsed" else "step")
    ax.set_ylabel("validation score (lower is better)")
    ax.set_title(study["name"], fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend()
    return ax


def _batch_of(command: str, default: int) -> int:
    words = shlex.split(command or "")
    return int(words[words.index("--batch") + 1]) if "--batch" in words else default


def training_budget(meta: dict, preset_batch: int) -> dict:
    """The whole training budget behind weights with metadata ``meta``, over every run of its ``--init`` chain:
    ``runs``, ``steps``, ``samples`` (steps times each run's batch: the ``--batch`` of its command, else
    ``preset_batch``) and ``hours`` of wall time."""
    runs = list(meta.get("lineage", [])) + [{"steps": meta.get("steps", 0), "command": meta.get("command", ""),
                                               "wall_time": meta.get("wall_time", 0.0)}]
    samples = sum(int(r.get("steps", 0)) * _batch_of(r.get("command", ""), preset_batch) for r in runs)
    return {"runs": len(runs), "steps": int(meta.get("cumulative_steps", meta.get("steps", 0))), "samples": samples,
            "hours": float(meta.get("cumulative_wall_time", meta.get("wall_time", 0.0))) / 3600.0}


def teacher_of(meta: dict) -> str:
    """The classical teacher of the last run behind weights (``'none'``: data-free, as in the paper)."""
    t = (meta.get("config") or {}).get("teacher") or {}
    return str(t.get("method", "none")) if float(t.get("weight", 0.0)) > 0 else "none"


def budget_table(metas: dict, paper_steps: dict, paper_batch: dict):
    """One row per model (a :class:`pandas.DataFrame`): runs, steps, fields seen and wall time (hours) over the
    whole chain, the paper's epochs and the fields of the ``paper`` preset (an epoch read as one step on a freshly
    drawn batch of the preset's size, since the paper gives no batch size), the ratios of steps to epochs
    (``× paper's epochs``) and of fields (``× fields, assumed batch``: the preset's batch is this project's
    assumption), and the teacher of the last run."""
    import pandas as pd

    rows = []
    for name, meta in metas.items():
        b = training_budget(meta, int((meta.get("config") or {}).get("batch", 1)))
        rows.append({"model": name, "runs": b["runs"], "steps": b["steps"], "fields seen": b["samples"],
                     "hours": b["hours"], "paper's epochs": paper_steps[name],
                     "paper preset's fields": paper_steps[name] * paper_batch[name],
                     "× paper's epochs": b["steps"] / paper_steps[name],
                     "× fields, assumed batch": b["samples"] / (paper_steps[name] * paper_batch[name]),
                     "teacher": teacher_of(meta)})
    return pd.DataFrame(rows).set_index("model")


def shrinking_batches(metas: dict) -> list[str]:
    """The models whose batch shrinks on larger grids (``batch_points`` set in their configuration): the fields they
    saw are counted at the largest batch, so :func:`budget_table` gives an upper bound for them."""
    return [k for k, m in metas.items() if (m.get("config") or {}).get("batch_points", 0) > 0]


def budget_markdown(budget, metas: dict, columns: list[str], headers: dict | None = None) -> str:
    """The ``columns`` of a :func:`budget_table` as Markdown (:func:`to_markdown`), with the fields-seen ratio of
    each model of :func:`shrinking_batches` marked as the upper bound it is (a ``≤`` before the number);
    ``headers`` renames columns for the reader
    (``{"× fields, assumed batch": "× fields at an assumed batch of 8"}``)."""
    shown = budget[columns].astype(object)
    col = "× fields, assumed batch"
    if col in columns:
        for k in shrinking_batches(metas):
            shown.at[k, col] = "≤ " + format_sig(float(budget.at[k, col]), 3)
    return to_markdown(shown.rename(columns=headers or {}))


def to_markdown(df) -> str:
    """A table of this module as Markdown: integers with thousands separators, other numbers with three
    significant digits (as powers of ten below 10⁻³, ``2.3 × 10⁻⁴``, never e-notation:
    :func:`~rfmap.core.wording.format_sig`), the index as the first column."""
    def fmt(v):
        if isinstance(v, bool) or not isinstance(v, (int, float)) and not hasattr(v, "dtype"):
            return str(v)
        if not isinstance(v, float) and float(v).is_integer():
            return f"{int(v):,}"
        v = float(v)
        return format_sig(v, 3)

    cols = [df.index.name or ""] + [str(c) for c in df.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for idx in df.index:  # by cell, so that integer columns keep their type
        lines.append("| " + " | ".join([str(idx)] + [fmt(df.at[idx, c]) for c in df.columns]) + " |")
    return "\n".join(lines)


def example_field(values: dict, fields, suffix: str = "") -> dict:
    """The example a sentence quotes from a population summary (``values`` of
    ``rfmap.paper.reproduce.population_summary``): the field where the best surrogate value (``{f}_best{suffix}``) comes
    closest to the paper's (``{f}_std_paper``), relative to it, so that it is a field that meets the paper whenever
    one does.  Returns ``field``, ``best``, ``paper``, ``ratio`` and ``verb`` ("meets" or "misses")."""
    ratio = {f: values[f"{f}_best{suffix}"] / values[f"{f}_std_paper"] for f in fields}
    f = min(ratio, key=ratio.get)
    return {"field": f, "best": values[f"{f}_best{suffix}"], "paper": values[f"{f}_std_paper"], "ratio": ratio[f],
            "verb": "meets" if ratio[f] <= 1.0 else "misses"}


def example_text(example: dict) -> str:
    """A sentence's example from :func:`example_field`, true to its numbers: ``"for example F: 0.0412 against the
    paper's 0.0488"`` when the field meets the paper, else ``"the closest is F: 0.0775, 1.05 times the paper's
    0.0737"``."""
    f, best, paper = example["field"], example["best"], example["paper"]
    if example["verb"] == "meets":
        return f"for example {f}: {best:.3g} against the paper's {paper:.3g}"
    return f"the closest is {f}: {best:.3g}, {example['ratio']:.3g} times the paper's {paper:.3g}"


def map_gap(sur, n: int, count: int = 4, stream: str = "report"):
    r"""How far a surrogate's map lies from the classical maps of the same fields, against how far the two classical
    solvers lie from each other (a :class:`pandas.DataFrame`, one row per field of the held-out ``stream``).

    Columns: :math:`\mathrm{Std}(\tilde\rho)` of the input, of the network's raw map and of the diffusion map, and
    the relative squared distances :math:`\sum_v |a_v - b_v|^2 / \sum_v |b_v - x_v|^2` (the teacher's loss,
    :mod:`rfmap.tasks.teacher`) of the network's map and of the flow map to the diffusion map.  Every
    density-equalizing map composed with a measure-preserving one equalizes as well, so the data-free losses do
    not single out one map: a distance near 1 or above means the network found another of them.
    """
    import numpy as np
    import pandas as pd


    spec = sur.spec
    pts = grid_points(n, spec.dim)
    rows = []
    for vf in validation_fields("density", spec.dim, count, stream=stream):
        raw = vf.field(pts).reshape((n,) * spec.dim)
        dens = preprocess_density(raw)
        with quiet_quality():
            net = sur.map(dens, n, repair=False, preprocess=False)
        diff = teacher_map(raw, spec.boundary, "diffusion")
        flow = teacher_map(raw, spec.boundary, "flow")
        if diff is None or flow is None:
            continue
        scale = float(((diff - pts) ** 2).sum())
        m = net.metrics()
        std_diff = MapResult(net.ref_points, diff, net.elements, net.field).metrics().std_rho_map
        rows.append({"field": vf.label, "Std input": m.std_rho_orig, "Std network": m.std_rho_map,
                     "Std diffusion": std_diff,
                     "network to diffusion": float(((net.mapped_points - diff) ** 2).sum()) / scale,
                     "flow to diffusion": float(((flow - diff) ** 2).sum()) / scale})
    return pd.DataFrame(rows).set_index("field")
