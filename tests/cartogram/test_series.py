"""Tests of :mod:`rfmap.cartogram.series`: a warm-started series of cartograms reaches the tolerance in every frame
in fewer passes than the cold one (passes compared, not seconds), the regions below the judged share are reported
apart, and the animation is written."""
from __future__ import annotations

import numpy as np
import pytest

from rfmap.cartogram.series import cartogram_series, compare_warm_cold, save_animation

YEARS = (1952, 1957, 1962)
#: N and the flow method: South America's cartograms reach 1 % in 8-9 passes cold, 4 warm (measured at N = 96)
OPTIONS = {"n": 96, "method": "flow", "max_iterations": 12}


@pytest.fixture(scope="module")
def south_america():
    pytest.importorskip("plotly")
    pytest.importorskip("pyproj")
    from rfmap.cartogram.data import world_population

    fc = world_population(YEARS).collection
    return {"type": "FeatureCollection",
            "features": [f for f in fc["features"] if f["properties"]["continent"] == "South America"]}


@pytest.fixture(scope="module")
def series(south_america):
    return compare_warm_cold(south_america, [f"pop_{y}" for y in YEARS], **OPTIONS)


def test_every_frame_meets_the_tolerance(series):
    for s in series:
        assert s.within_tolerance().all(), s.problems()
        assert s.max_errors.max() <= 0.01  # measured 0.0053-0.0095
        assert not s.problems()


def test_warm_frames_take_fewer_passes(series):
    warm, cold = series
    assert warm.passes[0] == cold.passes[0]  # the first frame is the same cold cartogram
    assert (warm.passes[1:] < cold.passes[1:]).all(), (warm.passes, cold.passes)  # measured 4 against 8-9


def test_small_regions_are_reported_apart(series):
    """The Falkland Islands (about 2,000 people) hold under 0.01 % of South America's population."""
    for f in series[0].frames:
        assert f.small == ["Falkland Is."]
        share = f.carto.values / f.carto.values.sum()
        big = share >= 1e-4
        assert f.max_error == pytest.approx(f.carto.area_errors[big].max())


def test_frames_share_one_plane(series, south_america):
    """Every frame of both series lies in the metres of one equal-area plane: each frame's total area matches the
    first's within 2 % (the sea at the mean density keeps the land's total area)."""
    warm, cold = series
    total = [sum(g.area for g in f.carto.projected_geometries()) for s in series for f in s.frames]
    assert np.ptp(total) / total[0] < 0.02
    assert total[0] > 1e12  # square metres (South America is about 1.8e13)


def test_a_frame_uses_its_own_values(series):
    """The warm frame of 1962 is the cartogram by 1962's values: its area shares are those values' shares."""
    f = series[0].frames[2]
    a = np.array([g.area for g in f.carto.projected_geometries()])
    v = np.array([feat["properties"]["pop_1962"] for feat in f.carto.features])
    big = v / v.sum() >= 1e-4
    assert np.abs(a / a.sum() / (v / v.sum()) - 1)[big].max() <= 0.01


def test_bad_series_options(south_america):
    with pytest.raises(ValueError, match="at least one"):
        cartogram_series(south_america, [])
    with pytest.raises(ValueError, match="output"):
        cartogram_series(south_america, ["pop_1952"], output="input")


def test_animation_is_written(series, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from PIL import Image

    path = save_animation(series[0], tmp_path / "s.gif", titles=[str(y) for y in YEARS], dpi=40)
    with Image.open(path) as im:
        assert im.format == "GIF" and im.n_frames == len(YEARS)
    with pytest.raises(ValueError, match=".gif or .mp4"):
        save_animation(series[0], tmp_path / "s.png")


def test_series_grid_has_a_colour_legend_below_the_frames(series):
    """With ``key`` the grid carries one legend of the categories (and "no data" for grey regions), below the
    frames."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rfmap.viz.cartograms import series_grid

    n = len(series[0].frames[0].carto.projected_geometries())
    colors = ["tab:red"] * (n - 1) + ["0.85"]
    fig = series_grid(series[0], [0, len(YEARS) - 1], colors=colors, key={"South America": "tab:red"})
    (legend,) = fig.legends
    assert [t.get_text() for t in legend.get_texts()] == ["South America", "no data"]
    fig.canvas.draw()
    frames = [ax for ax in fig.axes if ax.has_data()]
    assert frames and all(legend.get_window_extent().y1 <= ax.get_window_extent().y0 + 1 for ax in frames)
    plt.close(fig)


# ----------------------------------------------------------------------------------------------- command line
def block(years):
    """Four squares of 1 km in a 2 x 2 block, ids a..d, the fourth growing: ``y<k>`` = (1, 1, 1, 2 + k)."""
    corners = [(0, 0), (1000, 0), (0, 1000), (1000, 1000)]
    return {"type": "FeatureCollection", "features": [
        {"type": "Feature", "id": name, "properties": {f"y{k}": (2 + k if name == "d" else 1) for k in years},
         "geometry": {"type": "Polygon", "coordinates": [[[x, y], [x + 1000, y], [x + 1000, y + 1000],
                                                          [x, y + 1000], [x, y]]]}}
        for name, (x, y) in zip("abcd", corners)]}


def test_cli_series_writes_the_last_frame_and_the_animation(tmp_path, capsys):
    import json

    from rfmap.cli import main

    src, out, gif = tmp_path / "map.geojson", tmp_path / "out.geojson", tmp_path / "out.gif"
    src.write_text(json.dumps(block(range(3))))
    rc = main([str(a) for a in ("cartogram", src, "--series", "y0", "y1", "y2", "--method", "flow", "--n", 48,
                                "--out", out, "--gif", gif)])
    stdout, err = capsys.readouterr()
    assert rc == 0, err
    lines = stdout.splitlines()
    assert [ln.split(":")[0] for ln in lines[:3]] == ["y0", "y1", "y2"]
    feats = json.loads(out.read_text())["features"]
    import shapely
    from shapely.geometry import shape

    a = shapely.area(np.array([shape(f["geometry"]) for f in feats], dtype=object))
    assert a[3] / a.sum() == pytest.approx(4 / 7, abs=0.01)  # the last frame: d holds 4 of 7
    from PIL import Image

    with Image.open(gif) as im:
        assert im.n_frames == 3
    for args, match in ((["--value", "y0", "--series", "y1"], "one of --value"), (["--value", "y0", "--gif", gif],
                                                                                  "--gif needs --series"),
                        (["--series", "y0", "--gif", tmp_path / "out.png"], "--gif must name")):
        gif.unlink(missing_ok=True)
        out.unlink(missing_ok=True)
        rc = main([str(a) for a in ("cartogram", src, *args, "--out", out)])
        _, err = capsys.readouterr()
        assert rc == 2 and match in err and not list(tmp_path.glob("out*"))
