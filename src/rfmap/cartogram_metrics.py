r"""Area errors and topology of cartograms: the metrics of the cartogram literature, judged over the regions that hold
a given share of the total value, and the repair of numerically tiny folds.

The relative area error of region :math:`i` is :math:`|A_i / T_i - 1|` with the target
:math:`T_i = (v_i / \sum_j v_j) \sum_j A_j`; its mean and maximum are taken over the regions holding at least
``min_share`` of the total value (:data:`MIN_SHARE` in :func:`rfmap.cartogram.cartogram`), and the others' largest
error is reported apart.  The topology check asks that every polygon be valid and that no two regions overlap by more
than ``overlap_tol`` of the total area.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .regions import _shapely

__all__ = ["CartogramMetrics", "cartogram_metrics", "overlaps",
           "judged", "repair_folds", "repair_overlaps", "boost", "MIN_SHARE",
           "REPAIR_AREA", "REPAIR_OVERLAP", "BOOST_GAIN", "BOOST_CAP"]

#: The share of the total value from which a region's area error is judged (stopping rule, :meth:`Cartogram.metrics`,
#: tolerance): 0.01 %.  Smaller regions (a world map's uninhabited Antarctica, islands of a few thousand people) are
#: at most a few grid cells, where no raster resolves 1 %; their errors are reported apart (``max_error_minor``).
MIN_SHARE = 1e-4
#: The largest change of area (a fraction of the total) by which :func:`repair_folds` fixes an invalid mapped
#: polygon: the default ``overlap_tol`` of the metrics, below which an overlap of two regions is not counted either
REPAIR_AREA = 1e-6
#: The largest overlap of two mapped regions (a fraction of the total area) that :func:`repair_overlaps` removes: two
#: neighbours that the input keeps a fraction of a grid cell apart (a lake, a river drawn as a gap) can be pressed
#: together by the passes until their straight edges cross by a sliver
REPAIR_OVERLAP = 1e-5
#: :func:`boost`: the smallest share of a region's log area error that a pass is taken to remove, and the largest
#: log weight boost (a factor of :math:`e^{0.4} \approx 1.5`); stronger boosts overshoot, and the passes oscillate
BOOST_GAIN, BOOST_CAP = 0.25, 0.4


@dataclass
class CartogramMetrics:
    """Area errors and topology of a cartogram (see :func:`cartogram_metrics`)."""

    mean_error: float
    max_error: float
    n_invalid: int
    max_overlap: float
    n_overlapping: int
    overlap_tol: float
    #: regions below the judged share of the total value (:data:`MIN_SHARE`), left out of ``mean_error`` and
    #: ``max_error`` and reported here
    n_minor: int = 0
    max_error_minor: float = 0.0

    @property
    def topology_ok(self) -> bool:
        """Every polygon valid and no pair of regions overlapping by more than ``overlap_tol``."""
        return self.n_invalid == 0 and self.n_overlapping == 0

    def __str__(self) -> str:
        topo = "valid, no overlaps" if self.topology_ok else \
            f"{self.n_invalid} invalid, {self.n_overlapping} overlapping pairs (max {self.max_overlap:.2g})"
        minor = f" ({self.n_minor} region(s) under the judged share: max {self.max_error_minor:.4f})" \
            if self.n_minor else ""
        return f"area error mean {self.mean_error:.4f}, max {self.max_error:.4f}{minor}; {topo}"


def cartogram_metrics(mapped: np.ndarray, values: np.ndarray, *, overlap_tol: float = 1e-6,
                      topology: bool = True, min_share: float = 0.0) -> CartogramMetrics:
    r"""Relative area errors and topology of mapped regions.

    The area error of region :math:`i` is :math:`|A_i / T_i - 1|` with :math:`T_i = (v_i/\sum_j v_j)\sum_j A_j`;
    a polygon is invalid when shapely says so (self-intersection, a hole outside its shell, ...); two regions
    overlap when the area of their intersection exceeds ``overlap_tol`` times the total area.

    Parameters
    ----------
    mapped : ndarray of shapely geometries, shape (R,)
    values : ndarray, shape (R,), positive
    overlap_tol : float
    topology : bool
        ``False`` skips the validity and overlap checks (their counts are then reported as zero).
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
    if not topology:
        return CartogramMetrics(float(err.mean()), float(err.max()), 0, 0.0, 0, overlap_tol, **minor)
    valid = shapely.is_valid(mapped)
    total = float(a.sum())
    rel = overlaps(mapped, valid)[2] / total  # an invalid polygon's overlaps are not measured: it counts as invalid
    return CartogramMetrics(mean_error=float(err.mean()), max_error=float(err.max()),
                            n_invalid=int((~valid).sum()), max_overlap=float(rel.max(initial=0.0)),
                            n_overlapping=int((rel > overlap_tol).sum()), overlap_tol=overlap_tol, **minor)


def overlaps(mapped: np.ndarray, valid: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pairs ``i < j`` of valid regions whose interiors overlap, and the areas of their intersections (shapes
    (K,)).  Regions whose every edge is matched by a neighbour's or meets none (``shapely.coverage_invalid_edges``:
    a border drawn with the same vertices on both sides, as the cartogram's passes keep it) cannot overlap another
    such region, so intersections are computed only for the pairs that hold a region with an unmatched edge."""
    shapely = _shapely()
    valid = shapely.is_valid(mapped) if valid is None else valid
    idx = np.flatnonzero(valid)
    flagged = np.zeros(len(mapped), dtype=bool)
    if idx.size:
        flagged[idx] = ~shapely.is_empty(shapely.coverage_invalid_edges(mapped[idx]))
    left, right = shapely.STRtree(mapped[idx]).query(mapped[idx], predicate="intersects")
    left, right = idx[left], idx[right]
    keep = (left < right) & (flagged[left] | flagged[right])
    left, right = left[keep], right[keep]
    inter = shapely.area(shapely.intersection(mapped[left], mapped[right])) if left.size else np.zeros(0)
    pos = inter > 0
    return left[pos], right[pos], inter[pos]


def judged(values: np.ndarray, min_share: float) -> np.ndarray:
    r"""The regions whose area errors are judged: :math:`v_i \ge` ``min_share`` :math:`\sum_j v_j` (all of them when
    none is), boolean, shape (R,)."""
    major = np.asarray(values) >= min_share * float(np.sum(values))
    return major if major.any() else np.ones_like(major)


def repair_folds(mapped: np.ndarray, *, max_change: float = REPAIR_AREA) -> tuple[np.ndarray, list]:
    """Invalid mapped polygons whose fix (``shapely.make_valid``) changes their area by at most ``max_change`` of the
    total area replaced by the fix: a crossing of two edges that the input drew nearly touching, which no map of the
    vertices alone keeps apart.  Returns the polygons and the indices of those fixed; larger folds stay invalid, for
    :meth:`Cartogram.problems` to report."""
    shapely = _shapely()
    bad = np.flatnonzero(~shapely.is_valid(mapped))
    if not bad.size:
        return mapped, []
    fixed = shapely.make_valid(mapped[bad])
    parts = [shapely.get_parts(g) for g in fixed]  # the polygons of each fix (no stray lines or points)
    fixed = np.array([shapely.union_all(p[np.isin(shapely.get_type_id(p), (3, 6))]) for p in parts], dtype=object)
    change = np.abs(shapely.area(fixed) - shapely.area(mapped[bad])) / shapely.area(mapped).sum()
    ok = (change <= max_change) & shapely.is_valid(fixed) & np.isin(shapely.get_type_id(fixed), (3, 6))
    out = mapped.copy()
    out[bad[ok]] = fixed[ok]
    return out, [int(i) for i in bad[ok]]


def repair_overlaps(mapped: np.ndarray, values: np.ndarray, *,
                    max_change: float = REPAIR_OVERLAP) -> tuple[np.ndarray, list]:
    r"""Sliver overlaps of valid mapped regions removed: each overlap of two regions holding at most ``max_change``
    of the total area (and over a thousandth of :data:`REPAIR_AREA`, below which it is rounding) is cut from the
    one of the two further above its target area :math:`T_i = (v_i/\sum_j v_j)\sum_j A_j` (``shapely.difference``),
    so that the two then share a border.  Larger overlaps stay, for :meth:`Cartogram.problems` to report.

    Parameters
    ----------
    mapped : ndarray of shapely geometries, shape (R,)
    values : ndarray, shape (R,)

    Returns
    -------
    (ndarray of shapely geometries, list of (int, int))
        The polygons and the pairs ``(cut, kept)`` whose overlap was cut from the first.
    """
    shapely = _shapely()
    left, right, inter = overlaps(mapped)
    if not left.size:
        return mapped, []
    area = shapely.area(mapped)
    total = float(area.sum())
    share = inter / total
    excess = np.log(np.maximum(area, 1e-300) / (values / values.sum() * total))
    out, cut = mapped.copy(), []
    for k in np.flatnonzero((share > 1e-3 * REPAIR_AREA) & (share <= max_change)):
        i, j = (left[k], right[k]) if excess[left[k]] >= excess[right[k]] else (right[k], left[k])
        parts = shapely.get_parts(shapely.difference(out[i], out[j]))
        g = shapely.union_all(parts[shapely.get_type_id(parts) == 3])
        if shapely.is_valid(g) and shapely.get_type_id(g) in (3, 6):
            out[i] = g
            cut.append((int(i), int(j)))
    return out, cut


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
