r"""Cartograms with insets: groups of regions drawn in their own frames beside the main map (Alaska and Hawaii beside
the contiguous states), as cartogram-cpp's ``Inset`` column places them.

Every region names its inset: ``C`` (the main map; also empty), ``L``, ``R``, ``T`` or ``B`` (left, right, top,
bottom of it; the words ``center``, ``left``, ... too).  Each inset is a cartogram of its own
(:func:`rfmap.cartogram.resize.cartogram`, in its own equal-area plane: an inset far from the main map is not distorted by
the main map's projection), and the insets are then put on one scale: inset :math:`k`, holding the value
:math:`V_k` on the area :math:`A_k`, is scaled about its centre by

.. math:: s_k = \sqrt{\frac{A_C}{V_C}\,\frac{V_k}{A_k}},

so that a unit of value covers the same area in every frame, and placed beside the main map's bounding box on its
side, a gap of :data:`GAP` of the main map's larger side away, centred on it.  The area errors, validity and overlaps
are judged on the placed regions together, against the total value (:func:`rfmap.cartogram.metrics.cartogram_metrics`).
The input map is laid out the same way at its true scale (:math:`s_k = 1`).  The placed frames are no map
projection: the GeoJSON is written in them (``"coordinates": "insets"``) with each inset's projection, scale and
offset in its ``"rfmap"`` member.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..core.wording import counted
from .data import atomic_write
from .metrics import cartogram_metrics
from .options import CartogramOptions
from .output import mapped_features, write_geojson
from .regions import read_regions
from .resize import cartogram

__all__ = ["INSET_SIDES", "GAP", "InsetCartogram", "cartogram_insets", "inset_groups"]

#: The names of an inset's place, as cartogram-cpp writes them and in words (case ignored); empty is the main map
INSET_SIDES = {"": "C", "c": "C", "center": "C", "centre": "C", "l": "L", "left": "L", "r": "R", "right": "R",
               "t": "T", "top": "T", "b": "B", "bottom": "B"}
#: The gap between the main map and an inset, a share of the main map's larger side
GAP = 0.05


def inset_groups(names: Sequence) -> dict[str, np.ndarray]:
    """The regions of every inset: ``{side: indices}`` in the order C, L, R, T, B, from one name per region
    (:data:`INSET_SIDES`; ``None`` is the main map).  Raises ValueError (one line) for an unknown name."""
    sides = []
    for k, name in enumerate(names):
        key = "" if name is None else str(name).strip().lower()
        if key not in INSET_SIDES:
            raise ValueError(f"region #{k}: unknown inset {name!r}; an inset is one of C, L, R, T, B (or empty: the "
                             f"main map)")
        sides.append(INSET_SIDES[key])
    sides = np.array(sides)
    return {s: np.flatnonzero(sides == s) for s in "CLRTB" if (sides == s).any()}


def _bounds(geoms) -> np.ndarray:
    import shapely

    return np.asarray(shapely.total_bounds(geoms), dtype=float)


def _layout(groups: dict[str, np.ndarray], scales: dict[str, float]) -> dict[str, tuple[float, np.ndarray, np.ndarray]]:
    """Where every inset goes: ``{side: (scale, centre, offset)}``, a point :math:`p` of it placed at
    :math:`s (p - c) + o`; the main inset (``C``, else the first) stays where it is."""
    main = "C" if "C" in groups else next(iter(groups))
    b = _bounds(groups[main])
    lo, hi = b[:2], b[2:]
    gap = GAP * float((hi - lo).max())
    mid = 0.5 * (lo + hi)
    out = {main: (1.0, mid, mid)}
    for side, geoms in groups.items():
        if side == main:
            continue
        s = scales[side]
        bb = _bounds(geoms)
        c = 0.5 * (bb[:2] + bb[2:])
        half = 0.5 * s * (bb[2:] - bb[:2])
        offset = {"L": (lo[0] - gap - half[0], mid[1]), "R": (hi[0] + gap + half[0], mid[1]),
                  "T": (mid[0], hi[1] + gap + half[1]), "B": (mid[0], lo[1] - gap - half[1])}[side]
        out[side] = (s, c, np.array(offset))
    return out


def _place(geoms, where) -> np.ndarray:
    import shapely

    s, c, o = where
    return shapely.transform(geoms, lambda p: (p - c) * s + o)


@dataclass
class InsetCartogram:
    """A cartogram with insets (:func:`cartogram_insets`).

    Attributes
    ----------
    input_features : list of dict
    insets : dict
        ``{side: rfmap.cartogram.resize.Cartogram}``, each in its own projection's plane.
    groups : dict
        ``{side: indices of its regions}`` (:func:`inset_groups`).
    geometries : ndarray of shapely geometries, shape (R,)
        The cartogram, its insets placed (in input order).
    regions : ndarray of shapely geometries, shape (R,)
        The input map, placed as the cartogram (in input order).
    values : ndarray, shape (R,)
    placement : dict
        ``{side: (scale, centre, offset)}``: a point :math:`p` of that inset is placed at :math:`s (p - c) + o`;
        the main inset (``C``, else the first) stays where it is.
    tol : float
        The tolerance on the largest relative area error (the options' ``tol``).
    min_share : float
        The share of the total value from which a region is judged (the main inset's ``min_share``, filled from the
        options as for :class:`~rfmap.cartogram.resize.Cartogram`; the class default 0 holds only for one built by
        hand).
    """

    input_features: list
    insets: dict
    groups: dict
    geometries: np.ndarray
    regions: np.ndarray
    values: np.ndarray
    placement: dict
    tol: float = 0.01
    min_share: float = 0.0
    output: str = "insets"
    _metrics: dict = field(default_factory=dict, init=False, repr=False)

    @property
    def method(self) -> str:
        return next(iter(self.insets.values())).method

    @property
    def n(self) -> int:
        return next(iter(self.insets.values())).n

    @property
    def time(self) -> float:
        """Seconds of all the insets' cartograms."""
        return float(sum(c.time for c in self.insets.values()))

    @property
    def features(self) -> list:
        return mapped_features(self.input_features, self.geometries)

    @property
    def area_errors(self) -> np.ndarray:
        r"""Relative area errors :math:`|A_i / T_i - 1|` of the placed regions against the total, shape (R,)."""
        import shapely

        a = shapely.area(self.geometries)
        return np.abs(a / (self.values / self.values.sum() * a.sum()) - 1.0)

    def metrics(self, *, overlap_tol: float = 1e-6):
        """Area errors and topology of the placed regions together
        (:func:`rfmap.cartogram.metrics.cartogram_metrics`)."""
        if overlap_tol not in self._metrics:
            self._metrics[overlap_tol] = cartogram_metrics(self.geometries, self.values, overlap_tol=overlap_tol,
                                                           min_share=self.min_share)
        return self._metrics[overlap_tol]

    def projected_geometries(self, *, mapped: bool = True) -> np.ndarray:
        """The placed cartogram (or, with ``mapped=False``, the placed input map), for the figures."""
        return self.geometries if mapped else self.regions

    def problems(self) -> list[str]:
        """What keeps the cartogram from being right (empty when it is): the placed regions' largest area error
        above ``tol``, invalid or overlapping regions, and every inset's own problems (prefixed by its side)."""
        m = self.metrics()
        out = []
        if not m.max_error <= self.tol:
            out.append(f"the largest area error {m.max_error:.4f} (insets together) is above the tolerance "
                       f"{self.tol:g}")
        if m.n_invalid:
            out.append(counted(m.n_invalid, "invalid region"))
        if m.n_overlapping:
            out.append(f"overlapping regions: {counted(m.n_overlapping, 'pair')} (the largest overlap "
                       f"{m.max_overlap:.2g})")
        for side, c in self.insets.items():
            out += [f"inset {side}: {p}" for p in c.problems()]
        return out

    def status(self) -> dict:
        """The ``"rfmap"`` member of the written GeoJSON."""
        problems, m = self.problems(), self.metrics()
        insets = {side: {"regions": int(self.groups[side].size), "projection": c.frame.projection.definition,
                         "scale": float(self.placement[side][0]), "centre": self.placement[side][1].tolist(),
                         "offset": self.placement[side][2].tolist(), "passes": c.info.get("iterations"),
                         "max_error": c.metrics().max_error} for side, c in self.insets.items()}
        return {"status": "failed" if problems else "ok", "problems": problems, "max_error": m.max_error,
                "minor": {"share": self.min_share, "count": m.n_minor, "max_error": m.max_error_minor},
                "method": self.method, "n": self.n, "coordinates": "insets", "insets": insets}

    def save(self, path) -> None:
        """Write the placed regions as a GeoJSON FeatureCollection, atomically, with the ``"rfmap"`` member
        :meth:`status` (no ``"crs"``: the placed frames are no one projection)."""
        atomic_write(path, lambda fh: write_geojson(fh, self.input_features, self.geometries, self.status(), None))


def cartogram_insets(collection, value: str, insets, options: CartogramOptions | None = None,
                     **kw) -> InsetCartogram:
    """A cartogram whose regions are grouped into insets, each computed in its own frame and placed beside the main
    map on one scale (see :mod:`rfmap.cartogram.insets`).

    Parameters
    ----------
    collection : dict, str or path
        A GeoJSON FeatureCollection (:func:`rfmap.cartogram.resize.cartogram`).
    value : str
        The property holding each region's value.
    insets : str or sequence
        The property that names each region's inset (:data:`INSET_SIDES`), or one name per feature.
    options : CartogramOptions, optional
        The options of every inset's :func:`rfmap.cartogram.resize.cartogram` (its fields may be given as keywords;
        ``output`` is always the projection's plane).

    Returns
    -------
    InsetCartogram

    Raises
    ------
    ValueError
        For bad input (:func:`rfmap.cartogram.regions.read_regions`), an unknown inset name, or insets not one per region.
    """
    import shapely

    features = read_regions(collection, value)[0]
    names = [(f.get("properties") or {}).get(insets) for f in features] if isinstance(insets, str) else list(insets)
    if len(names) != len(features):
        raise ValueError(f"insets must be one per region ({len(features)}), got {len(names)}")
    groups = inset_groups(names)
    o = replace(replace(options or CartogramOptions(), **kw), output="projected")
    cartos = {side: cartogram({"type": "FeatureCollection", "features": [features[i] for i in idx]}, value, o)
              for side, idx in groups.items()}
    area = {side: float(shapely.area(c.geometries).sum()) for side, c in cartos.items()}
    total = {side: float(c.values.sum()) for side, c in cartos.items()}
    main = next(iter(groups))
    scales = {side: float(np.sqrt(area[main] / total[main] * total[side] / area[side])) for side in groups}
    placement = _layout({side: c.geometries for side, c in cartos.items()}, scales)
    before = _layout({side: c.projected_geometries(mapped=False) for side, c in cartos.items()},
                     dict.fromkeys(groups, 1.0))
    count = len(features)
    geoms, regions, values = np.empty(count, dtype=object), np.empty(count, dtype=object), np.zeros(count)
    for side, idx in groups.items():
        c = cartos[side]
        geoms[idx] = _place(c.geometries, placement[side])
        regions[idx] = _place(c.projected_geometries(mapped=False), before[side])
        values[idx] = c.values
    return InsetCartogram(input_features=features, insets=cartos, groups=groups, geometries=geoms, regions=regions,
                          values=values, placement=placement, tol=float(o.tol),
                          min_share=float(cartos[main].min_share))
