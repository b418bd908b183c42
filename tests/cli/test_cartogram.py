"""The cartogram command's report (rfmap.cli.cartogram) and its torch-free drawing."""
import json
import subprocess
import sys

import pytest


def test_long_lists_in_the_report_are_cut_to_ten_names():
    """A county map may cut overlaps in a thousand pairs: the report names ten and counts the rest."""
    from rfmap.cli.cartogram import LISTED_CUTS, _listed

    assert _listed(["a", "b"]) == "a, b"
    line = _listed([f"r{i}" for i in range(1492)], LISTED_CUTS)
    assert line.startswith("r0, r1,") and "r9 and 1482 more" in line and "r10" not in line
    assert line.endswith('lists them all)')


def test_drawing_a_cartogram_never_imports_torch(tmp_path):
    """``--svg``, ``--png``, ``--html`` (coloured and labelled from a CSV) and ``--gif`` run through the command line
    in a fresh interpreter and load no PyTorch: the figures need matplotlib (and plotly), not the neural layer."""
    pytest.importorskip("shapely")
    pytest.importorskip("plotly")
    feats = []
    for i, (x, y) in enumerate([(0, 0), (1, 0), (0, 1), (1, 1)]):
        ring = [[x, y], [x + 1, y], [x + 1, y + 1], [x, y + 1], [x, y]]
        feats.append({"type": "Feature", "id": f"r{i}", "properties": {"code": f"r{i}"},
                      "geometry": {"type": "Polygon", "coordinates": [[[1000.0 * a, 1000.0 * b] for a, b in ring]]}})
    src = tmp_path / "in.geojson"
    src.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    (tmp_path / "data.csv").write_text("code,y1,y2,group,name\nr0,1,4,a,A\nr1,1,3,b,B\nr2,1,2,a,C\nr3,5,1,b,D\n")
    common = [str(src), "--data", str(tmp_path / "data.csv"), "--id", "code", "--n", "32"]
    runs = [["--value", "y1", "--color", "group", "--label", "name", "--svg", "a.svg", "--png", "a.png",
             "--html", "a.html", "--out", "a.geojson"],
            ["--series", "y1", "y2", "--gif", "b.gif", "--html", "b.html", "--out", "b.geojson"]]
    code = f"""
import sys
from rfmap.cli import main
for extra in {runs!r}:
    rc = main(['cartogram', *{common!r}, *extra])
    assert rc == 0, (extra, rc)
print('torch' in sys.modules)
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip().splitlines()[-1] == "False", "drawing a cartogram imported torch"
    for name in ("a.svg", "a.png", "a.html", "a.geojson", "b.gif", "b.html", "b.geojson"):
        assert (tmp_path / name).stat().st_size > 0, name
