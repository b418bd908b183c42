"""The cartogram methods as strategies looked up by name (rfmap.cartogram.methods), and the options that travel whole
from the command line to the cartogram, the series and the insets (rfmap.cli.cartogram.cartogram_options)."""
from __future__ import annotations

import argparse
from dataclasses import fields

import pytest

from rfmap.cartogram.methods import METHODS, get_method
from rfmap.cartogram.options import CartogramOptions
from rfmap.cli.cartogram import add_cartogram_parser, cartogram_options


def _args(*argv):
    parser = argparse.ArgumentParser()
    add_cartogram_parser(parser.add_subparsers())
    return parser.parse_args(["cartogram", "in.geojson", *argv])


def test_methods_are_looked_up_by_name_and_say_what_the_passes_need():
    assert list(METHODS) == ["diffusion", "flow", "surrogate", "hybrid"]
    assert get_method("dem") is get_method("diffusion")
    flow, diffusion, hybrid = get_method("flow"), get_method("diffusion"), get_method("hybrid")
    assert flow.classical and flow.carries_vertices and flow.accelerate and flow.finest == 2048
    assert diffusion.classical and diffusion.carries_vertices and not diffusion.accelerate
    assert not hybrid.classical and not hybrid.carries_vertices
    with pytest.raises(ValueError, match="unknown cartogram method 'cont'.*diffusion, flow, surrogate, hybrid"):
        get_method("cont")


def test_the_command_line_defaults_are_the_apis():
    """Built from no options, the command's CartogramOptions is the API's default object, field for field."""
    assert cartogram_options(_args()) == CartogramOptions()
    o = cartogram_options(_args("--method", "dem", "--n", "128", "--tol", "0.02", "--max-passes", "7", "--lonlat",
                                "--points", "900", "--timeout", "30", "--projection", "none", "--model", "m"))
    want = CartogramOptions(method="diffusion", n=128, tol=0.02, max_iterations=7, output="input", points=900,
                            timeout=30.0, projection="none", model="m")
    assert o == want, [f.name for f in fields(o) if getattr(o, f.name) != getattr(want, f.name)]


def test_the_flow_blurs_its_first_passes_less_and_less(monkeypatch):
    """Pass k of the flow blurs over FLOW_BLUR / 2**k vertex spacings, none below a quarter."""
    import rfmap.solvers.cartoflow as cf

    seen = []
    monkeypatch.setattr(cf, "flow_square", lambda density, opts, points=None: seen.append(opts.blur))
    method = get_method("flow")(CartogramOptions())
    for _ in range(4):
        method.grid_map(None, None)
    assert seen == [1.0, 0.5, 0.25, 0.0]


def test_a_series_and_insets_refuse_options_they_cannot_take(tmp_path):
    from rfmap.cartogram.series import cartogram_series

    with pytest.raises(ValueError, match="output cannot be chosen"):
        cartogram_series({"type": "FeatureCollection", "features": []}, ["v"], CartogramOptions(output="input"))
