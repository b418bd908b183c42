"""Design decisions: the tuned constants of the package, with the measurements that chose them.

The record is ``src/rfmap/data/design.json``: one entry per decision with the ``constant``, its ``module``, the
chosen ``value`` (as ``repr`` prints it), where to read it (``attribute``: a dotted path in the module, a dict key
as a path component, ``null`` for a choice that is not a constant), what it sets (``what``), the ``alternatives``
tried, the ``criterion``, the ``data`` it was measured on, the ``results`` (rows ``case``, ``chosen``,
``alternative``), ``notes`` and the ``benchmark`` that measures it.

A decision is either *re-measurable* or a *historical record*.  A re-measurable one names its case of
``benchmarks/design.py`` (``remeasure``); that script prints the table again and, with ``--record``, stores the rows
with :func:`record`, together with ``measured`` (date, code version, machine, seconds).  A historical record keeps
the numbers written down when the value was chosen, with ``recorded``: the commit that set the value
(``value_set``, where it could be traced) and the commit that entered the numbers in this record (``entered``).

The book's page *Design decisions* (``book/design.md``) is generated from the record by
``scripts/make_design_md.py`` (:func:`to_markdown`).  :func:`stale_values` lists the entries whose value is no
longer the one in the code.
"""
from __future__ import annotations

import importlib
import json
from pathlib import Path
from typing import Any

__all__ = ["DESIGN_PATH", "AREAS", "load_decisions", "current_value", "stale_values", "record", "area",
           "remeasure_command", "to_markdown"]

#: the record of the design decisions
DESIGN_PATH = Path(__file__).resolve().parent.parent / "data" / "design.json"


def load_decisions(path: Path = DESIGN_PATH) -> list[dict[str, Any]]:
    """The decisions of ``design.json``, in the order of the file."""
    return json.loads(Path(path).read_text(encoding="utf-8"))["decisions"]


def current_value(decision: dict[str, Any]) -> str | None:
    """``repr`` of the decision's constant as the code holds it now (``None`` when it has no ``attribute``).

    The ``attribute`` is a dotted path from the module: ``"RTOL"``, ``"_HARD2.p_hard"`` (an attribute of an
    object) or ``"_FOLD_HARD.fold"`` (a key of a dict)."""
    path = decision.get("attribute")
    if not path:
        return None
    obj: Any = importlib.import_module(decision["module"])
    for part in path.split("."):
        obj = obj[part] if isinstance(obj, dict) else getattr(obj, part)
    return repr(obj)


def stale_values(decisions: list[dict[str, Any]] | None = None) -> list[tuple[str, str, str]]:
    """``(constant, recorded value, value in the code)`` for every decision whose code has moved on."""
    out = []
    for d in load_decisions() if decisions is None else decisions:
        now = current_value(d)
        if now is not None and now != d["value"]:
            out.append((d["constant"], d["value"], now))
    return out


def record(constant: str, *, path: Path = DESIGN_PATH, **fields: Any) -> dict[str, Any]:
    """Store new measurements of one decision (named by its ``constant`` or its ``remeasure`` key; e.g.
    ``results=[...]``, ``data=...``, ``measured={...}``) in ``design.json``, for a benchmark that measures it again;
    returns the updated entry.  Regenerate the page with ``python scripts/make_design_md.py`` afterwards."""
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    for d in data["decisions"]:
        if constant in (d["constant"], d.get("remeasure")):
            d.update(fields)
            Path(path).write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
            return d
    raise KeyError(f"no decision {constant!r} in {path}")


#: the page's groups: a module prefix and the heading of its decisions, in the page's order
AREAS = (("rfmap.solvers", "Classical solvers"), ("rfmap.finish", "Finishing a network's map"),
         ("rfmap.surrogate", "Network inference"), ("rfmap.nn", "Network inference"),
         ("rfmap.core", "Memory and input checks"), ("rfmap.cartogram", "Cartograms"),
         ("rfmap.training", "Training"))

#: the script that re-measures a decision with a ``remeasure`` key
REMEASURE = "python benchmarks/design.py --only"


def area(decision: dict[str, Any]) -> str:
    """The page group of a decision, from its module (:data:`AREAS`)."""
    for prefix, heading in AREAS:
        if decision["module"] == prefix or decision["module"].startswith(prefix + "."):
            return heading
    return "Other"


def remeasure_command(decision: dict[str, Any]) -> str | None:
    """The command that measures the decision again (``None`` for a historical record)."""
    key = decision.get("remeasure")
    return f"{REMEASURE} {key}" if key else None


def _cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ") if text not in (None, "") else "—"


def _label(d: dict[str, Any]) -> str:
    """The page's target of a decision's section (``design-walk-fill``)."""
    slug = "".join(c if c.isalnum() else "-" for c in (d.get("remeasure") or d["constant"]).lower())
    return "design-" + "-".join(part for part in slug.split("-") if part)


def _commit(entry: dict[str, str]) -> str:
    return f"commit `{entry['commit']}` ({entry['date']})"


def _status(d: dict[str, Any]) -> list[str]:
    """What kind of numbers the section shows: how to measure them again, or where they come from."""
    command = remeasure_command(d)
    if command:
        m = d.get("measured") or {}
        lines = [f"**Re-measure:** `{command}` (add `--record` to store the new rows here)."]
        if m:
            took = f"; the run took {m['seconds']} s" if m.get("seconds") is not None else ""
            load = f", load average {m['load']}" if m.get("load") is not None else ""
            lines[0] += (f" The table below is that script's run of {m['date']} ({m['code']}; {m['machine']}{load}"
                         f"{took}).")
        return lines + [""]
    rec = d.get("recorded") or {}
    text = "**Historical record, not re-measured.**"
    if rec.get("value_set"):
        text += f" The value was set in {_commit(rec['value_set'])}."
    if rec.get("entered"):
        text += (f" The numbers below were written down when it was chosen and entered "
                 f"this record in {_commit(rec['entered'])}.")
    text += " The code has changed since: they show why the value was chosen, not that they still hold."
    bench = str(d.get("benchmark", ""))
    if bench.startswith("not scripted"):
        why = bench.partition(":")[2].strip()
        text += f" No script repeats them{'; ' + why if why else ''}."
    elif bench:
        text += f" Related measurement: {bench}."
    return [text, ""]


def _details(d: dict[str, Any]) -> list[str]:
    lines = [f"({_label(d)})=", f"### `{d['constant']}` = `{d['value']}`", "", f"In `{d['module']}`. {d['what']}", ""]
    if d.get("alternatives"):
        lines += [f"**Alternatives:** {'; '.join(d['alternatives'])}.", ""]
    lines += [f"**Criterion:** {d['criterion']}.", ""]
    lines += _status(d)
    if d.get("data"):
        lines += [f"**Measured on:** {d['data'].rstrip('.')}.", ""]
    if d.get("results"):
        lines += ["| Case | Chosen value | Alternatives |", "| --- | --- | --- |"]
        lines += [f"| {_cell(r.get('case'))} | {_cell(r.get('chosen'))} | {_cell(r.get('alternative'))} |"
                  for r in d["results"]]
        lines.append("")
    if d.get("notes"):
        lines += [d["notes"], ""]
    return lines


def _groups(decisions: list[dict[str, Any]]) -> list[tuple[str, list[dict[str, Any]]]]:
    """The decisions by page group, groups in the order of :data:`AREAS`, decisions in the record's order."""
    order = list(dict.fromkeys(h for _, h in AREAS)) + ["Other"]
    by: dict[str, list[dict[str, Any]]] = {}
    for d in decisions:
        by.setdefault(area(d), []).append(d)
    return [(h, by[h]) for h in order if h in by]


def to_markdown(decisions: list[dict[str, Any]] | None = None, source: str = "src/rfmap/data/design.json") -> str:
    """The page *Design decisions*: how to read it, a table of every decision, then one section per decision."""
    decisions = load_decisions() if decisions is None else decisions
    scripted = [d for d in decisions if d.get("remeasure")]
    lines = [f"<!-- Generated by scripts/make_design_md.py from {source}: edit the JSON, then rerun. -->", "",
             "# Design decisions", "",
             "A *design decision* here is a constant or a rule of the package whose value was chosen by measuring "
             "it against alternatives: a solver's step tolerance, how many smoothing passes a finishing stage runs, "
             "how much memory the input checks reserve per grid vertex. The code keeps one line of rationale beside "
             f"each; this page keeps the measurements, read from `{source}`. A test checks that every value "
             "recorded here is the one in the code, so a changed constant fails the tests until it is measured "
             "again.", "",
             "Each decision says which of two kinds its numbers are:", "",
             "- **Re-measure**: a case of `benchmarks/design.py` measures it again at a small size and prints the "
             "table shown (`python benchmarks/design.py --list` lists the cases). The "
             "section names the command, the date, the code version and the machine of the run shown. Timings "
             "depend on the machine and its load; compare the chosen value with the alternatives within one run.",
             "- **Historical record**: numbers written down once, when the value was chosen, with the commit that "
             "set the value and the commit that entered the numbers here. No script repeats them; the code has "
             "changed since, so they explain the choice but do not show that it still holds.", "",
             "To refresh the re-measurable decisions and this page:", "",
             "```bash",
             "python benchmarks/design.py --record        # every case; or --only NAME [NAME ...]",
             "make pages                                  # regenerate this page from the record",
             "```", "",
             "## At a glance", "",
             "| Decision | Value | Numbers |", "| --- | --- | --- |"]
    for heading, group in _groups(decisions):
        lines.append(f"| **{heading}** | | |")
        for d in group:
            if d.get("remeasure"):
                how = f"re-measure: `--only {d['remeasure']}`"
            else:
                entered = (d.get("recorded") or {}).get("entered")
                how = "historical" + (f" ({entered['date']})" if entered else "")
            lines.append(f"| [`{d['constant']}`]({_label(d)}) | `{_cell(d['value'])}` | {how} |")
    lines += ["", f"{len(scripted)} of the {len(decisions)} decisions can be measured again by "
              "`benchmarks/design.py`; the others are historical records.", ""]
    for heading, group in _groups(decisions):
        lines += [f"## {heading}", ""]
        for d in group:
            lines += _details(d)
    return "\n".join(lines).rstrip("\n") + "\n"
