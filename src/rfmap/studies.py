r"""Training studies: runs of one configuration that differ in one option, trained side by side for the same wall
time, and their validation curves.

``benchmarks/train_study.py`` starts the runs at once (one thread each, so that they share the machine alike),
and writes their validation histories (:func:`collect`) to ``src/rfmap/data/studies/NAME.json``; the book reads
them with :func:`load_study` and draws them with :func:`plot_study`.  The score is the validation stream's
(:func:`rfmap.validation.score`: per field family, Std(rho~_map) relative to Std(rho~_orig), averaged over the
families), never the paper's test fields.
"""
from __future__ import annotations

import json
from pathlib import Path

__all__ = ["STUDIES_DIR", "collect", "load_study", "study_names", "study_table", "plot_study"]

STUDIES_DIR = Path(__file__).resolve().parent / "data" / "studies"


def _curve(log_path: Path) -> dict:
    steps, elapsed, score, families, folded = [], [], [], [], []
    last_step, last_elapsed = 0, 0.0
    for line in Path(log_path).read_text().splitlines():
        rec = json.loads(line)
        if "validation" in rec and not rec.get("final"):
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
            "total_steps": last_step, "total_time": last_elapsed}


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


def study_table(study: dict):
    """One row per run: steps and minutes trained, the best and the last validation score, the step of the best,
    and the families at the best (a :class:`pandas.DataFrame`)."""
    import pandas as pd

    rows = []
    for label, r in study["runs"].items():
        if not r["score"]:
            continue
        i = min(range(len(r["score"])), key=r["score"].__getitem__)
        rows.append({"run": label, "steps": r["total_steps"], "minutes": r["total_time"] / 60.0,
                     "best score": r["score"][i], "at step": r["step"][i], "last score": r["score"][-1],
                     **{f"{k} (best)": v for k, v in r["families"][i].items()},
                     "folded (best)": r["folded_fields"][i]})
    return pd.DataFrame(rows).set_index("run")


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
    ax.legend(fontsize=8)
    return ax
