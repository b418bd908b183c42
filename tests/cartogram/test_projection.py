"""The numpy equal-area projections of :mod:`rfmap.cartogram.projection` (ellipsoidal Lambert azimuthal equal-area and Equal
Earth on WGS84) against PROJ through pyproj, the reference: forward to 1e-9 of the plane's extent, inverse to 1e-9 of
a turn, on random points; and a longitude/latitude cartogram command that never imports pyproj."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from rfmap.cartogram.projection import Projection, _eqearth, _laea, _proj

pytest.importorskip("pyproj")

CASES = [("laea", 10.0, 45.0), ("laea", -170.0, -30.0), ("laea", 0.0, 0.0), ("laea", 100.0, 80.0),
         ("laea", 179.5, 89.0), ("eqearth", 0.0, 0.0), ("eqearth", 150.0, 0.0)]


def _points(kind: str, lon0: float, lat0: float, size: int = 20_000) -> np.ndarray:
    """Random longitude/latitude around the centre (the Lambert projection's hemisphere; Equal Earth's whole
    globe), away from the poles, where a longitude means nothing."""
    rng = np.random.default_rng([len(kind), int(lon0 + 180), int(lat0 + 90)])
    if kind == "laea":
        lat = np.clip(lat0 + rng.uniform(-60, 60, size), -89.999, 89.999)
        return np.column_stack([lon0 + rng.uniform(-80, 80, size), lat])
    return np.column_stack([lon0 + rng.uniform(-179.99, 179.99, size), rng.uniform(-89.999, 89.999, size)])


@pytest.mark.parametrize("kind,lon0,lat0", CASES)
def test_numpy_projection_matches_proj(kind, lon0, lat0):
    ll = _points(kind, lon0, lat0)
    proj = Projection(kind, lon0, lat0)
    ref = np.column_stack(_proj(proj.definition)(ll[:, 0], ll[:, 1]))
    mine = _laea(lon0, lat0, ll, False) if kind == "laea" else _eqearth(lon0, ll, False)
    assert np.abs(mine - ref).max() <= 1e-9 * np.abs(ref).max()
    back_ref = np.column_stack(_proj(proj.definition)(ref[:, 0], ref[:, 1], inverse=True))
    back = _laea(lon0, lat0, ref, True) if kind == "laea" else _eqearth(lon0, ref, True)
    assert np.abs(back - back_ref).max() <= 1e-9 * 360.0
    # the round trip, in degrees of a great circle (a longitude near a pole is worth little); 1e-8 degrees (1 mm):
    # near a pole the latitude passes through the sine of the authalic latitude, whose rounding it magnifies
    assert np.abs(back[:, 1] - ll[:, 1]).max() <= 1e-8
    assert (np.abs(back[:, 0] - ll[:, 0]) * np.cos(np.radians(ll[:, 1]))).max() <= 1e-9
    # the Projection's own methods use them (but near a pole, where the centre's formulas degenerate)
    assert proj._numpy == (kind == "eqearth" or abs(lat0) < 89.9)
    assert np.abs(proj.forward(ll) - ref).max() <= 1e-9 * np.abs(ref).max()


def test_lambert_inverse_beyond_the_disc_is_not_finite_as_proj():
    proj = Projection("laea", 20.0, 10.0)
    far = np.array([[2.1 * 6371e3 * 2, 0.0], [0.0, -1.3e7]])  # beyond the disc of radius 2 R_q (about 12,742 km)
    assert not np.isfinite(_laea(20.0, 10.0, far, True)).all(axis=1).any()
    assert not np.isfinite(np.column_stack(_proj(proj.definition)(far[:, 0], far[:, 1], inverse=True))).all(1).any()
    edge = proj.inverse(far)  # pulled to the disc's edge, the centre's antipode: finite
    assert np.isfinite(edge).all()
    assert np.allclose(edge[:, 1], -10.0, atol=1e-4) and np.allclose(np.mod(edge[:, 0], 360.0), 200.0, atol=1e-4)


def test_equal_earth_inverse_clamps_beyond_the_pole_as_proj():
    proj = Projection("eqearth", 0.0)
    far = np.array([[1e6, 9.5e6], [-2e6, -9.9e6]])  # the poles lie at y = +-8.4e6 m
    ref = np.column_stack(_proj(proj.definition)(far[:, 0], far[:, 1], inverse=True))
    mine = _eqearth(0.0, far, True)
    assert np.allclose(mine[:, 1], [90.0, -90.0], atol=1e-9) and np.allclose(mine, ref, atol=1e-6)


def test_lonlat_cartogram_command_does_not_import_pyproj(tmp_path):
    from rfmap.cartogram.regions import world_countries

    feats = [f for f in world_countries()["features"] if f["properties"]["continent"] == "South America"]
    src = tmp_path / "sa.geojson"
    src.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    code = ("import sys; from rfmap.cli import main; "
            f"rc = main(['cartogram', {str(src)!r}, '--value', 'pop_est', '--n', '64', '--out', "
            f"{str(tmp_path / 'out.geojson')!r}]); print(rc, 'pyproj' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out[-1] == "False" and out[-2] in ("0", "1")
    assert json.loads((tmp_path / "out.geojson").read_text())["features"]
