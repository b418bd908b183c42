r"""Map projections for cartograms: longitude/latitude to a plane where areas are true, and that plane to the unit
square.

A cartogram sizes regions by area, so it must be computed where areas are the Earth's.  For longitude/latitude input
(every point within :math:`|\lambda| \le 180^\circ`, :math:`|\varphi| \le 90^\circ`) the default is an equal-area
projection of the WGS84 ellipsoid fitted to the map.  It is computed by numpy formulas, so that pyproj is not
imported: Snyder's for the Lambert projection, with the authalic latitude, and Šavrič et al.'s for Equal Earth;
both agree with PROJ's to 1e-9 in the tests.  Only a Lambert projection centred within 0.1° of a pole goes through
PROJ (with pyproj).  The two projections:

* the **Lambert azimuthal equal-area** projection centred on the map, for a regional map: centre longitude
  :math:`\lambda_0` the midpoint of the smallest arc of longitudes that holds every vertex, centre latitude
  :math:`\varphi_0` the midpoint of the latitudes;
* the **Equal Earth** projection (Šavrič, Patterson & Jenny 2019) centred on Greenwich, for a world map: one whose
  smallest arc of longitudes is wider than :data:`WORLD_SPAN` (180°).

The smallest arc is the circle of longitudes less its largest empty gap, so a map that crosses the antimeridian
(longitudes 170° … 180° and −180° … −170°) is centred on 180°, not on the mean 0° of its two halves.  Every ring is
read as its vertices joined the short way round (a step of more than 180° in longitude crosses the antimeridian) and
is made continuous before it is projected; a ring that still does not close goes round a pole and is kept as given.
On the way back every ring is shifted by whole turns so that its middle longitude lies in :math:`[-180^\circ,
180^\circ)`; a ring that crosses the antimeridian then comes back with longitudes beyond ±180° on one side.

``"equirectangular"`` keeps the earlier frame :math:`(x, y) = ((\lambda - \lambda_0)\cos\varphi_0, \varphi)` in
degrees (areas right to :math:`O(\Delta\varphi^2)` across a city) and ``"none"`` takes the coordinates as planar
(already projected) ones.

References
----------
Bojan Šavrič, Tom Patterson, Bernhard Jenny, "The Equal Earth map projection", Int. J. Geogr. Inf. Sci. 33(3),
454–465 (2019).

John P. Snyder, "Map Projections: A Working Manual", U.S. Geological Survey Professional Paper 1395 (1987), §24
(Lambert azimuthal equal-area).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["PROJECTIONS", "WORLD_SPAN", "Projection", "PlanarFrame", "longitude_arc", "is_lonlat", "unwrap_rings",
           "wrap_rings"]

#: The ``projection`` argument of :meth:`PlanarFrame.fit`: ``"auto"`` (equal-area for longitude/latitude input,
#: ``"none"`` for any other), ``"equal-area"``, ``"equirectangular"`` or ``"none"``.
PROJECTIONS = ("auto", "equal-area", "equirectangular", "none")

#: A map whose smallest arc of longitudes is wider than this (degrees) is a world map (Equal Earth).
WORLD_SPAN = 180.0

#: Metres per degree of a great circle on the sphere of the Earth's mean radius (6371.0088 km).
_METRES_PER_DEGREE = 6371008.8 * math.pi / 180.0


def is_lonlat(coords: np.ndarray) -> bool:
    """Whether every point of ``coords`` (P, 2) can be a longitude/latitude pair in degrees."""
    return bool((np.abs(coords[:, 0]) <= 180).all() and (np.abs(coords[:, 1]) <= 90).all())


def longitude_arc(lon: np.ndarray) -> tuple[float, float]:
    """The smallest arc of the circle of longitudes that holds every ``lon`` (degrees): its midpoint in
    :math:`[-180, 180)` and its width (the circle less its largest gap between neighbouring longitudes)."""
    l = np.sort(np.mod(np.asarray(lon, dtype=float) + 180.0, 360.0) - 180.0)  # repeats leave gaps of 0
    gaps = np.diff(np.append(l, l[0] + 360.0))
    i = int(np.argmax(gaps))
    span = 360.0 - float(gaps[i])
    start = float(l[(i + 1) % l.size])
    return float(np.mod(start + 0.5 * span + 180.0, 360.0) - 180.0), span


@functools.lru_cache(maxsize=16)
def _proj(definition: str):
    try:
        import pyproj
    except ImportError as e:
        raise ImportError("equal-area projections need pyproj: pip install 'rfmap[geo]' "
                          "(or choose projection='equirectangular')") from e
    return pyproj.Proj(definition)


# ----------------------------------------------------------------------------------------------- numpy projections
#: WGS84: semi-major axis (m) and squared eccentricity
_A, _E2 = 6378137.0, 0.0066943799901413165
_E = math.sqrt(_E2)
#: Equal Earth's polynomial coefficients and :math:`M = \sqrt3/2` (Šavrič et al.)
_EQ = (1.340264, -0.081106, 0.000893, 0.003796)
_M = math.sqrt(3.0) / 2.0


def _q(sinphi: np.ndarray) -> np.ndarray:
    r"""Snyder's :math:`q(\varphi) = (1-e^2)\left[\frac{\sin\varphi}{1-e^2\sin^2\varphi} - \frac{1}{2e}
    \ln\frac{1-e\sin\varphi}{1+e\sin\varphi}\right]`; the authalic latitude is :math:`\arcsin(q/q_p)`."""
    es = _E * sinphi
    return (1.0 - _E2) * (sinphi / (1.0 - es * es) - np.log((1.0 - es) / (1.0 + es)) / (2.0 * _E))


_QP = float(_q(np.float64(1.0)))
#: the authalic sphere's radius over the semi-major axis, :math:`\sqrt{q_p/2}`
_RQ = math.sqrt(0.5 * _QP)


def _geodetic(sinbeta: np.ndarray) -> np.ndarray:
    r"""The latitude (radians) of authalic latitude :math:`\arcsin(\text{sinbeta})`: Newton's iteration on
    :math:`q(\varphi) = q_p \sin\beta` (Snyder 3-16), from :math:`\varphi = \beta`."""
    q = _QP * np.clip(sinbeta, -1.0, 1.0)
    phi = np.arcsin(np.clip(sinbeta, -1.0, 1.0))
    for _ in range(8):
        s = np.sin(phi)
        w = 1.0 - _E2 * s * s
        c = np.maximum(np.cos(phi), 1e-300)
        phi = phi + w * w / (2.0 * c) * (q / (1.0 - _E2) - s / w + np.log((1.0 - _E * s) / (1.0 + _E * s))
                                         / (2.0 * _E))
    return np.where(np.abs(sinbeta) >= 1.0, np.sign(sinbeta) * (0.5 * math.pi), phi)


def _laea(lon0: float, lat0: float, pts: np.ndarray, inverse: bool) -> np.ndarray:
    r"""The ellipsoidal Lambert azimuthal equal-area projection centred on (``lon0``, ``lat0``) degrees (Snyder
    24-13 to 24-28, PROJ's ``laea``), or its inverse (nan beyond the disc of radius :math:`2R_q`), metres."""
    p0 = math.radians(lat0)
    sb1 = float(_q(np.float64(math.sin(p0)))) / _QP
    cb1 = math.sqrt(max(0.0, 1.0 - sb1 * sb1))
    d = math.cos(p0) / (math.sqrt(1.0 - _E2 * math.sin(p0) ** 2) * _RQ * cb1)
    if not inverse:
        lam, phi = np.radians(pts[:, 0] - lon0), np.radians(pts[:, 1])
        sb = _q(np.sin(phi)) / _QP
        cb = np.sqrt(np.maximum(0.0, 1.0 - sb * sb))
        with np.errstate(divide="ignore", invalid="ignore"):  # the antipode: not finite, as PROJ's
            b = np.sqrt(2.0 / (1.0 + sb1 * sb + cb1 * cb * np.cos(lam)))
            return _A * _RQ * np.column_stack([d * b * cb * np.sin(lam), b / d * (cb1 * sb - sb1 * cb * np.cos(lam))])
    x, y = pts[:, 0] / (_A * _RQ * d), pts[:, 1] * d / (_A * _RQ)
    rho = np.hypot(x, y)
    with np.errstate(invalid="ignore"):
        ce = 2.0 * np.arcsin(0.5 * rho)
        sc, cc = np.sin(ce), np.cos(ce)
        safe = np.where(rho > 0, rho, 1.0)
        sb = np.where(rho > 0, cc * sb1 + y * sc * cb1 / safe, sb1)
        lam = np.arctan2(x * sc, rho * cb1 * cc - y * sb1 * sc)
    return np.column_stack([lon0 + np.degrees(lam), np.degrees(_geodetic(sb))])


def _eqearth(lon0: float, pts: np.ndarray, inverse: bool) -> np.ndarray:
    r"""The ellipsoidal Equal Earth projection (Šavrič et al., on the authalic sphere: PROJ's ``eqearth``), or its
    inverse (latitudes beyond a pole at the pole), metres."""
    a1, a2, a3, a4 = _EQ
    if not inverse:
        th = np.arcsin(_M * _q(np.sin(np.radians(pts[:, 1]))) / _QP)
        t2 = th * th
        t6 = t2 * t2 * t2
        x = np.radians(pts[:, 0] - lon0) * np.cos(th) / (_M * (a1 + 3 * a2 * t2 + t6 * (7 * a3 + 9 * a4 * t2)))
        return (_A * _RQ) * np.column_stack([x, th * (a1 + a2 * t2 + t6 * (a3 + a4 * t2))])
    x, y = pts[:, 0] / (_A * _RQ), np.clip(pts[:, 1] / (_A * _RQ), -1.3173627591574, 1.3173627591574)
    th = y.copy()
    for _ in range(12):  # Newton on the polynomial, as PROJ
        t2 = th * th
        t6 = t2 * t2 * t2
        th = th - (th * (a1 + a2 * t2 + t6 * (a3 + a4 * t2)) - y) / (a1 + 3 * a2 * t2 + t6 * (7 * a3 + 9 * a4 * t2))
    t2 = th * th
    t6 = t2 * t2 * t2
    lam = _M * x * (a1 + 3 * a2 * t2 + t6 * (7 * a3 + 9 * a4 * t2)) / np.cos(th)
    return np.column_stack([lon0 + np.degrees(lam), np.degrees(_geodetic(np.sin(th) / _M))])


@dataclass(frozen=True)
class Projection:
    r"""A projection of longitude/latitude (degrees) to a plane, or the identity of planar coordinates.

    ``kind`` is ``"laea"`` (Lambert azimuthal equal-area centred on :math:`(\lambda_0, \varphi_0)`), ``"eqearth"``
    (Equal Earth, central meridian :math:`\lambda_0`), both on the WGS84 ellipsoid in metres; ``"equirectangular"``
    (:math:`((\lambda-\lambda_0)\cos\varphi_0, \varphi)` in degrees) or ``"none"``.  Longitudes are not wrapped on
    either side: :meth:`forward` expects them within :math:`\lambda_0 \pm 180^\circ` (as :func:`unwrap_rings` leaves
    them) and :meth:`inverse` returns them continuous.
    """

    kind: str
    lon0: float = 0.0
    lat0: float = 0.0

    @classmethod
    def fit(cls, lonlat: np.ndarray, kind: str = "equal-area") -> "Projection":
        """The projection of ``kind`` (``"equal-area"``, ``"equirectangular"`` or ``"none"``) for points ``lonlat``
        (P, 2): centred on the midpoint of their smallest arc of longitudes (Greenwich for a world map, wider than
        :data:`WORLD_SPAN`) and of their latitudes."""
        if kind == "none":
            return cls("none")
        centre, span = longitude_arc(lonlat[:, 0])
        world = span > WORLD_SPAN
        lon0 = 0.0 if world else centre
        lat0 = 0.5 * float(lonlat[:, 1].min() + lonlat[:, 1].max())
        if kind == "equirectangular":
            return cls("equirectangular", lon0, lat0)
        if kind != "equal-area":
            raise ValueError(f"unknown projection {kind!r}; choose one of {', '.join(PROJECTIONS)}")
        return cls("eqearth", lon0) if world else cls("laea", lon0, lat0)

    @property
    def geographic(self) -> bool:
        """Whether the input is longitude/latitude."""
        return self.kind != "none"

    @property
    def equal_area(self) -> bool:
        """Whether areas in the plane are proportional to the Earth's (planar input is taken as equal-area)."""
        return self.kind in ("laea", "eqearth", "none")

    @property
    def cos_lat(self) -> float:
        r""":math:`\cos\varphi_0`: the aspect that draws longitude/latitude true to scale at the map's centre."""
        return math.cos(math.radians(self.lat0)) if self.geographic else 1.0

    @property
    def definition(self) -> str | None:
        """The PROJ definition of the plane (``None`` for planar input); the equirectangular plane's unit is the
        degree of latitude (a sphere of radius :math:`180/\\pi`)."""
        if self.kind == "laea":
            return f"+proj=laea +lat_0={self.lat0:.10g} +lon_0={self.lon0:.10g} +ellps=WGS84 +units=m +over +no_defs"
        if self.kind == "eqearth":
            return f"+proj=eqearth +lon_0={self.lon0:.10g} +ellps=WGS84 +units=m +over +no_defs"
        if self.kind == "equirectangular":
            return (f"+proj=eqc +lat_ts={self.lat0:.10g} +lon_0={self.lon0:.10g} +R={180 / math.pi!r} +units=m "
                    f"+over +no_defs")
        return None

    @property
    def metres_per_unit(self) -> float:
        """Metres per unit of the plane, roughly (for choosing step lengths)."""
        return _METRES_PER_DEGREE if self.kind == "equirectangular" else 1.0

    def forward(self, lonlat: np.ndarray) -> np.ndarray:
        """Longitude/latitude (P, 2), longitudes within :math:`\\lambda_0 \\pm 180^\\circ`, to the plane (P, 2);
        latitudes beyond ±90° are taken at the pole."""
        lonlat = np.asarray(lonlat, dtype=float)
        if self.kind == "none":
            return lonlat.copy()
        if self.kind == "equirectangular":
            return np.column_stack([(lonlat[:, 0] - self.lon0) * self.cos_lat, lonlat[:, 1]])
        # a latitude beyond a pole (an equirectangular cartogram's sea may reach there) is taken at the pole
        lonlat = np.column_stack([lonlat[:, 0], np.clip(lonlat[:, 1], -90.0, 90.0)])
        if self._numpy:
            return _eqearth(self.lon0, lonlat, False) if self.kind == "eqearth" else \
                _laea(self.lon0, self.lat0, lonlat, False)
        x, y = _proj(self.definition)(lonlat[:, 0], lonlat[:, 1])
        return np.column_stack([x, y])

    def inverse(self, xy: np.ndarray) -> np.ndarray:
        """The plane (P, 2) to longitude/latitude (P, 2), longitudes continuous about :math:`\\lambda_0`.  A point
        beyond the projection's domain (the far side of the Lambert disc) is pulled towards the centre to its
        edge."""
        xy = np.asarray(xy, dtype=float)
        if self.kind == "none":
            return xy.copy()
        if self.kind == "equirectangular":
            return np.column_stack([xy[:, 0] / self.cos_lat + self.lon0, xy[:, 1]])
        ll = self._inverse(xy)
        bad = ~np.isfinite(ll).all(1)
        if bad.any():
            p = xy[bad]
            lo, hi = np.zeros(len(p)), np.ones(len(p))
            for _ in range(60):  # bisection along the ray to the centre, which always projects back
                t = 0.5 * (lo + hi)
                ok = np.isfinite(self._inverse(p * t[:, None])).all(1)
                lo, hi = np.where(ok, t, lo), np.where(ok, hi, t)
            ll[bad] = self._inverse(p * lo[:, None])
        return ll

    @property
    def _numpy(self) -> bool:
        """Whether the numpy formulas serve (Equal Earth; the Lambert projection but for a centre near a pole): no
        pyproj import, whose time a small map's whole command would notice."""
        return self.kind == "eqearth" or self.kind == "laea" and abs(self.lat0) < 89.9

    def _inverse(self, xy: np.ndarray) -> np.ndarray:
        if self._numpy:
            return _eqearth(self.lon0, xy, True) if self.kind == "eqearth" else _laea(self.lon0, self.lat0, xy, True)
        lon, lat = _proj(self.definition)(xy[:, 0], xy[:, 1], inverse=True)
        return np.column_stack([lon, lat])


# ----------------------------------------------------------------------------------------------- rings
def _rings(geoms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ring number of every vertex of ``geoms`` (in ``shapely.get_coordinates`` order) and each ring's first
    vertex."""
    import shapely

    counts = shapely.get_num_coordinates(shapely.get_rings(shapely.get_parts(geoms)))
    return np.repeat(np.arange(counts.size), counts), np.cumsum(counts) - counts


def _shift_rings(lon: np.ndarray, ring: np.ndarray, starts: np.ndarray, centre: float) -> np.ndarray:
    """``lon`` with every ring shifted by whole turns so that its middle longitude lies within ``centre`` ± 180."""
    mid = 0.5 * (np.minimum.reduceat(lon, starts) + np.maximum.reduceat(lon, starts))
    return lon - 360.0 * np.floor((mid - centre + 180.0) / 360.0)[ring]


def unwrap_rings(geoms: np.ndarray, lon0: float) -> np.ndarray:
    """Longitude/latitude geometries with every ring continuous (each step of more than 180° in longitude taken the
    short way, across the antimeridian) and shifted by whole turns so that its middle lies within ``lon0`` ± 180; a
    ring that does not close once continuous goes round a pole and keeps its longitudes."""
    import shapely

    xy = shapely.get_coordinates(geoms)
    if not len(xy):
        return geoms
    ring, starts = _rings(geoms)
    lon = xy[:, 0]
    step = np.diff(lon, prepend=lon[:1])
    step = np.mod(step + 180.0, 360.0) - 180.0
    step[starts] = 0.0
    total = np.cumsum(step)
    cont = lon[starts][ring] + total - total[starts][ring]
    ends = np.append(starts[1:], lon.size) - 1
    polar = np.abs(cont[ends] - cont[starts]) > 1e-9
    cont[ends] = cont[starts]  # closed exactly, whatever the rounding of the sums
    cont = np.where(polar[ring], lon, cont)
    return shapely.set_coordinates(geoms.copy(), np.column_stack([_shift_rings(cont, ring, starts, lon0), xy[:, 1]]))


def wrap_rings(geoms: np.ndarray) -> np.ndarray:
    """Longitude/latitude geometries with every ring shifted by whole turns so that its middle longitude lies in
    :math:`[-180, 180)`."""
    import shapely

    xy = shapely.get_coordinates(geoms)
    if not len(xy):
        return geoms
    ring, starts = _rings(geoms)
    return shapely.set_coordinates(geoms.copy(), np.column_stack([_shift_rings(xy[:, 0], ring, starts, 0.0), xy[:, 1]]))


# ----------------------------------------------------------------------------------------------- frame
@dataclass(frozen=True)
class PlanarFrame:
    r"""The input coordinates to the unit square and back: :math:`u = s\,(P(x) - c) + (\tfrac12, \tfrac12)`.

    ``P`` is the :class:`Projection` (``projection``), ``c`` the centre of the projected map's bounding box and ``s``
    fits its longer side into :math:`1 - 2\,\mathrm{margin}`.  ``area_projection`` is the equal-area projection in
    which areas are measured: ``projection`` itself when it is equal-area, else the one that ``"equal-area"`` would
    fit to the same map.
    """

    projection: Projection
    center: tuple[float, float]
    scale: float
    area_projection: Projection

    @classmethod
    def fit(cls, coords, *, margin: float, projection: str = "auto") -> "PlanarFrame":
        """The frame of a map given by its points ``coords`` (P, 2) or its shapely geometries (R,).

        ``projection`` is one of :data:`PROJECTIONS`: ``"auto"`` is ``"equal-area"`` when every point is a
        longitude/latitude pair and ``"none"`` otherwise.  Given geometries, the bounding box is that of the
        projected rings (continuous across the antimeridian); given points, that of the projected points.
        """
        import shapely

        if projection not in PROJECTIONS:
            raise ValueError(f"unknown projection {projection!r}; choose one of {', '.join(PROJECTIONS)}")
        if not 0 <= margin < 0.5:
            raise ValueError(f"margin must be in [0, 0.5), got {margin!r}")
        geoms = None
        if isinstance(coords, np.ndarray) and coords.dtype == object:
            geoms, coords = coords, shapely.get_coordinates(coords)
        coords = np.asarray(coords, dtype=float)
        lonlat = is_lonlat(coords)
        if projection == "auto":
            projection = "equal-area" if lonlat else "none"
        if projection != "none" and not lonlat:
            raise ValueError(f"projection {projection!r} needs longitude/latitude in degrees "
                             f"(|lon| <= 180, |lat| <= 90); these coordinates are planar (choose 'none')")
        proj = Projection.fit(coords, projection)
        area = proj if proj.equal_area else Projection.fit(coords, "equal-area")
        if geoms is not None:
            p = shapely.get_coordinates(_project(geoms, proj))
        else:
            p = proj.forward(_near(coords, proj))
        lo, hi = p.min(0), p.max(0)
        side = float((hi - lo).max())
        if not side > 0:
            raise ValueError("the regions have no extent")
        return cls(proj, tuple(float(c) for c in 0.5 * (lo + hi)), (1.0 - 2.0 * margin) / side, area)

    @property
    def cos_lat(self) -> float:
        r""":math:`\cos\varphi_0` of the map's centre latitude (1 for planar input): the aspect that draws its
        longitude/latitude true to scale there."""
        return self.projection.cos_lat

    def forward(self, coords: np.ndarray) -> np.ndarray:
        """Input coordinates (P, 2) to the unit square (longitudes within :math:`\\lambda_0 \\pm 180^\\circ`)."""
        return (self.projection.forward(coords) - np.array(self.center)) * self.scale + 0.5

    def inverse(self, u: np.ndarray) -> np.ndarray:
        """Unit-square points (P, 2) to input coordinates (longitudes continuous about :math:`\\lambda_0`)."""
        return self.projection.inverse(self.to_plane(u))

    def to_plane(self, u: np.ndarray) -> np.ndarray:
        """Unit-square points (P, 2) to the projection's plane (metres for the equal-area projections)."""
        return (np.asarray(u) - 0.5) / self.scale + np.array(self.center)

    def project(self, geoms: np.ndarray, max_step: float | None = None) -> np.ndarray:
        """Input geometries to the unit square: rings made continuous about :math:`\\lambda_0` and, with
        ``max_step``, edges split so that none is longer than ``max_step`` (unit-square units) — for a curved
        projection first along the input's straight lines in longitude/latitude, so that they bend as they
        should."""
        import shapely

        if self.projection.geographic:
            geoms = unwrap_rings(geoms, self.projection.lon0)
            if max_step and self.projection.kind != "equirectangular":
                metres = max_step / self.scale * self.projection.metres_per_unit
                geoms = shapely.segmentize(geoms, metres / _METRES_PER_DEGREE)
        out = shapely.transform(geoms, self.forward)
        return shapely.segmentize(out, max_step) if max_step else out

    def unproject(self, geoms: np.ndarray) -> np.ndarray:
        """Unit-square geometries to input coordinates, every ring's middle longitude in :math:`[-180, 180)`."""
        import shapely

        out = shapely.transform(geoms, self.inverse)
        return wrap_rings(out) if self.projection.geographic else out

    def planar(self, geoms: np.ndarray) -> np.ndarray:
        """Unit-square geometries to the projection's plane (:attr:`Projection.definition`)."""
        import shapely

        return shapely.transform(geoms, self.to_plane)

    def beyond_domain(self, geoms: np.ndarray, *, tol: float = 1.0) -> np.ndarray:
        """Whether each unit-square geometry (R,) has a vertex that no longitude/latitude projects to (past a pole's
        line, or beyond the far side of the Lambert disc, by more than ``tol`` metres): in input coordinates such a
        vertex is drawn at the domain's edge."""
        import shapely

        hit = np.zeros(len(geoms), dtype=bool)
        if not self.projection.geographic:
            return hit
        xy, index = shapely.get_coordinates(geoms, return_index=True)
        lonlat = self.inverse(xy)
        metres = np.abs(self.forward(lonlat) - xy).max(1) / self.scale * self.projection.metres_per_unit
        off = (metres > tol) | (np.abs(lonlat[:, 1]) > 90.0)
        np.logical_or.at(hit, index, off)
        return hit

    def equal_area(self, geoms: np.ndarray) -> np.ndarray:
        """Unit-square geometries to a plane whose areas are proportional to the Earth's: the unit square itself when
        the projection is equal-area, else ``area_projection``'s plane."""
        import shapely

        if self.projection.equal_area:
            return geoms
        # both projections are centred on the same meridian, so the continuous longitudes need no wrapping
        return shapely.transform(geoms, lambda u: self.area_projection.forward(self.inverse(u)))


def _near(lonlat: np.ndarray, proj: Projection) -> np.ndarray:
    """Points with every longitude shifted by whole turns into ``proj.lon0`` ± 180."""
    if not proj.geographic:
        return lonlat
    lon = lonlat[:, 0] - 360.0 * np.floor((lonlat[:, 0] - proj.lon0 + 180.0) / 360.0)
    return np.column_stack([lon, lonlat[:, 1]])


def _project(geoms: np.ndarray, proj: Projection) -> np.ndarray:
    """Input geometries to ``proj``'s plane, rings continuous about its central meridian."""
    import shapely

    if proj.geographic:
        geoms = unwrap_rings(geoms, proj.lon0)
    return shapely.transform(geoms, proj.forward)
