"""Tests of :mod:`rfmap.cartogram.html` and ``rfmap cartogram --html``: the page's traces carry each region's label,
value and area error; the page is self-contained; in headless Chromium it draws every region, hovering a region shows
its text, and moving the slider shows another frame (skipped where Chromium is not installed)."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest
import shapely
from shapely.geometry import mapping

pytest.importorskip("plotly")

from rfmap.cartogram.resize import cartogram  # noqa: E402
from rfmap.cartogram.html import (  # noqa: E402
    HtmlOptions, cartogram_page, figure_html, page_figure, series_page)
from rfmap.cartogram.series import cartogram_series  # noqa: E402

KEYS = ("a", "b")


@pytest.fixture(scope="module")
def grid_map():
    """Nine squares whose two values run in opposite directions: the two frames differ."""
    feats = [{"type": "Feature", "id": f"r{3 * i + j}",
              "properties": {"a": 1.0 + 3 * i + j, "b": 9.0 - 3 * i - j, "name": f"Square {3 * i + j}"},
              "geometry": mapping(shapely.box(i, j, i + 1, j + 1))} for i in range(3) for j in range(3)]
    return {"type": "FeatureCollection", "features": feats}


@pytest.fixture(scope="module")
def series(grid_map):
    return cartogram_series(grid_map, list(KEYS), n=32, max_iterations=8)


def test_traces_carry_label_value_and_area_error(series):
    fig = page_figure([f.carto for f in series.frames], list(KEYS), HtmlOptions(detail=0.0))
    first = series.frames[0].carto
    assert len(fig.data) == len(first.values) == 9
    for k, trace in enumerate(fig.data):
        assert trace.text.startswith(f"<b>r{k}</b>")
        assert f"value: {first.values[k]:,.6g}" in trace.text
        assert f"area error: {100 * first.area_errors[k]:.2f} %" in trace.text
    assert [fr.name for fr in fig.frames] == list(KEYS)
    assert [s["label"] for s in fig.layout.sliders[0].steps] == list(KEYS)
    last = series.frames[-1].carto
    x = [v for v in fig.frames[-1].data[0].x if v is not None]
    assert np.allclose(x, shapely.get_coordinates(shapely.get_exterior_ring(last.geometries[0]))[:, 0])


def test_outlines_are_drawn_to_the_detail_asked(series):
    """By default a region's outline keeps only the vertices a page a thousand pixels wide shows: within that of
    the cartogram's own outline, with fewer vertices."""
    carto = series.frames[0].carto
    full = page_figure([carto], ["a"], HtmlOptions(detail=0.0)).data
    fine = page_figure([carto], ["a"]).data
    extent = np.ptp(shapely.get_coordinates(carto.geometries), axis=0).max()
    for a, b, geom in zip(full, fine, carto.geometries):
        pts = [(x, y) for x, y in zip(b.x, b.y) if x is not None]
        assert 4 <= len(pts) < len([x for x in a.x if x is not None])
        assert shapely.hausdorff_distance(shapely.Polygon(pts), geom) <= 1.2e-3 * extent


def test_labels_and_colours_must_be_one_per_region(series):
    cartos = [f.carto for f in series.frames]
    with pytest.raises(ValueError, match="one per region"):
        page_figure(cartos, list(KEYS), HtmlOptions(labels=["x"]))
    with pytest.raises(ValueError, match="same regions"):
        page_figure(cartos, ["a"])


def _bold(text: str) -> str:
    """``<b>text</b>`` as plotly writes it into a page's JSON (``<``, ``>`` and ``/`` escaped)."""
    return f"\\u003cb\\u003e{text}\\u003c\\u002fb\\u003e"


def test_the_page_is_self_contained(grid_map, tmp_path):
    c = cartogram(grid_map, "a", n=32)
    path = tmp_path / "one.html"
    cartogram_page(c, path, HtmlOptions(labels=[f"L{k}" for k in range(9)]))
    html = path.read_text()
    assert "<script src=" not in html and len(html) > 1_000_000  # plotly.js embedded
    assert _bold("L4") in html and not (tmp_path / "one.html.part").exists()


# ----------------------------------------------------------------------------------------------- headless Chromium
#: Appended to a copy of the page: hovers the first region, moves the slider to its last step the way a mouse does
#: (a press on the slider's rail, then a release), and writes what it saw into the page as JSON
PROBE = """<script>
(function () {
  function fills(gd) {
    return Array.prototype.map.call(gd.querySelectorAll(".scatterlayer .trace path.js-fill"),
                                    function (p) { return p.getAttribute("d") || ""; });
  }
  function report(out) {
    var pre = document.createElement("pre");
    pre.id = "probe";
    pre.textContent = JSON.stringify(out);
    document.body.appendChild(pre);
  }
  function probe() {
    var gd = document.querySelector(".js-plotly-plot");
    var out = {traces: gd.data.length, before: fills(gd)};
    var pts = gd.data[0].x.map(function (x, i) { return [x, gd.data[0].y[i]]; })
                          .filter(function (p) { return p[0] !== null; });
    var mean = function (k) { return pts.reduce(function (s, p) { return s + p[k]; }, 0) / pts.length; };
    Plotly.Fx.hover(gd, {xval: mean(0), yval: mean(1)}, "xy");
    var label = document.querySelector(".hoverlayer .hovertext");
    out.hover = label ? label.textContent : null;
    var rail = gd.querySelector(".slider-rail-touch-rect");
    if (!rail) { report(out); return; }
    out.active_before = gd._fullLayout.sliders[0].active;
    var r = rail.getBoundingClientRect();
    var at = {clientX: r.right - 3, clientY: r.top + r.height / 2, bubbles: true, view: window, buttons: 1};
    rail.dispatchEvent(new MouseEvent("mousedown", at));
    rail.dispatchEvent(new MouseEvent("mouseup", at));
    var tries = 0, last = null;
    (function wait() {  // until the outlines changed and stayed so for one poll (the frame drawn), at most 60 s
      out.active_after = gd._fullLayout.sliders[0].active;
      out.after = fills(gd);
      var now = out.after.join(), changed = now !== out.before.join();
      if ((changed && now === last) || ++tries > 300) { report(out); } else { last = now; setTimeout(wait, 200); }
    })();
  }
  window.addEventListener("load", function () { setTimeout(probe, 500); });
})();
</script>"""


def _chromium():
    for name in ("chromium", "chromium-browser"):
        if shutil.which(name):
            return shutil.which(name)
    pytest.skip("headless Chromium is not installed (Debian: apt-get install chromium)")


def _in_chromium(page, tmp_path) -> dict:
    """What :data:`PROBE` saw on ``page`` in headless Chromium (a fresh profile, no network services)."""
    html = page.read_text()
    end = html.rfind("</body>")
    probed = tmp_path / f"probe-{page.name}"
    probed.write_text(html[:end] + PROBE + html[end:])
    cmd = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
           "--disable-component-update", "--disable-sync", "--no-first-run", f"--user-data-dir={tmp_path / 'profile'}",
           "--virtual-time-budget=120000", "--dump-dom", probed.as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    found = re.search(r'<pre id="probe">(.*?)</pre>', proc.stdout, re.S)
    assert found, proc.stderr[-2000:]
    return json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&").replace("&lt;", "<")
                      .replace("&gt;", ">"))


def test_the_page_renders_regions_and_the_slider_changes_the_frame(series, tmp_path):
    _chromium()
    path = tmp_path / "series.html"
    series_page(series, path)
    seen = _in_chromium(path, tmp_path)
    assert seen["traces"] == 9
    assert sum(len(d) > 20 for d in seen["before"]) == 9  # every region drawn as a filled outline
    assert seen["hover"].startswith("r0") and "value: 1" in seen["hover"] and "area error:" in seen["hover"]
    assert seen["active_before"] == 0 and seen["active_after"] == len(KEYS) - 1
    assert sum(len(d) > 20 for d in seen["after"]) == 9
    assert seen["after"] != seen["before"]  # the second frame's outlines: the values ran the other way


def _geojson(tmp_path, collection):
    path = tmp_path / "grid.geojson"
    path.write_text(json.dumps(collection))
    return path


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "rfmap.cli", "cartogram", *map(str, args)], capture_output=True,
                          text=True, timeout=600)


def test_the_command_writes_the_page(grid_map, tmp_path):
    src = _geojson(tmp_path, grid_map)
    page = tmp_path / "series.html"
    proc = _cli(src, "--series", *KEYS, "--n", 32, "--out", tmp_path / "out.geojson", "--html", page,
                "--label", "name")
    assert proc.returncode == 0, proc.stderr
    assert str(page) in proc.stdout
    html = page.read_text()
    assert _bold("Square 4") in html and '"currentvalue":{"prefix":"frame: "' in html
    one = tmp_path / "one.html"
    proc = _cli(src, "--value", "a", "--n", 32, "--out", tmp_path / "one.geojson", "--html", one)
    assert proc.returncode == 0, proc.stderr
    assert one.exists() and '"currentvalue":{"prefix":"frame: "' not in one.read_text()


def test_a_page_that_is_not_html_is_bad_input(grid_map, tmp_path):
    src = _geojson(tmp_path, grid_map)
    proc = _cli(src, "--value", "a", "--out", tmp_path / "out.geojson", "--html", tmp_path / "page.txt")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "--html must name a .html file" in proc.stderr
    assert not (tmp_path / "out.geojson").exists()


def test_figure_html_is_a_captioned_self_contained_figure(series):
    fig = page_figure([f.carto for f in series.frames], list(KEYS))
    text = figure_html(fig, "Beyond the paper: a <small> map & its frames.", name="fig-x", height=400)
    assert text.startswith('<figure class="align-default" id="fig-x">') and text.endswith("</figure>")
    assert text.count("<figcaption>") == 1 and "a &lt;small&gt; map &amp; its frames." in text
    assert "400px" in text and "plotly.js" in text.lower() and '<script src="http' not in text


def test_figure_html_fits_its_height_to_the_map(series):
    """A wide map gets a low figure: no empty band above or below it at the page's width."""
    from rfmap.cartogram.html import PAGE_WIDTH_PX, fitted_height

    fig = page_figure([f.carto for f in series.frames], list(KEYS))
    fig.update_layout(xaxis={"range": [0.0, 3.0]}, yaxis={"range": [0.0, 1.0], "scaleratio": 1.0})
    lay = fig.layout
    plot = (PAGE_WIDTH_PX - lay.margin.l - lay.margin.r) / 3
    assert fitted_height(fig) == max(300, round(plot + lay.margin.t + lay.margin.b + 110))
    fig.update_layout(yaxis={"range": [0.0, 3.0]})
    assert f"{fitted_height(fig)}px" in figure_html(fig, "a map")
