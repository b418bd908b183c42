r"""Area errors and topology of cartograms: the metrics of the cartogram literature, judged over the regions that hold
a given share of the total value, and the repair of numerically tiny folds.

The relative area error of region :math:`i` is :math:`|A_i / T_i - 1|` with the target :math:`T_i = (v_i / \sum_j v_j)
\sum_j A_j`; its mean and maximum are taken over the regions holding at least ``min_share`` of the total value
(:data:`MIN_SHARE` in :func:`~rfmap.cartogram.resize.cartogram`), and the others' largest error is reported apart.  The
topology check asks that every polygon be valid and that no two regions overlap by more than ``overlap_tol`` of the
total area.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.wording import counted
from .regions import _distinct_vertices, _shapely

__all__ = ["CartogramMetrics", "Topology", "cartogram_metrics", "overlaps", "judged", "pass_weights", "repair_folds",
           "repair_overlaps", "valid_polygons", "clean_input_overlaps", "boost", "MIN_SHARE", "MINOR_BUDGET", "SPLITS", "SPLIT_COST",
           "REPAIR_AREA", "REPAIR_OVERLAP", "SLIVER_SHAPE", "SLIVER_SHARE", "BOOST_GAIN", "BOOST_CAP"]

#: The share of the total value from which a region's area error is judged (stopping rule,
#: :meth:`~rfmap.cartogram.resize.Cartogram.metrics`, tolerance): 0.01 %.  Smaller regions (a world map's uninhabited
#: Antarctica, islands of a few thousand people) are at most a few grid cells, where no raster resolves 1 %; their
#: errors are reported apart (``max_error_minor``).
MIN_SHARE = 1e-4
#: The most that :func:`pass_weights` adds to the total value by raising the regions under the judged share (a share
#: of it): every judged region comes out smaller by about this share, so it must stay well below a tolerance of 1 %
MINOR_BUDGET = 1e-3
#: The largest change of area (a fraction of the total) by which :func:`repair_folds` fixes an invalid mapped
#: polygon: the default ``overlap_tol`` of the metrics, below which an overlap of two regions is not counted either
REPAIR_AREA = 1e-6
#: The largest overlap of two mapped regions (a fraction of the total area) that :func:`repair_overlaps` removes: two
#: neighbours that the input keeps a fraction of a grid cell apart (a lake, a river drawn as a gap) can be pressed
#: together by the passes until their straight edges cross by a sliver
REPAIR_OVERLAP = 1e-5
#: The largest overlap that :func:`repair_overlaps` removes when it is thin (isoperimetric quotient under
#: ``SLIVER_SHAPE``): two tiny, dense regions that touch at a corner in the input, each grown hundredfold by the passes
REPAIR_SLIVER = 1e-4
#: :func:`clean_input_overlaps`: an overlap of two input regions is a sliver when its isoperimetric quotient is under
#: this (a strip ten times as long as wide: 0.26; a square: 0.79) or it holds under ``SLIVER_SHARE`` of either region
SLIVER_SHAPE = 0.3
#: :func:`clean_input_overlaps`: an overlap holding under this share of either of its two regions is a sliver
SLIVER_SHARE = 0.01
#: the width, in cells of the raster, under which an enclosed gap between input regions that :func:`clean_input_overlaps`
#: makes a coverage is closed (a quarter cell: far below what the raster resolves)
SLIVER_GAP = 0.25
#: :func:`boost`: the smallest share of a region's log area error that a pass is taken to remove
BOOST_GAIN = 0.25
#: :func:`boost`: the largest log weight boost (a factor of :math:`e^{0.4} \approx 1.5`); stronger boosts overshoot,
#: and the passes oscillate
BOOST_CAP = 0.4


@dataclass
class CartogramMetrics:
    r"""Area errors and topology of a cartogram (see :func:`cartogram_metrics`).

    The area error of region :math:`i` is its relative error :math:`|A_i / T_i - 1|` against its target area
    :math:`T_i`; the mean and largest errors are taken over the judged regions (at least the judged share of the
    total value, :data:`MIN_SHARE`).

    Attributes
    ----------
    mean_error : float
        The mean area error of the judged regions.
    max_error : float
        The largest area error of the judged regions.
    n_invalid : int
        Regions whose polygon is invalid (self-intersecting, a hole outside its shell, ...).
    max_overlap : float
        The largest area shared by two regions, as a share of the total area (0 when none overlap).
    n_overlapping : int
        Pairs of regions that overlap by more than ``overlap_tol``.
    overlap_tol : float
        The share of the total area above which two regions count as overlapping.
    n_minor : int
        Regions under the judged share, left out of ``mean_error`` and ``max_error``.
    max_error_minor : float
        The largest area error of those regions (0 when there are none).
    """

    mean_error: float
    max_error: float
    n_invalid: int
    max_overlap: float
    n_overlapping: int
    overlap_tol: float
    n_minor: int = 0
    max_error_minor: float = 0.0

    @property
    def topology_ok(self) -> bool:
        """Every polygon valid and no pair of regions overlapping by more than ``overlap_tol``."""
        return self.n_invalid == 0 and self.n_overlapping == 0

    def report_lines(self) -> list[str]:
        """Two lines: the area errors (and those of the regions under the judged share, where there are any), and
        the topology."""
        minor = f" ({counted(self.n_minor, 'region')} under the judged share: max {self.max_error_minor:.4f})" \
            if self.n_minor else ""
        topo = "valid, no overlaps" if self.topology_ok else \
            (f"{counted(self.n_invalid, 'invalid region')}, {counted(self.n_overlapping, 'overlapping pair')} "
             f"(the largest overlap {self.max_overlap:.2g})")
        return [f"area error mean {self.mean_error:.4f}, max {self.max_error:.4f}{minor}", f"topology: {topo}"]

    def __str__(self) -> str:
        errors, topo = self.report_lines()
        return f"{errors}; {topo}"


def cartogram_metrics(mapped: np.ndarray, values: np.ndarray, *, overlap_tol: float = 1e-6,
                      topology: bool | Topology = True, min_share: float = 0.0) -> CartogramMetrics:
    r"""Relative area errors and topology of mapped regions.

    The area error of region :math:`i` is :math:`|A_i / T_i - 1|` with :math:`T_i = (v_i/\sum_j v_j)\sum_j A_j`;
    a polygon is invalid when shapely says so (self-intersection, a hole outside its shell, ...); two regions
    overlap when the area of their intersection exceeds ``overlap_tol`` times the total area.

    Parameters
    ----------
    mapped : ndarray of shapely geometries, shape (R,)
    values : ndarray, shape (R,), positive
    overlap_tol : float
    topology : bool or Topology
        ``False`` skips the validity and overlap checks (their counts are then reported as zero); a
        :class:`Topology` of ``mapped`` (the same array) is taken instead of measuring them again.
    min_share : float
        The mean and largest error are taken over the regions with :math:`v_i \ge` ``min_share`` :math:`\sum_j v_j`;
        the others are counted in ``n_minor`` and their largest error is ``max_error_minor``.

    Returns
    -------
    CartogramMetrics
    """
    shapely = _shapely()
    a = shapely.area(mapped)
    err = np.abs(a / (values / values.sum() * a.sum()) - 1.0)
    major = judged(values, min_share)
    minor = dict(n_minor=int((~major).sum()), max_error_minor=float(err[~major].max()) if (~major).any() else 0.0)
    err = err[major]
    if topology is False:
        return CartogramMetrics(float(err.mean()), float(err.max()), 0, 0.0, 0, overlap_tol, **minor)
    topo = topology if isinstance(topology, Topology) and topology.geoms is mapped else Topology.of(mapped)
    valid, total = topo.valid, float(a.sum())
    rel = topo.pairs[2] / total  # an invalid polygon's overlaps are not measured: it counts as invalid
    return CartogramMetrics(mean_error=float(err.mean()), max_error=float(err.max()),
                            n_invalid=int((~valid).sum()), max_overlap=float(rel.max(initial=0.0)),
                            n_overlapping=int((rel > overlap_tol).sum()), overlap_tol=overlap_tol, **minor)


def overlaps(mapped: np.ndarray, valid: np.ndarray | None = None,
             among: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pairs ``i < j`` of valid regions whose interiors overlap, and the areas of their intersections (shapes
    (K,)); with ``among`` (indices), only the pairs that hold one of those regions.  Intersections are computed only
    for the pairs whose interiors meet (``shapely.relate_pattern`` ``"T********"``, asked of the pairs whose boxes
    meet: asking first which of them intersect at all costs more than it saves): neighbours that share a border, as
    the cartogram's passes keep them, merely touch."""
    shapely = _shapely()
    valid = shapely.is_valid(mapped) if valid is None else valid
    idx = np.flatnonzero(valid)
    ask = idx if among is None else np.intersect1d(idx, among)
    left, right = shapely.STRtree(mapped[idx]).query(mapped[ask])  # the pairs whose boxes meet
    left, right = ask[left], idx[right]
    if among is not None:  # each pair once, as i < j (a pair of two regions asked about came twice)
        left, right = np.unique(np.stack([np.minimum(left, right), np.maximum(left, right)]), axis=1)
    keep = left < right
    left, right = left[keep], right[keep]
    keep = shapely.relate_pattern(mapped[left], mapped[right], "T********") if left.size else np.zeros(0, bool)
    left, right = left[keep], right[keep]
    inter = shapely.area(shapely.intersection(mapped[left], mapped[right])) if left.size else np.zeros(0)
    pos = inter > 0
    return left[pos], right[pos], inter[pos]


@dataclass(frozen=True)
class Topology:
    """The validity (R,) of the polygons ``geoms`` (R,) and their overlapping pairs (:func:`overlaps`: ``left``,
    ``right``, ``inter``), measured once: :func:`cartogram_metrics` and :func:`repair_overlaps` take it for that
    same array only."""

    geoms: np.ndarray
    valid: np.ndarray
    pairs: tuple

    @classmethod
    def of(cls, geoms: np.ndarray, valid: np.ndarray | None = None) -> "Topology":
        """Measured (``valid``: ``shapely.is_valid(geoms)``, where the caller has it)."""
        valid = _shapely().is_valid(geoms) if valid is None else valid
        return cls(geoms, valid, overlaps(geoms, valid))

    def updated(self, geoms: np.ndarray, changed) -> "Topology":
        """The topology of ``geoms``, which differ from ``self.geoms`` in the regions ``changed`` only: those are
        measured again, with every pair that holds one of them; the result is :meth:`of`'s (its pairs in another
        order)."""
        changed = np.unique(np.asarray(changed, dtype=np.intp))
        if not changed.size:
            return Topology(geoms, self.valid, self.pairs)
        valid = self.valid.copy()
        valid[changed] = _shapely().is_valid(geoms[changed])
        left, right, inter = self.pairs
        stay = ~(np.isin(left, changed) | np.isin(right, changed))
        new = overlaps(geoms, valid, among=changed)
        return Topology(geoms, valid, tuple(np.concatenate([old[stay], fresh]) for old, fresh in zip(self.pairs, new)))


def judged(values: np.ndarray, min_share: float) -> np.ndarray:
    r"""The regions whose area errors are judged: :math:`v_i \ge` ``min_share`` :math:`\sum_j v_j` (all of them when
    none is), boolean, shape (R,)."""
    major = np.asarray(values) >= min_share * float(np.sum(values))
    return major if major.any() else np.ones_like(major)


def pass_weights(values: np.ndarray, min_share: float, budget: float = MINOR_BUDGET) -> np.ndarray:
    r"""The weights by which a cartogram's passes map the regions: the judged regions' values (:func:`judged`), the
    others' raised to a floor :math:`f`, so that none (an uninhabited Antarctica) collapses into a sliver that folds.

    With :math:`s` = ``min_share`` and :math:`b` = ``budget``, the floor is the judged share
    :math:`f = s \sum_j v_j`, unless raising the others to it adds more than :math:`b \sum_j v_j` in all (a county
    map holds a thousand regions under 0.01 %); then :math:`f` is the floor that adds exactly that,
    :math:`\sum_{i \notin J} \max(0, f - v_i) = b \sum_j v_j`.  Every judged region's target share is then off by at most ``budget``.

    Parameters
    ----------
    values : ndarray, shape (R,), positive
    min_share, budget : float

    Returns
    -------
    ndarray, shape (R,)
    """
    values = np.asarray(values, dtype=float)
    big = judged(values, min_share)
    total = float(values.sum())
    floor = min_share * total
    minor = np.sort(values[~big])
    if minor.size and np.maximum(floor - minor, 0.0).sum() > budget * total:
        # the added value is piecewise linear and increasing in f: find the piece that holds the budget
        added = np.arange(1, minor.size + 1) * minor - np.cumsum(minor)  # added when f = minor[k]
        k = int(np.searchsorted(added, budget * total, side="right"))  # f lies in [minor[k-1], minor[k])
        floor = (budget * total + minor[:k].sum()) / k
    return np.where(big, values, np.maximum(values, floor))


def repair_folds(mapped: np.ndarray, *, max_change: float = REPAIR_AREA,
                 valid: np.ndarray | None = None) -> tuple[np.ndarray, list]:
    """Invalid mapped polygons whose fix (``shapely.make_valid``) changes their area by at most ``max_change`` of the
    total area replaced by the fix: a crossing of two edges that the input drew nearly touching, which no map of the
    vertices alone keeps apart.  ``valid``: ``shapely.is_valid(mapped)``, where the caller has it (its entries of the
    polygons fixed are then set, so that it stays true of the polygons returned).  Returns the polygons and the
    indices of those fixed; larger folds stay invalid, for :meth:`~rfmap.cartogram.resize.Cartogram.problems` to
    report."""
    shapely = _shapely()
    bad = np.flatnonzero(~(shapely.is_valid(mapped) if valid is None else valid))
    if not bad.size:
        return mapped, []
    fixed = valid_polygons(mapped[bad])
    change = np.abs(shapely.area(fixed) - shapely.area(mapped[bad])) / shapely.area(mapped).sum()
    ok = (change <= max_change) & shapely.is_valid(fixed) & np.isin(shapely.get_type_id(fixed), (3, 6))
    out = mapped.copy()
    out[bad[ok]] = fixed[ok]
    if valid is not None:
        valid[bad[ok]] = True
    return out, [int(i) for i in bad[ok]]


def clean_input_overlaps(regions: np.ndarray, gap_width: float = 0.0) -> tuple[np.ndarray, int]:
    r"""Regions that overlap in the input made a coverage, so that neighbours share their borders.

    Input regions can overlap (borders drawn twice, a file simplified feature by feature).  ``shapely.coverage_clean``
    gives every overlap to one of its regions (the one with the longest border along it) and snaps nearby vertices,
    so that neighbours share their border vertex for vertex.  Enclosed gaps narrower than ``gap_width`` (slivers of
    sea that such a file opens between neighbours, which no raster resolves) go to the neighbour with the longest
    border along them, so that the two then share that border; wider gaps stay (sea).  The map of a coverage keeps
    its regions apart; a map of overlapping regions carries every overlap along, and the two sides of a sliver gap,
    drawn with different vertices, cross when the map closes it.

    Only slivers are cleaned: every overlap holding more than :data:`REPAIR_AREA` of the total area (the metrics'
    default tolerance; smaller ones are left to :func:`repair_overlaps`) must be

    * thin: its isoperimetric quotient :math:`4\pi A / P^2` under :data:`SLIVER_SHAPE`, or
    * small: under :data:`SLIVER_SHARE` of the smaller region's area.

    The overlaps are found among the regions with their vertices merged as the passes merge them
    (``_merged``): borders that two neighbours draw from opposite ends, equal to the last bits, then touch instead
    of overlapping by :math:`10^{-17}` of the map, which would cost an intersection per pair of neighbours; the
    overlaps found are measured on the regions themselves.

    The regions are returned as they are when no overlap holds more than :data:`REPAIR_AREA`; when one that does is
    not a sliver (a region drawn over half of another: bad input that
    :meth:`rfmap.cartogram.resize.Cartogram.problems` reports); and when the cleaning leaves a region empty or
    invalid, or shapely is older than 2.2.

    Parameters
    ----------
    regions : ndarray of shapely geometries, shape (R,)
    gap_width : float

    Returns
    -------
    (ndarray of shapely geometries, int)
        The regions and the number of overlapping pairs cleaned (0 when they are returned as they are).
    """
    shapely = _shapely()
    left, right, inter = overlaps(*_merged(regions))
    area = shapely.area(regions)
    big = inter > REPAIR_AREA * area.sum()
    count = int(big.sum())
    if not count or not hasattr(shapely, "coverage_clean"):
        return regions, 0
    shape = shapely.intersection(regions[left[big]], regions[right[big]])
    inter = shapely.area(shape)
    thin = 4 * np.pi * inter / np.maximum(shapely.length(shape), 1e-300) ** 2 < SLIVER_SHAPE
    small = inter < SLIVER_SHARE * np.minimum(area[left[big]], area[right[big]])
    if not (thin | small).all():
        return regions, 0
    clean = shapely.coverage_clean(regions, gap_width=gap_width)
    if shapely.is_empty(clean).any() or not shapely.is_valid(clean).all():
        return regions, 0
    return clean, count


def _merged(regions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The regions with every group of vertices that :func:`rfmap.cartogram.regions._distinct_vertices` merges (closer
    than ``MERGE``) moved onto its first point, as the passes map them, and their validity; a region that the merge
    makes invalid is kept as it was."""
    shapely = _shapely()
    points, index = _distinct_vertices(regions)
    merged = shapely.set_coordinates(regions.copy(), points[index])
    valid = shapely.is_valid(merged)
    merged[~valid] = regions[~valid]
    valid[~valid] = shapely.is_valid(regions[~valid])
    return merged, valid


def repair_overlaps(mapped: np.ndarray, values: np.ndarray, *, max_change: float = REPAIR_OVERLAP,
                    min_share: float = MIN_SHARE, valid: np.ndarray | None = None,
                    topology: Topology | None = None) -> tuple[np.ndarray, list]:
    r"""Sliver overlaps of valid mapped regions, each shared out between its two regions so that they share a border.

    An overlap of two regions is removed when it holds more than a thousandth of :data:`REPAIR_AREA` of the total
    area (below that it is rounding) and

    * at most ``max_change`` of the total area, or
    * at most :data:`REPAIR_SLIVER` of it, and it is thin (its isoperimetric quotient under :data:`SLIVER_SHAPE`) or
      one of its regions holds less than the judged share ``min_share`` of the total value (such a region is drawn
      at the size :func:`pass_weights` raised it to, not at its value).

    Larger overlaps stay, for :meth:`~rfmap.cartogram.resize.Cartogram.problems` to report.

    The overlap is cut along a line across it (``shapely.difference``): the first region gives up the share
    :math:`f \in` :data:`SPLITS` of it and the second the rest.  :math:`f` is the share that keeps the larger of the
    two relative area errors :math:`|A_i / T_i - 1|` (target :math:`T_i = (v_i/\sum_j v_j)\sum_j A_j`) lowest; the
    whole overlap goes to one region instead unless that raises the larger error by more than :data:`SPLIT_COST`.
    So a cut never takes a small region off its target where its neighbour can spare the sliver.

    Parameters
    ----------
    mapped : ndarray of shapely geometries, shape (R,)
    values : ndarray, shape (R,)
    valid : ndarray of bool, shape (R,), optional
        ``shapely.is_valid(mapped)``, where the caller has it (only valid regions are measured: :func:`overlaps`).
    topology : Topology, optional
        The validity and overlaps of ``mapped`` (the same array), where the caller has them
        (:meth:`Topology.updated` then gives the result's from the regions of the pairs cut).

    Returns
    -------
    (ndarray of shapely geometries, list of (int, int))
        The polygons and the pairs ``(cut, kept)``: the first gave up the larger share of their overlap.
    """
    shapely = _shapely()
    use = topology is not None and topology.geoms is mapped
    left, right, inter = topology.pairs if use else overlaps(mapped, valid)
    if not left.size:
        return mapped, []
    area = shapely.area(mapped)
    total = float(area.sum())
    share = inter / total
    target = values / values.sum() * total
    big = judged(values, min_share)
    out, cut = mapped.copy(), []
    for k in np.flatnonzero((share > 1e-3 * REPAIR_AREA) & (share <= max(max_change, REPAIR_SLIVER))):
        a, b = left[k], right[k]
        if share[k] > max_change and big[a] and big[b] and not _thin(shapely.intersection(out[a], out[b])):
            continue
        # the share f of the overlap that a gives up (b gives up the rest): the one that keeps both errors lowest,
        # the whole overlap from one of them unless that costs more than SPLIT_COST
        err = {f: max(abs((area[a] - f * inter[k]) / target[a] - 1.0),
                      abs((area[b] - (1.0 - f) * inter[k]) / target[b] - 1.0)) for f in SPLITS}
        f = min(err, key=err.get)
        whole = min((0.0, 1.0), key=err.get)
        f = whole if err[whole] <= err[f] + SPLIT_COST else f
        new = _cut_overlap(out[a], out[b], f)
        if new is not None:
            out[a], out[b] = new
            area[[a, b]] = shapely.area(new)
            cut.append((int(a), int(b)) if f >= 0.5 else (int(b), int(a)))
    return out, cut


#: The shares of an overlap that :func:`repair_overlaps` may cut from the first of its two regions (0, 0.1, ..., 1)
SPLITS = tuple(np.linspace(0.0, 1.0, 11))
#: The increase of the larger relative area error of the two regions below which :func:`repair_overlaps` cuts the whole
#: overlap from one of them
SPLIT_COST = 1e-3


def valid_polygons(geoms: np.ndarray, *, min_lobe: float | np.ndarray = 0.0) -> np.ndarray:
    """The polygonal part of ``shapely.make_valid`` of each geometry (R,), as one (Multi)Polygon each (no stray
    lines or points, crumbs under :data:`CRUMB` dropped).  The ``"structure"`` method: the area inside the rings
    (where a ring crossed itself, both lobes) less the holes, in half the time of the default on the long rings of
    a country's subdivisions.  A MultiPolygon is fixed part by part where that is enough
    (``_valid_by_parts``).

    With ``min_lobe > 0``, a crossed polygon that falls apart into pieces keeps its largest piece and those of at
    least ``min_lobe`` area (one for all, or one per geometry, (R,)): the lobes that a fold twists off a ring (where
    a fjord's two shores cross) are dropped instead of piling up as parts of the region over a cartogram's passes."""
    lobes = np.broadcast_to(np.asarray(min_lobe, dtype=float), (len(geoms),))
    return np.array([_polygons(_valid_by_parts(g, m)) for g, m in zip(geoms, lobes)], dtype=object)


def _valid_by_parts(g, min_lobe: float = 0.0):
    """``shapely.make_valid(g, method="structure")`` of one geometry, cheaper on a MultiPolygon of many parts: only its
    invalid parts are fixed, and only the parts that meet are unioned (:func:`_union_meeting`), with ``make_valid`` of
    the whole as the fallback should that not give a valid MultiPolygon.  ``make_valid`` of the whole unions every
    part with every other, which on a region of a hundred islands costs ten times as much as fixing the one part that
    crossed itself; the result is the same point set.  Lobes under ``min_lobe`` are dropped
    (:func:`valid_polygons`)."""
    shapely = _shapely()
    if shapely.get_type_id(g) != 6:
        return _without_lobes(shapely.make_valid(g, method="structure", keep_collapsed=False), min_lobe)
    parts = shapely.get_parts(g)
    bad = ~shapely.is_valid(parts)
    fixed = iter(shapely.make_valid(parts[bad], method="structure", keep_collapsed=False))
    parts = np.concatenate([shapely.get_parts(_without_lobes(next(fixed), min_lobe)) if b else [p]
                            for p, b in zip(parts, bad)])
    joined = shapely.multipolygons(parts)
    if shapely.is_valid(joined):
        return joined
    joined = _union_meeting(parts)  # parts that overlap or share a border: those unioned
    return joined if shapely.is_valid(joined) else shapely.make_valid(g, method="structure", keep_collapsed=False)


def _without_lobes(g, min_lobe: float):
    """The polygonal parts of a fixed polygon ``g`` (:func:`_polygons`) less those of area under ``min_lobe`` other
    than the largest."""
    shapely = _shapely()
    g = _polygons(g)
    if min_lobe <= 0 or shapely.get_type_id(g) != 6:
        return g
    parts = shapely.get_parts(g)
    area = shapely.area(parts)
    keep = (area >= min_lobe) | (np.arange(len(parts)) == np.argmax(area))
    return g if keep.all() else _polygons(shapely.multipolygons(parts[keep]))


def _union_meeting(parts: np.ndarray):
    """The union of valid polygons (P,) as one MultiPolygon: each group of parts that share area or a stretch of
    border (directly or through others) unioned, the other parts kept as they are (parts that touch at points may
    stay apart in a valid MultiPolygon)."""
    shapely = _shapely()
    first, second = shapely.STRtree(parts).query(parts)  # the pairs whose boxes meet
    first, second = first[first < second], second[first < second]
    # DE-9IM: the interiors meet (first letter) or the boundaries share a line (fifth); asked of every pair at once,
    # which is quicker than asking first which pairs intersect at all
    meet = np.array([m[0] != "F" or m[4] == "1" for m in shapely.relate(parts[first], parts[second])], dtype=bool)
    first, second = first[meet], second[meet]
    group = np.arange(len(parts))
    for a, b in zip(first, second):  # the groups as a forest: each pair joins its two roots
        while group[a] != a:
            a = group[a]
        while group[b] != b:
            b = group[b]
        group[max(a, b)] = min(a, b)
    for k in range(len(parts)):  # every part points at its root (roots have the lowest index of their group)
        group[k] = group[group[k]]
    pieces = [shapely.union_all(parts[group == root]) if (group == root).sum() > 1 else parts[root]
              for root in np.flatnonzero(group == np.arange(len(parts)))]
    return shapely.multipolygons(np.concatenate([shapely.get_parts(p) for p in pieces]))


def _thin(g) -> bool:
    r"""Whether ``g`` is a sliver: its isoperimetric quotient :math:`4\pi A / P^2` is under :data:`SLIVER_SHAPE`."""
    shapely = _shapely()
    return bool(4 * np.pi * shapely.area(g) < SLIVER_SHAPE * max(shapely.length(g), 1e-300) ** 2)


#: Polygons of less area than this (in the unit square) that a cut leaves are dropped: crumbs of rounding, whose
#: vertices the next pass would merge into a ring without area
CRUMB = 1e-12


def _polygons(g):
    """The polygonal parts of ``g`` (a collection flattened, crumbs under :data:`CRUMB` dropped) as one
    (Multi)Polygon."""
    shapely = _shapely()
    kind = shapely.get_type_id(g)
    parts = shapely.get_parts(g)
    if kind in (3, 6):  # a (Multi)Polygon's parts are disjoint already: no union needed
        keep = parts[shapely.area(parts) > CRUMB]
        return keep[0] if kind == 3 and len(keep) == 1 else shapely.multipolygons(keep)
    parts = np.concatenate([parts[shapely.get_type_id(parts) == 3],
                            shapely.get_parts(parts[shapely.get_type_id(parts) == 6])])
    return shapely.union_all(parts[shapely.area(parts) > CRUMB])


def _cut_overlap(a, b, f: float):
    """Regions ``a`` and ``b`` with their overlap shared out: ``a`` gives up the share ``f`` of it (by area, the part
    on one side of a line across the overlap's long axis) and ``b`` the rest; ``None`` when a cut region is not a valid
    (Multi)Polygon."""
    shapely = _shapely()
    if f >= 1.0:
        pieces = (_polygons(shapely.difference(a, b)), b)
    elif f <= 0.0:
        pieces = (a, _polygons(shapely.difference(b, a)))
    else:
        inter = _polygons(shapely.intersection(a, b))
        if shapely.is_empty(inter):  # an earlier cut took the overlap away
            return None
        first = _area_split(inter, f)
        pieces = (_polygons(shapely.difference(a, first)),
                  _polygons(shapely.difference(b, shapely.difference(inter, first))))
    # a region left whole is valid already (overlaps pairs valid regions; every cut is checked)
    ok = all(g is k or (shapely.is_valid(g) and not shapely.is_empty(g) and shapely.get_type_id(g) in (3, 6))
             for g, k in zip(pieces, (a, b)))
    return pieces if ok else None


def _area_split(g, f: float, steps: int = 16):
    """The part of ``g`` on the low side of a line across its long axis (that of its minimum rotated rectangle) that
    holds the share ``f`` of its area (bisection on the line's position)."""
    shapely = _shapely()
    rect = shapely.get_coordinates(shapely.minimum_rotated_rectangle(g))[:4]
    e1, e2 = rect[1] - rect[0], rect[2] - rect[1]
    axis = e1 if np.hypot(*e1) >= np.hypot(*e2) else e2
    axis = axis / np.hypot(*axis)
    normal = np.array([-axis[1], axis[0]])
    t = shapely.get_coordinates(g) @ axis
    lo, hi, total = float(t.min()), float(t.max()), shapely.area(g)
    reach = float(np.abs(shapely.get_coordinates(g) @ normal).max()) + 1.0
    part = None
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        half = shapely.Polygon([axis * (t.min() - 1.0) + normal * s for s in (-reach, reach)] +
                               [axis * mid + normal * s for s in (reach, -reach)])
        part = _polygons(shapely.intersection(g, half))
        lo, hi = (mid, hi) if shapely.area(part) < f * total else (lo, mid)
    return part


def boost(log_err: np.ndarray, last: np.ndarray, gain: np.ndarray) -> np.ndarray:
    r"""Log weight boosts of a cartogram's next pass, a secant acceleration of the passes.

    A region a few grid cells wide is smeared by the raster, so a pass removes only a share :math:`g_i` of its log
    area error :math:`\ell_i = \log(A_i / T_i)`: the passes converge geometrically.  With the last pass's errors
    :math:`\ell_i^-` and boosts :math:`b_i^-` (its weights were :math:`v_i e^{-b_i^-}`), that share is
    :math:`g_i = (\ell_i^- - \ell_i) / (\ell_i^- + b_i^-)`, clipped to :math:`[` :data:`BOOST_GAIN` :math:`, 1]`, and
    the next boost :math:`b_i = \ell_i (1/g_i - 1)`, clipped to :math:`\pm` :data:`BOOST_CAP`, so that the pass aims
    at the whole error; a region the raster resolves (:math:`g_i = 1`) gets none.

    Parameters
    ----------
    log_err, last, gain : ndarray, shape (R,)
        :math:`\ell`, :math:`\ell^-` and :math:`b^-`.

    Returns
    -------
    ndarray, shape (R,)
        :math:`b`.
    """
    den = last + gain
    ok = np.abs(den) > 1e-12
    share = np.ones_like(log_err)
    share[ok] = (last[ok] - log_err[ok]) / den[ok]
    share = np.clip(share, BOOST_GAIN, 1.0)
    return np.clip(log_err * (1.0 / share - 1.0), -BOOST_CAP, BOOST_CAP)
