"""Tests of :mod:`rfmap.cartogram.data` (a CSV joined to GeoJSON regions, its template, the world's population), of
the figures of :func:`rfmap.viz.cartograms.cartogram_figure` (SVG and PNG with the area legend) and of ``rfmap
cartogram --data / --make-csv / --svg`` with its exit status."""
from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from rfmap.cartogram.data import join_values, read_csv_table, read_csv_values, region_ids, write_csv_template
from rfmap.cli import main

SIDE = 1000.0  # metres: planar coordinates


def square(x, y, side=SIDE):
    return [[[x, y], [x + side, y], [x + side, y + side], [x, y + side], [x, y]]]


def block(ids=("a", "b", "c", "d"), key="code"):
    """Four squares in a 2 x 2 block, their ids under the property ``key`` (and a ``name``)."""
    corners = [(0, 0), (SIDE, 0), (0, SIDE), (SIDE, SIDE)]
    return {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {key: i, "name": f"region {i}"},
         "geometry": {"type": "Polygon", "coordinates": square(x, y)}} for i, (x, y) in zip(ids, corners)]}


def write_csv(path, rows, header=("code", "pop", "group", "short")):
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


ROWS = [("a", 1, "x", "A"), ("b", 1, "y", "B"), ("c", 1, "x", "C"), ("d", 5, "y", "D")]


# ----------------------------------------------------------------------------------------------- the join
def test_read_csv_values_and_table(tmp_path):
    path = write_csv(tmp_path / "v.csv", ROWS)
    assert read_csv_values(path, "code", "pop") == {"a": 1.0, "b": 1.0, "c": 1.0, "d": 5.0}
    assert read_csv_table(path, "code", ["group"])["d"] == {"group": "y"}


@pytest.mark.parametrize("rows,match", [
    ([("a", "", "x", "A")], "missing"),
    ([("a", "many", "x", "A")], "not a number"),
    ([("a", "-2", "x", "A")], "negative"),
    ([("a", "nan", "x", "A")], "NaN"),
    ([("a", "1", "x", "A"), ("a", "2", "x", "A")], "twice"),
])
def test_bad_values_are_one_line_value_errors(tmp_path, rows, match):
    path = write_csv(tmp_path / "v.csv", rows)
    with pytest.raises(ValueError, match=match) as e:
        read_csv_values(path, "code", "pop")
    assert "\n" not in str(e.value)


def test_unknown_columns_and_unreadable_files(tmp_path):
    path = write_csv(tmp_path / "v.csv", ROWS)
    with pytest.raises(ValueError, match="no column 'iso'"):
        read_csv_values(path, "iso", "pop")
    with pytest.raises(ValueError, match="no column 'votes'"):
        read_csv_values(path, "code", "votes")
    with pytest.raises(ValueError, match="cannot read"):
        read_csv_values(tmp_path / "nope.csv", "code", "pop")
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00code")
    with pytest.raises(ValueError, match="not UTF-8"):
        read_csv_values(tmp_path / "bin.csv", "code", "pop")
    with pytest.raises(ValueError, match="no region has the property 'iso'"):
        region_ids(block(), "iso")


def test_a_windows_1252_table_is_read_with_a_warning(tmp_path):
    """Census tables often come in Windows-1252 ("Doña Ana" as one byte per letter): read, with a warning."""
    path = tmp_path / "latin.csv"
    path.write_bytes("code,pop,name\na,1,Doña Ana\nb,2,Bexar\n".encode("cp1252"))
    with pytest.warns(UnicodeWarning, match="not UTF-8 text; read as Windows-1252"):
        table = read_csv_table(path, "code", ["name"])
    assert table["a"]["name"] == "Doña Ana" and table["b"]["name"] == "Bexar"


def test_join_matches_and_reports_both_sides():
    values = {"a": 1, "b": 2, "d": 4, "zz": 9}
    j = join_values(block(), values, key="code", value="pop", missing="drop")
    assert j.matched == 3 and j.unmatched_regions == ["c"] and j.unmatched_rows == ["zz"]
    assert [f["properties"]["pop"] for f in j.collection["features"]] == [1.0, 2.0, 4.0]
    regions, rows = j.report()
    assert regions.startswith("regions without data (1, left out): c") and rows == "data without a region (1): zz"


def test_a_region_without_data_gets_the_mean_density():
    """Four equal squares, three matched with 1, 2 and 3: the fourth gets (1 + 2 + 3) / 3 = 2 (equal areas)."""
    j = join_values(block(), {"a": 1, "b": 2, "d": 3}, key="code", value="pop")
    assert [f["properties"]["pop"] for f in j.collection["features"]] == pytest.approx([1, 2, 2, 3], rel=1e-12)
    with pytest.raises(ValueError, match="1 region.*without data: c"):
        join_values(block(), {"a": 1, "b": 2, "d": 3}, key="code", missing="error")
    j = join_values(block(), {"a": 1, "b": 2, "d": 3}, key="code", fallback={"c": 7.0}, missing="error")
    assert j.collection["features"][2]["properties"]["value"] == 7.0 and j.unmatched_regions == ["c"]


def test_a_region_without_data_gets_the_total_value_over_the_total_area_of_the_others():
    """Matched squares of 4 and 1 km^2 holding 4 and 3 (densities 1 and 3 per km^2): a 1 km^2 region without data
    gets (4 + 3) / (4 + 1) = 1.4 per km^2, the density of the matched land taken together; the mean of the two
    densities, 2, would give 2.  Planar coordinates: the areas are exact."""
    big = [[[0, 0], [2000, 0], [2000, 2000], [0, 2000], [0, 0]]]
    fc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"k": k}, "geometry": {"type": "Polygon", "coordinates": ring}}
        for k, ring in (("big", big), ("small", square(2000.0, 0.0)), ("none", square(2000.0, 1000.0)))]}
    j = join_values(fc, {"big": 4e6, "small": 3e6}, key="k", value="v")
    assert j.unmatched_regions == ["none"] and j.missing == "mean"
    assert j.collection["features"][2]["properties"]["v"] == pytest.approx(1.4e6, rel=1e-12)


def test_ids_match_as_text_and_the_feature_id_is_used():
    fc = block(ids=(1, 2, 3, 4.0), key="num")
    j = join_values(fc, {"1": 1, "2": 1, "3": 1, "4": 5}, key="num")
    assert j.matched == 4 and not j.unmatched_regions
    for k, f in enumerate(fc["features"]):
        f["id"] = f"r{k}"
    assert region_ids(fc, "id") == ["r0", "r1", "r2", "r3"]
    with pytest.raises(ValueError, match="no region's 'num' matches"):
        join_values(fc, {"x": 1}, key="num")


def test_template_has_one_row_per_region(tmp_path):
    out = tmp_path / "t.csv"
    assert write_csv_template(block(), out, key="code", value="pop") == 4
    rows = list(csv.reader(out.open(encoding="utf-8")))
    assert rows == [["code", "pop"], ["a", ""], ["b", ""], ["c", ""], ["d", ""]]
    with pytest.raises(ValueError, match="several regions"):
        write_csv_template(block(ids=("a", "a", "b", "c")), tmp_path / "u.csv", key="code")
    assert not (tmp_path / "u.csv").exists()


def test_joined_values_make_the_cartogram():
    from rfmap.cartogram.resize import cartogram

    j = join_values(block(), dict(zip("abcd", (1, 1, 1, 5))), key="code", value="pop")
    c = cartogram(j.collection, "pop", method="flow", n=48)
    assert c.metrics().max_error <= 0.01  # measured 0.002
    assert c.areas[3] / c.areas.sum() == pytest.approx(5 / 8, abs=0.01)


def test_world_population_joins_gapminder_by_iso3():
    pytest.importorskip("plotly")
    pytest.importorskip("pyproj")
    from rfmap.cartogram.data import gapminder_population, world_population

    j = world_population((1952, 2007))
    props = {f["properties"]["iso_a3"]: f["properties"] for f in j.collection["features"]}
    assert "ATA" not in props and len(props) == 176
    assert props["CHN"]["pop_2007"] == gapminder_population(2007)["CHN"]
    # the table files both Koreas under KOR; each gets its own row (South Korea about twice the North)
    assert props["KOR"]["pop_2007"] / props["PRK"]["pop_2007"] == pytest.approx(2.1, abs=0.1)
    assert "North Korea" not in j.unmatched_regions
    assert props["IND"]["pop_1952"] < props["IND"]["pop_2007"]
    assert "Russia" in j.unmatched_regions and "SGP" in j.unmatched_rows  # too small for the 1:110m map
    # the table's Sudan is the Sudan of before 2011: split between today's Sudan and South Sudan, not counted twice
    assert "S. Sudan" not in j.unmatched_regions
    for year in (1952, 2007):
        parts = props["SDN"][f"pop_{year}"] + props["SSD"][f"pop_{year}"]
        assert parts == pytest.approx(gapminder_population(year)["SDN"], rel=1e-12)
    assert props["SSD"]["pop_2007"] / props["SDN"]["pop_2007"] == pytest.approx(
        props["SSD"]["pop_est"] / props["SDN"]["pop_est"], rel=1e-12)
    # a country without a row keeps its share of Natural Earth's estimate among the matched countries
    est = {i: p["pop_est"] for i, p in props.items()}
    matched = [i for i, p in props.items() if p["name"] not in j.unmatched_regions]
    ratio = sum(props[i]["pop_2007"] for i in matched) / sum(est[i] for i in matched)
    assert props["RUS"]["pop_2007"] == pytest.approx(est["RUS"] * ratio, rel=1e-12)


# ----------------------------------------------------------------------------------------------- figures
@pytest.fixture(scope="module")
def carto():
    from rfmap.cartogram.resize import cartogram

    return cartogram(join_values(block(), dict(zip("abcd", (1, 1, 1, 5))), key="code", value="pop").collection,
                     "pop", method="flow", n=48)


def test_figure_svg_has_the_area_legend(carto, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from rfmap.viz.cartograms import area_legend, cartogram_figure, format_amount

    svg = tmp_path / "f.svg"
    fig = cartogram_figure(carto, labels=list("ABCD"), unit="people", path=svg)
    text = svg.read_text(encoding="utf-8")
    # the input panel names the value after its head, not run together with it
    titled = cartogram_figure(carto, title="people 2007")
    assert titled.axes[0].get_title() == "input map (people 2007)"
    # the legend square stands for a round amount (1, 2 or 5 times a power of ten) of the 8 people, the largest
    # whose square's side is at most 10 % of the axes' width, at the cartogram's scale (value per unit area)
    import re

    amount = float(re.search(r"= ([0-9.]+) people", text).group(1))
    assert ">D<" in text
    per_area = 8.0 / sum(g.area for g in carto.projected_geometries())
    side = fig.axes[1].patches[-1].get_width()
    assert side**2 * per_area == pytest.approx(amount, rel=1e-9)
    width = np.diff(fig.axes[1].get_xlim())[0]
    assert side <= 0.1 * width
    digits = f"{amount:e}"[0]
    bigger = amount * (2.5 if digits == "2" else 2.0)  # the next round amount
    assert (bigger / per_area) ** 0.5 > 0.1 * width
    assert format_amount(5e7) == "50 million" and format_amount(2e9) == "2 billion" and format_amount(2000) == "2,000"
    import matplotlib.pyplot as plt

    _, ax = plt.subplots()
    ax.set(xlim=(0, 10), ylim=(0, 10))
    assert area_legend(ax, 300.0, 100.0, unit="votes") == "= 2 votes"  # side <= 1 holds <= 3 -> 2


def test_neighbours_get_different_colours(carto):
    from rfmap.viz.cartograms import neighbour_colours, region_colours

    c = neighbour_colours(carto.projected_geometries(mapped=False))
    assert len(set(c)) == 4  # every square of the 2 x 2 block touches the three others (corners included)
    faces, key = region_colours(["x", "y", None, "x"])
    assert faces[0] == faces[3] != faces[1] and faces[2] == "0.85" and list(key) == ["x", "y"]
    assert region_colours(["red", "#00ff00"]) == (["red", "#00ff00"], {})


#: a row of five planar squares named as Dutch provinces are, and the table's spellings of them
PROVINCES = ("Fryslân", "Groningen", "Drenthe", "Île", "Zeeland")


def provinces() -> dict:
    return {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"name": name},
         "geometry": {"type": "Polygon", "coordinates": square(k * SIDE, 0)}} for k, name in enumerate(PROVINCES)]}


def test_loose_ids_drop_accents_and_case():
    from rfmap.cartogram.data import loose_id

    assert loose_id("Fryslân") == loose_id("FRYSLAN") == "fryslan"
    assert loose_id("Île-de-France") == "ile-de-france" and loose_id("Straße") == "strasse"  # casefold: ß -> ss
    assert loose_id("Frysl\u00e2n") == loose_id("Frysla\u0302n")  # composed and decomposed â alike


def test_join_ignores_accents_and_case_where_the_partner_is_unique():
    """Exact ids first ("Drenthe"); "Fryslan" and "groningen" find their one region with accents and case ignored
    and are reported by pair; "ILE" and "île" both fold to the region "Île": not joined, asked about."""
    values = {"Fryslan": 2, "groningen": 3, "Drenthe": 4, "ILE": 5, "île": 6, "Zeeland": 1}
    j = join_values(provinces(), values, key="name", value="pop", missing="drop")
    assert j.matched == 4 and j.unmatched_regions == ["Île"] and j.unmatched_rows == ["ILE", "île"]
    assert j.loose == [("Fryslân", "Fryslan"), ("Groningen", "groningen")]
    assert j.ambiguous == [("Île", ["ILE", "île"])]
    assert [f["properties"]["pop"] for f in j.collection["features"]] == [2.0, 3.0, 4.0, 1.0]
    assert j.report()[2:] == [
        "joined with accents and case ignored (2, region = data): 'Fryslân' = 'Fryslan', 'Groningen' = 'groningen'",
        "not joined, several near-matches (1): 'Île': did you mean 'ILE' or 'île'?"]


def test_an_exact_match_wins_over_a_loose_one_and_regions_sharing_a_loose_id_are_asked_about():
    """The row "Zeeland" joins its region exactly, so the row "ZEELAND" finds no free partner; two regions "Ile" and
    "ÎLE" with one row "île" leave the row unjoined and both regions asked about."""
    fc = provinces()
    fc["features"][2]["properties"]["name"] = "ÎLE"
    fc["features"][3]["properties"]["name"] = "Ile"
    j = join_values(fc, {"Fryslân": 1, "Groningen": 1, "Zeeland": 2, "ZEELAND": 7, "île": 3}, key="name",
                    value="pop", missing="drop")
    assert j.loose == [] and j.ambiguous == [("ÎLE", ["île"]), ("Ile", ["île"])]
    assert j.unmatched_rows == ["ZEELAND", "île"] and j.collection["features"][-1]["properties"]["pop"] == 2.0
    assert len(j.report()) == 3  # no line of loose pairs


def test_cli_reports_the_loose_pairs_and_takes_their_values(tmp_path, capsys):
    src = tmp_path / "map.geojson"
    src.write_text(json.dumps(provinces()), encoding="utf-8")
    data = write_csv(tmp_path / "v.csv", [("Fryslan", 2, "x", "F"), ("GRONINGEN", 3, "y", "G"),
                                          ("Drenthe", 4, "x", "D"), ("Île", 5, "y", "I"), ("Zeeland", 1, "x", "Z")],
                     header=("province", "pop", "group", "short"))
    out = tmp_path / "out.geojson"
    rc, stdout, err = run_cli(capsys, "cartogram", src, "--data", data, "--id", "province", "--id-property", "name",
                              "--value", "pop", "--label", "short", "--n", 48, "--out", out)
    assert rc == 0, err
    lines = stdout.splitlines()
    assert lines[:3] == ["regions without data: none", "data without a region: none",
                         "joined with accents and case ignored (2, region = data): 'Fryslân' = 'Fryslan', "
                         "'Groningen' = 'GRONINGEN'"]
    props = [f["properties"] for f in json.loads(out.read_text(encoding="utf-8"))["features"]]
    assert [p["pop"] for p in props] == [2.0, 3.0, 4.0, 5.0, 1.0] and props[0]["short"] == "F"


# ----------------------------------------------------------------------------------------------- command line
def run_cli(capsys, *args):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def test_cli_joins_a_csv_and_draws_png_and_svg(tmp_path, capsys):
    src = tmp_path / "map.geojson"
    src.write_text(json.dumps(block()))
    data = write_csv(tmp_path / "v.csv", ROWS[1:] + [("zz", 3, "x", "Z")])
    out, png, svg = tmp_path / "out.geojson", tmp_path / "out.png", tmp_path / "out.svg"
    rc, stdout, err = run_cli(capsys, "cartogram", src, "--data", data, "--id", "code", "--value", "pop", "--color",
                              "group", "--label", "short", "--method", "flow", "--n", 48, "--out", out, "--png", png,
                              "--svg", svg)
    assert rc == 0, err
    lines = stdout.splitlines()
    assert lines[0] == "regions without data (1, given the mean density): a"
    assert lines[1] == "data without a region (1): zz"
    back = json.loads(out.read_text())
    pops = [f["properties"]["pop"] for f in back["features"]]
    assert pops[1:] == [1.0, 1.0, 5.0] and pops[0] == pytest.approx(7 / 3)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = svg.read_text(encoding="utf-8")
    import re

    assert re.search(r"= [0-9.]+ pop<", text) and ">D<" in text and ">x<" in text  # area legend, label, colours
    assert ">no data<" in text


def test_cli_make_csv(tmp_path, capsys):
    src, tmpl = tmp_path / "map.geojson", tmp_path / "t.csv"
    src.write_text(json.dumps(block()))
    rc, stdout, err = run_cli(capsys, "cartogram", src, "--make-csv", tmpl, "--id", "code", "--value", "pop")
    assert rc == 0, err
    assert "4 regions" in stdout
    assert tmpl.read_text().splitlines() == ["code,pop", "a,", "b,", "c,", "d,"]
    rc, _, err = run_cli(capsys, "cartogram", src, "--make-csv", tmp_path / "u.csv", "--id", "iso", "--value", "pop")
    assert rc == 2 and "no region has the property 'iso'" in err and not (tmp_path / "u.csv").exists()


@pytest.mark.parametrize("rows,args,match", [
    (ROWS[:3] + [("d", "-5", "y", "D")], [], "negative"),
    (ROWS[:3] + [("d", "five", "y", "D")], [], "not a number"),
    (ROWS[:3] + [("d", "", "y", "D")], [], "missing"),
    (ROWS, ["--id", "iso"], "no column 'iso'"),
    (ROWS, ["--id-property", "iso"], "no region has the property 'iso'"),
    (ROWS, ["--color", "colour"], "no column 'colour'"),
    (ROWS[:3], ["--missing", "error"], "without data: d"),
    (None, [], "cannot read"),
    (ROWS, ["--svg", "f.png"], "--svg must name a .svg"),
])
def test_cli_bad_data_exits_2_and_writes_nothing(tmp_path, capsys, rows, args, match):
    src = tmp_path / "map.geojson"
    src.write_text(json.dumps(block()))
    data = write_csv(tmp_path / "v.csv", rows) if rows is not None else tmp_path / "none.csv"
    if "--id" not in args:
        args = ["--id", "code", *args]
    out = tmp_path / "out.geojson"
    rc, stdout, err = run_cli(capsys, "cartogram", src, "--data", data, "--value", "pop", *args, "--n", 32,
                              "--out", out, "--png", tmp_path / "out.png")
    assert rc == 2
    assert len(err.strip().splitlines()) == 1 and err.startswith("rfmap cartogram: error:") and match in err, err
    assert not list(tmp_path.glob("out*"))


def test_cli_no_polygons_exits_2(tmp_path, capsys):
    src = tmp_path / "map.geojson"
    fc = block()
    fc["features"][0]["geometry"] = {"type": "Point", "coordinates": [0, 0]}
    src.write_text(json.dumps(fc))
    data = write_csv(tmp_path / "v.csv", ROWS)
    rc, _, err = run_cli(capsys, "cartogram", src, "--data", data, "--id", "code", "--value", "pop",
                         "--out", tmp_path / "out.geojson", "--svg", tmp_path / "out.svg")
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "Polygon" in err
    assert not list(tmp_path.glob("out*"))
    rc, _, err = run_cli(capsys, "cartogram", src, "--value", "pop")
    assert rc == 2 and "--out is required" in err


def test_areas_of_unmatched_regions_use_the_equal_area_plane():
    """Two boxes of 10 x 5 degrees at the equator and at 60 N: the northern one has about half the area, so with
    the mean density of the southern one it gets about half its value (the ratio of the two areas)."""
    pytest.importorskip("pyproj")

    def box(lon, lat):
        return [[[lon, lat], [lon + 10, lat], [lon + 10, lat + 5], [lon, lat + 5], [lon, lat]]]

    fc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"k": k}, "geometry": {"type": "Polygon", "coordinates": box(0, lat)}}
        for k, lat in (("s", 0), ("n", 60))]}
    j = join_values(fc, {"s": 100.0}, key="k")
    ratio = j.collection["features"][1]["properties"]["value"] / 100.0
    # on the sphere the ratio is (sin 65 - sin 60) / sin 5 = 0.4624; the ellipsoid changes it by under 1 %
    exact = (np.sin(np.radians(65)) - np.sin(np.radians(60))) / np.sin(np.radians(5))
    assert ratio == pytest.approx(exact, rel=0.01)
