"""The API reference keeps a constant's comment whole when its first line holds a colon."""
from sphinx.ext.napoleon import Config
from sphinx.ext.napoleon.docstring import NumpyDocstring

from rfmap.paper._apidocs import GUARD, keep_whole


def _rendered(what: str, lines: list[str]) -> list[str]:
    lines = list(lines)
    keep_whole(None, what, "X", None, None, lines)
    return NumpyDocstring(lines, Config(napoleon_use_ivar=True), what=what, name="X").lines()


def test_a_comment_with_a_colon_is_not_cut_into_a_type():
    comment = ["cells per side: the raster's side at which", "the flow is run."]
    plain = NumpyDocstring(list(comment), Config(napoleon_use_ivar=True), what="data", name="X").lines()
    assert ":type: cells per side" in plain  # what napoleon alone makes of it
    out = _rendered("data", comment)
    assert out == [GUARD, *comment] and not any(line.startswith(":type:") for line in out)


def test_the_guard_is_taken_out_after_napoleon():
    from rfmap.paper._apidocs import drop_guard

    lines = _rendered("data", ["cells per side: the raster's side at which", "the flow is run."])
    drop_guard(None, "data", "X", None, None, lines)
    assert lines == ["cells per side: the raster's side at which", "the flow is run."]
    joined = [GUARD + "text", "more"]
    drop_guard(None, "data", "X", None, None, joined)
    assert joined == ["text", "more"]


def test_functions_and_comments_without_a_colon_are_left_alone():
    assert _rendered("data", ["the largest side"]) == ["the largest side"]
    lines = ["Do this: then that."]
    keep_whole(None, "function", "f", None, None, lines)
    assert lines == ["Do this: then that."]


def test_the_extension_loads_before_autodoc_in_a_sphinx_build(tmp_path):
    """_config.yml lists it before sphinx.ext.autodoc: it sets autodoc up itself, and a constant's comment with a
    colon comes out whole in the built page."""
    import sys

    from sphinx.application import Sphinx

    (tmp_path / "mod_x.py").write_text('#: cells per side: the raster\'s side\nSIDE = 4\n', encoding="utf-8")
    (tmp_path / "conf.py").write_text(
        'extensions = ["rfmap.paper._apidocs", "sphinx.ext.autodoc", "sphinx.ext.napoleon"]\n', encoding="utf-8")
    (tmp_path / "index.rst").write_text(".. autodata:: mod_x.SIDE\n", encoding="utf-8")
    sys.path.insert(0, str(tmp_path))
    try:
        app = Sphinx(str(tmp_path), str(tmp_path), str(tmp_path / "_build"), str(tmp_path / "_doctrees"), "text",
                     status=None, warning=None)
        app.build()
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("mod_x", None)
    text = (tmp_path / "_build" / "index.txt").read_text(encoding="utf-8")
    assert "cells per side: the raster's side" in text and "Type:" not in text
    assert GUARD not in text  # taken out again after napoleon


def test_an_entry_naming_several_attributes_becomes_one_entry_each():
    from rfmap.paper._apidocs import split_attributes

    lines = ["A class.", "", "Attributes", "----------", "regions, mapped : ndarray", "    Before and after.",
             "tol, min_share : float", "", "Examples", "--------", "a, b : 1"]
    split_attributes(None, "class", "X", None, None, lines)
    assert lines == ["A class.", "", "Attributes", "----------", "regions : ndarray", "    Before and after.",
                     "mapped : ndarray", "    Before and after.", "tol : float", "min_share : float", "",
                     "Examples", "--------", "a, b : 1"]


def test_a_hidden_string_value_is_shown_as_its_text():
    from rfmap.paper._apidocs import show_text

    lines = ["The rule.", "", ":meta hide-value:"]
    show_text(None, "data", "X", "*met*: |Δd| under a_ b", None, lines)
    assert lines[-2] == "*met*: \\|Δd\\| under a\\_ b"
    plain = ["A constant."]
    show_text(None, "data", "X", "text", None, plain)
    assert plain == ["A constant."]
    table = [":meta hide-value:"]
    show_text(None, "data", "X", {"ours": "ours", "LBS": "a|b"}, None, table)
    assert table[1:] == ["", "* ``ours``: ours", "* ``LBS``: a\\|b", ""]


def test_factory_defaults_are_written_as_calls():
    from dataclasses import dataclass, field

    from rfmap.paper._apidocs import factory_defaults

    @dataclass
    class D:
        a: int
        info: dict = field(default_factory=dict)
        more: list = field(default_factory=lambda: [1])

    sig = "(a: int, info: dict = <factory>, more: list = <factory>)"
    out = factory_defaults(None, "class", "D", D, None, sig, None)
    assert out == ("(a: int, info: dict = dict(), more: list = ...)", None)
    assert factory_defaults(None, "class", "D", D, None, "(a: int)", None) is None
