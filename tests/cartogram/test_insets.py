"""Tests of :mod:`rfmap.cartogram.insets` and ``rfmap cartogram --inset``: insets named as cartogram-cpp names them,
each a cartogram in its own frame, put on the main map's scale (a unit of value covers the same area in every
frame) and placed beside it without overlap; labels from a column."""
from __future__ import annotations

import csv
import json
import re
import subprocess
import sys

import numpy as np
import pytest
import shapely
from shapely.geometry import mapping, shape

from rfmap.cartogram.insets import GAP, cartogram_insets, inset_groups


def _feature(fid, box, value, inset):
    return {"type": "Feature", "id": fid, "properties": {"v": value, "inset": inset, "name": f"Region {fid}"},
            "geometry": mapping(shapely.box(*box))}


@pytest.fixture(scope="module")
def states():
    """A main map of nine states, a large sparse one far to the north-west (an Alaska, inset L) and two small dense
    islands far to the south-west (a Hawaii, inset B)."""
    feats = [_feature(f"m{3 * i + j}", (i, j, i + 1, j + 1), 1.0 + 3 * i + j, "C") for i in range(3) for j in range(3)]
    feats.append(_feature("ak", (-30, 20, -26, 24), 2.0, "L"))
    feats.append(_feature("hi1", (-20, -20, -19.5, -19.5), 3.0, "b"))
    feats.append(_feature("hi2", (-19.5, -20, -19, -19.5), 1.0, "bottom"))
    return {"type": "FeatureCollection", "features": feats}


def test_inset_names_as_cartogram_cpp_writes_them():
    groups = inset_groups(["C", "", None, "l", "Right", "T", "b"])
    assert {k: v.tolist() for k, v in groups.items()} == {"C": [0, 1, 2], "L": [3], "R": [4], "T": [5], "B": [6]}
    with pytest.raises(ValueError, match="unknown inset 'Alaska'"):
        inset_groups(["C", "Alaska"])


def test_insets_share_one_scale_and_sit_beside_the_main_map(states):
    c = cartogram_insets(states, "v", "inset", n=64)
    assert list(c.groups) == ["C", "L", "B"]
    assert not c.problems(), c.problems()
    m = c.metrics()
    assert m.max_error <= 0.01 and m.n_invalid == 0 and m.n_overlapping == 0
    # a unit of value covers the same area in every frame: each inset's area over its value as the whole map's
    area = shapely.area(c.geometries)
    density = area.sum() / c.values.sum()
    for side, idx in c.groups.items():
        assert area[idx].sum() / c.values[idx].sum() == pytest.approx(density, rel=0.01), side
    # placed beside the main map, a gap away, on their sides
    main = shapely.total_bounds(c.geometries[c.groups["C"]])
    gap = GAP * max(main[2] - main[0], main[3] - main[1])
    left = shapely.total_bounds(c.geometries[c.groups["L"]])
    below = shapely.total_bounds(c.geometries[c.groups["B"]])
    assert left[2] == pytest.approx(main[0] - gap, rel=1e-6) and below[3] == pytest.approx(main[1] - gap, rel=1e-6)
    assert left[1] < 0.5 * (main[1] + main[3]) < left[3] and below[0] < 0.5 * (main[0] + main[2]) < below[2]
    # the input map is laid out the same way, at its true scale: the sparse Alaska is larger than in the cartogram
    assert shapely.area(c.regions[c.groups["L"]]).sum() > area[c.groups["L"]].sum()


def test_insets_must_be_one_per_region(states):
    with pytest.raises(ValueError, match="one per region"):
        cartogram_insets(states, "v", ["C", "L"], n=32)


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "rfmap.cli", "cartogram", *map(str, args)], capture_output=True,
                          text=True, timeout=600, cwd=cwd)


def _files(tmp_path, states, inset_of=None):
    """The map without its values and a CSV as cartogram-cpp reads it: Region, Data, Inset, Label."""
    src = tmp_path / "states.geojson"
    bare = [{**f, "properties": {"name": f["properties"]["name"]}} for f in states["features"]]
    src.write_text(json.dumps({"type": "FeatureCollection", "features": bare}))
    table = tmp_path / "data.csv"
    with open(table, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["Region", "Data", "Inset", "Label"])
        for f in states["features"]:
            p = f["properties"]
            w.writerow([f["id"], p["v"], (inset_of or {}).get(f["id"], p["inset"]), f["id"].upper()])
    return src, table


def test_the_command_reads_cartogram_cpp_inset_and_label_columns(states, tmp_path):
    src, table = _files(tmp_path, states)
    out, svg = tmp_path / "out.geojson", tmp_path / "out.svg"
    proc = _cli(src, "--data", table, "--id", "Region", "--id-property", "id", "--value", "Data", "--inset", "Inset",
                "--label", "Label", "--n", 64, "--out", out, "--svg", svg)
    assert proc.returncode == 0, proc.stderr
    assert "3 insets (C 9, L 1, B 2)" in proc.stdout
    doc = json.loads(out.read_text())
    assert doc["rfmap"]["status"] == "ok" and doc["rfmap"]["coordinates"] == "insets" and "crs" not in doc
    assert set(doc["rfmap"]["insets"]) == {"C", "L", "B"}
    geoms = np.array([shape(f["geometry"]) for f in doc["features"]], dtype=object)
    assert shapely.is_valid(geoms).all() and [f["id"] for f in doc["features"]] == [f["id"] for f in states["features"]]
    labels = re.findall(r"<text[^>]*>([^<]*)</text>", svg.read_text())
    for label in ("M0", "M8", "AK", "HI1", "HI2"):  # from the Label column, on the input map and the cartogram
        assert labels.count(label) == 2, (label, labels)


def test_an_unknown_inset_is_bad_input(states, tmp_path):
    src, table = _files(tmp_path, states, {"ak": "Alaska"})
    out = tmp_path / "out.geojson"
    proc = _cli(src, "--data", table, "--id", "Region", "--id-property", "id", "--value", "Data", "--inset", "Inset",
                "--n", 32, "--out", out)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "unknown inset 'Alaska'" in proc.stderr
    assert not out.exists()


def test_the_interactive_page_draws_the_placed_insets(states):
    pytest.importorskip("plotly")
    from rfmap.cartogram.html import HtmlOptions, page_figure

    c = cartogram_insets(states, "v", "inset", n=64)
    fig = page_figure([c], ["v"], HtmlOptions(detail=0.0))
    assert len(fig.data) == 12 and fig.data[9].text.startswith("<b>ak</b>")
    x = [v for v in fig.data[9].x if v is not None]
    assert max(x) < shapely.total_bounds(c.geometries[c.groups["C"]])[0]  # Alaska drawn left of the main map
