r"""Values for cartograms from tables: a CSV joined to GeoJSON regions by an id, a template to fill in, and the
world's population by year.

A cartogram (:func:`rfmap.cartogram.resize.cartogram`) reads one value per region from a feature property.  Values often
live in a table instead: :func:`read_csv_values` reads a CSV column by an id column (every value a number
:math:`\ge 0`), and :func:`join_values` writes it onto the regions whose id property matches, as cartogram programs
do (``cartogram-cpp --id --area``).  Ids are compared as text (``11`` and ``11.0`` are the same id); an id left
without a partner is then compared with accents and case ignored (:func:`loose_id`: "Fryslan" finds "Fryslân"), and
joined where that comparison finds exactly one partner on each side.  Such pairs are reported, and so are the ids
that it finds several partners for ("did you mean ...").  A region without a row is reported and, by default, takes
the mean density of the matched regions,

.. math:: v_i = a_i \, \frac{\sum_{j \in M} v_j}{\sum_{j \in M} a_j},

(:math:`a` its area in the equal-area plane, :math:`M` the matched regions), so that it keeps about its size; a row
without a region is reported too.  :func:`write_csv_template` writes the table to fill in: one row per region with
its id and an empty value column.

:func:`world_population` joins plotly's gapminder table (population of 142 countries every five years, 1952-2007) to
the Natural Earth countries of :func:`rfmap.cartogram.regions.world_countries` by ISO 3166-1 alpha-3 code.

Nothing here imports PyTorch.
"""
from __future__ import annotations

import csv
import io
import math
import os
import unicodedata
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..core.wording import counted
from .projection import PlanarFrame
from .regions import _load_collection, world_countries

__all__ = ["Join", "MISSING", "GAPMINDER_YEARS", "SPLIT_ROWS", "read_csv_table", "read_csv_values", "region_ids", "loose_id",
           "join_values",
           "write_csv_template", "gapminder_population", "world_population", "atomic_write"]

#: What :func:`join_values` does with a region that has no row: give it the matched regions' ``"mean"`` density,
#: ``"drop"`` it from the map, or raise (``"error"``).
MISSING = ("mean", "drop", "error")
#: The years of plotly's gapminder table.
GAPMINDER_YEARS = tuple(range(1952, 2008, 5))


def _id_text(v) -> str | None:
    """An id as text: integral numbers without a decimal point (``11.0`` -> ``"11"``), strings stripped."""
    if v is None:
        return None
    if isinstance(v, float) and v.is_integer():
        return str(int(v))
    return str(v).strip()


def atomic_write(path, write, *, newline: str | None = None) -> None:
    """Call ``write(fh)`` on a text file that replaces ``path`` only once it is complete, so that no partial file is
    left behind (a failed ``write`` removes it)."""
    path = os.fspath(path)
    tmp = f"{path}.part"
    try:
        with open(tmp, "w", encoding="utf-8", newline=newline) as fh:
            write(fh)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def _atomic_write_text(path, text: str) -> None:
    """Write ``text`` to ``path`` through :func:`atomic_write`."""
    atomic_write(path, lambda fh: fh.write(text), newline="")


# ----------------------------------------------------------------------------------------------- CSV
def _decode_csv(data: bytes, name: str) -> str:
    """The text of a CSV file: UTF-8 (a byte-order mark allowed), else Windows-1252 with a warning (the encoding
    spreadsheets and census tables often export, where a name such as "Doña Ana" is one byte per letter); bytes
    that are neither, or a NUL byte (UTF-16, a binary file), are a ``ValueError``."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        if b"\x00" in data:
            raise ValueError(f"cannot read {name}: not UTF-8 text ({e.reason} at byte {e.start})") from e
        try:
            text = data.decode("cp1252")
        except UnicodeDecodeError:
            raise ValueError(f"cannot read {name}: not UTF-8 text ({e.reason} at byte {e.start})") from e
    warnings.warn(f"{name} is not UTF-8 text; read as Windows-1252", UnicodeWarning, stacklevel=3)
    return text


def read_csv_table(path, id_column: str, columns=()) -> dict[str, dict[str, str]]:
    """The rows of a CSV file by id: ``{id: {column: text}}`` for the named ``columns``.

    Parameters
    ----------
    path : str or path
        A CSV file with a header row (UTF-8, a byte-order mark allowed; else Windows-1252, with a
        ``UnicodeWarning``).
    id_column : str
    columns : sequence of str
        Further columns to keep (each must be in the header).

    Raises
    ------
    ValueError
        One line: the file cannot be read, has no header, lacks ``id_column`` or a named column, or has a row
        without an id or an id twice.
    """
    name = os.fspath(path)
    try:
        with open(name, "rb") as fh:
            text = _decode_csv(fh.read(), name)
        reader = csv.DictReader(io.StringIO(text, newline=""))
        header = reader.fieldnames
        rows = list(reader)
    except OSError as e:
        raise ValueError(f"cannot read {name}: {e.strerror or e}") from e
    except csv.Error as e:
        raise ValueError(f"cannot read {name}: not a CSV table ({e})") from e
    if not header:
        raise ValueError(f"{name} has no header row")
    for col in (id_column, *columns):
        if col not in header:
            raise ValueError(f"{name} has no column {col!r} (columns: {', '.join(map(str, header))})")
    out: dict[str, dict[str, str]] = {}
    for k, row in enumerate(rows, start=2):
        rid = _id_text(row.get(id_column))
        if not rid:
            raise ValueError(f"{name}, line {k}: no {id_column!r}")
        if rid in out:
            raise ValueError(f"{name}, line {k}: the id {rid!r} appears twice")
        out[rid] = {c: (row.get(c) or "").strip() for c in columns}
    return out


def read_csv_values(path, id_column: str, value_column: str) -> dict[str, float]:
    r"""One number :math:`\ge 0` per id from a CSV file: ``{id: value}``, usable with :func:`join_values`.

    Raises
    ------
    ValueError
        One line, as :func:`read_csv_table`, or naming the first row whose value is missing (empty), not a number,
        NaN or infinite, or negative.
    """
    table = read_csv_table(path, id_column, (value_column,))
    values = {}
    for rid, row in table.items():
        text = row[value_column]
        where = f"{os.fspath(path)}: {value_column!r} of {rid!r}"
        if not text:
            raise ValueError(f"{where} is missing")
        try:
            v = float(text)
        except ValueError:
            raise ValueError(f"{where} = {text!r} is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"{where} is {text} (NaN or infinite)")
        if v < 0:
            raise ValueError(f"{where} = {text} is negative")
        values[rid] = v
    return values


# ----------------------------------------------------------------------------------------------- regions
def _features(collection) -> list:
    fc = _load_collection(collection)
    if not isinstance(fc, dict) or fc.get("type") != "FeatureCollection" or not isinstance(fc.get("features"), list):
        raise ValueError("not a GeoJSON FeatureCollection (need {'type': 'FeatureCollection', 'features': [...]})")
    if not fc["features"]:
        raise ValueError("the FeatureCollection has no features")
    return fc["features"]


def region_ids(collection, key: str) -> list[str | None]:
    """The id of every region: its property ``key``, or, for ``key="id"`` where no region has that property, the
    feature's own ``id``; ``None`` for a region without one.

    Raises
    ------
    ValueError
        When no region has an id under ``key`` (one line, listing the properties there are).
    """
    feats = _features(collection)
    props = [f.get("properties") or {} if isinstance(f, dict) else {} for f in feats]
    if key == "id" and not any("id" in p for p in props):
        ids = [_id_text(f.get("id")) if isinstance(f, dict) else None for f in feats]
    else:
        ids = [_id_text(p.get(key)) for p in props]
    if not any(ids):
        names = sorted({k for p in props for k in p})
        raise ValueError(f"no region has the property {key!r} (properties: {', '.join(names) or 'none'})")
    return ids


@dataclass
class Join:
    """Values joined to regions (:func:`join_values`).

    Attributes
    ----------
    collection : dict
        The FeatureCollection with the value (and any ``extra`` columns) as properties of every region kept.
    value : str
        The property that holds the value.
    matched : int
        Regions that found a row.
    unmatched_regions : list of str
        Ids (or ``#k``) of the regions without a row, in map order.
    unmatched_rows : list of str
        Ids of the rows without a region, sorted.
    missing : str
        What was done with the unmatched regions (:data:`MISSING`, or ``"fallback"`` where all had one).
    loose : list of (str, str)
        ``(region id, row id)`` of the pairs joined with accents and case ignored (:func:`loose_id`), in map order;
        counted in ``matched``.
    ambiguous : list of (str, list of str)
        ``(region id, row ids)`` of the unmatched regions whose id, accents and case ignored, is that of several rows
        or is shared with other unmatched regions: the candidates of a "did you mean", in map order.
    """

    collection: dict
    value: str
    matched: int
    unmatched_regions: list = field(default_factory=list)
    unmatched_rows: list = field(default_factory=list)
    missing: str = "mean"
    loose: list = field(default_factory=list)
    ambiguous: list = field(default_factory=list)

    def report(self) -> list[str]:
        """Two lines, and up to two more: the regions without a row (how many, what they were given, their ids;
        ``none`` when every region has a row), and the rows without a region; then, where there are any, a line
        for the pairs joined with accents and case ignored, and one for the ambiguous near-matches."""
        todo = {"mean": "given the mean density", "drop": "left out", "error": "", "fallback": "given a fallback"}
        n_regions, n_rows = len(self.unmatched_regions), len(self.unmatched_rows)
        lines = [f"regions without data ({n_regions}, {todo[self.missing]}): {', '.join(self.unmatched_regions)}"
                 if n_regions else "regions without data: none",
                 f"data without a region ({n_rows}): {', '.join(self.unmatched_rows)}"
                 if n_rows else "data without a region: none"]
        if self.loose:
            pairs = ", ".join(f"{region!r} = {row!r}" for region, row in self.loose)
            lines.append(f"joined with accents and case ignored ({len(self.loose)}, region = data): {pairs}")
        if self.ambiguous:
            asks = "; ".join(f"{region!r}: did you mean {' or '.join(map(repr, rows))}?"
                             for region, rows in self.ambiguous)
            lines.append(f"not joined, several near-matches ({len(self.ambiguous)}): {asks}")
        return lines


def loose_id(text: str) -> str:
    """An id with accents and case ignored: Unicode NFKD, the combining marks dropped, case-folded
    (``"Fryslân"`` -> ``"fryslan"``, ``"ÎLE-DE-FRANCE"`` -> ``"ile-de-france"``)."""
    parts = unicodedata.normalize("NFKD", text)
    return "".join(c for c in parts if not unicodedata.combining(c)).casefold()


def _match_rows(ids: list, values: Mapping[str, float], key: str) -> tuple[list, list, list]:
    """The row id of every region (``None`` where there is none): exact matches first, then the ids that, with
    accents and case ignored (:func:`loose_id`), have exactly one partner on each side.

    Returns
    -------
    rows : list of str or None, one per region
    loose : list of (int, str)
        The regions (index) joined to a row (id) by the loose comparison.
    ambiguous : list of (int, list of str)
        The regions (index) left unmatched whose loose id is that of several rows, or of one row that several
        unmatched regions share.
    """
    seen: dict[str, int] = {}
    for k, rid in enumerate(ids):
        if rid in values:
            if rid in seen:
                raise ValueError(f"the id {rid!r} names two regions (#{seen[rid]} and #{k}); ids must be unique")
            seen[rid] = k
    rows = [rid if rid in values else None for rid in ids]
    free_rows: dict[str, list[str]] = {}
    for rid in values:
        if rid not in seen:
            free_rows.setdefault(loose_id(rid), []).append(rid)
    free_regions: dict[str, list[int]] = {}
    for k, rid in enumerate(ids):
        if rid and rows[k] is None:
            free_regions.setdefault(loose_id(rid), []).append(k)
    loose, ambiguous = [], []
    for folded, regions in free_regions.items():
        candidates = sorted(free_rows.get(folded, []))
        if len(candidates) == 1 and len(regions) == 1:
            rows[regions[0]] = candidates[0]
            loose.append((regions[0], candidates[0]))
        elif candidates:
            ambiguous.extend((k, candidates) for k in regions)
    if not any(r is not None for r in rows):
        raise ValueError(f"no region's {key!r} matches an id of the data (e.g. {next(iter(values), 'none')!r} "
                         f"against {next((i for i in ids if i), 'none')!r})")
    return rows, sorted(loose), sorted(ambiguous)


def _areas(features: list, projection: str) -> np.ndarray:
    """Areas of the features' polygons in the equal-area plane of :class:`rfmap.cartogram.projection.PlanarFrame`."""
    import shapely
    from shapely.geometry import shape

    try:
        geoms = np.array([shape(f["geometry"]) for f in features], dtype=object)
    except Exception as e:  # noqa: BLE001 - shapely raises several types for malformed geometries
        raise ValueError(f"a region has no readable Polygon / MultiPolygon geometry ({e})") from e
    frame = PlanarFrame.fit(geoms, margin=0.0, projection=projection)
    return shapely.area(frame.equal_area(frame.project(geoms)))


def join_values(collection, values: Mapping[str, float], *, key: str = "id", value: str = "value",
                missing: str = "mean", fallback: Mapping[str, float] | None = None,
                extra: Mapping[str, Mapping[str, object]] | None = None, projection: str = "auto") -> Join:
    """Values by id written onto the regions whose ``key`` matches (see :mod:`rfmap.cartogram.data`).

    Parameters
    ----------
    collection : dict, str or path
        A GeoJSON FeatureCollection.
    values : mapping
        ``{id: number}`` (:func:`read_csv_values`).
    key : str
        The region property that holds the id (:func:`region_ids`).
    value : str
        The property to write the value to (read it back with ``cartogram(join.collection, value)``).
    missing : {"mean", "drop", "error"}
        What a region without a value gets (:data:`MISSING`), after ``fallback``.
    fallback : mapping, optional
        ``{id: number}`` for regions without a row (still reported as unmatched).
    extra : mapping, optional
        ``{property: {id: anything}}`` written beside the value (a colour or label column).
    projection : str
        The plane in which areas are measured for ``missing="mean"`` (:class:`rfmap.cartogram.projection.PlanarFrame`).

    Returns
    -------
    Join

    Raises
    ------
    ValueError
        One line: no region has the id property, a matched id names two regions, no region is matched, or a
        region has no value with ``missing="error"``.
    """
    if missing not in MISSING:
        raise ValueError(f"unknown missing {missing!r}; choose one of {', '.join(MISSING)}")
    feats = _features(collection)
    ids = region_ids(collection if isinstance(collection, dict) else {"type": "FeatureCollection",
                                                                      "features": feats}, key)
    values = {_id_text(k): float(v) for k, v in values.items()}
    rows, loose, ambiguous = _match_rows(ids, values, key)
    names = [rid if rid else f"#{k}" for k, rid in enumerate(ids)]
    unmatched = [k for k, row in enumerate(rows) if row is None]
    v = np.array([values[row] if row is not None else np.nan for row in rows])
    fallback = {_id_text(k): float(x) for k, x in (fallback or {}).items()}
    for k in unmatched:
        v[k] = fallback.get(ids[k], np.nan)
    keep = np.ones(len(feats), dtype=bool)
    gap = np.isnan(v)
    if gap.any() and missing == "error":
        bad = np.flatnonzero(gap)
        raise ValueError(f"{counted(bad.size, 'region without data')}: {', '.join(names[k] for k in bad[:10])}")
    if gap.any() and missing == "drop":
        keep = ~gap
    elif gap.any():
        a = _areas(feats, projection)
        m = np.array([row is not None for row in rows])
        v[gap] = a[gap] * v[m].sum() / a[m].sum()
    out = []
    for k in np.flatnonzero(keep):
        f = feats[k]
        props = {**(f.get("properties") or {}), value: float(v[k])}
        for col, by_id in (extra or {}).items():
            props[col] = by_id.get(rows[k]) if rows[k] is not None else None
        out.append({**f, "properties": props})
    how = missing if gap.any() else ("fallback" if unmatched else missing)
    joined = {row for row in rows if row is not None}
    return Join({"type": "FeatureCollection", "features": out}, value, len(feats) - len(unmatched),
                [names[k] for k in unmatched], sorted(set(values) - joined), how,
                loose=[(names[k], row) for k, row in loose], ambiguous=[(names[k], c) for k, c in ambiguous])


def write_csv_template(collection, path, *, key: str = "id", value: str = "value") -> int:
    """Write the CSV to fill in: a header ``key,value`` and one row per region with its id and an empty value;
    returns the number of rows.

    Raises
    ------
    ValueError
        When a region has no id under ``key`` (:func:`region_ids`) or two regions share one.
    """
    ids = region_ids(collection, key)
    missing = [f"#{k}" for k, rid in enumerate(ids) if not rid]
    if missing:
        raise ValueError(f"{counted(len(missing), 'region without')} {key!r}: {', '.join(missing[:10])}")
    dup = sorted({rid for rid in ids if ids.count(rid) > 1})
    if dup:
        raise ValueError(f"ids that name several regions: {', '.join(map(repr, dup[:10]))}; ids must be unique")
    import io

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([key, value])
    w.writerows([rid, ""] for rid in ids)
    _atomic_write_text(path, buf.getvalue())
    return len(ids)


# ----------------------------------------------------------------------------------------------- world
def gapminder_population(year: int) -> dict[str, float]:
    """Population by ISO 3166-1 alpha-3 code in ``year`` (one of :data:`GAPMINDER_YEARS`) from plotly's gapminder
    table (needs the ``geo`` extra); North Korea, which the table files under South Korea's code, under its own."""
    try:
        import plotly.data
    except ImportError as e:
        raise ImportError("the gapminder table comes with plotly: pip install 'rfmap[geo]'") from e
    if year not in GAPMINDER_YEARS:
        raise ValueError(f"gapminder has the years {GAPMINDER_YEARS[0]}-{GAPMINDER_YEARS[-1]} every five; "
                         f"got {year!r}")
    g = plotly.data.gapminder()
    g = g[g["year"] == year]
    # the table gives North Korea ("Korea, Dem. Rep.") South Korea's code, KOR; North Korea's is PRK
    iso = ["PRK" if c == "Korea, Dem. Rep." else str(i) for c, i in zip(g["country"], g["iso_alpha"])]
    return {i: float(p) for i, p in zip(iso, g["pop"])}


#: Rows of the gapminder table that cover several countries of today's map: its Sudan (to 2007) is the Sudan of
#: before 2011, South Sudan included.  :func:`world_population` splits such a row in proportion to Natural Earth's
#: estimates of the parts.
SPLIT_ROWS = {"SDN": ("SDN", "SSD")}


def world_population(years=(2007,), *, antarctica: bool = False) -> Join:
    r"""The countries of :func:`rfmap.cartogram.regions.world_countries` with their population in each of ``years`` as the
    properties ``pop_<year>``, joined to the gapminder table by ISO-3 code (``iso_a3``).

    The borders are Natural Earth's, of about 2019; gapminder gives each country's population within its present
    borders back to 1952 (one Germany, Slovenia apart from Yugoslavia), and a row that today's map divides
    (:data:`SPLIT_ROWS`) is split in proportion to Natural Earth's estimates ``pop_est`` of the parts.  A country
    without a gapminder row (Russia, the other former Soviet republics, ...) keeps its share of those estimates
    (about 2019) in every year: :math:`v_i = e_i \sum_{j \in M} v_j / \sum_{j \in M} e_j` over the matched
    countries :math:`M` of that year, so its size follows the world's total, not its own population.  Antarctica,
    nearly unpeopled, is left out unless ``antarctica``.

    Returns
    -------
    Join
        ``collection`` with the ``pop_<year>`` properties (``value`` is the first year's), the countries without a
        gapminder row (by name) and the gapminder codes without a country of the map.
    """
    years = [int(y) for y in years]
    if not years:
        raise ValueError("give at least one year")
    world = world_countries()
    feats = [f for f in world["features"] if antarctica or f["properties"]["name"] != "Antarctica"]
    fc = {"type": "FeatureCollection", "features": feats}
    estimate = {f["properties"]["iso_a3"]: float(f["properties"]["pop_est"]) for f in feats}
    joins = []
    for year in years:
        pop = gapminder_population(year)
        for row, parts in SPLIT_ROWS.items():
            if row in pop and all(p in estimate for p in parts):
                total, whole = pop.pop(row), sum(estimate[p] for p in parts)
                pop.update({p: total * estimate[p] / whole for p in parts})
        matched = [iso for iso in estimate if iso in pop]
        ratio = sum(pop[iso] for iso in matched) / sum(estimate[iso] for iso in matched)
        fallback = {iso: e * ratio for iso, e in estimate.items() if iso not in pop}
        joins.append(join_values(fc, pop, key="iso_a3", value=f"pop_{year}", missing="error", fallback=fallback))
        fc = joins[-1].collection
    names = {f["properties"]["iso_a3"]: f["properties"]["name"] for f in feats}
    first = joins[0]
    return Join(fc, first.value, first.matched, [names.get(i, i) for i in first.unmatched_regions],
                first.unmatched_rows, "fallback")
