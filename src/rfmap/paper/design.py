"""Design decisions: the tuned constants of the package, with the measurements that chose them.

The record is the file ``design.json`` in the package's data folder (:data:`DESIGN_PATH`): one entry per decision.
Every entry has these keys:

* ``constant``, ``module`` and ``attribute``: the constant, its module and where to read it (a dotted path in the
  module, a dict key as a path component; ``null`` or absent for a choice that is not a constant);
* ``value``: the chosen value, as ``repr`` prints it; ``what``: what it sets;
* ``alternatives``, ``criterion`` and ``data``: the values tried, the criterion, and the data they were measured on;
* ``results``: the rows of the decision's table (``case``, ``chosen``, ``alternative``); ``notes``; ``benchmark``:
  what measures it;
* ``purpose``, ``outcome`` and ``kept``: in plain words, what it controls, what the measurement showed and why the
  value is kept (the page's overview, :func:`kept_text`);
* ``title``: the decision's name in plain words, the page's heading (followed by the constant where it is a public
  one, :func:`display_name`).

Some entries also have these:

* ``value_keys``: what the keys of a dict value (or the items of a tuple) are, ``"dimension"``, ``"boundary"`` or
  ``"option"``, so that the page can show the value readably (:func:`readable_value`);
* ``finding``: where the numbers do not support the chosen value: its ``text``, the ``rows`` (by ``case``) that
  show it and ``why_kept``, the decision's own account of what is known, what was not measured and why the value
  stays all the same; the page shows it in the decision's section (:func:`finding`); optionally ``lead``, the
  warning's first sentence, and ``short``, the overview's, where the gap is narrower than "the numbers do not
  support the value" (the comparison left out the rule most models were chosen by, say);
* ``columns``: the heads of the decision's table, where the default heads do not fit its rows: three, or two
  where every row is one setting's result;
* ``alternatives_per_case``: true where not every alternative was tried in every case, so that the section points
  at its table instead of listing them;
* ``where``: where a constant that has no public name is set, in public terms (a training config key, say);
* ``remeasure`` and ``measured``, or ``recorded``: how the numbers can be obtained again (below).

A decision is either *re-measurable* or a *historical record*.  A re-measurable one names in ``remeasure`` its case
of the benchmark script ``benchmarks/design.py`` (in the source repository); that script prints the table again
and, with ``--record``, stores the rows with :func:`record`, together with ``measured`` (date, code version,
machine, seconds).  A historical record keeps the numbers written down when the value was chosen, with
``recorded``: the commit that set the value (``value_set``, where it could be traced) and the commit that entered
the numbers in this record (``entered``).

The book's page *Design decisions* is the output of :func:`to_markdown` on the record (written to the page by the
script ``scripts/make_design_md.py`` of the source repository).  :func:`stale_values` lists the entries whose value
is no longer the one in the code.
"""
from __future__ import annotations

import ast
import importlib
import json
import os
import platform
import re
import subprocess
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from rfmap._version import __version__
from rfmap.paper.tables import power_of_ten, printed_digits

__all__ = ["DESIGN_PATH", "AREAS", "load_decisions", "current_value", "stale_values", "record", "area",
           "remeasure_command", "display_name", "readable_value", "finding", "kept_text", "plain_numbers",
           "load_range",
           "to_markdown"]

#: The file of the record of the design decisions: ``design.json`` in the package's data folder.
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
    returns the updated entry.  The page is then written again from the record (the source repository's script
    ``scripts/make_design_md.py`` does it)."""
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    for d in data["decisions"]:
        if constant in (d["constant"], d.get("remeasure")):
            d.update(fields)
            Path(path).write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
            return d
    raise KeyError(f"no decision {constant!r} in {path}")


def measured_on(threads: int, seconds: float) -> dict[str, Any]:
    """What a measurement ran on, as :func:`record` stores it under ``measured``: the date (UTC), the code
    (``rfmap VERSION, commit SHORT``, with ``+ changes`` when a tracked file of the package differs from the commit
    (``src/rfmap/data`` and ``src/rfmap/paper`` do not count); the version alone outside a git checkout), the machine
    and thread count, the one-minute load average and the ``seconds`` it took."""
    version = f"rfmap {__version__}"
    root = str(Path(__file__).resolve().parents[3])
    try:
        sha = subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                             check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", root, "status", "--porcelain", "--untracked-files=no", "--", "src/rfmap",
                                ":!src/rfmap/data", ":!src/rfmap/paper"], capture_output=True, text=True,
                               check=True).stdout.strip()
        version = f"{version}, commit {sha}" + (" + changes" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        pass
    cpu = platform.processor() or platform.machine()
    return {"date": datetime.now(timezone.utc).strftime("%Y-%m-%d"), "code": version,
            "machine": f"{cpu}, {os.cpu_count()} cores, {'one thread' if threads == 1 else f'{threads} threads'}",
            "load": round(os.getloadavg()[0], 1), "seconds": round(seconds)}


#: The page's groups: a module prefix and the heading of its decisions, in the page's order.  ``rfmap.surrogate``
#: and ``rfmap.nn`` share one group, *Network inference*.
#:
#: :meta hide-value:
AREAS = (("rfmap.solvers", "Classical solvers"), ("rfmap.finish", "Finishing a network's map"),
         ("rfmap.surrogate", "Network inference"), ("rfmap.nn", "Network inference"),
         ("rfmap.core", "Memory and input checks"), ("rfmap.cartogram", "Cartograms"),
         ("rfmap.training", "Training"))

#: A paragraph under a group's heading in the sections, where something holds for every decision of the group.
_GROUP_NOTES = {"Training": "The shares of hard fields and the fold penalties below are those the shipped models "
               "were trained with. A different value takes effect only in a model trained again, so where the "
               "record does not support one of them, its section says what is known and what a new training run "
               "would have to measure."}

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


#: how a key of a dict value reads, by the name ``value_keys`` gives it
_KEY_TEXT = {"dimension": lambda k: f"{k}D", "boundary": lambda k: f"{k} boundary"}


def _number(v: Any) -> str:
    """A scalar of a constant as the page shows it: integers with thousands separators, small and large floats as a
    power of ten, strings without quotes."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return str(v)
    if isinstance(v, int):
        return f"{v:,}"
    if v != 0 and not 1e-3 <= abs(v) < 1e5:
        text = power_of_ten(v, printed_digits(v))
        return text.removeprefix("1 × ") if v > 0 else text  # 10⁻⁹, not 1 × 10⁻⁹
    return f"{int(v):,}" if v.is_integer() else repr(v)


def _code_words(text: str) -> str:
    """``text`` with its calls (``score()``) and its names with an underscore (``grid_sample``) as inline code."""
    return re.sub(r"([A-Za-z_][\w.]*\([\w=, ]*\)|\b[A-Za-z]\w*_\w*\b)", r"`\1`", text)


def _code_name(d: dict[str, Any]) -> str | None:
    """The public name of the decision's constant as a reader would type it (``RTOL``), or ``None`` for a choice
    that is not a public constant (a private one such as ``_HARD2.p_hard`` is set through a training config key)."""
    m = re.fullmatch(r"([A-Za-z_]\w*)(?: \((.*)\))?", d["constant"])
    if not m or m.group(1).startswith("_") or not (d.get("attribute") or m.group(1).isupper()):
        return None
    return m.group(1)


def display_name(d: dict[str, Any]) -> str:
    """The decision's name for headings and the overview: its ``title`` in plain words, followed by the constant
    as inline code where it is a public one (``Step size of the flow solver (`RTOL`)``); without a title, the
    constant as inline code, else its words; never its value."""
    name = _code_name(d)
    if d.get("title"):
        return d["title"] + (f" (`{name}`)" if name else "")
    if name:
        return f"`{name}`"
    return _code_words(d["constant"])


def readable_value(d: dict[str, Any]) -> str:
    """The decision's value in words: a dict as ``2D: 0.2; 3D: 0.4`` (its keys named by ``value_keys``), settings as
    ``refine=1``, numbers without e-notation; a value that is not a Python literal as it is recorded, its calls as
    code."""
    try:
        v = ast.literal_eval(d["value"])
    except (ValueError, SyntaxError):
        return _code_words(d["value"])
    names = list(d.get("value_keys") or [])

    def key(k: Any) -> str:
        parts = k if isinstance(k, tuple) else (k,)
        names_ = names + [""] * (len(parts) - len(names))
        return ", ".join(_KEY_TEXT.get(n, str)(p) for n, p in zip(names_, parts))

    if isinstance(v, dict):
        if names == ["option"]:
            return ", ".join(f"`{k}={x!r}`" for k, x in v.items())
        return "; ".join(f"{key(k)}: {_number(x)}" for k, x in v.items())
    if isinstance(v, (tuple, list)):
        return ", ".join(key(x) if names else _number(x) for x in v) + (" only" if len(v) == 1 and names else "")
    if isinstance(v, bool):
        return f"`{v}`"
    return _number(v)


def _cores(machine: str) -> str:
    m = re.search(r"(\d+) cores?", machine or "")
    return f"{m.group(1)} cores" if m else (machine or "an unnamed machine")


def load_range(decisions: list[dict[str, Any]] | None = None) -> tuple[float, float, str] | None:
    """``(lowest, highest load average, cores)`` of the re-measured runs that recorded their load (``None`` when
    none did); the cores are those of the machines named, joined where they differ."""
    decisions = load_decisions() if decisions is None else decisions
    runs = [d["measured"] for d in decisions if (d.get("measured") or {}).get("load") is not None]
    if not runs:
        return None
    loads = [float(m["load"]) for m in runs]
    cores = " or ".join(dict.fromkeys(_cores(m.get("machine", "")) for m in runs))
    return min(loads), max(loads), cores


_E_NOTATION = re.compile(r"(?<![\w.])(\d+(?:\.\d+)?)e([-+]?\d+)\b")


def plain_numbers(text: str) -> str:
    """``text`` with its numbers in e-notation written as powers of ten (``8.9e-16`` as ``8.9 × 10⁻¹⁶``, ``1e-7``
    as ``10⁻⁷``)."""
    def power(m: re.Match) -> str:
        v = float(m.group(0))
        out = power_of_ten(v, printed_digits(m.group(1)) if "." in m.group(1) else 1)
        return out.removeprefix("1 × ")

    return _E_NOTATION.sub(power, text)


def _row_text(r: dict[str, Any]) -> str:
    """One row of a decision's numbers as a line of a Markdown table: its case, the chosen value's result and the
    alternatives' (an em dash where the row has none)."""
    return plain_numbers("| " + " | ".join(_cell(r.get(k)) for k in ("case", "chosen", "alternative")) + " |")


def _one_sided(rows: list[dict[str, Any]]) -> bool:
    """Whether every row is one setting's result: the chosen value's or an alternative's, never both."""
    return all(bool(r.get("chosen")) != bool(r.get("alternative")) for r in rows)


def _rows_table(rows: list[dict[str, Any]], columns: list[str] | None = None) -> list[str]:
    """A decision's numbers as a table: per case, what the chosen value gave and what the alternatives gave; where
    every row is the result of one setting or one case, a table of two columns, whose rows name the setting.
    ``columns``, the decision's own heads, replaces the default ones: three keep all three columns, two head the
    table of two columns."""
    if columns and len(columns) == 3:
        return ["| " + " | ".join(columns) + " |", "| --- | --- | --- |"] + [_row_text(r) for r in rows]
    if _one_sided(rows):
        head = columns or ["setting or case", "result"]
        return ["| " + " | ".join(head) + " |", "| --- | --- |"] + \
            [plain_numbers(f"| {_cell(r.get('case'))} | {_cell(r.get('chosen') or r.get('alternative'))} |")
             for r in rows]
    return ["| case | with the chosen value | with the alternatives |", "| --- | --- | --- |"] + \
        [_row_text(r) for r in rows]


def _kind(d: dict[str, Any]) -> str:
    return "re-measurement" if d.get("remeasure") else "record"


def _why_kept(d: dict[str, Any]) -> str:
    """What is known and what was not measured, for a value its numbers do not support: the finding's own
    ``why_kept``, specific to the decision (a finding without one is an error: the page has no stock reason)."""
    why = (d.get("finding") or {}).get("why_kept")
    if not why:
        raise KeyError(f"{d['constant']}: a finding needs its own why_kept")
    return why


def kept_text(d: dict[str, Any]) -> str:
    """The overview's last field: the decision's ``kept``, why the value was chosen; where the numbers do not
    support the value (a ``finding``), that first, plainly (the finding's ``short``, else "Not supported by the
    record"), then the decision's own ``kept``."""
    f = d.get("finding")
    if f:
        short = f.get("short") or f"Not supported by the {_kind(d)}"
        return f"**{_sentence(short)}** {_sentence(d.get('kept'))}"
    return d.get("kept", "")


def finding(d: dict[str, Any]) -> list[str]:
    """The section's finding, where the record's numbers do not support the chosen value (``finding`` of the
    decision): what they show, the rows that show it, and that the constant stays until it is measured again.
    Empty without a finding."""
    f = d.get("finding")
    if not f:
        return []
    rows = {r.get("case"): r for r in d.get("results") or []}
    missing = [c for c in f.get("rows", []) if c not in rows]
    if missing:
        raise KeyError(f"{d['constant']}: the finding names rows that the record does not hold: {missing}")
    lead = f.get("lead") or f"The {_kind(d)} does not support the choice"
    text = f"**{_sentence(lead)}** {_sentence(f['text'])}"
    shown = [rows[c] for c in f.get("rows", [])]
    end = _sentence(_why_kept(d))
    return [":::{warning}", text, ""] + (_rows_table(shown, d.get("columns")) + [""] if shown else []) + [end, ":::", ""]


def _cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ") if text not in (None, "") else "—"


def _where(d: dict[str, Any]) -> str:
    """Where a decision is set, in public terms, where its heading does not say it: its ``where`` (a training config
    key, say)."""
    if d.get("where"):
        return f" ({d['where']})"
    return ""  # a public constant is named in the heading, its module under "In the code"


def _label(d: dict[str, Any]) -> str:
    """The page's target of a decision's section (``design-walk-fill``)."""
    slug = "".join(c if c.isalnum() else "-" for c in (d.get("remeasure") or d["constant"]).lower())
    return "design-" + "-".join(part for part in slug.split("-") if part)


#: the tag of a section whose numbers were written down when the value was chosen and are not measured again
#: (what that means is said once, in the page's introduction)
RECORD_TAG = "**Record{date}, not re-measured.**"


def _status(d: dict[str, Any]) -> list[str]:
    """What kind of numbers the section shows: how to measure them again, or when they were written down."""
    command = remeasure_command(d)
    if command:
        m = d.get("measured") or {}
        text = f"**Measure it again:** `{command}`."
        if m:
            text += f" The numbers below are that script's run of {m['date']} on a machine with {_cores(m.get('machine', ''))}."
        return [text, ""]
    entered = (d.get("recorded") or {}).get("entered") or {}
    date = f" of {entered['date']}" if entered.get("date") else ""
    return [f"{RECORD_TAG.format(date=date)}", ""]


def _evidence(d: dict[str, Any]) -> str:
    """Of what date the overview's outcome is: ``re-measured 2026-12-06`` for a decision a script measures again (its
    last run), ``record of 2026-11-27, not re-measured`` for the others (``record, not re-measured`` without a
    date)."""
    if remeasure_command(d):
        date = (d.get("measured") or {}).get("date")
        return f"re-measured {date}" if date else "re-measurable, not measured yet"
    date = ((d.get("recorded") or {}).get("entered") or {}).get("date")
    return f"record of {date}, not re-measured" if date else "record, not re-measured"


def _details(d: dict[str, Any]) -> list[str]:
    """One decision's section: its name and value and its criterion (what it controls and what the measurement
    showed are said in the overview), then the numbers in a collapsed block (rows quoted by a finding not
    repeated)."""
    lines = [f"({_label(d)})=", f"### {display_name(d)}", "", f"**Value:** {readable_value(d)}" + _where(d), "",
             f"**Criterion:** {d['criterion']}.", ""]  # the outcome is the overview's, said once
    lines += finding(d)
    lines += ["::::{dropdown} The measurement", ""]
    if d.get("alternatives_per_case"):
        lines += ["**Tried per case:** see the table.", ""]
    elif d.get("alternatives"):
        lines += [f"**Tried instead:** {'; '.join(d['alternatives'])}.", ""]
    lines += _status(d)
    if d.get("data"):
        lines += [f"**Measured on:** {plain_numbers(d['data'].rstrip('.'))}.", ""]
    quoted = set((d.get("finding") or {}).get("rows", []))  # shown in the warning above: not repeated here
    rest = [r for r in d.get("results") or [] if r.get("case") not in quoted]
    if rest:
        lines += (["The other rows:", ""] if quoted else []) + _rows_table(rest, d.get("columns")) + [""]
    if d.get("notes"):
        lines += [plain_numbers(d["notes"]), ""]
    lines += [f"In the code: `{d['module']}`. {plain_numbers(d['what'])}", "", "::::", ""]
    return lines


def _groups(decisions: list[dict[str, Any]]) -> list[tuple[str, list[dict[str, Any]]]]:
    """The decisions by page group, groups in the order of :data:`AREAS`, decisions in the record's order."""
    order = list(dict.fromkeys(h for _, h in AREAS)) + ["Other"]
    by: dict[str, list[dict[str, Any]]] = {}
    for d in decisions:
        by.setdefault(area(d), []).append(d)
    return [(h, by[h]) for h in order if h in by]


def _glance(decisions: list[dict[str, Any]]) -> list[str]:
    """The page's overview: per group of decisions a list, one item per decision with its name and value, what it
    controls, what the measurement showed and why the value is kept (or that the numbers do not support it); the
    alternatives tried are in the section's collapsed block. A list rather than a four-column table, whose columns
    the page's text width would squeeze to a word or two per line."""
    lines = []
    for heading, group in _groups(decisions):
        lines += [f"**{heading}**", ""]
        for d in group:
            lines.append(f"- [{display_name(d)}]({_label(d)}): {readable_value(d)}. "
                         f"{_sentence(d.get('purpose') or d['what'])} "
                         f"*Outcome ({_evidence(d)}):* {_sentence(d.get('outcome'))} "
                         f"*Why this value:* {_sentence(kept_text(d))}")
        lines.append("")
    return lines


def _sentence(text: Any) -> str:
    """``text`` as a sentence: a capital first letter and a full stop; an em dash where there is none.  A first word
    that names code (with an underscore, a digit or a bracket, such as ``float64`` or ``grid_sample``) keeps its
    case."""
    text = str(text or "").strip()
    if not text:
        return "—."
    first = text.split()[0]
    code = any(c in first for c in "_()`") or any(c.isdigit() for c in first)
    return (text if code else text[0].upper() + text[1:]) + ("" if text.endswith((".", "!", "?")) else ".")


def to_markdown(decisions: list[dict[str, Any]] | None = None, source: str = "src/rfmap/data/design.json") -> str:
    """The page *Design decisions*: how to read it, one table of every decision, one short section per decision
    with its numbers folded, and last how to measure the decisions again."""
    decisions = load_decisions() if decisions is None else decisions
    lines = [f"<!-- Generated by scripts/make_design_md.py from {source}: edit the JSON, then rerun. -->", "",
             "# Design decisions", "",
             "The paper specifies its method, but an implementation needs settings that the paper does not fix: "
             "how large a step the flow solver takes, how much a network's map is smoothed before the solver "
             "finishes it, how the checkpoint of a training run is chosen. This page gives, for each such setting, "
             "its value, the criterion it was chosen by, what else was tried and what the measurements showed, "
             "including where they do not support the value. It is a reference for those who change or "
             "re-measure these settings; the chapters do not depend on it, and its collapsed blocks name the "
             "records and code behind each number.", "",
             "The overview below has one entry per setting, grouped by the part of the package it belongs to. The "
             "sections after it repeat the value and give the criterion; what else was tried and the numbers sit in "
             "a collapsed block "
             "(click *The measurement* to open it). Where the numbers do not support the value, a warning box at "
             "the top of the section says so, shows the rows that show it, and says what is known and what was "
             "not measured.", "",
             "Most settings are judged by {term}`Std(ρ̃)` of the mapped mesh, Std(ρ̃_map): the spread of the "
             "density that a map leaves, zero for a perfectly equalized density (*more even* means lower). The "
             "other words of the pipeline are those of the {doc}`glossary`: the {term}`working grid` the network "
             "runs on, its {term}`raw map`, the {term}`default map`, and the {term}`polish`, in which the flow "
             "solver starts from the network's map (a *warm* flow) and, with the {term}`guard`, also from the "
             "identity (a *cold* flow). The models named (`deq2d-square`, `dem3d-cube`, ...) are the shipped "
             "networks that `rfmap models` lists. N is the side of a grid in points; M, that of the flow "
             "solver's density raster and velocity table, finer than the grid. The test densities named "
             "(sin-cos, ring, octant-3d, ...) are the paper's, with their formulas in {doc}`api/fields`; the "
             "{term}`sea` is the margin of (nearly) mean density around a free boundary.", "",
             "The numbers are of two kinds. A *re-measured* decision is measured again by the script "
             "`benchmarks/design.py`, which prints the same table; its section gives the command and the date of "
             "the run. A *record* holds the numbers written down when the value was chosen; the code has changed "
             "since, so a record explains the choice without showing that it still holds, and its section is "
             "marked *Record of* its date, *not re-measured*.", ""]
    loads = load_range(decisions)
    if loads:
        lines[-2] += (f" The timings were taken on a shared machine with {loads[2]} while other work was running, "
                      "so a small difference in time between two settings can come from that load rather than "
                      "from the setting.")
    lines += ["## At a glance", ""] + _glance(decisions)
    for heading, group in _groups(decisions):
        lines += [f"## {heading}", ""] + ([_GROUP_NOTES[heading], ""] if heading in _GROUP_NOTES else [])
        for d in group:
            lines += _details(d)
    lines += ["## Measuring again", "",
              "To measure the re-measured decisions again and write this page from the new numbers:", "",
              "```bash",
              "python benchmarks/design.py --record  # every case; or --only NAME [NAME ...]",
              "python scripts/make_design_md.py      # write this page from the record",
              "```", ""]
    return "\n".join(lines).rstrip("\n") + "\n"
