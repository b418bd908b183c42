"""The book's tables: the :class:`Table` of rows ``(case, method, {column: value})`` with Markdown and CSV output,
the formatter of its cells, the paper's published tables (a data file shipped inside the package, read by
:func:`paper_table`) and the helpers that write numbers into the book's text (each number a chapter's text quotes
is computed when the chapter runs).
"""
from __future__ import annotations

import csv
import io
import json
from decimal import Decimal
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..core.wording import format_sig, power_of_ten  # noqa: F401  (the book imports them from here too)

__all__ = ["Table", "Headline", "headline", "printed_digits", "rate_text", "decimal_text",
           "paper_table", "format_value", "span_text", "change_text", "agreement_text",
           "glue_all", "one_notation", "COLUMN_TITLES", "DIGITS", "MAX_COLUMNS"]


DATA = Path(__file__).resolve().parent.parent / "data"


COLUMN_TITLES = {
    "time": "time", "speedup": "speed-up", "mean_dd": "mean |Δd|", "mean_dmu": "mean |Δμ|",
    "mean_dmu_pl": "mean |Δμ| vs PL", "std_rho_orig": "Std ρ̃ orig", "std_rho_map": "Std ρ̃ map",
    "min_jacobian": "min det J", "n_flipped": "flips", "max_mu": "max |μ|", "mean_mu": "mean |μ|",
    "alpha": "α", "mean": "mean", "median": "median", "worst": "worst",
    "raw_std": "raw Std ρ̃ map", "flips_repaired": "flips after repair", "parameters": "parameters",
    "train_time": "training (min)", "validation": "held-out Std ρ̃ map", "work_n": "network grid", "arch": "arch",
    "count": "fields", "demand_median": "demand (median)", "demand_p90": "demand (90 %)",
    "reach_ratio": "reach / demand", "left_net": "left, ours", "left_classical": "left, classical",
    "fields": "training fields", "fold": "fold penalty", "lr": "peak lr", "ema": "weight average",
    "held_out": "held-out mean", "scored": "held-out maps scored", "folded_maps": "folded held-out maps",
    "val_n": "held-out N", "mu_ratio": "mean |μ| ratio", "std_ratio": "Std / best classical",
    "time_ratio": "time / best classical", "folded": "folded fields",
}


#: Significant digits of the numbers in a :class:`Table`'s Markdown and CSV (times: one fewer, with their unit),
#: trailing zeros dropped (``0.13``).  The comparison tables of :mod:`rfmap.paper.comparison` print as many digits
#: with trailing zeros kept (``0.1300``); the short summary tables of
#: :func:`~rfmap.paper.generalization.pivot_markdown`, :func:`~rfmap.paper.generalization.columns_markdown` and
#: :class:`Headline` print three (:func:`~rfmap.core.wording.format_sig`), trailing zeros dropped.  The table above
#: sets these rules side by side.
DIGITS = 4


#: Data columns per Markdown table.  A wider table continues in a second table below it, so that each fits the
#: page.
MAX_COLUMNS = 6


def format_value(v, column: str = "", *, unit: bool = True) -> str:
    """One table cell: :data:`DIGITS` significant digits (below 10⁻³ as ``2.572 × 10⁻⁵``,
    :func:`~rfmap.core.wording.format_sig`);
    times (column ``time``, seconds) as ``12.3 ms`` or
    ``2.43 s`` (without ``unit``: seconds, as a plain number); speed-ups as ``41.2×``; integers exactly; a missing
    value as an em dash (empty without ``unit``)."""
    if v is None:
        return "—" if unit else ""
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (list, tuple)):
        return "(" + ", ".join(f"{float(x):.{DIGITS - 1}g}" for x in v) + ")"
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if not unit:
            return f"{v:.{DIGITS}g}"
        if column == "time":
            ms = float(f"{v * 1e3:.{DIGITS - 1}g}")  # rounded first: 0.9997 s is 1 s, not 1e+03 ms
            return f"{ms:g} ms" if abs(ms) < 1000 else f"{v:.{DIGITS - 1}g} s"
        if column == "speedup":
            return f"{v:.{DIGITS - 1}g}×"
        return format_sig(v, DIGITS)
    return str(v)


@lru_cache(maxsize=1)
def _paper() -> dict:
    return json.loads((DATA / "paper_tables.json").read_text())["tables"]


def paper_table(label: str) -> dict:
    """Published values of a paper table (``tab:...``): ``{'columns': [...], 'rows': {key: {col: value}}}``."""
    t = _paper()
    if label not in t:
        raise ValueError(f"unknown paper table {label!r}; known: {', '.join(t)}")
    return t[label]


@dataclass
class Table:
    """Rows of ``(case, method, {column: value})`` with Markdown and CSV output."""

    label: str
    title: str
    columns: list[str]
    rows: list[tuple[str, str, dict]] = field(default_factory=list)
    #: How the Markdown cells of a column are written, one notation throughout the column: ``{column: function of
    #: the value}`` (a missing value is an em dash).  The other columns are written by :func:`format_value`, and so
    #: is every column of the CSV.
    formats: dict = field(default_factory=dict)
    #: The Markdown heads of the ``case`` and ``method`` columns.
    heads: tuple[str, str] = ("case", "method")

    def cell(self, value, column: str) -> str:
        """One Markdown cell: by the column's entry of :attr:`formats`, else :func:`format_value`."""
        if value is not None and column in self.formats:
            return self.formats[column](value)
        return format_value(value, column)

    def add(self, case: str, method: str, values: dict) -> None:
        self.rows.append((str(case), method, dict(values)))

    def value(self, case: str, method: str, column: str):
        for c, m, v in self.rows:
            if c == str(case) and m == method:
                return v.get(column)
        raise KeyError((case, method, column))

    def to_markdown(self, max_columns: int | None = MAX_COLUMNS) -> str:
        """The table as Markdown (cells by :meth:`cell`).  With more than ``max_columns`` data columns
        it is wrapped: the further columns follow in another table with the same ``case`` and ``method``
        columns."""
        cols = list(self.columns)
        parts_n = -(-len(cols) // max_columns) if max_columns and cols else 1
        step = max(1, -(-len(cols) // parts_n))  # balanced: 9 columns at most 6 per table give 5 + 4
        parts = []
        for i in range(0, max(len(cols), 1), step):
            chunk = cols[i:i + step]
            head = list(self.heads) + [COLUMN_TITLES.get(c, c).replace("|", "\\|") for c in chunk]
            lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
            for case, method, vals in self.rows:
                lines.append("| " + " | ".join([case, method] + [self.cell(vals.get(c), c) for c in chunk]) + " |")
            parts.append("\n".join(lines))
        return "\n\n".join(parts)

    def to_csv(self) -> str:
        """The table as CSV: one header row of column keys, numbers to :data:`DIGITS` significant digits (times in
        seconds), empty cells for missing values."""
        buf = io.StringIO()
        w = csv.writer(buf)
        w.writerow(["case", "method"] + self.columns)
        for case, method, vals in self.rows:
            w.writerow([case, method] + [format_value(vals.get(c), c, unit=False) for c in self.columns])
        return buf.getvalue()

    def _repr_markdown_(self) -> str:
        return f"**{self.title}**\n\n" + self.to_markdown()

    def save(self, out_dir) -> list[Path]:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        stem = self.label.replace(":", "-").replace("_", "-")
        md, cs = out / f"{stem}.md", out / f"{stem}.csv"
        md.write_text(f"{self.title}\n\n{self.to_markdown()}\n")
        cs.write_text(self.to_csv())
        return [md, cs]


def printed_digits(v: float) -> int:
    """The significant digits of the shortest text of ``v`` (``0.000006``: 1, ``0.082541``: 5): the digits a
    published value was printed with, where it is stored as the float of that text."""
    if float(v) == 0 or not np.isfinite(float(v)):
        return 1
    return len(Decimal(repr(abs(float(v)))).normalize().as_tuple().digits)


def rate_text(v) -> str:
    """A learning rate or a weight decay as papers print it, always as a power of ten with the digits it was given
    with (:func:`printed_digits`): ``5e-4`` → ``"5 × 10⁻⁴"``, ``0.001`` → ``"1 × 10⁻³"``, so that a column or a
    sentence of rates never mixes ``0.0005`` with ``1e-05``; zero → ``"0"``."""
    v = float(v)
    return "0" if v == 0 else power_of_ten(v, printed_digits(v))


def decimal_text(v, digits: int = 3) -> str:
    """A number with ``digits`` significant digits in positional notation, never in powers of ten
    (``0.0006288`` → ``"0.000629"``, ``0.07308`` → ``"0.0731"``, ``761.3`` → ``"761"``): one notation for a column
    whose values span several orders of magnitude below 1000."""
    v = float(v)
    if v == 0 or not np.isfinite(v):
        return format_sig(v, digits)
    out = np.format_float_positional(v, precision=digits, unique=False, fractional=False, trim="-")
    return out.rstrip(".")


@dataclass
class Headline:
    """One experiment at a glance: per case the delivered result, the paper's value, the classical solver's and
    whether the paper's value is met (``ours <= paper`` for a metric where lower is better).  ``paper_label``
    names that column where the value to meet is a target rather than the paper's; ``classical_label`` names the
    classical solver of its column (the headlines of :mod:`rfmap.paper.reproduce` name the diffusion DEM or the
    LBS).

    Two criteria of "met" coexist, one per kind of table.  A headline's ``met`` judges the map in its ``ours``
    column: in the headlines of :mod:`rfmap.paper.reproduce`, the best *delivered* map, and the column's head says
    so (``ours, best delivered``).  The scoreboard and :meth:`rfmap.paper.comparison.Comparison.met` judge the
    *paper's method* (native, refined, not repaired) and skip the cases whose input is not the paper's.  The two
    counts of one paper table can therefore differ.

    Build it with :func:`headline`; show it with ``display(Markdown(h.to_markdown()))`` or as the cell's value.
    """

    title: str
    metric: str
    rows: list[tuple[str, float | None, float | None, float | None]]
    ours_label: str = "ours"
    classical_label: str = "classical"
    lower_is_better: bool = True
    paper_label: str = "paper"

    def met_of(self, ours, paper) -> bool | None:
        if ours is None or paper is None:
            return None
        return bool(ours <= paper) if self.lower_is_better else bool(ours >= paper)

    @property
    def met(self) -> int:
        """How many cases meet the paper's value."""
        return sum(bool(self.met_of(o, p)) for _, o, p, _ in self.rows)

    @property
    def compared(self) -> int:
        """How many cases have a paper value to meet."""
        return sum(self.met_of(o, p) is not None for _, o, p, _ in self.rows)

    def to_markdown(self) -> str:
        has_classical = any(c is not None for *_, c in self.rows)
        head = ["case", f"{self.ours_label}", self.paper_label] + ([self.classical_label] if has_classical else [])
        head += [f"{self.ours_label} / {self.paper_label}", "met"]
        lines = ["| " + " | ".join(h.replace("|", "\\|") for h in head) + " |", "|" + "---|" * len(head)]
        for case, ours, paper, classical in self.rows:
            ratio = ours / paper if ours is not None and paper else None
            met = self.met_of(ours, paper)
            cells = [case, format_sig(ours), format_sig(paper)] + ([format_sig(classical)] if has_classical else [])
            cells += ["—" if ratio is None else f"{ratio:.3g}×", "—" if met is None else ("yes" if met else "no")]
            lines.append("| " + " | ".join(cells) + " |")
        return f"{self.metric}; met: {self.met} of {self.compared}.\n\n" + "\n".join(lines)

    def _repr_markdown_(self) -> str:
        return f"**{self.title}**\n\n" + self.to_markdown()


def headline(title: str, metric: str, ours: dict, paper: dict | None = None, classical: dict | None = None, *,
             labels: dict[str, str] | None = None, lower_is_better: bool = True) -> Headline:
    """The headline table of an experiment from three mappings ``case -> value`` (the cases are those of ``ours``,
    in its order; a case missing from ``paper`` or ``classical`` shows an em dash).  ``labels`` names the columns
    where they differ from ``{"ours": "ours", "paper": "paper", "classical": "classical"}`` (e.g. ``{"paper":
    "target"}`` where the value to meet is a target).

    Examples
    --------
    >>> h = headline("Square boundary", "Std ρ̃ map", {"ring": 0.041},
    ...              {"ring": 0.0488}, {"ring": 0.012})
    >>> h.met
    1
    """
    paper, classical = paper or {}, classical or {}
    rows = [(str(c), None if v is None else float(v), _num(paper.get(c)), _num(classical.get(c)))
            for c, v in ours.items()]
    names = {"ours": "ours", "paper": "paper", "classical": "classical", **(labels or {})}
    unknown = set(names) - {"ours", "paper", "classical"}
    if unknown:
        raise ValueError(f"unknown headline columns {sorted(unknown)}; expected ours, paper, classical")
    return Headline(title, metric, rows, names["ours"], names["classical"], lower_is_better, names["paper"])


def _num(v) -> float | None:
    return None if v is None else float(v)


def span_text(lo: float, hi: float, fmt: str = ".3g") -> str:
    """A range for the book's text: ``"0.41 to 0.57"``, or one value where both ends print the same
    (``"0.57"``, never ``"0.57 to 0.57"``).  ``fmt``: the format of each end."""
    a, b = format(float(lo), fmt), format(float(hi), fmt)
    return a if a == b else f"{a} to {b}"


def change_text(before: float, after: float, fmt: str | None = None, digits: int = 4) -> str:
    """A change for the book's text: ``"goes from 1.083 to 0.1162"``, or ``"stays at 0.1923 (to the digits
    shown)"`` where both values print the same.  Each value has ``digits`` significant digits
    (:func:`~rfmap.core.wording.format_sig`: below 10⁻³ as a power of ten), so a small value is never rounded to a
    zero it did not reach; ``fmt``, where given, is a format of each value instead (``".4f"``).

    Examples
    --------
    >>> change_text(1.08314, 0.11617)
    'goes from 1.083 to 0.1162'
    >>> change_text(0.01234, 0.0004567)
    'goes from 0.01234 to 4.567 × 10⁻⁴'
    """
    def show(v: float) -> str:
        return format_sig(float(v), digits) if fmt is None else format(float(v), fmt)

    a, b = show(before), show(after)
    return f"goes from {a} to {b}" if a != b else f"stays at {a} (to the digits shown)"


def agreement_text(difference: float, digits: int = 2) -> str:
    """How close two results that should agree are, for the book's text: ``"identical (largest difference 0)"`` where
    the largest difference is exactly zero, else ``"equal to within 2.4 × 10⁻⁸"``
    (:func:`~rfmap.core.wording.format_sig`, never e-notation)."""
    difference = abs(float(difference))
    if difference == 0:
        return "identical (largest difference 0)"
    return f"equal to within {format_sig(difference, digits)}"


def one_notation(values: dict[str, str], groups: list[str]) -> dict[str, str]:
    """The formatted numbers of ``values`` in one notation per group, so that a column of the scoreboard reads
    alike: where any entry of a group (the keys ``{group}_...``, each key in the longest group it starts with) is
    a power of ten, every positional number of the group becomes one too, with the significant digits it was
    printed with (``0.001946`` → ``1.946 × 10⁻³`` beside ``2.822 × 10⁻⁴``).  Entries that are not decimal numbers
    (``"3 of 4"``, ``"—"``, ``"yes"``, integers) are kept as they are.

    Examples
    --------
    >>> out = one_notation({"dd_a": "0.001946", "dd_b": "2.822 × 10⁻⁴",
    ...                     "dd_met": "1 of 2", "mu_a": "0.1200"}, ["dd", "mu"])
    >>> out["dd_a"], out["dd_b"]
    ('1.946 × 10⁻³', '2.822 × 10⁻⁴')
    >>> out["dd_met"], out["mu_a"]
    ('1 of 2', '0.1200')
    """
    def group(key: str) -> str | None:
        return max((g for g in groups if key.startswith(f"{g}_")), key=len, default=None)

    members: dict[str, list[str]] = {}
    for key in values:
        members.setdefault(group(key), []).append(key)
    out = dict(values)
    for g, keys in members.items():
        if g is not None and any("×" in str(values[k]) for k in keys):
            out.update({k: _power_text(values[k]) for k in keys})
    return out


def _power_text(text):
    """A positional decimal number as a power of ten with its printed significant digits; anything else as it is."""
    if not isinstance(text, str) or "." not in text or "×" in text:
        return text
    try:
        d = Decimal(text)
    except ArithmeticError:
        return text
    digits = d.as_tuple().digits
    significant = len(digits) - next((i for i, x in enumerate(digits) if x), len(digits))
    return power_of_ten(float(d), significant) if d and significant else text


def glue_all(values: dict, prefix: str) -> None:
    """Store every entry of ``values`` under the name ``{prefix}_{key}``, for the chapter's text to quote
    (``myst_nb.glue``, not displayed)."""
    from myst_nb import glue

    for key, value in values.items():
        glue(f"{prefix}_{key}", value, display=False)


def _csv_cell(v) -> str:
    """A value of a comparison's CSV: six significant digits, integers exactly, a list space-separated."""
    if v is None:
        return ""
    if isinstance(v, (list, tuple)):
        return " ".join(f"{float(a):.6g}" for a in v)
    return str(int(v)) if isinstance(v, (int, np.integer)) else f"{float(v):.6g}"
